//! `probegi view`: the field through a fly camera (`probegi_view`): in a
//! window with panels, or `--headless`, the scripted run without one. Both
//! build their sessions here, from the same arguments as `probegi render`.

use anyhow::{Context, Result, bail};
use probegi_scene::{BvhSettings, BvhTracer};
use probegi_view::input_script::InputScript;
use probegi_view::scripted_run::{ScriptedOutput, ScriptedRun, frame_time_percentiles, run_scripted};

use probegi_frame::frame_loop::RenderSettings;
use probegi_view::view_layers::ViewMode;
use probegi_view::viewer_controls::{GiChoice, ViewerControls};
use probegi_view::viewer_prefs::ViewerPrefs;
use probegi_view::viewer_window::WindowOptions;
use probegi_view::viewer_worker::{FramePresenter, SessionParts, SharedDevice, ViewSource, WorkerOptions};
use probegi_wgpu::GpuContext;
use std::sync::Arc;

use crate::args::{GiArg, RenderArgs, ViewArgs};
use crate::render_outputs::write_radiance;
use crate::scene_setup::{check_posed_bounds, prepare};
use probegi_frame::frame_loop::TemporalSettings;

/// The render arguments a view run stands for (its scene, GI, volume,
/// backend; no file outputs).
fn render_args(args: &ViewArgs, frames: u32) -> RenderArgs {
    RenderArgs {
        scene: args.scene.clone(),
        gi: args.gi,
        frames,
        volume: args.volume.clone(),
        dump_atlases: None,
        show_probes: false,
        ao: None,
        area_samples: args.area_samples,
        temporal_frames: TemporalSettings::default().temporal_history_frames,
        temporal_clip_sigma: TemporalSettings::default().temporal_clip_sigma,
        out: args.screenshot.clone().unwrap_or_default(),
        stats: None,
        sequence: None,
        sequence_exr: false,
        gif: None,
        gif_fps: 25.0,
        allow_black_frames: false,
        backend: args.backend,
    }
}

pub fn run(args: &ViewArgs) -> Result<()> {
    if !args.headless {
        return run_windowed(args);
    }
    let frames = args.exit_after_frames.context("--headless needs --exit-after-frames N")?;
    check_frames(frames)?;
    if args.view.is_some() {
        bail!("--view picks the window's view; --headless renders the full frame");
    }
    let script = match &args.input_script {
        Some(p) => InputScript::load(p)?,
        None => InputScript::default(),
    };
    if let Some((f, k)) = script.first_viewer_key() {
        bail!(
            "{}: the viewer key {k:?} at frame {f} acts in the window only; --headless takes fly keys, mouse and scroll",
            args.input_script.as_deref().unwrap_or(std::path::Path::new("script")).display()
        );
    }
    if let Some(p) = &args.screenshot {
        probegi_image::check_output_path(p, true)?;
    }
    if args.fly_speed.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
        bail!("--fly-speed must be a positive number of metres per second");
    }
    let render = render_args(args, frames);
    let (scene, camera) = prepare(&args.scene, &args.volume.set, crate::render_settings::IMAGE_BYTES_PER_PIXEL)?;
    check_posed_bounds(&scene, frames.saturating_sub(1) as f32)?;
    let gi = crate::render_settings::gi_method(&scene, &render)?;
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let gpu = crate::gpu_backend::render_probe_tracer(args.backend, &gi, &scene, &bvh)?;
    let adapter = gpu.as_ref().map(|g| g.adapter_name().to_string());
    let mut settings = crate::render_settings::render_settings(&render, &scene, gi, gpu);
    settings.device_readback_lag_frames = probegi_view::view_session::VIEWER_READBACK_LAG_FRAMES;
    let diagonal = scene.bounds().map_or(1.0, |(lo, hi)| (hi - lo).length());
    // A keyframed camera plays (as in `render`) unless a --camera-* flag fixes it.
    let s = &args.scene;
    let fixed = s.camera_pos.is_some() || s.camera_target.is_some() || s.fov_y.is_some();
    let camera_path = if fixed { Vec::new() } else { scene.camera_path(frames) };
    let run = ScriptedRun {
        script: &script,
        frames,
        frame_dt_s: 1.0 / 60.0,
        fly_speed_m_per_s: args.fly_speed.unwrap_or(0.1 * diagonal),
        camera_path,
    };
    if let Some(dir) = &args.sequence {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut written: Result<()> = Ok(());
    let out = run_scripted(&scene, &bvh, &camera, &settings, &run, |f, session| {
        if let (Some(dir), Ok(())) = (&args.sequence, &written) {
            let image = session.image()?;
            written = write_radiance(&dir.join(format!("frame-{f:04}.png")), &image);
        }
        Ok(())
    })
    .map_err(anyhow::Error::msg)?;
    written?;
    if let Some(p) = &args.screenshot {
        write_radiance(p, &out.image)?;
    }
    if args.bench {
        crate::print_line(&serde_json::to_string_pretty(&bench_report(&scene.name, adapter, &out))?)?;
    }
    let at = out.camera.position_m;
    eprintln!(
        "view: {frames} frames of {}, camera at ({:.2}, {:.2}, {:.2}){}",
        scene.name,
        at.x,
        at.y,
        at.z,
        args.screenshot.as_ref().map_or(String::new(), |p| format!(", wrote {}", p.display()))
    );
    Ok(())
}

/// Frames `view --headless --bench` leaves out of its percentiles at most (a
/// quarter of the run at most): the probes' initialisation rounds.
const BENCH_WARMUP_FRAMES: usize = 10;

/// `view --headless --bench`: frame-time percentiles over the run (after the
/// warm-up frames), the host's share of each frame (its wall time less the
/// time it waited for the device), and how long
/// the field update and the camera frame take on average.
fn bench_report(scene: &str, adapter: Option<String>, out: &ScriptedOutput) -> serde_json::Value {
    // The first frames run the probes' initialisation rounds: a start-up, not the steady state.
    let warmup = (out.frame_ms.len() / 4).min(BENCH_WARMUP_FRAMES);
    let [median, p95, max] = frame_time_percentiles(&out.frame_ms[warmup..]);
    let [host_median, host_p95, host_max] = frame_time_percentiles(&out.host_ms[warmup..]);
    // The mean is the frame period: a host that runs ahead of the device has
    // quick frames and, once its frames in flight fill the ring, a slow one.
    let mean = |ms: &[f64]| ms.iter().sum::<f64>() / ms.len().max(1) as f64;
    let (frame_mean, host_mean) = (mean(&out.frame_ms[warmup..]), mean(&out.host_ms[warmup..]));
    let stats = &out.render.stats;
    serde_json::json!({
        "scene": scene,
        "adapter": adapter,
        "frames": out.frame_ms.len(),
        "warmup_frames": warmup,
        "frame_ms": { "mean": frame_mean, "median": median, "p95": p95, "max": max },
        "host_ms": { "mean": host_mean, "median": host_median, "p95": host_p95, "max": host_max },
        "field_update_ms": stats.field_update_ms,
        "camera_ms": stats.pass_ms.get("camera"),
        // The device's own times of the frame's passes (timestamp queries, read late).
        "gpu_pass_ms": stats.pass_ms.iter().filter(|(k, _)| k.starts_with("gpu_")).collect::<std::collections::BTreeMap<_, _>>(),
        "rays_per_frame": stats.rays_per_frame,
    })
}

fn check_frames(frames: u32) -> Result<()> {
    if frames == 0 || frames > 100_000 {
        bail!("--exit-after-frames {frames}: must be in 1..=100000");
    }
    Ok(())
}

/// The window (`probegi_view::viewer_window`): checks the arguments, then
/// the frame worker builds its sessions through [`CliViewSource`].
fn run_windowed(args: &ViewArgs) -> Result<()> {
    if let Some(n) = args.exit_after_frames {
        check_frames(n)?;
    }
    let script = match &args.input_script {
        Some(p) => Some(InputScript::load(p)?),
        None => None,
    };
    if let Some(p) = &args.screenshot {
        probegi_image::check_output_path(p, true)?;
    }
    if args.fly_speed.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
        bail!("--fly-speed must be a positive number of metres per second");
    }
    let start_view = match &args.view {
        Some(v) => Some(ViewMode::from_name(v).with_context(|| {
            let names: Vec<String> = ViewMode::ALL.iter().map(|m| m.label().replace(' ', "-")).collect();
            format!("--view {v}: not a view ({})", names.join(", "))
        })?),
        None => None,
    };
    if args.reference_spp == 0 {
        bail!("--reference-spp must be at least 1");
    }
    let scripted = args.exit_after_frames.is_some();
    let prefs_path = (!scripted).then(ViewerPrefs::default_path).flatten();
    let prefs = prefs_path.as_deref().map(ViewerPrefs::load).unwrap_or_default();
    let worker = WorkerOptions {
        script,
        exit_after_frames: args.exit_after_frames,
        screenshot: args.screenshot.clone(),
        // A scripted run steps the fly camera as --headless does; a person's
        // run by the wall clock.
        fixed_dt_s: (scripted || args.input_script.is_some()).then_some(1.0 / 60.0),
        adaptive_target_ms: (!scripted).then_some(prefs.cpu_target_frame_ms),
        screenshot_dir: std::env::current_dir().unwrap_or_default(),
        reference_spp: args.reference_spp,
        start_view,
    };
    let scene_name = args.scene.scene.clone();
    let window = WindowOptions {
        title: format!("probegi view: {scene_name}"),
        scene_name,
        cpu_backend: args.backend == crate::gpu_backend::Backend::Cpu,
        scripted,
        capture_path: scripted.then(|| args.screenshot.clone()).flatten(),
        prefs_path,
        start_view,
        bench: args.bench,
    };
    if args.bench && !scripted {
        bail!("--bench in the window needs --exit-after-frames N (a scripted run)");
    }
    let source = CliViewSource { args: args.clone() };
    probegi_view::viewer_window::run_window(Box::new(source), worker, window).map_err(anyhow::Error::msg)
}

/// Builds the viewer's sessions from the command line and the panels' controls.
struct CliViewSource {
    args: ViewArgs,
}

impl CliViewSource {
    /// The arguments with the panels' rebuild settings applied: the GI
    /// method and cascades, and the field settings the panels changed from
    /// what the command line built. A method other than the command line's
    /// keeps the scene-level `--set` keys only (the probe keys were for the
    /// other method).
    fn args_for(&self, controls: Option<&ViewerControls>) -> ViewArgs {
        let mut args = self.args.clone();
        let Some(c) = controls else { return args };
        let gi = match c.gi {
            GiChoice::None => GiArg::None,
            GiChoice::Ddgi => GiArg::Ddgi,
            GiChoice::Sh => GiArg::Sh,
        };
        if gi != self.args.gi {
            let set = args.volume.set.iter().filter(|a| probegi_scene::scene_file::is_scene_setting(a)).cloned();
            let cascade_ratio = args.volume.cascade_ratio;
            args.volume = crate::args::VolumeArgs { set: set.collect(), cascade_ratio, ..Default::default() };
        }
        args.gi = gi;
        if gi == GiArg::Ddgi {
            args.volume.cascades = (c.cascades > 0).then_some(c.cascades);
            if let Some(f) = c.field {
                let overrides = f.set_overrides_from(c.field_at_start.as_ref());
                if overrides.iter().any(|o| o.starts_with("probe_rays_per_probe=")) {
                    args.volume.rays_per_probe = None;
                }
                args.volume.set.extend(overrides);
            }
        }
        args
    }

    fn build(&self, controls: Option<&ViewerControls>, device: Option<&SharedDevice>) -> Result<SessionParts> {
        let args = self.args_for(controls);
        let frames = args.exit_after_frames.unwrap_or(100_000);
        let render = render_args(&args, frames);
        let (scene, camera) = prepare(&args.scene, &args.volume.set, crate::render_settings::IMAGE_BYTES_PER_PIXEL)?;
        let gi = crate::render_settings::gi_method(&scene, &render)?;
        let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
        // The window's own device, where it shares one: the frame reaches it as a texture.
        let ctx = device.map(|d| GpuContext::from_device(d.device.clone(), d.queue.clone(), d.adapter_name.clone()));
        let gpu = crate::gpu_backend::render_probe_tracer_on(args.backend, &gi, &scene, &bvh, ctx)?;
        let adapter = gpu.as_ref().map(|g| g.adapter_name().to_string());
        let presenter: Option<FramePresenter> =
            gpu.as_ref().filter(|g| device.is_some() && g.renders_camera()).map(|g| {
                let g = Arc::clone(g);
                Box::new(move |layer| g.present_frame(layer).map_err(|e| e.to_string())) as FramePresenter
            });
        let mut settings = crate::render_settings::render_settings(&render, &scene, gi, gpu);
        settings.device_readback_lag_frames = probegi_view::view_session::VIEWER_READBACK_LAG_FRAMES;
        let diagonal = scene.bounds().map_or(1.0, |(lo, hi)| (hi - lo).length());
        let s = &args.scene;
        let fixed = s.camera_pos.is_some() || s.camera_target.is_some() || s.fov_y.is_some();
        let path_frames =
            args.exit_after_frames.unwrap_or_else(|| scene.camera_keyframes.last().map_or(1, |k| k.frame as u32 + 1));
        let camera_path = if fixed { Vec::new() } else { scene.camera_path(path_frames) };
        Ok(SessionParts {
            camera,
            camera_path,
            settings: RenderSettings { camera_path: Vec::new(), ..settings },
            fly_speed_m_per_s: args.fly_speed.unwrap_or(0.1 * diagonal),
            adapter,
            gi: match args.gi {
                GiArg::None => GiChoice::None,
                GiArg::Ddgi => GiChoice::Ddgi,
                GiArg::Sh => GiChoice::Sh,
            },
            cascades: args.volume.cascades.unwrap_or(0),
            presenter,
            tracer: Box::new(bvh),
            scene,
        })
    }
}

impl ViewSource for CliViewSource {
    fn load(&self, controls: Option<&ViewerControls>, device: Option<&SharedDevice>) -> Result<SessionParts, String> {
        self.build(controls, device).map_err(|e| format!("{e:#}"))
    }

    fn watched_file(&self) -> Option<std::path::PathBuf> {
        let p = std::path::Path::new(&self.args.scene.scene);
        p.is_file().then(|| p.to_path_buf())
    }
}
