//! Spherical Fibonacci point sets (Keinert et al. 2015), the probe-ray directions
//! of DDGI (seed 003 eq. 4.1–4.3): point i of n is at φᵢ = 2π·i/Φ, zᵢ = 1 − (2i+1)/n
//! with Φ the golden ratio. Each frame the whole set is rotated by one uniformly
//! random rotation (seed 004 §2.3).

use glam::{Quat, Vec3};
use std::f32::consts::PI;

/// The golden ratio Φ = (√5 + 1) / 2.
pub const GOLDEN_RATIO: f32 = 1.618_034;

/// Direction `i` of an `n`-point spherical Fibonacci set.
pub fn spherical_fibonacci(i: u32, n: u32) -> Vec3 {
    // φ = 2π·frac(i/Φ), computed in f64 so large i keep their precision.
    let frac = (i as f64 / GOLDEN_RATIO as f64).fract();
    let phi = 2.0 * PI * frac as f32;
    let z = 1.0 - (2.0 * i as f32 + 1.0) / n as f32;
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(phi.cos() * r, phi.sin() * r, z)
}

/// A uniformly distributed random rotation from three uniforms in `[0,1)`
/// (Shoemake 1992, "Uniform random rotations").
pub fn sample_uniform_rotation(u: Vec3) -> Quat {
    let (r1, r2) = ((1.0 - u.x).sqrt(), u.x.sqrt());
    let (t1, t2) = (2.0 * PI * u.y, 2.0 * PI * u.z);
    Quat::from_xyzw(t1.sin() * r1, t1.cos() * r1, t2.sin() * r2, t2.cos() * r2).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fibonacci_directions_cover_the_sphere_uniformly() {
        for n in [32u32, 256] {
            let dirs: Vec<Vec3> = (0..n).map(|i| spherical_fibonacci(i, n)).collect();
            let mean = dirs.iter().copied().sum::<Vec3>() / n as f32;
            assert!(mean.length() < 2.0 / n as f32, "n = {n}: mean direction {mean}");
            let mut octants = [0u32; 8];
            for d in &dirs {
                assert!((d.length() - 1.0).abs() < 1e-5);
                octants[(d.x > 0.0) as usize | ((d.y > 0.0) as usize) << 1 | ((d.z > 0.0) as usize) << 2] += 1;
            }
            for (o, &c) in octants.iter().enumerate() {
                let frac = c as f32 / n as f32;
                assert!((frac - 0.125).abs() < 1.5 / n as f32 + 0.01, "n = {n}: octant {o} holds {frac}");
            }
        }
    }

    #[test]
    fn random_rotations_preserve_length_and_spread_directions() {
        let mut mean = Vec3::ZERO;
        let m = 16;
        for i in 0..m * m * m {
            let u = Vec3::new(
                ((i % m) as f32 + 0.5) / m as f32,
                (((i / m) % m) as f32 + 0.5) / m as f32,
                ((i / (m * m)) as f32 + 0.5) / m as f32,
            );
            let q = sample_uniform_rotation(u);
            let v = q * Vec3::Z;
            assert!((v.length() - 1.0).abs() < 1e-5);
            mean += v;
        }
        mean /= (m * m * m) as f32;
        assert!(mean.length() < 0.02, "rotated +z should average to zero, got {mean}");
    }
}
