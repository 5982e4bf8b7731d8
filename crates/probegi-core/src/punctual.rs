//! Attenuation of punctual lights exactly as the glTF KHR_lights_punctual
//! specification defines it (its "Range Property" and "Inner and Outer Cone
//! Angles" sections). Units follow the spec: point and spot `intensity` is
//! radiant intensity (the spec's candela, used here directly as W·sr⁻¹ per
//! colour channel), directional `intensity` is irradiance at normal incidence
//! (the spec's lux, used as W·m⁻²).

/// The spec's recommended range window: `clamp(1 - (d/range)^4, 0, 1)^2`.
/// `None` means infinite range, i.e. pure inverse-square falloff.
pub fn range_window(distance_m: f32, range_m: Option<f32>) -> f32 {
    match range_m {
        Some(r) if r > 0.0 => {
            let q = distance_m / r;
            (1.0 - q * q * q * q).clamp(0.0, 1.0).powi(2)
        }
        _ => 1.0,
    }
}

/// Spot cone attenuation. `cos_angle` is the cosine between the spot direction
/// and the direction from the light to the shaded point. The spec's smooth
/// falloff: `t = saturate((cos - cos_outer) / max(1e-3, cos_inner - cos_outer))`, squared.
pub fn spot_cone_attenuation(cos_angle: f32, inner_cone_angle: f32, outer_cone_angle: f32) -> f32 {
    let cos_outer = outer_cone_angle.cos();
    let cos_inner = inner_cone_angle.cos();
    let scale = 1.0 / (cos_inner - cos_outer).max(1e-3);
    let offset = -cos_outer * scale;
    let t = (cos_angle * scale + offset).clamp(0.0, 1.0);
    t * t
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::FRAC_PI_4;

    #[test]
    fn spot_is_full_inside_inner_zero_outside_outer() {
        let inner = 0.2;
        assert_eq!(spot_cone_attenuation(1.0, inner, FRAC_PI_4), 1.0);
        assert_eq!(spot_cone_attenuation(inner.cos() + 1e-4, inner, FRAC_PI_4), 1.0);
        assert_eq!(spot_cone_attenuation((FRAC_PI_4 + 0.01).cos(), inner, FRAC_PI_4), 0.0);
        let mid = ((inner + FRAC_PI_4) * 0.5).cos();
        let a = spot_cone_attenuation(mid, inner, FRAC_PI_4);
        assert!(a > 0.0 && a < 1.0);
    }

    #[test]
    fn range_window_bounds() {
        assert_eq!(range_window(5.0, None), 1.0);
        assert_eq!(range_window(0.0, Some(2.0)), 1.0);
        assert_eq!(range_window(2.0, Some(2.0)), 0.0);
        assert_eq!(range_window(3.0, Some(2.0)), 0.0);
        assert!((range_window(1.0, Some(2.0)) - (1.0f32 - 1.0 / 16.0).powi(2)).abs() < 1e-6);
    }
}
