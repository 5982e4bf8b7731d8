//! The ray-casting interface renderers use, so that another tracer (Embree, a GPU
//! BVH) can be dropped in behind it. Implementations must not allocate per ray.

use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: Vec3,
    /// Unit direction.
    pub dir: Vec3,
    pub t_min: f32,
    pub t_max: f32,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self { origin, dir, t_min: 0.0, t_max: f32::INFINITY }
    }

    pub fn segment(origin: Vec3, dir: Vec3, t_max: f32) -> Self {
        Self { origin, dir, t_min: 0.0, t_max }
    }

    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    pub t: f32,
    /// Index into `Scene::mesh.triangles`.
    pub triangle: u32,
    /// Weights of vertices 1 and 2; vertex 0 gets `1 - x - y`.
    pub barycentric: Vec2,
    /// The ray hit the back (clockwise) side: geometric normal · ray direction > 0.
    /// DDGI shortens and zeroes such samples (seed 004 §4.1).
    pub backface: bool,
    /// Index into `Scene::instances` when the hit is on an instance (then
    /// `triangle` indexes its prototype's mesh); `u32::MAX` otherwise.
    pub instance: u32,
}

/// Closest-hit and any-hit queries over a fixed set of triangles.
pub trait RayTracer: Send + Sync {
    /// Nearest intersection with `t` in `[t_min, t_max]`, both faces.
    fn closest_hit(&self, ray: &Ray) -> Option<RayHit>;
    /// Whether anything intersects the ray within `[t_min, t_max]` (shadow rays).
    fn occluded(&self, ray: &Ray) -> bool;
    /// A tracer over `posed` (a scene set to `frame` by `Scene::set_frame_from`),
    /// or `None` when this one already matches it (no moving geometry).
    fn at_frame<'a>(&'a self, _posed: &crate::Scene, _frame: f32) -> Option<Box<dyn RayTracer + 'a>> {
        None
    }
    /// A tracer over the geometry that never moves, or `None` when that is all
    /// there is. DDGI classifies and relocates probes against it (seed 004 §6:
    /// dynamic objects wake probes instead).
    fn static_part<'a>(&'a self) -> Option<Box<dyn RayTracer + 'a>> {
        None
    }
}
