//! The ray and hit records every tracer speaks: a ray with its `[t_min, t_max]`
//! range, and the triangle, barycentrics and side of a hit.

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
