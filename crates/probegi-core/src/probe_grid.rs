//! The uniform probe grid of a DDGI volume (seed 003 §4.1): any probe count per
//! axis (not only powers of two), per-axis spacing. Logical probe `(x, y, z)` sits
//! at `origin + spacing · (x, y, z)`.
//!
//! Storage is a circular buffer (seed 004 §7.3, Fig. 10; RTXGI's
//! `probeScrollOffsets`): logical coordinates `c` are stored at
//! `s = (c + probe_scroll_offsets) mod counts`, linear index `sx + nx·(sy + ny·sz)`.
//! A tracking window that moves by whole cells ([`ProbeGrid::scroll`]) changes the
//! origin and the offsets only, so the probes that stay keep their storage slot
//! (their atlas tile, state and offset) and no atlas data is copied. Every index
//! goes through [`ProbeGrid::probe_index`] / [`ProbeGrid::probe_coords`], which are
//! inverses, so code that loops over storage slots and asks for their logical
//! coordinates is correct for any phase.

use glam::{IVec3, UVec3, Vec3};

/// A DDGI volume's uniform probe grid: logical probe `(x, y, z)` at
/// `origin_m + spacing_m · (x, y, z)`, stored circularly (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeGrid {
    /// World position of probe (0, 0, 0), metres.
    pub origin_m: Vec3,
    /// Probes per axis (any count, not only powers of two).
    pub probe_counts: UVec3,
    /// Distance between neighbouring probes per axis, metres.
    pub spacing_m: Vec3,
    /// Circular-buffer phase per axis, each in `[0, count)`; zero for a grid that never moved.
    pub probe_scroll_offsets: UVec3,
}

impl ProbeGrid {
    /// A grid that has not scrolled.
    pub fn new(origin_m: Vec3, probe_counts: UVec3, spacing_m: Vec3) -> Self {
        Self { origin_m, probe_counts, spacing_m, probe_scroll_offsets: UVec3::ZERO }
    }

    /// Moves the grid by `cells` whole cells per axis: the origin moves and the
    /// storage phase follows, so logical probes that remain in the window keep
    /// their slot. The slots of probes that left now hold the planes that entered
    /// ([`ProbeGrid::scrolled_in`]), whose data the caller must reset.
    pub fn scroll(&mut self, cells: IVec3) {
        self.origin_m += self.spacing_m * cells.as_vec3();
        let n = self.probe_counts.as_ivec3();
        self.probe_scroll_offsets = (self.probe_scroll_offsets.as_ivec3() + cells).rem_euclid(n).as_uvec3();
    }

    /// Whether logical probe `coords` of this grid, just moved by `cells`, entered
    /// the window with that move (its slot holds a probe that left).
    pub fn scrolled_in(&self, cells: IVec3, coords: UVec3) -> bool {
        let n = self.probe_counts.as_ivec3();
        let c = coords.as_ivec3();
        (0..3).any(|a| {
            let k = cells[a];
            if k.abs() >= n[a] {
                true
            } else if k > 0 {
                c[a] >= n[a] - k
            } else {
                c[a] < -k
            }
        })
    }

    /// A grid of `counts` probes at the centres of `counts` equal cells spanning the
    /// box `[lo, hi]`, so no probe lies on the box's faces (which are usually walls).
    pub fn fit_to_bounds(lo: Vec3, hi: Vec3, counts: UVec3) -> Self {
        let spacing_m = ((hi - lo) / counts.as_vec3()).max(Vec3::splat(1e-4));
        Self::new(lo + spacing_m * 0.5, counts, spacing_m)
    }

    /// Total number of probes: the product of `probe_counts`.
    pub fn probe_count(&self) -> usize {
        self.probe_counts.x as usize * self.probe_counts.y as usize * self.probe_counts.z as usize
    }

    /// Storage index of logical probe `coords` (each coordinate below its count).
    pub fn probe_index(&self, coords: UVec3) -> usize {
        let c = self.probe_counts;
        let wrap = |v: u32, n: u32| if v >= n { v - n } else { v };
        let s = coords + self.probe_scroll_offsets;
        let s = UVec3::new(wrap(s.x, c.x), wrap(s.y, c.y), wrap(s.z, c.z));
        s.x as usize + c.x as usize * (s.y as usize + c.y as usize * s.z as usize)
    }

    /// Logical coordinates of the probe in storage slot `index`.
    pub fn probe_coords(&self, index: usize) -> UVec3 {
        let c = self.probe_counts;
        let i = index as u32;
        let s = UVec3::new(i % c.x, (i / c.x) % c.y, i / (c.x * c.y));
        let unwrap = |v: u32, o: u32, n: u32| if v >= o { v - o } else { v + n - o };
        let o = self.probe_scroll_offsets;
        UVec3::new(unwrap(s.x, o.x, c.x), unwrap(s.y, o.y, c.y), unwrap(s.z, o.z, c.z))
    }

    /// World position of the middle of the probe box.
    pub fn centre_m(&self) -> Vec3 {
        self.origin_m + self.spacing_m * (self.probe_counts.as_vec3() - Vec3::ONE) * 0.5
    }

    /// Cells a tracking window must move so that `target_m` stays within one cell
    /// of its centre on every axis (seed 004 §7.3: a new plane spawns when the
    /// target is farther from the centre than one probe spacing). Zero while it is.
    pub fn tracking_scroll_cells(&self, target_m: Vec3) -> IVec3 {
        let d = (target_m - self.centre_m()) / self.spacing_m;
        // A move of a whole window or more resets every probe alike: clamp there, so
        // far jumps cannot overflow the phase arithmetic.
        let step = |d: f32, n: u32| {
            let n = n as f32;
            if d.abs() > 1.0 { d.trunc().clamp(-n, n) as i32 } else { 0 }
        };
        let c = self.probe_counts;
        IVec3::new(step(d.x, c.x), step(d.y, c.y), step(d.z, c.z))
    }

    /// The point a tracking window of this grid's counts and spacing should
    /// centre on to follow `target_m` without leaving `bounds` (`[lo, hi]`).
    /// Per axis, `target_m` is clamped so that the probe box, on this grid's
    /// lattice (whole cells from `origin_m`), keeps its outer planes at least
    /// half a cell inside the bounds. Where no lattice position does (the box
    /// is larger than that, or a lattice fixed by `probe_origin_m` has no slot
    /// in a range narrower than a cell), the bounds' centre is returned.
    ///
    /// The half cell: a scene's bounds touch its outermost surfaces, so a plane
    /// on them (or just beyond, after the lattice snap) puts probes on or
    /// behind the outer walls, where they see both sides and leak the sunlit
    /// outside into the rooms within. Fitted grids keep the same margin
    /// ([`Self::fit_to_bounds`]).
    pub fn tracking_target_within(&self, target_m: Vec3, bounds: [Vec3; 2]) -> Vec3 {
        let s = self.spacing_m;
        let half = s * (self.probe_counts.as_vec3() - Vec3::ONE) * 0.5;
        let [lo, hi] = bounds;
        let anchor = self.origin_m;
        // The lowest and highest lattice origins whose box lies within the bounds
        // shrunk by half a cell. The quotients are often whole numbers up to
        // rounding (the origin drifts by whole cells as the window scrolls), so
        // a thousandth of a cell decides for the nearer whole one.
        const WHOLE_CELL_TOLERANCE: f32 = 1e-3;
        let first = anchor + ((lo + s * 0.5 - anchor) / s - WHOLE_CELL_TOLERANCE).ceil() * s;
        let last = anchor + ((hi - s * 0.5 - half * 2.0 - anchor) / s + WHOLE_CELL_TOLERANCE).floor() * s;
        let (min, max) = (first + half, last + half);
        let centre = (lo + hi) * 0.5;
        Vec3::select(min.cmple(max), target_m.clamp(min.min(max), max.max(min)), centre)
    }

    /// The lattice anchor of a tracking window of `counts` probes `spacing_m`
    /// apart held inside `bounds` (`[lo, hi]`), unless `origin_m` fixes the
    /// lattice. Per axis: where the probe box fits within the bounds less half a
    /// cell at each end, planes at the centres of whole cells from `lo`, as a
    /// fitted grid's are; where it does not (the window then sits still at the
    /// bounds' centre), the lattice that centres it on them exactly.
    pub fn tracking_anchor(origin_m: Option<Vec3>, bounds: Option<[Vec3; 2]>, counts: UVec3, spacing_m: Vec3) -> Vec3 {
        match (origin_m, bounds) {
            (Some(o), _) => o,
            (None, Some([lo, hi])) => {
                let extent = spacing_m * (counts.as_vec3() - Vec3::ONE);
                let fits = extent.cmple(hi - lo - spacing_m);
                Vec3::select(fits, lo + spacing_m * 0.5, (lo + hi - extent) * 0.5)
            }
            (None, None) => Vec3::ZERO,
        }
    }

    /// A grid of `counts` probes `spacing_m` apart, centred on `target_m` and
    /// snapped to the lattice of whole cells from `anchor_m` (so windows that start
    /// anywhere land on the same world lattice, and, anchored alike, nested
    /// cascades whose spacings are multiples of each other share probe planes;
    /// windows held inside bounds are anchored per spacing,
    /// [`Self::tracking_anchor`], and do not).
    pub fn centred_on(target_m: Vec3, anchor_m: Vec3, counts: UVec3, spacing_m: Vec3) -> Self {
        let half = spacing_m * (counts.as_vec3() - Vec3::ONE) * 0.5;
        let cell = ((target_m - half - anchor_m) / spacing_m).round();
        Self::new(anchor_m + cell * spacing_m, counts, spacing_m)
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
    /// Grid coordinates of the cage's lowest corner probe (corner 0), clamped into the
    /// grid.
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
        let mut g = ProbeGrid::new(Vec3::ZERO, UVec3::new(3, 5, 7), Vec3::ONE);
        for i in 0..g.probe_count() {
            assert_eq!(g.probe_index(g.probe_coords(i)), i);
        }
        // Any phase: still inverses, and a probe that stays keeps its slot.
        let before = g;
        g.scroll(IVec3::new(1, -2, 9));
        assert_eq!(g.probe_scroll_offsets, UVec3::new(1, 3, 2));
        for i in 0..g.probe_count() {
            assert_eq!(g.probe_index(g.probe_coords(i)), i);
            let c = g.probe_coords(i);
            let world = g.probe_position(c);
            let stayed = !g.scrolled_in(IVec3::new(1, -2, 9), c);
            // z moved by 9 ≥ 7: the whole window is new.
            assert!(!stayed);
            let _ = (world, before);
        }
        let mut h = ProbeGrid::new(Vec3::ZERO, UVec3::new(4, 3, 2), Vec3::new(1.0, 2.0, 0.5));
        let old = h;
        h.scroll(IVec3::new(1, -1, 0));
        let mut kept = 0;
        for i in 0..h.probe_count() {
            let c = h.probe_coords(i);
            if h.scrolled_in(IVec3::new(1, -1, 0), c) {
                continue;
            }
            kept += 1;
            // The same world position was stored in the same slot before the move.
            let old_c = old.probe_coords(i);
            assert_eq!(old.probe_position(old_c), h.probe_position(c), "slot {i}");
        }
        assert_eq!(kept, 3 * 2 * 2, "x loses one plane, y one plane");
    }

    #[test]
    fn tracking_moves_in_whole_cells_once_the_target_is_a_cell_off_centre() {
        let g = ProbeGrid::centred_on(Vec3::new(10.3, 0.0, -4.0), Vec3::ZERO, UVec3::splat(5), Vec3::splat(2.0));
        assert_eq!(g.origin_m, Vec3::new(6.0, -4.0, -8.0));
        assert_eq!(g.tracking_scroll_cells(Vec3::new(11.9, 0.0, -4.0)), IVec3::ZERO);
        assert_eq!(g.tracking_scroll_cells(Vec3::new(12.5, 0.0, -4.0)), IVec3::new(1, 0, 0));
        assert_eq!(g.tracking_scroll_cells(Vec3::new(3.0, 0.0, 3.0)), IVec3::new(-3, 0, 3));
        assert_eq!(g.tracking_scroll_cells(Vec3::new(-1e30, 0.0, 1e12)), IVec3::new(-5, 0, 5), "clamped");
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
    fn a_tracking_target_is_held_inside_the_bounds_or_at_their_centre() {
        // 5 probes 1 m apart per axis: a box 4 m across, half 2 m; on the
        // lattice of whole metres.
        let g = ProbeGrid::new(Vec3::ZERO, UVec3::new(5, 5, 9), Vec3::ONE);
        let bounds = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(10.0, 3.0, 20.0)];
        // x: the outer planes at least half a cell inside, on the lattice: box
        // origins in [1, 5], targets in [3, 7]; y: the box (4 m) is larger than
        // the bounds (3 m): their centre; z: half 4 m, origins in [1, 11].
        let t = g.tracking_target_within(Vec3::new(5.0, 9.0, -3.0), bounds);
        assert_eq!(t, Vec3::new(5.0, 1.5, 5.0));
        assert_eq!(g.tracking_target_within(Vec3::new(9.5, 0.0, 30.0), bounds), Vec3::new(7.0, 1.5, 15.0));
        // On a lattice anchored half a cell inside the bounds (a fitted grid's
        // planes), the first plane lands exactly there.
        let anchor = ProbeGrid::tracking_anchor(None, Some(bounds), UVec3::new(5, 5, 9), Vec3::ONE);
        // y: the box (4 m) does not fit the 3 m bounds: centred on them exactly.
        assert_eq!(anchor, Vec3::new(0.5, -0.5, 0.5));
        let g = ProbeGrid::new(anchor, UVec3::new(5, 5, 9), Vec3::ONE);
        let t = g.tracking_target_within(Vec3::new(-4.0, 9.0, 30.0), bounds);
        let placed = ProbeGrid::centred_on(t, anchor, g.probe_counts, g.spacing_m);
        assert_eq!(placed.origin_m.x, 0.5, "first plane half a cell inside lo");
        assert_eq!(placed.origin_m.z + 8.0, 19.5, "last plane half a cell inside hi");
        assert_eq!(placed.origin_m.y, -0.5, "the box centred on the bounds: [-0.5, 3.5]");
    }

    #[test]
    fn a_window_scrolled_by_whole_cells_keeps_the_same_clamped_range() {
        // A spacing and bounds that are not whole numbers: the origin drifts by
        // rounding as the window scrolls, and the range it may take must not.
        let (counts, s) = (UVec3::new(12, 6, 12), Vec3::splat(0.3));
        let bounds = [Vec3::new(-17.0, -0.9, -7.8), Vec3::new(17.3, 15.65, 7.8)];
        let anchor = ProbeGrid::tracking_anchor(None, Some(bounds), counts, s);
        let g = ProbeGrid::new(anchor, counts, s);
        let far = Vec3::new(1e3, 1e3, 1e3);
        let near = Vec3::splat(-1e3);
        let mut moved = g;
        for _ in 0..37 {
            moved.scroll(IVec3::new(1, 1, 1));
        }
        for target in [far, near] {
            let (a, b) = (g.tracking_target_within(target, bounds), moved.tracking_target_within(target, bounds));
            assert!((a - b).abs().max_element() < 1e-3, "{a} vs {b}");
            let placed = ProbeGrid::centred_on(a, anchor, counts, s);
            let (lo, hi) = (placed.origin_m, placed.origin_m + s * (counts.as_vec3() - Vec3::ONE));
            assert!(lo.cmpge(bounds[0] + s * 0.5 - 1e-4).all() && hi.cmple(bounds[1] - s * 0.5 + 1e-4).all());
            // Pressed against a face: its outer plane within a cell of half a cell inside.
            let gap = if target == far { bounds[1] - hi } else { lo - bounds[0] };
            assert!(gap.cmplt(s * 1.5).all(), "{gap}");
        }
    }

    #[test]
    fn cage_weights_sum_to_one_and_clamp_beyond_the_grid() {
        let g = ProbeGrid::new(Vec3::ZERO, UVec3::new(3, 2, 1), Vec3::new(2.0, 1.0, 1.0));
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
