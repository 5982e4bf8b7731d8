//! Screen-sample pass of the SH probe method (seed 001 §5.1, §6.1): after the
//! lighting pass, the frame is split into `sh_screen_samples` regular tiles and one
//! stratified random pixel per tile becomes a sample (radiance, position, normal,
//! and the area eq. 10 gives it).
//!
//! The radiance is what the surface sends toward a probe, not toward the camera:
//! the diffuse part of the lit frame at that pixel — diffuse direct light (with
//! the camera pass's own light sampling), plus albedo/π × the probes' irradiance
//! (the recursion that accumulates bounces, §5.1), plus its emission when emitters
//! reach surfaces through the probes (`sh_light_injection`). Without injection the
//! camera pass samples emitters itself, so emission is left out here and the
//! probes carry reflected light only. Recomputing 400 pixels' diffuse lighting
//! costs less than keeping a second full-frame buffer.

use glam::Vec3;
use probegi_core::bsdf::SurfaceBsdf;
use probegi_core::camera::CameraRays;
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_core::sh_cascades::ShCascades;
use probegi_core::sh_probe_update::{ShSample, screen_sample_area_m2};
use probegi_scene::{Scene, SurfacePoint};
use std::f32::consts::FRAC_1_PI;

use crate::direct::{DirectLighting, DirectSettings};
use crate::gbuffer::GBuffer;
use crate::shading::ShadingContext;

/// A screen sample and the surface it came from (for occlusion rays).
#[derive(Clone, Copy, Debug)]
pub struct ScreenSample {
    /// What the probes project: radiance, position, normal and area.
    pub sample: ShSample,
    /// The surface the sample's pixel sees.
    pub surface: SurfacePoint,
}

/// What the screen-sample pass reads.
pub struct ScreenSampleInputs<'a> {
    /// The scene as this frame sees it.
    pub scene: &'a Scene,
    /// Direct light at the sampled surfaces.
    pub direct: &'a DirectLighting<'a>,
    /// The camera pass's light sampling.
    pub direct_settings: DirectSettings,
    /// The probes as they stand (albedo/π × their irradiance is the bounce).
    pub probes: &'a ShCascades,
    /// Add the surface's emission (with `sh_light_injection`).
    pub include_emission: bool,
    /// The frame's camera (each sample's pixel footprint, eq. 10).
    pub camera: &'a CameraRays,
    /// The frame's G-buffer.
    pub gbuffer: &'a GBuffer,
    /// Tiles across and down; one sample per tile.
    pub tiles: glam::UVec2,
    /// The render's seed.
    pub seed: u64,
    /// The frame index (per-frame sample positions).
    pub frame: u32,
}

/// Takes one sample per tile. Returns the samples and the shadow rays traced.
pub fn take_screen_samples(inputs: &ScreenSampleInputs<'_>) -> (Vec<ScreenSample>, u64) {
    use rayon::prelude::*;
    let g = inputs.gbuffer;
    let (w, h) = (g.width, g.height);
    let tiles = inputs.tiles.min(glam::UVec2::new(w, h));
    let per_tile = (w as f32 / tiles.x as f32) * (h as f32 / tiles.y as f32);
    let results: Vec<(Option<ScreenSample>, u64)> = (0..tiles.x * tiles.y)
        .into_par_iter()
        .map(|tile| {
            let mut rng = Pcg32::new(hash_combine(&[inputs.seed, inputs.frame as u64, tile as u64, 0x5c]), tile as u64);
            let (tx, ty) = (tile % tiles.x, tile / tiles.x);
            let x0 = tx * w / tiles.x;
            let x1 = ((tx + 1) * w / tiles.x).max(x0 + 1);
            let y0 = ty * h / tiles.y;
            let y1 = ((ty + 1) * h / tiles.y).max(y0 + 1);
            let x = (x0 + (rng.next_f32() * (x1 - x0) as f32) as u32).min(x1 - 1);
            let y = (y0 + (rng.next_f32() * (y1 - y0) as f32) as u32).min(y1 - 1);
            let texel = &g.texels[(y * w + x) as usize];
            let Some(sp) = texel.surface else { return (None, 0) };
            let to_eye = inputs.camera.origin_world - sp.position;
            let n = sp.facing_normal();
            let mut ctx = ShadingContext::new(inputs.scene, &sp, texel.view_dir_world);
            ctx.bsdf = SurfaceBsdf::lambertian(ctx.bsdf.diffuse_albedo());
            let (direct, rays) = inputs.direct.reflected(&sp, &ctx, inputs.direct_settings, true, &mut rng);
            let indirect = ctx.bsdf.diffuse * FRAC_1_PI * inputs.probes.irradiance(sp.position, n);
            let emission = if inputs.include_emission { inputs.scene.emitted(&sp) } else { Vec3::ZERO };
            let radiance = emission + direct + indirect;
            let omega = inputs.camera.pixel_solid_angle_sr(-texel.view_dir_world) * per_tile;
            let area_m2 = screen_sample_area_m2(omega, to_eye.length(), n.dot(texel.view_dir_world));
            if !(radiance.is_finite() && area_m2.is_finite()) {
                return (None, rays);
            }
            let sample = ShSample { position_m: sp.position, normal: n, radiance, area_m2 };
            (Some(ScreenSample { sample, surface: sp }), rays)
        })
        .collect();
    let rays = results.iter().map(|r| r.1).sum();
    (results.into_iter().filter_map(|r| r.0).collect(), rays)
}
