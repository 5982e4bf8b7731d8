//! The GPU ray generation (`probe_ray_gen.wgsl`) against the CPU's
//! (`probegi_field::probe_ray_gen::probe_ray_directions`): the same rotated
//! spherical Fibonacci directions for every probe, from the same (seed, frame)
//! rotation, within 1e-4: frac(i/Φ) is exact to 2⁻³² in 0.32 fixed point where
//! the CPU uses f64, but Vulkan lets sin and cos be off by 2⁻¹¹ absolute
//! (lavapipe: 2.4e-5 at 1000 rays); origins and max distances exactly; and the
//! generated batch traces exactly like the same rays uploaded, in batch order
//! or direction-major (`TraceSegment`).

use crate::common;

use glam::Vec3;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_field::probe_ray_gen::{probe_ray_directions, probe_ray_rotation};
use probegi_wgpu::bvh_trace::{GpuBvh, GpuRay, GpuRayTrace, TraceSegment};
use probegi_wgpu::probe_ray_gen::GpuProbeRayGen;

#[test]
fn gpu_rays_are_the_cpus_rotated_fibonacci_sets() {
    let Some(ctx) = common::context() else { return };
    let trace = GpuRayTrace::new(&ctx);
    let ray_gen = GpuProbeRayGen::new(&ctx);
    let origins: Vec<Vec3> = (0..37).map(|p| Vec3::new(p as f32 * 0.3, 1.0 - p as f32 * 0.05, 2.0)).collect();
    let mut worst = 0f32;
    for (n, frame) in [(32u32, 0u32), (256, 7), (1000, 123)] {
        let s = DdgiVolumeSettings { probe_rays_per_probe: n, ..Default::default() };
        let cpu = probe_ray_directions(&s, 9, frame);
        let batch =
            ray_gen.generate(&ctx, &trace, &origins, 12.5, probe_ray_rotation(9, frame), n, None).expect("ray gen");
        let rays = trace.download_rays(&ctx, &batch).expect("read back");
        assert_eq!(rays.len(), origins.len() * n as usize);
        for (k, r) in rays.iter().enumerate() {
            assert_eq!(Vec3::from(r.origin), origins[k / n as usize]);
            assert_eq!((r.t_min, r.t_max), (0.0, 12.5));
            worst = worst.max((Vec3::from(r.dir) - cpu[k % n as usize]).abs().max_element());
        }
    }
    eprintln!("worst direction component difference {worst:.2e}");
    assert!(worst < 1e-4, "{worst}");
}

#[test]
fn a_generated_batch_traces_like_the_same_rays_uploaded() {
    let Some(ctx) = common::context() else { return };
    let scene = probegi_scene::builtin::cornell_box();
    let cpu = probegi_scene::BvhTracer::for_scene(&scene, Default::default());
    let bvh = GpuBvh::upload(&ctx, &cpu.export()).expect("upload");
    let trace = GpuRayTrace::new(&ctx);
    let (lo, hi) = scene.bounds().expect("bounds");
    let origins: Vec<Vec3> = (0..27)
        .map(|p| {
            lo + (hi - lo)
                * Vec3::new(0.2 + 0.3 * (p % 3) as f32, 0.2 + 0.3 * ((p / 3) % 3) as f32, 0.2 + 0.3 * (p / 9) as f32)
        })
        .collect();
    let batch = GpuProbeRayGen::new(&ctx)
        .generate(&ctx, &trace, &origins, f32::INFINITY, probe_ray_rotation(1, 2), 64, None)
        .expect("gen");
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    trace.record(&mut encoder, &bvh, &batch, None);
    ctx.queue.submit([encoder.finish()]);
    let generated = trace.download(&ctx, &batch).expect("hits");
    let rays: Vec<GpuRay> = trace.download_rays(&ctx, &batch).expect("rays");
    let uploaded = trace.trace(&ctx, &bvh, &rays, false).expect("trace");
    let differ = generated.iter().zip(&uploaded).filter(|(a, b)| a != b).count();
    if let Some((a, b)) = generated.iter().zip(&uploaded).find(|(a, b)| a != b) {
        eprintln!("{differ} of {} differ, e.g. {a:?} vs {b:?}", generated.len());
    }
    assert_eq!(differ, 0);
    // Direction-major thread order over two segments with a gap between them
    // (probes 0..5, then 9..27; 5..9 in batch order): the same hit at every ray.
    let segments = [
        TraceSegment { first_ray: 0, probe_count: 5, rays_per_probe: 64 },
        TraceSegment { first_ray: 9 * 64, probe_count: 18, rays_per_probe: 64 },
    ];
    for order in [&segments[..], &segments[1..], &[]] {
        // A fresh batch each time, its hits zeroed: a ray no thread traced would show.
        let batch = GpuProbeRayGen::new(&ctx)
            .generate(&ctx, &trace, &origins, f32::INFINITY, probe_ray_rotation(1, 2), 64, None)
            .expect("gen");
        batch.configure(&ctx, false, order);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        trace.record(&mut encoder, &bvh, &batch, None);
        ctx.queue.submit([encoder.finish()]);
        let reordered = trace.download(&ctx, &batch).expect("hits");
        let differ = reordered.iter().zip(&uploaded).filter(|(a, b)| a != b).count();
        assert_eq!(differ, 0, "{} segments: {differ} of {} hits differ", order.len(), reordered.len());
    }
    // Inside the box (open at the front) most rays hit.
    let hits = generated.iter().filter(|h| h.is_hit()).count();
    assert!(hits > generated.len() / 2, "{hits} of {} rays hit", generated.len());
}
