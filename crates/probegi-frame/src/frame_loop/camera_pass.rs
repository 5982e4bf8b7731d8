//! The `camera` pass of the CPU frame: per pixel of the G-buffer, emission and
//! direct light, glossy pixels' reflected ray under DDGI (seed 004 §4.4), and
//! the diffuse albedo/π × the field's irradiance (DDGI set or SH probes).

use glam::Vec3;
use probegi_core::ddgi_volume_blend::{DdgiFieldSetView, field_set_irradiance};
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_core::sh_cascades::ShCascades;
use probegi_scene::{Ray, RayTracer, Scene};
use std::f32::consts::FRAC_1_PI;

use super::Accumulation;
use probegi_cpu::direct::{DirectLighting, DirectSettings};
use probegi_cpu::gbuffer::GBuffer;
use probegi_cpu::shading::{ShadingContext, lambert_cos};

/// Where the camera pass reads indirect irradiance.
pub(super) enum IndirectField<'a> {
    Ddgi(DdgiFieldSetView<'a>),
    Sh(&'a ShCascades),
}

impl IndirectField<'_> {
    fn irradiance(&self, position: Vec3, normal: Vec3, view_dir: Vec3) -> Vec3 {
        match self {
            IndirectField::Ddgi(f) => field_set_irradiance(f, position, normal, view_dir),
            IndirectField::Sh(c) => c.irradiance(position, normal),
        }
    }
}

/// What the camera pass shades with.
pub(super) struct CameraPasses<'a> {
    pub(super) scene: &'a Scene,
    pub(super) tracer: &'a dyn RayTracer,
    pub(super) direct: &'a DirectLighting<'a>,
    pub(super) direct_settings: DirectSettings,
    /// Second-order glossy from probes on glossy rays' hits.
    pub(super) second_order: bool,
    /// With a shadowing field (`shadow_field`), pixels read punctual lights'
    /// visibility from it (seed 003 §5.2) instead of tracing shadow rays.
    pub(super) shadow_field: Option<&'a probegi_field::DdgiFieldSet>,
}

/// The camera pass: per pixel, emission + direct light into `direct_out` and, with
/// a DDGI volume or SH probes, the field's irradiance/π into `irradiance_out` and
/// the diffuse albedo that weighs it into the frame's albedo.
/// Glossy pixels under DDGI also trace one reflected ray per frame (seed 004 §4.4),
/// importance-sampled from the GGX lobe, whose hit is shaded with direct light plus
/// probe irradiance (and, with `glossy_second_order`, the hit's own specular
/// reflection read from the probes); that term accumulates with the direct one.
/// Area lights' specular highlights then come from reflected rays that hit the
/// emitter, so the direct NEE uses the diffuse lobe only for them (no double count).
/// Pixels that see nothing get the sky. Returns rays traced and, for the
/// `frame_unlit_fraction` statistic, (surface pixels with a diffuse albedo, those
/// of them that got no indirect light). A pixel whose direct radiance comes out
/// non-finite is written as 0 and counted in `nonfinite` (never silently).
pub(super) fn shade_camera(
    passes: &CameraPasses<'_>,
    field: Option<IndirectField<'_>>,
    gbuffer: &GBuffer,
    frame: u32,
    seed: u64,
    acc: &mut Accumulation,
    nonfinite: &std::sync::atomic::AtomicU64,
) -> (u64, usize, usize) {
    let CameraPasses { scene, direct, direct_settings, .. } = *passes;
    let (direct_out, irradiance_out) = (&mut acc.frame_direct, &mut acc.frame_irradiance);
    let albedo_out = &mut acc.frame_albedo;
    use rayon::prelude::*;
    let w = gbuffer.width as usize;
    let ddgi = match &field {
        Some(IndirectField::Ddgi(f)) => Some(f),
        _ => None,
    };
    direct_out
        .par_chunks_mut(w)
        .zip(irradiance_out.par_chunks_mut(w))
        .zip(albedo_out.par_chunks_mut(w))
        .enumerate()
        .map(|(y, ((drow, irow), arow))| {
            let (mut rays, mut surfaces, mut unlit) = (0u64, 0usize, 0usize);
            for (x, ((d, i), a)) in drow.iter_mut().zip(irow.iter_mut()).zip(arow.iter_mut()).enumerate() {
                let texel = &gbuffer.texels[y * w + x];
                let Some(sp) = &texel.surface else {
                    *d = scene.sky_toward(-texel.view_dir_world);
                    *i = Vec3::ZERO;
                    *a = Vec3::ZERO;
                    continue;
                };
                let pixel = (y * w + x) as u64;
                let mut rng = Pcg32::new(hash_combine(&[seed, pixel, frame as u64, 0xd1]), pixel);
                let ctx = ShadingContext::new(scene, sp, texel.view_dir_world);
                let glossy_rays = ddgi.is_some() && ctx.bsdf.has_specular();
                let view_dir = texel.view_dir_world;
                // The point's shadow cage, weighed once for all its lights.
                let cage = passes.shadow_field.map(|set| set.shadow_cage(sp.position, sp.facing_normal(), view_dir));
                let field_visibility =
                    cage.map(|cage| move |_: &probegi_scene::SurfacePoint, wi: Vec3| cage.map(|c| c.visibility(wi)));
                let visibility = field_visibility.as_ref().map(|v| v as &probegi_cpu::shading::PunctualVisibility<'_>);
                let (l, k) = direct.reflected_with(sp, &ctx, direct_settings, !glossy_rays, visibility, &mut rng);
                rays += k;
                let mut l = scene.emitted(sp) + l;
                if let (true, Some(f)) = (glossy_rays, ddgi)
                    && let Some((wi_local, weight)) = ctx.bsdf.sample_specular(ctx.wo, rng.next_vec2())
                {
                    let wi = ctx.frame.to_world(wi_local);
                    if lambert_cos(sp, wi).is_some() {
                        rays += 1;
                        let (lr, kh) = glossy_ray_radiance(passes, f, sp, wi, &mut rng);
                        rays += kh;
                        l += weight * lr;
                    }
                }
                *d = if l.is_finite() {
                    l
                } else {
                    nonfinite.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    Vec3::ZERO
                };
                let albedo = ctx.bsdf.diffuse_albedo();
                *a = albedo;
                let diffuse = albedo.max_element() > 0.0;
                surfaces += diffuse as usize;
                *i = match &field {
                    Some(f) => {
                        let e = f.irradiance(sp.position, sp.facing_normal(), texel.view_dir_world);
                        unlit += (diffuse && e.max_element() <= 0.0) as usize;
                        // Weighed by the (accumulated) albedo when composed.
                        e * FRAC_1_PI
                    }
                    None => Vec3::ZERO,
                };
            }
            (rays, surfaces, unlit)
        })
        .reduce(|| (0, 0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2))
}

/// Radiance along a glossy pixel's reflected ray `wi` from `sp`: the sky on a
/// miss, else its hit shaded by [`shade_glossy_hit`]; and the rays that took
/// (besides the reflected ray itself).
fn glossy_ray_radiance(
    passes: &CameraPasses<'_>,
    field: &DdgiFieldSetView<'_>,
    sp: &probegi_scene::SurfacePoint,
    wi: Vec3,
    rng: &mut Pcg32,
) -> (Vec3, u64) {
    let CameraPasses { scene, tracer, direct, direct_settings, second_order, .. } = *passes;
    let ray = Ray::new(sp.spawn_origin(wi), wi);
    match tracer.closest_hit(&ray) {
        None => (scene.sky_toward(wi), 0),
        Some(hit) => {
            shade_glossy_hit(scene, direct, direct_settings, field, &scene.surface_point(&hit), wi, second_order, rng)
        }
    }
}

/// Radiance leaving the hit of a camera glossy ray toward the camera surface:
/// emission + direct light + diffuse albedo/π × probe irradiance, plus with
/// `second_order` its specular reflection taken from the probes
/// (`glossy::second_order_specular`).
#[allow(clippy::too_many_arguments)]
fn shade_glossy_hit(
    scene: &Scene,
    direct: &DirectLighting<'_>,
    direct_settings: DirectSettings,
    field: &DdgiFieldSetView<'_>,
    sp: &probegi_scene::SurfacePoint,
    ray_dir: Vec3,
    second_order: bool,
    rng: &mut Pcg32,
) -> (Vec3, u64) {
    let ctx = ShadingContext::new(scene, sp, -ray_dir);
    let (l, rays) = direct.reflected(sp, &ctx, direct_settings, true, rng);
    let e = field_set_irradiance(field, sp.position, sp.facing_normal(), -ray_dir);
    let mut out = scene.emitted(sp) + l + ctx.bsdf.diffuse_albedo() * FRAC_1_PI * e;
    if second_order {
        out += probegi_cpu::glossy::second_order_specular(field, sp, &ctx, ray_dir);
    }
    (out, rays)
}
