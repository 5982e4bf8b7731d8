//! The per-frame loop of `probegi render`: passes in order, per-pass timings and
//! ray counts.
//!
//! Per frame, DDGI: the field update (`ray_gen`, `trace`, `shade`, `blend`,
//! `border`), then `gbuffer` (primary rays) and `camera` (shading each pixel).
//! SH probes (seed 001 §6.1): `gbuffer`, `camera` (the lighting pass reads the
//! probes), then the probe update from that frame (`sh_screen_samples`, `sh_update`).
//! The direct term (emission + direct light) of a static scene accumulates over
//! frames; the indirect term is the last frame's, so the image shows the field as
//! it stands after N updates.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::{DVec3, Vec3};
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_query::irradiance;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::image::Image;
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_scene::{Ray, RayTracer, Scene};
use std::f32::consts::FRAC_1_PI;

use crate::ddgi::DdgiVolume;
use crate::direct::{DirectLighting, DirectSettings};
use crate::gbuffer::{GBuffer, trace_gbuffer};
use crate::sh_probes::{SH_UPDATE_PASSES, ShProbes};
use crate::shading::{ShadingContext, lambert_cos};
use probegi_core::ddgi_query::DdgiFieldView;
use probegi_core::sh_cascades::ShCascades;
use probegi_core::sh_settings::ShProbeSettings;

/// Which global illumination runs on top of direct light.
#[derive(Clone, Debug, PartialEq)]
pub enum GiMethod {
    /// Direct light only.
    None,
    /// Dynamic diffuse global illumination with one probe volume.
    Ddgi(Box<DdgiVolumeSettings>),
    /// Screen-space GI with progressive SH probes (seed 001).
    Sh(Box<ShProbeSettings>),
}

/// Where the camera pass reads indirect irradiance.
enum IndirectField<'a> {
    Ddgi(DdgiFieldView<'a>),
    Sh(&'a ShCascades),
}

impl IndirectField<'_> {
    fn irradiance(&self, position: Vec3, normal: Vec3, view_dir: Vec3) -> Vec3 {
        match self {
            IndirectField::Ddgi(f) => irradiance(f, position, normal, view_dir),
            IndirectField::Sh(c) => c.irradiance(position, normal),
        }
    }
}

#[derive(Clone, Debug)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub frames: u32,
    pub seed: u64,
    pub gi: GiMethod,
    pub direct: DirectSettings,
    /// Draw DDGI probes as spheres in the final image.
    pub show_probes: bool,
}

/// Measurements of a render; serialised by the CLI's `--stats`.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    pub frames: u32,
    /// Mean wall-clock milliseconds per frame, by pass name.
    pub pass_ms: BTreeMap<&'static str, f64>,
    pub rays_traced: u64,
    /// DDGI and SH: probes; DDGI only: probe rays per frame, mean field-update ms (the four
    /// update passes plus border) and probe rays per second over it.
    pub probes: Option<usize>,
    pub rays_per_frame: Option<u64>,
    pub field_update_ms: Option<f64>,
    pub field_update_mrays_per_s: Option<f64>,
    /// DDGI only: probes per state name after the last frame.
    pub probe_states: Option<BTreeMap<&'static str, usize>>,
    /// DDGI only: probes that traced and blended in the last frame.
    pub active_probes: Option<usize>,
    /// DDGI with moving objects: Sleeping probes woken around them, summed over frames.
    pub probes_woken: u64,
}

pub struct RenderOutput {
    pub image: Image,
    pub stats: RenderStats,
    /// The DDGI volume after the last update (for atlas dumps).
    pub ddgi: Option<DdgiVolume>,
    /// The SH probes after the last update.
    pub sh: Option<ShProbes>,
}

/// Names of the passes that make up a DDGI field update.
pub const FIELD_UPDATE_PASSES: [&str; 5] = ["ray_gen", "trace", "shade", "blend", "border"];

/// Renders `settings.frames` frames and returns the final image. After each frame
/// `on_frame_done(f, image)` is called; `image()` composes that frame's image
/// (for `--sequence`), at a cost only when called.
///
/// An animated scene (`Scene::is_animated`) is set to each frame's state before
/// the frame, and its direct term is that frame's alone (no accumulation). A
/// light switching on or off notifies the DDGI volume of a large light change.
/// Moving objects are placed by `tracer.at_frame` (pass `instances`), DDGI
/// probes around them are woken each frame, and an object that jumps by more than
/// a probe cell between frames notifies a large object change.
pub fn render_frames(
    base_scene: &Scene,
    tracer: &dyn RayTracer,
    camera: &CameraRays,
    settings: &RenderSettings,
    mut on_frame_done: impl FnMut(u32, &dyn Fn() -> Image),
) -> RenderOutput {
    let scene = base_scene;
    let animated = scene.is_animated();
    let mut frame_scene = animated.then(|| scene.clone());
    let static_direct = DirectLighting::new(scene, tracer, settings.direct);
    let mut volume = match &settings.gi {
        GiMethod::Ddgi(s) => {
            let bounds = scene.bounds().unwrap_or((Vec3::splat(-1.0), Vec3::ONE));
            Some(DdgiVolume::new((**s).clone(), bounds))
        }
        _ => None,
    };
    let mut sh = match &settings.gi {
        GiMethod::Sh(s) => Some(ShProbes::new((**s).clone(), scene, camera.origin_world)),
        _ => None,
    };
    // The field carries the sky under DDGI (see `probe_shade`); SH probes carry
    // emitters and sky with light injection; direct-only renders sample both.
    let camera_direct = match (&volume, &sh) {
        (Some(_), _) => DirectSettings { direct_sky_samples: 0, ..settings.direct },
        (_, Some(p)) => p.camera_direct_settings(settings.direct),
        _ => settings.direct,
    };
    let n = settings.width as usize * settings.height as usize;
    let mut direct_sum = vec![DVec3::ZERO; n];
    let mut frame_direct = vec![Vec3::ZERO; n];
    let mut indirect = vec![Vec3::ZERO; n];
    let mut stats = RenderStats::default();
    let mut pass_totals: BTreeMap<&'static str, f64> = BTreeMap::new();
    let frames = settings.frames.max(1);
    let mut last_gbuffer: Option<GBuffer> = None;
    let mut accumulated = 0u32;
    let mut prev_object_bounds: Vec<(Vec3, Vec3)> = Vec::new();
    for f in 0..frames {
        if let Some(fs) = frame_scene.as_mut() {
            let was_on: Vec<bool> = fs.lights.iter().map(|l| l.intensity > 0.0).collect();
            fs.set_frame_from(base_scene, f as f32);
            // A light switching on or off is a large light change (seed 004 §4.3):
            // the frame loop reports it as an application would.
            let toggled = fs.lights.iter().zip(&was_on).any(|(l, &on)| (l.intensity > 0.0) != on);
            if let (true, true, Some(v)) = (toggled, f > 0, volume.as_mut()) {
                v.notify_scene_event(crate::ddgi::SceneEvent::LargeLightChange);
            }
        }
        let scene: &Scene = frame_scene.as_ref().unwrap_or(base_scene);
        // Moving geometry: place the instances for this frame (TLAS rebuild).
        let t = Instant::now();
        let frame_tracer = if animated { tracer.at_frame(scene, f as f32) } else { None };
        let tracer: &dyn RayTracer = frame_tracer.as_deref().unwrap_or(tracer);
        if animated {
            *pass_totals.entry("instances").or_default() += t.elapsed().as_secs_f64() * 1e3;
        }
        let frame_direct_lighting = animated.then(|| static_direct.for_frame(scene, tracer));
        let direct = frame_direct_lighting.as_ref().unwrap_or(&static_direct);
        if let Some(v) = volume.as_mut() {
            if scene.has_moving_geometry() {
                // Seed 004 Listing 5: sleeping probes around dynamic objects wake up.
                let bounds = scene.moving_object_bounds();
                stats.probes_woken += v.wake_probes_near(&bounds) as u64;
                // An object that jumps by more than a probe cell in one frame (an
                // occluder put in place) inside the volume (grown by a cell) is a
                // large object change (seed 004 §4.3), reported as an application would.
                let g = &v.grid;
                let (lo, hi) = (g.probe_position(glam::UVec3::ZERO), g.probe_position(g.probe_counts - 1));
                let near = |b: &(Vec3, Vec3)| b.0.cmple(hi + g.spacing_m).all() && b.1.cmpge(lo - g.spacing_m).all();
                let centre = |b: &(Vec3, Vec3)| (b.0 + b.1) * 0.5;
                let jumped = prev_object_bounds.len() == bounds.len()
                    && prev_object_bounds
                        .iter()
                        .zip(&bounds)
                        .any(|(a, b)| (near(a) || near(b)) && centre(a).distance(centre(b)) > g.min_spacing_m());
                if jumped {
                    v.notify_scene_event(crate::ddgi::SceneEvent::LargeObjectChange);
                }
                prev_object_bounds = bounds;
            }
            stats.rays_traced += v.update(scene, tracer, direct, settings.seed, f, &mut pass_totals);
        }

        let t = Instant::now();
        let (gbuffer, rays) = trace_gbuffer(scene, tracer, camera, settings.width, settings.height, f, settings.seed);
        *pass_totals.entry("gbuffer").or_default() += t.elapsed().as_secs_f64() * 1e3;
        stats.rays_traced += rays;

        if let Some(p) = sh.as_mut() {
            p.recentre(camera.origin_world, camera.forward_world());
        }
        let field = match (&volume, &sh) {
            (Some(v), _) => Some(IndirectField::Ddgi(v.view())),
            (_, Some(p)) => Some(IndirectField::Sh(&p.cascades)),
            _ => None,
        };
        let t = Instant::now();
        stats.rays_traced += shade_camera(
            scene,
            tracer,
            direct,
            camera_direct,
            field,
            volume.as_ref().is_some_and(|v| v.settings.glossy_second_order),
            &gbuffer,
            f,
            settings.seed,
            &mut frame_direct,
            &mut indirect,
        );
        if animated {
            accumulated = 0;
            direct_sum.iter_mut().for_each(|a| *a = DVec3::ZERO);
        }
        for (a, p) in direct_sum.iter_mut().zip(&frame_direct) {
            *a += p.as_dvec3();
        }
        accumulated += 1;
        *pass_totals.entry("camera").or_default() += t.elapsed().as_secs_f64() * 1e3;
        if let Some(p) = sh.as_mut() {
            stats.rays_traced +=
                p.update(scene, tracer, direct, settings.direct, camera, &gbuffer, settings.seed, f, &mut pass_totals);
        }
        last_gbuffer = Some(gbuffer);
        let compose = || Image {
            width: settings.width,
            height: settings.height,
            pixels: compose_pixels(&direct_sum, accumulated, &indirect),
        };
        on_frame_done(f, &compose);
    }
    stats.frames = frames;
    stats.pass_ms = pass_totals.into_iter().map(|(k, v)| (k, v / frames as f64)).collect();
    if let Some(v) = &volume {
        let update_ms: f64 = FIELD_UPDATE_PASSES.iter().filter_map(|p| stats.pass_ms.get(p)).sum();
        stats.probes = Some(v.grid.probe_count());
        stats.rays_per_frame = Some(v.rays_per_frame());
        stats.field_update_ms = Some(update_ms);
        stats.field_update_mrays_per_s = Some(v.rays_per_frame() as f64 / (update_ms * 1e-3) / 1e6);
        stats.probe_states = Some(v.state_counts());
        stats.active_probes = Some(v.active_probe_count());
    }
    if let Some(p) = &sh {
        stats.probes = Some(p.cascades.probe_count());
        stats.field_update_ms = Some(SH_UPDATE_PASSES.iter().filter_map(|k| stats.pass_ms.get(k)).sum());
    }
    let mut pixels = compose_pixels(&direct_sum, accumulated, &indirect);
    if let (true, Some(v), Some(g)) = (settings.show_probes, &volume, &last_gbuffer) {
        crate::probe_vis::draw_probes(v, camera, g, &mut pixels);
    }
    let image = Image { width: settings.width, height: settings.height, pixels };
    RenderOutput { image, stats, ddgi: volume, sh }
}

/// Mean direct term over the accumulated frames plus the last frame's indirect term.
fn compose_pixels(direct_sum: &[DVec3], accumulated: u32, indirect: &[Vec3]) -> Vec<Vec3> {
    direct_sum.iter().zip(indirect).map(|(d, i)| (*d / accumulated.max(1) as f64).as_vec3() + *i).collect()
}

/// The camera pass: per pixel, emission + direct light into `direct_out` and, with
/// a DDGI volume or SH probes, the diffuse albedo/π × the field's irradiance into
/// `indirect_out`.
/// Glossy pixels under DDGI also trace one reflected ray per frame (seed 004 §4.4),
/// importance-sampled from the GGX lobe, whose hit is shaded with direct light plus
/// probe irradiance (and, with `glossy_second_order`, the hit's own specular
/// reflection read from the probes); that term accumulates with the direct one.
/// Area lights' specular highlights then come from reflected rays that hit the
/// emitter, so the direct NEE uses the diffuse lobe only for them (no double count).
/// Pixels that see nothing get the sky. Returns rays traced.
#[allow(clippy::too_many_arguments)]
fn shade_camera(
    scene: &Scene,
    tracer: &dyn RayTracer,
    direct: &DirectLighting<'_>,
    direct_settings: DirectSettings,
    field: Option<IndirectField<'_>>,
    second_order: bool,
    gbuffer: &GBuffer,
    frame: u32,
    seed: u64,
    direct_out: &mut [Vec3],
    indirect_out: &mut [Vec3],
) -> u64 {
    use rayon::prelude::*;
    let w = gbuffer.width as usize;
    let ddgi = match &field {
        Some(IndirectField::Ddgi(f)) => Some(f),
        _ => None,
    };
    direct_out
        .par_chunks_mut(w)
        .zip(indirect_out.par_chunks_mut(w))
        .enumerate()
        .map(|(y, (drow, irow))| {
            let mut rays = 0;
            for (x, (d, i)) in drow.iter_mut().zip(irow.iter_mut()).enumerate() {
                let texel = &gbuffer.texels[y * w + x];
                let Some(sp) = &texel.surface else {
                    *d = scene.sky_radiance;
                    *i = Vec3::ZERO;
                    continue;
                };
                let pixel = (y * w + x) as u64;
                let mut rng = Pcg32::new(hash_combine(&[seed, pixel, frame as u64, 0xd1]), pixel);
                let ctx = ShadingContext::new(scene, sp, texel.view_dir_world);
                let glossy_rays = ddgi.is_some() && ctx.bsdf.has_specular();
                let (l, k) = direct.reflected(sp, &ctx, direct_settings, !glossy_rays, &mut rng);
                rays += k;
                let mut l = scene.emitted(sp) + l;
                if let (true, Some(f)) = (glossy_rays, ddgi)
                    && let Some((wi_local, weight)) = ctx.bsdf.sample_specular(ctx.wo, rng.next_vec2())
                {
                    let wi = ctx.frame.to_world(wi_local);
                    if lambert_cos(sp, wi).is_some() {
                        rays += 1;
                        let ray = Ray::new(sp.spawn_origin(wi), wi);
                        let lr = match tracer.closest_hit(&ray) {
                            None => scene.sky_radiance,
                            Some(hit) => {
                                let (lh, kh) = shade_glossy_hit(
                                    scene,
                                    direct,
                                    direct_settings,
                                    f,
                                    &scene.surface_point(&hit),
                                    wi,
                                    second_order,
                                    &mut rng,
                                );
                                rays += kh;
                                lh
                            }
                        };
                        l += weight * lr;
                    }
                }
                *d = if l.is_finite() { l } else { Vec3::ZERO };
                *i = match &field {
                    Some(f) => {
                        let e = f.irradiance(sp.position, sp.facing_normal(), texel.view_dir_world);
                        ctx.bsdf.diffuse_albedo() * FRAC_1_PI * e
                    }
                    None => Vec3::ZERO,
                };
            }
            rays
        })
        .sum()
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
    field: &probegi_core::ddgi_query::DdgiFieldView<'_>,
    sp: &probegi_scene::SurfacePoint,
    ray_dir: Vec3,
    second_order: bool,
    rng: &mut Pcg32,
) -> (Vec3, u64) {
    let ctx = ShadingContext::new(scene, sp, -ray_dir);
    let (l, rays) = direct.reflected(sp, &ctx, direct_settings, true, rng);
    let e = irradiance(field, sp.position, sp.facing_normal(), -ray_dir);
    let mut out = scene.emitted(sp) + l + ctx.bsdf.diffuse_albedo() * FRAC_1_PI * e;
    if second_order {
        out += crate::glossy::second_order_specular(field, sp, &ctx, ray_dir);
    }
    (out, rays)
}
