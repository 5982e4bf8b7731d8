//! The screen-space probe update of seed 001 §5.1 (Fig. 3): samples of the lit
//! frame (radiance, position, normal) are splatted into every probe by projecting
//! the prediction error (eq. 7, [`crate::sh::progressive_update`]), each weighted
//! by the solid angle its surface patch subtends at the probe.
//!
//! - eq. 10, [`screen_sample_area_m2`]: the surface area a sample represents,
//!   A = Ω z² / max(n·v̄, 0.01). We use the pixel's own solid angle Ω (which falls
//!   as cos³ off the optical axis) and its distance to the eye for z, which makes
//!   Ω z² the exact footprint of a fronto-parallel pixel; the paper's constant Ω
//!   with view depth is the same at the image centre. A stratified sample stands
//!   for its whole tile, so Ω is the pixel's solid angle × pixels per tile.
//! - [`progressive_update_toward`]: eq. 7 over a frame's samples for one probe,
//!   [`SH_SAMPLE_LANES`] samples at a time from [`ShSampleBlocks`] (every probe
//!   of every cascade reads the same samples, so they are laid out once).
//! - eq. 11, [`sample_toward_probe`]: w = A (n·d̂)/(d·d) with d from the sample to
//!   the (jittered) probe. Samples facing away from the probe (n·d̂ ≤ 0) send it
//!   nothing and are skipped.
//!
//! Deviation: w is clamped to [`MAX_SAMPLE_SOLID_ANGLE_SR`] = 4π/9. For L2 SH,
//! Σ y_i(s)² = 9/(4π) in every direction s, so one error-projection step of
//! weight w moves the reconstruction in the sample's direction by w · 9/(4π) of
//! the error: above 4π/9 it overshoots. Without the clamp a sample a few
//! millimetres from a jittered probe (w ∝ 1/d²) throws the probe far past the
//! sample's radiance, which then rings for many frames.
//!
//! Injected light samples (seed 001 §5.2) use the same weight with the emitter
//! as the "sample": a point on an emissive triangle, its normal, and the area it
//! stands for.

use glam::Vec3;
use std::f32::consts::PI;

use crate::sh::ShRgb9;

/// Largest weight one sample may carry (see the module doc).
pub const MAX_SAMPLE_SOLID_ANGLE_SR: f32 = 4.0 * PI / 9.0;

/// A sample of the lit frame, or of an emitter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShSample {
    /// World position of the sample's surface point (or of the point on the emitter),
    /// metres.
    pub position_m: Vec3,
    /// Unit normal on the side that emits/reflects toward the probe.
    pub normal: Vec3,
    /// Radiance the sample sends toward the probes (diffuse: the same in every direction).
    pub radiance: Vec3,
    /// Surface area the sample stands for, m² (eq. 10).
    pub area_m2: f32,
}

/// Eq. 10: area of the surface seen through a pixel of solid angle `pixel_solid_angle_sr`
/// at `distance_m` from the eye, with `n_dot_v` the cosine between the surface
/// normal and the direction to the eye (clamped to ≥ 0.01 as the paper does).
pub fn screen_sample_area_m2(pixel_solid_angle_sr: f32, distance_m: f32, n_dot_v: f32) -> f32 {
    pixel_solid_angle_sr * distance_m * distance_m / n_dot_v.max(0.01)
}

/// Eq. 11: the direction from the probe toward the sample and the differential
/// solid angle w the sample subtends at the probe, or `None` if it faces away.
pub fn sample_toward_probe(sample: &ShSample, probe_m: Vec3) -> Option<(Vec3, f32)> {
    let d = probe_m - sample.position_m;
    let dd = d.length_squared();
    if !(dd > 0.0 && dd.is_finite()) {
        return None;
    }
    let d_hat = d / dd.sqrt();
    let cos = sample.normal.dot(d_hat);
    if cos <= 0.0 {
        return None;
    }
    let w = (sample.area_m2 * cos / dd).min(MAX_SAMPLE_SOLID_ANGLE_SR);
    Some((-d_hat, w))
}

/// Lanes of one [`ShSampleBlocks`] block: the samples one probe's update
/// processes side by side.
pub const SH_SAMPLE_LANES: usize = 8;

/// One block of samples, each field one value per lane. Padding lanes have zero
/// area, so they weigh nothing.
#[derive(Clone, Copy, Debug, Default)]
struct ShSampleBlock {
    position_m: [[f32; SH_SAMPLE_LANES]; 3],
    normal: [[f32; SH_SAMPLE_LANES]; 3],
    radiance: [[f32; SH_SAMPLE_LANES]; 3],
    area_m2: [f32; SH_SAMPLE_LANES],
}

/// A frame's screen samples in structure-of-arrays blocks, built once and read
/// by every probe's [`progressive_update_toward`]. Samples whose radiance is not
/// finite are left out, as [`crate::sh::progressive_update`] skips them.
#[derive(Clone, Debug, Default)]
pub struct ShSampleBlocks {
    blocks: Vec<ShSampleBlock>,
    len: usize,
}

impl ShSampleBlocks {
    /// The blocks of `samples`, in order.
    pub fn new<'a>(samples: impl IntoIterator<Item = &'a ShSample>) -> Self {
        let mut out = Self::default();
        for s in samples.into_iter().filter(|s| s.radiance.is_finite()) {
            let lane = out.len % SH_SAMPLE_LANES;
            if lane == 0 {
                out.blocks.push(ShSampleBlock::default());
            }
            let Some(b) = out.blocks.last_mut() else { continue };
            for (field, v) in
                [(&mut b.position_m, s.position_m), (&mut b.normal, s.normal), (&mut b.radiance, s.radiance)]
            {
                for (k, x) in v.to_array().into_iter().enumerate() {
                    field[k][lane] = x;
                }
            }
            b.area_m2[lane] = s.area_m2;
            out.len += 1;
        }
        out
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether no sample is held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// [`crate::sh::progressive_update`] of `c` with every sample of `blocks` as
/// [`sample_toward_probe`] weighs it toward a probe at `probe_m`, computed
/// [`SH_SAMPLE_LANES`] samples at a time (the compiler vectorises the lanes).
/// Every step reads the coefficients from before the update, so the samples are
/// independent and their sum may be taken in any order: the result differs from
/// the one-sample-at-a-time loop only by float rounding of that sum.
// Lane loops index several arrays by lane, which is what lets them vectorise.
#[allow(clippy::needless_range_loop)]
pub fn progressive_update_toward(c: &mut ShRgb9, probe_m: Vec3, blocks: &ShSampleBlocks, hysteresis: f32) {
    const L: usize = SH_SAMPLE_LANES;
    let coeffs: [[f32; 3]; 9] = c.c.map(|v| v.to_array());
    let mut acc = [[[0.0f32; L]; 3]; 9];
    for b in &blocks.blocks {
        let (dir, w) = lanes_toward_probe(b, probe_m);
        let y = lanes_sh9_basis(&dir);
        for ch in 0..3 {
            let mut step = [0.0f32; L];
            for l in 0..L {
                let mut predicted = 0.0;
                for (k, yk) in y.iter().enumerate() {
                    predicted += coeffs[k][ch] * yk[l];
                }
                // Lanes that send nothing have w = 0 and a zero direction (finite
                // basis), so their step is 0; no branch, so the lanes vectorise.
                step[l] = (b.radiance[ch][l] - predicted) * (w[l] * hysteresis);
            }
            for (acc_k, yk) in acc.iter_mut().zip(&y) {
                for l in 0..L {
                    acc_k[ch][l] += step[l] * yk[l];
                }
            }
        }
    }
    let mut next = *c;
    for (n, acc_k) in next.c.iter_mut().zip(&acc) {
        *n += Vec3::from_array(acc_k.map(|lanes| lanes.iter().sum()));
    }
    if next.is_finite() {
        *c = next;
    }
}

/// [`sample_toward_probe`] per lane: the direction from the probe to the sample
/// and eq. 11's weight; a lane that sends the probe nothing (facing away, at
/// the probe, or a negative weight, which `progressive_update` skips) gets
/// weight 0 and a zero direction.
fn lanes_toward_probe(b: &ShSampleBlock, probe_m: Vec3) -> ([[f32; SH_SAMPLE_LANES]; 3], [f32; SH_SAMPLE_LANES]) {
    let (mut dir, mut w) = ([[0.0f32; SH_SAMPLE_LANES]; 3], [0.0f32; SH_SAMPLE_LANES]);
    for l in 0..SH_SAMPLE_LANES {
        let lane = |v: &[[f32; SH_SAMPLE_LANES]; 3]| Vec3::new(v[0][l], v[1][l], v[2][l]);
        let sample = ShSample {
            position_m: lane(&b.position_m),
            normal: lane(&b.normal),
            radiance: lane(&b.radiance),
            area_m2: b.area_m2[l],
        };
        if let Some((d, weight)) = sample_toward_probe(&sample, probe_m).filter(|(_, w)| *w >= 0.0) {
            w[l] = weight;
            for (k, x) in d.to_array().into_iter().enumerate() {
                dir[k][l] = x;
            }
        }
    }
    (dir, w)
}

/// [`crate::sh::sh9_basis`] per lane.
// Lane loops index several arrays by lane, which is what lets them vectorise.
#[allow(clippy::needless_range_loop)]
fn lanes_sh9_basis(dir: &[[f32; SH_SAMPLE_LANES]; 3]) -> [[f32; SH_SAMPLE_LANES]; 9] {
    let mut y = [[0.0f32; SH_SAMPLE_LANES]; 9];
    for l in 0..SH_SAMPLE_LANES {
        let v = crate::sh::sh9_basis(Vec3::new(dir[0][l], dir[1][l], dir[2][l]));
        for k in 0..9 {
            y[k][l] = v[k];
        }
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fibonacci::spherical_fibonacci;
    use crate::rng::Pcg32;
    use crate::sh::{ShRgb9, progressive_update};

    /// The lane update is the one-sample loop up to the rounding of its sum: on
    /// samples facing toward and away from the probe, one at the probe itself,
    /// non-finite radiance, and a count that leaves a block half full.
    #[test]
    fn the_update_in_lanes_is_the_one_sample_update() {
        let mut rng = Pcg32::new(11, 3);
        let mut samples: Vec<ShSample> = (0..203)
            .map(|_| {
                let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - Vec3::splat(2.0);
                let n = spherical_fibonacci(rng.next_u32() % 1000, 1000);
                let radiance = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 3.0;
                ShSample { position_m: p, normal: n, radiance, area_m2: rng.next_f32() * 0.05 }
            })
            .collect();
        let probe = Vec3::new(0.1, -0.2, 0.3);
        samples.push(ShSample { position_m: probe, ..samples[0] });
        samples.push(ShSample { radiance: Vec3::new(f32::NAN, 0.0, 1.0), ..samples[1] });
        let blocks = ShSampleBlocks::new(&samples);
        assert_eq!(blocks.len(), samples.len() - 1, "the NaN sample is left out");
        let mut start = ShRgb9::default();
        start.add_sample(Vec3::Y, Vec3::new(0.5, 0.2, 0.1), 2.0);
        for hysteresis in [0.02, 0.5] {
            let (mut one, mut lanes) = (start, start);
            let weighted =
                samples.iter().filter_map(|s| sample_toward_probe(s, probe).map(|(d, w)| (d, s.radiance, w)));
            progressive_update(&mut one, weighted, hysteresis);
            progressive_update_toward(&mut lanes, probe, &blocks, hysteresis);
            assert!(one != start, "the samples move the probe");
            for (a, b) in one.c.iter().zip(&lanes.c) {
                assert!((*a - *b).abs().max_element() <= 1e-5 * a.abs().max_element().max(1.0), "{a} vs {b}");
            }
        }
    }

    #[test]
    fn eq_10_and_11_give_the_solid_angle_of_a_small_patch() {
        // A 1 cm² patch 2 m away, facing the probe: ω = A/d².
        let s = ShSample { position_m: Vec3::ZERO, normal: Vec3::Z, radiance: Vec3::ONE, area_m2: 1e-4 };
        let (dir, w) = sample_toward_probe(&s, Vec3::new(0.0, 0.0, 2.0)).expect("faces the probe");
        assert!((w - 1e-4 / 4.0).abs() < 1e-9);
        assert!((dir - Vec3::NEG_Z).length() < 1e-6, "direction from probe to sample");
        // Tilted 60°: half the solid angle; behind: nothing.
        let p = Vec3::new(3f32.sqrt(), 0.0, 1.0);
        let (_, w) = sample_toward_probe(&s, p).expect("faces the probe");
        assert!((w - 1e-4 * 0.5 / 4.0).abs() < 1e-9, "{w}");
        assert!(sample_toward_probe(&s, Vec3::new(0.0, 0.0, -1.0)).is_none());
        // Eq. 10: a pixel of 1e-6 sr at 3 m seen at 60° covers 2 × 9e-6 m²; grazing is clamped.
        assert!((screen_sample_area_m2(1e-6, 3.0, 0.5) - 1.8e-5).abs() < 1e-10);
        assert!((screen_sample_area_m2(1e-6, 1.0, 0.0) - 1e-4).abs() < 1e-10);
        // A patch touching the probe is clamped so one step cannot overshoot.
        let near = ShSample { area_m2: 1.0, ..s };
        assert_eq!(sample_toward_probe(&near, Vec3::new(0.0, 0.0, 1e-3)).map(|x| x.1), Some(MAX_SAMPLE_SOLID_ANGLE_SR));
    }

    #[test]
    fn a_probe_inside_a_uniformly_glowing_sphere_converges_to_irradiance_pi_l() {
        // Screen-like samples: random points on a sphere of radius 2 around a probe
        // jittered inside it, each standing for its share of the sphere's area. The
        // probe must converge to radiance L in every direction: E(n) = πL.
        let radius = 2.0f32;
        let l = Vec3::new(1.0, 0.5, 0.25);
        let mut c = ShRgb9::default();
        let mut rng = Pcg32::new(7, 1);
        let m = 400;
        for frame in 0..150 {
            let probe = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5) * 0.4;
            let offset = rng.next_u32();
            let samples: Vec<ShSample> = (0..m)
                .map(|i| {
                    let n = spherical_fibonacci((i * 7919 + offset) % m, m);
                    ShSample {
                        position_m: n * radius,
                        normal: -n,
                        radiance: l,
                        area_m2: 4.0 * PI * radius * radius / m as f32,
                    }
                })
                .collect();
            let weighted =
                samples.iter().filter_map(|s| sample_toward_probe(s, probe).map(|(d, w)| (d, s.radiance, w)));
            progressive_update(&mut c, weighted, 0.1);
            assert!(c.is_finite(), "frame {frame}");
        }
        for n in [Vec3::X, Vec3::NEG_Y, Vec3::new(0.0, 0.6, -0.8)] {
            let e = c.irradiance(n);
            assert!(((e - PI * l).abs() / (PI * l)).max_element() < 0.03, "E({n}) = {e}, want {}", PI * l);
        }
    }
}
