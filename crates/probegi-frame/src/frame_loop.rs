//! The per-frame loop of `probegi render`: passes in order, per-pass timings and
//! ray counts.
//!
//! Per frame, DDGI: the field update (`ray_gen`, `trace`, `shade`, `blend`,
//! `border`), then `gbuffer` (primary rays) and `camera` (shading each pixel).
//! SH probes (seed 001 §6.1): `gbuffer`, `camera` (the lighting pass reads the
//! probes), then the probe update from that frame (`sh_screen_samples`, `sh_update`).
//! The direct term (emission + direct light) of a static scene accumulates over
//! frames; the indirect term is the last frame's irradiance, so the image shows
//! the field as it stands after N updates, weighed by the diffuse albedo
//! accumulated with the direct term (antialiased; see `Accumulation`). A moving
//! camera reprojects both sums from the last frame (`accumulation`'s temporal filter).
//!
//! [`render_frames`] steps a [`FrameStepper`] (one frame at a time, each with
//! the camera its caller chooses: the viewer's fly camera) over the frames; the
//! stepper drives a private frame-loop type with one method per step of
//! ARCHITECTURE.md's per-frame data flow (pose, field update, camera image),
//! then composes the output; the `camera` pass itself is in `camera_pass`.

mod accumulation;
mod camera_pass;
mod device_resident;
mod frame_stepper;

use std::collections::{BTreeMap, VecDeque};
use std::ops::ControlFlow::{self, Break, Continue};
use std::time::Instant;

use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings};
use probegi_core::image::Image;
use probegi_scene::{RayTracer, Scene};

use crate::field_update::FieldSetUpdate;
use crate::scene_events::SceneChangeDetector;
pub use accumulation::TemporalSettings;
use accumulation::{Accumulation, History};
use camera_pass::{CameraPasses, IndirectField, shade_camera};
pub use frame_stepper::{FrameLayers, FrameStepper};
use probegi_cpu::direct::{DirectLighting, DirectSettings};
use probegi_cpu::gbuffer::{GBuffer, trace_gbuffer};
use probegi_cpu::sh_probes::{SH_UPDATE_PASSES, ShProbes};

use probegi_core::sh_settings::ShProbeSettings;
use probegi_field::CameraFrameOut;
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

/// What [`render_frames`] renders: image size, frames, seed, the GI method and
/// who traces. `Default` is the CLI's `probegi render` without options.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// Image width in pixels (default 512, the CLI's `--width`).
    pub width: u32,
    /// Image height in pixels (default 512, the CLI's `--height`).
    pub height: u32,
    /// Frames to run, at least one (default 1, the CLI's `--frames`): a static
    /// scene's direct term accumulates over them, the field updates once per frame.
    pub frames: u32,
    /// Random seed of every sampling stream (default 0, the CLI's `--seed`).
    pub seed: u64,
    /// Global illumination on top of direct light (default none, the CLI's `--gi`).
    pub gi: GiMethod,
    /// Direct-light sample counts (default [`DirectSettings::default`], as the
    /// CLI's); the camera pass leaves out what the field carries (the sky under DDGI).
    pub direct: DirectSettings,
    /// Draw DDGI probes as spheres in the final image (default off, the CLI's
    /// `--show-probes`).
    pub show_probes: bool,
    /// The camera of each frame (a keyframed flythrough); empty = the fixed camera
    /// passed to [`render_frames`] (the default). Frames past the end hold the last entry.
    pub camera_path: Vec<CameraRays>,
    /// Who traces the DDGI probe ray batches: `None` for the CPU tracer (the
    /// default), or a [`probegi_field::ProbeBatchTracer`] (the CLI's `--backend wgpu`).
    pub probe_tracer: Option<probegi_field::ProbeTracerHandle>,
    /// The temporal filter of a moving camera (default [`TemporalSettings::default`],
    /// the CLI's `--temporal-frames` and `--temporal-clip-sigma`).
    pub temporal: TemporalSettings,
    /// Where a `probe_tracer` keeps the camera frame on its device
    /// ([`probegi_field::DeviceFrame`]): how many frames late its statistics
    /// (means, unlit and non-finite counts, the screen scheme's requests) may
    /// come back. 0 (the default, `probegi render`) waits for each frame's, so
    /// that the bookkeeping is the CPU's frame for frame; the viewer takes 2
    /// and never waits while the device keeps up.
    pub device_readback_lag_frames: u32,
}

impl Default for RenderSettings {
    /// The CLI's `probegi render` defaults: one 512 × 512 frame at seed 0,
    /// direct light only, traced on the CPU.
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            frames: 1,
            seed: 0,
            gi: GiMethod::None,
            direct: DirectSettings::default(),
            show_probes: false,
            camera_path: Vec::new(),
            probe_tracer: None,
            temporal: TemporalSettings::default(),
            device_readback_lag_frames: 0,
        }
    }
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
    /// DDGI and SH: the field's probes.
    pub probes: Option<usize>,
    /// DDGI only: probe rays per frame.
    pub rays_per_frame: Option<u64>,
    /// DDGI only: probe rays over every frame's field update (initialisation
    /// rounds included); over `frames`, the mean a scheme that varies its
    /// rays per frame (screen states, a budget) traced.
    pub probe_rays_traced: u64,
    /// Mean milliseconds per frame of the field update: DDGI's four update passes
    /// plus border ([`FIELD_UPDATE_PASSES`]), SH's `SH_UPDATE_PASSES`.
    pub field_update_ms: Option<f64>,
    /// DDGI only: millions of probe rays per second over the field update.
    pub field_update_mrays_per_s: Option<f64>,
    /// DDGI only: probes per state name after the last frame.
    pub probe_states: Option<BTreeMap<&'static str, usize>>,
    /// DDGI only: probes that traced and blended in the last frame.
    pub active_probes: Option<usize>,
    /// DDGI with moving objects: Sleeping probes woken around them, summed over frames.
    pub probes_woken: u64,
    /// DDGI: volumes in the set.
    pub volumes: Option<usize>,
    /// DDGI: rays of the last frame's batch (all volumes, one trace).
    pub batch_rays: Option<u64>,
    /// DDGI: the last frame's batch rays, per volume.
    pub batch_rays_per_volume: Option<Vec<u64>>,
    /// DDGI: probes scrolled into tracking windows, summed over frames.
    pub probes_scrolled_in: u64,
    /// Per frame: the mean of that frame's image (what `--sequence` writes).
    pub frame_means: Vec<Vec3>,
    /// Per frame: the mean of its indirect (field) term alone.
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

/// What [`render_frames`] returns: the image, its measurements and the field
/// as the last frame left it.
pub struct RenderOutput {
    /// The final image: the mean direct term over the accumulated frames plus the
    /// last frame's irradiance × the mean diffuse albedo (with `show_probes`, the
    /// probes drawn on it).
    pub image: Image,
    /// Measurements of the render.
    pub stats: RenderStats,
    /// The DDGI volumes after the last update (for atlas dumps).
    pub ddgi: Option<DdgiFieldSet>,
    /// The SH probes after the last update.
    pub sh: Option<ShProbes>,
}

/// Names of the passes that make up a DDGI field update (`shadow_blend`: the
/// shadowing field's occlusion blend, where a volume keeps one).
pub const FIELD_UPDATE_PASSES: [&str; 6] = ["ray_gen", "trace", "shade", "blend", "border", "shadow_blend"];

/// A caller's edit of the posed scene, each frame: `(base, posed)` (see
/// [`FrameStepper::set_scene_edit`]).
pub type SceneEdit<'a> = Box<dyn Fn(&Scene, &mut Scene) + 'a>;

impl Accumulation {
    /// Records frame `f`'s means and hands its image to the caller.
    fn finish_frame(
        &self,
        f: u32,
        settings: &RenderSettings,
        stats: &mut RenderStats,
        on_frame_done: &mut impl FnMut(u32, &dyn Fn() -> Image),
    ) {
        let compose = || Image { width: settings.width, height: settings.height, pixels: self.pixels() };
        let (mean, indirect_mean) = self.means();
        stats.frame_means.push(mean);
        stats.frame_indirect_means.push(indirect_mean);
        on_frame_done(f, &compose);
    }

    /// Notes frame `f` in `stats.black_frames` when its image is all black
    /// although `scene` has light sources and `surfaces` pixels see a surface.
    fn check_black(&self, f: u32, scene: &Scene, surfaces: usize, stats: &mut RenderStats) {
        if surfaces > 0 && self.means().0 == Vec3::ZERO && scene.has_light_sources() {
            stats.black_frames.push(f);
        }
    }
}

/// The camera of frame `f`: its entry of `settings.camera_path`, the path's last
/// past its end, or the fixed `camera` when there is no path.
fn frame_camera<'c>(settings: &'c RenderSettings, camera: &'c CameraRays, f: u32) -> &'c CameraRays {
    settings.camera_path.get(f as usize).or(settings.camera_path.last()).unwrap_or(camera)
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
/// the frame, and its direct term is that frame's alone (no accumulation); a
/// moving camera's (`settings.camera_path`) is reprojected from the frames
/// before (`settings.temporal`, see `accumulation`). Scene changes reach the DDGI set
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
    let mut stepper = FrameStepper::new(base_scene, tracer, camera, settings);
    for f in 0..settings.frames.max(1) {
        if stepper.step_with(frame_camera(settings, camera, f), &mut on_frame_done).is_break() {
            break;
        }
    }
    stepper.finish()
}

/// What one frame's passes read: the frame, the scene posed at it, the tracer
/// that places its moving objects, its direct lighting and its camera.
struct Frame<'f> {
    index: u32,
    scene: &'f Scene,
    tracer: &'f dyn RayTracer,
    direct: &'f FrameDirect<'f>,
    camera: &'f CameraRays,
}

/// A frame's direct lighting for the passes the CPU runs, built on first use
/// (an animated scene's lights move): a frame whose field update and camera
/// frame stay on a device never builds it.
struct FrameDirect<'f> {
    base: &'f DirectLighting<'f>,
    posed: &'f std::cell::OnceCell<DirectLighting<'f>>,
    animated: bool,
    scene: &'f Scene,
    tracer: &'f dyn RayTracer,
}

impl<'f> FrameDirect<'f> {
    /// The frame's lighting: the base scene's, or that of the frame's pose.
    fn get(&self) -> &DirectLighting<'f> {
        if !self.animated {
            return self.base;
        }
        self.posed.get_or_init(|| self.base.for_frame(self.scene, self.tracer))
    }
}

/// [`render_frames`] between frames: the settings, the field (DDGI set or SH
/// probes), the running sums of the image and the statistics. One method per
/// step of a frame as ARCHITECTURE.md's per-frame data flow reads: [`Self::pose`],
/// [`Self::update_field`], [`Self::camera_image`]; then [`Self::finish`].
struct FrameLoop<'a> {
    base_scene: &'a Scene,
    /// The fixed camera (frames without a path entry), owned so a viewer can
    /// keep the stepper while it rebuilds its own.
    camera: CameraRays,
    /// The render's settings, owned so a viewer can resize the frame
    /// ([`FrameStepper::set_size`]).
    settings: RenderSettings,
    /// The scene is posed every frame: it is animated, or a caller edits it
    /// ([`FrameStepper::set_scene_edit`]).
    animated: bool,
    /// The scene moves on its own (`Scene::is_animated`): the direct term
    /// restarts every frame.
    self_animated: bool,
    /// A caller's edit of each posed frame (a viewer's light switches), and
    /// whether it changed since the last frame (the direct term restarts once).
    scene_edit: Option<SceneEdit<'a>>,
    scene_edit_changed: bool,
    /// The scene clock a caller holds (a paused viewer); `None`: the frame index.
    scene_frame: Option<u32>,
    field: Option<DdgiFieldSet>,
    sh: Option<ShProbes>,
    /// The camera pass's direct-light settings (see [`FrameLoop::new`]).
    camera_direct: DirectSettings,
    acc: Accumulation,
    stats: RenderStats,
    pass_totals: BTreeMap<&'static str, f64>,
    last_gbuffer: Option<GBuffer>,
    detector: SceneChangeDetector,
    /// The camera of the last frame rendered (a different one restarts the direct term).
    prev_camera: Option<CameraRays>,
    /// The frames a device kept the camera frame of (`device_frame`) whose
    /// statistics have not come back yet: (frame, the scene had light sources).
    device_pending: VecDeque<(u32, bool)>,
    /// The last frame's image lives on the device, not in `acc`.
    device_image: bool,
}

impl<'a> FrameLoop<'a> {
    /// The field the settings ask for, placed around the first frame's camera.
    fn new(base_scene: &'a Scene, camera: &CameraRays, settings: &RenderSettings) -> Self {
        let animated = base_scene.is_animated();
        let field = make_field_set(&settings.gi, base_scene, frame_camera(settings, camera, 0).origin_world);
        let sh = match &settings.gi {
            GiMethod::Sh(s) => {
                Some(ShProbes::new((**s).clone(), base_scene, frame_camera(settings, camera, 0).origin_world))
            }
            _ => None,
        };
        // The field carries a constant sky under DDGI (see `probe_shade`), and
        // the camera samples a sky map (`Scene::sky_on_probe_miss`) unless the
        // field carries that too; SH probes
        // carry emitters and sky with light injection; direct-only renders
        // sample both.
        // A field whose misses read the map (`probe_sky_map_on_miss`) carries
        // its light: the camera then takes no sky samples either.
        let map_in_field = |f: &DdgiFieldSet| f.volumes().iter().any(|v| v.settings.probe_sky_map_on_miss);
        let camera_direct = match (&field, &sh) {
            (Some(f), _) if base_scene.sky_map.is_some() && !map_in_field(f) => settings.direct,
            (Some(_), _) => DirectSettings { direct_sky_samples: 0, ..settings.direct },
            (_, Some(p)) => p.camera_direct_settings(settings.direct),
            _ => settings.direct,
        };
        Self {
            base_scene,
            camera: *camera,
            settings: settings.clone(),
            animated,
            self_animated: animated,
            scene_edit: None,
            scene_edit_changed: false,
            scene_frame: None,
            field,
            sh,
            camera_direct,
            acc: Accumulation::new(settings.width, settings.height),
            stats: RenderStats::default(),
            pass_totals: BTreeMap::new(),
            last_gbuffer: None,
            detector: SceneChangeDetector::new(),
            prev_camera: None,
            device_pending: VecDeque::new(),
            device_image: false,
        }
    }

    /// The camera of frame `f` (see [`frame_camera`]).
    fn camera_at(&self, f: u32) -> &CameraRays {
        frame_camera(&self.settings, &self.camera, f)
    }

    /// Poses an animated scene at frame `f` (`frame_scene`, and on the device)
    /// and places its moving objects for the frame (TLAS rebuild): the frame's
    /// scene and, when `tracer` places them, the frame's tracer. `Break` when the
    /// device could not pose the scene.
    #[allow(clippy::type_complexity)]
    fn pose<'s>(
        &mut self,
        tracer: &'s dyn RayTracer,
        frame_scene: &'s mut Option<Scene>,
        f: u32,
    ) -> ControlFlow<(), (&'s Scene, Option<Box<dyn RayTracer + 's>>)>
    where
        'a: 's,
    {
        let animated = self.animated;
        let f = self.scene_frame.unwrap_or(f);
        if let Some(fs) = frame_scene.as_mut() {
            fs.set_frame_from(self.base_scene, f as f32);
            if let Some(edit) = &self.scene_edit {
                // Posing does not carry the constant sky (a sky map it poses);
                // an edit starts from the base's.
                fs.sky_radiance = self.base_scene.sky_radiance;
                edit(self.base_scene, fs);
            }
        }
        let scene: &Scene = frame_scene.as_ref().unwrap_or(self.base_scene);
        if let (true, Some(h)) = (animated, &self.settings.probe_tracer)
            && let Err(e) = h.0.pose_scene(scene, f as f32)
        {
            self.stats.error = Some(format!("frame {f}: posing the scene on the device: {e}"));
            return Break(());
        }
        // Moving geometry: place the instances for this frame (TLAS rebuild).
        let t = Instant::now();
        let frame_tracer = if animated { tracer.at_frame(scene, f as f32) } else { None };
        if animated {
            *self.pass_totals.entry("instances").or_default() += t.elapsed().as_secs_f64() * 1e3;
        }
        Continue((scene, frame_tracer))
    }

    /// The DDGI field update of the frame (`--gi ddgi`): tracking windows follow
    /// the camera, scene changes reach the set, then one update through the seam.
    /// `Break` when the probe trace failed.
    fn update_field(&mut self, frame: &Frame<'_>) -> ControlFlow<()> {
        let (f, settings) = (frame.index, &self.settings);
        if let Some(set) = self.field.as_mut() {
            self.stats.probes_scrolled_in += set.set_tracking_target(frame.camera.origin_world) as u64;
            if self.animated {
                self.stats.probes_woken += self.detector.observe(frame.scene, set).probes_woken as u64;
            }
            let batch_tracer = settings.probe_tracer.as_ref().map(|h| &*h.0);
            let (scene, tracer, pass_totals) = (frame.scene, frame.tracer, &mut self.pass_totals);
            // A device that keeps the field shades there: no CPU lighting.
            let updated = match batch_tracer.filter(|bt| bt.device_field().is_some()) {
                Some(device) => set.update_on_device(scene, tracer, device, settings.seed, f, pass_totals),
                None => {
                    set.update_traced_by(scene, tracer, batch_tracer, frame.direct.get(), settings.seed, f, pass_totals)
                }
            };
            match updated {
                Ok(rays) => {
                    self.stats.rays_traced += rays;
                    self.stats.probe_rays_traced += rays;
                }
                Err(e) => {
                    self.stats.error = Some(format!("frame {f}: probe trace: {e}"));
                    return Break(());
                }
            }
        }
        Continue(())
    }

    /// The frame's camera image, on the device where the backend renders it,
    /// else on the CPU; the frame then goes to `on_frame_done`. `Break` when a
    /// backend failed.
    fn camera_image(
        &mut self,
        frame: &Frame<'_>,
        on_frame_done: &mut impl FnMut(u32, &dyn Fn() -> Image),
    ) -> ControlFlow<()> {
        match self.camera_image_on_device(frame, on_frame_done) {
            Some(done) => done,
            None => self.camera_image_on_cpu(frame, on_frame_done),
        }
    }

    /// The camera frame on another device, where the backend renders it
    /// (`show_probes` draws on the CPU's G-buffer, so it keeps the CPU camera):
    /// `None` when the CPU renders it.
    fn camera_image_on_device(
        &mut self,
        frame: &Frame<'_>,
        on_frame_done: &mut impl FnMut(u32, &dyn Fn() -> Image),
    ) -> Option<ControlFlow<()>> {
        let (f, camera, settings) = (frame.index, frame.camera, &self.settings);
        let (Some(h), Some(set), false) = (&settings.probe_tracer, self.field.as_ref(), settings.show_probes) else {
            return None;
        };
        if h.0.device_frame().is_some() {
            let handle = h.clone();
            let df = handle.0.device_frame()?;
            return Some(self.camera_image_kept_on_device(df, frame, on_frame_done));
        }
        self.device_image = false;
        let t = Instant::now();
        let second_order = set.volumes().iter().any(|v| v.settings.glossy_second_order);
        let view = set.view();
        let mut requests = set.wants_probe_requests().then(|| {
            let total = set.probe_request_layout().last().copied().unwrap_or(0);
            vec![0u32; total.div_ceil(32)]
        });
        let on_device = h.0.camera_frame(
            camera,
            &view,
            set.field_on_device(),
            self.camera_direct.direct_area_samples,
            self.camera_direct.direct_sky_samples,
            second_order,
            f,
            settings.seed,
            CameraFrameOut {
                direct: &mut self.acc.frame_direct,
                irradiance_over_pi: &mut self.acc.frame_irradiance,
                albedo: &mut self.acc.frame_albedo,
                position_m: &mut self.acc.frame_position_m,
                normal: &mut self.acc.frame_normal,
            },
            requests.as_mut(),
        );
        drop(view);
        if let (Some(Ok(_)), Some(words), Some(set)) = (&on_device, &requests, self.field.as_mut()) {
            // Sized from this set's layout above, so the length holds.
            let _ = set.submit_probe_requests(words);
        }
        match on_device {
            Some(Ok((surfaces, unlit))) => {
                // Primary rays; the device's shadow and glossy rays are not counted.
                self.stats.rays_traced += settings.width as u64 * settings.height as u64;
                self.stats.frame_unlit_fraction.push(unlit as f32 / surfaces.max(1) as f32);
                self.acc.add_frame(frame.camera, self.history(frame));
                self.acc.check_black(f, frame.scene, surfaces, &mut self.stats);
                *self.pass_totals.entry("camera").or_default() += t.elapsed().as_secs_f64() * 1e3;
                self.acc.finish_frame(f, settings, &mut self.stats, on_frame_done);
                Some(Continue(()))
            }
            Some(Err(e)) => {
                self.stats.error = Some(format!("frame {f}: camera frame: {e}"));
                Some(Break(()))
            }
            None => None,
        }
    }

    /// The camera image on the CPU: `gbuffer`, then `camera` (reading the DDGI
    /// set or the SH probes); with SH probes their update from this frame.
    /// `Break` when the field could not be read back from a device.
    fn camera_image_on_cpu(
        &mut self,
        frame: &Frame<'_>,
        on_frame_done: &mut impl FnMut(u32, &dyn Fn() -> Image),
    ) -> ControlFlow<()> {
        let Frame { index: f, scene, tracer, camera, .. } = *frame;
        let direct = frame.direct.get();
        self.device_image = false;
        let settings = &self.settings;
        let t = Instant::now();
        let (gbuffer, rays) = trace_gbuffer(scene, tracer, camera, settings.width, settings.height, f, settings.seed);
        *self.pass_totals.entry("gbuffer").or_default() += t.elapsed().as_secs_f64() * 1e3;
        self.stats.rays_traced += rays;
        let hits = self.acc.frame_position_m.iter_mut().zip(self.acc.frame_normal.iter_mut());
        for ((x, n), texel) in hits.zip(&gbuffer.texels) {
            let sp = texel.surface.as_ref();
            *x = sp.map_or(Vec3::ZERO, |sp| sp.position);
            *n = sp.map_or(Vec3::ZERO, |sp| sp.facing_geometric_normal());
        }

        if let Some(p) = self.sh.as_mut() {
            p.recentre(camera.origin_world, camera.forward_world());
        }
        // The CPU camera reads the field's atlases on the host.
        if let Some(set) = self.field.as_mut()
            && let Err(e) = set.sync_host_atlases(settings.probe_tracer.as_ref().map(|h| &*h.0))
        {
            self.stats.error = Some(format!("frame {f}: reading the field back: {e}"));
            return Break(());
        }
        let indirect_field = match (&self.field, &self.sh) {
            (Some(set), _) => Some(IndirectField::Ddgi(set.view())),
            (_, Some(p)) => Some(IndirectField::Sh(&p.cascades)),
            _ => None,
        };
        let indirect_field_used = indirect_field.is_some();
        let second_order =
            self.field.as_ref().is_some_and(|s| s.volumes().iter().any(|v| v.settings.glossy_second_order));
        let t = Instant::now();
        let shadow_field = self.field.as_ref().filter(|s| s.has_shadow_field());
        let passes =
            CameraPasses { scene, tracer, direct, direct_settings: self.camera_direct, second_order, shadow_field };
        let nonfinite = std::sync::atomic::AtomicU64::new(0);
        let (rays, surfaces, unlit) =
            shade_camera(&passes, indirect_field, &gbuffer, f, settings.seed, &mut self.acc, &nonfinite);
        self.stats.nonfinite_pixels += nonfinite.into_inner();
        self.stats.rays_traced += rays;
        if indirect_field_used {
            self.stats.frame_unlit_fraction.push(unlit as f32 / surfaces.max(1) as f32);
        }
        self.acc.add_frame(frame.camera, self.history(frame));
        self.acc.check_black(f, scene, surfaces, &mut self.stats);

        *self.pass_totals.entry("camera").or_default() += t.elapsed().as_secs_f64() * 1e3;
        if let Some(p) = self.sh.as_mut() {
            self.stats.rays_traced += p.update(
                scene,
                tracer,
                direct,
                settings.direct,
                camera,
                &gbuffer,
                settings.seed,
                f,
                &mut self.pass_totals,
            );
        }
        request_probes(self.field.as_mut(), &gbuffer, &mut self.pass_totals);
        self.last_gbuffer = Some(gbuffer);
        self.acc.finish_frame(f, settings, &mut self.stats, on_frame_done);
        Continue(())
    }

    /// What this frame does to the image's sums: a changed scene starts them
    /// again, a moved camera reprojects them, a still one (or one that holds at
    /// its last key) adds to them.
    fn history(&self, frame: &Frame<'_>) -> History {
        if self.self_animated || self.scene_edit_changed {
            return History::Restart;
        }
        match &self.prev_camera {
            Some(from) if from != frame.camera => History::Reproject { from: *from, settings: self.settings.temporal },
            _ => History::Accumulate,
        }
    }

    /// After the last frame: the field back on the host, the statistics, the
    /// composed image (with `show_probes`, the probes drawn on it).
    fn finish(mut self) -> RenderOutput {
        self.drain_device_readouts();
        let device_image = self.device_layer(probegi_field::FrameLayer::Full);
        let settings = &self.settings;
        // The field as the render leaves it, on the host (a device may hold it).
        if let Some(set) = self.field.as_mut()
            && let Err(e) = set.sync_host_atlases(settings.probe_tracer.as_ref().map(|h| &*h.0))
        {
            self.stats.error.get_or_insert(format!("reading the field back after the last frame: {e}"));
        }
        // Frames that completed (all of them unless a backend failed).
        let frames = self.stats.frame_means.len().max(1) as u32;
        let last_camera = self.prev_camera.unwrap_or(*self.camera_at(0));
        let FrameLoop { field, sh, acc, mut stats, pass_totals, last_gbuffer, .. } = self;
        stats.frames = stats.frame_means.len() as u32;
        stats.pass_ms = pass_totals.into_iter().map(|(k, v)| (k, v / frames as f64)).collect();
        if let Some(set) = &field {
            field_stats(set, &mut stats);
        }
        if let Some(p) = &sh {
            stats.probes = Some(p.cascades.probe_count());
            stats.field_update_ms = Some(SH_UPDATE_PASSES.iter().filter_map(|k| stats.pass_ms.get(k)).sum());
        }
        let mut pixels = match device_image {
            Some(Ok(image)) => image.pixels,
            Some(Err(e)) => {
                stats.error.get_or_insert(e);
                vec![Vec3::ZERO; acc.len()]
            }
            None => acc.pixels(),
        };
        if let (true, Some(set), Some(g)) = (settings.show_probes, &field, &last_gbuffer) {
            for v in set.volumes() {
                probegi_cpu::probe_vis::draw_probes(v, &last_camera, g, &mut pixels);
            }
        }
        let image = Image { width: settings.width, height: settings.height, pixels };
        RenderOutput { image, stats, ddgi: field, sh }
    }
}

/// The screen scheme's requests (`ProbeStatesMode::Screen`): the probes
/// whose cages the frame's surface pixels read, for the next update. Timed
/// under `probe_requests`.
fn request_probes(field: Option<&mut DdgiFieldSet>, gbuffer: &GBuffer, pass_totals: &mut BTreeMap<&'static str, f64>) {
    let Some(set) = field.filter(|s| s.wants_probe_requests()) else {
        return;
    };
    let t = Instant::now();
    let points: Vec<(Vec3, Vec3, Vec3)> = gbuffer
        .texels
        .iter()
        .filter_map(|t| t.surface.as_ref().map(|sp| (sp.position, sp.facing_normal(), t.view_dir_world)))
        .collect();
    set.request_probes_at(&points);
    *pass_totals.entry("probe_requests").or_default() += t.elapsed().as_secs_f64() * 1e3;
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
