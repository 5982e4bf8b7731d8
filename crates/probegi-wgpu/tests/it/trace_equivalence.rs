//! The GPU trace (`bvh.wgsl`) against the CPU tracer over the same obvhs CWBVH:
//! random rays from points spread over each scene's bounds, closest hit and any
//! hit, on the built-in Cornell box, the shared Sibenik (75k triangles) and the
//! shared scrub pine (alpha-cut leaves, tested inside the traversal on both
//! sides). Scenes with a top level (the instanced forest; the room of
//! `scenes/moving-box.toml` with a box that moves, turns and grows, at a frame
//! and with moving objects left out) are held the same way, instance included.
//!
//! On lavapipe every answer equals the CPU's. A real GPU may fuse multiply-adds
//! and divide approximately, so each hit is held to the bound of
//! `common::trace_error`, computed per ray from its condition (the origin's
//! distance to the plane, the angle of incidence, the triangle's shape, a placed
//! copy's transform): on the same triangle, t and the barycentrics agree within
//! it; a different answer (hit/miss, triangle, copy, occlusion) must come from a
//! ray whose hit lies within that tolerance of a boundary (an edge, a segment's
//! end, or a cutout triangle's coverage test), or from two hits whose distances
//! tie within it. A wrong triangle away from any tie fails. The number of such
//! disagreements is held to what the tolerances predict (`allowed`).
//! Hostile rays (NaN, ±∞, zero, denormal, huge) finish under the same rule on both.
use crate::common;

use common::trace_error::{self, HitTolerance};
use glam::Vec3;
use probegi_core::rng::Pcg32;
use probegi_core::sampling::sample_uniform_sphere;
use probegi_scene::{BvhSettings, BvhTracer, Ray, RayHit, RayTracer, Scene, load_scene};
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

/// What the GPU's closest and any hits over `rays` random rays and as many
/// segments showed against the CPU's (the bounds: `common::trace_error` and
/// [`assert_agrees`]).
struct Agreement {
    rays: usize,
    hits: usize,
    /// Hit/miss or triangle disagreements of the closest hit, each near a tie.
    closest_disagree: usize,
    /// Occlusion disagreements over segments, each near a tie.
    any_disagree: usize,
    /// How many of the closest-hit and of the segment disagreements are expected
    /// at most, on average: Σ over both sides' hits of the chance that the hit
    /// lies within its tolerance of a boundary (see [`expected_near_ties`]).
    expected_closest: f64,
    expected_any: f64,
    /// Largest |Δt| over its tolerance on same-triangle hits (≤ 1), and the
    /// largest relative Δt for the log.
    worst_dt_share: f64,
    max_rel_dt: f64,
}

fn compare(ctx: &probegi_wgpu::GpuContext, scene: &Scene, n: usize) -> Agreement {
    let cpu = BvhTracer::for_scene(scene, BvhSettings::default());
    let bvh = GpuBvh::upload(ctx, &cpu.export()).expect("upload");
    compare_with(ctx, (scene, 0.0), &cpu, &bvh, n, false)
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

/// A hit and its tolerance, on the scene as posed for the trace; the hit must
/// be a true meeting of the ray with the triangle it names
/// (`trace_error::is_genuine`), whichever side reported it.
fn with_tolerance(posed: (&Scene, f32), ray: &Ray, hit: RayHit) -> (RayHit, HitTolerance) {
    let tri = trace_error::world_triangle(posed.0, posed.1, &hit);
    let tol = trace_error::hit_tolerance(ray, hit.t, &tri);
    assert!(trace_error::is_genuine(ray, &hit, &tri, &tol), "{hit:?} is no hit of {ray:?} ({tol:?})");
    (hit, tol)
}

/// The chance that a hit lies within its tolerance of a boundary its side's
/// rounding may cross: an edge (a point spread evenly over a triangle lies within
/// barycentric distance δ of an edge with chance 1 − (1 − 3δ)² ≤ 6δ), or the
/// segment's end (a hit distance spread evenly over [0, t_max] lies within Δt of
/// t_max with chance Δt/t_max). Summed over both sides' hits, it is the expected
/// number of rays whose answer a rounding may flip.
fn expected_near_ties(hit: &(RayHit, HitTolerance), t_max: f32) -> f64 {
    let edge = (6.0 * hit.1.bary).min(1.0);
    let end = if t_max.is_finite() { (hit.1.dt / t_max as f64).min(1.0) } else { 0.0 };
    edge + end
}

/// Whether another surface lies just behind the CPU's closest hit, within twice
/// its distance tolerance (coplanar or crossing triangles, a box resting on a
/// floor): the two sides may order those hits either way, so such a ray counts
/// as a certain candidate for a disagreement, not a chance.
fn tie_behind(cpu: &dyn RayTracer, r: &Ray, c: &(RayHit, HitTolerance)) -> bool {
    let reach = (c.0.t as f64 + 2.0 * c.1.dt) as f32;
    cpu.occluded(&Ray { t_min: c.0.t.next_up(), t_max: reach.min(r.t_max), ..*r })
}

/// The expected number of disagreements one ray contributes (at most 1): its
/// CPU hit's and its GPU hit's chances of lying near a boundary, or a certain
/// tie behind the CPU's hit.
fn expected_for(
    cpu: &dyn RayTracer,
    r: &Ray,
    c: &Option<(RayHit, HitTolerance)>,
    g: &Option<(RayHit, HitTolerance)>,
) -> f64 {
    let tie = c.as_ref().is_some_and(|c| tie_behind(cpu, r, c));
    let chance: f64 = [c, g].iter().flat_map(|h| h.as_ref()).map(|h| expected_near_ties(h, r.t_max)).sum();
    if tie { 1.0 } else { chance.min(1.0) }
}

/// Whether a hit is within its tolerance of a boundary: an edge, the segment's
/// end, or (unmeasured) a cutout's.
fn near_a_boundary(scene: &Scene, ray: &Ray, hit: &(RayHit, HitTolerance)) -> bool {
    trace_error::near_an_edge(&hit.0, &hit.1)
        || (ray.t_max.is_finite() && (ray.t_max - hit.0.t) as f64 <= hit.1.dt)
        || trace_error::cut_out(scene, &hit.0)
}

/// Two closest hits of one ray that differ (hit/miss, triangle or copy) must be
/// a near tie: both hit distances within their tolerances of each other, or a
/// hit within its tolerance of a boundary.
fn assert_near_a_tie(scene: &Scene, r: &Ray, c: &Option<(RayHit, HitTolerance)>, g: &Option<(RayHit, HitTolerance)>) {
    let tie = match (c, g) {
        (Some(c), Some(g)) => (c.0.t - g.0.t).abs() as f64 <= c.1.dt + g.1.dt,
        _ => false,
    };
    let near = [c, g].iter().flat_map(|h| h.as_ref()).any(|h| near_a_boundary(scene, r, h));
    assert!(
        tie || near,
        "the GPU's closest hit {:?} and the CPU's {:?} differ far from a tie: {r:?}",
        g.map(|h| h.0),
        c.map(|h| h.0)
    );
}

/// The closest hits and segment occlusion of `n` random rays through `bvh`
/// against `cpu`'s, on `posed` (the scene at a frame, for the hit triangles'
/// tolerances). A same-triangle hit must agree within its tolerance in t and the
/// barycentrics; a disagreement must sit within one side's tolerance of a
/// boundary (or the two hit distances within their tolerances of each other);
/// anything else panics. The counts are left to [`assert_agrees`].
fn compare_with(
    ctx: &probegi_wgpu::GpuContext,
    posed: (&Scene, f32),
    cpu: &dyn RayTracer,
    bvh: &GpuBvh,
    n: usize,
    static_only: bool,
) -> Agreement {
    let scene = posed.0;
    let rays = random_rays(scene, n, 0.0);
    let gpu = gpu_trace(ctx, bvh, &rays, false, static_only);
    let mut a = Agreement {
        rays: n,
        hits: 0,
        closest_disagree: 0,
        any_disagree: 0,
        expected_closest: 0.0,
        expected_any: 0.0,
        worst_dt_share: 0.0,
        max_rel_dt: 0.0,
    };
    for (r, g) in rays.iter().zip(&gpu) {
        let c = cpu.closest_hit(r).map(|h| with_tolerance(posed, r, h));
        let g = g.ray_hit().map(|h| with_tolerance(posed, r, h));
        a.expected_closest += expected_for(cpu, r, &c, &g);
        match (&c, &g) {
            (None, None) => {}
            (Some(c), Some(g)) if c.0.triangle == g.0.triangle && c.0.instance == g.0.instance => {
                a.hits += 1;
                let tol = &c.1;
                assert_eq!(c.0.backface, g.0.backface, "same triangle, other face: {r:?}");
                let dt = (c.0.t - g.0.t).abs() as f64;
                assert!(dt <= tol.dt, "Δt {dt:e} > {:e} (t {}): {r:?}", tol.dt, c.0.t);
                a.worst_dt_share = a.worst_dt_share.max(dt / tol.dt);
                a.max_rel_dt = a.max_rel_dt.max(dt / c.0.t as f64);
                let db = (c.0.barycentric - g.0.barycentric).abs().max_element() as f64;
                assert!(db <= tol.bary, "barycentrics {db:e} > {:e}: {r:?}", tol.bary);
            }
            _ => {
                a.hits += usize::from(c.is_some());
                a.closest_disagree += 1;
                assert_near_a_tie(scene, r, &c, &g);
            }
        }
    }
    // Any hit over segments a fifth of the scene long: occlusion must agree but
    // within a tolerance of a boundary. A side that found no hit missed the
    // other side's (for the CPU: its closest in the segment), so that hit is the
    // one near a boundary.
    let segs = random_rays(scene, n, 0.2);
    let occluded = gpu_trace(ctx, bvh, &segs, true, static_only);
    for (r, g) in segs.iter().zip(&occluded) {
        let c = cpu.closest_hit(r).map(|h| with_tolerance(posed, r, h));
        let g = g.ray_hit().map(|h| with_tolerance(posed, r, h));
        a.expected_any += expected_for(cpu, r, &c, &g);
        assert_eq!(c.is_some(), cpu.occluded(r), "the CPU's closest and any hit agree: {r:?}");
        if c.is_some() != g.is_some() {
            a.any_disagree += 1;
            let hit = c.as_ref().or(g.as_ref()).expect("one side hit");
            assert!(near_a_boundary(scene, r, hit), "occlusion differs far from a tie: {:?}, {r:?}", hit.0);
        }
    }
    eprintln!(
        "{n} rays: {} hits, {} closest-hit disagreements (expected at most {:.2}), {} any-hit disagreements \
         (expected at most {:.2}), max relative Δt {:.2e}, largest Δt {:.3} of its tolerance",
        a.hits, a.closest_disagree, a.expected_closest, a.any_disagree, a.expected_any, a.max_rel_dt, a.worst_dt_share
    );
    a
}

/// The disagreement counts against their expectation: a Poisson count of mean E
/// exceeds 2E + 6 with chance below 6e-5 for every E (computed over E in
/// [0, 200]), so a count past it is no rounding's doing.
fn allowed(expected: f64) -> usize {
    (2.0 * expected + 6.0).floor() as usize
}

fn assert_agrees(a: &Agreement) {
    assert!(a.hits > a.rays / 10, "too few hits to test: {}", a.hits);
    assert!(
        a.closest_disagree <= allowed(a.expected_closest),
        "closest hit: {} disagreements > 2·{:.2} + 6",
        a.closest_disagree,
        a.expected_closest
    );
    assert!(
        a.any_disagree <= allowed(a.expected_any),
        "any hit: {} disagreements > 2·{:.2} + 6",
        a.any_disagree,
        a.expected_any
    );
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
    let a = compare_with(&ctx, (&scene, 0.0), &cpu, &bvh, 20_000, false);
    assert_agrees(&a);
    // Hits land on many copies, not one.
    let rays = random_rays(&scene, 2_000, 0.0);
    let copies: std::collections::BTreeSet<u32> =
        gpu_trace(&ctx, &bvh, &rays, false, false).iter().filter(|h| h.is_hit()).map(|h| h.instance).collect();
    assert!(copies.len() > 20, "{} copies hit", copies.len());
}

/// `scenes/moving-box.toml`: a room whose blue box slides, turns and grows.
fn moving_box_room() -> Scene {
    let path = common::repo_file("scenes/moving-box.toml");
    load_scene(&path).expect("moving box")
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
        let a = compare_with(&ctx, (&posed, frame), framed.as_ref(), &bvh, 20_000, false);
        assert_agrees(&a);
        // Rays aimed at the box where it is at this frame hit it.
        let (lo, hi) = posed.moving_object_bounds()[0];
        let rays = aimed_rays(&base, (lo + hi) * 0.5, 2_000);
        let box_tris = base.objects.iter().find(|o| o.name == "blue box").expect("blue box").triangles();
        let on_box =
            |h: &Option<(RayHit, HitTolerance)>| h.is_some_and(|h| box_tris.contains(&(h.0.triangle as usize)));
        // Where one side hits the box and the other does not, the ray passes
        // within a tolerance of a boundary; no more of them than expected.
        let (mut flips, mut expected) = (0, 0.0);
        moved_hits = 0;
        for (r, g) in rays.iter().zip(gpu_trace(&ctx, &bvh, &rays, false, false)) {
            let c = framed.closest_hit(r).map(|h| with_tolerance((&posed, frame), r, h));
            let g = g.ray_hit().map(|h| with_tolerance((&posed, frame), r, h));
            expected += expected_for(framed.as_ref(), r, &c, &g);
            moved_hits += usize::from(on_box(&g));
            if on_box(&c) != on_box(&g) {
                flips += 1;
                assert_near_a_tie(&posed, r, &c, &g);
            }
        }
        assert!(moved_hits > 100, "frame {frame}: {moved_hits} of 2000 aimed rays hit the box");
        assert!(
            flips <= allowed(expected),
            "frame {frame}: {flips} rays hit the box on one side only > 2·{expected:.2} + 6"
        );
    }
    // Static only: what the CPU's static part sees (the box left out).
    let statics = cpu.static_part().expect("a static part");
    let a = compare_with(&ctx, (&base, 0.0), statics.as_ref(), &bvh, 20_000, true);
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

/// obvhs `RtTriangle::intersect` as a device may run it: every dot and cross
/// product fused (`mul_add`), and the reciprocal of D off by 2.5 ulp either way
/// (`off` = ±1). Returns t and the barycentrics of vertices 1 and 2.
fn fused_intersect(ray: &Ray, p: [Vec3; 3], off: f32) -> (f32, glam::Vec2) {
    let dot = |a: Vec3, b: Vec3| a.x.mul_add(b.x, a.y.mul_add(b.y, a.z * b.z));
    let cross = |a: Vec3, b: Vec3| {
        Vec3::new(a.y.mul_add(b.z, -(a.z * b.y)), a.z.mul_add(b.x, -(a.x * b.z)), a.x.mul_add(b.y, -(a.y * b.x)))
    };
    let (e1, e2) = (p[0] - p[1], p[2] - p[0]);
    let ng = e1.cross(e2);
    let c = p[0] - ray.origin;
    let r = cross(ray.dir, c);
    let inv_det = (1.0 / dot(ng, ray.dir)) * (1.0 + off * 2.5 * f32::EPSILON);
    (dot(ng, c) * inv_det, glam::Vec2::new(dot(r, e2) * inv_det, dot(r, e1) * inv_det))
}

/// The tolerances of `common::trace_error` hold against a device emulated on
/// the CPU: the CPU's closest hits recomputed with fused multiply-adds and an
/// approximate reciprocal (in the copy's space for instances, the ray moved
/// there with fused operations too) stay within them in t and barycentrics, in
/// the Cornell box, Sibenik and the instanced forest. Needs no device.
#[test]
fn the_tolerances_cover_a_device_that_fuses_and_approximates_emulated_on_the_cpu() {
    let scenes = [
        probegi_scene::builtin::cornell_box(),
        load_scene(&common::shared("sibenik/sibenik.obj")).expect("shared Sibenik"),
        load_scene("builtin:forest").expect("built-in forest (shared pine)"),
    ];
    for scene in &scenes {
        let cpu = BvhTracer::for_scene(scene, BvhSettings::default());
        let (mut worst_dt, mut worst_bary, mut hits) = (0f64, 0f64, 0);
        for (k, r) in random_rays(scene, 20_000, 0.0).iter().enumerate() {
            let Some(hit) = cpu.closest_hit(r) else { continue };
            let tri = trace_error::world_triangle(scene, 0.0, &hit);
            let tol = trace_error::hit_tolerance(r, hit.t, &tri);
            let (local, p) = match scene.instances.get(hit.instance as usize) {
                Some(inst) => {
                    let m = inst.world_from_local.inverse();
                    let fused = |v: Vec3, w: f32| {
                        let (x, y, z) = (Vec3::from(m.matrix3.x_axis), Vec3::from(m.matrix3.y_axis), m.matrix3.z_axis);
                        x.mul_add(Vec3::splat(v.x), y.mul_add(Vec3::splat(v.y), Vec3::from(z) * v.z))
                            + Vec3::from(m.translation) * w
                    };
                    let mesh = &scene.prototypes[inst.prototype as usize].mesh;
                    let p = mesh.triangles[hit.triangle as usize].map(|v| mesh.positions[v as usize]);
                    (Ray { origin: fused(r.origin, 1.0), dir: fused(r.dir, 0.0), ..*r }, p)
                }
                None => (*r, scene.mesh.triangles[hit.triangle as usize].map(|v| scene.mesh.positions[v as usize])),
            };
            let (t, bary) = fused_intersect(&local, p, if k % 2 == 0 { 1.0 } else { -1.0 });
            worst_dt = worst_dt.max((t - hit.t).abs() as f64 / tol.dt);
            worst_bary = worst_bary.max((bary - hit.barycentric).abs().max_element() as f64 / tol.bary);
            hits += 1;
        }
        eprintln!(
            "{hits} hits: emulated device Δt up to {worst_dt:.3}, barycentrics up to {worst_bary:.3} of the tolerance"
        );
        assert!(hits > 2_000, "{hits} hits");
        assert!(
            worst_dt <= 1.0 && worst_bary <= 1.0,
            "Δt {worst_dt} or barycentrics {worst_bary} beyond the tolerance"
        );
    }
}
