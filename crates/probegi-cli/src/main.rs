//! `probegi`: render, reference, compare, bench. Errors are reported once, here,
//! with the context chain ("loading scene x.obj: x.obj:12: ...") and exit code 1.

mod args;
mod atlas_dump;
mod bench;
mod gpu_backend;
mod lag;

use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use probegi_core::camera::{Camera, CameraRays};
use probegi_cpu::frame_loop::{GiMethod, RenderSettings, render_frames};
use probegi_cpu::{DirectSettings, PathTracer, PathTracerSettings};
use probegi_field::{ProbeBatchTracer, ProbeTracerHandle};
use probegi_scene::{BvhSettings, BvhTracer, Scene, load_scene};

use args::{Cli, Command, GiArg, ReferenceArgs, RenderArgs, SceneArgs, VolumeArgs};
use probegi_core::ddgi_settings::{DdgiFieldSetSettings, DdgiVolumeSettings};
use probegi_core::sh_settings::ShProbeSettings;
use probegi_cpu::probe_trace::ddgi_volume_bytes;

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
            println!("mean_flip: {mean:.6}");
            if let Some(sheet) = &a.out {
                eprintln!("wrote contact sheet {}", sheet.display());
            }
            Ok(())
        }
        Some(Command::Lag(a)) => lag::run(&a),
        Some(Command::Bench(a)) => {
            let report = bench::run(&a)?;
            println!("{}", serde_json::to_string_pretty(&report)?);
            Ok(())
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

/// Fails if `bytes` exceeds the memory this machine has available.
pub fn check_memory(bytes: u64, what: &str) -> Result<()> {
    let (available, source) = memory_available();
    if bytes > available {
        bail!(
            "{what} would need {:.1} GiB but only {:.1} GiB of memory is available ({source})",
            bytes as f64 / (1u64 << 30) as f64,
            available as f64 / (1u64 << 30) as f64
        );
    }
    Ok(())
}

/// Memory this process may still use, and what limits it: the least of the
/// system's MemAvailable, the cgroup's limit less its usage (v2, then v1), and
/// the address-space rlimit (`ulimit -v`) less the process's current size.
fn memory_available() -> (u64, &'static str) {
    let read = |p: &str| std::fs::read_to_string(p).ok();
    let kib_field = |text: &str, key: &str| {
        text.lines()
            .find(|l| l.starts_with(key))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|kb| kb.parse::<u64>().ok())
            .map(|kb| kb * 1024)
    };
    let number = |t: Option<String>| t.and_then(|t| t.trim().parse::<u64>().ok());
    let mut limits: Vec<(u64, &'static str)> = vec![];
    if let Some(avail) = read("/proc/meminfo").and_then(|m| kib_field(&m, "MemAvailable:")) {
        limits.push((avail, "MemAvailable"));
    }
    let cgroup = match number(read("/sys/fs/cgroup/memory.max")) {
        Some(max) => Some((max, number(read("/sys/fs/cgroup/memory.current")).unwrap_or(0))),
        None => number(read("/sys/fs/cgroup/memory/memory.limit_in_bytes"))
            .map(|max| (max, number(read("/sys/fs/cgroup/memory/memory.usage_in_bytes")).unwrap_or(0))),
    };
    if let Some((max, used)) = cgroup {
        limits.push((max.saturating_sub(used), "the cgroup's memory limit"));
    }
    let address_space = read("/proc/self/limits").and_then(|l| {
        let line = l.lines().find(|l| l.starts_with("Max address space"))?.to_string();
        line.split_whitespace().nth(3)?.parse::<u64>().ok()
    });
    if let Some(limit) = address_space {
        let size = read("/proc/self/status").and_then(|s| kib_field(&s, "VmSize:")).unwrap_or(0);
        limits.push((limit.saturating_sub(size), "the address-space limit (ulimit -v)"));
    }
    limits.into_iter().min_by_key(|l| l.0).unwrap_or((16 << 30, "assumed: no limit could be read"))
}

/// Loads the scene and resolves the camera and sky the arguments ask for.
fn prepare(args: &SceneArgs, set: &[String], bytes_per_pixel: u64) -> Result<(Scene, Camera)> {
    if args.width == 0 || args.height == 0 {
        bail!("--width and --height must be at least 1 (got {}×{})", args.width, args.height);
    }
    if args.width > 65_536 || args.height > 65_536 {
        bail!("--width and --height must be at most 65536 (got {}×{})", args.width, args.height);
    }
    check_memory(args.width as u64 * args.height as u64 * bytes_per_pixel, "the image buffers")?;
    let mut scene = load_scene(&args.scene).with_context(|| format!("loading scene {}", args.scene))?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    apply_scene_settings(&mut scene, set)?;
    if let Some(sky) = args.sky {
        if sky.min_element() < 0.0 {
            bail!("--sky {sky} must be non-negative");
        }
        scene.sky_radiance = sky;
    }
    let mut camera = scene.default_camera();
    if let Some(p) = args.camera_pos {
        camera.position = p;
    }
    if let Some(t) = args.camera_target {
        camera.target = t;
    }
    if let Some(u) = args.camera_up {
        camera.up = u;
    }
    if let Some(f) = args.fov_y {
        camera.fov_y_deg = f;
    }
    camera.validate().map_err(anyhow::Error::msg).with_context(|| {
        format!(
            "invalid camera for scene {} (position {}, target {}, up {}); --camera-pos, --camera-target, \
             --camera-up and --fov-y set it",
            args.scene, camera.position, camera.target, camera.up
        )
    })?;
    Ok((scene, camera))
}

/// Writes a rendered image; a non-finite pixel (which `write_image` refuses, naming
/// it) gets a hint at its usual causes.
fn write_radiance(path: &std::path::Path, image: &probegi_core::image::Image) -> Result<()> {
    probegi_image::write_image(path, image).map_err(|e| {
        let hint = matches!(e, probegi_image::ImageError::NonFinite { .. }).then_some(
            "; check the scene's materials (Kd, Ke, emissive factors), textures and light intensities for huge or \
             non-finite values",
        );
        anyhow::anyhow!("{e}{}", hint.unwrap_or(""))
    })
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
    check_render_outputs(args)?;
    // G-buffer texel, frame and accumulation buffers.
    let (scene, camera) = prepare(&args.scene, &args.volume.set, 160)?;
    check_posed_bounds(&scene, args.frames.saturating_sub(1) as f32)?;
    let v = &args.volume;
    if args.gi == GiArg::None
        && (v.probes.is_some() || v.rays_per_probe.is_some() || probe_settings(&v.set).next().is_some())
    {
        bail!("--probes, --rays-per-probe and --set configure probes: they need --gi ddgi or --gi sh");
    }
    if args.gi != GiArg::Ddgi && v.cascades.is_some() {
        bail!("--cascades configures DDGI volumes: it needs --gi ddgi");
    }
    let gi = match args.gi {
        GiArg::None => GiMethod::None,
        GiArg::Ddgi => ddgi_method(&scene, &args.volume)?,
        GiArg::Sh => GiMethod::Sh(Box::new(sh_settings(&scene, &args.volume)?)),
    };
    if !matches!(gi, GiMethod::Ddgi(_) | GiMethod::DdgiSet(_)) && (args.dump_atlases.is_some() || args.show_probes) {
        bail!("--dump-atlases and --show-probes need --gi ddgi");
    }
    // Static geometry in one BVH, moving objects instanced (see probegi_scene::bvh).
    let bvh = BvhTracer::for_scene(&scene, BvhSettings::default());
    let gpu = match args.backend {
        gpu_backend::Backend::Cpu => None,
        gpu_backend::Backend::Wgpu => {
            if !matches!(gi, GiMethod::Ddgi(_) | GiMethod::DdgiSet(_)) {
                bail!("--backend wgpu runs the DDGI field and its camera frame on the GPU: it needs --gi ddgi");
            }
            Some(std::sync::Arc::new(gpu_backend::wgpu_probe_tracer(&scene, &bvh)?))
        }
    };
    let rays = CameraRays::new(&camera, args.scene.width, args.scene.height);
    let camera_path = camera_path(&scene, &args.scene, args.frames);
    let settings = RenderSettings {
        width: args.scene.width,
        height: args.scene.height,
        frames: args.frames,
        seed: args.scene.seed,
        gi,
        direct: DirectSettings { direct_area_samples: args.area_samples, ..Default::default() },
        show_probes: args.show_probes,
        camera_path,
        probe_tracer: gpu.clone().map(|g| ProbeTracerHandle(g as std::sync::Arc<dyn ProbeBatchTracer>)),
    };
    let bar = progress(args.frames as u64, "render");
    let start = Instant::now();
    if let Some(dir) = &args.sequence {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut gif = match &args.gif {
        Some(path) => Some(probegi_image::AnimatedGif::create(path, args.gif_fps)?),
        None => None,
    };
    let mut sequence_error = None;
    let mut sequence_written: Vec<std::path::PathBuf> = Vec::new();
    let out = render_frames(&scene, &bvh, &rays, &settings, |f, image| {
        bar.inc(1);
        if sequence_error.is_some() || (args.sequence.is_none() && gif.is_none()) {
            return;
        }
        let img = image();
        if let Some(dir) = &args.sequence {
            let mut names = vec![format!("frame-{f:04}.png")];
            if args.sequence_exr {
                names.push(format!("frame-{f:04}.exr"));
            }
            for path in names.into_iter().map(|n| dir.join(n)) {
                match probegi_image::write_image(&path, &img) {
                    Ok(()) => sequence_written.push(path),
                    Err(e) => {
                        sequence_error = Some(e);
                        break;
                    }
                }
            }
        }
        if let (Some(g), None) = (gif.as_mut(), &sequence_error) {
            sequence_error = g.push(&img).err();
        }
    });
    let (image, stats) = (out.image, out.stats);
    bar.finish_and_clear();
    let failure = match sequence_error {
        Some(e) => Some(anyhow::Error::new(e).context(
            "writing the --sequence / --gif frames (this run's frames were removed); a non-finite pixel \
             usually comes from a material, texture or light with huge or non-finite values",
        )),
        None => render_failure(&stats, args.allow_black_frames),
    };
    if let Some(e) = failure {
        // No partial sequence that looks complete: this run's frames go too, and
        // the unfinished GIF's temporary file goes when `gif` drops.
        for path in &sequence_written {
            std::fs::remove_file(path).ok();
        }
        return Err(e);
    }
    if let Some(g) = gif {
        g.finish()?;
    }
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
        for (i, volume) in set.volumes().iter().enumerate() {
            // One volume: its atlases in DIR as before; several: DIR/volume-I each.
            let d = if set.volumes().len() == 1 { dir.clone() } else { dir.join(format!("volume-{i}")) };
            atlas_dump::dump_atlases(&d, volume)?;
        }
        eprintln!("wrote atlases to {}", dir.display());
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
        write_text(path, &serde_json::to_string_pretty(&render_stats_json(&run)?)?)?;
    }
    Ok(())
}

/// What a finished render's `--stats` reports from.
struct RenderRun<'a> {
    args: &'a RenderArgs,
    scene: &'a Scene,
    bvh: &'a BvhTracer,
    gpu: Option<&'a probegi_wgpu::wgpu_field_backend::WgpuProbeTracer>,
    image: &'a probegi_core::image::Image,
    stats: &'a probegi_cpu::frame_loop::RenderStats,
}

/// The `--stats` JSON of a render.
fn render_stats_json(run: &RenderRun<'_>) -> Result<serde_json::Value> {
    Ok(serde_json::json!({
        "backend": format!("{:?}", run.args.backend).to_lowercase(),
        "adapter": run.gpu.map(|g| g.adapter_name().to_string()),
        "probe_shade_on": run.gpu.map(|g| if g.shades() { "gpu" } else { "cpu" }),
        // --show-probes draws on the CPU's G-buffer, so its camera frame is the CPU's.
        "camera_on": if run.gpu.is_some_and(|g| g.renders_camera()) && !run.args.show_probes { "gpu" } else { "cpu" },
        "frames": run.stats.frames,
        "pass_ms": run.stats.pass_ms,
        "rays_traced": run.stats.rays_traced,
        "width": run.image.width,
        "height": run.image.height,
        "triangles": run.scene.drawn_triangle_count(),
        "stored_triangles": run.scene.stored_triangle_count(),
        "instances": run.scene.instances.len(),
        "bvh_build_ms": run.bvh.build_time.as_secs_f64() * 1e3,
        "probes": run.stats.probes,
        "rays_per_frame": run.stats.rays_per_frame,
        "field_update_ms": run.stats.field_update_ms,
        "field_update_mrays_per_s": run.stats.field_update_mrays_per_s,
        "probe_states": run.stats.probe_states,
        "active_probes": run.stats.active_probes,
        "volumes": run.stats.volumes,
        "batch_rays": run.stats.batch_rays,
        "batch_rays_per_volume": run.stats.batch_rays_per_volume,
        "probes_scrolled_in": run.stats.probes_scrolled_in,
        "probes_woken": run.stats.probes_woken,
        "frame_means": run.stats.frame_means.iter().map(|m| [m.x, m.y, m.z]).collect::<Vec<_>>(),
        "frame_indirect_means": run.stats.frame_indirect_means.iter().map(|m| [m.x, m.y, m.z]).collect::<Vec<_>>(),
        "frame_unlit_fraction": run.stats.frame_unlit_fraction,
        // Rays answered without a full BVH walk (probegi_scene::bvh_walk): the
        // ray rule's misses and walks cut short, per backend.
        "trace_guards_cpu": run.bvh.trace_guard_counts(),
        "nonfinite_pixels": run.stats.nonfinite_pixels,
        "trace_guards_gpu": run.gpu.map(|g| g.bvh.trace_guard_counts(&g.ctx)).transpose()?,
    }))
}

/// The scene-level `--set` keys (`normal_maps`, `alpha_cutouts`) among `set`.
pub fn apply_scene_settings(scene: &mut Scene, set: &[String]) -> Result<()> {
    for a in set.iter().filter(|a| probegi_scene::scene_file::is_scene_setting(a)) {
        probegi_scene::scene_file::apply_scene_setting(scene, a)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--set {a}"))?;
    }
    Ok(())
}

/// The `--set` assignments that configure probes (not the scene).
pub fn probe_settings(set: &[String]) -> impl Iterator<Item = &String> {
    set.iter().filter(|a| !probegi_scene::scene_file::is_scene_setting(a))
}

/// The DDGI of `render --gi ddgi`: `--cascades`, else the scene file's
/// `[[volumes]]`, else one volume (the file's `[volume]` or the defaults).
pub fn ddgi_method(scene: &Scene, args: &VolumeArgs) -> Result<GiMethod> {
    if let Some(n) = args.cascades {
        if n == 0 || n > 16 {
            bail!("--cascades {n}: must be in 1..=16");
        }
        let r = args.cascade_ratio;
        if !(1.0..=16.0).contains(&r) {
            bail!("--cascade-ratio {r}: must be in [1, 16]");
        }
        let base = volume_settings(scene, args)?;
        let spacing = match base.probe_spacing_m {
            Some(s) => s,
            None => {
                // The coarsest cascade's probe box spans the scene bounds.
                let (lo, hi) = scene.bounds().unwrap_or((glam::Vec3::splat(-1.0), glam::Vec3::ONE));
                let cells = (base.probe_counts.as_vec3() - glam::Vec3::ONE).max(glam::Vec3::ONE);
                ((hi - lo) / cells / r.powi(n as i32 - 1)).max(glam::Vec3::splat(1e-3))
            }
        };
        let set = DdgiFieldSetSettings::cascades(n, &base, spacing, r);
        set.validate().map_err(|(i, f, why)| anyhow::anyhow!("cascade {i}: volume setting {f}: {why}"))?;
        check_memory(set.volumes.iter().map(ddgi_volume_bytes).sum(), "the DDGI cascades")?;
        return Ok(GiMethod::DdgiSet(Box::new(set)));
    }
    if !scene.volumes.is_empty() {
        if args.probes.is_some() {
            bail!(
                "--probes would refit every one of the scene's [[volumes]] to the scene bounds; change their \
                 probe_counts in the file, or use --cascades"
            );
        }
        let mut volumes = Vec::new();
        for v in &scene.volumes {
            volumes.push(apply_volume_args(v.clone(), args)?);
        }
        let set = DdgiFieldSetSettings { volumes, blending: probegi_core::ddgi_volume_blend::VolumeBlending::Density };
        check_memory(set.volumes.iter().map(ddgi_volume_bytes).sum(), "the DDGI volumes")?;
        return Ok(GiMethod::DdgiSet(Box::new(set)));
    }
    Ok(GiMethod::Ddgi(Box::new(volume_settings(scene, args)?)))
}

/// The camera of every frame when the scene's camera is keyframed and no
/// `--camera-*` option fixes it; empty otherwise.
fn camera_path(scene: &Scene, args: &SceneArgs, frames: u32) -> Vec<CameraRays> {
    let fixed = args.camera_pos.is_some() || args.camera_target.is_some() || args.fov_y.is_some();
    if fixed || !scene.has_camera_animation() {
        return Vec::new();
    }
    scene.camera_path(frames).iter().map(|c| CameraRays::new(c, args.width, args.height)).collect()
}

/// `--probes`, `--rays-per-probe` and each `--set`, in order, over `s`.
fn apply_volume_args(mut s: DdgiVolumeSettings, args: &VolumeArgs) -> Result<DdgiVolumeSettings> {
    if let Some(p) = args.probes {
        s.probe_counts = glam::UVec3::from(p);
        s.probe_origin_m = None;
        s.probe_spacing_m = None;
    }
    if let Some(r) = args.rays_per_probe {
        s.probe_rays_per_probe = r;
    }
    for a in probe_settings(&args.set) {
        s = probegi_scene::scene_file::apply_volume_override(&s, a)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--set {a}"))?;
    }
    s.validate().map_err(|(field, why)| anyhow::anyhow!("volume setting {field}: {why}"))?;
    check_memory(ddgi_volume_bytes(&s), "the DDGI volume")?;
    Ok(s)
}

/// Volume settings: the papers' defaults, then the scene file's `[volume]`, then
/// `--probes`, `--rays-per-probe` and each `--set` in order.
pub fn volume_settings(scene: &Scene, args: &VolumeArgs) -> Result<DdgiVolumeSettings> {
    apply_volume_args(scene.volume.clone().unwrap_or_default(), args)
}

/// SH probe settings: the paper's defaults, then the scene file's `[sh]`, then each
/// `--set`. `--probes` sets the probe counts of every cascade.
pub fn sh_settings(scene: &Scene, args: &VolumeArgs) -> Result<ShProbeSettings> {
    let mut s = scene.sh_probes.clone().unwrap_or_default();
    if let Some(p) = args.probes {
        s.sh_cascade_probe_counts = glam::UVec3::from(p);
    }
    if args.rays_per_probe.is_some() {
        bail!("--rays-per-probe is a DDGI setting; SH probes trace no rays (see --set sh_screen_samples)");
    }
    for a in probe_settings(&args.set) {
        s = probegi_scene::scene_file::apply_sh_override(&s, a)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--set {a}"))?;
    }
    s.validate().map_err(|(field, why)| anyhow::anyhow!("SH setting {field}: {why}"))?;
    Ok(s)
}

fn reference(args: &ReferenceArgs) -> Result<()> {
    if args.spp == 0 {
        bail!("--spp must be at least 1");
    }
    if args.max_depth == 0 || args.max_depth > 4096 {
        bail!("--max-depth must be in 1..=4096 (got {})", args.max_depth);
    }
    probegi_image::check_output_path(&args.out, true)?;
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

/// Why a finished render must not be written: the frame loop stopped early,
/// or frames came out all black though the scene has light sources and the
/// camera sees surfaces with a diffuse albedo (`RenderStats::black_frames`).
fn render_failure(stats: &probegi_cpu::frame_loop::RenderStats, allow_black_frames: bool) -> Option<anyhow::Error> {
    if let Some(e) = &stats.error {
        return Some(anyhow::anyhow!("render stopped: {e}; nothing was written"));
    }
    if stats.black_frames.is_empty() || allow_black_frames {
        return None;
    }
    Some(anyhow::anyhow!(
        "frame{} {:?} came out all black although the scene has light sources and the camera sees diffuse \
         surfaces: this is almost always a bug (please report it with the scene); nothing was written. \
         --allow-black-frames accepts such frames (a view where every light is hidden)",
        if stats.black_frames.len() == 1 { "" } else { "s" },
        stats.black_frames
    ))
}

/// Every output of a render checked before it starts, so that a long render
/// does not fail at its end (`probegi_image::check_output_path`).
fn check_render_outputs(args: &RenderArgs) -> Result<()> {
    probegi_image::check_output_path(&args.out, true)?;
    if let Some(p) = &args.stats {
        probegi_image::check_output_path(p, false)?;
    }
    if let Some(p) = &args.gif {
        probegi_image::check_output_path(p, false)?;
    }
    for dir in [&args.sequence, &args.dump_atlases].into_iter().flatten() {
        if dir.exists() && !dir.is_dir() {
            bail!("{}: exists and is not a directory", dir.display());
        }
        probegi_image::check_output_path(&dir.join("frame-0000.png"), true)?;
    }
    Ok(())
}

/// Moving geometry must stay inside the coordinate bound of loaded geometry
/// at every frame up to `last_frame` (`Scene::check_posed_bounds`).
fn check_posed_bounds(scene: &Scene, last_frame: f32) -> Result<()> {
    scene.check_posed_bounds(last_frame).map_err(|e| anyhow::anyhow!("scene {}: {e}", scene.name))
}

fn write_text(path: &Path, text: &str) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}
