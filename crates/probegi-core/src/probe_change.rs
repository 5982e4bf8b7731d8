//! How much a probe changed: the priority signal of the per-frame ray budget
//! (`probegi_field::ray_budget`; seed 003 §8.2, seed 000 §5.2).
//!
//! Seed 000 §5.2 proposes "absolute percentage errors, e.g. SMAPE" between the
//! current and the previous frame in the YCoCg space of Vardis et al. The
//! blends measure, per interior texel, this frame's estimate (the weighted
//! mean of the probe's rays, before hysteresis) against the texel's history,
//! the same pair seed 004 Listing 3's thresholds compare; the probe's change is
//! the mean over its tile:
//! - **irradiance** ([`texel_change`], in `probe_blend::blend_irradiance_tile`):
//!   the SMAPE of the encoded (γ, seed 004 §4.2) colours as YCoCg vectors,
//!   Σ|a − b| / Σ(|a| + |b|) over the three components (0 where both are
//!   black), in [0, 1]. Encoded values are what queries interpolate, and the γ
//!   curve makes a relative change in the dark count as one in the light does.
//! - **visibility** (the shadowing field's occlusion maps, in
//!   `shadow_field::blend_shadow_tile`): the mean absolute difference, in
//!   [0, 1]. *Deviation:* not a percentage error, which would make noise in a
//!   dark texel (V ≈ 0) look like a large change.
//! - a probe's change ([`probe_change`]) is the larger of its irradiance change
//!   in its last blend and its visibility change in its last occlusion blend.
//!
//! Before hysteresis, not after: after it, a light switched off moves a texel
//! by (1 − α) of the step, 3 % at RTXGI's 0.97, which the rays' own noise
//! hides; the estimate against the history shows the whole step.

use glam::Vec3;

/// YCoCg of a linear or encoded RGB colour (Malvar & Sullivan's transform).
pub fn ycocg(c: Vec3) -> Vec3 {
    Vec3::new(0.25 * c.x + 0.5 * c.y + 0.25 * c.z, 0.5 * c.x - 0.5 * c.z, -0.25 * c.x + 0.5 * c.y - 0.25 * c.z)
}

/// One texel's SMAPE between `history` and `estimate` as YCoCg vectors, in [0, 1].
pub fn texel_change(history: Vec3, estimate: Vec3) -> f32 {
    let (a, b) = (ycocg(history), ycocg(estimate));
    let den = (a.abs() + b.abs()).element_sum();
    if den > 0.0 { ((a - b).abs().element_sum() / den).min(1.0) } else { 0.0 }
}

/// A probe's change: the larger of its irradiance and visibility changes;
/// anything not a number counts as a full change (1).
pub fn probe_change(irradiance: f32, occlusion: Option<f32>) -> f32 {
    let occlusion = occlusion.unwrap_or(0.0);
    // Not a number is no reason to starve a probe.
    if !(irradiance.is_finite() && occlusion.is_finite()) {
        return 1.0;
    }
    irradiance.max(occlusion).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::probe_atlas::ProbeAtlas;
    use crate::probe_blend::{BlendWeights, blend_irradiance_tile};

    #[test]
    fn ycocg_separates_luma_from_chroma() {
        assert_eq!(ycocg(Vec3::ONE), Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(ycocg(Vec3::X), Vec3::new(0.25, 0.5, -0.25));
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
        assert_eq!(probe_change(0.1, Some(0.2)), 0.2);
        assert_eq!(probe_change(f32::NAN, None), 1.0);
    }

    #[test]
    fn the_blend_reports_the_step_before_hysteresis() {
        // A converged grey tile whose rays now see 3× the light: the estimate
        // differs from the history by SMAPE 0.5 in γ-encoded terms, whatever
        // the hysteresis, and a repeat of the history reports 0.
        let dirs: Vec<Vec3> = (0..64).map(|i| crate::fibonacci::spherical_fibonacci(i, 64)).collect();
        let w = BlendWeights::new(&dirs, 4, 1.0);
        let gamma = 5.0;
        let mut atlas = ProbeAtlas::<Vec3>::new(1, 4);
        let still = vec![Vec3::ONE; 64];
        assert_eq!(
            blend_irradiance_tile(
                atlas.tile_mut(0),
                4,
                &w,
                &still,
                (0.0, 1),
                &crate::probe_blend::IrradianceBlendRule::plain(gamma),
                &mut []
            ),
            1.0
        );
        assert_eq!(
            blend_irradiance_tile(
                atlas.tile_mut(0),
                4,
                &w,
                &still,
                (0.97, 1),
                &crate::probe_blend::IrradianceBlendRule::plain(gamma),
                &mut []
            ),
            0.0
        );
        let brighter = vec![Vec3::splat(3.0); 64];
        let e = 3f32.powf(1.0 / gamma);
        let expected = (e - 1.0) / (e + 1.0);
        let c = blend_irradiance_tile(
            atlas.tile_mut(0),
            4,
            &w,
            &brighter,
            (0.97, 1),
            &crate::probe_blend::IrradianceBlendRule::plain(gamma),
            &mut [],
        );
        assert!((c - expected).abs() < 1e-4, "change {c}, expected {expected}");
    }
}
