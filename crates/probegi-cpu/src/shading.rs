//! The surface model every CPU renderer shares: the two-sided BSDF of
//! `probegi_core::bsdf` in the frame of the shading normal on the viewer's side,
//! shadow-ray construction, and the direct contribution of punctual lights.

use glam::Vec3;
use probegi_core::bsdf::SurfaceBsdf;
use probegi_core::sampling::Frame;
use probegi_scene::{Ray, RayTracer, Scene, SurfacePoint};

use crate::light_sampling::punctual_incident;

/// Cosine of `wi` to the side of the surface the viewer is on, or `None` when `wi`
/// points into the surface (by the shading or the geometric normal): two-sided
/// surfaces reflect on the viewer's side only.
pub fn lambert_cos(sp: &SurfacePoint, wi: Vec3) -> Option<f32> {
    let cos = wi.dot(sp.facing_normal());
    (cos > 0.0 && wi.dot(sp.facing_geometric_normal()) > 0.0).then_some(cos)
}

/// A surface point ready for BSDF queries with world-space directions.
#[derive(Clone, Copy, Debug)]
pub struct ShadingContext {
    /// Orthonormal frame around the facing shading normal.
    pub frame: Frame,
    /// Direction toward the viewer, local frame (+z = facing normal).
    pub wo: Vec3,
    /// The surface's BSDF at the point.
    pub bsdf: SurfaceBsdf,
}

impl ShadingContext {
    /// The context at `sp` seen from the unit direction `to_viewer_world`.
    pub fn new(scene: &Scene, sp: &SurfacePoint, to_viewer_world: Vec3) -> Self {
        let frame = Frame::from_normal(sp.facing_normal());
        let mut wo = frame.to_local(to_viewer_world);
        // Interpolated normals can put the viewer slightly below the shading horizon.
        wo.z = wo.z.max(1e-4);
        Self { frame, wo: wo.normalize(), bsdf: scene.bsdf(sp) }
    }

    /// The BSDF for light arriving from `wi_world`, toward the viewer (no cosine).
    pub fn eval(&self, wi_world: Vec3) -> Vec3 {
        self.bsdf.eval(self.wo, self.frame.to_local(wi_world))
    }

    /// The diffuse lobe alone for light arriving from `wi_world` (no cosine).
    pub fn eval_diffuse(&self, wi_world: Vec3) -> Vec3 {
        self.bsdf.eval_diffuse(self.frame.to_local(wi_world))
    }

    /// Density of sampling `wi_world` from the BSDF, per steradian.
    pub fn pdf(&self, wi_world: Vec3) -> f32 {
        self.bsdf.pdf(self.wo, self.frame.to_local(wi_world))
    }
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

/// A punctual light's visibility in `[0, 1]` at a surface point toward unit
/// direction `wi` from somewhere other than a shadow ray (the shadowing field,
/// `DdgiFieldSet::shadow_visibility`); `None` where it has none, and a shadow
/// ray decides.
pub type PunctualVisibility<'a> = dyn Fn(&SurfacePoint, Vec3) -> Option<f32> + Sync + 'a;

/// Radiance reflected toward the viewer from all punctual lights (exact, one shadow
/// ray each). Returns the radiance and the number of rays traced.
pub fn punctual_direct(scene: &Scene, tracer: &dyn RayTracer, sp: &SurfacePoint, ctx: &ShadingContext) -> (Vec3, u64) {
    punctual_direct_with(scene, tracer, sp, ctx, None)
}

/// [`punctual_direct`], with each light's visibility from `visibility` where it
/// gives one (no shadow ray then).
pub fn punctual_direct_with(
    scene: &Scene,
    tracer: &dyn RayTracer,
    sp: &SurfacePoint,
    ctx: &ShadingContext,
    visibility: Option<&PunctualVisibility<'_>>,
) -> (Vec3, u64) {
    let mut l = Vec3::ZERO;
    let mut rays = 0;
    for light in &scene.lights {
        let Some(inc) = punctual_incident(light, sp.position) else { continue };
        let Some(cos) = lambert_cos(sp, inc.wi) else { continue };
        let v = match visibility.and_then(|v| v(sp, inc.wi)) {
            Some(v) => v,
            None => {
                rays += 1;
                if tracer.occluded(&shadow_ray_along(sp, inc.wi, inc.distance)) { 0.0 } else { 1.0 }
            }
        };
        if v > 0.0 {
            l += ctx.eval(inc.wi) * inc.irradiance * (cos * v);
        }
    }
    (l, rays)
}
