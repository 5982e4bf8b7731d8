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
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings};
use probegi_core::ddgi_volume_blend::{DdgiFieldSetView, field_set_irradiance};
use probegi_core::image::Image;
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_scene::{Ray, RayTracer, Scene};
use std::f32::consts::FRAC_1_PI;

use crate::direct::{DirectLighting, DirectSettings};
use crate::field_update::FieldSetUpdate;
use crate::gbuffer::{GBuffer, trace_gbuffer};
use crate::scene_events::SceneChangeDetector;
use crate::sh_probes::{SH_UPDATE_PASSES, ShProbes};
use crate::shading::{ShadingContext, lambert_cos};
use probegi_core::sh_cascades::ShCascades;
use probegi_core::sh_settings::ShProbeSettings;
use probegi_field::ddgi_field_set::DdgiFieldSet;

/// Which global illumination runs on top of direct light.
#[derive(Clone, Debug, PartialEq)]
pub enum GiMethod {
    /// Direct light only.
    None,
    /// Dynamic diffuse global illumination with one probe volume.
    Ddgi(Box<DdgiVolumeSettings>),
    /// DDGI with a set of volumes: `[[volumes]]` or camera-centred cascades.
    DdgiSet(Box<DdgiFieldSetSettings>),
    /// Screen-space GI with progressive SH probes (seed 001).
    Sh(Box<ShProbeSettings>),
}

/// Where the camera pass reads indirect irradiance.
enum IndirectField<'a> {
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
    /// The camera of each frame (a keyframed flythrough); empty = the fixed camera
    /// passed to [`render_frames`]. Frames past the end hold the last entry.
    pub camera_path: Vec<CameraRays>,
    /// Who traces the DDGI probe ray batches: `None` for the CPU tracer, or a
    /// [`probegi_field::ProbeBatchTracer`] (the CLI's `--backend wgpu`).
    pub probe_tracer: Option<probegi_field::ProbeTracerHandle>,
}

/// Measurements of a render; serialised by the CLI's `--stats`.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    /// Frames rendered (fewer than asked when `error` is set).
    pub frames: u32,
    /// Mean wall-clock milliseconds per frame, by pass name.
    pub pass_ms: BTreeMap<&'static str, f64>,
    /// Rays traced on the CPU, plus the probe batches and camera primary rays a
    /// `probe_tracer` traced; the shadow and glossy rays it traced are not counted.
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
    /// DDGI: volumes in the set, the last frame's ray batch (all volumes, one
    /// trace) and its split per volume, and probes scrolled into tracking windows.
    pub volumes: Option<usize>,
    pub batch_rays: Option<u64>,
    pub batch_rays_per_volume: Option<Vec<u64>>,
    pub probes_scrolled_in: u64,
    /// Per frame: the mean of that frame's image (what `--sequence` writes), and
    /// of its indirect (field) term alone.
    pub frame_means: Vec<Vec3>,
    pub frame_indirect_means: Vec<Vec3>,
    /// Per frame, with a DDGI or SH field: the fraction of pixels that see a
    /// surface whose diffuse albedo is non-zero but get no indirect light from the
    /// field (a black wall or an unreadable probe shows up here).
    pub frame_unlit_fraction: Vec<f32>,
    /// Frames whose image is all black (mean exactly 0) although the scene had
    /// light sources at that frame (`Scene::has_light_sources`) and pixels
    /// that see a surface with a diffuse albedo: almost always a bug to find,
    /// not an output (the CLI refuses such a render unless told to accept it).
    pub black_frames: Vec<u32>,
    /// CPU camera pixels, summed over frames, whose direct radiance came out
    /// NaN or infinite and were written as 0 (the CLI warns and reports them).
    pub nonfinite_pixels: u64,
    /// Set when the render stopped early: a probe batch tracer failed (a GPU
    /// device lost, say). The image is then that of the frames before.
    pub error: Option<String>,
}

pub struct RenderOutput {
    pub image: Image,
    pub stats: RenderStats,
    /// The DDGI volumes after the last update (for atlas dumps).
    pub ddgi: Option<DdgiFieldSet>,
    /// The SH probes after the last update.
    pub sh: Option<ShProbes>,
}

/// Names of the passes that make up a DDGI field update.
pub const FIELD_UPDATE_PASSES: [&str; 5] = ["ray_gen", "trace", "shade", "blend", "border"];

/// The render's running sums between frames.
struct Accumulation {
    direct_sum: Vec<DVec3>,
    frame_direct: Vec<Vec3>,
    indirect: Vec<Vec3>,
    accumulated: u32,
}

impl Accumulation {
    fn new(pixels: usize) -> Self {
        Self {
            direct_sum: vec![DVec3::ZERO; pixels],
            frame_direct: vec![Vec3::ZERO; pixels],
            indirect: vec![Vec3::ZERO; pixels],
            accumulated: 0,
        }
    }

    /// Adds the frame's direct term; an animated scene (or camera) restarts the mean.
    fn add_frame(&mut self, restart: bool) {
        if restart {
            self.accumulated = 0;
            self.direct_sum.iter_mut().for_each(|a| *a = DVec3::ZERO);
        }
        for (a, p) in self.direct_sum.iter_mut().zip(&self.frame_direct) {
            *a += p.as_dvec3();
        }
        self.accumulated += 1;
    }

    fn pixels(&self) -> Vec<Vec3> {
        compose_pixels(&self.direct_sum, self.accumulated, &self.indirect)
    }

    /// Records frame `f`'s means and hands its image to the caller.
    fn finish_frame(
        &self,
        f: u32,
        settings: &RenderSettings,
        stats: &mut RenderStats,
        on_frame_done: &mut impl FnMut(u32, &dyn Fn() -> Image),
    ) {
        let compose = || Image { width: settings.width, height: settings.height, pixels: self.pixels() };
        stats.frame_means.push(self.mean());
        let indirect_sum: DVec3 = self.indirect.iter().map(|i| i.as_dvec3()).sum();
        stats.frame_indirect_means.push((indirect_sum / self.indirect.len().max(1) as f64).as_vec3());
        on_frame_done(f, &compose);
    }

    /// Notes frame `f` in `stats.black_frames` when its image is all black
    /// although `scene` has light sources and `surfaces` pixels see a surface.
    fn check_black(&self, f: u32, scene: &Scene, surfaces: usize, stats: &mut RenderStats) {
        if surfaces > 0 && self.mean() == Vec3::ZERO && scene.has_light_sources() {
            stats.black_frames.push(f);
        }
    }

    /// Mean of the composed image, without composing it.
    fn mean(&self) -> Vec3 {
        let k = self.accumulated.max(1) as f64;
        let sum: DVec3 = self.direct_sum.iter().zip(&self.indirect).map(|(d, i)| *d / k + i.as_dvec3()).sum();
        (sum / self.direct_sum.len().max(1) as f64).as_vec3()
    }
}

/// The DDGI field set a render's settings ask for.
fn make_field_set(gi: &GiMethod, scene: &Scene, camera_m: Vec3) -> Option<DdgiFieldSet> {
    let bounds = scene.bounds().unwrap_or((Vec3::splat(-1.0), Vec3::ONE));
    match gi {
        GiMethod::Ddgi(s) => {
            Some(DdgiFieldSet::new(&DdgiFieldSetSettings::single((**s).clone()), bounds, Some(camera_m)))
        }
        GiMethod::DdgiSet(s) => Some(DdgiFieldSet::new(s, bounds, Some(camera_m))),
        _ => None,
    }
}

/// Renders `settings.frames` frames and returns the final image. After each frame
/// `on_frame_done(f, image)` is called; `image()` composes that frame's image
/// (for `--sequence`), at a cost only when called.
///
/// An animated scene (`Scene::is_animated`) is set to each frame's state before
/// the frame, and its direct term is that frame's alone (no accumulation), as is a
/// moving camera's (`settings.camera_path`). Scene changes reach the DDGI set
/// through `scene_events::SceneChangeDetector` (light toggles, object jumps,
/// probes woken around movers). Moving objects are placed by `tracer.at_frame`
/// (pass `instances`). Tracking windows follow the frame's camera.
pub fn render_frames(
    base_scene: &Scene,
    tracer: &dyn RayTracer,
    camera: &CameraRays,
    settings: &RenderSettings,
    mut on_frame_done: impl FnMut(u32, &dyn Fn() -> Image),
) -> RenderOutput {
    let animated = base_scene.is_animated();
    let moving_camera = settings.camera_path.len() > 1;
    let camera_at = |f: u32| settings.camera_path.get(f as usize).or(settings.camera_path.last()).unwrap_or(camera);
    let mut frame_scene = animated.then(|| base_scene.clone());
    let static_direct = DirectLighting::new(base_scene, tracer, settings.direct);
    let mut field = make_field_set(&settings.gi, base_scene, camera_at(0).origin_world);
    let mut sh = match &settings.gi {
        GiMethod::Sh(s) => Some(ShProbes::new((**s).clone(), base_scene, camera_at(0).origin_world)),
        _ => None,
    };
    // The field carries the sky under DDGI (see `probe_shade`); SH probes carry
    // emitters and sky with light injection; direct-only renders sample both.
    let camera_direct = match (&field, &sh) {
        (Some(_), _) => DirectSettings { direct_sky_samples: 0, ..settings.direct },
        (_, Some(p)) => p.camera_direct_settings(settings.direct),
        _ => settings.direct,
    };
    let mut acc = Accumulation::new(settings.width as usize * settings.height as usize);
    let mut stats = RenderStats::default();
    let mut pass_totals: BTreeMap<&'static str, f64> = BTreeMap::new();
    let frames = settings.frames.max(1);
    let mut last_gbuffer: Option<GBuffer> = None;
    let mut detector = SceneChangeDetector::new();
    for f in 0..frames {
        let camera = camera_at(f);
        if let Some(fs) = frame_scene.as_mut() {
            fs.set_frame_from(base_scene, f as f32);
        }
        let scene: &Scene = frame_scene.as_ref().unwrap_or(base_scene);
        if let (true, Some(h)) = (animated, &settings.probe_tracer)
            && let Err(e) = h.0.pose_scene(scene, f as f32)
        {
            stats.error = Some(format!("frame {f}: posing the scene on the device: {e}"));
            break;
        }
        // Moving geometry: place the instances for this frame (TLAS rebuild).
        let t = Instant::now();
        let frame_tracer = if animated { tracer.at_frame(scene, f as f32) } else { None };
        let tracer: &dyn RayTracer = frame_tracer.as_deref().unwrap_or(tracer);
        if animated {
            *pass_totals.entry("instances").or_default() += t.elapsed().as_secs_f64() * 1e3;
        }
        let frame_direct_lighting = animated.then(|| static_direct.for_frame(scene, tracer));
        let direct = frame_direct_lighting.as_ref().unwrap_or(&static_direct);
        if let Some(set) = field.as_mut() {
            stats.probes_scrolled_in += set.set_tracking_target(camera.origin_world) as u64;
            if animated {
                stats.probes_woken += detector.observe(scene, set).probes_woken as u64;
            }
            let batch_tracer = settings.probe_tracer.as_ref().map(|h| &*h.0);
            match set.update_traced_by(scene, tracer, batch_tracer, direct, settings.seed, f, &mut pass_totals) {
                Ok(rays) => stats.rays_traced += rays,
                Err(e) => {
                    stats.error = Some(format!("frame {f}: probe trace: {e}"));
                    break;
                }
            }
        }

        // The camera frame on another device, where the backend renders it
        // (`show_probes` draws on the CPU's G-buffer, so it keeps the CPU camera).
        if let (Some(h), Some(set), false) = (&settings.probe_tracer, field.as_ref(), settings.show_probes) {
            let t = Instant::now();
            let second_order = set.volumes().iter().any(|v| v.settings.glossy_second_order);
            let view = set.view();
            let on_device = h.0.camera_frame(
                camera,
                &view,
                set.field_on_device(),
                camera_direct.direct_area_samples,
                second_order,
                f,
                settings.seed,
                &mut acc.frame_direct,
                &mut acc.indirect,
            );
            drop(view);
            match on_device {
                Some(Ok((surfaces, unlit))) => {
                    // Primary rays; the device's shadow and glossy rays are not counted.
                    stats.rays_traced += settings.width as u64 * settings.height as u64;
                    stats.frame_unlit_fraction.push(unlit as f32 / surfaces.max(1) as f32);
                    let camera_moved = moving_camera && f > 0 && camera_at(f - 1) != camera;
                    acc.add_frame(animated || camera_moved);
                    acc.check_black(f, scene, surfaces, &mut stats);
                    *pass_totals.entry("camera").or_default() += t.elapsed().as_secs_f64() * 1e3;
                    acc.finish_frame(f, settings, &mut stats, &mut on_frame_done);
                    continue;
                }
                Some(Err(e)) => {
                    stats.error = Some(format!("frame {f}: camera frame: {e}"));
                    break;
                }
                None => {}
            }
        }

        let t = Instant::now();
        let (gbuffer, rays) = trace_gbuffer(scene, tracer, camera, settings.width, settings.height, f, settings.seed);
        *pass_totals.entry("gbuffer").or_default() += t.elapsed().as_secs_f64() * 1e3;
        stats.rays_traced += rays;

        if let Some(p) = sh.as_mut() {
            p.recentre(camera.origin_world, camera.forward_world());
        }
        // The CPU camera reads the field's atlases on the host.
        if let Some(set) = field.as_mut()
            && let Err(e) = set.sync_host_atlases(settings.probe_tracer.as_ref().map(|h| &*h.0))
        {
            stats.error = Some(format!("frame {f}: reading the field back: {e}"));
            break;
        }
        let indirect_field = match (&field, &sh) {
            (Some(set), _) => Some(IndirectField::Ddgi(set.view())),
            (_, Some(p)) => Some(IndirectField::Sh(&p.cascades)),
            _ => None,
        };
        let indirect_field_used = indirect_field.is_some();
        let second_order = field.as_ref().is_some_and(|s| s.volumes().iter().any(|v| v.settings.glossy_second_order));
        let t = Instant::now();
        let passes = CameraPasses { scene, tracer, direct, direct_settings: camera_direct, second_order };
        let nonfinite = std::sync::atomic::AtomicU64::new(0);
        let (rays, surfaces, unlit) =
            shade_camera(&passes, indirect_field, &gbuffer, f, settings.seed, &mut acc, &nonfinite);
        stats.nonfinite_pixels += nonfinite.into_inner();
        stats.rays_traced += rays;
        if indirect_field_used {
            stats.frame_unlit_fraction.push(unlit as f32 / surfaces.max(1) as f32);
        }
        // The direct term restarts when the scene or the camera changed since the
        // last frame (a camera that holds at its last key accumulates again).
        let camera_moved = moving_camera && f > 0 && camera_at(f - 1) != camera;
        acc.add_frame(animated || camera_moved);
        acc.check_black(f, scene, surfaces, &mut stats);

        *pass_totals.entry("camera").or_default() += t.elapsed().as_secs_f64() * 1e3;
        if let Some(p) = sh.as_mut() {
            stats.rays_traced +=
                p.update(scene, tracer, direct, settings.direct, camera, &gbuffer, settings.seed, f, &mut pass_totals);
        }
        last_gbuffer = Some(gbuffer);
        acc.finish_frame(f, settings, &mut stats, &mut on_frame_done);
    }
    // The field as the render leaves it, on the host (a device may hold it).
    if let Some(set) = field.as_mut()
        && let Err(e) = set.sync_host_atlases(settings.probe_tracer.as_ref().map(|h| &*h.0))
    {
        stats.error.get_or_insert(format!("reading the field back after the last frame: {e}"));
    }
    // Frames that completed (all of them unless a backend failed).
    let frames = stats.frame_means.len().max(1) as u32;
    stats.frames = stats.frame_means.len() as u32;
    stats.pass_ms = pass_totals.into_iter().map(|(k, v)| (k, v / frames as f64)).collect();
    if let Some(set) = &field {
        field_stats(set, &mut stats);
    }
    if let Some(p) = &sh {
        stats.probes = Some(p.cascades.probe_count());
        stats.field_update_ms = Some(SH_UPDATE_PASSES.iter().filter_map(|k| stats.pass_ms.get(k)).sum());
    }
    let mut pixels = acc.pixels();
    if let (true, Some(set), Some(g)) = (settings.show_probes, &field, &last_gbuffer) {
        for v in set.volumes() {
            crate::probe_vis::draw_probes(v, camera_at(frames - 1), g, &mut pixels);
        }
    }
    let image = Image { width: settings.width, height: settings.height, pixels };
    RenderOutput { image, stats, ddgi: field, sh }
}

/// The DDGI figures of `--stats` after the last frame.
fn field_stats(set: &DdgiFieldSet, stats: &mut RenderStats) {
    let update_ms: f64 = FIELD_UPDATE_PASSES.iter().filter_map(|p| stats.pass_ms.get(p)).sum();
    stats.probes = Some(set.probe_count());
    stats.rays_per_frame = Some(set.rays_per_frame());
    stats.field_update_ms = Some(update_ms);
    stats.field_update_mrays_per_s = Some(set.rays_per_frame() as f64 / (update_ms * 1e-3) / 1e6);
    let mut states = BTreeMap::new();
    for v in set.volumes() {
        for (k, n) in v.state_counts() {
            *states.entry(k).or_default() += n;
        }
    }
    stats.probe_states = Some(states);
    stats.active_probes = Some(set.volumes().iter().map(|v| v.active_probe_count()).sum());
    stats.volumes = Some(set.volumes().len());
    stats.batch_rays = Some(set.last_batch_rays);
    stats.batch_rays_per_volume = Some(set.last_batch_rays_per_volume.clone());
}

/// Mean direct term over the accumulated frames plus the last frame's indirect term.
fn compose_pixels(direct_sum: &[DVec3], accumulated: u32, indirect: &[Vec3]) -> Vec<Vec3> {
    direct_sum.iter().zip(indirect).map(|(d, i)| (*d / accumulated.max(1) as f64).as_vec3() + *i).collect()
}

/// What the camera pass shades with.
struct CameraPasses<'a> {
    scene: &'a Scene,
    tracer: &'a dyn RayTracer,
    direct: &'a DirectLighting<'a>,
    direct_settings: DirectSettings,
    /// Second-order glossy from probes on glossy rays' hits.
    second_order: bool,
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
/// Pixels that see nothing get the sky. Returns rays traced and, for the
/// `frame_unlit_fraction` statistic, (surface pixels with a diffuse albedo, those
/// of them that got no indirect light). A pixel whose direct radiance comes out
/// non-finite is written as 0 and counted in `nonfinite` (never silently).
fn shade_camera(
    passes: &CameraPasses<'_>,
    field: Option<IndirectField<'_>>,
    gbuffer: &GBuffer,
    frame: u32,
    seed: u64,
    acc: &mut Accumulation,
    nonfinite: &std::sync::atomic::AtomicU64,
) -> (u64, usize, usize) {
    let CameraPasses { scene, tracer, direct, direct_settings, second_order } = *passes;
    let (direct_out, indirect_out) = (&mut acc.frame_direct, &mut acc.indirect);
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
            let (mut rays, mut surfaces, mut unlit) = (0u64, 0usize, 0usize);
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
                *d = if l.is_finite() {
                    l
                } else {
                    nonfinite.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    Vec3::ZERO
                };
                let albedo = ctx.bsdf.diffuse_albedo();
                let diffuse = albedo.max_element() > 0.0;
                surfaces += diffuse as usize;
                *i = match &field {
                    Some(f) => {
                        let e = f.irradiance(sp.position, sp.facing_normal(), texel.view_dir_world);
                        unlit += (diffuse && e.max_element() <= 0.0) as usize;
                        albedo * FRAC_1_PI * e
                    }
                    None => Vec3::ZERO,
                };
            }
            (rays, surfaces, unlit)
        })
        .reduce(|| (0, 0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2))
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
        out += crate::glossy::second_order_specular(field, sp, &ctx, ray_dir);
    }
    (out, rays)
}
