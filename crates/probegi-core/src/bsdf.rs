//! The surface BSDF every renderer shares: a Lambertian lobe plus a GGX
//! (Trowbridge–Reitz) specular lobe with height-correlated Smith masking and
//! Schlick Fresnel (Walter et al. 2007; Heitz 2014, 2018). All directions are in the
//! local shading frame, +z = the normal on the viewer's side.
//!
//! `f = diffuse·(1 − max(F0))/π + D·G₂·F / (4 cosθo cosθi)`. The diffuse lobe is
//! scaled by 1 − max(F0) so that MTL materials with Kd + Ks > 1 (McGuire's
//! CornellBox-Glossy has Kd ≈ 0.6 with Ks 0.9) stay energy-conserving; a pure
//! diffuse material (F0 = 0) is exactly Lambertian.
//!
//! Sampling picks the specular lobe with probability ∝ luminance of F0 against the
//! scaled diffuse albedo (clamped to [0.1, 0.9] when both exist), the specular
//! half-vector from the visible normals (Heitz 2018), the diffuse direction
//! cosine-weighted; `pdf` is the one-sample mixture of both.
//!
//! [`specular_directional_albedo`] is the lobe's hemispherical-directional
//! reflectance ∫ f_spec cos θi dωi = F0·A(μo, α) + B(μo, α) (the split-sum factors
//! of Karis 2013, with Schlick's F split into F0 and 1 − F0 parts), from a table
//! integrated once by VNDF sampling: masking, shadowing and roughness included.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

use crate::color::luminance;
use crate::sampling::{cosine_hemisphere_pdf, sample_cosine_hemisphere};

/// GGX α below this is treated as this (a near-mirror, still a finite density).
pub const MIN_ALPHA: f32 = 1e-3;

/// A surface's BSDF: the Lambertian lobe plus the GGX specular lobe of the module docs,
/// in the local shading frame (+z = normal).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceBsdf {
    /// Diffuse albedo (before the 1 − max(F0) scale).
    pub diffuse: Vec3,
    /// Specular reflectance at normal incidence; zero = no specular lobe.
    pub specular_f0: Vec3,
    /// GGX α (perceptual roughness squared).
    pub alpha: f32,
}

/// GGX normal distribution D(h) for cos θh.
pub fn ggx_d(cos_h: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let c2 = cos_h * cos_h;
    let d = c2 * (a2 - 1.0) + 1.0;
    a2 / (PI * d * d)
}

/// Smith Λ-based G1 for GGX.
pub fn smith_g1(cos_v: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    2.0 * cos_v / (cos_v + (a2 + (1.0 - a2) * cos_v * cos_v).sqrt())
}

/// Height-correlated Smith G2 for GGX.
pub fn smith_g2(cos_o: f32, cos_i: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let lo = cos_i * (a2 + (1.0 - a2) * cos_o * cos_o).sqrt();
    let li = cos_o * (a2 + (1.0 - a2) * cos_i * cos_i).sqrt();
    2.0 * cos_o * cos_i / (lo + li)
}

/// Schlick's Fresnel approximation `F0 + (1 − F0)·(1 − cos)⁵` per channel, `cos`
/// (half-vector · light direction) clamped to [0, 1].
pub fn fresnel_schlick(f0: Vec3, cos: f32) -> Vec3 {
    let m = (1.0 - cos.clamp(0.0, 1.0)).powi(5);
    f0 + (Vec3::ONE - f0) * m
}

/// A visible-normal sample of GGX for outgoing `wo` (Heitz 2018, "Sampling the GGX
/// Distribution of Visible Normals").
pub fn sample_ggx_vndf(wo: Vec3, alpha: f32, u: Vec2) -> Vec3 {
    let vh = Vec3::new(alpha * wo.x, alpha * wo.y, wo.z).normalize();
    let lensq = vh.x * vh.x + vh.y * vh.y;
    let t1 = if lensq > 0.0 { Vec3::new(-vh.y, vh.x, 0.0) / lensq.sqrt() } else { Vec3::X };
    let t2 = vh.cross(t1);
    let r = u.x.sqrt();
    let phi = 2.0 * PI * u.y;
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    Vec3::new(alpha * nh.x, alpha * nh.y, nh.z.max(1e-6)).normalize()
}

/// Density of the reflected direction `wi` produced by [`sample_ggx_vndf`].
pub fn ggx_reflection_pdf(wo: Vec3, wi: Vec3, alpha: f32) -> f32 {
    let h = (wo + wi).normalize_or_zero();
    if wo.z <= 0.0 || wi.z <= 0.0 || h == Vec3::ZERO {
        return 0.0;
    }
    let o_h = wo.dot(h).max(1e-8);
    // D_v(h) = G1(wo)·max(0, wo·h)·D(h)/cosθo; pdf(wi) = D_v(h) / (4 wo·h).
    smith_g1(wo.z, alpha) * ggx_d(h.z, alpha) / (4.0 * wo.z) * if o_h > 0.0 { 1.0 } else { 0.0 }
}

/// Table resolution of [`specular_directional_albedo`] (and of
/// [`specular_albedo_table`]) in μo and in α.
pub const ALBEDO_TABLE_SIZE: usize = 32;

/// The (A, B) split-sum table behind [`specular_directional_albedo`], row-major
/// over α (rows) and cos θo (columns), both from 0 to 1 in `ALBEDO_TABLE_SIZE`
/// steps; what the GPU backend uploads.
pub fn specular_albedo_table() -> &'static [[f32; 2]] {
    albedo_table()
}

/// (A, B) per (α, μo) node, row-major in α; node i sits at i/(N − 1), so both ends
/// of [0, 1] are nodes. 1024 stratified VNDF samples each.
fn albedo_table() -> &'static [[f32; 2]] {
    static TABLE: std::sync::OnceLock<Vec<[f32; 2]>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let n = ALBEDO_TABLE_SIZE;
        let m = 32;
        let mut table = Vec::with_capacity(n * n);
        for ia in 0..n {
            let alpha = (ia as f32 / (n - 1) as f32).max(MIN_ALPHA);
            for im in 0..n {
                let mu = (im as f32 / (n - 1) as f32).max(1e-3);
                let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                let (mut a, mut b) = (0.0f64, 0.0f64);
                for k in 0..m * m {
                    let u = Vec2::new(((k % m) as f32 + 0.5) / m as f32, ((k / m) as f32 + 0.5) / m as f32);
                    let h = sample_ggx_vndf(wo, alpha, u);
                    let wi = reflect(wo, h);
                    if wi.z <= 0.0 {
                        continue;
                    }
                    // VNDF sampling: f·cos/pdf = F · G2/G1(wo).
                    let g = smith_g2(wo.z, wi.z, alpha) / smith_g1(wo.z, alpha);
                    let fc = (1.0 - wo.dot(h).clamp(0.0, 1.0)).powi(5);
                    a += ((1.0 - fc) * g) as f64;
                    b += (fc * g) as f64;
                }
                let count = (m * m) as f64;
                table.push([(a / count) as f32, (b / count) as f32]);
            }
        }
        table
    })
}

/// The GGX lobe's directional albedo ∫ f_spec(wo, wi) cos θi dωi for a viewer at
/// cos θo = `cos_o` (F0·A + B, bilinear in the table): the fraction of uniform
/// incident radiance the specular lobe reflects toward the viewer.
pub fn specular_directional_albedo(f0: Vec3, cos_o: f32, alpha: f32) -> Vec3 {
    let n = ALBEDO_TABLE_SIZE;
    let t = albedo_table();
    let x = cos_o.clamp(0.0, 1.0) * (n - 1) as f32;
    let y = alpha.clamp(0.0, 1.0) * (n - 1) as f32;
    let (x0, y0) = ((x as usize).min(n - 2), (y as usize).min(n - 2));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let at = |i: usize, j: usize| t[j * n + i];
    let lerp = |a: [f32; 2], b: [f32; 2], f: f32| [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f];
    let ab = lerp(lerp(at(x0, y0), at(x0 + 1, y0), fx), lerp(at(x0, y0 + 1), at(x0 + 1, y0 + 1), fx), fy);
    f0 * ab[0] + Vec3::splat(ab[1])
}

fn reflect(wo: Vec3, h: Vec3) -> Vec3 {
    h * (2.0 * wo.dot(h)) - wo
}

impl SurfaceBsdf {
    /// A purely diffuse BSDF of albedo `albedo`: F0 = 0, so no specular lobe and
    /// `f = albedo/π` exactly.
    pub fn lambertian(albedo: Vec3) -> Self {
        Self { diffuse: albedo, specular_f0: Vec3::ZERO, alpha: 1.0 }
    }

    /// Whether the specular lobe exists: some channel of `specular_f0` is above zero.
    pub fn has_specular(&self) -> bool {
        self.specular_f0.max_element() > 0.0
    }

    fn alpha(&self) -> f32 {
        self.alpha.max(MIN_ALPHA)
    }

    /// The diffuse albedo after the energy split.
    pub fn diffuse_albedo(&self) -> Vec3 {
        self.diffuse * (1.0 - self.specular_f0.max_element().min(1.0))
    }

    /// Probability of sampling the specular lobe.
    pub fn specular_probability(&self) -> f32 {
        if !self.has_specular() {
            return 0.0;
        }
        let s = luminance(self.specular_f0);
        let d = luminance(self.diffuse_albedo());
        if d <= 0.0 { 1.0 } else { (s / (s + d)).clamp(0.1, 0.9) }
    }

    /// The specular lobe alone, f·(nothing else).
    pub fn eval_specular(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if !self.has_specular() || wo.z <= 0.0 || wi.z <= 0.0 {
            return Vec3::ZERO;
        }
        let h = (wo + wi).normalize_or_zero();
        if h == Vec3::ZERO {
            return Vec3::ZERO;
        }
        let a = self.alpha();
        fresnel_schlick(self.specular_f0, wi.dot(h)) * (ggx_d(h.z, a) * smith_g2(wo.z, wi.z, a) / (4.0 * wo.z * wi.z))
    }

    /// The diffuse lobe alone.
    pub fn eval_diffuse(&self, wi: Vec3) -> Vec3 {
        if wi.z <= 0.0 { Vec3::ZERO } else { self.diffuse_albedo() * FRAC_1_PI }
    }

    /// f(wo, wi), without the cosine.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.eval_diffuse(wi) + self.eval_specular(wo, wi)
    }

    /// Density of [`Self::sample`] producing `wi`, per steradian.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let ps = self.specular_probability();
        let spec = if ps > 0.0 { ggx_reflection_pdf(wo, wi, self.alpha()) } else { 0.0 };
        ps * spec + (1.0 - ps) * cosine_hemisphere_pdf(wi.z)
    }

    /// Samples `wi`; returns (wi, f·cos/pdf, pdf). `u_lobe` chooses the lobe.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
        let ps = self.specular_probability();
        let wi = if u_lobe < ps {
            let h = sample_ggx_vndf(wo, self.alpha(), u);
            reflect(wo, h)
        } else {
            sample_cosine_hemisphere(u)
        };
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return None;
        }
        let pdf = self.pdf(wo, wi);
        if pdf.is_nan() || pdf <= 0.0 || !pdf.is_finite() {
            return None;
        }
        let weight = self.eval(wo, wi) * (wi.z / pdf);
        weight.is_finite().then_some((wi, weight, pdf))
    }

    /// Samples the specular lobe only (camera glossy rays): (wi, f_spec·cos/pdf_spec).
    pub fn sample_specular(&self, wo: Vec3, u: Vec2) -> Option<(Vec3, Vec3)> {
        if !self.has_specular() || wo.z <= 0.0 {
            return None;
        }
        let a = self.alpha();
        let h = sample_ggx_vndf(wo, a, u);
        let wi = reflect(wo, h);
        if wi.z <= 0.0 {
            return None;
        }
        // With VNDF sampling, f·cos/pdf = F · G2 / G1(wo).
        let weight = fresnel_schlick(self.specular_f0, wi.dot(h)) * (smith_g2(wo.z, wi.z, a) / smith_g1(wo.z, a));
        weight.is_finite().then_some((wi, weight))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{sample_uniform_sphere, uniform_sphere_pdf};

    fn grid(n: usize) -> impl Iterator<Item = Vec2> {
        (0..n * n).map(move |i| Vec2::new(((i % n) as f32 + 0.5) / n as f32, ((i / n) as f32 + 0.5) / n as f32))
    }

    #[test]
    fn ggx_d_is_normalised_over_projected_area() {
        // ∫ D(h) cos θh dω = 1.
        for alpha in [0.3f32, 0.5, 0.8] {
            let n = 400;
            let s: f32 = grid(n)
                .map(|u| {
                    let d = sample_uniform_sphere(u);
                    if d.z > 0.0 { ggx_d(d.z, alpha) * d.z / uniform_sphere_pdf() } else { 0.0 }
                })
                .sum::<f32>()
                / (n * n) as f32;
            assert!((s - 1.0).abs() < 0.03, "alpha {alpha}: {s}");
        }
    }

    #[test]
    fn sampled_weights_match_eval_over_pdf_and_energy_is_bounded() {
        let wo = Vec3::new(0.4, 0.1, 0.9).normalize();
        for bsdf in [
            SurfaceBsdf { diffuse: Vec3::splat(0.5), specular_f0: Vec3::splat(0.9), alpha: 0.2 },
            SurfaceBsdf { diffuse: Vec3::splat(0.6), specular_f0: Vec3::splat(0.04), alpha: 0.5 },
            SurfaceBsdf::lambertian(Vec3::splat(0.7)),
        ] {
            let n = 128;
            let mut sum = Vec3::ZERO;
            let mut count = 0;
            for (k, u) in grid(n).enumerate() {
                let u_lobe = ((k as f32) * 0.618_034).fract();
                if let Some((wi, w, pdf)) = bsdf.sample(wo, u_lobe, u) {
                    let expect = bsdf.eval(wo, wi) * wi.z / bsdf.pdf(wo, wi);
                    assert!((w - expect).length() < 1e-3 * (1.0 + expect.length()));
                    assert!((pdf - bsdf.pdf(wo, wi)).abs() < 1e-4 * pdf.max(1.0));
                    sum += w;
                }
                count += 1;
            }
            let albedo = sum / count as f32;
            assert!(albedo.max_element() <= 1.02, "{bsdf:?}: directional albedo {albedo}");
            // Uniform-sphere estimate of the same integral agrees with the sampled one.
            let m = 600;
            let direct: Vec3 = grid(m)
                .map(|u| {
                    let wi = sample_uniform_sphere(u);
                    if wi.z > 0.0 { bsdf.eval(wo, wi) * wi.z / uniform_sphere_pdf() } else { Vec3::ZERO }
                })
                .sum::<Vec3>()
                / (m * m) as f32;
            assert!((direct - albedo).abs().max_element() < 0.03, "{bsdf:?}: {direct} vs {albedo}");
        }
    }

    #[test]
    fn the_directional_albedo_table_matches_direct_integration() {
        let m = 700;
        for (f0, mu, alpha) in [(0.04f32, 0.9f32, 0.3f32), (0.9, 0.5, 0.6), (0.5, 0.2, 0.9), (0.9, 0.75, 0.1)] {
            let b = SurfaceBsdf { diffuse: Vec3::ZERO, specular_f0: Vec3::splat(f0), alpha };
            let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
            // Uniform-sphere estimate: independent of the table's VNDF sampling.
            let direct: f32 = grid(m)
                .map(|u| {
                    let wi = sample_uniform_sphere(u);
                    if wi.z > 0.0 { b.eval_specular(wo, wi).x * wi.z / uniform_sphere_pdf() } else { 0.0 }
                })
                .sum::<f32>()
                / (m * m) as f32;
            let table = specular_directional_albedo(Vec3::splat(f0), mu, alpha).x;
            assert!((table - direct).abs() < 0.02 + 0.03 * direct, "F0 {f0} μ {mu} α {alpha}: {table} vs {direct}");
        }
        // Rough lobes lose energy to masking: well below Schlick's F at the same angle.
        let rough = specular_directional_albedo(Vec3::splat(0.9), 0.3, 1.0).x;
        assert!(rough < 0.85 * fresnel_schlick(Vec3::splat(0.9), 0.3).x, "{rough}");
        // A near-mirror reflects Schlick's F.
        let mirror = specular_directional_albedo(Vec3::splat(0.5), 0.8, 0.0).x;
        assert!((mirror - fresnel_schlick(Vec3::splat(0.5), 0.8).x).abs() < 0.01, "{mirror}");
    }

    #[test]
    fn lambertian_is_exactly_albedo_over_pi() {
        let b = SurfaceBsdf::lambertian(Vec3::new(0.2, 0.4, 0.6));
        assert_eq!(b.eval(Vec3::Z, Vec3::new(0.6, 0.0, 0.8)), Vec3::new(0.2, 0.4, 0.6) * FRAC_1_PI);
        assert_eq!(b.specular_probability(), 0.0);
    }
}
