//! The ray-casting interface renderers use, so that another tracer (Embree, a GPU
//! BVH) can be dropped in behind it. Implementations must not allocate per ray.

pub use crate::ray::{Ray, RayHit};
use crate::scene::Scene;

/// Closest-hit and any-hit queries over a fixed set of triangles.
pub trait RayTracer: Send + Sync {
    /// Nearest intersection with `t` in `[t_min, t_max]`, both faces.
    fn closest_hit(&self, ray: &Ray) -> Option<RayHit>;
    /// Whether anything intersects the ray within `[t_min, t_max]` (shadow rays).
    fn occluded(&self, ray: &Ray) -> bool;
    /// A tracer over `posed` (a scene set to `frame` by `Scene::set_frame_from`),
    /// or `None` when this one already matches it (no moving geometry).
    fn at_frame<'a>(&'a self, _posed: &Scene, _frame: f32) -> Option<Box<dyn RayTracer + 'a>> {
        None
    }
    /// A tracer over the geometry that never moves, or `None` when that is all
    /// there is. DDGI classifies and relocates probes against it (seed 004 §6:
    /// dynamic objects wake probes instead).
    fn static_part<'a>(&'a self) -> Option<Box<dyn RayTracer + 'a>> {
        None
    }
}
