//! The window of `probegi view`: winit 0.30, a wgpu 30 surface through
//! `egui-wgpu`, and the egui panels (`viewer_panels`). The frame worker
//! (`viewer_worker`) renders on its own thread with its own device; the
//! window shows its newest frame as a texture, so the UI keeps its own rate
//! whatever a field update costs. Input that egui does not take goes to the
//! worker as the same events an input script holds.
//!
//! A scripted run in the window (`--input-script`, `--exit-after-frames`)
//! takes the script's events frame by frame in the worker with a fixed time
//! step, exactly as `--headless` does, so its screenshot matches the headless
//! run's; the window itself is then captured beside it
//! (`NAME-window.png`) so a test can see what was on screen.

use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex};

use egui::{ColorImage, TextureHandle, TextureOptions, ViewportId};
use winit::application::ApplicationHandler;
use winit::event::{DeviceEvent, ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::input_script::{FlyKey, ScriptEvent};
use crate::viewer_controls::ViewerControls;
use crate::viewer_panels::{PanelAction, PanelState, panels_ui};
use crate::viewer_prefs::ViewerPrefs;
use crate::viewer_worker::{
    LatestFrame, ReferenceReport, SharedDevice, ViewSource, WorkerCommand, WorkerLink, WorkerOptions, WorkerReport,
    run_worker,
};

/// How the window runs.
#[derive(Clone, Debug, Default)]
pub struct WindowOptions {
    /// The window's title.
    pub title: String,
    /// The scene's name (panels, screenshots).
    pub scene_name: String,
    /// The CPU backend renders (the GI panel offers SH).
    pub cpu_backend: bool,
    /// A scripted run: the window closes when the worker is done (or fails).
    pub scripted: bool,
    /// Capture the window beside this screenshot at a scripted run's end.
    pub capture_path: Option<PathBuf>,
    /// Print the UI's and the worker's frame-time percentiles as JSON at the end.
    pub bench: bool,
    /// Settings that persist between runs (`None`: a scripted run reads none).
    pub prefs_path: Option<PathBuf>,
    /// The view asked for on the command line (`--view`; the worker starts with it).
    pub start_view: Option<crate::view_layers::ViewMode>,
}

/// Why the window could not open: no window system.
pub fn no_display_message(detail: &str) -> String {
    format!(
        "probegi view: no window system ({detail}); run it without a window: \
         probegi view --headless --exit-after-frames N [--input-script FILE] [--screenshot FILE]"
    )
}

/// Opens the window over a worker built from `source`; returns when the
/// window closes or a scripted run ends. An error names what failed.
pub fn run_window(source: Box<dyn ViewSource>, worker: WorkerOptions, opts: WindowOptions) -> Result<(), String> {
    let has_display = ["DISPLAY", "WAYLAND_DISPLAY"].iter().any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()));
    if cfg!(target_os = "linux") && !has_display {
        return Err(no_display_message("neither DISPLAY nor WAYLAND_DISPLAY is set"));
    }
    let event_loop = EventLoop::new().map_err(|e| no_display_message(&e.to_string()))?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let (cmd_tx, cmd_rx) = mpsc::channel();
    let (rep_tx, rep_rx) = mpsc::channel();
    let latest: LatestFrame = Arc::new(Mutex::new(None));
    let link = WorkerLink { commands: cmd_rx, reports: rep_tx, latest: Arc::clone(&latest) };
    // One device for the window and the field: the worker's GPU passes run on
    // the device egui draws with, and the frame reaches the window as a texture.
    let device = shared_device();
    let worker_device = device.clone();
    let worker_thread = std::thread::Builder::new()
        .name("probegi-view-frames".into())
        .spawn(move || run_worker(&*source, &worker, &link, worker_device.as_ref()))
        .map_err(|e| format!("starting the frame worker: {e}"))?;
    let mut app = ViewerApp::new(opts, cmd_tx.clone(), rep_rx, latest);
    app.device = device;
    let run = event_loop.run_app(&mut app).map_err(|e| format!("the window's event loop: {e}"));
    let _ = cmd_tx.send(WorkerCommand::Quit);
    drop(cmd_tx);
    app.save_prefs();
    if app.opts.bench {
        println!("{}", app.bench_json());
    }
    let worker_result = worker_thread.join().map_err(|_| "the frame worker panicked".to_string())?;
    run?;
    app.outcome.take().unwrap_or(Ok(())).and(worker_result)
}

/// A device for the window and the frame worker to share (the adapter's
/// limits, timestamp queries where it has them, as `GpuContext::headless`
/// asks), or `None` with a line saying why: each then makes its own.
fn shared_device() -> Option<SharedDevice> {
    if std::env::var_os("PROBEGI_VIEW_SEPARATE_DEVICES").is_some() {
        eprintln!("probegi view: PROBEGI_VIEW_SEPARATE_DEVICES: the window and the field make their own devices");
        return None;
    }
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let options =
        wgpu::RequestAdapterOptions { power_preference: wgpu::PowerPreference::HighPerformance, ..Default::default() };
    let made = pollster::block_on(instance.request_adapter(&options)).map_err(|e| e.to_string()).and_then(|adapter| {
        let required_features = adapter.features() & wgpu::Features::TIMESTAMP_QUERY;
        let descriptor = wgpu::DeviceDescriptor {
            label: Some("probegi view"),
            required_features,
            required_limits: adapter.limits(),
            ..Default::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&descriptor)).map_err(|e| e.to_string())?;
        let info = adapter.get_info();
        let adapter_name = format!("{} ({:?}, {})", info.name, info.backend, info.driver);
        Ok(SharedDevice { instance: instance.clone(), adapter, device, queue, adapter_name })
    });
    made.inspect_err(|e| eprintln!("probegi view: no device to share ({e}); the window and the field make their own"))
        .ok()
}

/// The GPU side of the window.
struct Gfx {
    window: Arc<Window>,
    painter: egui_wgpu::winit::Painter,
    egui_state: egui_winit::State,
}

/// Textures of the central panel.
#[derive(Default)]
struct Textures {
    live: Option<TextureHandle>,
    /// The live frame as a texture on the shared device, registered with
    /// egui-wgpu: its id, size and the worker's serial for it.
    live_native: Option<(egui::TextureId, [usize; 2], u64)>,
    reference: Option<TextureHandle>,
    heat: Option<TextureHandle>,
}

struct ViewerApp {
    opts: WindowOptions,
    prefs: ViewerPrefs,
    ctx: egui::Context,
    /// The device shared with the frame worker (`None`: each made its own).
    device: Option<SharedDevice>,
    gfx: Option<Gfx>,
    commands: Sender<WorkerCommand>,
    reports: Receiver<WorkerReport>,
    latest: LatestFrame,
    panels: Option<PanelState>,
    textures: Textures,
    ui_visible: bool,
    looking: bool,
    /// The result the window closes with (set by a scripted run's end or an error).
    outcome: Option<Result<(), String>>,
    /// A scripted run ended: capture the window, then close.
    capture: Option<(Receiver<Arc<ColorImage>>, u32)>,
    done: bool,
    /// The worker's last error, shown in the central panel.
    error: Option<String>,
    /// When the last UI frame began, and the intervals between UI frames (ms).
    last_ui_frame: Option<std::time::Instant>,
    ui_frame_ms: Vec<f64>,
    /// The worker's frame times (a scripted run's, at its end).
    worker_frame_ms: Vec<f64>,
}

impl ViewerApp {
    fn new(
        opts: WindowOptions,
        commands: Sender<WorkerCommand>,
        reports: Receiver<WorkerReport>,
        latest: LatestFrame,
    ) -> Self {
        let prefs = opts.prefs_path.as_deref().map(ViewerPrefs::load).unwrap_or_default();
        Self {
            ui_visible: prefs.panels_visible,
            prefs,
            opts,
            ctx: egui::Context::default(),
            gfx: None,
            device: None,
            commands,
            reports,
            latest,
            panels: None,
            textures: Textures::default(),
            looking: false,
            outcome: None,
            capture: None,
            done: false,
            error: None,
            last_ui_frame: None,
            ui_frame_ms: Vec::new(),
            worker_frame_ms: Vec::new(),
        }
    }

    fn save_prefs(&mut self) {
        let Some(path) = &self.opts.prefs_path else { return };
        if let Some(p) = &self.panels {
            self.prefs.view = p.controls.view;
            self.prefs.reference_spp = p.reference_spp;
        }
        self.prefs.panels_visible = self.ui_visible;
        if let Err(e) = self.prefs.save(path) {
            eprintln!("probegi view: {e}");
        }
    }

    /// `--bench` in the window: the UI's frame interval and the worker's frame
    /// time, percentiles (median, p95, max) in milliseconds.
    fn bench_json(&self) -> String {
        let p = |ms: &[f64]| {
            let [m, p95, max] = crate::scripted_run::frame_time_percentiles(ms);
            format!("{{\"median\": {m:.2}, \"p95\": {p95:.2}, \"max\": {max:.2}, \"frames\": {}}}", ms.len())
        };
        format!(
            "{{\"scene\": {:?}, \"ui_frame_ms\": {}, \"worker_frame_ms\": {}}}",
            self.opts.scene_name,
            p(&self.ui_frame_ms),
            p(&self.worker_frame_ms)
        )
    }

    fn send(&self, cmd: WorkerCommand) {
        // A scripted run is the script's alone: live fly input would make it
        // differ from the same script's headless run.
        if self.opts.scripted && matches!(cmd, WorkerCommand::Input(_)) {
            return;
        }
        let _ = self.commands.send(cmd);
    }

    /// Takes the worker's reports and its newest frame in.
    fn take_reports(&mut self, event_loop: &ActiveEventLoop) {
        loop {
            let report = match self.reports.try_recv() {
                Ok(r) => r,
                Err(mpsc::TryRecvError::Empty) => break,
                Err(mpsc::TryRecvError::Disconnected) => {
                    // The worker ended without `Done`: its error (if any) is its result.
                    if !self.done {
                        self.outcome.get_or_insert(Ok(()));
                        event_loop.exit();
                    }
                    break;
                }
            };
            match report {
                WorkerReport::Ready(c) => self.take_ready(c),
                WorkerReport::Controls(c) => {
                    if let Some(p) = self.panels.as_mut() {
                        p.controls = c;
                    }
                }
                WorkerReport::Reference(r) => self.take_reference(r),
                WorkerReport::Message(m) => self.status(m),
                WorkerReport::Error(e) => {
                    eprintln!("probegi view: {e}");
                    self.status(format!("error: {e}"));
                    self.error = Some(e.clone());
                    if self.opts.scripted {
                        self.outcome = Some(Err(e));
                        event_loop.exit();
                    }
                }
                WorkerReport::Done(ms) => {
                    self.done = true;
                    self.worker_frame_ms = ms;
                }
            }
        }
        self.take_frame();
    }

    /// A session is ready: its controls, the panels made for the first one (with
    /// the saved view), an old reference dropped for a later one.
    fn take_ready(&mut self, mut c: ViewerControls) {
        let first = self.panels.is_none();
        if first && self.opts.prefs_path.is_some() && self.opts.start_view.is_none() {
            c.view = self.prefs.view;
            self.send(WorkerCommand::Controls(c.clone()));
        }
        let panels = self.panels.get_or_insert_with(|| {
            let mut p = PanelState::new(c.clone(), &self.opts.scene_name, self.opts.cpu_backend);
            p.reference_spp = self.prefs.reference_spp;
            p
        });
        panels.controls = c;
        if !first {
            // A new session: an old reference no longer describes it.
            panels.reference = None;
            self.textures.reference = None;
            self.textures.heat = None;
        }
    }

    /// A reference render came: its image and FLIP heat map as textures.
    fn take_reference(&mut self, r: ReferenceReport) {
        let size = [r.width as usize, r.height as usize];
        if let Some(rgba) = &r.rgba {
            let image = ColorImage::from_rgba_unmultiplied(size, rgba);
            set_texture(&self.ctx, &mut self.textures.reference, "reference", image);
        }
        match &r.heat_rgba {
            Some(rgba) => {
                let image = ColorImage::from_rgba_unmultiplied(size, rgba);
                set_texture(&self.ctx, &mut self.textures.heat, "flip", image);
            }
            None if r.rgba.is_some() => self.textures.heat = None,
            None => {}
        }
        if let Some(p) = self.panels.as_mut() {
            p.reference = Some(r);
        }
    }

    /// The worker's newest frame: a texture on the shared device, or RGBA8 to upload.
    fn take_frame(&mut self) {
        let frame = self.latest.lock().ok().and_then(|mut s| s.take());
        if let Some(mut f) = frame {
            match f.texture.take() {
                Some((texture, serial)) => self.show_native(&texture, serial),
                None => {
                    let image = ColorImage::from_rgba_unmultiplied([f.width as usize, f.height as usize], &f.rgba);
                    set_texture(&self.ctx, &mut self.textures.live, "live", image);
                    self.free_native();
                }
            }
            if let Some(p) = self.panels.as_mut() {
                p.push_frame(f);
            }
        }
    }

    /// Shows `texture` (on the shared device) as the live frame, registering
    /// it with egui-wgpu when it is another texture than the one shown.
    fn show_native(&mut self, texture: &wgpu::Texture, serial: u64) {
        let Some(state) = self.gfx.as_ref().and_then(|g| g.painter.render_state()) else { return };
        let size = [texture.width() as usize, texture.height() as usize];
        let view = texture.create_view(&Default::default());
        let mut renderer = state.renderer.write();
        match self.textures.live_native {
            Some((_, _, s)) if s == serial => {}
            Some((id, _, _)) => {
                renderer.update_egui_texture_from_wgpu_texture(&state.device, &view, wgpu::FilterMode::Nearest, id);
                self.textures.live_native = Some((id, size, serial));
            }
            None => {
                let id = renderer.register_native_texture(&state.device, &view, wgpu::FilterMode::Nearest);
                self.textures.live_native = Some((id, size, serial));
            }
        }
        self.textures.live = None;
    }

    /// Forgets the native live texture (the frame comes from the host again).
    fn free_native(&mut self) {
        if let (Some((id, _, _)), Some(state)) =
            (self.textures.live_native.take(), self.gfx.as_ref().and_then(|g| g.painter.render_state()))
        {
            state.renderer.write().free_texture(&id);
        }
    }

    /// Releases every fly key and stops looking (focus lost, a release missed).
    fn release_all(&mut self) {
        self.looking = false;
        for k in [FlyKey::W, FlyKey::A, FlyKey::S, FlyKey::D, FlyKey::Q, FlyKey::E] {
            self.send(WorkerCommand::Input(ScriptEvent::Key(k, false)));
        }
    }

    fn status(&mut self, message: String) {
        if let Some(p) = self.panels.as_mut() {
            p.status = message;
        }
    }

    /// A key egui did not take.
    fn key(&mut self, event_loop: &ActiveEventLoop, code: KeyCode, pressed: bool, ctrl: bool) {
        let fly = match code {
            KeyCode::KeyW => Some(FlyKey::W),
            KeyCode::KeyA => Some(FlyKey::A),
            KeyCode::KeyS => Some(FlyKey::S),
            KeyCode::KeyD => Some(FlyKey::D),
            KeyCode::KeyQ => Some(FlyKey::Q),
            KeyCode::KeyE => Some(FlyKey::E),
            KeyCode::KeyR if !ctrl => Some(FlyKey::R),
            _ => None,
        };
        if let Some(k) = fly {
            self.send(WorkerCommand::Input(ScriptEvent::Key(k, pressed)));
            return;
        }
        if !pressed {
            return;
        }
        match code {
            KeyCode::Escape => event_loop.exit(),
            KeyCode::Tab => self.ui_visible = !self.ui_visible,
            KeyCode::F12 => self.send(WorkerCommand::Screenshot),
            KeyCode::KeyR if ctrl => self.send(WorkerCommand::Reload),
            KeyCode::F5 => {
                let spp = self.panels.as_ref().map_or(64, |p| p.reference_spp);
                self.send(WorkerCommand::Reference(spp));
            }
            KeyCode::KeyN => self.send(WorkerCommand::StepClock),
            KeyCode::Space | KeyCode::KeyV => {
                let Some(p) = self.panels.as_mut() else { return };
                if code == KeyCode::Space {
                    p.controls.paused = !p.controls.paused;
                } else {
                    p.controls.view = p.controls.view.next(p.controls.field.is_some());
                }
                let c = p.controls.clone();
                self.send(WorkerCommand::Controls(c));
            }
            _ => {}
        }
    }

    /// One UI frame: reports in, panels, paint.
    fn redraw(&mut self, event_loop: &ActiveEventLoop) {
        let now = std::time::Instant::now();
        if let Some(last) = self.last_ui_frame.replace(now) {
            self.ui_frame_ms.push((now - last).as_secs_f64() * 1e3);
        }
        self.take_reports(event_loop);
        let Some(gfx) = self.gfx.as_mut() else { return };
        let raw_input = gfx.egui_state.take_egui_input(&gfx.window);
        let mut actions = vec![];
        let (ui_visible, textures, error) = (self.ui_visible, &self.textures, self.error.as_deref());
        let panels = &mut self.panels;
        let full_output = self.ctx.run_ui(raw_input, |ui| {
            if ui_visible && let Some(p) = panels.as_mut() {
                egui::Panel::right("panels").default_size(340.0).show(ui, |ui| actions = panels_ui(ui, p));
            }
            egui::CentralPanel::default().show(ui, |ui| {
                if let Some(e) = error.filter(|_| textures.live.is_none()) {
                    ui.colored_label(egui::Color32::from_rgb(255, 120, 100), format!("error: {e}"));
                }
                central_ui(ui, textures, panels.as_ref())
            });
        });
        gfx.egui_state.handle_platform_output(&gfx.window, full_output.platform_output);
        let clipped = self.ctx.tessellate(full_output.shapes, full_output.pixels_per_point);
        let mut deltas = full_output.textures_delta;
        let capture = self.capture_request();
        let gfx = self.gfx.as_mut().expect("checked above");
        gfx.painter.paint_and_update_textures(
            ViewportId::ROOT,
            full_output.pixels_per_point,
            [0.05, 0.05, 0.08, 1.0],
            &clipped,
            &mut deltas,
            capture,
            &gfx.window,
        );
        for a in actions {
            self.panel_action(a);
        }
        self.finish_capture(event_loop);
    }

    fn panel_action(&mut self, a: PanelAction) {
        match a {
            PanelAction::Controls => {
                if let Some(p) = &self.panels {
                    self.send(WorkerCommand::Controls(p.controls.clone()));
                }
            }
            PanelAction::Reference(spp) => self.send(WorkerCommand::Reference(spp)),
            PanelAction::Screenshot => self.send(WorkerCommand::Screenshot),
            PanelAction::StepClock => self.send(WorkerCommand::StepClock),
            PanelAction::Reload => self.send(WorkerCommand::Reload),
        }
    }

    /// After a scripted run's last frame has been shown: ask for the window's pixels.
    fn capture_request(&mut self) -> Vec<egui::ScreenshotCallback> {
        if !self.done || self.capture.is_some() || self.opts.capture_path.is_none() {
            return vec![];
        }
        let (tx, rx) = mpsc::channel();
        self.capture = Some((rx, 0));
        vec![egui::ScreenshotCallback::new(move |img| {
            let _ = tx.send(img);
        })]
    }

    /// Writes the window's pixels beside the screenshot and closes (or gives
    /// up after 120 UI frames, saying so).
    fn finish_capture(&mut self, event_loop: &ActiveEventLoop) {
        let Some((rx, waited)) = self.capture.as_mut() else {
            if self.done && self.opts.capture_path.is_none() && self.opts.scripted {
                self.outcome.get_or_insert(Ok(()));
                event_loop.exit();
            }
            return;
        };
        *waited += 1;
        let result = match rx.try_recv() {
            Ok(img) => write_capture(self.opts.capture_path.as_deref(), &img),
            Err(_) if *waited < 120 => return,
            Err(_) => Err("the window's pixels never came back from the surface".into()),
        };
        self.outcome.get_or_insert(result);
        event_loop.exit();
    }
}

/// Sets (or creates) a texture from `image`.
fn set_texture(ctx: &egui::Context, slot: &mut Option<TextureHandle>, name: &str, image: ColorImage) {
    match slot {
        Some(t) => t.set(image, TextureOptions::NEAREST),
        None => *slot = Some(ctx.load_texture(name, image, TextureOptions::NEAREST)),
    }
}

/// The live frame; with a reference, a 2 × 2 grid: live and reference on
/// top, the FLIP heat map below the live frame.
fn central_ui(ui: &mut egui::Ui, textures: &Textures, panels: Option<&PanelState>) {
    let live = match (&textures.live, textures.live_native) {
        (Some(t), _) => (t.id(), t.size()),
        (None, Some((id, size, _))) => (id, size),
        (None, None) => {
            ui.centered_and_justified(|ui| ui.label("rendering the first frame…"));
            return;
        }
    };
    let reference = panels.and_then(|p| p.reference.as_ref()).filter(|r| r.rgba.is_some());
    let cells = if reference.is_some() { 2.0 } else { 1.0 };
    let avail = ui.available_size();
    let [w, h] = live.1.map(|s| s as f32);
    let scale = ((avail.x / cells - 8.0) / w).min((avail.y / cells - 8.0) / h).max(0.01);
    let size = egui::vec2(w * scale, h * scale);
    ui.horizontal(|ui| {
        ui.image((live.0, size));
        if let (Some(_), Some(t)) = (reference, &textures.reference) {
            ui.image((t.id(), size));
        }
    });
    if let (Some(_), Some(t)) = (reference, &textures.heat) {
        ui.horizontal(|ui| {
            ui.image((t.id(), size));
            if let Some(f) = reference.and_then(|r| r.mean_flip) {
                ui.label(format!("FLIP of the live frame\nagainst the reference: {f:.3}"));
            }
        });
    }
}

/// The window's pixels as PNG beside `screenshot` (`NAME-window.png`).
fn write_capture(screenshot: Option<&std::path::Path>, img: &ColorImage) -> Result<(), String> {
    let Some(path) = screenshot else { return Ok(()) };
    let stem = path.file_stem().map_or("screenshot".into(), |s| s.to_string_lossy().into_owned());
    let out = path.with_file_name(format!("{stem}-window.png"));
    let rgb: Vec<u8> = img.pixels.iter().flat_map(|c| [c.r(), c.g(), c.b()]).collect();
    probegi_image::io::write_png(&out, img.size[0] as u32, img.size[1] as u32, rgb).map_err(|e| e.to_string())
}

impl ApplicationHandler for ViewerApp {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.gfx.is_some() {
            return;
        }
        match open_window(event_loop, &self.ctx, &self.opts.title, self.device.as_ref()) {
            Ok(g) => self.gfx = Some(g),
            Err(e) => {
                self.outcome = Some(Err(e));
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(gfx) = self.gfx.as_mut() else { return };
        let consumed = gfx.egui_state.on_window_event(&gfx.window, &event).consumed;
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let (Some(w), Some(h)) =
                    (std::num::NonZeroU32::new(size.width), std::num::NonZeroU32::new(size.height))
                {
                    gfx.painter.on_window_resized(ViewportId::ROOT, w, h);
                }
            }
            WindowEvent::RedrawRequested => self.redraw(event_loop),
            // Releases always reach the fly camera (a key held into a text field
            // must not stick); presses only when egui does not take them.
            WindowEvent::KeyboardInput { event, .. }
                if !event.repeat && (!consumed || event.state == ElementState::Released) =>
            {
                if let PhysicalKey::Code(code) = event.physical_key {
                    let ctrl = self.ctx.input(|i| i.modifiers.ctrl);
                    self.key(event_loop, code, event.state == ElementState::Pressed, ctrl);
                }
            }
            WindowEvent::Focused(false) => self.release_all(),
            WindowEvent::MouseInput { button: MouseButton::Right, state, .. } => {
                self.looking = state == ElementState::Pressed && !self.ctx.egui_wants_pointer_input();
            }
            WindowEvent::MouseWheel { delta, .. } if !consumed && !self.ctx.egui_wants_pointer_input() => {
                let steps = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => (p.y / 40.0) as f32,
                };
                self.send(WorkerCommand::Input(ScriptEvent::Scroll(steps)));
            }
            _ => {}
        }
    }

    fn device_event(&mut self, _event_loop: &ActiveEventLoop, _id: winit::event::DeviceId, event: DeviceEvent) {
        if let (true, DeviceEvent::MouseMotion { delta }) = (self.looking, event) {
            self.send(WorkerCommand::Input(ScriptEvent::Mouse(delta.0 as f32, delta.1 as f32)));
        }
    }

    fn about_to_wait(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(g) = &self.gfx {
            g.window.request_redraw();
        }
        // The UI's own rate: about 60 frames a second, whatever the worker does.
        std::thread::sleep(std::time::Duration::from_millis(8));
    }
}

/// The window, its wgpu surface and egui's winit state.
fn open_window(
    event_loop: &ActiveEventLoop,
    ctx: &egui::Context,
    title: &str,
    device: Option<&SharedDevice>,
) -> Result<Gfx, String> {
    let attributes =
        Window::default_attributes().with_title(title).with_inner_size(winit::dpi::LogicalSize::new(1280.0, 760.0));
    let window = Arc::new(event_loop.create_window(attributes).map_err(|e| no_display_message(&e.to_string()))?);
    let mut config = egui_wgpu::WgpuConfiguration::default();
    if let Some(d) = device {
        config.wgpu_setup = egui_wgpu::WgpuSetup::Existing(egui_wgpu::WgpuSetupExisting {
            instance: d.instance.clone(),
            adapter: d.adapter.clone(),
            device: d.device.clone(),
            queue: d.queue.clone(),
        });
    }
    let mut painter = pollster::block_on(egui_wgpu::winit::Painter::new(
        ctx.clone(),
        config,
        false,
        egui_wgpu::RendererOptions::default(),
    ));
    pollster::block_on(painter.set_window(ViewportId::ROOT, Some(Arc::clone(&window))))
        .map_err(|e| format!("the window's GPU surface: {e}"))?;
    let egui_state = egui_winit::State::new(
        ctx.clone(),
        ViewportId::ROOT,
        &window,
        Some(window.scale_factor() as f32),
        None,
        painter.max_texture_side(),
    );
    Ok(Gfx { window, painter, egui_state })
}
