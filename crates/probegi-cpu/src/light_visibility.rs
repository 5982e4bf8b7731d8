//! Light-visibility images (`render --ao`, `reference --ao`): per pixel, the
//! fraction of the punctual lights' unshadowed direct light that reaches the
//! visible surface, `Σ_l w_l V_l / Σ_l w_l` with `w_l` the luminance of the
//! light's irradiance times the cosine, and `V_l` from the shadowing field
//! (seed 003 ch. 5, `DdgiFieldSet::shadow_visibility`; a shadow ray where no
//! volume covers the point) or from an exact shadow ray. It is what the field
//! replaces, so the field's image and the exact one compare directly (seed 003
//! Fig. 7.9–7.10 show the field's). Pixels no punctual light reaches, and the
//! sky, are 0.

use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::color::luminance;
use probegi_core::image::Image;
use probegi_field::DdgiFieldSet;
use probegi_scene::{RayTracer, Scene, SurfacePoint};
use rayon::prelude::*;

use crate::gbuffer::trace_gbuffer;
use crate::light_sampling::punctual_incident;
use crate::shading::{lambert_cos, shadow_ray_along};

/// The visibility image of `scene` seen by `camera` (`width × height`, pixel
/// centres): from `field`'s shadowing field, or exact shadow rays with `None`.
pub fn light_visibility_image(
    scene: &Scene,
    tracer: &dyn RayTracer,
    camera: &CameraRays,
    width: u32,
    height: u32,
    field: Option<&DdgiFieldSet>,
) -> Image {
    let (gbuffer, _) = trace_gbuffer(scene, tracer, camera, width, height, 0, 0);
    let pixels: Vec<Vec3> = gbuffer
        .texels
        .par_iter()
        .map(|t| match &t.surface {
            Some(sp) => Vec3::splat(surface_visibility(scene, tracer, sp, t.view_dir_world, field)),
            None => Vec3::ZERO,
        })
        .collect();
    let mut image = Image::new(width, height);
    image.pixels = pixels;
    image
}

/// One surface point's weighted light visibility (module docs).
fn surface_visibility(
    scene: &Scene,
    tracer: &dyn RayTracer,
    sp: &SurfacePoint,
    view_dir: Vec3,
    field: Option<&DdgiFieldSet>,
) -> f32 {
    let (mut sum, mut wsum) = (0.0f32, 0.0f32);
    let cage = field.and_then(|f| f.shadow_cage(sp.position, sp.facing_normal(), view_dir));
    for light in &scene.lights {
        let Some(inc) = punctual_incident(light, sp.position) else { continue };
        let Some(cos) = lambert_cos(sp, inc.wi) else { continue };
        let w = luminance(inc.irradiance) * cos;
        if !(w > 0.0 && w.is_finite()) {
            continue;
        }
        let v = cage.map(|c| c.visibility(inc.wi));
        let v =
            v.unwrap_or_else(|| if tracer.occluded(&shadow_ray_along(sp, inc.wi, inc.distance)) { 0.0 } else { 1.0 });
        sum += w * v;
        wsum += w;
    }
    if wsum > 0.0 { sum / wsum } else { 0.0 }
}
