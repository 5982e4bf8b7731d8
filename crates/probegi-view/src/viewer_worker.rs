//! The frame worker of `probegi view`: a thread that owns the scene, the
//! tracer and the [`ViewSession`], renders frame after frame, and hands each
//! one to the window. The window keeps its own rate whatever a frame costs
//! (a field update slower than a UI frame never stalls the UI); the worker
//! takes the input and the panels' controls between two frames.
//!
//! It also runs what the panels ask of it: the path-traced reference of the
//! current view on a thread beside the frames (progress, then the reference
//! beside the live frame with its FLIP heat map), screenshots (PNG and linear
//! EXR named after the scene and frame), scene reload when the scene file
//! changes, and on the CPU backend an adaptive frame size.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::{Instant, SystemTime};

use probegi_core::camera::{Camera, CameraRays};
use probegi_core::image::Image;
use probegi_cpu::{PathTracer, PathTracerSettings};
use probegi_frame::frame_loop::RenderSettings;
use probegi_scene::{RayTracer, Scene};

use crate::input_script::{InputScript, ScriptEvent, ViewerKey};
use crate::view_layers::{ViewMode, to_rgba8, view_image};
use crate::view_session::{ViewCarry, ViewSession};
use crate::viewer_controls::{GiChoice, ViewerControls};

/// The image a frame report carries: RGBA8 from the host, or a texture on
/// the window's device.
enum FrameImage {
    Rgba(Vec<u8>),
    Texture(wgpu::Texture, u64),
}

/// What a session is built from: what the CLI's scene setup makes of its
/// arguments and the panels' controls.
pub struct SessionParts {
    /// The scene as loaded (unposed).
    pub scene: Scene,
    /// Its ray tracer.
    pub tracer: Box<dyn RayTracer>,
    /// The fly camera's start.
    pub camera: Camera,
    /// The render settings (size, seed, GI, probe tracer).
    pub settings: RenderSettings,
    /// A keyframed camera's path, one per frame (may be empty).
    pub camera_path: Vec<Camera>,
    /// The fly camera's speed, metres per second.
    pub fly_speed_m_per_s: f32,
    /// The GPU adapter's name (`None`: the CPU backend).
    pub adapter: Option<String>,
    /// The GI method and cascade count the settings were built with.
    pub gi: GiChoice,
    /// Camera-centred cascades (0: the scene's volumes).
    pub cascades: u32,
    /// Where the frame stays on a device the window shares
    /// ([`SharedDevice`]): the last frame's layer, tone-mapped, as a texture
    /// on that device, which the window draws with no pixel crossing to the host.
    pub presenter: Option<FramePresenter>,
}

/// A session's way to the frame a shared device keeps ([`SessionParts::presenter`]).
pub type FramePresenter = Box<dyn Fn(probegi_field::FrameLayer) -> Result<wgpu::Texture, String> + Send + Sync>;

/// The window's device, shared with the field's (`probegi view`'s one device):
/// what egui-wgpu draws with and what a session's GPU passes run on.
#[derive(Clone, Debug)]
pub struct SharedDevice {
    /// The instance the adapter came from.
    pub instance: wgpu::Instance,
    /// The adapter.
    pub adapter: wgpu::Adapter,
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter's name and driver, as `GpuContext::adapter_name` spells it.
    pub adapter_name: String,
}

/// Builds sessions: the CLI's scene setup.
pub trait ViewSource: Send {
    /// A session for `controls` (`None`: as the command line says). An error
    /// names the file and the place.
    /// With `device`, GPU work runs on the window's own device.
    fn load(&self, controls: Option<&ViewerControls>, device: Option<&SharedDevice>) -> Result<SessionParts, String>;
    /// The scene file to watch for changes (`None`: a built-in scene).
    fn watched_file(&self) -> Option<PathBuf>;
}

/// What the window asks of the worker.
#[derive(Clone, Debug)]
pub enum WorkerCommand {
    /// A key, mouse or scroll event for the fly camera.
    Input(ScriptEvent),
    /// The panels' controls changed.
    Controls(ViewerControls),
    /// While paused: advance the scene clock by one frame.
    StepClock,
    /// Path-trace the current view at this many samples per pixel.
    Reference(u32),
    /// Write the current frame as PNG and EXR.
    Screenshot,
    /// Load the scene anew.
    Reload,
    /// Stop.
    Quit,
}

/// How the worker runs.
#[derive(Clone, Debug, Default)]
pub struct WorkerOptions {
    /// Timed input, applied at its frames (a scripted run).
    pub script: Option<InputScript>,
    /// Stop after this many frames, writing `screenshot` (a scripted run).
    pub exit_after_frames: Option<u32>,
    /// The last frame's file (`--screenshot`).
    pub screenshot: Option<PathBuf>,
    /// Fly time per frame; `None`: the wall time since the last frame.
    pub fixed_dt_s: Option<f32>,
    /// The CPU backend's frame-time target, milliseconds: the frame size
    /// shrinks above it and grows back below; `None` keeps the size.
    pub adaptive_target_ms: Option<f64>,
    /// Where the screenshot key writes.
    pub screenshot_dir: PathBuf,
    /// Samples per pixel of a scripted reference key (`f5`).
    pub reference_spp: u32,
    /// The first session's view (`--view`).
    pub start_view: Option<ViewMode>,
}

/// One rendered frame and the figures of the stats panel.
#[derive(Clone, Debug, Default)]
pub struct FrameReport {
    /// Frames rendered since the viewer started.
    pub frame: u32,
    /// The scene clock.
    pub scene_frame: u32,
    /// The view's image, tone-mapped RGBA8 (empty where `texture` holds it).
    pub rgba: Vec<u8>,
    /// The view's image in a texture on the window's own device (sRGB), with
    /// a serial that changes whenever the texture is another one.
    pub texture: Option<(wgpu::Texture, u64)>,
    /// Its size, pixels.
    pub width: u32,
    /// Its size, pixels.
    pub height: u32,
    /// The rendered frame's size, pixels (the view's differs for the atlases).
    pub frame_size: (u32, u32),
    /// Wall milliseconds of the frame (input, field update, camera frame, view).
    pub frame_ms: f64,
    /// This frame's milliseconds by pass.
    pub pass_ms: Vec<(&'static str, f64)>,
    /// Probe rays traced this frame.
    pub rays: u64,
    /// Probes per state, over every volume.
    pub probe_states: BTreeMap<&'static str, usize>,
    /// The field's volumes.
    pub volumes: usize,
    /// The fast-convergence heuristics' factor on the irradiance hysteresis
    /// (the smallest over the volumes; 1: none running).
    pub hysteresis_scale: f32,
    /// The adapter (`None`: CPU).
    pub adapter: Option<String>,
    /// Where the camera is, metres.
    pub camera_m: glam::Vec3,
    /// The fly camera's speed, metres per second.
    pub fly_speed_m_per_s: f32,
}

/// The reference's progress and, once done, its images.
#[derive(Clone, Debug, Default)]
pub struct ReferenceReport {
    /// Rows done over rows.
    pub progress: f32,
    /// Samples per pixel.
    pub spp: u32,
    /// The reference, tone-mapped RGBA8 (when done).
    pub rgba: Option<Vec<u8>>,
    /// FLIP between it and the live frame, magma RGBA8 (when the camera is
    /// still where the reference was taken).
    pub heat_rgba: Option<Vec<u8>>,
    /// Mean FLIP of the live frame against the reference.
    pub mean_flip: Option<f32>,
    /// Size of the images.
    pub width: u32,
    /// Size of the images.
    pub height: u32,
    /// The camera or the frame size changed since the reference was taken.
    pub stale: bool,
}

/// What the worker tells the window.
#[derive(Clone, Debug)]
pub enum WorkerReport {
    /// A session started with these controls (after a rebuild or reload too).
    Ready(ViewerControls),
    /// The worker changed the controls itself (a scripted viewer key).
    Controls(ViewerControls),
    /// The reference's state.
    Reference(ReferenceReport),
    /// Something to show in the status line (a screenshot written).
    Message(String),
    /// A failure; the worker waits for a reload or quit.
    Error(String),
    /// A scripted run finished: the wall milliseconds of each of its frames.
    Done(Vec<f64>),
}

/// The newest frame, overwritten by the worker and taken by the window.
pub type LatestFrame = Arc<Mutex<Option<FrameReport>>>;

enum SessionEnd {
    Rebuild,
    Quit,
}

/// The worker's channels.
pub struct WorkerLink {
    /// Commands from the window.
    pub commands: Receiver<WorkerCommand>,
    /// Reports to the window.
    pub reports: Sender<WorkerReport>,
    /// The newest frame.
    pub latest: LatestFrame,
}

/// Runs the worker until `Quit`, a scripted run's last frame, or the window
/// goes away. Returns the first error of a scripted run.
pub fn run_worker(
    source: &dyn ViewSource,
    opts: &WorkerOptions,
    link: &WorkerLink,
    device: Option<&SharedDevice>,
) -> Result<(), String> {
    let mut controls: Option<ViewerControls> = None;
    let mut carry: Option<ViewCarry> = None;
    let mut frames_total = 0u32;
    let mut frame_ms = Vec::new();
    loop {
        let failure = match source.load(controls.as_ref(), device) {
            Err(e) => e,
            Ok(parts) => {
                let first = controls.is_none();
                let mut state = SessionState::new(&parts, controls.take(), opts, frames_total, source.watched_file());
                state.frame_ms = std::mem::take(&mut frame_ms);
                state.carry = carry.take();
                if let (true, Some(v)) = (first, opts.start_view) {
                    state.controls.view = v;
                }
                let end = state.run(link);
                frames_total = state.frames_total;
                frame_ms = std::mem::take(&mut state.frame_ms);
                carry = state.carry.take();
                controls = Some(state.controls);
                match end {
                    Ok(SessionEnd::Rebuild) => continue,
                    Ok(SessionEnd::Quit) => return Ok(()),
                    Err(e) => e,
                }
            }
        };
        let _ = link.reports.send(WorkerReport::Error(failure.clone()));
        if controls.is_none() || opts.exit_after_frames.is_some() {
            return Err(failure);
        }
        match wait_for_reload(link, source.watched_file().as_deref()) {
            Some(Some(c)) => controls = Some(c),
            Some(None) => {}
            None => return Ok(()),
        }
    }
}

/// After a failure: waits for a reload, new controls (`Some(Some)`), a
/// change of the scene file (`Some(None)`), or quit (`None`).
fn wait_for_reload(link: &WorkerLink, watched: Option<&std::path::Path>) -> Option<Option<ViewerControls>> {
    let mut seen = watched.map(watch_state);
    loop {
        match link.commands.recv_timeout(std::time::Duration::from_millis(500)) {
            Ok(WorkerCommand::Reload) => return Some(None),
            Ok(WorkerCommand::Controls(c)) => return Some(Some(c)),
            Ok(WorkerCommand::Quit) | Err(RecvTimeoutError::Disconnected) => return None,
            Ok(_) => {}
            Err(RecvTimeoutError::Timeout) => {
                if let Some((path, time)) = &mut seen {
                    let now = std::fs::metadata(&*path).and_then(|m| m.modified()).ok();
                    if now.is_some() && now != *time {
                        return Some(None);
                    }
                    *time = now;
                }
            }
        }
    }
}

/// The commands waiting; a window gone away reads as `Quit`.
fn take_commands(link: &WorkerLink) -> Vec<WorkerCommand> {
    let mut commands = vec![];
    loop {
        match link.commands.try_recv() {
            Ok(c) => commands.push(c),
            Err(TryRecvError::Empty) => return commands,
            Err(TryRecvError::Disconnected) => {
                commands.push(WorkerCommand::Quit);
                return commands;
            }
        }
    }
}

/// The scene a reference saw: the scene clock (for a scene that moves) and
/// the light switches.
#[derive(Clone, Debug, PartialEq)]
struct ReferenceScene {
    scene_frame: Option<u32>,
    lights: Vec<crate::viewer_controls::LightControl>,
    sky_scale: f32,
}

/// A finished reference: its image and where it was taken.
struct Reference {
    image: Image,
    camera: Camera,
    scene: ReferenceScene,
    spp: u32,
}

/// A reference being path-traced.
struct ReferenceJob<'s> {
    handle: std::thread::ScopedJoinHandle<'s, Option<Image>>,
    cancel: Arc<AtomicBool>,
    rows_done: Arc<AtomicU32>,
    rows: u32,
    camera: Camera,
    scene: ReferenceScene,
    spp: u32,
}

/// One session's loop state.
struct SessionState<'p> {
    parts: &'p SessionParts,
    controls: ViewerControls,
    opts: &'p WorkerOptions,
    frames_total: u32,
    /// Wall milliseconds of every frame so far (all sessions).
    frame_ms: Vec<f64>,
    /// The last full frame on the host (`None` where it stays on the device:
    /// [`Self::full_image`] reads it back when a reference or screenshot needs it).
    last_full: Option<Image>,
    /// The size of the texture the window was last given, and a serial that
    /// changes with the texture.
    presented_size: Option<(u32, u32)>,
    texture_serial: u64,
    prev_pass_totals: BTreeMap<&'static str, f64>,
    reference: Option<Reference>,
    watch_file: Option<PathBuf>,
    watched: Option<(PathBuf, Option<SystemTime>)>,
    last_frame_at: Instant,
    /// The last session's camera and clock, for the next one.
    carry: Option<ViewCarry>,
}

impl<'p> SessionState<'p> {
    fn new(
        parts: &'p SessionParts,
        user: Option<ViewerControls>,
        opts: &'p WorkerOptions,
        frames_total: u32,
        watch_file: Option<PathBuf>,
    ) -> Self {
        Self {
            parts,
            controls: user.unwrap_or_else(|| ViewerControls::new(parts.gi, parts.cascades, &parts.scene, None)),
            opts,
            frames_total,
            frame_ms: Vec::new(),
            last_full: None,
            presented_size: None,
            texture_serial: 0,
            prev_pass_totals: BTreeMap::new(),
            reference: None,
            watch_file,
            watched: None,
            last_frame_at: Instant::now(),
            carry: None,
        }
    }

    /// Builds the session (taking the last one's camera and clock over) and
    /// runs its frames.
    fn run(&mut self, link: &WorkerLink) -> Result<SessionEnd, String> {
        let parts = self.parts;
        let mut session = ViewSession::new(
            &parts.scene,
            &*parts.tracer,
            &parts.camera,
            &parts.settings,
            parts.fly_speed_m_per_s,
            parts.camera_path.clone(),
        );
        if let Some(c) = self.carry {
            session.restore(c);
        }
        self.start_controls(&mut session);
        let _ = link.reports.send(WorkerReport::Ready(self.controls.clone()));
        self.watched = self.watch_file.as_deref().filter(|_| self.opts.exit_after_frames.is_none()).map(watch_state);
        let pool = reference_pool();
        let end = std::thread::scope(|scope| {
            let mut job: Option<ReferenceJob<'_>> = None;
            let end = self.session_loop(&mut session, link, scope, &pool, &mut job);
            // A running reference stops at its next row rather than hold the exit up.
            if let Some(j) = job {
                j.cancel.store(true, Ordering::Relaxed);
            }
            end
        });
        self.carry = Some(session.carry());
        end
    }

    /// Frames until quit, rebuild or (scripted) the last frame.
    fn session_loop<'s>(
        &mut self,
        session: &mut ViewSession<'_>,
        link: &WorkerLink,
        scope: &'s std::thread::Scope<'s, '_>,
        pool: &'s Option<rayon::ThreadPool>,
        job: &mut Option<ReferenceJob<'s>>,
    ) -> Result<SessionEnd, String>
    where
        'p: 's,
    {
        let mut frame_in_session = 0u32;
        loop {
            let mut commands = take_commands(link);
            if commands.iter().any(|c| matches!(c, WorkerCommand::Quit)) {
                return Ok(SessionEnd::Quit);
            }
            commands.extend(self.script_commands(session, link));
            let mut rebuild = false;
            for cmd in commands {
                match cmd {
                    WorkerCommand::Input(e) => session.apply(e),
                    WorkerCommand::Controls(c) if self.controls.needs_rebuild(&c) || rebuild => {
                        self.controls = c;
                        rebuild = true;
                    }
                    WorkerCommand::Controls(c) => self.apply_controls(session, c),
                    WorkerCommand::StepClock => session.step_scene_clock(),
                    WorkerCommand::Reference(spp) => {
                        if let Some(old) = job.take() {
                            old.cancel.store(true, Ordering::Relaxed);
                            let _ = old.handle.join();
                        }
                        *job = Some(self.start_reference(scope, pool, session, spp));
                    }
                    WorkerCommand::Screenshot => self.screenshot(session, link),
                    WorkerCommand::Reload => rebuild = true,
                    WorkerCommand::Quit => return Ok(SessionEnd::Quit),
                }
            }
            if rebuild {
                return Ok(SessionEnd::Rebuild);
            }
            self.frame(session, link, job.is_some())?;
            frame_in_session += 1;
            *job = self.poll_reference(job.take(), session, link, frame_in_session);
            if self.opts.exit_after_frames.is_some_and(|n| self.frames_total >= n) {
                return self.finish_scripted(session, link);
            }
            if frame_in_session.is_multiple_of(30) && self.scene_file_changed() {
                let _ = link.reports.send(WorkerReport::Message("scene file changed: reloading".into()));
                return Ok(SessionEnd::Rebuild);
            }
        }
    }

    /// A new session takes the user's view, clock, lights, sky and live
    /// field settings; the rest is what it was built with.
    fn start_controls(&mut self, session: &mut ViewSession<'_>) {
        let built =
            ViewerControls::new(self.parts.gi, self.parts.cascades, &self.parts.scene, session.stepper().field());
        let user = std::mem::replace(&mut self.controls, built.clone());
        let mut c = ViewerControls {
            view: user.view,
            atlas_volume: user.atlas_volume,
            paused: user.paused,
            sky_scale: user.sky_scale,
            field_at_start: user.field_at_start.or(built.field),
            ..built
        };
        if user.lights.len() == c.lights.len() {
            c.lights = user.lights;
        }
        if let (Some(u), Some(b)) = (user.field, c.field.as_mut()) {
            b.hysteresis = u.hysteresis;
            b.fast_convergence = u.fast_convergence;
            b.glossy_second_order = u.glossy_second_order;
            b.ray_budget = u.ray_budget;
        }
        self.apply_controls(session, c);
    }

    /// Applies live controls (see `viewer_controls`).
    fn apply_controls(&mut self, session: &mut ViewSession<'_>, c: ViewerControls) {
        // Only a change is written: the volumes of a set keep their own settings otherwise.
        if let (true, Some(f), Some(set)) = (c.field != self.controls.field, c.field, session.stepper_mut().field_mut())
        {
            f.apply_live(set);
        }
        let lights_changed = c.lights != self.controls.lights || c.sky_scale != self.controls.sky_scale;
        if lights_changed && (c.edits_scene() || self.controls.edits_scene()) {
            session.stepper_mut().set_scene_edit(Some(c.scene_edit()));
        }
        session.set_paused(c.paused);
        self.controls = c;
    }

    /// The script's events for the next frame: fly input goes to the
    /// session; viewer keys become the commands the window's keys send
    /// (their new controls reported to the window).
    fn script_commands(&self, session: &mut ViewSession<'_>, link: &WorkerLink) -> Vec<WorkerCommand> {
        let Some(s) = &self.opts.script else { return vec![] };
        let mut commands = vec![];
        let mut controls = self.controls.clone();
        for (_, e) in s.events.iter().filter(|(at, _)| *at == self.frames_total) {
            let ScriptEvent::Viewer(key) = e else {
                session.apply(*e);
                continue;
            };
            match key {
                ViewerKey::Pause => controls.paused = !controls.paused,
                ViewerKey::NextView => controls.view = controls.view.next(controls.field.is_some()),
                ViewerKey::Step => commands.push(WorkerCommand::StepClock),
                ViewerKey::Reference => commands.push(WorkerCommand::Reference(self.opts.reference_spp.max(1))),
                ViewerKey::Screenshot => commands.push(WorkerCommand::Screenshot),
            }
        }
        if controls != self.controls {
            let _ = link.reports.send(WorkerReport::Controls(controls.clone()));
            commands.insert(0, WorkerCommand::Controls(controls));
        }
        commands
    }

    /// Renders one frame and hands it to the window.
    fn frame(&mut self, session: &mut ViewSession<'_>, link: &WorkerLink, referencing: bool) -> Result<(), String> {
        let t = Instant::now();
        let dt_s = self.opts.fixed_dt_s.unwrap_or_else(|| self.last_frame_at.elapsed().as_secs_f32().min(0.1));
        self.last_frame_at = Instant::now();
        let layer = match self.controls.view {
            ViewMode::Full => Some(probegi_field::FrameLayer::Full),
            ViewMode::Direct => Some(probegi_field::FrameLayer::Direct),
            ViewMode::Indirect => Some(probegi_field::FrameLayer::Indirect),
            _ => None,
        };
        let report = match (self.parts.presenter.as_ref(), layer) {
            // The frame stays on the window's device: a texture, no pixel read back.
            (Some(present), Some(layer)) => {
                session.advance(dt_s).map_err(|e| format!("frame {}: {e}", self.frames_total))?;
                let texture = present(layer).map_err(|e| format!("frame {}: {e}", self.frames_total))?;
                let size = texture.size();
                if self.presented_size != Some((size.width, size.height)) {
                    self.presented_size = Some((size.width, size.height));
                    self.texture_serial += 1;
                }
                self.last_full = None;
                let shown = FrameImage::Texture(texture, self.texture_serial);
                self.report(session, shown, (size.width, size.height), t.elapsed().as_secs_f64() * 1e3)
            }
            _ => {
                let full = session.frame(dt_s).map_err(|e| format!("frame {}: {e}", self.frames_total))?;
                let (mode, volume) = (self.controls.view, self.controls.atlas_volume);
                let view = view_image(mode, &full, session, &*self.parts.tracer, volume)?;
                self.last_full = Some(full);
                let size = (view.width, view.height);
                self.report(session, FrameImage::Rgba(to_rgba8(&view)), size, t.elapsed().as_secs_f64() * 1e3)
            }
        };
        // A reference compares frames of its own size: the size holds while one exists.
        if !referencing && self.reference.is_none() {
            self.adapt_size(session, report.frame_ms);
        }
        self.frame_ms.push(report.frame_ms);
        self.frames_total += 1;
        if let Ok(mut slot) = link.latest.lock() {
            *slot = Some(report);
        }
        Ok(())
    }

    /// The stats panel's figures for the frame just rendered.
    fn report(&mut self, session: &ViewSession<'_>, view: FrameImage, size: (u32, u32), frame_ms: f64) -> FrameReport {
        let (rgba, texture) = match view {
            FrameImage::Rgba(rgba) => (rgba, None),
            FrameImage::Texture(t, serial) => (Vec::new(), Some((t, serial))),
        };
        let totals = session.stepper().pass_totals_ms();
        let pass_ms =
            totals.iter().map(|(k, v)| (*k, v - self.prev_pass_totals.get(k).copied().unwrap_or(0.0))).collect();
        self.prev_pass_totals = totals.clone();
        let mut probe_states = BTreeMap::new();
        let (mut rays, mut volumes, mut hysteresis_scale) = (0, 0, 1.0f32);
        if let Some(set) = session.stepper().field() {
            for v in set.volumes() {
                for (k, n) in v.state_counts() {
                    *probe_states.entry(k).or_default() += n;
                }
            }
            rays = set.last_batch_rays;
            volumes = set.volumes().len();
            hysteresis_scale = set.volumes().iter().map(|v| v.irradiance_hysteresis_scale()).fold(1.0, f32::min);
        }
        FrameReport {
            frame: self.frames_total,
            scene_frame: session.last_scene_frame(),
            rgba,
            texture,
            width: size.0,
            height: size.1,
            frame_size: session.size(),
            frame_ms,
            pass_ms,
            rays,
            probe_states,
            volumes,
            hysteresis_scale,
            adapter: self.parts.adapter.clone(),
            camera_m: session.last_camera().position,
            fly_speed_m_per_s: session.fly_camera().speed_m_per_s,
        }
    }

    /// The CPU backend's adaptive frame size: ×0.8 above the target frame
    /// time, ×1.15 below 60 % of it, never above the size asked for.
    fn adapt_size(&self, session: &mut ViewSession<'_>, frame_ms: f64) {
        let (Some(target), None) = (self.opts.adaptive_target_ms, &self.parts.settings.probe_tracer) else { return };
        let (max_w, max_h) = (self.parts.settings.width, self.parts.settings.height);
        let (w, _) = session.size();
        let scale = if frame_ms > target * 1.25 && w > 64 {
            0.8
        } else if frame_ms < target * 0.6 && w < max_w {
            1.15
        } else {
            return;
        };
        let nw = ((w as f64 * scale).round() as u32).clamp(32.min(max_w), max_w);
        let nh = ((nw as f64 * max_h as f64 / max_w as f64).round() as u32).max(1);
        session.set_size(nw, nh);
    }

    /// What the reference of the current view sees of the scene.
    fn reference_scene(&self, session: &ViewSession<'_>) -> ReferenceScene {
        ReferenceScene {
            scene_frame: self.parts.scene.is_animated().then(|| session.last_scene_frame()),
            lights: self.controls.lights.clone(),
            sky_scale: self.controls.sky_scale,
        }
    }

    /// Starts the path-traced reference of the current view on a thread of
    /// `scope`, its rows on `pool` (so the frames keep the global pool).
    fn start_reference<'s>(
        &self,
        scope: &'s std::thread::Scope<'s, '_>,
        pool: &'s Option<rayon::ThreadPool>,
        session: &ViewSession<'_>,
        spp: u32,
    ) -> ReferenceJob<'s>
    where
        'p: 's,
    {
        let camera = session.last_camera();
        let (w, h) = session.size();
        // The scene as the last frame saw it: posed at its clock, lights switched.
        let posed = session.stepper().frame_scene().clone();
        let clock = session.last_scene_frame() as f32;
        let rows_done = Arc::new(AtomicU32::new(0));
        let cancel = Arc::new(AtomicBool::new(false));
        let (rows, stop) = (Arc::clone(&rows_done), Arc::clone(&cancel));
        let seed = self.parts.settings.seed;
        let base_tracer: &'p dyn RayTracer = &*self.parts.tracer;
        let handle = scope.spawn(move || {
            let at_frame = base_tracer.at_frame(&posed, clock);
            let tracer: &dyn RayTracer = at_frame.as_deref().unwrap_or(base_tracer);
            let settings = PathTracerSettings { pt_spp: spp.max(1), seed, ..Default::default() };
            let pt = PathTracer::new(&posed, tracer, settings);
            let rays = CameraRays::new(&camera, w, h);
            let on_row = || {
                rows.fetch_add(1, Ordering::Relaxed);
            };
            let render = || pt.render_cancellable(&rays, w, h, &on_row, &stop).map(|(image, _)| image);
            match pool {
                Some(p) => p.install(render),
                None => render(),
            }
        });
        ReferenceJob { handle, cancel, rows_done, rows: h, camera, scene: self.reference_scene(session), spp }
    }

    /// Reports a running reference's progress; takes a finished one in; every
    /// 10 frames compares the live frame against it.
    fn poll_reference<'s>(
        &mut self,
        job: Option<ReferenceJob<'s>>,
        session: &ViewSession<'_>,
        link: &WorkerLink,
        frame: u32,
    ) -> Option<ReferenceJob<'s>> {
        if let Some(j) = job {
            if !j.handle.is_finished() {
                let progress = j.rows_done.load(Ordering::Relaxed) as f32 / j.rows.max(1) as f32;
                let report = ReferenceReport { progress, spp: j.spp, ..Default::default() };
                let _ = link.reports.send(WorkerReport::Reference(report));
                return Some(j);
            }
            match j.handle.join() {
                Ok(Some(image)) => {
                    self.reference = Some(Reference { image, camera: j.camera, scene: j.scene, spp: j.spp })
                }
                Ok(None) => return None,
                Err(_) => {
                    let _ = link.reports.send(WorkerReport::Error("the reference render panicked".into()));
                }
            }
            self.send_reference(session, link);
        } else if frame.is_multiple_of(10) && self.reference.is_some() {
            self.send_reference(session, link);
        }
        None
    }

    /// The finished reference beside the live frame: FLIP while the camera
    /// and size are where it was taken.
    fn send_reference(&self, session: &ViewSession<'_>, link: &WorkerLink) {
        let (Some(r), Some(live)) = (&self.reference, self.full_image(session)) else { return };
        let live = &live;
        let same_view = r.camera == session.last_camera()
            && (r.image.width, r.image.height) == (live.width, live.height)
            && r.scene == self.reference_scene(session);
        let mut report = ReferenceReport {
            progress: 1.0,
            spp: r.spp,
            rgba: Some(to_rgba8(&r.image)),
            width: r.image.width,
            height: r.image.height,
            stale: !same_view,
            ..Default::default()
        };
        if same_view {
            let reference = probegi_image::LoadedImage::Hdr(r.image.clone()).to_srgb8();
            let test = probegi_image::LoadedImage::Hdr(live.clone()).to_srgb8();
            let flip = probegi_image::flip_srgb8(live.width, live.height, &reference, &test);
            let magma = probegi_image::compare::error_map_magma(&flip);
            report.heat_rgba = Some(magma.chunks(3).flat_map(|c| [c[0], c[1], c[2], 255]).collect());
            report.mean_flip = Some(flip.mean_flip);
        }
        let _ = link.reports.send(WorkerReport::Reference(report));
    }

    /// The screenshot key: the last full frame as PNG and linear EXR.
    fn screenshot(&self, session: &ViewSession<'_>, link: &WorkerLink) {
        let Some(img) = &self.full_image(session) else { return };
        let stem = format!("{}-frame{:04}", file_safe(&self.parts.scene.name), self.frames_total);
        let mut written = vec![];
        for ext in ["png", "exr"] {
            let path = self.opts.screenshot_dir.join(format!("{stem}.{ext}"));
            match probegi_image::write_image(&path, img) {
                Ok(()) => written.push(path.display().to_string()),
                Err(e) => {
                    let _ = link.reports.send(WorkerReport::Error(format!("screenshot: {e}")));
                    return;
                }
            }
        }
        let _ = link.reports.send(WorkerReport::Message(format!("wrote {}", written.join(" and "))));
    }

    /// The scripted run's end: the screenshot, then `Done`.
    fn finish_scripted(&self, session: &ViewSession<'_>, link: &WorkerLink) -> Result<SessionEnd, String> {
        if let Some(path) = &self.opts.screenshot {
            let img = self.full_image(session).ok_or("no frame to write")?;
            probegi_image::write_image(path, &img).map_err(|e| e.to_string())?;
        }
        let _ = link.reports.send(WorkerReport::Done(self.frame_ms.clone()));
        Ok(SessionEnd::Quit)
    }

    /// The last full frame on the host: the one kept, else read back from the
    /// device that holds it.
    fn full_image(&self, session: &ViewSession<'_>) -> Option<Image> {
        self.last_full.clone().or_else(|| session.image().ok().filter(|i| !i.pixels.is_empty()))
    }

    /// Whether the watched scene file's modification time moved.
    fn scene_file_changed(&mut self) -> bool {
        let Some((path, seen)) = &mut self.watched else { return false };
        let now = std::fs::metadata(&*path).and_then(|m| m.modified()).ok();
        if now.is_some() && now != *seen {
            *seen = now;
            return true;
        }
        false
    }
}

/// The scene file and its modification time now.
fn watch_state(path: &std::path::Path) -> (PathBuf, Option<SystemTime>) {
    (path.to_path_buf(), std::fs::metadata(path).and_then(|m| m.modified()).ok())
}

/// The reference's own thread pool: half the cores (at least one), so the
/// frames keep the global pool while it runs. `None` if it cannot be built
/// (the reference then shares the global pool).
fn reference_pool() -> Option<rayon::ThreadPool> {
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    rayon::ThreadPoolBuilder::new()
        .num_threads((cores / 2).max(1))
        .thread_name(|i| format!("reference-{i}"))
        .build()
        .ok()
}

/// `name` with anything but letters, digits, `-` and `_` replaced by `_`.
fn file_safe(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect()
}
