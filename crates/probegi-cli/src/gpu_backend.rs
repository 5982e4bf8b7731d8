//! `--backend wgpu`: what of a frame runs on the GPU today (`probegi_wgpu::wgpu_field_backend`
//! with the field kept on the device). The DDGI probe ray batches are traced by
//! probegi-wgpu's compute-shader CWBVH traversal over the same BVH the CPU
//! builds; the update batch is shaded, blended and bordered there into atlases
//! that stay there; the initialisation rounds relocate and classify there; the
//! camera frame is rendered there too (primary rays, direct light, glossy
//! rays, the field query). The host plans the batches and keeps the set's
//! bookkeeping (probe states, hysteresis ramps).

use std::sync::Arc;

use anyhow::{Context, Result, bail};
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_field::ddgi_field_set::ProbeRayBatch;
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_frame::frame_loop::GiMethod;
use probegi_scene::{BvhTracer, Scene};
use probegi_wgpu::GpuContext;
use probegi_wgpu::bvh_trace::GpuRayBatch;
use probegi_wgpu::gpu_timer::GpuTimer;
use probegi_wgpu::probe_blend::{BlendBindings, BlendFrame, GpuProbeBlend, GpuVolumeAtlases, PASS_NAMES};

/// Which device traces the probe rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Backend {
    Cpu,
    Wgpu,
}

pub use probegi_wgpu::wgpu_field_backend::WgpuProbeTracer;

/// A headless device with the scene on it; a clear error when there is no
/// adapter. Moving objects and instanced meshes go through the top level the
/// CPU builds, placed on the device each frame. Were the GPU
/// shading to lack something a scene needs, the probe rays and the camera would
/// be shaded on the CPU, with a line that says why (`shading_note`).
pub fn wgpu_probe_tracer(scene: &Scene, bvh: &BvhTracer) -> Result<WgpuProbeTracer> {
    wgpu_probe_tracer_on(GpuContext::headless().context("--backend wgpu")?, scene, bvh)
}

/// [`wgpu_probe_tracer`] on a device the caller made (the viewer's window's).
pub fn wgpu_probe_tracer_on(ctx: GpuContext, scene: &Scene, bvh: &BvhTracer) -> Result<WgpuProbeTracer> {
    let g = WgpuProbeTracer::new(ctx, scene, bvh, true)
        .context("--backend wgpu: putting the scene on the device")?
        .keeping_field(true);
    match &g.shading_note {
        None => eprintln!("the DDGI field and the camera frame on {}", g.adapter_name()),
        Some(why) => {
            eprintln!("probe rays traced on {}; their shading and the camera frame on the CPU: {why}", g.adapter_name())
        }
    }
    Ok(g)
}

/// The probe tracer of `render --backend`: none on the CPU; with wgpu, the
/// device with the scene on it (`wgpu_probe_tracer`), which needs DDGI.
pub fn render_probe_tracer(
    backend: Backend,
    gi: &GiMethod,
    scene: &Scene,
    bvh: &BvhTracer,
) -> Result<Option<Arc<WgpuProbeTracer>>> {
    render_probe_tracer_on(backend, gi, scene, bvh, None)
}

/// [`render_probe_tracer`], on `ctx` where given (the viewer's shared device).
pub fn render_probe_tracer_on(
    backend: Backend,
    gi: &GiMethod,
    scene: &Scene,
    bvh: &BvhTracer,
    ctx: Option<GpuContext>,
) -> Result<Option<Arc<WgpuProbeTracer>>> {
    Ok(match backend {
        Backend::Cpu => None,
        Backend::Wgpu => {
            if !matches!(gi, GiMethod::Ddgi(_) | GiMethod::DdgiSet(_)) {
                bail!("--backend wgpu runs the DDGI field and its camera frame on the GPU: it needs --gi ddgi");
            }
            Some(Arc::new(match ctx {
                Some(ctx) => wgpu_probe_tracer_on(ctx, scene, bvh)?,
                None => wgpu_probe_tracer(scene, bvh)?,
            }))
        }
    })
}

/// `bench --backend wgpu`: the GPU passes alone on one volume's last update batch,
/// best of `repeat` submits: ray generation for the batch's probes (on the
/// device, so no ray is uploaded), the trace (closest hit of every one of
/// those rays), blend and border over every probe of the volume (an upper
/// bound: sleeping probes would skip theirs), then (where the GPU shades this
/// scene) the shade of every batch ray, with per-pass times from timestamp queries where
/// the adapter has them (wall-clock around the submit otherwise), device memory
/// per probe and per probe ray.
pub fn time_gpu_passes(
    gpu: &WgpuProbeTracer,
    set: &probegi_field::ddgi_field_set::DdgiFieldSet,
    batch: &ProbeRayBatch,
    repeat: u32,
) -> Result<serde_json::Value> {
    let volume = &set.volumes()[0];
    let ctx = &gpu.ctx;
    let s = &volume.settings;
    let n = s.probe_rays_per_probe as usize;
    // The batch's probes (their relocated origins), their rays generated on the device.
    let origins = &batch.probe_origins_m;
    let max_m = batch.generated.first().map_or(f32::INFINITY, |g| g.max_distance_m);
    let rotation = probegi_field::probe_ray_gen::probe_ray_rotation(volume.stream_seed(1), 1);
    let ray_gen = probegi_wgpu::probe_ray_gen::GpuProbeRayGen::new(ctx);
    let (_atlases, blend, bindings) = blend_pass(ctx, volume, batch)?;
    // Timestamp slots: the trace, the blend's passes, shade, ray generation, the batch-order trace.
    let timer = GpuTimer::new(ctx, 7);
    let names = ["trace", PASS_NAMES[0], PASS_NAMES[1], PASS_NAMES[2], "shade", "ray_gen", "trace_batch_order"];
    // The update's thread order (direction-major per volume), and batch order for comparison.
    let segment = probegi_wgpu::bvh_trace::TraceSegment {
        first_ray: 0,
        probe_count: origins.len() as u32,
        rays_per_probe: n as u32,
    };
    let traced = ray_gen.generate(ctx, &gpu.trace, origins, max_m, rotation, n as u32, Some((&timer, 5)))?;
    ctx.wait()?;
    // The shade pass over every ray of the batch, with the set's field on the device.
    let field = probegi_wgpu::ddgi_query::GpuDdgiField::upload(ctx, &set.view())?;
    let info = probegi_wgpu::probe_shade::volume_shade_info(true, s);
    let shade_probes: Vec<probegi_wgpu::probe_shade::ShadeProbe> = batch
        .probes
        .iter()
        .map(|p| probegi_wgpu::probe_shade::ShadeProbe {
            first_ray: p.first_ray,
            ray_count: p.ray_count,
            info,
            hit_ao_radius_bits: probegi_wgpu::probe_shade::hit_ao_radius_m(volume).to_bits(),
        })
        .collect();
    let mut best: Option<Vec<f64>> = None;
    let mut wall_trace_ms = f64::INFINITY;
    for k in 0..repeat {
        if k > 0 {
            // Time the ray generation again, into the same kind of batch.
            ray_gen.generate(ctx, &gpu.trace, origins, max_m, rotation, n as u32, Some((&timer, 5)))?;
            ctx.wait()?;
        }
        traced.configure(ctx, false, &[]);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        gpu.trace.record(&mut encoder, &gpu.bvh, &traced, timer.writes(6));
        ctx.queue.submit([encoder.finish()]);
        ctx.wait()?;
        traced.configure(ctx, false, &[segment]);
        let t = std::time::Instant::now();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        gpu.trace.record(&mut encoder, &gpu.bvh, &traced, timer.writes(0));
        ctx.queue.submit([encoder.finish()]);
        ctx.wait()?;
        wall_trace_ms = wall_trace_ms.min(t.elapsed().as_secs_f64() * 1e3);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        blend.record(&mut encoder, &bindings, Some((&timer, 1)));
        ctx.queue.submit([encoder.finish()]);
        ctx.wait()?;
        if let Some((shade, scene)) = gpu.shading() {
            shade.shade(ctx, &gpu.bvh, &field, scene, &traced, &shade_probes, 1, 1, Some((&timer, 4)))?;
        }
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        timer.resolve(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
        ctx.wait()?;
        if let Some(ms) = timer.read_ms(ctx)? {
            best = Some(match best {
                None => ms,
                Some(b) => b.iter().zip(&ms).map(|(a, b)| a.min(*b)).collect(),
            });
        }
    }
    Ok(gpu_passes_json(gpu, s, &traced, names, best, wall_trace_ms))
}

/// The blend and border passes of `time_gpu_passes` ready to record: `volume`'s
/// atlases on the device, and every one of its probes blending the rays of
/// `batch`'s directions with made-up radiance and distances (the passes' cost
/// does not depend on them). The atlases are returned so that they outlive the
/// bindings.
fn blend_pass(
    ctx: &GpuContext,
    volume: &DdgiVolume,
    batch: &ProbeRayBatch,
) -> Result<(GpuVolumeAtlases, GpuProbeBlend, BlendBindings)> {
    let s = &volume.settings;
    let probes = volume.grid.probe_count();
    let n = s.probe_rays_per_probe as usize;
    let atlases = GpuVolumeAtlases::new(ctx, probes, s.probe_irradiance_texels, s.probe_distance_texels);
    atlases.upload(ctx, &volume.irradiance, &volume.distance);
    let dirs: Vec<glam::Vec3> = batch.expanded().directions.iter().take(n).copied().collect();
    let radiance = vec![glam::Vec3::splat(0.5); probes * n];
    let distance: Vec<f32> = (0..probes * n).map(|i| 1.0 + (i % 7) as f32).collect();
    let hysteresis = vec![Some(s.probe_hysteresis); probes];
    let frame = BlendFrame {
        settings: s,
        ray_dirs: &dirs,
        ray_radiance: &radiance,
        ray_distance: &distance,
        probe_hysteresis: &hysteresis,
        irradiance_scale: 1.0,
        visibility_scale: 1.0,
        distance_clamp_m: volume.distance_clamp_m(),
    };
    let blend = GpuProbeBlend::new(ctx);
    let bindings = blend.prepare(ctx, &atlases, &frame)?;
    Ok((atlases, blend, bindings))
}

/// The report of `time_gpu_passes`: the best time of each pass (timestamp
/// queries; the trace's wall clock where the adapter has none), throughput over
/// the rays of `traced`, and device memory per probe and per probe ray.
fn gpu_passes_json(
    gpu: &WgpuProbeTracer,
    s: &DdgiVolumeSettings,
    traced: &GpuRayBatch,
    names: [&str; 7],
    best: Option<Vec<f64>>,
    wall_trace_ms: f64,
) -> serde_json::Value {
    let ray_count = traced.ray_count as f64;
    let (pass_ms, source) = match &best {
        Some(ms) => (
            names
                .iter()
                .zip(ms)
                .filter(|(k, _)| **k != "shade" || gpu.shades())
                .map(|(k, v)| (k.to_string(), *v))
                .collect(),
            "timestamp queries",
        ),
        None => {
            (std::collections::BTreeMap::from([("trace".to_string(), wall_trace_ms)]), "wall clock (no timestamps)")
        }
    };
    let trace_ms = pass_ms["trace"];
    // The batch-order trace is the comparison, not a pass of the update.
    let all_ms: f64 = pass_ms.iter().filter(|(k, _)| *k != "trace_batch_order").map(|(_, v)| v).sum();
    let order_gain = pass_ms.get("trace_batch_order").map(|b| b / trace_ms);
    let atlas_bytes_per_probe = (probegi_core::probe_atlas::tile_texel_count(s.probe_irradiance_texels) * 16
        + probegi_core::probe_atlas::tile_texel_count(s.probe_distance_texels) * 8)
        as f64;
    serde_json::json!({
        "adapter": gpu.adapter_name(),
        "pass_ms": pass_ms,
        "pass_ms_source": source,
        "trace_mrays_per_s": ray_count / (trace_ms * 1e-3) / 1e6,
        // Batch-order trace time over the direction-major one (`TraceSegment`): > 1 where the order pays.
        "trace_order_speedup": order_gain,
        "gpu_passes_mrays_per_s": ray_count / (all_ms * 1e-3) / 1e6,
        "gpu_passes": pass_ms.keys().collect::<Vec<_>>(),
        // In the field update timed above (these pass times are the passes alone).
        "not_on_gpu": if gpu.keeps_field() {
            vec!["batch planning and probe-state bookkeeping (host)"]
        } else {
            vec!["shade, blend, border (CPU)", "relocation, classification and probe states (CPU)"]
        },
        "bvh_mib": gpu.bvh.bytes() as f64 / (1u64 << 20) as f64,
        "device_bytes_per_probe": atlas_bytes_per_probe,
        "device_bytes_per_probe_ray": traced.bytes() as f64 / ray_count.max(1.0),
    })
}
