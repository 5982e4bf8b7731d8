//! Colour maths: luminance, the sRGB transfer functions and the tone-mapping
//! operator used everywhere an HDR image becomes 8-bit (PNG output and the HDR
//! branch of `probegi compare`).

use glam::Vec3;

/// Rec. 709 / sRGB relative luminance of a linear colour.
pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// sRGB electro-optical transfer function (IEC 61966-2-1): encoded `[0,1]` to linear.
pub fn srgb_to_linear(encoded: f32) -> f32 {
    if encoded <= 0.04045 { encoded / 12.92 } else { ((encoded + 0.055) / 1.055).powf(2.4) }
}

/// Inverse of [`srgb_to_linear`]; input is clamped to `[0,1]`.
pub fn linear_to_srgb(linear: f32) -> f32 {
    let l = if linear.is_nan() { 0.0 } else { linear.clamp(0.0, 1.0) };
    if l <= 0.003_130_8 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 }
}

/// Lookup table from an 8-bit sRGB code to linear, built once per texture user.
pub fn srgb8_to_linear_table() -> [f32; 256] {
    let mut t = [0.0; 256];
    for (i, v) in t.iter_mut().enumerate() {
        *v = srgb_to_linear(i as f32 / 255.0);
    }
    t
}

/// Human-readable name of [`tonemap`], shown in `--help`.
pub const TONEMAP_NAME: &str = "ACES filmic (Narkowicz 2015 fit), exposure 1, then sRGB OETF";

/// The single HDR → display operator: Narkowicz's fit of the ACES filmic curve
/// applied per channel, followed by the sRGB OETF. Output in `[0,1]`.
///
/// One fixed operator, so that PNGs written by `render`/`reference` and HDR input
/// to `compare` are mapped identically before LDR-FLIP.
pub fn tonemap(linear: Vec3) -> Vec3 {
    fn aces(x: f32) -> f32 {
        let x = if x.is_finite() { x.max(0.0) } else { 0.0 };
        let (a, b, c, d, e) = (2.51, 0.03, 2.43, 0.59, 0.14);
        ((x * (a * x + b)) / (x * (c * x + d) + e)).clamp(0.0, 1.0)
    }
    Vec3::new(linear_to_srgb(aces(linear.x)), linear_to_srgb(aces(linear.y)), linear_to_srgb(aces(linear.z)))
}

/// [`tonemap`] quantised to 8-bit sRGB.
pub fn tonemap_rgb8(linear: Vec3) -> [u8; 3] {
    let t = tonemap(linear);
    [quantize(t.x), quantize(t.y), quantize(t.z)]
}

/// `[0,1]` to `0..=255`, rounding to nearest.
pub fn quantize(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip_is_exact_to_1e5() {
        for i in 0..=1000 {
            let x = i as f32 / 1000.0;
            let back = srgb_to_linear(linear_to_srgb(x));
            assert!((back - x).abs() < 1e-5, "{x} -> {back}");
        }
    }

    #[test]
    fn srgb_known_values() {
        // 0.5 linear is 0.7354 encoded; encoded 0.5 is 0.2140 linear.
        assert!((linear_to_srgb(0.5) - 0.735_356_7).abs() < 1e-5);
        assert!((srgb_to_linear(0.5) - 0.214_041_14).abs() < 1e-5);
    }

    #[test]
    fn tonemap_is_monotonic_bounded_and_nan_safe() {
        let mut prev = -1.0;
        for i in 0..2000 {
            let x = i as f32 * 0.01;
            let y = tonemap(Vec3::splat(x)).x;
            assert!((0.0..=1.0).contains(&y));
            assert!(y >= prev);
            prev = y;
        }
        assert_eq!(tonemap(Vec3::new(f32::NAN, f32::INFINITY, -1.0)).x, 0.0);
        assert_eq!(tonemap_rgb8(Vec3::ZERO), [0, 0, 0]);
        assert_eq!(tonemap_rgb8(Vec3::splat(1e6)), [255, 255, 255]);
    }

    #[test]
    fn luminance_of_white_is_one() {
        assert!((luminance(Vec3::ONE) - 1.0).abs() < 1e-6);
    }
}
