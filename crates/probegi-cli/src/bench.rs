//! `probegi bench`: BVH build time and closest-hit / any-hit throughput on
//! probe-like rays — uniformly random directions from the points of a probe grid
//! spread over the scene bounds, the workload of DDGI's trace pass. Any-hit rays
//! are the same rays limited to one grid cell (a typical visibility query).

use std::collections::BTreeMap;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use glam::Vec3;
use probegi_core::rng::{Pcg32, hash_combine};
use probegi_core::sampling::sample_uniform_sphere;
use probegi_cpu::probe_trace::ddgi_volume_bytes;
use probegi_cpu::{DirectLighting, DirectSettings};
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_frame::field_update::FieldSetUpdate;
use probegi_frame::field_update::HOST_PLAN_PASS;
use probegi_frame::frame_loop::FIELD_UPDATE_PASSES;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, Scene, load_scene};
use rayon::prelude::*;
use serde_json::json;

use crate::args::BenchArgs;
use crate::gpu_backend::WgpuProbeTracer;
use crate::memory::check_memory;
use crate::render_settings::{apply_scene_settings, probe_settings};
use crate::scene_setup::check_posed_bounds;

pub fn run(args: &BenchArgs) -> Result<serde_json::Value> {
    if args.dump_rays.is_some() && args.gi != crate::args::GiArg::None {
        bail!("--dump-rays dumps the ray bench's rays: it takes no --gi");
    }
    match args.gi {
        crate::args::GiArg::None => run_rays(args),
        crate::args::GiArg::Ddgi => run_ddgi(args),
        crate::args::GiArg::Sh => run_sh(args),
    }
}

/// `bench --gi sh`: seed 001 §7.2's cost comparison. Per grid, in one run on the
/// scene's camera: the DDGI field update (`--rays` per probe, default 256) and the
/// SH probe update with one cascade of the same probe count, without and with
/// occlusion. Both run inside the real frame loop at 256×256; only their update
/// passes are timed (mean over all `--frames` + 1 frames).
fn run_sh(args: &BenchArgs) -> Result<serde_json::Value> {
    use probegi_core::camera::CameraRays;
    use probegi_core::sh_settings::ShProbeSettings;
    use probegi_frame::frame_loop::{GiMethod, RenderSettings, render_frames};

    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let grids = if args.grids.is_empty() { vec![[16, 8, 16]] } else { args.grids.clone() };
    let rays = args.rays.first().copied().unwrap_or(256);
    let scene = bench_scene(args)?;
    let bvh = BvhTracer::for_scene(&scene, BvhSettings { bvh_aabb_pad_rel: args.aabb_pad_rel });
    let camera = CameraRays::new(&scene.default_camera(), 256, 256);
    let timed = |gi: GiMethod| {
        let settings = RenderSettings {
            width: 256,
            height: 256,
            frames: args.frames + 1,
            seed: args.seed,
            gi,
            direct: DirectSettings::default(),
            show_probes: false,
            camera_path: Vec::new(),
            probe_tracer: None,
            temporal: Default::default(),
            device_readback_lag_frames: 0,
        };
        render_frames(&scene, &bvh, &camera, &settings, |_, _| {}).stats
    };
    let mut rows = Vec::new();
    for grid in &grids {
        let ddgi = bench_volume_settings(args, *grid, rays)?;
        let d = timed(GiMethod::Ddgi(Box::new(ddgi)));
        let ddgi_ms = d.field_update_ms.unwrap_or(0.0);
        let mut row = json!({
            "probes": grid,
            "probe_count": d.probes,
            "ddgi_rays_per_probe": rays,
            "ddgi_active_probes": d.active_probes,
            "ddgi_field_update_ms": ddgi_ms,
            "ddgi_pass_ms": d.pass_ms,
        });
        for occlusion in [false, true] {
            let sh = ShProbeSettings {
                sh_cascade_count: 1,
                sh_cascade_probe_counts: glam::UVec3::from(*grid),
                sh_occlusion: occlusion,
                ..Default::default()
            };
            let s = timed(GiMethod::Sh(Box::new(sh)));
            let sh_ms = s.field_update_ms.unwrap_or(0.0);
            let key = if occlusion { "sh_occlusion" } else { "sh" };
            row[format!("{key}_update_ms")] = json!(sh_ms);
            row[format!("{key}_pass_ms")] = json!(s.pass_ms);
            row[format!("ddgi_over_{key}")] = json!(ddgi_ms / sh_ms);
        }
        rows.push(row);
    }
    Ok(json!({
        "scene": args.scene,
        "triangles": scene.drawn_triangle_count(),
        "stored_triangles": scene.stored_triangle_count(),
        "instances": scene.instances.len(),
        "threads": rayon::current_num_threads(),
        "frames": args.frames + 1,
        "note": "update ms are means over all frames of the run, the first included",
        "peak_rss_mib": peak_rss_mib(),
        "comparison": rows,
    }))
}

/// `bench --gi ddgi`: the field update over a sweep of rays per probe × probe grids
/// (seed 000 Table 2), with the bare closest-hit rate of the same rays measured
/// in the same run.
fn run_ddgi(args: &BenchArgs) -> Result<serde_json::Value> {
    if args.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let grids = if args.grids.is_empty() { vec![[16, 8, 16], [24, 12, 24], [32, 16, 32]] } else { args.grids.clone() };
    let ray_counts = if args.rays.is_empty() { vec![32, 64, 128, 256] } else { args.rays.clone() };
    let scene = bench_scene(args)?;
    let bounds = scene.bounds().context("scene has no geometry")?;
    let bvh = BvhTracer::for_scene(&scene, BvhSettings { bvh_aabb_pad_rel: args.aabb_pad_rel });
    let direct = DirectLighting::new(&scene, &bvh, DirectSettings::default());
    let gpu = match args.backend {
        crate::gpu_backend::Backend::Cpu => None,
        crate::gpu_backend::Backend::Wgpu => {
            Some(crate::gpu_backend::wgpu_probe_tracer(&scene, &bvh)?.timing_passes(true))
        }
    };
    let batch_tracer = gpu.as_ref().map(|g| g as &dyn probegi_field::ProbeBatchTracer);
    let sweep = DdgiSweep { args, scene: &scene, bvh: &bvh, direct: &direct, bounds, gpu: gpu.as_ref(), batch_tracer };
    let mut rows = Vec::new();
    for grid in &grids {
        for &rays in &ray_counts {
            rows.push(sweep.row(*grid, rays)?);
        }
    }
    Ok(json!({
        "scene": args.scene,
        "backend": format!("{:?}", args.backend).to_lowercase(),
        "adapter": gpu.as_ref().map(|g| g.adapter_name().to_string()),
        "triangles": scene.drawn_triangle_count(),
        "stored_triangles": scene.stored_triangle_count(),
        "instances": scene.instances.len(),
        "threads": rayon::current_num_threads(),
        "frames_timed": args.frames,
        "peak_rss_mib": peak_rss_mib(),
        "sweep": rows,
    }))
}

/// The host's share of a timed field update (`--backend wgpu`): wall
/// milliseconds a frame less the time blocked on the device (waits, read-backs
/// and submissions), with the submissions and waits a frame. `null` on the CPU,
/// where the host is the whole update.
fn host_share_json(
    gpu: Option<&WgpuProbeTracer>,
    before: Option<probegi_wgpu::GpuCounters>,
    wall_ms: f64,
    frames: u32,
) -> serde_json::Value {
    let (Some(g), Some(before)) = (gpu, before) else {
        return json!(null);
    };
    let d = g.ctx.counters() - before;
    let per_frame = |x: f64| x / frames.max(1) as f64;
    json!({
        "update_wall_ms": wall_ms,
        "host_ms": (wall_ms - per_frame(d.wait_ms)).max(0.0),
        "device_wait_ms": per_frame(d.wait_ms),
        "submissions": per_frame(d.submissions as f64),
        "blocking_waits": per_frame(d.blocking_waits as f64),
    })
}

/// The fewest updates [`pipelined_json`] runs back to back, whatever `--frames` says.
const PIPELINED_MIN_FRAMES: u32 = 4;

/// The field update as the frame loop runs it on the GPU backend: no pass
/// waited for, each update's passes recorded and submitted together (one
/// submission), the updates of `frames` back to back and one wait after the
/// last. `update_ms` (wall time over the updates, that wait included) is what
/// a frame pays for the field; `host_ms` is the host's share, the time inside
/// the update calls less any time blocked on the device (with lavapipe that
/// includes the driver's own work inside a submission, counted as waiting),
/// and `host_cpu_ms` the CPU time the calling thread spent inside them
/// (`null` where the platform does not say): the host work apart from the
/// time other threads held the cores (lavapipe's, running the update
/// before on the same cores, stretch `host_ms` by up to a half), and with
/// the driver's own work inside the submission, which `host_ms` counts as
/// waiting,
/// and `field_set_ms` the field set's own part of it ([`HOST_PLAN_PASS`]:
/// planning and bookkeeping, no command recording), which `update` returns
/// with whether the update kept the plan before it
/// (`DdgiFieldSet::update_kept_plan`; `plans_kept`: the share that did) or
/// its trace plan alone (`DdgiFieldSet::update_kept_trace_plan`, the usage
/// scheme; `traces_kept`).
fn pipelined_json(
    gpu: &WgpuProbeTracer,
    frames: std::ops::RangeInclusive<u32>,
    mut update: impl FnMut(u32) -> Result<(f64, bool, bool)>,
    rays_per_frame: u64,
) -> Result<serde_json::Value> {
    let ctx = &gpu.ctx;
    gpu.set_timing_passes(false);
    ctx.wait()?;
    let before = ctx.counters();
    let (t, count) = (Instant::now(), frames.clone().count());
    let (mut inside_ms, mut waited_in_ms, mut field_set_ms, mut kept, mut traces_kept) = (0.0, 0.0, 0.0, 0, 0);
    let mut cpu_ms = Some(0.0);
    for f in frames {
        let (t_update, waited) = (Instant::now(), ctx.counters().wait_ms);
        let cpu = cpu_time::ThreadTime::try_now().ok();
        ctx.defer_submissions(true);
        let result = update(f);
        ctx.defer_submissions(false);
        let cpu = cpu.and_then(|c| c.try_elapsed().ok());
        cpu_ms = cpu_ms.zip(cpu).map(|(sum, c)| sum + c.as_secs_f64() * 1e3);
        let (ms, plan_kept, trace_kept) = result?;
        field_set_ms += ms;
        kept += plan_kept as u32;
        traces_kept += trace_kept as u32;
        inside_ms += t_update.elapsed().as_secs_f64() * 1e3;
        waited_in_ms += ctx.counters().wait_ms - waited;
    }
    ctx.wait()?;
    let wall_ms = t.elapsed().as_secs_f64() * 1e3;
    gpu.set_timing_passes(true);
    let d = ctx.counters() - before;
    let per = |x: f64| x / count as f64;
    Ok(json!({
        "updates": count,
        "update_ms": per(wall_ms),
        "mrays_per_s": rays_per_frame as f64 / (per(wall_ms) * 1e-3) / 1e6,
        "host_ms": per((inside_ms - waited_in_ms).max(0.0)),
        "host_cpu_ms": cpu_ms.map(per),
        "field_set_ms": per(field_set_ms),
        "plans_kept": per(kept as f64),
        "traces_kept": per(traces_kept as f64),
        "submissions": per(d.submissions as f64),
        "blocking_waits": per(d.blocking_waits as f64 - 1.0),
        "bytes_up": per(d.bytes_up as f64),
        "ray_batches_made": per(d.ray_batches_made as f64),
        "buffers_made": per(d.buffers_made as f64),
        "bind_groups_made": per(d.bind_groups_made as f64),
    }))
}

/// What every configuration of a `bench --gi ddgi` sweep shares: the scene,
/// its BVH and direct light, and the GPU where `--backend wgpu` traces.
#[derive(Clone, Copy)]
struct DdgiSweep<'a> {
    args: &'a BenchArgs,
    scene: &'a Scene,
    bvh: &'a BvhTracer,
    direct: &'a DirectLighting<'a>,
    bounds: (Vec3, Vec3),
    gpu: Option<&'a WgpuProbeTracer>,
    batch_tracer: Option<&'a dyn probegi_field::ProbeBatchTracer>,
}

impl DdgiSweep<'_> {
    /// One row of the sweep: a volume of `grid` probes and `rays` rays per probe
    /// initialised, then `--frames` field updates timed per pass, the bare
    /// closest-hit rate of the last update batch, and the GPU passes alone.
    fn row(&self, grid: [u32; 3], rays: u32) -> Result<serde_json::Value> {
        let DdgiSweep { args, scene, bvh, direct, bounds, gpu, batch_tracer } = *self;
        let settings = bench_volume_settings(args, grid, rays)?;
        let mut set = DdgiFieldSet::single(DdgiVolume::new(settings.clone(), bounds));
        let mut warmup = BTreeMap::new();
        set.update_traced_by(scene, bvh, batch_tracer, direct, args.seed, 0, &mut warmup)
            .map_err(anyhow::Error::msg)?;
        let init_ms = warmup.get("probe_init").copied().unwrap_or(0.0);
        let mut pass_ms: BTreeMap<&'static str, f64> = BTreeMap::new();
        let bus_before = gpu.map(|g| g.ctx.counters());
        let counters_before = gpu.map(|g| g.ctx.counters());
        let t = Instant::now();
        for f in 1..=args.frames {
            set.update_traced_by(scene, bvh, batch_tracer, direct, args.seed, f, &mut pass_ms)
                .map_err(anyhow::Error::msg)?;
        }
        let wall_ms = t.elapsed().as_secs_f64() * 1e3 / args.frames as f64;
        let host = host_share_json(gpu, counters_before, wall_ms, args.frames);
        let bus = bus_json(gpu, bus_before, args.frames, set.ray_batch());
        let pipelined = match gpu {
            Some(g) => {
                let frames = (args.frames + 1)..=(args.frames + args.frames.max(PIPELINED_MIN_FRAMES));
                let rays = set.volumes()[0].rays_per_frame();
                let update = |f: u32| {
                    let mut ms = BTreeMap::new();
                    set.update_traced_by(scene, bvh, batch_tracer, direct, args.seed, f, &mut ms)
                        .map_err(anyhow::Error::msg)?;
                    let host_ms = ms.get(HOST_PLAN_PASS).copied().unwrap_or(0.0);
                    Ok((host_ms, set.update_kept_plan(), set.update_kept_trace_plan()))
                };
                pipelined_json(g, frames, update, rays)?
            }
            None => json!(null),
        };
        // After the timed frames: the field back on the host, as the update left
        // it (the GPU passes alone below start from it).
        set.sync_host_atlases(batch_tracer).map_err(anyhow::Error::msg)?;
        let volume = &set.volumes()[0];
        for v in pass_ms.values_mut() {
            *v /= args.frames as f64;
        }
        let update_ms: f64 = FIELD_UPDATE_PASSES.iter().filter_map(|p| pass_ms.get(p)).sum();
        let n = volume.rays_per_frame() as f64;
        // The same rays, bare: the last update batch (its origins, directions and
        // max distances), closest hit only, as the update's trace pass. Both rates divide by the
        // rays of that batch, so they compare the same work.
        let batch = set.ray_batch();
        let bare_batch = batch.expanded();
        let t = Instant::now();
        let hits: usize = (0..batch.len())
            .into_par_iter()
            .filter(|&i| {
                let ray =
                    Ray::segment(bare_batch.origins_m[i], bare_batch.directions[i], bare_batch.max_distances_m[i]);
                bvh.closest_hit(&ray).is_some()
            })
            .count();
        let bare_s = t.elapsed().as_secs_f64();
        let bare_rays = batch.len() as f64;
        let get = |k: &str| pass_ms.get(k).copied().unwrap_or(0.0);
        let gpu_row = match &gpu {
            Some(g) => crate::gpu_backend::time_gpu_passes(g, &set, batch, args.repeat.max(1))?,
            None => json!(null),
        };
        Ok(json!({
            "probes": grid,
            "probe_count": volume.grid.probe_count(),
            "probe_states": volume.state_counts(),
            "active_probes": volume.active_probe_count(),
            "probe_init_ms": init_ms,
            "volume_mib": ddgi_volume_bytes(&settings) as f64 / (1u64 << 20) as f64,
            "rays_per_probe": rays,
            "rays_per_frame": n as u64,
            // The shadowing field's shadow rays in the same batch (seed 003 §5.1).
            "shadow_rays_per_frame": (batch.len() as u64).saturating_sub(n as u64),
            "bare_rays": bare_rays as u64,
            "pass_ms": pass_ms,
            "field_update_ms": update_ms,
            "field_update_mrays_per_s": n / (update_ms * 1e-3) / 1e6,
            "bare_closest_hit_mrays_per_s": bare_rays / bare_s / 1e6,
            "bare_hit_fraction": hits as f64 / bare_rays,
            "trace_mrays_per_s": n / (get("trace") * 1e-3) / 1e6,
            "shade_blend_border_over_trace": (get("shade") + get("blend") + get("border")) / get("trace"),
            "gpu": gpu_row,
            "bus_bytes_per_frame": bus,
            "host": host,
            "pipelined": pipelined,
        }))
    }
}

/// The bytes that crossed the bus per timed update frame on the GPU backend
/// (`GpuContext::counters` since `before`), each way, and per probe and per
/// ray of the last batch: O(probes) when nothing per ray crosses. `kept`: the
/// bytes the passes found already on the device (per-probe records that
/// repeated the last frame's) and did not upload. `ray_batches_made`: ray
/// batches allocated a frame (48 bytes a ray; 0 once a still field's batches
/// reuse the buffers of the one two frames before). `buffers_made`,
/// `bind_groups_made`: what the passes made a frame (0 for a still field,
/// whose passes keep their buffers and bind groups).
fn bus_json(
    gpu: Option<&WgpuProbeTracer>,
    before: Option<probegi_wgpu::GpuCounters>,
    frames: u32,
    batch: &probegi_field::seam::ProbeRayBatch,
) -> serde_json::Value {
    let (Some(g), Some(before)) = (gpu, before) else { return json!(null) };
    let d = g.ctx.counters() - before;
    let per_frame = |b: u64| b as f64 / frames as f64;
    let (up, down) = (per_frame(d.bytes_up), per_frame(d.bytes_down));
    json!({
        "host_to_device": up,
        "device_to_host": down,
        "kept": per_frame(d.bytes_kept),
        "ray_batches_made": per_frame(d.ray_batches_made),
        "buffers_made": per_frame(d.buffers_made),
        "bind_groups_made": per_frame(d.bind_groups_made),
        "per_batch_probe": (up + down) / batch.probes.len().max(1) as f64,
        "per_batch_ray": (up + down) / batch.len().max(1) as f64,
        "batch_probes": batch.probes.len(),
        "batch_rays": batch.len(),
        "per_ray_arrays_on_host": batch.has_ray_arrays(),
    })
}

/// DDGI settings of one bench configuration: defaults, the grid and ray count,
/// then every `--set`; validated and checked against available memory.
fn bench_volume_settings(
    args: &BenchArgs,
    grid: [u32; 3],
    rays: u32,
) -> Result<probegi_core::ddgi_settings::DdgiVolumeSettings> {
    let mut settings = probegi_core::ddgi_settings::DdgiVolumeSettings {
        probe_counts: glam::UVec3::from(grid),
        probe_rays_per_probe: rays,
        ..Default::default()
    };
    for a in probe_settings(&args.set) {
        settings = probegi_scene::scene_file::apply_volume_override(&settings, a)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("--set {a}"))?;
    }
    settings.validate().map_err(|(f, why)| anyhow::anyhow!("volume setting {f}: {why}"))?;
    check_memory(probegi_cpu::probe_trace::ddgi_volume_bytes(&settings), "the DDGI volume")?;
    Ok(settings)
}

/// The scene of `--scene` with the scene-level `--set` keys applied.
fn bench_scene(args: &BenchArgs) -> Result<probegi_scene::Scene> {
    let mut scene = load_scene(&args.scene).with_context(|| format!("loading scene {}", args.scene))?;
    apply_scene_settings(&mut scene, &args.set)?;
    // The last frame any bench mode poses: the frame loop's, or the instancing run's.
    let last_frame = (args.frames as f32 + 1.0).max(7.0 + args.repeat as f32);
    check_posed_bounds(&scene, last_frame)?;
    Ok(scene)
}

/// The process's peak resident set (VmHWM) in MiB, where /proc provides it.
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kb: f64 = status.lines().find(|l| l.starts_with("VmHWM:"))?.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn run_rays(args: &BenchArgs) -> Result<serde_json::Value> {
    let ray_count = args.probes.iter().map(|&n| n as u64).product::<u64>() * args.rays_per_probe as u64;
    if args.rays_per_probe == 0 || args.repeat == 0 {
        bail!("--rays-per-probe and --repeat must be at least 1");
    }
    check_memory(ray_count * std::mem::size_of::<Ray>() as u64, "bench rays")?;
    if !(args.aabb_pad_rel.is_finite() && args.aabb_pad_rel >= 0.0 && args.aabb_pad_rel < 0.1) {
        bail!("--aabb-pad-rel {} must be in [0, 0.1)", args.aabb_pad_rel);
    }
    let t = Instant::now();
    let scene = bench_scene(args)?;
    let load_ms = t.elapsed().as_secs_f64() * 1e3;
    let (lo, hi) = scene.bounds().context("scene has no geometry")?;

    let (bvh, build_ms) = best_bvh_build(args, &scene)?;
    if args.dump_rays.is_some() {
        check_dumpable(&scene, &bvh)?;
    }

    let (rays, cell) = probe_grid_rays(args, lo, hi);
    let any_hit_len = cell.min_element();

    let rates = |bvh: &BvhTracer| hit_rates(bvh, &rays, any_hit_len, args.repeat);
    let (closest_s, closest_hits, any_s, any_hits) = rates(&bvh);
    let n = rays.len() as f64;
    // Alpha testing's cost: the same rays through the same triangles, all opaque.
    let cutouts = if bvh.cutout_triangle_count() > 0 {
        let mut opaque_scene = scene.clone();
        probegi_scene::scene_file::apply_scene_setting(&mut opaque_scene, "alpha_cutouts=false")
            .map_err(anyhow::Error::msg)?;
        let opaque = BvhTracer::for_scene(&opaque_scene, BvhSettings { bvh_aabb_pad_rel: args.aabb_pad_rel });
        let (c_s, c_hits, a_s, a_hits) = rates(&opaque);
        json!({
            "cutout_triangles": bvh.cutout_triangle_count(),
            "opaque_closest_hit_mrays_per_s": n / c_s / 1e6,
            "opaque_closest_hit_fraction": c_hits as f64 / n,
            "opaque_any_hit_mrays_per_s": n / a_s / 1e6,
            "opaque_any_hit_fraction": a_hits as f64 / n,
            "cutout_closest_hit_time_ratio": closest_s / c_s,
            "cutout_any_hit_time_ratio": any_s / a_s,
        })
    } else {
        json!(null)
    };
    let report = json!({
        "scene": args.scene,
        "triangles": scene.drawn_triangle_count(),
        "stored_triangles": scene.stored_triangle_count(),
        "instances": scene.instances.len(),
        "threads": rayon::current_num_threads(),
        "load_ms": load_ms,
        "bvh_build_ms": build_ms,
        "bvh_aabb_pad_rel": args.aabb_pad_rel,
        "probes": args.probes,
        "rays_per_probe": args.rays_per_probe,
        "rays": rays.len(),
        "closest_hit_mrays_per_s": n / closest_s / 1e6,
        "closest_hit_fraction": closest_hits as f64 / n,
        "any_hit_max_distance_m": any_hit_len,
        "any_hit_mrays_per_s": n / any_s / 1e6,
        "any_hit_fraction": any_hits as f64 / n,
        "alpha_cutouts": cutouts,
        "peak_rss_mib": peak_rss_mib(),
    });
    if let Some(dir) = &args.dump_rays {
        dump_rays(dir, &scene, &bvh, &rays, &report)?;
    }
    let mut report = report;
    report["instancing"] = if args.moving_objects > 0 { bench_instancing(args, scene, &rays)? } else { json!(null) };
    report["peak_rss_mib"] = json!(peak_rss_mib());
    Ok(report)
}

/// Whether `--dump-rays` can write `scene` as plain triangles another tracer
/// reproduces: no instances, no alpha cutouts.
fn check_dumpable(scene: &Scene, bvh: &BvhTracer) -> Result<()> {
    if !scene.instances.is_empty() || bvh.cutout_triangle_count() > 0 {
        bail!("--dump-rays needs a scene without instances and alpha cutouts (try --set alpha_cutouts=false)");
    }
    Ok(())
}

/// `--dump-rays DIR`: the scene's triangles (9 f32 each, world space), the bench
/// rays (origin, direction: 6 f32 each; closest-hit rays are unbounded and
/// any-hit rays end at `any_hit_max_distance_m`), probegi's closest-hit
/// distance per ray (+∞ for a miss) and `meta.json` (this bench's report), all
/// little-endian. Only scenes whose every triangle the BVH holds as they are:
/// no instances and no alpha cutouts (`--set alpha_cutouts=false`).
fn dump_rays(
    dir: &std::path::Path,
    scene: &Scene,
    bvh: &BvhTracer,
    rays: &[Ray],
    report: &serde_json::Value,
) -> Result<()> {
    check_dumpable(scene, bvh)?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let write = |name: &str, values: &mut dyn Iterator<Item = f32>| -> Result<()> {
        let bytes: Vec<u8> = values.flat_map(f32::to_le_bytes).collect();
        let path = dir.join(name);
        std::fs::write(&path, bytes).with_context(|| format!("writing {}", path.display()))
    };
    let mesh = &scene.mesh;
    let corners = mesh.triangles.iter().flat_map(|t| t.map(|v| mesh.positions[v as usize].to_array()));
    write("triangles.f32", &mut corners.flatten())?;
    write("rays.f32", &mut rays.iter().flat_map(|r| [r.origin.to_array(), r.dir.to_array()]).flatten())?;
    let closest: Vec<f32> = rays.par_iter().map(|r| bvh.closest_hit(r).map_or(f32::INFINITY, |h| h.t)).collect();
    write("closest_t.f32", &mut closest.into_iter())?;
    let meta = dir.join("meta.json");
    std::fs::write(&meta, serde_json::to_string_pretty(report)?).with_context(|| format!("writing {}", meta.display()))
}

/// The BVH of `scene`, built `--repeat` times (at most 3), and the best build time (ms).
fn best_bvh_build(args: &BenchArgs, scene: &Scene) -> Result<(BvhTracer, f64)> {
    let mut build_ms = f64::INFINITY;
    let mut bvh = None;
    for _ in 0..args.repeat.min(3) {
        let b = BvhTracer::for_scene(scene, BvhSettings { bvh_aabb_pad_rel: args.aabb_pad_rel });
        build_ms = build_ms.min(b.build_time.as_secs_f64() * 1e3);
        bvh = Some(b);
    }
    let bvh = bvh.context("no BVH built")?;
    Ok((bvh, build_ms))
}

/// The bench rays: `--rays-per-probe` uniformly random directions from the
/// centre of each cell of a `--probes` grid over `[lo, hi]`, seeded per probe;
/// and the size of a cell.
fn probe_grid_rays(args: &BenchArgs, lo: Vec3, hi: Vec3) -> (Vec<Ray>, Vec3) {
    let [nx, ny, nz] = args.probes;
    let cell = (hi - lo) / Vec3::new(nx as f32, ny as f32, nz as f32);
    let rays: Vec<Ray> = (0..nx * ny * nz)
        .into_par_iter()
        .flat_map_iter(|p| {
            let (ix, iy, iz) = (p % nx, (p / nx) % ny, p / (nx * ny));
            let origin = lo + cell * (Vec3::new(ix as f32, iy as f32, iz as f32) + 0.5);
            let mut rng = Pcg32::new(hash_combine(&[args.seed, p as u64]), p as u64);
            (0..args.rays_per_probe).map(move |_| Ray::new(origin, sample_uniform_sphere(rng.next_vec2())))
        })
        .collect();
    (rays, cell)
}

/// The best of `repeat` runs of `f` (seconds), and what its last run returned.
fn time_best(repeat: u32, f: &(dyn Fn() -> u64 + Sync)) -> (f64, u64) {
    let mut best = f64::INFINITY;
    let mut hits = 0;
    for _ in 0..repeat {
        let t = Instant::now();
        hits = f();
        best = best.min(t.elapsed().as_secs_f64());
    }
    (best, hits)
}

/// Closest-hit and any-hit (rays cut to `any_hit_len`) over `rays` through
/// `bvh`: `(closest_s, closest_hits, any_s, any_hits)`, best of `repeat`.
fn hit_rates(bvh: &BvhTracer, rays: &[Ray], any_hit_len: f32, repeat: u32) -> (f64, u64, f64, u64) {
    let (closest_s, closest_hits) =
        time_best(repeat, &|| rays.par_iter().filter(|r| bvh.closest_hit(r).is_some()).count() as u64);
    let (any_s, any_hits) = time_best(repeat, &|| {
        rays.par_iter().filter(|r| bvh.occluded(&Ray { t_max: any_hit_len, ..**r })).count() as u64
    });
    (closest_s, closest_hits, any_s, any_hits)
}

/// `--moving-objects K`: K boxes (a twentieth of the scene's extent) orbiting the
/// scene centre, instanced over the static BVH (dynamic-scenes issue). Reports the
/// one-off build, the per-frame cost (posing the vertices, then the TLAS rebuild),
/// a full rebuild of the posed mesh for comparison, and closest-hit throughput on
/// the same rays through the TLAS.
fn bench_instancing(args: &BenchArgs, mut scene: probegi_scene::Scene, rays: &[Ray]) -> Result<serde_json::Value> {
    use probegi_scene::{MotionPath, ObjectAnimation};
    let (lo, hi) = scene.bounds().context("scene has no geometry")?;
    let (centre, extent) = ((lo + hi) * 0.5, (hi - lo).max_element());
    let material = scene.materials.len() as u32;
    scene.materials.push(probegi_scene::Material::diffuse("bench box", Vec3::splat(0.5)));
    let k = args.moving_objects;
    if k > 100_000 {
        bail!("--moving-objects {k} is more than 100000");
    }
    for i in 0..k {
        let angle = std::f32::consts::TAU * i as f32 / k as f32;
        let at = centre + Vec3::new(angle.cos(), 0.0, angle.sin()) * extent * 0.25;
        let animation = ObjectAnimation {
            motion: Some(MotionPath::Orbit { centre_m: centre, axis: Vec3::Y, period_frames: 100.0 }),
            ..Default::default()
        };
        let half = Vec3::splat(extent / 40.0);
        let add =
            |m: &mut probegi_scene::mesh::Mesh| probegi_scene::builtin::add_box(m, at - half, at + half, material);
        scene.add_object(&format!("box {i}"), add, animation);
    }
    scene.validate().map_err(anyhow::Error::msg)?;
    let settings = BvhSettings { bvh_aabb_pad_rel: args.aabb_pad_rel };
    let tracer = BvhTracer::for_scene(&scene, settings);
    let mut posed = scene.clone();
    let (mut pose_ms, mut tlas_ms, mut rebuild_ms) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    for r in 0..args.repeat {
        let frame = 7.0 + r as f32;
        let t = Instant::now();
        posed.set_frame_from(&scene, frame);
        pose_ms = pose_ms.min(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let framed = tracer.at_frame(&posed, frame);
        tlas_ms = tlas_ms.min(t.elapsed().as_secs_f64() * 1e3);
        drop(framed);
        let t = Instant::now();
        drop(BvhTracer::build(&posed.mesh, settings));
        rebuild_ms = rebuild_ms.min(t.elapsed().as_secs_f64() * 1e3);
    }
    let framed = tracer.at_frame(&posed, 7.0).context("moving objects must give a frame tracer")?;
    let mut best = f64::INFINITY;
    for _ in 0..args.repeat {
        let t = Instant::now();
        rays.par_iter().filter(|r| framed.closest_hit(r).is_some()).count();
        best = best.min(t.elapsed().as_secs_f64());
    }
    Ok(json!({
        "moving_objects": k,
        "static_and_object_build_ms": tracer.build_time.as_secs_f64() * 1e3,
        "per_frame_pose_ms": pose_ms,
        "per_frame_tlas_ms": tlas_ms,
        "full_rebuild_ms": rebuild_ms,
        "closest_hit_mrays_per_s": rays.len() as f64 / best / 1e6,
    }))
}
