//! The viewer's frame worker end to end on the CPU backend, without a
//! window: it starts a session and renders frames; a live setting reaches
//! the field without a rebuild; a structural one rebuilds it (the user's
//! live settings kept); the reference key path-traces the view and compares
//! the live frame against it; the screenshot key writes PNG and EXR named
//! after the scene and frame; quit ends it.

use std::path::PathBuf;
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_frame::frame_loop::{GiMethod, RenderSettings};
use probegi_scene::{BvhSettings, BvhTracer, load_scene};
use probegi_view::view_layers::ViewMode;
use probegi_view::viewer_controls::{GiChoice, ViewerControls};
use probegi_view::viewer_worker::{
    SessionParts, SharedDevice, ViewSource, WorkerCommand, WorkerLink, WorkerOptions, WorkerReport, run_worker,
};

/// The Cornell box at 24×24 with a small field; `controls` pick the rays.
/// `watched` stands for its scene file.
struct CornellSource {
    watched: PathBuf,
}

impl ViewSource for CornellSource {
    fn load(&self, controls: Option<&ViewerControls>, _device: Option<&SharedDevice>) -> Result<SessionParts, String> {
        let scene = load_scene("builtin:cornell-box").map_err(|e| e.to_string())?;
        let rays = controls.and_then(|c| c.field).map_or(32, |f| f.rays_per_probe);
        let hysteresis = controls.and_then(|c| c.field).map_or(0.97, |f| f.hysteresis);
        let volume = DdgiVolumeSettings {
            probe_counts: glam::UVec3::splat(4),
            probe_rays_per_probe: rays,
            probe_hysteresis: hysteresis,
            ..Default::default()
        };
        let settings =
            RenderSettings { width: 24, height: 24, gi: GiMethod::Ddgi(Box::new(volume)), ..Default::default() };
        let tracer = Box::new(BvhTracer::for_scene(&scene, BvhSettings::default()));
        Ok(SessionParts {
            camera: scene.default_camera(),
            camera_path: vec![],
            settings,
            fly_speed_m_per_s: 1.0,
            adapter: None,
            gi: GiChoice::Ddgi,
            cascades: 0,
            presenter: None,
            tracer,
            scene,
        })
    }

    fn watched_file(&self) -> Option<PathBuf> {
        Some(self.watched.clone())
    }
}

/// Waits for the first report `pick` accepts.
fn wait_for<T>(
    reports: &mpsc::Receiver<WorkerReport>,
    what: &str,
    mut pick: impl FnMut(WorkerReport) -> Option<T>,
) -> T {
    let deadline = Instant::now() + Duration::from_secs(300);
    while Instant::now() < deadline {
        match reports.recv_timeout(Duration::from_secs(1)) {
            Ok(WorkerReport::Error(e)) => panic!("worker error while waiting for {what}: {e}"),
            Ok(r) => {
                if let Some(t) = pick(r) {
                    return t;
                }
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(e) => panic!("the worker stopped while waiting for {what}: {e}"),
        }
    }
    panic!("no {what} within 300 s");
}

#[test]
fn the_worker_renders_rebuilds_references_and_screenshots() {
    let dir = std::env::temp_dir().join(format!("probegi-worker-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let (cmd_tx, cmd_rx) = mpsc::channel();
    let (rep_tx, rep_rx) = mpsc::channel();
    let latest = Arc::new(Mutex::new(None));
    let link = WorkerLink { commands: cmd_rx, reports: rep_tx, latest: Arc::clone(&latest) };
    let opts = WorkerOptions { fixed_dt_s: Some(1.0 / 60.0), screenshot_dir: dir.clone(), ..Default::default() };
    let watched = dir.join("scene.toml");
    std::fs::write(&watched, "# v1\n").expect("write");
    let source = CornellSource { watched: watched.clone() };
    let worker = std::thread::spawn(move || run_worker(&source, &opts, &link, None));

    let ready = wait_for(&rep_rx, "the first session", |r| match r {
        WorkerReport::Ready(c) => Some(c),
        _ => None,
    });
    let field = ready.field.expect("a DDGI field");
    assert_eq!((field.rays_per_probe, field.hysteresis), (32, 0.97));
    let frame = || latest.lock().expect("lock").take();
    let deadline = Instant::now() + Duration::from_secs(120);
    let first = loop {
        if let Some(f) = frame() {
            break f;
        }
        assert!(Instant::now() < deadline, "no frame");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!((first.width, first.height, first.rgba.len()), (24, 24, 24 * 24 * 4));
    // 64 probes × 32 rays, less those the probe states turned off.
    assert!(first.rays > 0 && first.rays <= 64 * 32 && first.rays % 32 == 0, "probe rays: {}", first.rays);

    // A live setting and a view: no new session; a structural one: a new
    // session that keeps the live one.
    let mut c = ready.clone();
    c.field.as_mut().expect("field").hysteresis = 0.8;
    c.view = ViewMode::Indirect;
    cmd_tx.send(WorkerCommand::Controls(c.clone())).expect("send");
    c.field.as_mut().expect("field").rays_per_probe = 48;
    cmd_tx.send(WorkerCommand::Controls(c.clone())).expect("send");
    let rebuilt = wait_for(&rep_rx, "the rebuilt session", |r| match r {
        WorkerReport::Ready(c) => Some(c),
        _ => None,
    });
    let f = rebuilt.field.expect("field");
    assert_eq!((f.rays_per_probe, f.hysteresis, rebuilt.view), (48, 0.8, ViewMode::Indirect));

    // The reference: progress, then the image and FLIP of the live frame.
    cmd_tx.send(WorkerCommand::Reference(4)).expect("send");
    let done = wait_for(&rep_rx, "the reference", |r| match r {
        WorkerReport::Reference(r) if r.rgba.is_some() => Some(r),
        _ => None,
    });
    assert_eq!((done.width, done.height, done.spp), (24, 24, 4));
    let flip = done.mean_flip.expect("the camera did not move: FLIP against the live frame");
    assert!(flip > 0.0 && flip < 0.6, "FLIP of the field against its reference: {flip}");
    assert_eq!(done.heat_rgba.as_ref().map(Vec::len), Some(24 * 24 * 4));

    cmd_tx.send(WorkerCommand::Screenshot).expect("send");
    let wrote = wait_for(&rep_rx, "the screenshot", |r| match r {
        WorkerReport::Message(m) if m.starts_with("wrote") => Some(m),
        _ => None,
    });
    assert!(wrote.contains("builtin_cornell-box-frame") && wrote.contains(".png") && wrote.contains(".exr"), "{wrote}");
    let pngs = std::fs::read_dir(&dir)
        .expect("dir")
        .filter(|e| e.as_ref().is_ok_and(|e| e.path().extension().is_some_and(|x| x == "exr")))
        .count();
    assert_eq!(pngs, 1);
    // The scene file changes: the worker loads it anew, the panels' settings kept.
    std::thread::sleep(Duration::from_millis(50));
    std::fs::write(&watched, "# v2, a longer file\n").expect("write");
    let reloaded = wait_for(&rep_rx, "the reload", |r| match r {
        WorkerReport::Ready(c) => Some(c),
        _ => None,
    });
    assert_eq!(reloaded.field.map(|f| f.rays_per_probe), Some(48));
    cmd_tx.send(WorkerCommand::Quit).expect("send");
    worker.join().expect("no panic").expect("the worker ends cleanly");
    let _ = std::fs::remove_dir_all(dir);
}
