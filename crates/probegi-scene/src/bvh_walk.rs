//! The tracer's ray rule and its bounded walks of obvhs's CWBVH. The same rule
//! and bound hold in `probegi-wgpu`'s `bvh.wgsl` (`bvh_ray_usable`,
//! `bvh_trace_skipping`), so every ray gets the same defined answer on both
//! backends, whatever an engine hands the seam.
//!
//! **The ray rule.** Direction components smaller in magnitude than
//! `f32::MIN_POSITIVE` (denormals) are flushed to zero, as GPUs do. A ray is
//! then traced when its origin and direction are finite, its direction is not
//! zero, `t_min` is finite, `t_max` is not NaN and `t_min ≤ t_max`. Every other
//! ray (NaN, ±∞, a zero direction, an empty or NaN range) is a **miss**: no
//! closest hit, not occluded. The tracer counts them
//! ([`TraceGuardCounts::rays_refused`]).
//!
//! **The bound.** A walk of a tree enters each node at most once, so no walk
//! of one BVH level may enter more nodes than that level holds. obvhs's
//! `traverse!` loop has no such bound (a ray made of NaNs spun in it forever);
//! the walks here count the nodes they enter. A walk that reaches the bound is
//! a bug: debug builds assert, release builds return a miss and count it
//! ([`TraceGuardCounts::walks_cut_short`]).

use std::sync::atomic::{AtomicU64, Ordering};

use glam::{UVec2, Vec3, Vec3A};
use obvhs::cwbvh::CwBvh;
use obvhs::ray::Ray as ObRay;

use crate::ray::Ray;

/// Rays a tracer answered without a full walk, since it was built.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct TraceGuardCounts {
    /// Rays the ray rule made a miss (non-finite, zero direction, empty range).
    pub rays_refused: u64,
    /// Walks that reached the node bound and returned a miss (release builds).
    pub walks_cut_short: u64,
}

/// The counters behind [`TraceGuardCounts`], shared by a tracer's threads.
#[derive(Debug, Default)]
pub(crate) struct TraceGuards {
    rays_refused: AtomicU64,
    walks_cut_short: AtomicU64,
}

impl TraceGuards {
    pub(crate) fn counts(&self) -> TraceGuardCounts {
        TraceGuardCounts {
            rays_refused: self.rays_refused.load(Ordering::Relaxed),
            walks_cut_short: self.walks_cut_short.load(Ordering::Relaxed),
        }
    }

    /// The obvhs ray for `ray` under the ray rule, or `None` (counted) for a miss.
    pub(crate) fn usable(&self, ray: &Ray) -> Option<ObRay> {
        let r = usable_ray(ray);
        if r.is_none() {
            self.rays_refused.fetch_add(1, Ordering::Relaxed);
        }
        r
    }

    fn cut_short(&self) {
        debug_assert!(false, "a BVH walk entered more nodes than its BVH holds");
        self.walks_cut_short.fetch_add(1, Ordering::Relaxed);
    }
}

/// Whether the ray rule (module docs) traces `ray` at all; every other ray is
/// a miss on both backends.
pub fn ray_is_traced(ray: &Ray) -> bool {
    usable_ray(ray).is_some()
}

/// The ray rule (module docs): the obvhs ray, or `None` for a miss.
pub(crate) fn usable_ray(ray: &Ray) -> Option<ObRay> {
    let flush = |c: f32| if c.abs() < f32::MIN_POSITIVE { 0.0 } else { c };
    // + 0.0 turns negative zeros positive: obvhs misses boxes along a direction
    // such as (-1, -0, -0) (seen on a unit cube), which `-Vec3::X` produces.
    let dir = Vec3::new(flush(ray.dir.x), flush(ray.dir.y), flush(ray.dir.z)) + Vec3::ZERO;
    let range_ok = ray.t_min.is_finite() && !ray.t_max.is_nan() && ray.t_min <= ray.t_max;
    let usable = ray.origin.is_finite() && dir.is_finite() && dir != Vec3::ZERO && range_ok;
    usable.then(|| ObRay::new(ray.origin.into(), dir.into(), ray.t_min, ray.t_max))
}

/// The nodes a walk of one BVH may still enter (the bound of the module docs).
struct NodeBudget {
    left: usize,
    /// The walk wanted one more node than its BVH holds.
    cut_short: bool,
}

impl NodeBudget {
    fn of(bvh: &CwBvh) -> Self {
        Self { left: bvh.nodes.len(), cut_short: false }
    }

    /// Takes one node; `false` (and `cut_short`) once the BVH's count is spent.
    #[inline(always)]
    fn enter(&mut self) -> bool {
        match self.left.checked_sub(1) {
            Some(left) => {
                self.left = left;
                true
            }
            None => {
                self.cut_short = true;
                false
            }
        }
    }
}

/// The closest primitive of `bvh` along `ray` whose `intersect` distance is
/// below the ray's `tmax` (leaf index and t), entering at most as many nodes as
/// `bvh` holds.
#[inline]
pub(crate) fn closest(
    bvh: &CwBvh,
    guards: &TraceGuards,
    ray: ObRay,
    mut intersect: impl FnMut(&ObRay, usize) -> f32,
) -> Option<(u32, f32)> {
    let mut traverse_ray = ray;
    let mut best = None;
    let mut state = bvh.new_traversal(ray.direction);
    let mut node;
    let mut budget = NodeBudget::of(bvh);
    obvhs::traverse!(
        bvh,
        node,
        state,
        {
            if !budget.enter() {
                break;
            }
            node.intersect_ray(&traverse_ray, state.oct_inv4)
        },
        {
            let t = intersect(&traverse_ray, state.primitive_id as usize);
            if t < traverse_ray.tmax {
                best = Some((state.primitive_id, t));
                traverse_ray.tmax = t;
            }
        }
    );
    if budget.cut_short {
        guards.cut_short();
        return None;
    }
    best
}

/// Whether any primitive of `bvh` has an `intersect` distance below the ray's
/// `tmax`, entering at most as many nodes as `bvh` holds.
#[inline]
pub(crate) fn any(
    bvh: &CwBvh,
    guards: &TraceGuards,
    ray: ObRay,
    mut intersect: impl FnMut(&ObRay, usize) -> f32,
) -> bool {
    let mut state = bvh.new_traversal(ray.direction);
    let mut node;
    let mut budget = NodeBudget::of(bvh);
    let mut found = false;
    'walk: {
        obvhs::traverse!(
            bvh,
            node,
            state,
            {
                if !budget.enter() {
                    break;
                }
                node.intersect_ray(&ray, state.oct_inv4)
            },
            {
                if intersect(&ray, state.primitive_id as usize) < ray.tmax {
                    found = true;
                    break 'walk;
                }
            }
        );
    }
    if budget.cut_short {
        guards.cut_short();
        return false;
    }
    found
}

/// `r` moved into a space by `local_from_world` (unnormalised direction: the
/// ray parameter t is the same in both spaces); a ray the move made unusable
/// (an overflow to ±∞) is `None`.
pub(crate) fn moved_ray(r: &ObRay, local_from_world: &glam::Affine3A) -> Option<ObRay> {
    // Denormals flushed and negative zeros cleared, as `usable_ray` does.
    let moved = local_from_world.transform_vector3a(r.direction);
    let flush = |c: f32| if c.abs() < f32::MIN_POSITIVE { 0.0 } else { c };
    let dir = Vec3A::new(flush(moved.x), flush(moved.y), flush(moved.z)) + Vec3A::ZERO;
    let origin = local_from_world.transform_point3a(r.origin);
    (origin.is_finite() && dir.is_finite() && dir != Vec3A::ZERO).then(|| ObRay::new(origin, dir, r.tmin, r.tmax))
}

/// A corpus of hostile rays for the tests and fuzzers of every backend:
/// rays the rule refuses (NaN, ±∞, zero and denormal directions, NaN and
/// empty ranges), then finite but extreme rays it traces (origins and
/// directions near `f32::MAX`, denormal components, zero-length and far
/// ranges), around the point `inside` of a scene.
pub fn hostile_rays(inside: Vec3) -> (Vec<Ray>, Vec<Ray>) {
    let (nan, inf) = (f32::NAN, f32::INFINITY);
    let ok = Ray::new(inside, Vec3::new(0.3, -0.8, 0.52).normalize());
    let mut refused = vec![];
    for origin in [Vec3::splat(nan), Vec3::new(inf, 0.0, 0.0), Vec3::new(0.0, -inf, 0.0), Vec3::new(nan, 1.0, 1.0)] {
        refused.push(Ray { origin, ..ok });
    }
    for dir in [
        Vec3::splat(nan),
        Vec3::new(nan, 0.0, 1.0),
        Vec3::new(inf, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -inf),
        Vec3::ZERO,
        Vec3::splat(-0.0),
        Vec3::splat(1e-40),
        Vec3::splat(f32::MIN_POSITIVE / 2.0),
    ] {
        refused.push(Ray { dir, ..ok });
    }
    for (t_min, t_max) in [(nan, inf), (0.0, nan), (5.0, 1.0), (inf, inf), (-inf, 1.0)] {
        refused.push(Ray { t_min, t_max, ..ok });
    }
    let mut traced = vec![ok, Ray { dir: Vec3::new(1.0, 1e-40, -0.0), ..ok }, Ray { t_max: f32::MAX, ..ok }];
    for origin in [Vec3::splat(1e38), Vec3::splat(-3e38), Vec3::new(1e30, inside.y, inside.z)] {
        traced.push(Ray { origin, ..ok });
        traced.push(Ray { origin, dir: (inside - origin).normalize_or(Vec3::X), ..ok });
    }
    for dir in [Vec3::splat(1e38), Vec3::new(3e38, -3e38, 1.0), Vec3::new(1e-30, 0.0, 0.0), Vec3::Y, -Vec3::Y] {
        traced.push(Ray { dir, ..ok });
    }
    traced.push(Ray { t_min: 0.0, t_max: 0.0, ..ok });
    traced.push(Ray { t_min: 1e30, t_max: f32::INFINITY, ..ok });
    (refused, traced)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ray_rule_refuses_non_finite_zero_and_empty_rays_and_flushes_denormals() {
        let ok = Ray::new(Vec3::ZERO, Vec3::X);
        assert!(usable_ray(&ok).is_some());
        for bad in [
            Ray { origin: Vec3::NAN, ..ok },
            Ray { origin: Vec3::new(f32::INFINITY, 0.0, 0.0), ..ok },
            Ray { dir: Vec3::new(f32::NAN, 0.0, 0.0), ..ok },
            Ray { dir: Vec3::new(0.0, f32::NEG_INFINITY, 0.0), ..ok },
            Ray { dir: Vec3::ZERO, ..ok },
            Ray { dir: Vec3::splat(1e-40), ..ok },
            Ray { t_min: f32::NAN, ..ok },
            Ray { t_max: f32::NAN, ..ok },
            Ray { t_min: 2.0, t_max: 1.0, ..ok },
            Ray { t_min: f32::INFINITY, ..ok },
        ] {
            assert!(usable_ray(&bad).is_none(), "{bad:?}");
        }
        let r = usable_ray(&Ray { dir: Vec3::new(1.0, 1e-40, -0.0), ..ok }).expect("usable");
        assert_eq!(<[f32; 3]>::from(r.direction), [1.0, 0.0, 0.0]);
        assert!(r.direction.y.is_sign_positive() && r.direction.z.is_sign_positive());
    }

    #[test]
    fn guards_count_refused_rays() {
        let g = TraceGuards::default();
        assert!(g.usable(&Ray::new(Vec3::NAN, Vec3::X)).is_none());
        assert!(g.usable(&Ray::new(Vec3::ZERO, Vec3::X)).is_some());
        assert_eq!(g.counts(), TraceGuardCounts { rays_refused: 1, walks_cut_short: 0 });
    }

    #[test]
    fn an_empty_bvh_is_walked_without_entering_a_node() {
        let g = TraceGuards::default();
        let r = usable_ray(&Ray::new(Vec3::ZERO, Vec3::X)).expect("usable");
        assert_eq!(closest(&CwBvh::default(), &g, r, |_, _| 0.0), None);
        assert!(!any(&CwBvh::default(), &g, r, |_, _| 0.0));
    }
}
