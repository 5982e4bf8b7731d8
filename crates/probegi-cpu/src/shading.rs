//! The surface model every CPU renderer shares: two-sided Lambertian reflection
//! with albedo/π, shadow-ray construction, and the direct contribution of
//! punctual lights.

use glam::Vec3;
use probegi_scene::{Ray, RayTracer, Scene, SurfacePoint};
use std::f32::consts::FRAC_1_PI;

use crate::light_sampling::punctual_incident;

/// Cosine of `wi` to the side of the surface the viewer is on, or `None` when `wi`
/// points into the surface (by the shading or the geometric normal): two-sided
/// Lambertian reflects on the viewer's side only.
pub fn lambert_cos(sp: &SurfacePoint, wi: Vec3) -> Option<f32> {
    let cos = wi.dot(sp.facing_normal());
    (cos > 0.0 && wi.dot(sp.facing_geometric_normal()) > 0.0).then_some(cos)
}

/// Shadow ray from the surface toward a point, stopping just short of it.
pub fn shadow_ray_to(sp: &SurfacePoint, point: Vec3) -> Ray {
    let origin = sp.spawn_origin(point - sp.position);
    let to = point - origin;
    let d = to.length();
    Ray::segment(origin, to / d, d * (1.0 - 1e-4))
}

/// Shadow ray from the surface along `wi` for `distance` (may be infinite).
pub fn shadow_ray_along(sp: &SurfacePoint, wi: Vec3, distance: f32) -> Ray {
    Ray::segment(sp.spawn_origin(wi), wi, if distance.is_finite() { distance * (1.0 - 1e-4) } else { f32::INFINITY })
}

/// Radiance reflected toward the viewer from all punctual lights (exact, one shadow
/// ray each). Returns the radiance and the number of rays traced.
pub fn punctual_direct(scene: &Scene, tracer: &dyn RayTracer, sp: &SurfacePoint, albedo: Vec3) -> (Vec3, u64) {
    let mut l = Vec3::ZERO;
    let mut rays = 0;
    for light in &scene.lights {
        let Some(inc) = punctual_incident(light, sp.position) else { continue };
        let Some(cos) = lambert_cos(sp, inc.wi) else { continue };
        rays += 1;
        if !tracer.occluded(&shadow_ray_along(sp, inc.wi, inc.distance)) {
            l += albedo * FRAC_1_PI * inc.irradiance * cos;
        }
    }
    (l, rays)
}
