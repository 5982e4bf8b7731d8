//! Monte Carlo sampling, in pbrt-v4's sets: `sample_x` maps uniform numbers in
//! `[0,1)^n` to the domain, `x_pdf` gives the density, `invert_x` maps back.
//! Round trips are tested below (pbrt `sampling_test.cpp`).

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// Orthonormal frame around a unit normal (Duff et al. 2017, "Building an
/// orthonormal basis, revisited"): branchless and continuous except at n.z = -1.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    /// Unit tangent, the frame's local +x, orthogonal to `bitangent` and `normal`.
    pub tangent: Vec3,
    /// Unit bitangent, the frame's local +y, orthogonal to `tangent` and `normal`.
    pub bitangent: Vec3,
    /// The unit normal the frame was built around, its local +z.
    pub normal: Vec3,
}

impl Frame {
    /// The frame around `normal`, which must already be unit length (Duff et al. 2017).
    pub fn from_normal(normal: Vec3) -> Self {
        let sign = 1.0f32.copysign(normal.z);
        let a = -1.0 / (sign + normal.z);
        let b = normal.x * normal.y * a;
        Self {
            tangent: Vec3::new(1.0 + sign * normal.x * normal.x * a, sign * b, -sign * normal.x),
            bitangent: Vec3::new(b, sign + normal.y * normal.y * a, -normal.y),
            normal,
        }
    }

    /// Local (tangent, bitangent, normal) coordinates to world.
    pub fn to_world(&self, local: Vec3) -> Vec3 {
        self.tangent * local.x + self.bitangent * local.y + self.normal * local.z
    }

    /// World to local (tangent, bitangent, normal) coordinates.
    pub fn to_local(&self, world: Vec3) -> Vec3 {
        Vec3::new(world.dot(self.tangent), world.dot(self.bitangent), world.dot(self.normal))
    }
}

/// Cosine-weighted hemisphere around +z (Malley's method, polar disk mapping).
pub fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let r = u.x.sqrt();
    let phi = 2.0 * PI * u.y;
    let z = (1.0 - u.x).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`sample_cosine_hemisphere`] per steradian, given cos θ to +z.
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// Inverse of [`sample_cosine_hemisphere`].
pub fn invert_cosine_hemisphere(dir: Vec3) -> Vec2 {
    let ux = dir.x * dir.x + dir.y * dir.y;
    let mut phi = dir.y.atan2(dir.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    Vec2::new(ux, phi / (2.0 * PI))
}

/// Uniform direction on the unit sphere.
pub fn sample_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`sample_uniform_sphere`] per steradian.
pub fn uniform_sphere_pdf() -> f32 {
    1.0 / (4.0 * PI)
}

/// Inverse of [`sample_uniform_sphere`].
pub fn invert_uniform_sphere(dir: Vec3) -> Vec2 {
    let mut phi = dir.y.atan2(dir.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    Vec2::new((1.0 - dir.z) / 2.0, phi / (2.0 * PI))
}

/// Uniform point on a triangle as barycentrics `(b0, b1, b2)` (square-root mapping).
pub fn sample_uniform_triangle(u: Vec2) -> Vec3 {
    let su = u.x.sqrt();
    let b0 = 1.0 - su;
    let b1 = u.y * su;
    Vec3::new(b0, b1, 1.0 - b0 - b1)
}

/// Density of [`sample_uniform_triangle`] per unit area.
pub fn uniform_triangle_pdf(area: f32) -> f32 {
    if area > 0.0 { 1.0 / area } else { 0.0 }
}

/// Inverse of [`sample_uniform_triangle`].
pub fn invert_uniform_triangle(bary: Vec3) -> Vec2 {
    let su = 1.0 - bary.x;
    let uy = if su > 0.0 { bary.y / su } else { 0.0 };
    Vec2::new(su * su, uy)
}

/// Veach's power heuristic (β = 2) weight for strategy `f` against `g`,
/// each with one sample.
pub fn power_heuristic(f_pdf: f32, g_pdf: f32) -> f32 {
    let f2 = f_pdf * f_pdf;
    let g2 = g_pdf * g_pdf;
    if f2 + g2 > 0.0 && f2.is_finite() {
        f2 / (f2 + g2)
    } else if f2.is_infinite() {
        1.0
    } else {
        0.0
    }
}

/// A discrete distribution proportional to non-negative weights, sampled by
/// binary search of its CDF.
#[derive(Clone, Debug, Default)]
pub struct Distribution1d {
    cdf: Vec<f32>,
    total: f64,
}

impl Distribution1d {
    /// Weights that are negative or not finite count as zero.
    pub fn new(weights: &[f32]) -> Self {
        let mut cdf = Vec::with_capacity(weights.len());
        let mut total = 0.0f64;
        for &w in weights {
            if w.is_finite() && w > 0.0 {
                total += w as f64;
            }
            cdf.push(total as f32);
        }
        if total > 0.0 {
            for c in &mut cdf {
                *c = (*c as f64 / total) as f32;
            }
            if let Some(last) = cdf.last_mut() {
                *last = 1.0;
            }
        }
        Self { cdf, total }
    }

    /// Whether no weight is positive, so [`Self::sample_discrete`] returns `None`;
    /// unlike `len() == 0`, zero weights count as empty.
    pub fn is_empty(&self) -> bool {
        self.total <= 0.0
    }

    /// Number of weights the distribution was built from, zero ones included.
    pub fn len(&self) -> usize {
        self.cdf.len()
    }

    /// Sum of the weights the distribution was built from.
    pub fn total_weight(&self) -> f64 {
        self.total
    }

    /// Index with probability proportional to its weight. `None` when all weights are zero.
    pub fn sample_discrete(&self, u: f32) -> Option<(usize, f32)> {
        if self.is_empty() {
            return None;
        }
        let idx = self.cdf.partition_point(|&c| c <= u).min(self.cdf.len() - 1);
        Some((idx, self.pmf(idx)))
    }

    /// Probability of picking `index`.
    pub fn pmf(&self, index: usize) -> f32 {
        if self.is_empty() || index >= self.cdf.len() {
            return 0.0;
        }
        let lo = if index == 0 { 0.0 } else { self.cdf[index - 1] };
        self.cdf[index] - lo
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> impl Iterator<Item = Vec2> {
        (0..n * n).map(move |i| Vec2::new(((i % n) as f32 + 0.5) / n as f32, ((i / n) as f32 + 0.5) / n as f32))
    }

    #[test]
    fn cosine_hemisphere_round_trip_and_pdf_integrates_to_one() {
        for u in grid(17) {
            let d = sample_cosine_hemisphere(u);
            assert!((d.length() - 1.0).abs() < 1e-5);
            assert!(d.z >= 0.0);
            let back = invert_cosine_hemisphere(d);
            assert!((back - u).abs().max_element() < 1e-4, "{u} -> {back}");
        }
        // Under the cosine density, E[cos θ] = ∫ cos²θ / π dω = 2/3.
        let n = 64;
        let mean: f32 = grid(n).map(|u| sample_cosine_hemisphere(u).z).sum::<f32>() / (n * n) as f32;
        assert!((mean - 2.0 / 3.0).abs() < 1e-3, "{mean}");
        // And the density integrates to one over the hemisphere (uniform-sphere estimator).
        let m = 256;
        let integral: f32 =
            grid(m).map(|u| cosine_hemisphere_pdf(sample_uniform_sphere(u).z) / uniform_sphere_pdf()).sum::<f32>()
                / (m * m) as f32;
        assert!((integral - 1.0).abs() < 1e-3, "{integral}");
    }

    #[test]
    fn uniform_sphere_round_trip() {
        for u in grid(17) {
            let d = sample_uniform_sphere(u);
            assert!((d.length() - 1.0).abs() < 1e-5);
            let back = invert_uniform_sphere(d);
            assert!((back - u).abs().max_element() < 1e-4, "{u} -> {back}");
        }
        assert!((uniform_sphere_pdf() * 4.0 * PI - 1.0).abs() < 1e-6);
    }

    #[test]
    fn uniform_triangle_round_trip_and_mean_is_centroid() {
        let mut mean = Vec3::ZERO;
        for u in grid(32) {
            let b = sample_uniform_triangle(u);
            assert!(b.min_element() >= -1e-6 && (b.x + b.y + b.z - 1.0).abs() < 1e-5);
            let back = invert_uniform_triangle(b);
            assert!((back - u).abs().max_element() < 1e-4);
            mean += b;
        }
        mean /= 1024.0;
        assert!((mean - Vec3::splat(1.0 / 3.0)).abs().max_element() < 5e-3, "{mean}");
    }

    #[test]
    fn frame_is_orthonormal_for_many_normals() {
        for u in grid(20) {
            let n = sample_uniform_sphere(u);
            let f = Frame::from_normal(n);
            assert!(f.tangent.dot(f.bitangent).abs() < 1e-5);
            assert!(f.tangent.dot(n).abs() < 1e-5);
            assert!((f.tangent.cross(f.bitangent) - n).length() < 1e-4);
            let v = Vec3::new(0.3, -0.4, 0.5);
            assert!((f.to_local(f.to_world(v)) - v).length() < 1e-5);
        }
    }

    #[test]
    fn distribution_pmf_matches_weights_and_skips_zeros() {
        let d = Distribution1d::new(&[1.0, 0.0, 3.0, f32::NAN, -2.0]);
        assert!((d.pmf(0) - 0.25).abs() < 1e-6);
        assert_eq!(d.pmf(1), 0.0);
        assert!((d.pmf(2) - 0.75).abs() < 1e-6);
        assert_eq!(d.pmf(3), 0.0);
        let mut counts = [0usize; 5];
        for i in 0..1000 {
            let (idx, pmf) = d.sample_discrete((i as f32 + 0.5) / 1000.0).expect("non-empty");
            assert!(pmf > 0.0);
            counts[idx] += 1;
        }
        assert_eq!(counts, [250, 0, 750, 0, 0]);
        assert!(Distribution1d::new(&[0.0, 0.0]).sample_discrete(0.5).is_none());
    }

    #[test]
    fn power_heuristic_handles_degenerate_pdfs() {
        assert_eq!(power_heuristic(1.0, 1.0), 0.5);
        assert_eq!(power_heuristic(0.0, 0.0), 0.0);
        assert_eq!(power_heuristic(f32::INFINITY, 1.0), 1.0);
        assert!((power_heuristic(3.0, 1.0) - 0.9).abs() < 1e-6);
    }
}
