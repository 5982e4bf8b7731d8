//! The uniform probe grid of a DDGI volume (seed 003 §4.1): any probe count per
//! axis (not only powers of two), per-axis spacing. Probe `(x, y, z)` sits at
//! `origin + spacing · (x, y, z)`; its linear index is `x + nx·(y + ny·z)`.

use glam::{IVec3, UVec3, Vec3};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeGrid {
    /// World position of probe (0, 0, 0), metres.
    pub origin_m: Vec3,
    pub probe_counts: UVec3,
    /// Distance between neighbouring probes per axis, metres.
    pub spacing_m: Vec3,
}

impl ProbeGrid {
    /// A grid of `counts` probes at the centres of `counts` equal cells spanning the
    /// box `[lo, hi]`, so no probe lies on the box's faces (which are usually walls).
    pub fn fit_to_bounds(lo: Vec3, hi: Vec3, counts: UVec3) -> Self {
        let spacing_m = ((hi - lo) / counts.as_vec3()).max(Vec3::splat(1e-4));
        Self { origin_m: lo + spacing_m * 0.5, probe_counts: counts, spacing_m }
    }

    pub fn probe_count(&self) -> usize {
        self.probe_counts.x as usize * self.probe_counts.y as usize * self.probe_counts.z as usize
    }

    pub fn probe_index(&self, coords: UVec3) -> usize {
        let c = self.probe_counts;
        coords.x as usize + c.x as usize * (coords.y as usize + c.y as usize * coords.z as usize)
    }

    pub fn probe_coords(&self, index: usize) -> UVec3 {
        let c = self.probe_counts;
        let i = index as u32;
        UVec3::new(i % c.x, (i / c.x) % c.y, i / (c.x * c.y))
    }

    /// Grid-point position of a probe (before any relocation offset).
    pub fn probe_position(&self, coords: UVec3) -> Vec3 {
        self.origin_m + self.spacing_m * coords.as_vec3()
    }

    /// The smallest axial distance between probes (seed 004 eq. 2's
    /// `minDistanceBetweenProbes`).
    pub fn min_spacing_m(&self) -> f32 {
        self.spacing_m.min_element()
    }

    /// Coordinates of the cage's lowest corner probe for `position`, clamped so that
    /// the cage lies inside the grid.
    pub fn base_probe(&self, position: Vec3) -> IVec3 {
        let rel = (position - self.origin_m) / self.spacing_m;
        let max = (self.probe_counts.as_ivec3() - IVec3::ONE).max(IVec3::ZERO);
        rel.floor().as_ivec3().clamp(IVec3::ZERO, max)
    }

    /// The cage of `position` (seed 003 §4.4): its lowest corner and the position's
    /// fraction across the cell per axis, clamped to [0, 1] so points beyond the
    /// grid take their boundary layer's values.
    pub fn cage(&self, position: Vec3) -> Cage {
        let base = self.base_probe(position);
        let base_pos = self.origin_m + self.spacing_m * base.as_vec3();
        let alpha = ((position - base_pos) / self.spacing_m).clamp(Vec3::ZERO, Vec3::ONE);
        Cage { base, alpha, max: (self.probe_counts.as_ivec3() - IVec3::ONE).max(IVec3::ZERO) }
    }
}

/// A point's 8-probe cage: corner `i` has offset bit 0 = x, bit 1 = y, bit 2 = z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cage {
    pub base: IVec3,
    /// The point's fraction across the cell per axis, in [0, 1].
    pub alpha: Vec3,
    max: IVec3,
}

impl Cage {
    /// Grid coordinates of corner `i`, clamped into the grid (a grid with one probe
    /// on an axis repeats it).
    pub fn corner(&self, i: usize) -> UVec3 {
        (self.base + corner_offset(i)).min(self.max).as_uvec3()
    }

    /// Per-axis trilinear factors of corner `i`; their product is its weight.
    pub fn trilinear(&self, i: usize) -> Vec3 {
        let o = corner_offset(i).as_vec3();
        (Vec3::ONE - self.alpha) * (Vec3::ONE - o) + self.alpha * o
    }
}

fn corner_offset(i: usize) -> IVec3 {
    IVec3::new((i & 1) as i32, ((i >> 1) & 1) as i32, ((i >> 2) & 1) as i32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_and_coords_round_trip_for_odd_counts() {
        let g = ProbeGrid { origin_m: Vec3::ZERO, probe_counts: UVec3::new(3, 5, 7), spacing_m: Vec3::ONE };
        for i in 0..g.probe_count() {
            assert_eq!(g.probe_index(g.probe_coords(i)), i);
        }
    }

    #[test]
    fn fitted_grid_puts_probes_at_cell_centres() {
        let g = ProbeGrid::fit_to_bounds(Vec3::ZERO, Vec3::new(4.0, 2.0, 1.0), UVec3::new(4, 2, 1));
        assert_eq!(g.probe_position(UVec3::ZERO), Vec3::new(0.5, 0.5, 0.5));
        assert_eq!(g.probe_position(UVec3::new(3, 1, 0)), Vec3::new(3.5, 1.5, 0.5));
        assert_eq!(g.base_probe(Vec3::new(1.7, 0.2, 0.5)), IVec3::new(1, 0, 0));
        assert_eq!(g.base_probe(Vec3::new(-5.0, 9.0, 0.5)), IVec3::new(0, 1, 0));
    }

    #[test]
    fn cage_weights_sum_to_one_and_clamp_beyond_the_grid() {
        let g =
            ProbeGrid { origin_m: Vec3::ZERO, probe_counts: UVec3::new(3, 2, 1), spacing_m: Vec3::new(2.0, 1.0, 1.0) };
        let c = g.cage(Vec3::new(1.5, 0.25, 0.0));
        assert_eq!((c.base, c.alpha), (IVec3::ZERO, Vec3::new(0.75, 0.25, 0.0)));
        let sum: f32 = (0..8).map(|i| c.trilinear(i).element_product()).sum();
        assert!((sum - 1.0).abs() < 1e-6);
        assert!((c.trilinear(1).element_product() - 0.75 * 0.75).abs() < 1e-6, "corner (1, 0, 0)");
        // One probe in z: both z corners are that probe.
        assert_eq!(c.corner(4), UVec3::new(0, 0, 0));
        // Beyond the grid: clamped onto the last layer, which takes the full weight.
        let far = g.cage(Vec3::new(9.0, 0.5, 0.0));
        assert_eq!(far.corner(1), UVec3::new(2, 0, 0));
        assert_eq!(far.alpha.x, 1.0);
    }
}
