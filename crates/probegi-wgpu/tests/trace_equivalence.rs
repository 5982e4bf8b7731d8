//! The GPU trace (`bvh.wgsl`) against the CPU tracer over the same obvhs CWBVH:
//! random rays from points spread over each scene's bounds, closest hit and any
//! hit, on the built-in Cornell box, the shared Sibenik (75k triangles) and the
//! shared scrub pine (alpha-cut leaves, tested inside the traversal on both
//! sides). On lavapipe every hit, triangle, t and any-hit answer is identical to
//! the CPU's. Other adapters may round differently (fused multiply-adds), so that
//! a ray grazing an edge picks a neighbouring triangle; the bounds allow that:
//! at most 0.2 % of rays disagree on hit or triangle, and hits on the same
//! triangle agree to 1e-4 relative in t. Scenes with a top level (the
//! instanced forest; the room of `scenes/moving-box.toml` with a box that moves, turns and grows, at a
//! frame and with moving objects left out) agree as closely, instance included.
//! Hostile rays (NaN, ±∞, zero, denormal, huge) finish under the same rule on both.

mod common;

use glam::Vec3;
use probegi_core::rng::Pcg32;
use probegi_core::sampling::sample_uniform_sphere;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, Scene, load_scene};
use probegi_wgpu::bvh_trace::{GpuBvh, GpuRay, GpuRayHit, GpuRayTrace};

fn random_rays(scene: &Scene, n: usize, max_rel: f32) -> Vec<Ray> {
    let (lo, hi) = scene.bounds().expect("geometry");
    let extent = hi - lo;
    let mut rng = Pcg32::new(7, 11);
    (0..n)
        .map(|_| {
            let o = lo + extent * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let d = sample_uniform_sphere(rng.next_vec2());
            let t_max = if max_rel > 0.0 { max_rel * extent.length() } else { f32::INFINITY };
            Ray::segment(o, d, t_max)
        })
        .collect()
}

/// `n` rays from points spread over the scene's bounds towards `target`.
fn aimed_rays(scene: &Scene, target: Vec3, n: usize) -> Vec<Ray> {
    random_rays(scene, n, 0.0).into_iter().map(|r| Ray::new(r.origin, (target - r.origin).normalize())).collect()
}

struct Agreement {
    rays: usize,
    hits: usize,
    hit_disagree: usize,
    triangle_disagree: usize,
    max_rel_dt: f32,
    any_disagree: usize,
}

fn compare(ctx: &probegi_wgpu::GpuContext, scene: &Scene, n: usize) -> Agreement {
    let cpu = BvhTracer::for_scene(scene, BvhSettings::default());
    let bvh = GpuBvh::upload(ctx, &cpu.export()).expect("upload");
    compare_with(ctx, scene, &cpu, &bvh, n, false)
}

/// The GPU's traces of `n` random rays (closest hit, then any hit over
/// segments) through `bvh`, moving objects left out with `static_only`.
fn gpu_trace(
    ctx: &probegi_wgpu::GpuContext,
    bvh: &GpuBvh,
    rays: &[Ray],
    any_hit: bool,
    static_only: bool,
) -> Vec<GpuRayHit> {
    let trace = GpuRayTrace::new(ctx);
    let gpu_rays: Vec<GpuRay> = rays.iter().map(|r| GpuRay::new(r.origin, r.dir, r.t_min, r.t_max)).collect();
    let batch = trace.batch(ctx, &gpu_rays, any_hit).expect("batch");
    batch.set_static_only(ctx, static_only);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    trace.record(&mut encoder, bvh, &batch, None);
    ctx.queue.submit([encoder.finish()]);
    trace.download(ctx, &batch).expect("hits")
}

fn compare_with(
    ctx: &probegi_wgpu::GpuContext,
    scene: &Scene,
    cpu: &dyn RayTracer,
    bvh: &GpuBvh,
    n: usize,
    static_only: bool,
) -> Agreement {
    let rays = random_rays(scene, n, 0.0);
    let gpu = gpu_trace(ctx, bvh, &rays, false, static_only);
    let mut a = Agreement { rays: n, hits: 0, hit_disagree: 0, triangle_disagree: 0, max_rel_dt: 0.0, any_disagree: 0 };
    for (r, g) in rays.iter().zip(&gpu) {
        match (cpu.closest_hit(r), g.ray_hit()) {
            (None, None) => {}
            (Some(c), Some(g)) => {
                a.hits += 1;
                if c.triangle != g.triangle || c.instance != g.instance {
                    a.triangle_disagree += 1;
                } else {
                    assert_eq!(c.backface, g.backface, "same triangle, other face");
                    a.max_rel_dt = a.max_rel_dt.max((c.t - g.t).abs() / c.t.max(1e-3));
                    assert!((c.barycentric - g.barycentric).abs().max_element() < 1e-3);
                }
            }
            _ => a.hit_disagree += 1,
        }
    }
    // Any hit over segments a fifth of the scene long: occlusion must agree.
    let segs = random_rays(scene, n, 0.2);
    let occluded = gpu_trace(ctx, bvh, &segs, true, static_only);
    a.any_disagree = segs.iter().zip(&occluded).filter(|(r, g)| cpu.occluded(r) != g.is_hit()).count();
    eprintln!(
        "{n} rays: {} hits, {} hit/miss and {} triangle disagreements, max relative Δt {:.2e}, {} any-hit disagreements",
        a.hits, a.hit_disagree, a.triangle_disagree, a.max_rel_dt, a.any_disagree
    );
    a
}

fn assert_agrees(a: &Agreement) {
    let allowed = a.rays / 500;
    assert!(a.hits > a.rays / 10, "too few hits to test: {}", a.hits);
    assert!(
        a.hit_disagree + a.triangle_disagree <= allowed,
        "{} + {} > {allowed}",
        a.hit_disagree,
        a.triangle_disagree
    );
    assert!(a.any_disagree <= allowed, "any hit: {} > {allowed}", a.any_disagree);
    assert!(a.max_rel_dt < 1e-4, "Δt {:e}", a.max_rel_dt);
}

#[test]
fn cornell_box_hits_match_the_cpu_tracer() {
    let Some(ctx) = common::context() else { return };
    let a = compare(&ctx, &probegi_scene::builtin::cornell_box(), 20_000);
    assert_agrees(&a);
}

#[test]
fn sibenik_hits_match_the_cpu_tracer() {
    let Some(ctx) = common::context() else { return };
    let scene = load_scene(&common::shared("sibenik/sibenik.obj")).expect("shared Sibenik");
    let a = compare(&ctx, &scene, 20_000);
    assert_agrees(&a);
}

#[test]
fn scrub_pine_cutouts_are_tested_inside_the_gpu_traversal() {
    let Some(ctx) = common::context() else { return };
    let scene = load_scene(&common::shared("scrub-pine/scrubPine.obj")).expect("shared pine");
    let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
    assert!(cpu.cutout_triangle_count() > 0, "the pine's leaves are cut out");
    let a = compare(&ctx, &scene, 20_000);
    assert_agrees(&a);
    // The same rays with every triangle opaque hit more: the cutouts did something.
    let mut opaque = scene.clone();
    for m in &mut opaque.materials {
        m.alpha_mode = probegi_scene::material::AlphaMode::Opaque;
    }
    let b = compare(&ctx, &opaque, 20_000);
    assert!(b.hits as f64 > a.hits as f64 * 1.05, "opaque {} vs cut {}", b.hits, a.hits);
}

#[test]
fn instanced_forest_hits_match_the_cpu_tracer_instance_for_instance() {
    let Some(ctx) = common::context() else { return };
    let scene = load_scene("builtin:forest").expect("built-in forest (shared pine)");
    assert!(scene.instances.len() >= 30, "{} pines", scene.instances.len());
    let cpu = BvhTracer::for_scene(&scene, BvhSettings::default());
    let export = cpu.export();
    assert_eq!(export.tlas.as_ref().map(|t| t.instances.len()), Some(scene.instances.len() + 1));
    let bvh = GpuBvh::upload(&ctx, &export).expect("upload");
    let a = compare_with(&ctx, &scene, &cpu, &bvh, 20_000, false);
    assert_agrees(&a);
    // Hits land on many copies, not one.
    let rays = random_rays(&scene, 2_000, 0.0);
    let copies: std::collections::BTreeSet<u32> =
        gpu_trace(&ctx, &bvh, &rays, false, false).iter().filter(|h| h.is_hit()).map(|h| h.instance).collect();
    assert!(copies.len() > 20, "{} copies hit", copies.len());
}

/// `scenes/moving-box.toml`: a room whose blue box slides, turns and grows.
fn moving_box_room() -> Scene {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/moving-box.toml");
    load_scene(&path.to_string_lossy()).expect("moving box")
}

#[test]
fn a_moving_box_is_placed_by_the_top_level_and_left_out_of_static_traces() {
    let Some(ctx) = common::context() else { return };
    let base = moving_box_room();
    let cpu = BvhTracer::for_scene(&base, BvhSettings::default());
    let export = cpu.export();
    let bvh = GpuBvh::upload(&ctx, &export).expect("upload");
    let layout = cpu.tlas_layout().expect("a top level");
    let mut posed = base.clone();
    let mut moved_hits = 0;
    for frame in [0.0f32, 13.0] {
        posed.set_frame_from(&base, frame);
        let framed = cpu.at_frame(&posed, frame).expect("moving scene");
        bvh.place(&ctx, &layout.export_at(&posed, frame).expect("layout"), &export.blas_root_nodes).expect("place");
        let a = compare_with(&ctx, &base, framed.as_ref(), &bvh, 20_000, false);
        assert_agrees(&a);
        // Rays aimed at the box where it is at this frame hit it.
        let (lo, hi) = posed.moving_object_bounds()[0];
        let rays = aimed_rays(&base, (lo + hi) * 0.5, 2_000);
        let box_tris = base.objects.iter().find(|o| o.name == "blue box").expect("blue box").triangles();
        moved_hits = gpu_trace(&ctx, &bvh, &rays, false, false)
            .iter()
            .filter(|h| h.is_hit() && box_tris.contains(&((h.triangle & 0x7fff_ffff) as usize)))
            .count();
        let cpu_hits = rays
            .iter()
            .filter(|r| framed.closest_hit(r).is_some_and(|h| box_tris.contains(&(h.triangle as usize))))
            .count();
        assert!(moved_hits > 100, "frame {frame}: {moved_hits} of 2000 aimed rays hit the box");
        assert!(moved_hits.abs_diff(cpu_hits) <= 4, "frame {frame}: {moved_hits} GPU, {cpu_hits} CPU hits on the box");
    }
    // Static only: what the CPU's static part sees (the box left out).
    let statics = cpu.static_part().expect("a static part");
    let a = compare_with(&ctx, &base, statics.as_ref(), &bvh, 20_000, true);
    assert_agrees(&a);
    let (lo, hi) = posed.moving_object_bounds()[0];
    let rays = aimed_rays(&base, (lo + hi) * 0.5, 2_000);
    let box_tris = base.objects.iter().find(|o| o.name == "blue box").expect("blue box").triangles();
    let still = gpu_trace(&ctx, &bvh, &rays, false, true)
        .iter()
        .filter(|h| h.is_hit() && box_tris.contains(&((h.triangle & 0x7fff_ffff) as usize)))
        .count();
    assert_eq!(still, 0, "static-only traces hit the box ({moved_hits} hits with it)");
    // The chunked trace (batches larger than one binding) leaves it out the same way.
    let gpu_rays: Vec<GpuRay> = rays.iter().map(|r| GpuRay::new(r.origin, r.dir, r.t_min, r.t_max)).collect();
    let chunked = GpuRayTrace::new(&ctx).trace_static_only(&ctx, &bvh, &gpu_rays, false, true).expect("trace");
    assert_eq!(chunked, gpu_trace(&ctx, &bvh, &rays, false, true));
}

/// `bvh.wgsl` keeps the CPU's ray rule and walk bound (`probegi_scene::bvh_walk`):
/// every hostile ray finishes, the refused ones are misses of both queries
/// and are counted on the device, and the extreme rays the rule traces
/// answer as on the CPU, on the shared Sponza and through the forest's top level.
fn hostile_rays_agree(ctx: &probegi_wgpu::GpuContext, scene: &Scene) {
    let cpu = BvhTracer::for_scene(scene, BvhSettings::default());
    let bvh = GpuBvh::upload(ctx, &cpu.export()).expect("upload");
    let (lo, hi) = scene.bounds().expect("geometry");
    let (refused, traced) = probegi_scene::bvh_walk::hostile_rays((lo + hi) * 0.5);
    for any_hit in [false, true] {
        let gpu = gpu_trace(ctx, &bvh, &refused, any_hit, false);
        assert!(gpu.iter().all(|h| !h.is_hit()), "refused rays must miss: {gpu:?}");
    }
    let counts = bvh.trace_guard_counts(ctx).expect("guards");
    assert_eq!(counts.rays_refused, 2 * refused.len() as u64, "{counts:?}");
    let closest = gpu_trace(ctx, &bvh, &traced, false, false);
    let occluded = gpu_trace(ctx, &bvh, &traced, true, false);
    for ((r, c), o) in traced.iter().zip(&closest).zip(&occluded) {
        // Near f32::MAX the CPU's SIMD node test and the GPU's scalar one may
        // round differently; such rays only have to answer.
        if r.origin.abs().max_element() > 1e6 || r.dir.abs().max_element() > 1e6 {
            assert!(c.ray_hit().is_none_or(|h| h.t.is_finite()), "{r:?}");
            continue;
        }
        let want = cpu.closest_hit(r);
        assert_eq!(want.map(|h| (h.triangle, h.instance)), c.ray_hit().map(|h| (h.triangle, h.instance)), "{r:?}");
        assert_eq!(cpu.occluded(r), o.is_hit(), "{r:?}");
    }
    let counts = bvh.trace_guard_counts(ctx).expect("guards");
    assert_eq!(counts.walks_cut_short, 0, "{counts:?}");
    assert_eq!(cpu.trace_guard_counts().walks_cut_short, 0);
}

#[test]
fn hostile_rays_finish_as_misses_or_as_on_the_cpu() {
    let Some(ctx) = common::context() else { return };
    hostile_rays_agree(&ctx, &load_scene(&common::shared("dabrovic-sponza/sponza.obj")).expect("shared Sponza"));
    hostile_rays_agree(&ctx, &load_scene("builtin:forest").expect("built-in forest (shared pine)"));
}
