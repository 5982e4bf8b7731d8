//! `probegi view`: the field through a fly camera (`probegi_view`). Built so
//! far: the headless, scripted run; without `--headless` it says the window is
//! not built yet.

use anyhow::{Context, Result, bail};
use probegi_scene::{BvhSettings, BvhTracer};
use probegi_view::input_script::InputScript;
use probegi_view::scripted_run::{ScriptedOutput, ScriptedRun, frame_time_percentiles, run_scripted};

use crate::args::{RenderArgs, ViewArgs};
use crate::render_outputs::write_radiance;
use crate::scene_setup::{check_posed_bounds, prepare};

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
        bail!(
            "probegi view: the window is not built yet; run it scripted without one: \
             --headless --exit-after-frames N [--input-script FILE] [--screenshot FILE]"
        );
    }
    let frames = args.exit_after_frames.context("--headless needs --exit-after-frames N")?;
    if frames == 0 || frames > 100_000 {
        bail!("--exit-after-frames {frames}: must be in 1..=100000");
    }
    let script = match &args.input_script {
        Some(p) => InputScript::load(p)?,
        None => InputScript::default(),
    };
    if let Some(p) = &args.screenshot {
        probegi_image::check_output_path(p, true)?;
    }
    if args.fly_speed.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
        bail!("--fly-speed must be a positive number of metres per second");
    }
    let render = render_args(args, frames);
    let (scene, camera) = prepare(&args.scene, &args.volume.set, 160)?;
    check_posed_bounds(&scene, frames.saturating_sub(1) as f32)?;
    let gi = crate::render_settings::gi_method(&scene, &render)?;
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let gpu = crate::gpu_backend::render_probe_tracer(args.backend, &gi, &scene, &bvh)?;
    let adapter = gpu.as_ref().map(|g| g.adapter_name().to_string());
    let settings = crate::render_settings::render_settings(&render, &scene, gi, gpu);
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
    let out = run_scripted(&scene, &bvh, &camera, &settings, &run, |f, image| {
        if let (Some(dir), Ok(())) = (&args.sequence, &written) {
            written = write_radiance(&dir.join(format!("frame-{f:04}.png")), image);
        }
    })
    .map_err(anyhow::Error::msg)?;
    written?;
    if let Some(p) = &args.screenshot {
        write_radiance(p, &out.image)?;
    }
    if args.bench {
        println!("{}", serde_json::to_string_pretty(&bench_report(&scene.name, adapter, &out))?);
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

/// `view --headless --bench`: frame-time percentiles over the run and how long
/// the field update and the camera frame take on average.
fn bench_report(scene: &str, adapter: Option<String>, out: &ScriptedOutput) -> serde_json::Value {
    let [median, p95, max] = frame_time_percentiles(&out.frame_ms);
    let stats = &out.render.stats;
    serde_json::json!({
        "scene": scene,
        "adapter": adapter,
        "frames": out.frame_ms.len(),
        "frame_ms": { "median": median, "p95": p95, "max": max },
        "field_update_ms": stats.field_update_ms,
        "camera_ms": stats.pass_ms.get("camera"),
        "rays_per_frame": stats.rays_per_frame,
    })
}
