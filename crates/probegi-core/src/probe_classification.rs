//! Probe states: two selectable schemes (`probe_states` setting).
//!
//! **jcgt** — seed 004 §6, Listing 5: Off, Sleeping, Newly Awake, Newly Vigilant,
//! Awake, Vigilant. After relocation a probe still inside geometry is Off; one
//! that sees a front face it serves is Newly Vigilant; otherwise Sleeping.
//! Sleeping probes inside a dynamic object's AABB (grown by one cell plus the
//! self-shadow bias) become Newly Awake. Newly * probes update once with
//! hysteresis 0, then become Awake / Vigilant. Only those trace and update.
//!
//! Deviation (the "serves" test): Listing 5 keeps a probe Vigilant when a front face
//! is closer than the *minimum* spacing. But a probe belongs to the cages of the
//! eight cells around it, so it serves surfaces up to one spacing away *per axis*
//! (a cell diagonal away, and more in the long axis of a non-cubic cell). On the
//! shared Sponza at 16×8×16 the minimum-spacing rule slept probes that were the only
//! lit members of cages on the upper back wall, which rendered black. Our rule is
//! per axis, in the grid's own cells: a probe stays Vigilant when a front-face hit
//! lies within `probe_classification_reach_rel` × the spacing of its grid point on
//! every axis (plus the query's surface bias; unbounded outward of the boundary
//! layers, whose cages serve everything beyond the grid) — [`probe_watches`]. With
//! the default 0.5 that box is the probe's Voronoi cell: every surface point the
//! rays find keeps its nearest grid probe, whatever the spacing per axis, and a
//! probe that sees surfaces only from the far half of its cells, where it has less
//! trilinear weight than a closer corner, sleeps. 1.0 is RTXGI's
//! `ProbeClassificationCS` rule (any front face within one spacing per axis).
//! Relocation helps the rule: a probe pushed out of a thick wall still has its grid
//! point in the wall, within half a cell of the wall's face, so it watches it.
//!
//! The Voronoi cell alone fails where a surface's nearest probes lie behind it: a
//! thick wall whose front-side probes are all more than half a cell away (on the
//! shared Sponza lit by the sun, `builtin:sponza-sun`, the upper gallery fronts
//! went dark, FLIP 0.038 against all-active). So a second pass covers every
//! surface point the rays found: if none of the probes of its cage on the
//! surface's front side is kept, the heaviest of them is ([`uncovered_point_probe`]).
//! The pass is greedy, in probe and ray order, so a probe added for one point
//! covers the points after it (deterministic; run against the first pass alone it
//! kept 6 % more of Sponza's probes for a slightly better image). It runs
//! order-free ([`cover_proposals`]): the greedy recursion as [`COVER_ITERATIONS`]
//! Jacobi rounds over every point at once, which give the greedy result once
//! the longest chain of points is shorter (24 to 30 rounds on the shared
//! Sibenik and sunlit Sponza at 32×8×32 and 32×16×32 probes, 6 to 8 at
//! 16×8×16), and a fix-up that keeps every point covered when a chain is
//! longer. A device runs it in parallel, where walking the points in order
//! took one invocation (the likely cause of an 11.5 s start-up at 32³ probes
//! on an H200, whose all-active start-up, without this round, took 1.3 s). Every seen
//! surface point then has a usable front-side cage probe, unless all of them are
//! inside geometry; sponza-sun improves to FLIP 0.027. A cage left without any
//! usable probe at all is handled by the query's fallback.
//!
//! **usage** — seed 003 §6.1, eq. 6.1–6.2: Usage(P) = Σ R(dᵢ) over a probe's
//! samples, R = 1 for a hit within the cage diagonal r, −1 for a backface, 0
//! otherwise. Every probe traces every frame and is classified from that frame's
//! rays, so the state follows the scene (a probe swallowed by a moving object
//! becomes DEAD and leaves DEAD when it is uncovered); the states only decide
//! which probes are shaded and blended:
//! - more than half of the relevant samples backfaces → DEAD: blended in the frame
//!   it becomes DEAD, then not again while it stays DEAD, and culled from queries;
//! - usage > 0 → ALIVE: blended every frame, hysteresis raised toward the maximum;
//!   it stays ALIVE for at least `probe_alive_min_frames` updates before it may
//!   fall asleep (the thesis's "minimum of frames", against flicker at the rim r);
//! - else SLEEPING: blended every `probe_sleeping_update_interval` frames,
//!   hysteresis lowered.
//!
//! A probe leaving DEAD replaces its stale history (hysteresis 0) on its first blend.
//!
//! **screen** — Timberdoodle PGI's screen-driven updates (`../shared/PEERS.md`,
//! "Sparse, screen-driven updates"), issue 32 item 4. The camera frame marks
//! the probes whose cages its pixels read
//! (`crate::ddgi_volume_blend::field_set_cage_probes`: every member that
//! weighs the pixel, the eight corners of its biased point's cage). A marked
//! probe is Requested for `probe_screen_request_frames` frames (PGI's direct
//! countdown, 63) and traces and blends every frame; the others are Idle and
//! trace and blend every `probe_screen_idle_interval_frames` frames (8, PGI's
//! 1/8), in the spatially interleaved phase of [`screen_idle_phase`], so the
//! idle rays spread evenly over the frames. A probe's blend stands for the
//! frames since its last one, capped at the idle interval: its hysteresis is
//! raised to that power (`probe_blend::hysteresis_over_frames`), so an idle
//! probe converges in wall-clock frames as fast as a requested one.
//! *Deviations:* PGI never updates an unrequested probe and requests
//! probes one bounce deep from probe-ray hits (its "indirect" countdown);
//! we update the rest at the reduced rate instead, which carries off-screen
//! light to the probes the camera reads without a second request level.
//! PGI interleaves the requested probes too (1/8 a frame); the issue asks
//! for them at full rate. Every probe traces until its first blend (or, with
//! `probe_seeding`, is read from its seed and waits for its phase), and every
//! probe is usable once blended, as under all-active. With a shadowing field
//! an Idle probe traces in its phase and the frame after, since its occlusion
//! maps blend from the surfels of the frame before.
//!
//! Queries read only probes that have been blended since they last (re)started
//! (or, under the screen scheme, seeded since):
//! Off, Sleeping (jcgt), Dead (usage) and Newly Awake / Newly Vigilant probes (not
//! yet blended in their new state) are excluded. Deviation: the thesis's
//! "logarithmic" hysteresis ramps are not specified further; we move the hysteresis
//! 10 % of the way toward its target per update (up to the volume's
//! `probe_hysteresis` for ALIVE, down to half of it for SLEEPING).

use glam::{UVec3, Vec3};
use serde::{Deserialize, Serialize};

use crate::probe_grid::ProbeGrid;

/// Which probe-state scheme a volume runs: the `probe_states` setting (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ProbeStatesMode {
    /// Every probe traces and updates every frame.
    AllActive,
    /// Seed 004's six-state machine.
    Jcgt,
    /// Seed 003's ALIVE / SLEEPING / DEAD usage classification.
    Usage,
    /// Screen-driven updates (Timberdoodle PGI's request countdowns): probes
    /// whose cages the camera frame reads trace and blend every frame for
    /// `probe_screen_request_frames` frames, the rest every
    /// `probe_screen_idle_interval_frames` frames, interleaved.
    Screen,
}

/// A probe's state: `Active` under all-active, seed 004 Listing 5's six states under
/// jcgt, seed 003 §6.1's three under usage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ProbeState {
    /// All-active: traces and updates every frame; also a new or reset probe's state
    /// until its scheme classifies it.
    Active,
    /// jcgt: inside geometry after relocation; neither traces nor updates, and queries
    /// skip it.
    Off,
    /// jcgt: serves no surface; neither traces nor updates, and queries skip it, until
    /// a dynamic object nearby wakes it.
    Sleeping,
    /// jcgt: a Sleeping probe inside a dynamic object's grown AABB; updates once with
    /// hysteresis 0, then becomes Awake.
    NewlyAwake,
    /// jcgt: just found to serve a surface; updates once with hysteresis 0, then
    /// becomes Vigilant.
    NewlyVigilant,
    /// jcgt: woken by a nearby dynamic object; traces and updates until no dynamic
    /// object is near, then sleeps again.
    Awake,
    /// jcgt: serves a surface; traces and updates every frame.
    Vigilant,
    /// usage (seed 003 §6.1, eq. 6.1–6.2): usage > 0; blended every frame, hysteresis
    /// raised toward the volume's `probe_hysteresis`.
    Alive,
    /// usage: usage ≤ 0 without a backface majority; blended every
    /// `probe_sleeping_update_interval` frames, hysteresis lowered toward half of
    /// `probe_hysteresis`.
    UsageSleeping,
    /// usage: more than half of its relevant samples are backfaces (inside geometry);
    /// culled from queries, blended only in the frame it turns DEAD.
    Dead,
    /// screen: a camera pixel read the probe's cage within the last
    /// `probe_screen_request_frames` frames; traces and blends every frame.
    Requested,
    /// screen: no camera pixel read it lately; traces and blends every
    /// `probe_screen_idle_interval_frames` frames ([`screen_idle_phase`]).
    Idle,
}

impl ProbeState {
    /// Every state, each at the index of its discriminant (`state as usize`),
    /// so a per-frame table indexed by state stands in for a match a probe.
    pub const ALL: [ProbeState; 12] = [
        Self::Active,
        Self::Off,
        Self::Sleeping,
        Self::NewlyAwake,
        Self::NewlyVigilant,
        Self::Awake,
        Self::Vigilant,
        Self::Alive,
        Self::UsageSleeping,
        Self::Dead,
        Self::Requested,
        Self::Idle,
    ];

    /// [`Self::updates_in_frame`] of every state in frame `frame`, indexed by
    /// `state as usize`: one match a state instead of one a probe.
    pub fn updates_in_frame_table(frame: u32, sleep_interval: u32) -> [bool; Self::ALL.len()] {
        Self::ALL.map(|s| s.updates_in_frame(frame, sleep_interval))
    }

    /// The state's snake-case name (`"newly_awake"`, `"usage_sleeping"`, …), the key of
    /// per-state probe counts.
    pub fn name(self) -> &'static str {
        match self {
            Self::Active => "active",
            Self::Off => "off",
            Self::Sleeping => "sleeping",
            Self::NewlyAwake => "newly_awake",
            Self::NewlyVigilant => "newly_vigilant",
            Self::Awake => "awake",
            Self::Vigilant => "vigilant",
            Self::Alive => "alive",
            Self::UsageSleeping => "usage_sleeping",
            Self::Dead => "dead",
            Self::Requested => "requested",
            Self::Idle => "idle",
        }
    }

    /// Whether queries may read this probe: not culled, and not waiting for its
    /// first blend in a new state (a Newly * probe's atlas is stale or empty).
    pub fn usable_in_queries(self) -> bool {
        !matches!(self, Self::Off | Self::Sleeping | Self::Dead | Self::NewlyAwake | Self::NewlyVigilant)
    }

    /// Whether the probe traces rays this frame: every probe but jcgt's Off and
    /// Sleeping ones (usage probes all trace: their state comes from the rays).
    pub fn traces(self) -> bool {
        !matches!(self, Self::Off | Self::Sleeping)
    }

    /// Whether the probe is shaded and blended in frame `frame` (usage scheme:
    /// SLEEPING every `sleep_interval` frames, DEAD never; a probe entering DEAD
    /// is blended by the caller once).
    pub fn updates_in_frame(self, frame: u32, sleep_interval: u32) -> bool {
        match self {
            Self::Off | Self::Sleeping | Self::Dead => false,
            Self::UsageSleeping => frame.is_multiple_of(sleep_interval.max(1)),
            _ => true,
        }
    }

    /// Newly woken probes converge with hysteresis 0 once.
    pub fn is_new(self) -> bool {
        matches!(self, Self::NewlyAwake | Self::NewlyVigilant)
    }

    /// The state after an update: Newly Awake → Awake, Newly Vigilant → Vigilant.
    pub fn after_update(self) -> Self {
        match self {
            Self::NewlyAwake => Self::Awake,
            Self::NewlyVigilant => Self::Vigilant,
            s => s,
        }
    }
}

/// The frame phase in which an Idle probe of the screen scheme updates: for
/// the probe's lattice point `cell` (whole cells from the world origin),
/// `(x + 2y + 4z) mod interval`, so with the default interval 8 every 2×2×2
/// block of probes spreads over the eight frames (PGI's interleave). A probe
/// keeps its cell while a tracking window scrolls, so it keeps its phase.
pub fn screen_idle_phase(cell: glam::IVec3, interval: u32) -> u32 {
    let k = cell.x as i64 + 2 * cell.y as i64 + 4 * cell.z as i64;
    k.rem_euclid(interval.max(1) as i64) as u32
}

/// Whether a front-face surface point at `offset_m` from a probe's grid point lies
/// in the box the probe keeps watch over: `reach_rel` × the spacing per axis, plus
/// `bias_m` (the query picks the cage at the biased point), unbounded outward of
/// the grid's first and last layers (the query clamps points beyond the grid onto
/// them). `reach_rel` 0.5 is the probe's own Voronoi box (every point's nearest
/// grid probe); 1 is every cell the probe belongs to (RTXGI's classifier).
pub fn probe_watches(grid: &ProbeGrid, coords: UVec3, offset_m: Vec3, reach_rel: f32, bias_m: f32) -> bool {
    let last = grid.probe_counts.saturating_sub(UVec3::ONE);
    (0..3).all(|axis| {
        let o = offset_m[axis];
        let outward = (coords[axis] == 0 && o < 0.0) || (coords[axis] == last[axis] && o > 0.0);
        outward || o.abs() <= reach_rel * grid.spacing_m[axis] + bias_m
    })
}

/// The second pass of the jcgt classification, for one front-face surface point
/// (`point`, `normal`: the hit triangle's plane normal, facing the ray) a
/// probe ray found: `None` when one of its cage's probes on
/// the surface's front side (probe position strictly in front of the surface's
/// plane) is already `kept`; else the front-side probe with the largest trilinear
/// weight there (the query's weights, clamped onto the boundary layers beyond the
/// grid), among those `eligible` (not Off), if any.
pub fn uncovered_point_probe(
    grid: &ProbeGrid,
    probe_positions: &[Vec3],
    kept: &[bool],
    eligible: &[bool],
    point: Vec3,
    normal: Vec3,
) -> Option<usize> {
    let cage = grid.cage(point);
    let mut best: Option<(usize, f32)> = None;
    for (i, p) in front_side_corners(grid, &cage, probe_positions, point, normal) {
        if kept[p] {
            return None;
        }
        let t = cage.trilinear(i);
        let w = t.x * t.y * t.z;
        if eligible[p] && best.is_none_or(|(_, b)| w > b) {
            best = Some((p, w));
        }
    }
    best.map(|(p, _)| p)
}

/// The corners of `cage` (the cage of `point`) whose probes lie on the
/// surface's front side, strictly in front of its plane: (corner, probe index).
fn front_side_corners<'a>(
    grid: &'a ProbeGrid,
    cage: &'a crate::probe_grid::Cage,
    probe_positions: &'a [Vec3],
    point: Vec3,
    normal: Vec3,
) -> impl Iterator<Item = (usize, usize)> + 'a {
    (0..8)
        .map(|i| (i, grid.probe_index(cage.corner(i))))
        .filter(move |&(_, p)| (probe_positions[p] - point).dot(normal) > 0.0)
}

/// The cage probes of a surface point that lie on the surface's front side
/// (strictly in front of its plane), as [`uncovered_point_probe`] reads them:
/// their indices and how many there are.
pub fn front_side_cage_probes(
    grid: &ProbeGrid,
    probe_positions: &[Vec3],
    point: Vec3,
    normal: Vec3,
) -> ([u32; 8], usize) {
    let cage = grid.cage(point);
    let mut front = [0u32; 8];
    let mut count = 0;
    for (_, p) in front_side_corners(grid, &cage, probe_positions, point, normal) {
        front[count] = p as u32;
        count += 1;
    }
    (front, count)
}

/// One surface point the covering pass must serve: the first pass kept none of
/// its front-side cage probes. `ray` is its ray in the batch (the greedy order),
/// `probe` the heaviest eligible front-side probe ([`uncovered_point_probe`]
/// over the first pass's kept flags), `front` / `front_count` its front-side
/// cage probes ([`front_side_cage_probes`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoverProposal {
    /// The point's ray in the batch: greedy order.
    pub ray: u32,
    /// The probe it would keep.
    pub probe: u32,
    /// Its front-side cage probes (the first `front_count`).
    pub front: [u32; 8],
    /// How many of `front` are set.
    pub front_count: usize,
}

/// Jacobi rounds of [`cover_proposals`]: the greedy pass's dependency chains
/// longer than this end in the fix-up (measured on the shared scenes at
/// 32 rays a probe: see the round's module docs).
pub const COVER_ITERATIONS: u32 = 32;

/// The covering pass, order-free: which probes the points of `proposals` keep
/// on top of `kept_first` (the first pass; one flag a probe of the volume).
///
/// The greedy pass in ray order keeps point i's proposal exactly when no
/// earlier point that kept its own proposal kept one of i's front-side probes.
/// Here that recursion runs as Jacobi rounds over every point at once, each
/// round a minimum per probe ("the first ray that keeps this probe"), so a
/// device runs it with one atomic minimum per point and both backends agree
/// bit for bit. After `iterations` rounds (the chains of the shared scenes are
/// shorter: the result is then the greedy pass's) a fix-up keeps the proposal
/// of any point still uncovered, so every point is served whatever the count.
/// Returns the kept flags, the first pass's included.
pub fn cover_proposals(kept_first: &[bool], proposals: &[CoverProposal], iterations: u32) -> Vec<bool> {
    let n = kept_first.len();
    // First round: every point keeps its proposal.
    let mut first_keeper = vec![u32::MAX; n];
    for c in proposals {
        first_keeper[c.probe as usize] = first_keeper[c.probe as usize].min(c.ray);
    }
    let mut next = vec![u32::MAX; n];
    for _ in 0..iterations {
        next.fill(u32::MAX);
        for c in proposals {
            let covered = c.front[..c.front_count].iter().any(|&p| first_keeper[p as usize] < c.ray);
            if !covered {
                next[c.probe as usize] = next[c.probe as usize].min(c.ray);
            }
        }
        if next == first_keeper {
            break;
        }
        std::mem::swap(&mut first_keeper, &mut next);
    }
    let kept: Vec<bool> = (0..n).map(|p| kept_first[p] || first_keeper[p] != u32::MAX).collect();
    // Fix-up: a point a cut-short chain left uncovered keeps its proposal.
    let mut out = kept.clone();
    for c in proposals {
        if !c.front[..c.front_count].iter().any(|&p| kept[p as usize]) {
            out[c.probe as usize] = true;
        }
    }
    out
}

/// One probe as the classification round sees it, for a backend that runs the
/// round elsewhere (the GPU's `probe_classification` pass).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClassificationProbe {
    /// Its first ray in the round's batch, when it traced in it.
    pub first_ray: Option<u32>,
    /// Waiting for initialisation: the round classifies it.
    pub pending: bool,
    /// Its current state traces (a probe not pending that does counts as covering).
    pub traces: bool,
    /// Position with its relocation offset (m).
    pub position_m: Vec3,
}

/// Seed 004 Listing 5's initial classification from the post-relocation trace:
/// inside geometry (Listing 4's backface test) → Off; watching some front-face
/// point ([`probe_watches`] over its front-face hits), or chosen by the covering
/// pass ([`uncovered_point_probe`]) → Newly Vigilant; else Sleeping.
pub fn classify_jcgt(inside_geometry: bool, serves_a_surface: bool) -> ProbeState {
    if inside_geometry {
        ProbeState::Off
    } else if serves_a_surface {
        ProbeState::NewlyVigilant
    } else {
        ProbeState::Sleeping
    }
}

/// Whether `point` lies in the box `[lo, hi]` grown by `grow` on every side.
pub fn inside_grown_aabb(point: Vec3, lo: Vec3, hi: Vec3, grow: Vec3) -> bool {
    point.cmpge(lo - grow).all() && point.cmple(hi + grow).all()
}

/// (usage, relevant samples, backfaces) of one probe: [`probe_usage`]'s answer.
pub type ProbeUsageCounts = (i32, u32, u32);

/// Seed 003 eq. 6.1–6.2 over one probe's signed distances (negative = backface,
/// infinite = miss) with cage diagonal `r`: (usage, relevant samples, backfaces).
pub fn probe_usage(signed_distance: impl IntoIterator<Item = f32>, cage_diagonal_m: f32) -> ProbeUsageCounts {
    let (mut usage, mut relevant, mut backfaces) = (0i32, 0u32, 0u32);
    for d in signed_distance {
        if d < 0.0 {
            usage -= 1;
            relevant += 1;
            backfaces += 1;
        } else if d <= cage_diagonal_m {
            usage += 1;
            relevant += 1;
        }
    }
    (usage, relevant, backfaces)
}

/// Seed 003 §6.1.1 state from a probe's usage counts.
pub fn classify_usage(usage: i32, relevant: u32, backfaces: u32) -> ProbeState {
    if relevant > 0 && backfaces * 2 > relevant {
        ProbeState::Dead
    } else if usage > 0 {
        ProbeState::Alive
    } else {
        ProbeState::UsageSleeping
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_lists_every_state_once_at_its_discriminant() {
        // A match without a wildcard: a new state fails to compile here until
        // it is added to `ProbeState::ALL` (and this list).
        let listed = |s: ProbeState| match s {
            ProbeState::Active
            | ProbeState::Off
            | ProbeState::Sleeping
            | ProbeState::NewlyAwake
            | ProbeState::NewlyVigilant
            | ProbeState::Awake
            | ProbeState::Vigilant
            | ProbeState::Alive
            | ProbeState::UsageSleeping
            | ProbeState::Dead
            | ProbeState::Requested
            | ProbeState::Idle => true,
        };
        for (i, s) in ProbeState::ALL.into_iter().enumerate() {
            assert!(listed(s));
            assert_eq!(s as usize, i, "{s:?}");
        }
        let names: std::collections::BTreeSet<_> = ProbeState::ALL.iter().map(|s| s.name()).collect();
        assert_eq!(names.len(), ProbeState::ALL.len());
    }

    #[test]
    fn jcgt_classification_keeps_probes_that_watch_a_surface_per_axis() {
        // Cells 4 × 1 × 1 m: a probe watches 2 m in x and 0.5 m in y and z (plus bias).
        let grid = ProbeGrid::new(Vec3::ZERO, UVec3::splat(3), Vec3::new(4.0, 1.0, 1.0));
        let inner = UVec3::ONE;
        let watches = |o: Vec3| probe_watches(&grid, inner, o, 0.5, 0.1);
        // 1.9 m away in x: beyond the minimum spacing (Listing 5 would sleep the probe),
        // yet it is the nearest grid probe of that point.
        assert!(watches(Vec3::new(1.9, 0.3, -0.5)));
        assert!(!watches(Vec3::new(2.2, 0.0, 0.0)) && !watches(Vec3::new(0.0, 0.7, 0.0)));
        assert!(probe_watches(&grid, inner, Vec3::new(3.9, 0.9, 0.9), 1.0, 0.0), "reach 1: RTXGI's rule");
        // The bottom layer watches everything below the grid, not above its reach.
        let bottom = UVec3::new(1, 0, 1);
        assert!(probe_watches(&grid, bottom, Vec3::new(0.0, -7.0, 0.0), 0.5, 0.0));
        assert!(!probe_watches(&grid, bottom, Vec3::new(0.0, 0.6, 0.0), 0.5, 0.0));
        // Covering pass: a wall facing −x at x = 3.4 in the cell of probes x = 0 and
        // x = 1 (4 m apart). The x = 0 probes, 3.4 m in front, watch nothing; the
        // x = 1 probes are behind the wall. The heaviest front-side corner is added.
        let positions: Vec<Vec3> = (0..27).map(|p| grid.probe_position(grid.probe_coords(p))).collect();
        let (point, n) = (Vec3::new(3.4, 1.3, 1.0), Vec3::NEG_X);
        let none = vec![false; 27];
        let all = vec![true; 27];
        let front = uncovered_point_probe(&grid, &positions, &none, &all, point, n).expect("a front-side probe");
        assert_eq!(grid.probe_coords(front), UVec3::new(0, 1, 1), "the nearest front-side corner");
        let mut kept = none.clone();
        kept[grid.probe_index(UVec3::new(0, 2, 1))] = true;
        assert_eq!(uncovered_point_probe(&grid, &positions, &kept, &all, point, n), None, "already covered");
        kept = none.clone();
        kept[grid.probe_index(UVec3::new(1, 1, 1))] = true;
        assert!(
            uncovered_point_probe(&grid, &positions, &kept, &all, point, n).is_some(),
            "a probe behind does not cover"
        );
        assert_eq!(uncovered_point_probe(&grid, &positions, &none, &none, point, n), None, "Off probes are not chosen");
        assert_eq!(classify_jcgt(true, true), ProbeState::Off);
        assert_eq!(classify_jcgt(false, true), ProbeState::NewlyVigilant);
        assert_eq!(classify_jcgt(false, false), ProbeState::Sleeping);
        assert_eq!(ProbeState::NewlyVigilant.after_update(), ProbeState::Vigilant);
        assert!(!ProbeState::Off.usable_in_queries() && ProbeState::Vigilant.usable_in_queries());
        assert!(!ProbeState::NewlyAwake.usable_in_queries() && !ProbeState::NewlyVigilant.usable_in_queries());
    }

    /// The greedy covering pass as the module docs state it: points in ray order, each
    /// keeps its proposal unless a front-side probe is kept already.
    fn greedy_cover(kept_first: &[bool], proposals: &[CoverProposal]) -> Vec<bool> {
        let mut kept = kept_first.to_vec();
        let mut order: Vec<&CoverProposal> = proposals.iter().collect();
        order.sort_by_key(|c| c.ray);
        for c in order {
            if !c.front[..c.front_count].iter().any(|&p| kept[p as usize]) {
                kept[c.probe as usize] = true;
            }
        }
        kept
    }

    #[test]
    fn the_order_free_covering_pass_is_the_greedy_pass_and_always_covers() {
        let mut rng = crate::rng::Pcg32::new(7, 3);
        let mut below = |n: u32| (rng.next_f32() * n as f32) as u32 % n;
        for case in 0..200 {
            let probes = 6 + below(30) as usize;
            // Probes 0 and 1 were kept by the first pass; no proposal sees them.
            let kept_first: Vec<bool> = (0..probes).map(|p| p < 2).collect();
            let count = 1 + below(60) as usize;
            let mut rays: Vec<u32> = (0..count as u32 * 3).collect();
            let proposals: Vec<CoverProposal> = (0..count)
                .map(|_| {
                    let ray = rays.swap_remove(below(rays.len() as u32) as usize);
                    let front_count = 1 + below(8) as usize;
                    let mut front = [0u32; 8];
                    for f in front.iter_mut().take(front_count) {
                        *f = 2 + below(probes as u32 - 2);
                    }
                    let probe = front[below(front_count as u32) as usize];
                    CoverProposal { ray, probe, front, front_count }
                })
                .collect();
            let covered =
                |kept: &[bool]| proposals.iter().all(|c| c.front[..c.front_count].iter().any(|&p| kept[p as usize]));
            let greedy = greedy_cover(&kept_first, &proposals);
            assert_eq!(cover_proposals(&kept_first, &proposals, 1000), greedy, "case {case}: converged rounds");
            for rounds in 0..4 {
                let kept = cover_proposals(&kept_first, &proposals, rounds);
                assert!(covered(&kept), "case {case}: {rounds} rounds leave a point uncovered");
                assert!(kept[0] && kept[1], "case {case}: the first pass's probes stay kept");
            }
        }
        // A chain in ray order: a (ray 0) keeps probe 2, which covers b (ray 1);
        // c (ray 2) sees only probe 4 and b's proposal 3: greedy keeps 2 and 4.
        let mk = |ray, probe, f: &[u32]| {
            let mut front = [0u32; 8];
            front[..f.len()].copy_from_slice(f);
            CoverProposal { ray, probe, front, front_count: f.len() }
        };
        let chain = [mk(2, 4, &[3, 4]), mk(0, 2, &[2]), mk(1, 3, &[2, 3])];
        let first = vec![false; 5];
        assert_eq!(greedy_cover(&first, &chain), vec![false, false, true, false, true]);
        assert_eq!(cover_proposals(&first, &chain, COVER_ITERATIONS), greedy_cover(&first, &chain));
        // No round: every proposal is kept. One round: b and c see the first
        // round's keepers 2 and 3 and drop theirs; the fix-up gives c back its 4.
        assert_eq!(cover_proposals(&first, &chain, 0), vec![false, false, true, true, true]);
        assert_eq!(cover_proposals(&first, &chain, 1), vec![false, false, true, false, true]);
    }

    #[test]
    fn usage_counts_follow_eq_6_2() {
        let d = [0.5, 1.5, -0.2, f32::INFINITY, 0.9];
        assert_eq!(probe_usage(d, 1.0), (1, 3, 1));
        assert_eq!(classify_usage(1, 3, 1), ProbeState::Alive);
        assert_eq!(classify_usage(0, 0, 0), ProbeState::UsageSleeping);
        assert_eq!(classify_usage(-3, 4, 3), ProbeState::Dead);
        assert!(ProbeState::UsageSleeping.updates_in_frame(20, 10));
        for (frame, interval) in [(20, 10), (21, 10), (0, 0), (7, 1)] {
            let table = ProbeState::updates_in_frame_table(frame, interval);
            for s in ProbeState::ALL {
                assert_eq!(table[s as usize], s.updates_in_frame(frame, interval), "{s:?} in frame {frame}");
            }
        }
        assert!(!ProbeState::UsageSleeping.updates_in_frame(21, 10));
        assert!(ProbeState::UsageSleeping.traces() && ProbeState::Dead.traces());
        assert!(!ProbeState::Dead.updates_in_frame(20, 10));
    }
}
