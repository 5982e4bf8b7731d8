//! The ray and hit records every tracer speaks: a ray with its `[t_min, t_max]`
//! range, and the triangle, barycentrics and side of a hit.

use glam::{Vec2, Vec3};

/// A ray `origin + t · dir` over `t` in `[t_min, t_max]`.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Start point, world space.
    pub origin: Vec3,
    /// Unit direction.
    pub dir: Vec3,
    /// Nearest distance along `dir` that counts.
    pub t_min: f32,
    /// Farthest distance along `dir` that counts (`INFINITY`: unbounded).
    pub t_max: f32,
}

impl Ray {
    /// An unbounded ray from `origin` along `dir`.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self { origin, dir, t_min: 0.0, t_max: f32::INFINITY }
    }

    /// A ray from `origin` along `dir` up to distance `t_max` (a shadow or visibility segment).
    pub fn segment(origin: Vec3, dir: Vec3, t_max: f32) -> Self {
        Self { origin, dir, t_min: 0.0, t_max }
    }

    /// The point at distance `t` along the ray.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// Where a ray hit a triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Distance along the ray.
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
