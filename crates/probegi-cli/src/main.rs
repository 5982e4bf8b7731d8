//! `probegi`: render, reference, compare, bench. Errors are reported once, here,
//! with the context chain ("loading scene x.obj: x.obj:12: ...") and exit code 1.
//!
//! This file is the command dispatch and the commands; the scene and camera
//! they start from are `scene_setup`'s, a render's settings `render_settings`',
//! what they write `render_outputs`'.

mod args;
mod atlas_dump;
mod bench;
mod gpu_backend;
mod lag;
mod memory;
mod render_outputs;
mod render_settings;
mod scene_setup;
mod view;

use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use probegi_core::camera::CameraRays;
use probegi_cpu::{PathTracer, PathTracerSettings};
use probegi_frame::frame_loop::render_frames;
use probegi_image::LoadedImage;
use probegi_scene::{BvhSettings, BvhTracer};

use args::{Cli, Command, ReferenceArgs, RenderArgs};
use render_outputs::{FrameOutputs, RenderRun, check_render_outputs, dump_set_atlases, write_radiance};
use render_settings::probe_settings;
use scene_setup::{check_posed_bounds, prepare};

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Writes `line` to stdout. A reader that closed the pipe early (`| head -1`)
/// ends the output quietly instead of a panic.
pub(crate) fn print_line(line: &str) -> Result<()> {
    use std::io::Write;
    match writeln!(std::io::stdout().lock(), "{line}") {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e).context("writing to stdout"),
        _ => Ok(()),
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        None => {
            let args = RenderArgs::try_parse_default()?;
            render(&args)
        }
        Some(Command::Render(a)) => render(&a),
        Some(Command::Reference(a)) => reference(&a),
        Some(Command::Compare(a)) => {
            let mean = probegi_image::compare_files(&a.reference, &a.test, a.out.as_deref())?;
            print_line(&format!("mean_flip: {mean:.6}"))?;
            // Two HDR images: also the share of lit pixels rendered dark and the
            // mean radiance ratio, test over reference.
            if let (Ok(LoadedImage::Hdr(r)), Ok(LoadedImage::Hdr(t))) =
                (probegi_image::read_image(&a.reference), probegi_image::read_image(&a.test))
            {
                if let Some(d) = probegi_image::compare::dark_fraction(&r, &t) {
                    print_line(&format!("dark_fraction: {d:.6}"))?;
                }
                if let Some(m) = probegi_image::compare::mean_ratio(&r, &t) {
                    print_line(&format!("mean_ratio: {:.6} {:.6} {:.6}", m.x, m.y, m.z))?;
                }
            }
            if let Some(sheet) = &a.out {
                eprintln!("wrote contact sheet {}", sheet.display());
            }
            Ok(())
        }
        Some(Command::Lag(a)) => lag::run(&a),
        Some(Command::View(a)) => view::run(&a),
        Some(Command::Bench(a)) => {
            let report = bench::run(&a)?;
            print_line(&serde_json::to_string_pretty(&report)?)
        }
    }
}

impl RenderArgs {
    /// The arguments of a bare `probegi` run: the main job, a DDGI render of the
    /// built-in Cornell box converged over 64 frames.
    fn try_parse_default() -> Result<Self> {
        let argv = ["probegi", "render", "--gi", "ddgi", "--frames", "64", "--out", "out/cornell-box.png"];
        match Cli::try_parse_from(argv)?.command {
            Some(Command::Render(a)) => Ok(a),
            _ => bail!("internal: default render arguments did not parse"),
        }
    }
}

fn progress(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({elapsed} < {eta})") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(what.to_string());
    bar
}

fn render(args: &RenderArgs) -> Result<()> {
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if !(args.temporal_clip_sigma >= 0.0 && args.temporal_clip_sigma.is_finite()) {
        bail!("--temporal-clip-sigma must be a finite number ≥ 0 (got {})", args.temporal_clip_sigma);
    }
    check_render_outputs(args)?;
    let (scene, camera) = prepare(&args.scene, &args.volume.set, crate::render_settings::IMAGE_BYTES_PER_PIXEL)?;
    check_posed_bounds(&scene, args.frames.saturating_sub(1) as f32)?;
    let gi = render_settings::gi_method(&scene, args)?;
    // Static geometry in one BVH, moving objects instanced (see probegi_scene::bvh).
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let gpu = gpu_backend::render_probe_tracer(args.backend, &gi, &scene, &bvh)?;
    let rays = CameraRays::new(&camera, args.scene.width, args.scene.height);
    let settings = render_settings::render_settings(args, &scene, gi, gpu.clone());
    let bar = progress(args.frames as u64, "render");
    let start = Instant::now();
    let mut frame_outputs = FrameOutputs::create(args)?;
    let out = render_frames(&scene, &bvh, &rays, &settings, |f, image| {
        bar.inc(1);
        frame_outputs.push(f, image);
    });
    let (image, stats) = (out.image, out.stats);
    bar.finish_and_clear();
    frame_outputs.finish(&stats, args.allow_black_frames, args.gi == args::GiArg::Sh)?;
    if stats.nonfinite_pixels > 0 {
        eprintln!(
            "warning: {} camera pixel samples came out NaN or infinite and were written as 0; check the \
             scene's materials, textures and lights for huge or non-finite values",
            stats.nonfinite_pixels
        );
    }
    let elapsed = start.elapsed();
    write_radiance(&args.out, &image)?;
    if let (Some(dir), Some(set)) = (&args.dump_atlases, &out.ddgi) {
        dump_set_atlases(dir, set)?;
    }
    if let Some(path) = &args.ao {
        let set = out.ddgi.as_ref().filter(|s| s.has_shadow_field());
        let set = set.context("--ao writes the shadowing field's image: it needs --gi ddgi --set shadow_field=true")?;
        let (w, h) = (args.scene.width, args.scene.height);
        let ao = probegi_cpu::light_visibility::light_visibility_image(&scene, &bvh, &rays, w, h, Some(set));
        probegi_image::write_image(path, &ao).with_context(|| format!("writing {}", path.display()))?;
    }
    eprintln!(
        "wrote {} ({}×{}, {} frame{}, {:.2} s, scene {})",
        args.out.display(),
        image.width,
        image.height,
        stats.frames,
        if stats.frames == 1 { "" } else { "s" },
        elapsed.as_secs_f64(),
        scene.name
    );
    if let Some(path) = &args.stats {
        let run = RenderRun { args, scene: &scene, bvh: &bvh, gpu: gpu.as_deref(), image: &image, stats: &stats };
        render_outputs::write_render_stats(path, &run)?;
    }
    Ok(())
}

fn reference(args: &ReferenceArgs) -> Result<()> {
    if args.spp == 0 {
        bail!("--spp must be at least 1");
    }
    if args.max_depth == 0 || args.max_depth > 4096 {
        bail!("--max-depth must be in 1..=4096 (got {})", args.max_depth);
    }
    probegi_image::check_output_path(&args.out, true)?;
    if let Some(p) = &args.ao {
        probegi_image::check_output_path(p, true)?;
    }
    if !args.frame.is_finite() {
        bail!("--frame must be a finite frame number");
    }
    let (mut scene, camera) = prepare(&args.scene, &args.set, 16)?;
    check_posed_bounds(&scene, args.frame.max(0.0))?;
    if let Some(a) = probe_settings(&args.set).next() {
        bail!(
            "--set {a}: the reference takes scene settings only ({})",
            probegi_scene::scene_file::SCENE_SETTING_KEYS.join(", ")
        );
    }
    let base = scene.clone();
    scene.set_frame_from(&base, args.frame);
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    // A keyframed camera is where it is at --frame, unless --camera-* fixes it.
    let fixed = args.scene.camera_pos.is_some() || args.scene.camera_target.is_some() || args.scene.fov_y.is_some();
    let camera = match scene.camera_at(args.frame) {
        Some(c) if !fixed => c,
        _ => camera,
    };
    let rays = CameraRays::new(&camera, args.scene.width, args.scene.height);
    let settings = PathTracerSettings {
        pt_spp: args.spp,
        pt_max_depth: args.max_depth,
        seed: args.scene.seed,
        ..Default::default()
    };
    let pt = PathTracer::new(&scene, &bvh, settings);
    let bar = progress(args.scene.height as u64, "reference");
    let start = Instant::now();
    let (image, counters) = pt.render(&rays, args.scene.width, args.scene.height, &|| bar.inc(1));
    bar.finish_and_clear();
    let secs = start.elapsed().as_secs_f64();
    write_radiance(&args.out, &image)?;
    if let Some(path) = &args.ao {
        let ao = probegi_cpu::light_visibility::light_visibility_image(
            &scene,
            &bvh,
            &rays,
            args.scene.width,
            args.scene.height,
            None,
        );
        probegi_image::write_image(path, &ao).with_context(|| format!("writing {}", path.display()))?;
    }
    eprintln!(
        "wrote {} ({}×{}, {} spp, {:.2} s, {:.2} Mrays/s, scene {})",
        args.out.display(),
        image.width,
        image.height,
        args.spp,
        secs,
        counters.rays_traced as f64 / secs / 1e6,
        scene.name
    );
    Ok(())
}
