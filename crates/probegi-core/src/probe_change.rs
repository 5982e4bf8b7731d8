//! How much a probe changed in its last blend: the priority signal of the
//! per-frame ray budget (`probegi_field::ray_budget`; seed 003 §8.2, seed 000
//! §5.2).
//!
//! Seed 000 §5.2 proposes "absolute percentage errors, e.g. SMAPE" between the
//! current and the previous frame in the YCoCg space of Vardis et al. We take:
//! - **irradiance**: per interior texel the SMAPE of its encoded (γ, seed 004
//!   §4.2) colour as a YCoCg vector, Σ|a − b| / Σ(|a| + |b|) over the three
//!   components (0 where both are black), averaged over the tile. The encoded
//!   values are what queries interpolate, and the γ curve makes a relative
//!   change in the dark as visible as one in the light, as SMAPE intends. The
//!   ratio lies in [0, 1].
//! - **visibility** (the shadowing field's occlusion maps, values in [0, 1]):
//!   the mean absolute change. *Deviation:* not a percentage error, which would
//!   make noise in a dark texel (V ≈ 0) look like a large change.
//! - the probe's change is the larger of the two.
//!
//! The values are of one blend, so they include the hysteresis: a texel that
//! moved towards a new value by (1 − α) reports that step.

use glam::Vec3;

use crate::probe_atlas::interior_texel_index;

/// YCoCg of a linear or encoded RGB colour (Malvar & Sullivan's transform).
pub fn ycocg(c: Vec3) -> Vec3 {
    Vec3::new(0.25 * c.x + 0.5 * c.y + 0.25 * c.z, 0.5 * c.x - 0.5 * c.z, -0.25 * c.x + 0.5 * c.y - 0.25 * c.z)
}

/// One texel's SMAPE between `old` and `new` as YCoCg vectors, in [0, 1].
pub fn texel_change(old: Vec3, new: Vec3) -> f32 {
    let (a, b) = (ycocg(old), ycocg(new));
    let den = (a.abs() + b.abs()).element_sum();
    if den > 0.0 { ((a - b).abs().element_sum() / den).min(1.0) } else { 0.0 }
}

/// Mean [`texel_change`] over the interior of an irradiance tile (`interior`²
/// texels, tile-major with the guard border), old against new; texels in
/// row-major order, summed in that order (the WGSL twin sums the same way).
pub fn irradiance_tile_change(old: &[Vec3], new: &[Vec3], interior: u32) -> f32 {
    let mut sum = 0.0f32;
    for j in 0..interior {
        for i in 0..interior {
            let t = interior_texel_index(interior, i, j);
            sum += texel_change(old[t], new[t]);
        }
    }
    sum / (interior * interior).max(1) as f32
}

/// Mean absolute change over the interior of an occlusion tile.
pub fn occlusion_tile_change(old: &[f32], new: &[f32], interior: u32) -> f32 {
    let mut sum = 0.0f32;
    for j in 0..interior {
        for i in 0..interior {
            let t = interior_texel_index(interior, i, j);
            sum += (new[t] - old[t]).abs();
        }
    }
    sum / (interior * interior).max(1) as f32
}

/// A probe's change: the larger of its irradiance and visibility changes.
pub fn probe_change(irradiance: f32, occlusion: Option<f32>) -> f32 {
    let occlusion = occlusion.unwrap_or(0.0);
    // Not a number is no reason to starve a probe: it counts as a full change.
    if !(irradiance.is_finite() && occlusion.is_finite()) {
        return 1.0;
    }
    irradiance.max(occlusion).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ycocg_separates_luma_from_chroma() {
        assert_eq!(ycocg(Vec3::ONE), Vec3::new(1.0, 0.0, 0.0));
        let red = ycocg(Vec3::X);
        assert_eq!(red, Vec3::new(0.25, 0.5, -0.25));
    }

    #[test]
    fn texel_change_is_a_symmetric_ratio_in_zero_one() {
        assert_eq!(texel_change(Vec3::ZERO, Vec3::ZERO), 0.0);
        assert_eq!(texel_change(Vec3::splat(0.3), Vec3::splat(0.3)), 0.0);
        assert_eq!(texel_change(Vec3::ZERO, Vec3::splat(0.5)), 1.0);
        // Grey 1 → 3: |1 − 3| / (1 + 3) on luma alone.
        assert!((texel_change(Vec3::ONE, Vec3::splat(3.0)) - 0.5).abs() < 1e-6);
        let (a, b) = (Vec3::new(0.2, 0.5, 0.1), Vec3::new(0.4, 0.1, 0.3));
        assert_eq!(texel_change(a, b), texel_change(b, a));
        // Relative: the same ratio in the dark and in the light.
        assert!((texel_change(a * 0.01, b * 0.01) - texel_change(a, b)).abs() < 1e-6);
    }

    #[test]
    fn tile_changes_average_the_interior_only() {
        let n = 2;
        let side = (n + 2) as usize;
        let old = vec![Vec3::ONE; side * side];
        let mut new = old.clone();
        new[0] = Vec3::splat(100.0); // a border texel: ignored
        assert_eq!(irradiance_tile_change(&old, &new, n), 0.0);
        new[interior_texel_index(n, 1, 1)] = Vec3::splat(3.0);
        assert!((irradiance_tile_change(&old, &new, n) - 0.5 / 4.0).abs() < 1e-6);
        let (o, mut v) = (vec![1.0; side * side], vec![1.0; side * side]);
        v[interior_texel_index(n, 0, 1)] = 0.2;
        assert!((occlusion_tile_change(&o, &v, n) - 0.2).abs() < 1e-6);
        assert_eq!(probe_change(0.1, Some(0.2)), 0.2);
        assert_eq!(probe_change(f32::NAN, None), 1.0);
    }
}
