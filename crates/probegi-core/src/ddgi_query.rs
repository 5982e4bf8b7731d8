//! The DDGI query: irradiance at a world position and normal from the 8-probe
//! cage (seed 003 §4.4, seed 004 §2.2, §4.1–4.2; RTXGI `DDGIGetVolumeIrradiance`).
//!
//! Per cage probe, the weight is the product of (each switchable):
//! - backface / wrap: `((dir·n + 1)/2)² + 0.2` (seed 003 eq. 4.4 with a = 1, plus
//!   RTXGI's 0.2 floor so no probe is fully rejected by angle alone);
//! - Chebyshev visibility (eq. 4.5–4.9) from the distance moments at the biased
//!   point, `σ²/(σ² + (r − μ)²)` for r > μ, cubed and floored at 0.05 (RTXGI);
//! - crush (eq. 4.10): weights below c are multiplied by w²/c² (RTXGI's form);
//! - trilinear, from the biased point's position in the cage.
//!
//! The bias is seed 004 eq. 2's self-shadow bias by default, or seed 003 eq.
//! 4.11's normal bias. Irradiance texels are decoded to `mean^(1/2)` (seed 004
//! Listing 2), blended, normalised by Σw and squared back. The atlas holds mean
//! radiance (see `probe_blend`), so the returned irradiance is π × that, scaled by
//! the energy-conservation factor. Shading multiplies by albedo/π.
//!
//! Probes that queries may not read (culled, or not yet blended) are skipped, and
//! the sum is renormalised over the rest. When no probe of the cage is usable the
//! query does not return black (RTXGI does, and under DDGI the sky reaches surfaces
//! only through the field): each corner's nearest usable probe
//! ([`nearest_usable_probes`]) stands in for it, with the same weights, so the
//! backface and Chebyshev terms still prefer stand-ins that see the point. That
//! value is less exact (a stand-in can be cells away), but it is the field's light,
//! not black.

use glam::{IVec3, UVec3, Vec2, Vec3};
use std::f32::consts::PI;

use crate::ddgi_settings::{DdgiVolumeSettings, ProbeBiasMode};

/// The backface weight's floor, `((dir·n + 1)/2)² + floor` (RTXGI's 0.2), so no
/// probe is rejected by angle alone. `ddgi_query.wgsl` reads it from the
/// constants prelude probegi-wgpu generates from this value.
pub const BACKFACE_WEIGHT_FLOOR: f32 = 0.2;

/// The floor of the Chebyshev visibility weight (RTXGI's 0.05); also in
/// `ddgi_query.wgsl`'s generated prelude.
pub const CHEBYSHEV_WEIGHT_FLOOR: f32 = 0.05;

/// The smallest weight a cage probe keeps before the crush, so Σw never vanishes;
/// also in `ddgi_query.wgsl`'s generated prelude.
pub const MIN_PROBE_WEIGHT: f32 = 1e-6;

/// The floor of each trilinear factor, so a probe at the far corner of the cage
/// still counts a little; also in `ddgi_query.wgsl`'s generated prelude.
pub const TRILINEAR_WEIGHT_FLOOR: f32 = 0.001;
use crate::irradiance_encoding::{decode_irradiance_half, finish_half_decode};
use crate::octahedral::oct_encode;
use crate::probe_atlas::{BilinearFootprint, ProbeAtlas};
use crate::probe_grid::ProbeGrid;

/// Everything a query reads: the grid, its settings, both atlases, and per probe
/// its relocation offset and whether queries may use it.
#[derive(Clone, Copy)]
pub struct DdgiFieldView<'a> {
    /// The volume's probe grid: probe grid points, spacing, the cage lookup and the
    /// storage slot of each probe, which indexes both atlases.
    pub grid: &'a ProbeGrid,
    /// The volume's settings the query reads: bias mode and amount, irradiance γ, which
    /// weights apply (backface, Chebyshev, crush and its threshold, trilinear) and the
    /// energy-conservation factor.
    pub settings: &'a DdgiVolumeSettings,
    /// Per probe, the octahedral irradiance tile looked up in the surface normal's
    /// direction: mean radiance encoded as `mean^(1/γ)` (seed 004 Listing 1).
    pub irradiance: &'a ProbeAtlas<Vec3>,
    /// Per probe, the octahedral distance tile looked up in the probe-to-point
    /// direction: (mean, mean²) of the ray hit distance in metres, the Chebyshev
    /// moments (seed 003 eq. 4.5–4.9, 4.14–4.16).
    pub distance: &'a ProbeAtlas<Vec2>,
    /// Offset of each probe from its grid point (seed 004 §5); empty = none.
    pub probe_offsets_m: &'a [Vec3],
    /// Probes queries may read (Off / Sleeping / Dead are excluded); empty = all.
    pub probe_usable: &'a [bool],
    /// Per probe, the nearest usable probe (itself when usable; `u32::MAX` when no
    /// probe is usable), from [`nearest_usable_probes`]; empty = no fallback.
    pub probe_fallback: &'a [u32],
    /// An identity of the three per-probe arrays above, where the field set
    /// that owns them gives one (`probegi_field::DdgiFieldSet::view`): views
    /// with the same `Some` identity and the same arrays (the same addresses
    /// and lengths) hold the same values, so a device that wrote their rows
    /// may keep them without comparing. `None`: no identity (compare). A
    /// caller that puts arrays of its own into a view sets `None`.
    pub probe_rows_id: Option<u64>,
}

/// For every probe, the index of the nearest usable probe in grid steps (the
/// 26-neighbourhood, so Chebyshev distance; ties go to the lower index), itself
/// when it is usable, `u32::MAX` when none is. A breadth-first search from all
/// usable probes at once: O(probes).
pub fn nearest_usable_probes(grid: &ProbeGrid, usable: &[bool]) -> Vec<u32> {
    let n = grid.probe_count();
    let mut nearest = vec![u32::MAX; n];
    let mut queue = std::collections::VecDeque::new();
    for (p, nearest) in nearest.iter_mut().enumerate() {
        if usable.get(p).copied().unwrap_or(true) {
            *nearest = p as u32;
            queue.push_back(p);
        }
    }
    let max = grid.probe_counts.as_ivec3() - IVec3::ONE;
    while let Some(p) = queue.pop_front() {
        let c = grid.probe_coords(p).as_ivec3();
        for i in 0..27 {
            let d = IVec3::new(i % 3 - 1, (i / 3) % 3 - 1, i / 9 - 1);
            let q = c + d;
            if q.cmplt(IVec3::ZERO).any() || q.cmpgt(max).any() {
                continue;
            }
            let q = grid.probe_index(q.as_uvec3());
            if nearest[q] == u32::MAX {
                nearest[q] = nearest[p];
                queue.push_back(q);
            }
        }
    }
    nearest
}

/// The world-space offset seed 004 eq. 2 (or seed 003 eq. 4.11) adds to the query
/// point before the visibility test. `view_dir` points from the surface toward
/// the viewer (camera or probe).
pub fn surface_bias(settings: &DdgiVolumeSettings, grid: &ProbeGrid, normal: Vec3, view_dir: Vec3) -> Vec3 {
    match settings.probe_bias_mode {
        ProbeBiasMode::SelfShadow => {
            (normal * 0.2 + view_dir * 0.8) * (0.75 * grid.min_spacing_m()) * settings.probe_self_shadow_bias
        }
        ProbeBiasMode::Normal => (normal * 0.8 + view_dir * 0.3) * settings.probe_normal_bias_m,
        ProbeBiasMode::None => Vec3::ZERO,
    }
}

/// The longest offset [`surface_bias`] can produce for these settings (unit normal
/// and view direction): |0.2·n + 0.8·ω| ≤ 1 and |0.8·n + 0.3·v| ≤ 1.1.
pub fn max_surface_bias_m(settings: &DdgiVolumeSettings, grid: &ProbeGrid) -> f32 {
    match settings.probe_bias_mode {
        ProbeBiasMode::SelfShadow => 0.75 * grid.min_spacing_m() * settings.probe_self_shadow_bias,
        ProbeBiasMode::Normal => 1.1 * settings.probe_normal_bias_m,
        ProbeBiasMode::None => 0.0,
    }
}

/// Chebyshev visibility weight for a point at `distance` from a probe whose
/// distance moments are `(mean, mean²)`: 1 in front of the mean, falling behind it.
pub fn chebyshev_weight(moments: Vec2, distance: f32) -> f32 {
    let mean = moments.x;
    if distance <= mean {
        return 1.0;
    }
    let variance = (moments.x * moments.x - moments.y).abs();
    let v = distance - mean;
    let w = variance / (variance + v * v);
    (w * w * w).max(0.0)
}

/// Wrap-shading backface weight for the direction from the surface to a probe.
pub fn backface_weight(dir_to_probe: Vec3, normal: Vec3) -> f32 {
    let wrap = (dir_to_probe.dot(normal) + 1.0) * 0.5;
    wrap * wrap + BACKFACE_WEIGHT_FLOOR
}

/// Irradiance (W·m⁻²) arriving at `position` on a surface with unit `normal`.
pub fn irradiance(field: &DdgiFieldView<'_>, position: Vec3, normal: Vec3, view_dir: Vec3) -> Vec3 {
    let s = field.settings;
    let g = field.grid;
    let biased = position + surface_bias(s, g, normal, view_dir);
    let cage = g.cage(biased);
    let at = QueryPoint {
        position,
        normal,
        biased,
        normal_texels: BilinearFootprint::new(field.irradiance.interior, oct_encode(normal)),
    };
    let mut corners = [CageCorner::NONE; 8];
    for (i, c) in corners.iter_mut().enumerate() {
        let coords = cage.corner(i);
        let probe = g.probe_index(coords);
        if field.probe_usable.get(probe).is_none_or(|u| *u) {
            *c = CageCorner { probe, coords, trilinear: cage.trilinear(i) };
        }
    }
    let (mut sum, mut wsum) = weigh_corners(field, &at, &corners);
    if !(wsum.is_finite() && wsum > 0.0) {
        // No usable probe in the cage: each corner's nearest usable probe stands in
        // for it, with the same weights (so visibility still picks among them).
        for (i, c) in corners.iter_mut().enumerate() {
            *c = match field.probe_fallback.get(g.probe_index(cage.corner(i))) {
                Some(&q) if q != u32::MAX => {
                    CageCorner { probe: q as usize, coords: g.probe_coords(q as usize), trilinear: cage.trilinear(i) }
                }
                _ => CageCorner::NONE,
            };
        }
        let (fallback_sum, fallback_wsum) = weigh_corners(field, &at, &corners);
        sum += fallback_sum;
        wsum += fallback_wsum;
    }
    if !(wsum.is_finite() && wsum > 0.0) {
        return Vec3::ZERO;
    }
    let e = finish_half_decode(sum / wsum) * PI * s.probe_energy_conservation;
    if e.is_finite() { e } else { Vec3::ZERO }
}

/// What every cage corner's weight reads about the shaded point.
struct QueryPoint {
    position: Vec3,
    normal: Vec3,
    /// `position` moved by the surface bias: where visibility is tested from.
    biased: Vec3,
    /// The irradiance texels in the normal's direction, the same in every tile.
    normal_texels: BilinearFootprint,
}

/// One corner of the cage as a query reads it: the probe that stands there (the
/// corner's own, or its fallback), its grid coordinates and the corner's
/// trilinear factors. `probe == usize::MAX`: no probe, the corner is skipped.
#[derive(Clone, Copy)]
struct CageCorner {
    probe: usize,
    coords: UVec3,
    trilinear: Vec3,
}

impl CageCorner {
    const NONE: Self = Self { probe: usize::MAX, coords: UVec3::ZERO, trilinear: Vec3::ZERO };
}

/// Σ weight · half-decoded irradiance and Σ weight over the corners that have a
/// probe, summed in corner order. Each step runs for all eight corners before
/// the next (positions, then visibility, then irradiance), so the corners'
/// lookups and square roots overlap instead of waiting on one another; every
/// corner's arithmetic is the same as one corner at a time.
fn weigh_corners(field: &DdgiFieldView<'_>, at: &QueryPoint, corners: &[CageCorner; 8]) -> (Vec3, f32) {
    let (s, g) = (field.settings, field.grid);
    let used = corners.map(|c| c.probe != usize::MAX);
    let probe_pos = corners.map(|c| {
        let offset = field.probe_offsets_m.get(c.probe).copied().unwrap_or(Vec3::ZERO);
        g.probe_position(c.coords) + offset
    });
    let mut weight = [1.0f32; 8];
    if s.probe_backface_weight {
        for i in 0..8 {
            let dir = (probe_pos[i] - at.position).normalize_or_zero();
            weight[i] *= backface_weight(dir, at.normal);
        }
    }
    if s.probe_chebyshev_weight {
        let mut uv = [Vec2::ZERO; 8];
        let mut dist = [0.0f32; 8];
        for i in 0..8 {
            let to_probe = probe_pos[i] - at.biased;
            dist[i] = to_probe.length();
            // oct_encode normalises by the L1 norm itself, so the direction need not be unit.
            uv[i] = oct_encode(-to_probe);
        }
        let moments = std::array::from_fn::<Vec2, 8, _>(|i| {
            if used[i] { field.distance.sample_bilinear(corners[i].probe, uv[i]) } else { Vec2::ZERO }
        });
        for i in 0..8 {
            weight[i] *= chebyshev_weight(moments[i], dist[i]).max(CHEBYSHEV_WEIGHT_FLOOR);
        }
    }
    let mut e = [Vec3::ZERO; 8];
    for i in 0..8 {
        let mut w = weight[i].max(MIN_PROBE_WEIGHT);
        if s.probe_crush_weight && w < s.probe_crush_threshold {
            let c = s.probe_crush_threshold;
            w *= w * w / (c * c);
        }
        if s.probe_trilinear_weight {
            let t = corners[i].trilinear.max(Vec3::splat(TRILINEAR_WEIGHT_FLOOR));
            w *= t.x * t.y * t.z;
        }
        weight[i] = w;
        if used[i] {
            e[i] = at.normal_texels.sample(field.irradiance.tile(corners[i].probe)).max(Vec3::ZERO);
        }
    }
    let (mut sum, mut wsum) = (Vec3::ZERO, 0.0f32);
    for i in (0..8).filter(|&i| used[i]) {
        sum += decode_irradiance_half(e[i], s.probe_irradiance_gamma) * weight[i];
        wsum += weight[i];
    }
    (sum, wsum)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance_encoding::encode_irradiance;

    /// A view with no relocation offsets, every probe usable and no fallback table.
    fn bare_view<'a>(
        grid: &'a ProbeGrid,
        settings: &'a DdgiVolumeSettings,
        irradiance: &'a ProbeAtlas<Vec3>,
        distance: &'a ProbeAtlas<Vec2>,
    ) -> DdgiFieldView<'a> {
        DdgiFieldView {
            grid,
            settings,
            irradiance,
            distance,
            probe_offsets_m: &[],
            probe_usable: &[],
            probe_fallback: &[],
            probe_rows_id: None,
        }
    }

    fn uniform_field(
        mean_radiance: f32,
        distance: f32,
        counts: UVec3,
    ) -> (ProbeGrid, DdgiVolumeSettings, ProbeAtlas<Vec3>, ProbeAtlas<Vec2>) {
        let grid = ProbeGrid::new(Vec3::ZERO, counts, Vec3::ONE);
        let settings = DdgiVolumeSettings::default();
        let n = grid.probe_count();
        let mut irr = ProbeAtlas::new(n, settings.probe_irradiance_texels);
        let mut dist = ProbeAtlas::new(n, settings.probe_distance_texels);
        irr.texels.fill(encode_irradiance(Vec3::splat(mean_radiance), settings.probe_irradiance_gamma));
        dist.texels.fill(Vec2::new(distance, distance * distance));
        (grid, settings, irr, dist)
    }

    #[test]
    fn uniform_field_returns_pi_times_mean_radiance_everywhere() {
        let (grid, settings, irr, dist) = uniform_field(2.0, 10.0, UVec3::splat(3));
        let f = bare_view(&grid, &settings, &irr, &dist);
        for p in [Vec3::new(0.3, 0.7, 1.2), Vec3::new(1.9, 0.1, 0.5), Vec3::new(-4.0, 9.0, 0.0)] {
            for n in [Vec3::X, Vec3::NEG_Y, Vec3::new(0.6, 0.0, 0.8)] {
                let e = irradiance(&f, p, n, n);
                assert!((e.x - 2.0 * PI).abs() < 1e-3, "{p} {n}: {e}");
            }
        }
    }

    #[test]
    fn chebyshev_is_one_in_front_of_the_mean_and_falls_behind_it() {
        let m = Vec2::new(2.0, 4.0 + 0.01);
        assert_eq!(chebyshev_weight(m, 1.0), 1.0);
        assert_eq!(chebyshev_weight(m, 2.0), 1.0);
        let a = chebyshev_weight(m, 2.1);
        let b = chebyshev_weight(m, 2.5);
        assert!(a < 1.0 && b < a && b > 0.0, "{a} {b}");
        assert!(chebyshev_weight(m, 4.0) < 1e-4);
    }

    #[test]
    fn a_probe_behind_the_surface_gets_little_weight() {
        let n = Vec3::Y;
        assert!((backface_weight(Vec3::Y, n) - 1.2).abs() < 1e-6);
        assert!((backface_weight(Vec3::NEG_Y, n) - 0.2).abs() < 1e-6);
        // Through a real query: two probes, one above and one below a floor at y = 0.5,
        // the lower one seeing the floor's underside at 0.5 m (and dark).
        let grid = ProbeGrid::new(Vec3::ZERO, UVec3::new(1, 2, 1), Vec3::ONE);
        let settings = DdgiVolumeSettings::default();
        let mut irr = ProbeAtlas::new(2, settings.probe_irradiance_texels);
        let mut dist = ProbeAtlas::new(2, settings.probe_distance_texels);
        irr.tile_mut(1).fill(Vec3::ONE); // upper probe: lit
        irr.tile_mut(0).fill(Vec3::ZERO); // lower probe: dark
        dist.tile_mut(1).fill(Vec2::new(5.0, 25.0));
        dist.tile_mut(0).fill(Vec2::new(0.5, 0.25));
        let f = bare_view(&grid, &settings, &irr, &dist);
        let e = irradiance(&f, Vec3::new(0.0, 0.5, 0.0), Vec3::Y, Vec3::Y);
        // The lit probe dominates: nearly π·1 rather than the unweighted ~π/2.
        assert!(e.x > 0.95 * PI, "{e}");
        let mut off = settings.clone();
        off.probe_backface_weight = false;
        off.probe_chebyshev_weight = false;
        let f = bare_view(&grid, &off, &irr, &dist);
        let leaky = irradiance(&f, Vec3::new(0.0, 0.5, 0.0), Vec3::Y, Vec3::Y);
        assert!(leaky.x < 0.8 * PI, "without the weights the dark probe leaks in: {leaky}");
        // Excluding the dark probe from queries (an Off probe) removes it entirely.
        let usable = [false, true];
        let f = DdgiFieldView { probe_usable: &usable, ..f };
        let culled = irradiance(&f, Vec3::new(0.0, 0.5, 0.0), Vec3::Y, Vec3::Y);
        assert!((culled.x - PI).abs() < 1e-3, "{culled}");
    }

    #[test]
    fn a_cage_without_usable_probes_reads_the_nearest_usable_probe_not_black() {
        // 5 × 1 × 1 probes; only the last one (x = 4) is usable and lit.
        let grid = ProbeGrid::new(Vec3::ZERO, UVec3::new(5, 1, 1), Vec3::ONE);
        let settings = DdgiVolumeSettings::default();
        let mut irr = ProbeAtlas::new(5, settings.probe_irradiance_texels);
        let mut dist = ProbeAtlas::new(5, settings.probe_distance_texels);
        irr.tile_mut(4).fill(encode_irradiance(Vec3::splat(3.0), settings.probe_irradiance_gamma));
        dist.texels.fill(Vec2::new(5.0, 25.0));
        let usable = [false, false, false, false, true];
        let fallback = nearest_usable_probes(&grid, &usable);
        assert_eq!(fallback, vec![4; 5]);
        let f = DdgiFieldView {
            probe_usable: &usable,
            probe_fallback: &fallback,
            ..bare_view(&grid, &settings, &irr, &dist)
        };
        // The cage of x = 0.4 holds probes 0 and 1, both unusable.
        let e = irradiance(&f, Vec3::new(0.4, 0.0, 0.0), Vec3::Y, Vec3::Y);
        assert!((e.x - 3.0 * PI).abs() < 1e-3, "{e}");
        // Without the fallback table the same query is black.
        let black = irradiance(&DdgiFieldView { probe_fallback: &[], ..f }, Vec3::new(0.4, 0.0, 0.0), Vec3::Y, Vec3::Y);
        assert_eq!(black, Vec3::ZERO);
        // Nothing usable anywhere: no fallback exists.
        assert_eq!(nearest_usable_probes(&grid, &[false; 5]), vec![u32::MAX; 5]);
        // Ties and distances on a 3-D grid: every probe gets a usable probe no farther
        // (in grid steps) than any other usable probe.
        let g3 = ProbeGrid::new(Vec3::ZERO, UVec3::new(4, 3, 5), Vec3::ONE);
        let u3: Vec<bool> = (0..g3.probe_count()).map(|i| i % 7 == 3).collect();
        let n3 = nearest_usable_probes(&g3, &u3);
        let steps =
            |a: usize, b: usize| (g3.probe_coords(a).as_ivec3() - g3.probe_coords(b).as_ivec3()).abs().max_element();
        for p in 0..g3.probe_count() {
            let best = (0..g3.probe_count()).filter(|&q| u3[q]).map(|q| steps(p, q)).min().unwrap_or(0);
            assert!(u3[n3[p] as usize] && steps(p, n3[p] as usize) == best, "probe {p}");
        }
    }
}
