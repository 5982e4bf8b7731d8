//! Blend pass: fold one frame of probe-ray results into each probe's octahedral
//! maps with hysteresis (seed 003 §4.5; seed 004 §2.3 eq. 1).
//!
//! - Irradiance texel in direction ω (eq. 4.12–4.13): the cosine-weighted mean
//!   Σ max(0, ω·r)·L / Σ max(0, ω·r) of the ray radiances — the mean radiance of
//!   the hemisphere around ω, i.e. irradiance / π. It is stored encoded as
//!   `mean^(1/γ)` (seed 004 Listing 1) and blended as `lerp(new, old, α)`.
//! - Distance texel (eq. 4.14–4.16): the power-cosine (`max(0, ω·r)^k_s`) weighted
//!   mean of the ray length and of its square, lengths clamped to the volume's
//!   distance limit. Deviation, as RTXGI does: normalised by the sum of the
//!   power-cosine weights (the thesis's eq. 4.15 reuses the cosine sum w_sum).
//! - A texel whose weights sum to zero, or whose new value is not finite, keeps its
//!   old value: NaN and Inf never enter an atlas.
//! - Deliberate additions from Timberdoodle PGI (`../shared/PEERS.md`), off by
//!   default ([`IrradianceBlendRule`]): a firefly clamp of the estimate against
//!   the history ([`firefly_clamp`]) and an adaptive per-texel hysteresis
//!   ([`adaptive_texel_hysteresis`]). PEERS names the ideas; the formulas are
//!   ours, measured in docs/RESULTS.md ("PGI's safeguards").
//!
//! All probes share one frame's ray directions (one random rotation per frame), so
//! the texel-to-ray weights are computed once per frame ([`BlendWeights`]) and each
//! probe's blend is a sparse weighted sum over its rays.

use glam::{Vec2, Vec3};

use crate::irradiance_encoding::encode_irradiance;
use crate::octahedral::{oct_decode, texel_center_uv};
use crate::probe_atlas::interior_texel_index;

/// Weights below this are dropped from the sparse tables. `max(0, cos)^50 < 1e-6`
/// beyond 40° from the texel direction; the dropped mass is below float precision
/// of the normalised mean.
pub const BLEND_WEIGHT_EPSILON: f32 = 1e-6;

/// The backface rule of the blend's distances (seed 004 §4.1; RTXGI stores
/// −0.2·t): a ray that hits a back face at distance t is blended with distance
/// `−BACKFACE_DISTANCE_SCALE · t`, so the probe reads as shadowed there.
/// `probe_shade.wgsl` reads it from probegi-wgpu's generated prelude.
pub const BACKFACE_DISTANCE_SCALE: f32 = 0.2;

/// Sparse texel × ray weight table for one frame's ray directions.
#[derive(Clone, Debug, Default)]
pub struct BlendWeights {
    /// Entries of texel `t` are `entries[offsets[t]..offsets[t + 1]]`.
    pub offsets: Vec<u32>,
    /// `(ray index, weight)`.
    pub entries: Vec<(u32, f32)>,
}

impl BlendWeights {
    /// Weights `max(0, ω_t · r)^exponent` for every interior texel `t` of an
    /// `interior × interior` map (row-major) and every ray direction `r`.
    pub fn new(ray_dirs: &[Vec3], interior: u32, exponent: f32) -> Self {
        let mut offsets = Vec::with_capacity((interior * interior + 1) as usize);
        let mut entries = Vec::new();
        offsets.push(0);
        for texel_dir in texel_directions(interior) {
            for (r, d) in ray_dirs.iter().enumerate() {
                let c = texel_dir.dot(*d);
                if c <= 0.0 {
                    continue;
                }
                let w = if exponent == 1.0 { c } else { c.powf(exponent) };
                if w >= BLEND_WEIGHT_EPSILON {
                    entries.push((r as u32, w));
                }
            }
            offsets.push(entries.len() as u32);
        }
        Self { offsets, entries }
    }

    fn texel(&self, t: usize) -> &[(u32, f32)] {
        &self.entries[self.offsets[t] as usize..self.offsets[t + 1] as usize]
    }
}

/// The unit direction of every interior texel of an `interior × interior`
/// octahedral tile, row-major (its centre, decoded): what the blend weighs
/// each ray against.
pub fn texel_directions(interior: u32) -> Vec<Vec3> {
    (0..interior).flat_map(|j| (0..interior).map(move |i| oct_decode(texel_center_uv(i, j, interior)))).collect()
}

/// Tile index of interior texel number `t` (row-major over the interior).
fn interior_index(t: usize, interior: u32) -> usize {
    interior_texel_index(interior, t as u32 % interior, t as u32 / interior)
}

/// Seed 004 §4.3 Listing 3's per-texel thresholds on the change of the encoded
/// irradiance (max component): above `significant` the hysteresis drops by 0.15,
/// above `new_distribution` to 0. Irradiance only; visibility is too unstable.
#[derive(Clone, Copy, Debug)]
pub struct TexelThresholds {
    /// Change above which the texel's hysteresis drops by 0.15 (Listing 3's
    /// `significantChangeThreshold`, default 0.25).
    pub significant: f32,
    /// Change above which the hysteresis drops to 0, replacing the texel (Listing 3's
    /// `newDistributionChangeThreshold`, default 0.8).
    pub new_distribution: f32,
}

/// Listing 3: the texel's hysteresis after its change is known.
pub fn adjusted_hysteresis(hysteresis: f32, change: f32, thresholds: &TexelThresholds) -> f32 {
    let change = change.abs();
    if change > thresholds.new_distribution {
        0.0
    } else if change > thresholds.significant {
        (hysteresis - 0.15).max(0.0)
    } else {
        hysteresis
    }
}

/// Timberdoodle PGI's firefly clamp (`../shared/PEERS.md`): a texel's new
/// estimate is scaled down so that its largest linear component is at most
/// `ratio` × its history's (PGI: 32). Works on encoded values
/// (`mean^(1/γ)`): scaling the linear value by s scales the encoded one by
/// s^(1/γ). A black history (no light yet) clamps nothing, so a light that
/// turns on in a dark room is not held back.
pub fn firefly_clamp(encoded: Vec3, history: Vec3, ratio: f32, gamma: f32) -> Vec3 {
    let old = history.max_element();
    let new = encoded.max_element();
    if old.is_nan() || old <= 0.0 {
        return encoded;
    }
    let limit = old * ratio.powf(1.0 / gamma);
    if new > limit { encoded * (limit / new) } else { encoded }
}

/// What the adaptive hysteresis adds per blend while the texel holds still
/// (Timberdoodle PGI: 0.1 per update).
pub const ADAPTIVE_HYSTERESIS_RISE: f32 = 0.1;

/// Added to the history's largest encoded component before it divides the
/// change (PGI adds 0.01 likewise), so that a nearly black texel's noise does
/// not read as a 100 % change.
pub const ADAPTIVE_HYSTERESIS_FLOOR: f32 = 0.01;

/// Timberdoodle PGI's adaptive per-texel hysteresis (`../shared/PEERS.md`),
/// in the perceptual (γ-encoded) space the blend works in: the texel's state
/// rises by [`ADAPTIVE_HYSTERESIS_RISE`] a blend and falls by the relative
/// change `max|new − old| / (max old + 0.01)` beyond `tolerance` (0: PGI's
/// rule), within [0, 1]; the blend then
/// uses at most that state. A blend whose planned hysteresis is 0 (the
/// probe's history restarts) restarts the state at 0. In encoded space a
/// γ = 5 field's per-frame noise of 10–20 % reads as 2–4 % and lets the state
/// climb, while a light that doubles reads as 15 % a frame and one that goes
/// to a tenth as 37 %, so the texel follows them within a few frames.
pub fn adaptive_texel_hysteresis(state: f32, planned: f32, (history, encoded): (Vec3, Vec3), tolerance: f32) -> f32 {
    if planned.is_nan() || planned <= 0.0 {
        return 0.0;
    }
    let relative =
        (encoded - history).abs().max_element() / (history.max_element().max(0.0) + ADAPTIVE_HYSTERESIS_FLOOR);
    let next = state + ADAPTIVE_HYSTERESIS_RISE - (relative - tolerance).max(0.0);
    if next.is_finite() { next.clamp(0.0, 1.0) } else { 0.0 }
}

/// How a texel's new estimate enters its history: the encoding, seed 004
/// Listing 3's thresholds and Timberdoodle PGI's safeguards.
#[derive(Clone, Copy, Debug)]
pub struct IrradianceBlendRule {
    /// Perceptual encoding exponent γ (seed 004 Listing 1).
    pub gamma: f32,
    /// Listing 3's per-texel thresholds (`probe_fast_convergence`).
    pub thresholds: Option<TexelThresholds>,
    /// [`firefly_clamp`]'s ratio; 0: off.
    pub firefly_clamp_ratio: f32,
    /// [`adaptive_texel_hysteresis`], with one state per texel.
    pub adaptive_hysteresis: bool,
    /// The relative change the adaptive states tolerate before they fall.
    pub adaptive_tolerance: f32,
}

impl IrradianceBlendRule {
    /// A volume's rule: γ, Listing 3's thresholds with `probe_fast_convergence`,
    /// and the PGI safeguards its settings turn on.
    pub fn from_settings(s: &crate::ddgi_settings::DdgiVolumeSettings) -> Self {
        Self {
            gamma: s.probe_irradiance_gamma,
            thresholds: s.probe_fast_convergence.then_some(TexelThresholds {
                significant: s.probe_significant_change_threshold,
                new_distribution: s.probe_new_distribution_threshold,
            }),
            firefly_clamp_ratio: s.probe_firefly_clamp_ratio,
            adaptive_hysteresis: s.probe_adaptive_hysteresis,
            adaptive_tolerance: s.probe_adaptive_hysteresis_tolerance,
        }
    }

    /// The rule with encoding `gamma` alone: no thresholds, no safeguards.
    pub fn plain(gamma: f32) -> Self {
        Self { gamma, thresholds: None, firefly_clamp_ratio: 0.0, adaptive_hysteresis: false, adaptive_tolerance: 0.0 }
    }
}

/// `h` to the power `frames` by repeated multiplication (the WGSL twin's
/// order): the hysteresis of a blend that stands for `frames` per-frame blends
/// of the same estimate (a ray budget's probe that waited; `frames` ≤ 1: `h`).
pub fn hysteresis_over_frames(h: f32, frames: u32) -> f32 {
    let mut hk = h;
    for _ in 1..frames {
        hk *= h;
    }
    hk
}

/// Blends one probe's ray radiances into its irradiance tile (encoded with
/// `rule.gamma`). `hysteresis` is the per-frame weight of the old value (0
/// replaces it); with a history, `rule`'s firefly clamp limits the estimate;
/// with `rule.thresholds` each texel lowers the hysteresis by Listing 3, with
/// `rule.adaptive_hysteresis` to at most its state in `texel_hysteresis`
/// (one per tile texel, updated; empty without it); then it is raised to
/// `frames` ([`hysteresis_over_frames`]; 1 without a ray budget). Returns the probe's change: the mean over
/// the interior of [`crate::probe_change::texel_change`] between each texel's
/// history and this frame's estimate (0 for a texel no ray weighs).
pub fn blend_irradiance_tile(
    tile: &mut [Vec3],
    interior: u32,
    weights: &BlendWeights,
    ray_radiance: &[Vec3],
    (hysteresis, frames): (f32, u32),
    rule: &IrradianceBlendRule,
    texel_hysteresis: &mut [f32],
) -> f32 {
    let mut change = 0.0f32;
    for t in 0..(interior * interior) as usize {
        let mut sum = Vec3::ZERO;
        let mut wsum = 0.0f32;
        for &(r, w) in weights.texel(t) {
            let l = ray_radiance[r as usize];
            if l.is_finite() {
                sum += l * w;
                wsum += w;
            }
        }
        if wsum <= 0.0 {
            continue;
        }
        let index = interior_index(t, interior);
        let dst = &mut tile[index];
        let mut encoded = encode_irradiance(sum / wsum, rule.gamma);
        if hysteresis > 0.0 && rule.firefly_clamp_ratio > 0.0 {
            encoded = firefly_clamp(encoded, *dst, rule.firefly_clamp_ratio, rule.gamma);
        }
        change += crate::probe_change::texel_change(*dst, encoded);
        let mut h = match &rule.thresholds {
            Some(th) => adjusted_hysteresis(hysteresis, (encoded - *dst).max_element(), th),
            None => hysteresis,
        };
        if let Some(state) = texel_hysteresis.get_mut(index).filter(|_| rule.adaptive_hysteresis) {
            *state = adaptive_texel_hysteresis(*state, hysteresis, (*dst, encoded), rule.adaptive_tolerance);
            h = h.min(*state);
        }
        let h = hysteresis_over_frames(h, frames);
        let blended = encoded * (1.0 - h) + *dst * h;
        if blended.is_finite() {
            *dst = blended;
        }
    }
    change / (interior * interior).max(1) as f32
}

/// Blends one probe's ray lengths into its distance tile as (mean, mean²).
/// `ray_distance` is signed (negative marks a backface hit, already shortened);
/// lengths are clamped to `max_distance_m`.
pub fn blend_distance_tile(
    tile: &mut [Vec2],
    interior: u32,
    weights: &BlendWeights,
    ray_distance: &[f32],
    hysteresis: f32,
    max_distance_m: f32,
) {
    for t in 0..(interior * interior) as usize {
        let mut sum = Vec2::ZERO;
        let mut wsum = 0.0f32;
        for &(r, w) in weights.texel(t) {
            let d = ray_distance[r as usize].abs();
            if d.is_nan() {
                continue;
            }
            let d = d.min(max_distance_m);
            sum += Vec2::new(d, d * d) * w;
            wsum += w;
        }
        if wsum <= 0.0 {
            continue;
        }
        let dst = &mut tile[interior_index(t, interior)];
        let blended = (sum / wsum) * (1.0 - hysteresis) + *dst * hysteresis;
        if blended.is_finite() {
            *dst = blended;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fibonacci::spherical_fibonacci;

    fn dirs(n: u32) -> Vec<Vec3> {
        (0..n).map(|i| spherical_fibonacci(i, n)).collect()
    }

    #[test]
    fn constant_radiance_blends_to_its_encoded_value() {
        let d = dirs(256);
        let w = BlendWeights::new(&d, 6, 1.0);
        let mut tile = vec![Vec3::ZERO; 64];
        blend_irradiance_tile(
            &mut tile,
            6,
            &w,
            &vec![Vec3::splat(2.0); 256],
            (0.0, 1),
            &IrradianceBlendRule::plain(5.0),
            &mut [],
        );
        let want = 2.0f32.powf(0.2);
        for j in 1..7 {
            for i in 1..7 {
                assert!((tile[j * 8 + i].x - want).abs() < 1e-5);
            }
        }
        // Hysteresis 0.75 keeps three quarters of the old value.
        blend_irradiance_tile(
            &mut tile,
            6,
            &w,
            &vec![Vec3::ZERO; 256],
            (0.75, 1),
            &IrradianceBlendRule::plain(5.0),
            &mut [],
        );
        assert!((tile[9].x - 0.75 * want).abs() < 1e-5);
        // Two frames' worth: 0.75² of the old value.
        blend_irradiance_tile(
            &mut tile,
            6,
            &w,
            &vec![Vec3::ZERO; 256],
            (0.75, 2),
            &IrradianceBlendRule::plain(5.0),
            &mut [],
        );
        assert!((tile[9].x - 0.75 * 0.5625 * want).abs() < 1e-5);
        assert_eq!(hysteresis_over_frames(0.5, 3), 0.125);
        assert_eq!(hysteresis_over_frames(0.97, 1), 0.97);
        assert_eq!(hysteresis_over_frames(0.97, 0), 0.97);
    }

    #[test]
    fn hemisphere_lighting_gives_cosine_weighted_means() {
        // Radiance 1 from +z only: the +z texel sees only lit rays (mean 1), the −z
        // texel none (mean 0), a horizon texel half its cosine mass (mean 1/2).
        let d = dirs(4096);
        let l: Vec<Vec3> = d.iter().map(|r| Vec3::splat(if r.z > 0.0 { 1.0 } else { 0.0 })).collect();
        let n = 14;
        let w = BlendWeights::new(&d, n, 1.0);
        let mut tile = vec![Vec3::ZERO; 16 * 16];
        blend_irradiance_tile(&mut tile, n, &w, &l, (0.0, 1), &IrradianceBlendRule::plain(1.0), &mut []);
        let value_at = |dir: Vec3| {
            let uv = crate::octahedral::oct_encode(dir);
            crate::probe_atlas::sample_tile_bilinear(&tile, n, uv * (1.0 - 1.0 / n as f32)).x
        };
        assert!((value_at(Vec3::Z) - 1.0).abs() < 0.01);
        assert!(value_at(Vec3::NEG_Z) < 0.01);
        assert!((value_at(Vec3::X) - 0.5).abs() < 0.05, "{}", value_at(Vec3::X));
    }

    #[test]
    fn listing_3_thresholds_lower_the_hysteresis() {
        let th = TexelThresholds { significant: 0.25, new_distribution: 0.8 };
        assert_eq!(adjusted_hysteresis(0.97, 0.1, &th), 0.97);
        assert!((adjusted_hysteresis(0.97, -0.3, &th) - 0.82).abs() < 1e-6);
        assert_eq!(adjusted_hysteresis(0.97, 0.9, &th), 0.0);
        // Through a blend: a texel jumping from 0 to 1 takes the new value at once.
        let d = dirs(256);
        let w = BlendWeights::new(&d, 6, 1.0);
        let mut tile = vec![Vec3::ZERO; 64];
        let rule = IrradianceBlendRule { thresholds: Some(th), ..IrradianceBlendRule::plain(5.0) };
        blend_irradiance_tile(&mut tile, 6, &w, &vec![Vec3::ONE; 256], (0.97, 1), &rule, &mut []);
        assert!((tile[9].x - 1.0).abs() < 1e-5);
    }

    #[test]
    fn the_firefly_clamp_limits_an_estimate_to_ratio_times_its_history() {
        let d = dirs(256);
        let w = BlendWeights::new(&d, 6, 1.0);
        let rule = IrradianceBlendRule { firefly_clamp_ratio: 32.0, ..IrradianceBlendRule::plain(5.0) };
        // History 1 (linear and encoded), estimate 1000: clamped to 32, encoded 32^0.2 = 2.
        let mut tile = vec![Vec3::ONE; 64];
        blend_irradiance_tile(&mut tile, 6, &w, &vec![Vec3::splat(1000.0); 256], (0.5, 1), &rule, &mut []);
        assert!((tile[9].x - (0.5 * 2.0 + 0.5 * 1.0)).abs() < 1e-5, "{}", tile[9].x);
        // The clamp scales all channels alike, keeping the estimate's hue.
        let c = firefly_clamp(Vec3::new(4.0, 2.0, 0.0), Vec3::ONE, 32.0, 5.0);
        assert!((c - Vec3::new(2.0, 1.0, 0.0)).length() < 1e-5, "{c}");
        // Within the ratio, and without a history (hysteresis 0 or black), nothing is clamped.
        assert_eq!(firefly_clamp(Vec3::splat(1.9), Vec3::ONE, 32.0, 5.0), Vec3::splat(1.9));
        assert_eq!(firefly_clamp(Vec3::splat(9.0), Vec3::ZERO, 32.0, 5.0), Vec3::splat(9.0));
        let mut fresh = vec![Vec3::ONE; 64];
        blend_irradiance_tile(&mut fresh, 6, &w, &vec![Vec3::splat(1000.0); 256], (0.0, 1), &rule, &mut []);
        assert!((fresh[9].x - 1000.0f32.powf(0.2)).abs() < 1e-4);
    }

    #[test]
    fn adaptive_hysteresis_rises_while_still_and_drops_on_a_change() {
        let d = dirs(256);
        let w = BlendWeights::new(&d, 6, 1.0);
        let rule = IrradianceBlendRule { adaptive_hysteresis: true, ..IrradianceBlendRule::plain(5.0) };
        let mut tile = vec![Vec3::ZERO; 64];
        let mut state = vec![0.5f32; 64];
        // A restart (hysteresis 0) sets the state to 0 and takes the estimate.
        blend_irradiance_tile(&mut tile, 6, &w, &vec![Vec3::ONE; 256], (0.0, 1), &rule, &mut state);
        assert_eq!((tile[9].x, state[9]), (1.0, 0.0));
        // Still light: +0.1 a blend, and the blend uses min(planned, state).
        for k in 1..=12 {
            blend_irradiance_tile(&mut tile, 6, &w, &vec![Vec3::ONE; 256], (0.97, 1), &rule, &mut state);
            assert!((state[9] - (0.1 * k as f32).min(1.0)).abs() < 1e-5, "blend {k}: {}", state[9]);
        }
        // The light goes to 1/32 (encoded 0.5): relative change 0.5 / 1.01, so
        // the state falls from 1 to 0.6 and the texel keeps 0.6, not 0.97, of its history.
        blend_irradiance_tile(&mut tile, 6, &w, &vec![Vec3::splat(1.0 / 32.0); 256], (0.97, 1), &rule, &mut state);
        let s = 1.0 + ADAPTIVE_HYSTERESIS_RISE - 0.5 / 1.01;
        assert!((state[9] - s).abs() < 1e-5, "{}", state[9]);
        assert!((tile[9].x - (0.5 * (1.0 - s) + s)).abs() < 1e-5, "{}", tile[9].x);
        // Border texels carry no state of their own.
        assert_eq!(state[0], 0.5);
        // A tolerance above the change: the state climbs on.
        let change = (0.5, 1.01);
        let (history, estimate) = (Vec3::splat(change.1 - ADAPTIVE_HYSTERESIS_FLOOR), Vec3::splat(0.5));
        assert!((adaptive_texel_hysteresis(0.3, 0.97, (history, estimate), 0.6) - 0.4).abs() < 1e-6);
        let fallen = adaptive_texel_hysteresis(0.3, 0.97, (history, estimate), 0.25);
        assert!((fallen - (0.3 + 0.1 - (change.0 / change.1 - 0.25))).abs() < 1e-5, "{fallen}");
    }

    #[test]
    fn distances_are_clamped_backfaces_use_their_magnitude_and_nan_is_dropped() {
        let d = dirs(256);
        let w = BlendWeights::new(&d, 4, 50.0);
        let mut tile = vec![Vec2::ZERO; 36];
        let mut dist = vec![3.0f32; 256];
        dist[0] = f32::NAN;
        dist[1] = -3.0;
        blend_distance_tile(&mut tile, 4, &w, &dist, 0.0, 2.0);
        for j in 1..5 {
            for i in 1..5 {
                assert_eq!(tile[j * 6 + i], Vec2::new(2.0, 4.0));
            }
        }
        let mut irr = vec![Vec3::ONE; 36];
        let w1 = BlendWeights::new(&d, 4, 1.0);
        blend_irradiance_tile(
            &mut irr,
            4,
            &w1,
            &vec![Vec3::splat(f32::NAN); 256],
            (0.0, 1),
            &IrradianceBlendRule::plain(5.0),
            &mut [],
        );
        assert!(irr.iter().all(|v| *v == Vec3::ONE), "all-NaN rays leave the old values");
    }
}
