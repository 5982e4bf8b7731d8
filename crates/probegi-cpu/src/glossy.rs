//! Second-order glossy from probes (seed 004 §4.4): a glossy surface reached by a
//! ray (a camera glossy ray's hit, or a probe ray's hit) reflects the probes'
//! irradiance reinterpreted as prefiltered radiance at maximum roughness. The atlas
//! holds mean radiance E/π (see `probegi_core::probe_blend`), so the radiance
//! around the mirror direction r is irradiance(x, r)/π; seed 004's factor 2π
//! belongs to RTXGI's storage (E/2π) and converts the same quantity. The term is
//! weighted by the GGX lobe's directional albedo at the viewing angle and roughness
//! (`probegi_core::bsdf::specular_directional_albedo`: Fresnel, masking-shadowing
//! and the energy a rough lobe loses), the split-sum's second factor; the field's
//! cosine-filtered radiance stands in for the prefiltered first factor.

use glam::Vec3;
use probegi_core::bsdf::specular_directional_albedo;
use probegi_core::ddgi_volume_blend::{DdgiFieldSetView, field_set_irradiance};
use probegi_scene::SurfacePoint;
use std::f32::consts::FRAC_1_PI;

use crate::shading::ShadingContext;

/// Specular radiance the surface at `sp` reflects back along `-ray_dir`, from the field.
pub fn second_order_specular(
    field: &DdgiFieldSetView<'_>,
    sp: &SurfacePoint,
    ctx: &ShadingContext,
    ray_dir: Vec3,
) -> Vec3 {
    if !ctx.bsdf.has_specular() {
        return Vec3::ZERO;
    }
    let n = sp.facing_normal();
    let mirror = ray_dir - n * (2.0 * ray_dir.dot(n));
    let e_mirror = field_set_irradiance(field, sp.position, mirror, -ray_dir);
    let b = &ctx.bsdf;
    specular_directional_albedo(b.specular_f0, (-ray_dir).dot(n).max(0.0), b.alpha) * e_mirror * FRAC_1_PI
}
