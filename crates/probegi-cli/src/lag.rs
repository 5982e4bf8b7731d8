//! `probegi lag`: convergence lag after a step change (seed 000 §5.1, seed 004
//! §4.3). In the door room, either the sun switches on or a panel appears in the
//! doorway at frame `frames_before`; every frame after it is compared by FLIP with
//! the converged image of the new state (the same scene held in that state for
//! `--target-frames`, 400 by default). The lag is the first frame after the step from which FLIP stays below
//! `--flip-threshold`. It is measured for each hysteresis, with the fast-
//! convergence heuristics (Listing 3 thresholds and scene events) on and off.
//!
//! The frame loop reports the events as an application would: a light switching
//! on is a large light change, an object jumping by more than a probe cell a large
//! object change.

use anyhow::{Context, Result};
use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::image::Image;
use probegi_cpu::DirectSettings;
use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_image::plot::{LinePlot, PALETTE, Series};
use probegi_scene::light::LightKeyframe;
use probegi_scene::{BvhSettings, BvhTracer, ObjectAnimation, Scene, TransformKeyframe, load_scene};

use crate::args::LagArgs;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Step {
    LightOn,
    Occluder,
}

impl Step {
    fn name(self) -> &'static str {
        match self {
            Step::LightOn => "light on",
            Step::Occluder => "occluder",
        }
    }
}

/// The door room with the step at frame `at`; `held` keeps the after-step state
/// from frame 0 (for the converged target).
fn step_scene(step: Step, at: f32, held: bool) -> Result<Scene> {
    let mut s = load_scene("builtin:door-room")?;
    let before = if held { -2.0 } else { at - 1.0 };
    let after = if held { -1.0 } else { at };
    let sun = s.lights[0].intensity;
    let key = |frame, intensity| LightKeyframe { frame, position: None, direction: None, intensity: Some(intensity) };
    match step {
        Step::LightOn => s.lights[0].keyframes = vec![key(before, 0.0), key(after, sun)],
        Step::Occluder => {
            // Keyframes that change nothing keep the scene animated like the other cases.
            s.lights[0].keyframes = vec![key(0.0, sun)];
            let place = |frame, y| TransformKeyframe {
                frame,
                translation: Some(Vec3::new(0.0, y, 0.0)),
                rotation: None,
                scale: None,
            };
            let animation =
                ObjectAnimation { keyframes: vec![place(before, -50.0), place(after, 0.0)], ..Default::default() };
            let panel = |m: &mut probegi_scene::mesh::Mesh| {
                probegi_scene::builtin::add_box(m, Vec3::new(1.4, 0.0, 4.0), Vec3::new(2.0, 2.2, 4.2), 0)
            };
            s.add_object("door panel", panel, animation);
        }
    }
    s.validate().map_err(anyhow::Error::msg)?;
    Ok(s)
}

struct Run {
    step: Step,
    hysteresis: f32,
    heuristics: bool,
    /// FLIP of each frame after the step against the converged target.
    flip: Vec<f32>,
    lag: Option<usize>,
}

fn render_sequence(
    scene: &Scene,
    frames: u32,
    size: u32,
    seed: u64,
    volume: &DdgiVolumeSettings,
    from: u32,
) -> Vec<Image> {
    let bvh = BvhTracer::for_scene(scene, BvhSettings::default());
    let camera = scene.default_camera();
    let rays = CameraRays::new(&camera, size, size);
    let settings = RenderSettings {
        width: size,
        height: size,
        frames,
        seed,
        gi: GiMethod::Ddgi(Box::new(volume.clone())),
        direct: DirectSettings::default(),
        show_probes: false,
        camera_path: Vec::new(),
        probe_tracer: None,
        temporal: Default::default(),
        device_readback_lag_frames: 0,
    };
    let mut out = vec![];
    render_frames(scene, &bvh, &rays, &settings, |f, image| {
        if f >= from {
            out.push(image());
        }
    });
    out
}

/// The volume of a stepped run: `base` with hysteresis `h`, the heuristics on
/// or off, then each of `set` (`--set`, e.g. a ray budget).
fn stepped_volume(base: &DdgiVolumeSettings, h: f32, heuristics: bool, set: &[String]) -> Result<DdgiVolumeSettings> {
    let mut v = DdgiVolumeSettings { probe_hysteresis: h, probe_fast_convergence: heuristics, ..base.clone() };
    for a in set {
        v = probegi_scene::scene_file::apply_volume_override(&v, a)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--set {a}"))?;
    }
    Ok(v)
}

/// First index from which every value is at most `threshold`.
fn settled_from(flip: &[f32], threshold: f32) -> Option<usize> {
    let last_above = flip.iter().rposition(|&v| v > threshold);
    match last_above {
        None => Some(0),
        Some(i) if i + 1 < flip.len() => Some(i + 1),
        Some(_) => None,
    }
}

pub fn run(args: &LagArgs) -> Result<()> {
    anyhow::ensure!(args.size > 0 && args.frames_after > 0, "--size and --frames-after must be positive");
    anyhow::ensure!(args.size <= 4096, "--size {} is more than 4096 pixels a side", args.size);
    anyhow::ensure!(
        args.frames_before as u64 + args.frames_after as u64 <= 100_000 && args.target_frames <= 100_000,
        "--frames-before, --frames-after and --target-frames must stay within 100000 frames"
    );
    // Each rendered frame of the sequence is kept (RGB f32) for the FLIP curve.
    let frames = args.frames_before as u64 + args.frames_after as u64 + 1;
    crate::memory::check_memory(frames * args.size as u64 * args.size as u64 * 12 * 2, "the lag sequences")?;
    anyhow::ensure!(args.hysteresis.iter().all(|h| (0.0..1.0).contains(h)), "--hysteresis values must lie in [0, 1)");
    let mut volume = load_scene("builtin:door-room")?.volume.context("door room volume")?;
    volume.probe_rays_per_probe = args.rays_per_probe;
    volume.validate().map_err(|(f, why)| anyhow::anyhow!("{f}: {why}"))?;
    stepped_volume(&volume, volume.probe_hysteresis, true, &args.set)?; // bad --set fails before any frame
    let at = args.frames_before;
    let mut runs = vec![];
    for step in [Step::LightOn, Step::Occluder] {
        let target_scene = step_scene(step, at as f32, true)?;
        let n = args.target_frames.max(1);
        let target = render_sequence(&target_scene, n, args.size, args.seed, &volume, n - 1).remove(0);
        let scene = step_scene(step, at as f32, false)?;
        for &h in &args.hysteresis {
            for heuristics in [true, false] {
                let v = stepped_volume(&volume, h, heuristics, &args.set)?;
                let frames = render_sequence(&scene, at + args.frames_after, args.size, args.seed, &v, at);
                let flip: Vec<f32> = frames
                    .iter()
                    .map(|f| probegi_image::mean_flip_hdr(&target, f))
                    .collect::<Option<_>>()
                    .context("frame sizes differ")?;
                let lag = settled_from(&flip, args.flip_threshold);
                eprintln!(
                    "{:9} hysteresis {h:.2} heuristics {:3}: lag {} frames (FLIP after 1 frame {:.3}, after 10 {:.3})",
                    step.name(),
                    if heuristics { "on" } else { "off" },
                    lag.map_or(format!(">{}", args.frames_after), |l| l.to_string()),
                    flip[0],
                    flip[9.min(flip.len() - 1)]
                );
                runs.push(Run { step, hysteresis: h, heuristics, flip, lag });
            }
        }
    }
    write_outputs(args, &runs)
}

fn write_outputs(args: &LagArgs, runs: &[Run]) -> Result<()> {
    let stem = args.out.with_extension("");
    let name = stem.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    // Beside the plot, named after it (`with_extension` would cut a stem
    // such as `lag-0.1` at its dot).
    let csv_path = stem.with_file_name(format!("{name}.csv"));
    let mut csv = String::from("step,hysteresis,heuristics,lag_frames,flip_after_1,flip_after_10,flip_last\n");
    for r in runs {
        let at = |k: usize| r.flip[k.min(r.flip.len() - 1)];
        csv += &format!(
            "{},{},{},{},{:.4},{:.4},{:.4}\n",
            r.step.name(),
            r.hysteresis,
            r.heuristics,
            r.lag.map_or(format!(">{}", args.frames_after), |l| l.to_string()),
            at(0),
            at(9),
            at(usize::MAX)
        );
    }
    if let Some(dir) = csv_path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;

    let mut lag_plot = LinePlot {
        title: format!("FRAMES TO FLIP < {} AFTER A STEP (DOOR ROOM)", args.flip_threshold),
        x_label: "HYSTERESIS".into(),
        y_label: "FRAMES".into(),
        guides: vec![(args.frames_after as f64, format!("NOT CONVERGED IN {}", args.frames_after))],
        ..Default::default()
    };
    for (k, (step, heuristics)) in
        [(Step::LightOn, true), (Step::LightOn, false), (Step::Occluder, true), (Step::Occluder, false)]
            .into_iter()
            .enumerate()
    {
        let points = runs
            .iter()
            .filter(|r| r.step == step && r.heuristics == heuristics)
            .map(|r| (r.hysteresis as f64, r.lag.unwrap_or(args.frames_after as usize) as f64))
            .collect();
        lag_plot.series.push(Series {
            label: format!("{} HEUR {}", step.name(), if heuristics { "ON" } else { "OFF" }),
            rgb: PALETTE[k / 2 * 3],
            points,
            dashed: !heuristics,
        });
    }
    lag_plot.write_png(&args.out)?;

    let curves_path = stem.with_file_name(format!("{name}-curves.png"));
    write_curves(args, runs, Step::LightOn, &curves_path)?;
    let occluder_path = stem.with_file_name(format!("{name}-occluder-curves.png"));
    write_curves(args, runs, Step::Occluder, &occluder_path)?;
    eprintln!(
        "wrote {}, {}, {} and {}",
        args.out.display(),
        curves_path.display(),
        occluder_path.display(),
        csv_path.display()
    );
    Ok(())
}

/// The per-frame FLIP curves of `step`'s runs into `path`.
fn write_curves(args: &LagArgs, runs: &[Run], step: Step, path: &std::path::Path) -> Result<()> {
    let mut curves = LinePlot {
        title: format!("{}: FLIP AGAINST THE CONVERGED IMAGE", step.name().to_uppercase()),
        x_label: "FRAMES AFTER THE STEP".into(),
        y_label: "FLIP".into(),
        guides: vec![(args.flip_threshold as f64, "THRESHOLD".into())],
        ..Default::default()
    };
    for (k, r) in runs.iter().filter(|r| r.step == step).enumerate() {
        curves.series.push(Series {
            label: format!("H {} {}", r.hysteresis, if r.heuristics { "ON" } else { "OFF" }),
            rgb: PALETTE[(k / 2) % PALETTE.len()],
            points: r.flip.iter().enumerate().map(|(i, &v)| (i as f64 + 1.0, v as f64)).collect(),
            dashed: !r.heuristics,
        });
    }
    Ok(curves.write_png(path)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settled_means_below_from_then_on() {
        assert_eq!(settled_from(&[0.5, 0.04, 0.06, 0.03, 0.02], 0.05), Some(3));
        assert_eq!(settled_from(&[0.01, 0.02], 0.05), Some(0));
        assert_eq!(settled_from(&[0.5, 0.4], 0.05), None);
    }
}
