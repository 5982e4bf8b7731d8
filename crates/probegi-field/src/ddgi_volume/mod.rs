//! One DDGI volume on the CPU: the persistent field (grid, atlases, relocation
//! offsets, probe states, hysteresis) and the volume's share of each seam step
//! (`ddgi_field_set` drives them for every volume of a set):
//!
//! - `plan_init_round` / `accept_init_round`: initialisation (seed 004 Listing 5,
//!   first step) as distance-only rounds against the static geometry:
//!   `probe_relocation_iterations` rounds of the position optimizer
//!   (`probegi_core::probe_relocation`), then with jcgt states one classification
//!   round (`probegi_core::probe_classification`). It runs for every probe when
//!   the volume is created, and for the planes a tracking window scrolls in;
//! - `plan_update`: the frame's rays (`probe_ray_gen`) for the probes whose state
//!   traces (jcgt: not Off or Sleeping; usage: all);
//! - `accept_update_hits`: the usage scheme classifies every probe from the
//!   frame's hits (seed 003 §6.1); marks the rays whose radiance the blend needs;
//! - `blend_inputs` (once per batch): the backface rule (zero radiance, distance
//!   −0.2·t, seed 004 §4.1); `blend_results`: blend (`probegi_core::probe_blend`, hysteresis with Listing 3's
//!   thresholds and the scene-event reductions) and border
//!   (`probegi_core::probe_border`), only for probes that update this frame;
//! - `scroll_to`: a tracking window's whole-cell move over the circular buffer.
//!
//! A probe's first update (and a Newly Awake / Newly Vigilant probe's, and a
//! scrolled-in probe's) replaces its history, i.e. blends with hysteresis 0; until
//! then queries skip it, so no stale or empty probe is ever read.

use std::collections::BTreeMap;

use glam::{IVec3, UVec3, Vec2, Vec3};
use probegi_core::ddgi_query::{DdgiFieldView, max_surface_bias_m, nearest_usable_probes};
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::probe_atlas::ProbeAtlas;
use probegi_core::probe_blend::{TexelThresholds, blend_distance_tile, blend_irradiance_tile};
use probegi_core::probe_border::update_tile_border;
use probegi_core::probe_classification::{
    ClassificationProbe, ProbeState, classify_jcgt, classify_usage, inside_grown_aabb, probe_usage, probe_watches,
    uncovered_point_probe,
};
use probegi_core::probe_grid::ProbeGrid;
use probegi_core::probe_relocation::{is_inside_geometry, probe_ray_stats, relocation_step};
use probegi_core::rng::hash_combine;
use rayon::prelude::*;

use crate::device_plans::{DeviceClassification, DeviceRelocationProbe, DeviceVolumeBlend};
use crate::probe_ray_gen::{ProbeRayDirections, generate_probe_rays, probe_ray_directions};
use crate::seam::{ProbeRayBatch, ProbeRayHit};

/// Scene changes the application reports so the field reacts faster (seed 004 §4.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneEvent {
    /// E.g. a flashlight turns on: irradiance hysteresis −15 % for 4 frames.
    SmallLightChange,
    /// E.g. an abrupt time-of-day change: irradiance hysteresis −50 % for 10 frames.
    LargeLightChange,
    /// E.g. a ceiling caves in: irradiance −50 % for 10 frames, visibility −50 % for 7.
    LargeObjectChange,
}

/// A temporary hysteresis reduction: multiply by `scale` for `frames_left` more updates.
#[derive(Clone, Copy, Debug)]
struct HysteresisReduction {
    scale: f32,
    frames_left: u32,
}

/// The persistent state of one volume. Per-frame scratch (ray directions, blend
/// weights, which probes trace and update) lives in [`VolumeFrame`].
#[derive(Clone, Debug)]
pub struct DdgiVolume {
    pub grid: ProbeGrid,
    pub settings: DdgiVolumeSettings,
    /// Encoded mean radiance per texel (see `probegi_core::irradiance_encoding`).
    pub irradiance: ProbeAtlas<Vec3>,
    /// (mean distance, mean squared distance) per texel.
    pub distance: ProbeAtlas<Vec2>,
    /// Probe positions including relocation offsets, per storage slot.
    pub probe_positions: Vec<Vec3>,
    pub probe_offsets: Vec<Vec3>,
    pub probe_states: Vec<ProbeState>,
    pub frames_updated: u32,
    /// Probes that scrolled into the window, summed over the volume's life.
    pub probes_scrolled_in: u64,
    /// The volume's index in its set: decorrelates ray rotations and shading
    /// streams between volumes (0 keeps a lone volume's streams).
    pub(crate) stream: u64,
    probe_hysteresis: Vec<f32>,
    probe_usable: Vec<bool>,
    /// Per probe, the nearest usable probe (the query's fallback for empty cages).
    probe_fallback: Vec<u32>,
    /// False until the probe's first blend, and again when its history is stale
    /// (leaving DEAD, scrolled in): the next blend then replaces the history.
    probe_has_history: Vec<bool>,
    /// Usage scheme: consecutive frames the probe has been ALIVE.
    probe_alive_frames: Vec<u32>,
    /// Probes waiting for initialisation (relocation, classification).
    probe_pending_init: Vec<bool>,
    initialized: bool,
    irradiance_events: Vec<HysteresisReduction>,
    visibility_events: Vec<HysteresisReduction>,
    traced_probes_last: usize,
    active_probes_last: usize,
    /// Probes whose tiles were cleared since the last blend (a device that holds
    /// the atlases clears its copies before its next blend).
    probes_reset_since_blend: Vec<u32>,
}

/// One volume's per-frame scratch.
#[derive(Clone, Debug, Default)]
pub struct VolumeFrame {
    /// The frame's update directions and blend weights.
    pub rays: ProbeRayDirections,
    /// The current initialisation round's directions.
    pub init_dirs: Vec<Vec3>,
    /// Probes that trace this frame.
    pub tracing: Vec<bool>,
    /// Probes that are shaded and blended this frame.
    pub active: Vec<bool>,
    /// Per probe, its first ray in the current batch (`u32::MAX`: none).
    pub first_ray: Vec<u32>,
    /// Rays per probe when the batch was planned.
    pub ray_count: usize,
}

/// What an initialisation round of a volume does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum InitRound {
    Relocation(u32),
    Classification,
}

/// Pseudo-frames for initialisation rounds, far from real ones, so their
/// directions differ from frame 0's.
fn init_frame(round: InitRound) -> u32 {
    match round {
        InitRound::Relocation(i) => u32::MAX - i,
        InitRound::Classification => u32::MAX - 1000,
    }
}

impl DdgiVolume {
    /// A volume over `scene_bounds` (used when the settings give neither an
    /// origin/spacing nor `volume_bounds_m`). A tracking volume starts centred on
    /// `camera_m` when given. Probes are placed and classified on the first update.
    pub fn new(settings: DdgiVolumeSettings, scene_bounds: (Vec3, Vec3)) -> Self {
        Self::placed(settings, scene_bounds, None)
    }

    /// As [`Self::new`], with the camera position a tracking window starts on.
    pub fn placed(settings: DdgiVolumeSettings, scene_bounds: (Vec3, Vec3), camera_m: Option<Vec3>) -> Self {
        let counts: UVec3 = settings.probe_counts;
        let (lo, hi) = settings.volume_bounds_m.map_or(scene_bounds, |[lo, hi]| (lo, hi));
        let fitted = ProbeGrid::fit_to_bounds(lo, hi, counts);
        let spacing = settings.probe_spacing_m.unwrap_or(fitted.spacing_m);
        let grid = match (settings.volume_tracks_camera, camera_m) {
            (true, Some(c)) => ProbeGrid::centred_on(c, settings.probe_origin_m.unwrap_or(Vec3::ZERO), counts, spacing),
            _ => ProbeGrid::new(settings.probe_origin_m.unwrap_or(fitted.origin_m), counts, spacing),
        };
        let probes = grid.probe_count();
        let probe_positions = (0..probes).map(|i| grid.probe_position(grid.probe_coords(i))).collect();
        Self {
            irradiance: ProbeAtlas::new(probes, settings.probe_irradiance_texels),
            distance: ProbeAtlas::new(probes, settings.probe_distance_texels),
            grid,
            probe_positions,
            probe_offsets: vec![Vec3::ZERO; probes],
            probe_states: vec![ProbeState::Active; probes],
            frames_updated: 0,
            probes_scrolled_in: 0,
            stream: 0,
            probe_hysteresis: vec![settings.probe_hysteresis; probes],
            probe_usable: vec![false; probes],
            probe_fallback: vec![u32::MAX; probes],
            probe_has_history: vec![false; probes],
            probe_alive_frames: vec![0; probes],
            probe_pending_init: vec![true; probes],
            initialized: false,
            irradiance_events: Vec::new(),
            visibility_events: Vec::new(),
            traced_probes_last: 0,
            active_probes_last: 0,
            probes_reset_since_blend: Vec::new(),
            settings,
        }
    }

    pub fn view(&self) -> DdgiFieldView<'_> {
        DdgiFieldView {
            grid: &self.grid,
            settings: &self.settings,
            irradiance: &self.irradiance,
            distance: &self.distance,
            probe_offsets_m: &self.probe_offsets,
            probe_usable: &self.probe_usable,
            probe_fallback: &self.probe_fallback,
        }
    }

    /// Probe rays traced by the last update (tracing probes × rays per probe).
    pub fn rays_per_frame(&self) -> u64 {
        self.traced_probes_last as u64 * self.settings.probe_rays_per_probe as u64
    }

    /// Probes shaded and blended in the last update.
    pub fn active_probe_count(&self) -> usize {
        self.active_probes_last
    }

    /// Whether queries may read probe `p` now.
    pub fn probe_usable(&self, p: usize) -> bool {
        self.probe_usable[p]
    }

    /// Whether probe `p` has been blended since it was created or last reset.
    pub fn probe_has_history(&self, p: usize) -> bool {
        self.probe_has_history[p]
    }

    /// Whether every probe is initialised (relocated and classified).
    pub fn is_initialized(&self) -> bool {
        self.initialized && !self.probe_pending_init.iter().any(|p| *p)
    }

    /// The per-ray RNG seed of this volume for `seed` (the seed itself for volume 0).
    pub fn stream_seed(&self, seed: u64) -> u64 {
        if self.stream == 0 { seed } else { hash_combine(&[seed, self.stream, 0x766f_6c75]) }
    }

    /// Recomputes which probes queries may read, and the fallback table if that changed.
    fn refresh_usable(&mut self) {
        let mut changed = false;
        for (p, u) in self.probe_usable.iter_mut().enumerate() {
            let now = self.probe_states[p].usable_in_queries() && self.probe_has_history[p];
            changed |= *u != now;
            *u = now;
        }
        if changed {
            self.probe_fallback = nearest_usable_probes(&self.grid, &self.probe_usable);
        }
    }

    /// The distance limit of the blend: RTXGI's 1.5 × the cell diagonal, or the
    /// trace limit if shorter.
    pub fn distance_clamp_m(&self) -> f32 {
        (1.5 * self.grid.spacing_m.length()).min(self.settings.probe_max_ray_distance_m)
    }

    /// Number of probes per state name.
    pub fn state_counts(&self) -> BTreeMap<&'static str, usize> {
        let mut m = BTreeMap::new();
        for s in &self.probe_states {
            *m.entry(s.name()).or_default() += 1;
        }
        m
    }

    /// Reports a scene change (seed 004 §4.3 per-probe heuristics; they apply to all
    /// probes). No effect unless `probe_fast_convergence` is on. Repeating an event
    /// while its reduction lasts restarts the reduction's window.
    pub fn notify_scene_event(&mut self, event: SceneEvent) {
        let (irr, vis) = match event {
            SceneEvent::SmallLightChange => (Some((0.85, 4)), None),
            SceneEvent::LargeLightChange => (Some((0.5, 10)), None),
            SceneEvent::LargeObjectChange => (Some((0.5, 10)), Some((0.5, 7))),
        };
        // The same reduction reported again (an object moving on every frame) restarts
        // its window rather than compounding: different reductions still multiply.
        let add = |events: &mut Vec<HysteresisReduction>, (scale, frames_left): (f32, u32)| match events
            .iter_mut()
            .find(|e| e.scale == scale)
        {
            Some(e) => e.frames_left = e.frames_left.max(frames_left),
            None => events.push(HysteresisReduction { scale, frames_left }),
        };
        if let Some(r) = irr {
            add(&mut self.irradiance_events, r);
        }
        if let Some(r) = vis {
            add(&mut self.visibility_events, r);
        }
    }

    /// Wakes Sleeping probes inside the AABBs of dynamic objects, grown by one cell
    /// plus the self-shadow bias (seed 004 Listing 5); Awake probes no longer inside
    /// any go back to sleep. jcgt states only. Returns the number of probes woken.
    pub fn wake_probes_near(&mut self, dynamic_aabbs: &[(Vec3, Vec3)]) -> usize {
        if self.settings.probe_states != ProbeStatesMode::Jcgt || !self.initialized {
            return 0;
        }
        let bias = 0.75 * self.grid.min_spacing_m() * self.settings.probe_self_shadow_bias;
        let grow = self.grid.spacing_m + Vec3::splat(bias);
        let mut woken = 0;
        for (p, state) in self.probe_states.iter_mut().enumerate() {
            let pos = self.probe_positions[p];
            let inside = dynamic_aabbs.iter().any(|&(lo, hi)| inside_grown_aabb(pos, lo, hi, grow));
            match *state {
                ProbeState::Sleeping if inside => {
                    *state = ProbeState::NewlyAwake;
                    woken += 1;
                }
                ProbeState::Awake if !inside => *state = ProbeState::Sleeping,
                _ => {}
            }
        }
        self.refresh_usable();
        woken
    }

    /// Moves a tracking window so that `target_m` stays within a cell of its
    /// centre (seed 004 §7.3). Only the grid origin and the circular buffer's phase
    /// change; the probes of the planes that enter are reset (atlas tiles cleared,
    /// offset 0, no history, so they blend with hysteresis 0 and are not read
    /// before that) and queued for initialisation. Returns the probes reset.
    pub(crate) fn scroll_to(&mut self, target_m: Vec3) -> usize {
        if !self.settings.volume_tracks_camera || !target_m.is_finite() {
            return 0;
        }
        let cells = self.grid.tracking_scroll_cells(target_m);
        if cells == IVec3::ZERO {
            return 0;
        }
        self.grid.scroll(cells);
        let mut reset = 0;
        for p in 0..self.grid.probe_count() {
            let coords = self.grid.probe_coords(p);
            if self.grid.scrolled_in(cells, coords) {
                self.reset_probe(p);
                reset += 1;
            }
            self.probe_positions[p] = self.grid.probe_position(coords) + self.probe_offsets[p];
        }
        self.probes_scrolled_in += reset as u64;
        self.refresh_usable();
        // The slots changed places on the grid: the nearest usable probe of each is
        // another one now, whether or not the usable set changed.
        self.probe_fallback = nearest_usable_probes(&self.grid, &self.probe_usable);
        reset
    }

    /// Clears again the tiles of the probes reset since the last blend (after the
    /// atlases were copied back from a device that had not cleared them yet).
    pub(crate) fn clear_reset_tiles(&mut self) {
        for &p in &self.probes_reset_since_blend {
            if (p as usize) < self.grid.probe_count() {
                self.irradiance.tile_mut(p as usize).fill(Vec3::ZERO);
                self.distance.tile_mut(p as usize).fill(Vec2::ZERO);
            }
        }
    }

    /// Forgets everything probe `p` knew: it is a new probe at its grid point.
    fn reset_probe(&mut self, p: usize) {
        self.irradiance.tile_mut(p).fill(Vec3::ZERO);
        self.distance.tile_mut(p).fill(Vec2::ZERO);
        self.probe_offsets[p] = Vec3::ZERO;
        self.probe_states[p] = ProbeState::Active;
        self.probe_hysteresis[p] = self.settings.probe_hysteresis;
        self.probe_has_history[p] = false;
        self.probe_alive_frames[p] = 0;
        self.probe_pending_init[p] = true;
        self.probes_reset_since_blend.push(p as u32);
    }

    /// The initialisation rounds this volume runs for its pending probes.
    fn init_rounds(&self) -> Vec<InitRound> {
        let mut rounds = Vec::new();
        if self.settings.probe_relocation {
            rounds.extend((0..self.settings.probe_relocation_iterations).map(InitRound::Relocation));
        }
        if self.settings.probe_states == ProbeStatesMode::Jcgt {
            rounds.push(InitRound::Classification);
        }
        rounds
    }

    /// Whether this volume's initialisation round `round` is its classification round.
    pub(crate) fn init_round_is_classification(&self, round: usize) -> bool {
        matches!(self.init_rounds().get(round), Some(InitRound::Classification))
    }

    /// The classification round's inputs, for a device that runs it.
    pub(crate) fn device_classification<'a>(&'a self, frame: &VolumeFrame) -> DeviceClassification<'a> {
        DeviceClassification {
            grid: &self.grid,
            rays_per_probe: frame.ray_count as u32,
            reach_rel: self.settings.probe_classification_reach_rel,
            bias_m: max_surface_bias_m(&self.settings, &self.grid),
            probes: (0..self.grid.probe_count())
                .map(|p| ClassificationProbe {
                    first_ray: frame.first_ray.get(p).copied().filter(|f| *f != u32::MAX),
                    pending: self.probe_pending_init[p],
                    traces: self.probe_states[p].traces(),
                    position_m: self.probe_positions[p],
                })
                .collect(),
        }
    }

    /// Applies a classification round a device ran: per probe (inside geometry, kept).
    pub(crate) fn accept_device_classification(&mut self, results: &[(bool, bool)]) {
        for (p, &(inside, kept)) in results.iter().enumerate().take(self.grid.probe_count()) {
            if self.probe_pending_init[p] {
                self.probe_states[p] = classify_jcgt(inside, kept);
            }
        }
    }

    /// Whether this volume's initialisation round `round` is a relocation iteration.
    pub(crate) fn init_round_is_relocation(&self, round: usize) -> bool {
        matches!(self.init_rounds().get(round), Some(InitRound::Relocation(_)))
    }

    /// The device's inputs for probe `p`'s relocation iteration in the current
    /// initialisation batch (`None` when it has no rays there).
    pub(crate) fn device_relocation(&self, frame: &VolumeFrame, p: usize) -> Option<DeviceRelocationProbe> {
        let first = *frame.first_ray.get(p)?;
        (first != u32::MAX && self.probe_pending_init[p]).then(|| DeviceRelocationProbe {
            first_ray: first,
            ray_count: frame.ray_count as u32,
            offset_m: self.probe_offsets[p],
            spacing_m: self.grid.spacing_m,
            offset_limit_rel: self.settings.probe_relocation_offset_limit_rel,
            min_frontface_rel: self.settings.probe_relocation_min_frontface_rel,
        })
    }

    /// Applies a relocation iteration another device ran: `offsets` are (probe, new offset).
    pub(crate) fn accept_device_relocation(&mut self, offsets: &[(u32, Vec3)]) {
        for &(p, o) in offsets {
            let p = p as usize;
            if p < self.probe_offsets.len() && self.probe_pending_init[p] {
                self.probe_offsets[p] = o;
                self.probe_positions[p] = self.grid.probe_position(self.grid.probe_coords(p)) + o;
            }
        }
    }

    /// Whether the volume has probes waiting for initialisation.
    pub(crate) fn needs_init(&self) -> bool {
        self.probe_pending_init.iter().any(|p| *p)
    }

    /// Adds this volume's rays for initialisation round `round` to `batch`, for its
    /// pending probes. Returns false when the volume has no such round (it then
    /// finishes its initialisation at once).
    pub(crate) fn plan_init_round(
        &self,
        frame: &mut VolumeFrame,
        round: usize,
        seed: u64,
        volume: u32,
        batch: &mut ProbeRayBatch,
    ) -> bool {
        let Some(&kind) = self.init_rounds().get(round) else {
            return false;
        };
        frame.init_dirs = probe_ray_directions(&self.settings, self.stream_seed(seed), init_frame(kind));
        frame.ray_count = frame.init_dirs.len();
        frame.first_ray = vec![u32::MAX; self.grid.probe_count()];
        for p in 0..self.grid.probe_count() {
            if self.probe_pending_init[p] {
                frame.first_ray[p] = batch.push_probe(
                    volume,
                    p as u32,
                    self.probe_positions[p],
                    &frame.init_dirs,
                    self.settings.probe_max_ray_distance_m,
                );
            }
        }
        true
    }

    /// Applies the hits of initialisation round `round` (see [`Self::plan_init_round`]).
    /// `distances` are the hits' signed distances (one per batch ray).
    pub(crate) fn accept_init_round(
        &mut self,
        frame: &VolumeFrame,
        round: usize,
        batch: &ProbeRayBatch,
        hits: &[ProbeRayHit],
        distances: &[f32],
    ) {
        let Some(&kind) = self.init_rounds().get(round) else {
            return;
        };
        let n = frame.ray_count;
        let dirs = &frame.init_dirs;
        let rays_of = |p: usize| {
            let first = frame.first_ray[p] as usize;
            first..first + n
        };
        match kind {
            InitRound::Relocation(_) => {
                let spacing = self.grid.spacing_m;
                let settings = &self.settings;
                let pending = &self.probe_pending_init;
                let planned = &frame.first_ray;
                self.probe_offsets.par_iter_mut().enumerate().for_each(|(p, offset)| {
                    if !pending[p] || planned[p] == u32::MAX {
                        return;
                    }
                    *offset =
                        relocation_step(*offset, &probe_ray_stats(dirs, &distances[rays_of(p)]), spacing, settings);
                });
                for p in 0..self.grid.probe_count() {
                    self.probe_positions[p] =
                        self.grid.probe_position(self.grid.probe_coords(p)) + self.probe_offsets[p];
                }
            }
            InitRound::Classification => self.classify_jcgt_pending(frame, batch, hits, distances),
        }
    }

    /// Seed 004 Listing 5's classification of the pending probes from one
    /// distance round (see `probegi_core::probe_classification`): a first pass per
    /// probe (inside geometry → Off; watching a front face → kept), then a covering
    /// pass in probe and ray order (sequential, so deterministic and greedy) that
    /// keeps a front-side cage probe for every surface point a pending probe saw.
    /// Probes that are not pending keep their states and count as covering when
    /// they are kept already (they trace: not Off or Sleeping).
    fn classify_jcgt_pending(
        &mut self,
        frame: &VolumeFrame,
        batch: &ProbeRayBatch,
        hits: &[ProbeRayHit],
        distances: &[f32],
    ) {
        let n = frame.ray_count;
        let bias = max_surface_bias_m(&self.settings, &self.grid);
        let reach = self.settings.probe_classification_reach_rel;
        let (grid, pending) = (&self.grid, &self.probe_pending_init);
        let dirs = &frame.init_dirs;
        // Front-face hits of probe p as (position, facing normal).
        let front_hits = |p: usize| {
            let first = frame.first_ray[p] as usize;
            (first..first + n).filter_map(move |r| {
                let h = hits[r];
                (h.distance_m > 0.0 && h.distance_m.is_finite())
                    .then(|| (batch.origins_m[r] + batch.directions[r] * h.distance_m, h.normal))
            })
        };
        let first: Vec<(bool, bool)> = (0..grid.probe_count())
            .into_par_iter()
            .map(|p| {
                if !pending[p] || frame.first_ray[p] == u32::MAX {
                    return (false, false);
                }
                let f = frame.first_ray[p] as usize;
                let d = &distances[f..f + n];
                let coords = grid.probe_coords(p);
                let grid_point = grid.probe_position(coords);
                let watches = front_hits(p).any(|(pos, _)| probe_watches(grid, coords, pos - grid_point, reach, bias));
                (is_inside_geometry(&probe_ray_stats(dirs, d)), watches)
            })
            .collect();
        let eligible: Vec<bool> = (0..grid.probe_count()).map(|p| pending[p] && !first[p].0).collect();
        let mut kept: Vec<bool> = (0..grid.probe_count())
            .map(|p| if pending[p] { !first[p].0 && first[p].1 } else { self.probe_states[p].traces() })
            .collect();
        let positions = &self.probe_positions;
        for p in (0..grid.probe_count()).filter(|&p| pending[p] && frame.first_ray[p] != u32::MAX) {
            for (pos, normal) in front_hits(p) {
                if let Some(q) = uncovered_point_probe(grid, positions, &kept, &eligible, pos, normal) {
                    kept[q] = true;
                }
            }
        }
        for p in 0..grid.probe_count() {
            if pending[p] {
                self.probe_states[p] = classify_jcgt(first[p].0, kept[p]);
            }
        }
    }

    /// Ends initialisation: pending probes take their starting state (jcgt: set by
    /// the classification round).
    pub(crate) fn finish_init(&mut self) {
        for p in 0..self.grid.probe_count() {
            if !self.probe_pending_init[p] {
                continue;
            }
            match self.settings.probe_states {
                ProbeStatesMode::AllActive => self.probe_states[p] = ProbeState::Active,
                ProbeStatesMode::Usage => self.probe_states[p] = ProbeState::Alive,
                ProbeStatesMode::Jcgt => {}
            }
            self.probe_pending_init[p] = false;
        }
        self.initialized = true;
        self.refresh_usable();
    }

    /// Adds the frame's update rays (seed 003 §4.2) of the probes whose state
    /// traces, and decides which probes update this frame.
    pub(crate) fn plan_update(
        &mut self,
        frame: &mut VolumeFrame,
        seed: u64,
        frame_index: u32,
        volume: u32,
        batch: &mut ProbeRayBatch,
    ) {
        let probes = self.grid.probe_count();
        let interval = self.settings.probe_sleeping_update_interval;
        frame.tracing = self.probe_states.iter().map(|s| s.traces()).collect();
        frame.active = self.probe_states.iter().map(|s| s.updates_in_frame(frame_index, interval)).collect();
        frame.rays = generate_probe_rays(&self.settings, self.stream_seed(seed), frame_index);
        frame.ray_count = frame.rays.dirs.len();
        frame.first_ray = vec![u32::MAX; probes];
        let first_probe = batch.probes.len() as u32;
        for p in 0..probes {
            if frame.tracing[p] {
                frame.first_ray[p] = batch.push_probe(
                    volume,
                    p as u32,
                    self.probe_positions[p],
                    &frame.rays.dirs,
                    self.settings.probe_max_ray_distance_m,
                );
            }
        }
        batch.generated.push(crate::seam::GeneratedProbeRays {
            volume,
            first_probe,
            probe_count: batch.probes.len() as u32 - first_probe,
            rays_per_probe: frame.ray_count as u32,
            rotation: crate::probe_ray_gen::probe_ray_rotation(self.stream_seed(seed), frame_index),
            max_distance_m: self.settings.probe_max_ray_distance_m,
        });
        self.traced_probes_last = frame.tracing.iter().filter(|t| **t).count();
    }

    /// After the trace: the usage scheme's classification from the hits (seed 003
    /// §6.1), then which rays the caller must shade (those of probes that update
    /// this frame, except backface hits, whose radiance is zero by rule).
    pub(crate) fn accept_update_hits(
        &mut self,
        frame: &mut VolumeFrame,
        frame_index: u32,
        hits: &[ProbeRayHit],
        needs_radiance: &mut [bool],
    ) {
        let n = frame.ray_count;
        if self.settings.probe_states == ProbeStatesMode::Usage {
            let cage_diagonal = self.grid.spacing_m.length();
            let counts: Vec<Option<(i32, u32, u32)>> = frame
                .first_ray
                .iter()
                .map(|&first| {
                    (first != u32::MAX).then(|| {
                        let rays = &hits[first as usize..first as usize + n];
                        probe_usage(rays.iter().map(|h| h.distance_m), cage_diagonal)
                    })
                })
                .collect();
            self.classify_usage_states(frame, frame_index, &counts);
        }
        for p in 0..self.grid.probe_count() {
            let first = frame.first_ray[p];
            if first == u32::MAX || !frame.active[p] {
                continue;
            }
            let first = first as usize;
            for r in first..first + n {
                needs_radiance[r] = hits[r].distance_m >= 0.0; // hits are sanitised: no NaN
            }
        }
    }

    /// As [`Self::accept_update_hits`] for hits that stayed on another device:
    /// `usage_counts` holds, per probe that traced, seed 003's (usage, relevant,
    /// backfaces) counted there (`probegi_core::probe_classification::probe_usage`;
    /// read only under the usage scheme). Every ray of an updating probe is
    /// marked: the device zeroes backface radiance itself.
    pub(crate) fn accept_device_hits(
        &mut self,
        frame: &mut VolumeFrame,
        frame_index: u32,
        usage_counts: &[Option<(i32, u32, u32)>],
        needs_radiance: &mut [bool],
    ) {
        let n = frame.ray_count;
        if self.settings.probe_states == ProbeStatesMode::Usage {
            self.classify_usage_states(frame, frame_index, usage_counts);
        }
        for p in 0..self.grid.probe_count() {
            let first = frame.first_ray[p];
            if first != u32::MAX && frame.active[p] {
                needs_radiance[first as usize..first as usize + n].fill(true);
            }
        }
    }

    /// Usage scheme (seed 003 §6.1): every probe's state from this frame's usage
    /// counts (per probe, `None` when it did not trace), and which probes blend
    /// this frame (see `probegi_core::probe_classification`).
    fn classify_usage_states(&mut self, frame: &mut VolumeFrame, frame_index: u32, counts: &[Option<(i32, u32, u32)>]) {
        let (interval, min_alive) =
            (self.settings.probe_sleeping_update_interval, self.settings.probe_alive_min_frames);
        for p in 0..self.grid.probe_count() {
            let Some(&Some((usage, relevant, backfaces))) = counts.get(p) else {
                continue;
            };
            let prev = self.probe_states[p];
            let mut next = classify_usage(usage, relevant, backfaces);
            if prev == ProbeState::Alive && next == ProbeState::UsageSleeping && self.probe_alive_frames[p] < min_alive
            {
                next = ProbeState::Alive;
            }
            self.probe_alive_frames[p] = if next == ProbeState::Alive { self.probe_alive_frames[p] + 1 } else { 0 };
            if prev == ProbeState::Dead && next != ProbeState::Dead {
                // Uncovered: the atlas holds light from before, so start over.
                self.probe_has_history[p] = false;
            }
            frame.active[p] = match next {
                ProbeState::Dead => prev != ProbeState::Dead,
                s => s.updates_in_frame(frame_index, interval) || !self.probe_has_history[p],
            };
            self.probe_states[p] = next;
        }
    }

    /// Blend and border (seed 003 §4.5, seed 004 §2.3–4.3) for the probes that
    /// update this frame, from the batch's per-ray blend inputs (radiance and
    /// signed distance after the backface rule, [`blend_inputs`]). Adds
    /// milliseconds to `pass_ms` under `blend` and `border`.
    pub(crate) fn blend_results(
        &mut self,
        frame: &VolumeFrame,
        ray_radiance: &[Vec3],
        ray_distance: &[f32],
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) {
        let t = std::time::Instant::now();
        let n = frame.ray_count;
        let (base, irr_scale, vis_scale) = self.blend_plan(frame);
        let thresholds = self.settings.probe_fast_convergence.then_some(TexelThresholds {
            significant: self.settings.probe_significant_change_threshold,
            new_distribution: self.settings.probe_new_distribution_threshold,
        });
        let (irr_n, dist_n) = (self.irradiance.interior, self.distance.interior);
        let gamma = self.settings.probe_irradiance_gamma;
        let clamp = self.distance_clamp_m();
        let irr_len = self.irradiance.tile_len();
        let dist_len = self.distance.tile_len();
        let weights = &frame.rays;
        self.irradiance.texels.par_chunks_mut(irr_len).zip(base.par_iter()).for_each(|(tile, b)| {
            if let Some((first, h)) = *b {
                blend_irradiance_tile(
                    tile,
                    irr_n,
                    &weights.irradiance_weights,
                    &ray_radiance[first..first + n],
                    h * irr_scale,
                    gamma,
                    thresholds.as_ref(),
                );
            }
        });
        self.distance.texels.par_chunks_mut(dist_len).zip(base.par_iter()).for_each(|(tile, b)| {
            if let Some((first, h)) = *b {
                blend_distance_tile(
                    tile,
                    dist_n,
                    &weights.distance_weights,
                    &ray_distance[first..first + n],
                    h * vis_scale,
                    clamp,
                );
            }
        });
        *pass_ms.entry("blend").or_default() += t.elapsed().as_secs_f64() * 1e3;

        let t = std::time::Instant::now();
        let updated: Vec<bool> = base.iter().map(|b| b.is_some()).collect();
        self.irradiance.texels.par_chunks_mut(irr_len).zip(updated.par_iter()).for_each(|(tile, a)| {
            if *a {
                update_tile_border(tile, irr_n)
            }
        });
        self.distance.texels.par_chunks_mut(dist_len).zip(updated.par_iter()).for_each(|(tile, a)| {
            if *a {
                update_tile_border(tile, dist_n)
            }
        });
        *pass_ms.entry("border").or_default() += t.elapsed().as_secs_f64() * 1e3;
        self.after_update(&updated);
        #[cfg(debug_assertions)]
        self.validate();
    }

    /// Per probe, its first ray and the hysteresis of its blend this frame (`None`:
    /// no blend), and the scene events' irradiance and visibility scales.
    fn blend_plan(&self, frame: &VolumeFrame) -> (Vec<Option<(usize, f32)>>, f32, f32) {
        let event_scale = |events: &[HysteresisReduction]| events.iter().map(|e| e.scale).product::<f32>();
        let (irr_scale, vis_scale) = if self.settings.probe_fast_convergence {
            (event_scale(&self.irradiance_events), event_scale(&self.visibility_events))
        } else {
            (1.0, 1.0)
        };
        let base = (0..self.grid.probe_count())
            .map(|p| {
                let first = frame.first_ray[p];
                (frame.active[p] && first != u32::MAX).then(|| {
                    let h = if !self.probe_has_history[p] || self.probe_states[p].is_new() {
                        0.0
                    } else {
                        self.probe_hysteresis[p]
                    };
                    (first as usize, h)
                })
            })
            .collect();
        (base, irr_scale, vis_scale)
    }

    /// This frame's blend as data, for a device that holds the atlases.
    pub(crate) fn device_blend<'a>(&'a self, frame: &'a VolumeFrame) -> DeviceVolumeBlend<'a> {
        let (base, irradiance_scale, visibility_scale) = self.blend_plan(frame);
        DeviceVolumeBlend {
            settings: &self.settings,
            ray_dirs: &frame.rays.dirs,
            irradiance_weights: &frame.rays.irradiance_weights,
            distance_weights: &frame.rays.distance_weights,
            probe_blend: base.into_iter().map(|b| b.map(|(first, h)| (first as u32, h))).collect(),
            irradiance_scale,
            visibility_scale,
            distance_clamp_m: self.distance_clamp_m(),
            reset_probes: &self.probes_reset_since_blend,
        }
    }

    /// The bookkeeping of a blend another device ran by [`Self::device_blend`].
    pub(crate) fn accept_device_blend(&mut self, frame: &VolumeFrame) {
        let updated: Vec<bool> = self.blend_plan(frame).0.iter().map(|b| b.is_some()).collect();
        self.after_update(&updated);
    }

    /// State transitions and hysteresis ramps after a blend.
    fn after_update(&mut self, updated: &[bool]) {
        self.frames_updated += 1;
        self.probes_reset_since_blend.clear();
        let max_h = self.settings.probe_hysteresis;
        self.active_probes_last = updated.iter().filter(|a| **a).count();
        for (p, _) in updated.iter().enumerate().filter(|(_, u)| **u) {
            self.probe_has_history[p] = true;
            let state = self.probe_states[p].after_update();
            if matches!(state, ProbeState::Alive | ProbeState::UsageSleeping) {
                let target = if state == ProbeState::Alive { max_h } else { 0.5 * max_h };
                self.probe_hysteresis[p] += 0.1 * (target - self.probe_hysteresis[p]);
            }
            self.probe_states[p] = state;
        }
        self.refresh_usable();
        for events in [&mut self.irradiance_events, &mut self.visibility_events] {
            for e in events.iter_mut() {
                e.frames_left = e.frames_left.saturating_sub(1);
            }
            events.retain(|e| e.frames_left > 0);
        }
    }

    /// Atlas invariants: every texel finite and non-negative, every border equal to
    /// its source texel, and no probe readable before its first blend.
    pub fn validate(&self) {
        assert!(self.irradiance.texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0), "irradiance atlas");
        assert!(self.distance.texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0), "distance atlas");
        for p in 0..self.grid.probe_count() {
            check_borders(self.irradiance.tile(p), self.irradiance.interior);
            check_borders(self.distance.tile(p), self.distance.interior);
            assert!(!self.probe_usable[p] || self.probe_has_history[p], "probe {p} is readable before its first blend");
        }
    }
}

/// The blend's per-ray inputs from a batch's hits and the caller's radiance, the
/// backface rule applied once per ray (seed 004 §4.1; RTXGI stores −0.2·t): a
/// backface hit gets zero radiance and a short negative distance, so the probe
/// reads as shadowed there; a miss keeps the caller's radiance (the sky) and the
/// ray's max distance. Fills `radiance_out` and `distance_out`.
pub(crate) fn blend_inputs(
    batch: &ProbeRayBatch,
    hits: &[ProbeRayHit],
    radiance: &[Vec3],
    radiance_out: &mut Vec<Vec3>,
    distance_out: &mut Vec<f32>,
) {
    radiance_out.clear();
    distance_out.clear();
    for ((h, &l), &max) in hits.iter().zip(radiance).zip(&batch.max_distances_m) {
        let d = h.distance_m;
        let (l, d) = if d < 0.0 {
            (Vec3::ZERO, 0.2 * d)
        } else if d.is_finite() {
            (l, d)
        } else {
            (l, max)
        };
        radiance_out.push(l);
        distance_out.push(d);
    }
}

fn check_borders<T: PartialEq + Copy + std::fmt::Debug>(tile: &[T], interior: u32) {
    use probegi_core::probe_atlas::tile_texel_index;
    for ((dx, dy), (sx, sy)) in probegi_core::probe_border::border_sources(interior) {
        assert_eq!(tile[tile_texel_index(interior, dx, dy)], tile[tile_texel_index(interior, sx, sy)], "border texel");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_repeated_event_restarts_its_window_instead_of_compounding() {
        let mut v = DdgiVolume::new(DdgiVolumeSettings::default(), (Vec3::ZERO, Vec3::ONE));
        for _ in 0..10 {
            v.notify_scene_event(SceneEvent::LargeObjectChange);
        }
        v.notify_scene_event(SceneEvent::SmallLightChange);
        let scales = |e: &[HysteresisReduction]| e.iter().map(|r| r.scale).product::<f32>();
        // One 0.5 (not 0.5¹⁰) and the small light change's 0.85 on top.
        assert!((scales(&v.irradiance_events) - 0.5 * 0.85).abs() < 1e-6);
        assert!((scales(&v.visibility_events) - 0.5).abs() < 1e-6);
        assert_eq!(v.irradiance_events.iter().map(|r| r.frames_left).max(), Some(10));
    }
}
