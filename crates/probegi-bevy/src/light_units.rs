//! Bevy's photometric light units in probegi's (glTF KHR_lights_punctual's).
//!
//! probegi's `PunctualLight::intensity` is glTF's: radiant intensity for point
//! and spot lights (glTF's candela, read as W·sr⁻¹) and irradiance at normal
//! incidence for directional lights (glTF's lux, read as W·m⁻²), and its
//! emissive radiance and sky radiance are per steradian and square metre. The
//! plugin keeps Bevy's photometric numbers as they are in those slots (1 cd
//! becomes 1 W·sr⁻¹): the field's irradiance is then in Bevy's own units
//! (lux), and the camera's `Exposure` applies to the field's light as it does
//! to Bevy's direct light. Only the quantities differ:
//!
//! - `PointLight::intensity` is luminous power (lm) emitted over the whole
//!   sphere; a point light's intensity is Φ / 4π cd. Bevy's renderer divides
//!   the same way (`bevy_pbr` 0.20 `render/light.rs`, extraction of point lights).
//! - `SpotLight::intensity` is also in lumens, and Bevy treats a spot as the
//!   point light of that power masked by its cone (Φ / 4π cd, the same
//!   division in the same file), not as Φ spread over the cone: so does this.
//! - `DirectionalLight::illuminance` is in lux: glTF's unit, unchanged.
//! - `StandardMaterial::emissive` with `emissive_exposure_weight` w: Bevy
//!   draws `emissive × mix(1, exposure, w)` (`pbr_functions.wesl`), so the
//!   luminance that the camera's exposure would draw so is
//!   `emissive × ((1 − w) / exposure + w)` cd·m⁻² ([`emissive_luminance`]).
//!   At w = 1 the emissive is luminance as it is; at Bevy's default w = 0 it
//!   is a display value, which the field reads as the light it shows (1 000×
//!   at Bevy's default EV100 of 9.7). The camera is the first active 3D
//!   camera (by `Camera::order`, then entity), its `Exposure` or Bevy's default.
//! - The clear colour (the camera's `ClearColorConfig::Custom`, else the
//!   `ClearColor` resource): Bevy writes it into the view target as it is,
//!   where a surface's light arrives × exposure, so the sky that would draw
//!   it has luminance `clear / exposure` cd·m⁻² ([`clear_color_luminance`]),
//!   the same reading as a w = 0 emissive. A camera that clears to nothing
//!   (`ClearColorConfig::None`) has no sky: black.
//! - A spot's cone: Bevy's `inner_angle` / `outer_angle` are half-angles from
//!   the axis with the falloff `clamp((cos θ − cos outer) / (cos inner − cos outer))²`,
//!   glTF's `innerConeAngle` / `outerConeAngle` and falloff.
//! - Bevy's `range` cuts a light off with glTF's window `(1 − (d/range)⁴)²`.

use std::f32::consts::PI;

/// A point light's radiant intensity (W·sr⁻¹, glTF's cd) from Bevy's
/// `PointLight::intensity` in lumens.
pub fn point_intensity_from_lumens(lumens: f32) -> f32 {
    lumens / (4.0 * PI)
}

/// A spot light's radiant intensity along its axis from Bevy's
/// `SpotLight::intensity` in lumens: Bevy's point-light division (see the
/// module docs).
pub fn spot_intensity_from_lumens(lumens: f32) -> f32 {
    lumens / (4.0 * PI)
}

/// A spot's (inner, outer) cone half-angles as Bevy draws them: the outer
/// held below π/2 − 10⁻⁴, the inner to [0, outer] (`bevy_pbr` 0.20
/// `render/light.rs`, extraction of spot lights). probegi's falloff would
/// light the half-space behind a spot whose outer angle reached π/2.
pub fn spot_cone(inner: f32, outer: f32) -> (f32, f32) {
    let outer = outer.clamp(0.0, std::f32::consts::FRAC_PI_2 - 1.0e-4);
    (inner.clamp(0.0, outer), outer)
}

/// A directional light's irradiance at normal incidence (W·m⁻², glTF's lux)
/// from Bevy's `DirectionalLight::illuminance` in lux.
pub fn directional_irradiance_from_lux(lux: f32) -> f32 {
    lux
}

/// The luminance (cd·m⁻²) of Bevy's `emissive` at `exposure_weight` seen
/// through a camera of `exposure` (Bevy's `Exposure::exposure()`): see the
/// module docs.
pub fn emissive_luminance(emissive: glam::Vec3, exposure_weight: f32, exposure: f32) -> glam::Vec3 {
    // Not clamped: Bevy's `mix` is not either.
    let w = exposure_weight;
    emissive * ((1.0 - w) / exposure.max(f32::MIN_POSITIVE) + w)
}

/// The sky luminance (cd·m⁻²) that a camera of `exposure` would draw as its
/// linear clear colour `clear`: see the module docs.
pub fn clear_color_luminance(clear: glam::Vec3, exposure: f32) -> glam::Vec3 {
    clear / exposure.max(f32::MIN_POSITIVE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_light_of_4_pi_lumens_is_one_candela_in_every_direction() {
        assert!((point_intensity_from_lumens(4.0 * PI) - 1.0).abs() < 1e-6);
        // Bevy's own example figure: a 1 000 000 lm light gives 79 577 cd.
        assert!((point_intensity_from_lumens(1.0e6) - 79_577.47).abs() < 0.1);
        assert_eq!(spot_intensity_from_lumens(800.0), point_intensity_from_lumens(800.0));
        assert_eq!(directional_irradiance_from_lux(10_000.0), 10_000.0);
        // Bevy's clamps: an outer angle of π/2 or more, an inner past the outer.
        let (inner, outer) = spot_cone(2.0, 2.0);
        assert!(outer < std::f32::consts::FRAC_PI_2 && inner == outer);
        assert_eq!(spot_cone(0.2, 0.5), (0.2, 0.5));
    }
}
