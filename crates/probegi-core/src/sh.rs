//! Real spherical harmonics up to band l = 2 (9 coefficients, 27 for RGB), the
//! probe representation of seed 001 (eq. 1–5), with Ramamoorthi & Hanrahan's
//! (2001) cosine-lobe convolution for irradiance and seed 001's progressive
//! ("dynamic") projection model (eq. 6–9).
//!
//! Basis order: index `l² + l + m`, i.e. y₀⁰, y₁⁻¹, y₁⁰, y₁¹, y₂⁻², y₂⁻¹, y₂⁰, y₂¹, y₂²,
//! with y₁⁻¹ ∝ y, y₁⁰ ∝ z, y₁¹ ∝ x (the Cartesian form of eq. 1 with θ from +z).

use glam::Vec3;
use std::f32::consts::PI;

/// The 9 basis functions at a unit direction.
pub fn sh9_basis(d: Vec3) -> [f32; 9] {
    let (x, y, z) = (d.x, d.y, d.z);
    [
        0.282_094_8,
        0.488_602_5 * y,
        0.488_602_5 * z,
        0.488_602_5 * x,
        1.092_548_4 * x * y,
        1.092_548_4 * y * z,
        0.315_391_57 * (3.0 * z * z - 1.0),
        1.092_548_4 * x * z,
        0.546_274_2 * (x * x - y * y),
    ]
}

/// Cosine-lobe convolution factors per band (Ramamoorthi & Hanrahan 2001):
/// A₀ = π, A₁ = 2π/3, A₂ = π/4.
pub const COSINE_LOBE_BAND_FACTORS: [f32; 3] = [PI, 2.0 * PI / 3.0, PI / 4.0];

fn band_of(i: usize) -> usize {
    match i {
        0 => 0,
        1..=3 => 1,
        _ => 2,
    }
}

/// RGB radiance in SH, 9 coefficients per channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShRgb9 {
    /// Coefficient `l² + l + m` in the module docs' basis order, one `Vec3` of RGB per
    /// basis function.
    pub c: [Vec3; 9],
}

impl ShRgb9 {
    /// Reconstructed radiance in direction `d` (eq. 4–5).
    pub fn eval(&self, d: Vec3) -> Vec3 {
        let y = sh9_basis(d);
        self.c.iter().zip(y).map(|(c, y)| *c * y).sum()
    }

    /// Irradiance on a surface with unit normal `n` from the radiance this SH holds:
    /// Σ A_l c_lm y_lm(n).
    pub fn irradiance(&self, n: Vec3) -> Vec3 {
        let y = sh9_basis(n);
        (0..9).map(|i| self.c[i] * (COSINE_LOBE_BAND_FACTORS[band_of(i)] * y[i])).sum()
    }

    /// Adds `weight · value · y(d)`: one sample of the projection integral (eq. 3).
    pub fn add_sample(&mut self, d: Vec3, value: Vec3, weight: f32) {
        let y = sh9_basis(d);
        for (c, y) in self.c.iter_mut().zip(y) {
            *c += value * (weight * y);
        }
    }

    /// Multiplies every coefficient by `s`, scaling the radiance the SH represents.
    pub fn scale(&mut self, s: f32) {
        for c in &mut self.c {
            *c *= s;
        }
    }

    /// Whether every coefficient is finite (no NaN or infinity).
    pub fn is_finite(&self) -> bool {
        self.c.iter().all(|c| c.is_finite())
    }
}

/// One step of the progressive projection (seed 001 eq. 6/8): each sample
/// `(direction, value f, w)` — w its differential solid angle — projects the
/// prediction error, `c ← c − h·Σ w·(c·y(s) − f(s))·y(s)`. `hysteresis` h is seed
/// 001's user-facing factor multiplying w (convergence rate against variance).
///
/// Deviation: the paper's collected form, eq. 7/9 `c ← (1 − Σw)·c + Σ w·f·y`, replaces
/// the projected reconstruction Σ w·(c·y)·y by (Σw)·c, which holds only in expectation
/// with w normalised to the sphere; taken literally with solid-angle weights its fixed
/// point is the static projection divided by Σw (4π for a full sphere). The error
/// form above is the model's definition (eq. 6), converges to the static projection
/// (tested below) and, for screen samples that cover only part of the sphere,
/// corrects only the directions it observed. A step whose result is not finite is
/// dropped.
pub fn progressive_update(c: &mut ShRgb9, samples: impl IntoIterator<Item = (Vec3, Vec3, f32)>, hysteresis: f32) {
    let mut next = *c;
    for (d, f, w) in samples {
        if !(f.is_finite() && w.is_finite()) || w < 0.0 {
            continue;
        }
        let y = sh9_basis(d);
        let predicted: Vec3 = c.c.iter().zip(y).map(|(c, y)| *c * y).sum();
        let step = (f - predicted) * (w * hysteresis);
        for (n, y) in next.c.iter_mut().zip(y) {
            *n += step * y;
        }
    }
    if next.is_finite() {
        *c = next;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fibonacci::spherical_fibonacci;

    const N: u32 = 20_000;

    fn sphere() -> impl Iterator<Item = Vec3> {
        (0..N).map(|i| spherical_fibonacci(i, N))
    }

    #[test]
    fn basis_is_orthonormal() {
        let w = 4.0 * PI / N as f32;
        let mut gram = [[0.0f64; 9]; 9];
        for d in sphere() {
            let y = sh9_basis(d);
            for i in 0..9 {
                for j in 0..9 {
                    gram[i][j] += (y[i] * y[j] * w) as f64;
                }
            }
        }
        for (i, row) in gram.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((v - want).abs() < 2e-3, "<y{i}, y{j}> = {v}");
            }
        }
    }

    fn project(f: impl Fn(Vec3) -> f32) -> ShRgb9 {
        let mut sh = ShRgb9::default();
        for d in sphere() {
            sh.add_sample(d, Vec3::splat(f(d)), 4.0 * PI / N as f32);
        }
        sh
    }

    #[test]
    fn projections_match_closed_forms() {
        // Constant 1: c₀ = √(4π), the rest 0.
        let c = project(|_| 1.0);
        assert!((c.c[0].x - (4.0 * PI).sqrt()).abs() < 1e-3);
        assert!(c.c[1..].iter().all(|v| v.x.abs() < 1e-3));
        // Clamped cosine max(0, z): c₀ = √π/2, c₁⁰ = √(π/3), c₂⁰ = √(5π)/8.
        let c = project(|d| d.z.max(0.0));
        assert!((c.c[0].x - PI.sqrt() / 2.0).abs() < 2e-3, "{}", c.c[0].x);
        assert!((c.c[2].x - (PI / 3.0).sqrt()).abs() < 2e-3, "{}", c.c[2].x);
        assert!((c.c[6].x - (5.0 * PI).sqrt() / 8.0).abs() < 2e-3, "{}", c.c[6].x);
    }

    #[test]
    fn irradiance_of_constant_radiance_is_pi_l_and_of_a_hemisphere_is_its_cosine_integral() {
        let c = project(|_| 2.0);
        for n in [Vec3::X, Vec3::NEG_Z, Vec3::new(0.6, 0.0, 0.8)] {
            assert!((c.irradiance(n).x - 2.0 * PI).abs() < 1e-2);
        }
        // Radiance 1 from the upper hemisphere: E(+z) = π, E(−z) = 0, E(horizontal) = π/2.
        // L2 truncation error of this step function is known to be small but not zero.
        let c = project(|d| if d.z > 0.0 { 1.0 } else { 0.0 });
        assert!((c.irradiance(Vec3::Z).x - PI).abs() < 0.1, "{}", c.irradiance(Vec3::Z).x);
        assert!(c.irradiance(Vec3::NEG_Z).x.abs() < 0.1);
        assert!((c.irradiance(Vec3::X).x - PI / 2.0).abs() < 0.02);
    }

    #[test]
    fn progressive_projection_converges_to_the_static_one() {
        // Seed 001 §7.1: a blurry environment sampled regularly, 20×20 samples per
        // iteration; the error against the static projection must fall and converge.
        let env = |d: Vec3| Vec3::new(1.0 + 0.8 * d.z, 0.5 + 0.4 * d.x * d.y, 0.3 + 0.3 * (d.x + 0.5).max(0.0));
        let mut stat = ShRgb9::default();
        for d in sphere() {
            stat.add_sample(d, env(d), 4.0 * PI / N as f32);
        }
        let mut prog = ShRgb9::default();
        let m = 400;
        let h = 0.05;
        let mut errors = Vec::new();
        for it in 0..200u32 {
            let rot = crate::fibonacci::sample_uniform_rotation(Vec3::new(
                ((it as f32) * 0.618_034).fract(),
                ((it as f32) * 0.414_213_5).fract(),
                ((it as f32) * 0.732_050_8).fract(),
            ));
            let samples: Vec<(Vec3, Vec3, f32)> = (0..m)
                .map(|i| {
                    let d = rot * spherical_fibonacci(i, m);
                    (d, env(d), 4.0 * PI / m as f32)
                })
                .collect();
            progressive_update(&mut prog, samples, h);
            let err: f32 = prog.c.iter().zip(stat.c).map(|(a, b)| (*a - b).length_squared()).sum::<f32>().sqrt();
            errors.push(err);
        }
        assert!(errors[10] < errors[0] && errors[50] < errors[10] && errors[199] < errors[50], "{errors:?}");
        let norm: f32 = stat.c.iter().map(|c| c.length_squared()).sum::<f32>().sqrt();
        assert!(errors[199] / norm < 0.01, "relative error after 200 iterations {}", errors[199] / norm);
    }
}
