//! The GPU trace (`bvh.wgsl`) against the CPU tracer over the same obvhs CWBVH:
//! random rays from points spread over each scene's bounds, closest hit and any
//! hit, on the built-in Cornell box, the shared Sibenik (75k triangles) and the
//! shared scrub pine (alpha-cut leaves, tested inside the traversal on both
//! sides). On lavapipe every hit, triangle, t and any-hit answer is identical to
//! the CPU's. Other adapters may round differently (fused multiply-adds), so that
//! a ray grazing an edge picks a neighbouring triangle; the bounds allow that:
//! at most 0.2 % of rays disagree on hit or triangle, and hits on the same
//! triangle agree to 1e-4 relative in t.

mod common;

use glam::Vec3;
use probegi_core::rng::Pcg32;
use probegi_core::sampling::sample_uniform_sphere;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayTracer, Scene, load_scene};
use probegi_wgpu::bvh_trace::{GpuBvh, GpuRay, GpuRayTrace};

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
    let export = cpu.export_static().expect("static scene");
    let bvh = GpuBvh::upload(ctx, &export).expect("upload");
    let trace = GpuRayTrace::new(ctx);
    let rays = random_rays(scene, n, 0.0);
    let gpu_rays: Vec<GpuRay> = rays.iter().map(|r| GpuRay::new(r.origin, r.dir, r.t_min, r.t_max)).collect();
    let gpu = trace.trace(ctx, &bvh, &gpu_rays, false).expect("trace");
    let mut a = Agreement { rays: n, hits: 0, hit_disagree: 0, triangle_disagree: 0, max_rel_dt: 0.0, any_disagree: 0 };
    for (r, g) in rays.iter().zip(&gpu) {
        match (cpu.closest_hit(r), g.ray_hit()) {
            (None, None) => {}
            (Some(c), Some(g)) => {
                a.hits += 1;
                if c.triangle != g.triangle {
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
    let gpu_segs: Vec<GpuRay> = segs.iter().map(|r| GpuRay::new(r.origin, r.dir, r.t_min, r.t_max)).collect();
    let occluded = trace.trace(ctx, &bvh, &gpu_segs, true).expect("any hit");
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
