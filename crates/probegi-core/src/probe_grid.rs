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
}
