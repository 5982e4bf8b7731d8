//! The dynamic global shadowing field (seed 003 ch. 5): per probe an octahedral
//! occlusion map holding, in each direction ω, the mean visibility of the
//! lights as seen from the surfels the probe's rays found.
//!
//! **Update (eq. 5.1–5.3).** A shadow ray from a surfel x toward light l gives
//! V(x, l) = 1 when it reaches the light. Each texel ω blends
//! `Σ_l Σ_rays max(0, ω·l)·V(x, l) / Σ_l Σ_rays max(0, ω·l)` with hysteresis α,
//! where l is the shadow ray's own direction, not the probe ray's: shadow rays
//! crowd toward the lights, so the uniform probe-ray weights of the irradiance
//! blend would be wrong ([`blend_shadow_tile`]). A texel no shadow ray faces
//! keeps its value.
//!
//! **Sampling (§5.2, Fig. 5.3).** The 8-probe cage of the DDGI query with, per
//! probe, the cosine weight `max(0, dir_to_probe·n)` (the seed's choice over
//! wrap shading, which leaks more), Chebyshev visibility from the volume's
//! distance moments, the trilinear weight and the query's surface bias; the
//! blended visibility is raised to the sharpening power of Fig. 7.10
//! ([`shadow_visibility`]).
//!
//! *Deviations, flagged:* the map is read in the direction of the light being
//! shaded (the seed does not say which direction it reads; the light's is the
//! one eq. 5.2 indexes by). A point whose cage has no probe facing it (every
//! cosine weight zero, e.g. on a thin wall) falls back to the DDGI query's wrap
//! weight instead of returning a made-up value.

use glam::{Vec2, Vec3};

use crate::ddgi_query::{CHEBYSHEV_WEIGHT_FLOOR, DdgiFieldView, TRILINEAR_WEIGHT_FLOOR, backface_weight};
use crate::ddgi_query::{chebyshev_weight, surface_bias};
use crate::octahedral::{oct_decode, oct_encode, texel_center_uv};
use crate::probe_atlas::{ProbeAtlas, interior_texel_index};
use crate::probe_border::update_tile_border;

/// One shadow ray's result, as the blend reads it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowSample {
    /// Unit direction from the surfel toward the light (the shadow ray's).
    pub dir_to_light: Vec3,
    /// V(x, l) (eq. 5.1): 1 when the ray reached the light, else 0.
    pub visible: f32,
}

/// Eq. 5.2–5.3 for one probe's tile (border included, `interior²` texels
/// inside): `hysteresis` is the weight of the old value (0 replaces it). The
/// border is refreshed afterwards. Returns the tile's change: the mean over the
/// interior of |this frame's visibility − the history| (0 for a texel no
/// sample weighs; `crate::probe_change`).
pub fn blend_shadow_tile(tile: &mut [f32], interior: u32, samples: &[ShadowSample], hysteresis: f32) -> f32 {
    if samples.is_empty() {
        return 0.0;
    }
    let mut change = 0.0f32;
    for j in 0..interior {
        for i in 0..interior {
            let omega = oct_decode(texel_center_uv(i, j, interior));
            let (mut sum, mut wsum) = (0.0f32, 0.0f32);
            for s in samples {
                let w = omega.dot(s.dir_to_light).max(0.0);
                sum += w * s.visible;
                wsum += w;
            }
            if wsum.is_nan() || wsum <= 0.0 {
                continue;
            }
            let dst = &mut tile[interior_texel_index(interior, i, j)];
            change += (sum / wsum - *dst).abs();
            let blended = (sum / wsum) * (1.0 - hysteresis) + *dst * hysteresis;
            if blended.is_finite() {
                *dst = blended.clamp(0.0, 1.0);
            }
        }
    }
    update_tile_border(tile, interior);
    change / (interior * interior).max(1) as f32
}

/// Mean light visibility in `[0, 1]` at `position` on a surface with unit
/// `normal`, toward the light in unit direction `dir_to_light`, from the
/// volume `field` and its occlusion maps `occlusion`, sharpened by `sharpness`
/// (1: as blended). `None` where no probe of the cage (nor a fallback) is usable.
pub fn shadow_visibility(
    field: &DdgiFieldView<'_>,
    occlusion: &ProbeAtlas<f32>,
    position: Vec3,
    normal: Vec3,
    view_dir: Vec3,
    dir_to_light: Vec3,
    sharpness: f32,
) -> Option<f32> {
    ShadowCage::new(field, occlusion, position, normal, view_dir, sharpness).map(|c| c.visibility(dir_to_light))
}

/// A shading point's cage in the shadowing field: each corner's probe and
/// normalised weight, which do not depend on the light, so a point lit by many
/// lights weighs its cage once and reads each light's visibility with eight
/// bilinear lookups ([`Self::visibility`]).
#[derive(Clone, Copy, Debug)]
pub struct ShadowCage<'a> {
    occlusion: &'a ProbeAtlas<f32>,
    /// (probe, weight / Σ weight); `usize::MAX`: no probe at that corner.
    corners: [(usize, f32); 8],
    sharpness: f32,
}

impl<'a> ShadowCage<'a> {
    /// The cage of `position` (module docs: cosine weight, the wrap weight
    /// where no probe faces the point, Chebyshev, trilinear); `None` where no
    /// probe of the cage nor a fallback is usable.
    pub fn new(
        field: &DdgiFieldView<'_>,
        occlusion: &'a ProbeAtlas<f32>,
        position: Vec3,
        normal: Vec3,
        view_dir: Vec3,
        sharpness: f32,
    ) -> Option<Self> {
        let g = field.grid;
        let biased = position + surface_bias(field.settings, g, normal, view_dir);
        let cage = g.cage(biased);
        // Per corner: probe, direction to it, and the weight but for the angle.
        let mut corners = [(usize::MAX, Vec3::ZERO, 0.0f32); 8];
        for (i, c) in corners.iter_mut().enumerate() {
            let probe = g.probe_index(cage.corner(i));
            let probe = match field.probe_usable.get(probe) {
                Some(false) => match field.probe_fallback.get(probe) {
                    Some(&q) if q != u32::MAX => q as usize,
                    _ => continue,
                },
                _ => probe,
            };
            let offset = field.probe_offsets_m.get(probe).copied().unwrap_or(Vec3::ZERO);
            let probe_pos = g.probe_position(g.probe_coords(probe)) + offset;
            let t = cage.trilinear(i).max(Vec3::splat(TRILINEAR_WEIGHT_FLOOR));
            let to_probe = probe_pos - biased;
            let moments: Vec2 = field.distance.sample_bilinear(probe, oct_encode(-to_probe));
            let w = chebyshev_weight(moments, to_probe.length()).max(CHEBYSHEV_WEIGHT_FLOOR) * (t.x * t.y * t.z);
            *c = (probe, (probe_pos - position).normalize_or_zero(), w);
        }
        let weigh = |cosine: bool| -> [(usize, f32); 8] {
            corners.map(|(probe, dir, w)| {
                let angle = if cosine { dir.dot(normal).max(0.0) } else { backface_weight(dir, normal) };
                (probe, if probe == usize::MAX { 0.0 } else { angle * w })
            })
        };
        let sum = |c: &[(usize, f32); 8]| c.iter().map(|c| c.1).sum::<f32>();
        let mut weighted = weigh(true);
        let mut wsum = sum(&weighted);
        if wsum.is_nan() || wsum <= 0.0 {
            weighted = weigh(false);
            wsum = sum(&weighted);
        }
        if !(wsum.is_finite() && wsum > 0.0) {
            return None;
        }
        Some(Self { occlusion, corners: weighted.map(|(p, w)| (p, w / wsum)), sharpness })
    }

    /// The visibility in `[0, 1]` toward the light in unit direction `dir_to_light`, sharpened.
    pub fn visibility(&self, dir_to_light: Vec3) -> f32 {
        let uv = oct_encode(dir_to_light);
        let mut v = 0.0f32;
        for &(probe, w) in self.corners.iter().filter(|c| c.0 != usize::MAX && c.1 > 0.0) {
            v += w * self.occlusion.sample_bilinear(probe, uv).clamp(0.0, 1.0);
        }
        if v.is_finite() { v.clamp(0.0, 1.0).powf(self.sharpness.max(0.0)) } else { 1.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ddgi_settings::DdgiVolumeSettings;
    use crate::probe_grid::ProbeGrid;

    fn tile_of(interior: u32, samples: &[ShadowSample], hysteresis: f32, start: f32) -> Vec<f32> {
        let mut a = ProbeAtlas::<f32>::new(1, interior);
        a.texels.fill(start);
        blend_shadow_tile(a.tile_mut(0), interior, samples, hysteresis);
        a.texels
    }

    #[test]
    fn one_light_half_visible_gives_half_where_it_faces() {
        let l = Vec3::new(0.3, 0.9, 0.1).normalize();
        let samples = [ShadowSample { dir_to_light: l, visible: 1.0 }, ShadowSample { dir_to_light: l, visible: 0.0 }];
        let a = tile_of(16, &samples, 0.0, 0.25);
        for j in 0..16 {
            for i in 0..16 {
                let omega = oct_decode(texel_center_uv(i, j, 16));
                let v = a[interior_texel_index(16, i, j)];
                // Texels facing the light take the mean; the others keep their value.
                let want = if omega.dot(l) > 0.0 { 0.5 } else { 0.25 };
                assert!((v - want).abs() < 1e-6, "({i},{j}) {v} {want}");
            }
        }
    }

    #[test]
    fn weights_follow_the_shadow_rays_and_hysteresis_keeps_history() {
        // Two lights, one seen and one blocked: texels nearer the seen light read
        // more visible (eq. 5.2's max(0, ω·l) weights).
        let (up, side) = (Vec3::Y, Vec3::X);
        let samples =
            [ShadowSample { dir_to_light: up, visible: 1.0 }, ShadowSample { dir_to_light: side, visible: 0.0 }];
        let interior = 16;
        let mut a = ProbeAtlas::<f32>::new(1, interior);
        blend_shadow_tile(a.tile_mut(0), interior, &samples, 0.0);
        let at = |a: &ProbeAtlas<f32>, d: Vec3| a.sample_bilinear(0, oct_encode(d));
        assert!(at(&a, up) > 0.95 && at(&a, side) < 0.05, "{} {}", at(&a, up), at(&a, side));
        let diag = at(&a, (up + side).normalize());
        assert!((diag - 0.5).abs() < 0.1, "{diag}");
        // α = 0.9 keeps 90 % of the old value.
        let before = a.clone();
        blend_shadow_tile(a.tile_mut(0), interior, &[ShadowSample { dir_to_light: up, visible: 0.0 }], 0.9);
        let (old, new) = (at(&before, up), at(&a, up));
        assert!((new - 0.9 * old).abs() < 1e-3, "{old} → {new}");
    }

    #[test]
    fn sampling_reads_the_cage_and_sharpens() {
        let grid = ProbeGrid::new(Vec3::ZERO, glam::UVec3::splat(2), Vec3::ONE);
        let settings = DdgiVolumeSettings::default();
        let irradiance = ProbeAtlas::<Vec3>::new(8, settings.probe_irradiance_texels);
        let mut distance = ProbeAtlas::<Vec2>::new(8, settings.probe_distance_texels);
        distance.texels.fill(Vec2::new(10.0, 100.0));
        let field = DdgiFieldView {
            grid: &grid,
            settings: &settings,
            irradiance: &irradiance,
            distance: &distance,
            probe_offsets_m: &[],
            probe_usable: &[],
            probe_fallback: &[],
            probe_rows_id: None,
        };
        let mut occlusion = ProbeAtlas::<f32>::new(8, 16);
        occlusion.texels.fill(0.5);
        let p = Vec3::splat(0.5);
        let v = shadow_visibility(&field, &occlusion, p, Vec3::Y, Vec3::Y, Vec3::Y, 1.0).expect("usable");
        assert!((v - 0.5).abs() < 1e-5, "{v}");
        let v3 = shadow_visibility(&field, &occlusion, p, Vec3::Y, Vec3::Y, Vec3::Y, 3.0).expect("usable");
        assert!((v3 - 0.125).abs() < 1e-5, "{v3}");
        // Probes on the lit side only: the upper probes (y = 1) see 1, the lower 0;
        // a point facing up reads only the upper ones (cosine weight).
        for p in 0..8 {
            let up = grid.probe_coords(p).y == 1;
            occlusion.tile_mut(p).fill(if up { 1.0 } else { 0.0 });
        }
        let v = shadow_visibility(&field, &occlusion, Vec3::new(0.5, 0.4, 0.5), Vec3::Y, Vec3::Y, Vec3::Y, 1.0);
        assert!(v.expect("usable") > 0.99, "{v:?}");
    }
}
