//! One DDGI volume, the same for every backend: the persistent field (grid,
//! atlases, relocation offsets, probe states, hysteresis) and the volume's share
//! of each seam step, which `ddgi_field_set` drives for every volume of a set.
//! The steps live in one child module each, in frame order:
//!
//! - `init_rounds`: initialisation (seed 004 Listing 5, first step), relocation
//!   and classification rounds against the static geometry;
//! - `update_plan`: the frame's rays for the probes whose state traces, and the
//!   acceptance of their hits;
//! - `usage_states`: which probes queries read, and the usage scheme's
//!   classification from the frame's hits (seed 003 §6.1);
//! - `blend_inputs`: scene-event hysteresis (seed 004 §4.3), the backface rule
//!   (seed 004 §4.1), the blend and the borders;
//! - `screen_requests`: the screen scheme's countdowns from the camera frame's
//!   requests, and which probes trace in a frame;
//! - `scrolling`: a tracking window's whole-cell move over the circular buffer;
//! - `steady_frames`: a still volume's plan kept from frame to frame, its
//!   probes' counters counted without planning them again.
//!
//! A probe's first update (and a Newly Awake / Newly Vigilant probe's, and a
//! scrolled-in probe's) replaces its history, i.e. blends with hysteresis 0; until
//! then queries skip it, so no stale or empty probe is ever read.

use glam::{UVec3, Vec2, Vec3};
use probegi_core::ddgi_query::DdgiFieldView;
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::probe_atlas::ProbeAtlas;
use probegi_core::probe_classification::{ProbeState, ProbeUsageCounts};
use probegi_core::probe_grid::ProbeGrid;
use probegi_core::rng::hash_combine;

use crate::probe_ray_gen::ProbeRayDirections;

mod blend_inputs;
mod init_rounds;
mod late_results;
mod probe_budget;
mod screen_requests;
mod scrolling;
mod shadow_rays;
mod steady_frames;
mod update_plan;
mod usage_states;

pub(crate) use blend_inputs::blend_inputs;
pub use init_rounds::HitNormals;
pub use shadow_rays::ShadowField;

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
    /// The probe lattice: origin, spacing and counts, and the circular storage
    /// offset of a tracking window.
    pub grid: ProbeGrid,
    /// The volume's settings, with the papers' defaults (`probegi_core::ddgi_settings`).
    pub settings: DdgiVolumeSettings,
    /// Encoded mean radiance per texel (see `probegi_core::irradiance_encoding`).
    pub irradiance: ProbeAtlas<Vec3>,
    /// (mean distance, mean squared distance) per texel.
    pub distance: ProbeAtlas<Vec2>,
    /// Probe positions including relocation offsets, per storage slot.
    pub probe_positions: Vec<Vec3>,
    /// Relocation offsets in metres per storage slot (seed 004 §5).
    pub probe_offsets: Vec<Vec3>,
    /// Probe states per storage slot (jcgt: seed 004 §6; usage: seed 003 §6.1).
    pub probe_states: Vec<ProbeState>,
    /// Blends run since the volume was created.
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
    /// Usage scheme (`usage_states`): the update batches whose usage counts
    /// wait for their classification, and per probe the first batch whose
    /// counts describe it where it is now.
    usage_pending: late_results::LateResults<(), Vec<Option<ProbeUsageCounts>>>,
    probe_usage_from_batch: Vec<u64>,
    /// Probes waiting for initialisation (relocation, classification).
    probe_pending_init: Vec<bool>,
    /// Initialisation: the probe's last relocation round left its offset as it
    /// was, so later rounds (same rays, same origin) would too (`init_rounds`).
    probe_relocation_settled: Vec<bool>,
    /// Initialisation: each pending probe's hits of the last round it traced
    /// on the host, probe-major (`probe_init_rays_per_probe` a probe; empty
    /// outside initialisation), and whether they were traced from where the
    /// probe is now (`init_rounds`: the classification round reads them).
    probe_init_hits: Vec<crate::seam::ProbeRayHit>,
    probe_init_hits_current: Vec<bool>,
    initialized: bool,
    irradiance_events: Vec<HysteresisReduction>,
    visibility_events: Vec<HysteresisReduction>,
    traced_probes_last: usize,
    active_probes_last: usize,
    /// Probes whose tiles were cleared since the last blend (a device that holds
    /// the atlases clears its copies before its next blend).
    probes_reset_since_blend: Vec<u32>,
    /// Seed 003 ch. 5's occlusion maps, with `settings.shadow_field`.
    pub shadow: Option<ShadowField>,
    /// The ray budget's signal (`probe_budget`): each probe's change in its
    /// last blend (1 before any), and the frames since it last traced.
    probe_change: Vec<f32>,
    probe_untraced_frames: Vec<u32>,
    /// The blends whose changes (per blended probe, in increasing order) wait
    /// to be recorded (`probe_budget`), and per probe the first batch whose
    /// change counts for it (the batches before it blended before a mark).
    change_pending: late_results::LateResults<Vec<u32>, Vec<f32>>,
    probe_change_from_batch: Vec<u64>,
    /// The occlusion change of each probe's last occlusion blend.
    probe_occlusion_change: Vec<f32>,
    /// Frames its state wanted each probe to blend but the budget held it
    /// back, since its last blend (`ray_budget_hysteresis_per_frame`).
    probe_unblended_frames: Vec<u32>,
    /// Frames in a row each probe has traced (the shadowing field's pairs).
    probe_trace_run: Vec<u32>,
    /// Per axis, the sign of the tracking window's last scroll along it (0:
    /// never scrolled): its leading faces, for the edge buffers.
    scroll_leading: glam::IVec3,
    /// Probes seeded since their reset (`probe_seeding`): their first blend
    /// weighs the seed instead of replacing it.
    probe_seeded: Vec<bool>,
    /// The seeds planned for this volume's probes reset since the last blend,
    /// for a device that holds the atlases (it mixes them before blending).
    pub(crate) pending_seeds: Vec<crate::probe_seeding::ProbeSeed>,
    /// Screen scheme (`screen_requests`): frames each probe stays Requested,
    /// and whether a camera pixel read it since the last update.
    probe_request_countdown: Vec<u32>,
    probe_requested: Vec<bool>,
    /// Blends since the probe's history last restarted (`probe_hysteresis_ramp`).
    probe_blends: Vec<u32>,
    /// One adaptive-hysteresis state per irradiance texel, laid out as the
    /// atlas (`probe_adaptive_hysteresis`; empty without it, sized at the
    /// first blend with it, from 0).
    irradiance_texel_hysteresis: Vec<f32>,
    /// The counters above that a kept plan's frames have not yet added
    /// (`steady_frames::OwedCounts`): `None` where every counter is current.
    steady_owed: Option<steady_frames::OwedCounts>,
    /// Screen scheme: every probe's idle phase and the grid and interval they
    /// were computed for (`screen_requests`).
    idle_phases: (Option<(ProbeGrid, u32)>, Vec<u32>),
    /// An identity of the probe rows (offsets and positions, usable flags,
    /// fallback table), drawn anew (`device_plans::next_plan_id`) by every
    /// write to them, by a clone, and whenever the volume may be changed from
    /// outside (`DdgiFieldSet::volumes_mut`, `into_volumes`, `from_volumes`):
    /// equal identities, equal rows. What
    /// [`DdgiFieldSet::view`](crate::DdgiFieldSet::view) gives the queries
    /// (`DdgiFieldView::probe_rows_id`), and what a kept plan's snapshot holds
    /// of the positions (`steady_frames`).
    probe_rows_id: RowsId,
}

/// [`DdgiVolume`]'s `probe_rows_id`: an identity, not a value, so a volume's
/// `Debug` leaves it out (two volumes with equal rows compare equal there
/// whatever identities they drew), and a clone draws its own (a clone's
/// public fields may change apart from the original's).
#[derive(PartialEq, Eq)]
pub(crate) struct RowsId(pub(crate) u64);

impl Clone for RowsId {
    fn clone(&self) -> Self {
        Self(crate::device_plans::next_plan_id())
    }
}

impl std::fmt::Debug for RowsId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("RowsId")
    }
}

/// One volume's per-frame scratch.
#[derive(Clone, Debug, Default)]
pub struct VolumeFrame {
    /// The frame's update directions and blend weights.
    pub rays: ProbeRayDirections,
    /// The current initialisation round's directions.
    pub init_dirs: Vec<Vec3>,
    /// The current classification round reads hits kept from a relocation
    /// round for some pending probe (which did not trace in it).
    pub init_reuses_hits: bool,
    /// Probes that trace this frame.
    pub tracing: Vec<bool>,
    /// Probes that are shaded and blended this frame.
    pub active: Vec<bool>,
    /// Per probe, its first ray in the current batch (`u32::MAX`: none).
    pub first_ray: Vec<u32>,
    /// Rays per probe when the batch was planned.
    pub ray_count: usize,
    /// The shadow field's first shadow ray in the batch.
    pub shadow_first_ray: usize,
    /// The shadow field's samples planned this frame, in probe order.
    pub(crate) shadow_slots: Vec<shadow_rays::ShadowSlot>,
    /// The samples' probe and (direction, visibility) once the batch is traced.
    pub(crate) shadow_samples: Vec<(u32, probegi_core::shadow_field::ShadowSample)>,
    /// Under a ray budget, the probes it lets trace this frame (`None`: no budget).
    pub budget_traces: Option<Vec<bool>>,
    /// A device blend measures each probe's change (a ray budget reads it;
    /// a host blend always reports it).
    pub measure_change: bool,
    /// Screen scheme: per probe, the frames its blend stands for (empty
    /// under the other schemes; `screen_requests`).
    pub(crate) screen_blend_frames: Vec<u32>,
    /// A steady frame's blend plan (`steady_frames`): per probe its first ray
    /// and hysteresis, kept while the plan is; `None` after a full plan.
    pub(crate) steady_blend: Option<Vec<Option<(u32, f32)>>>,
    /// The kept blend plan's identity (`DeviceVolumeBlend::probe_blend_id`).
    pub(crate) steady_blend_id: u64,
    /// The kept plan's per-probe flags for the frame counters
    /// (`steady_frames::OwedCounts`), made with `steady_blend`.
    pub(crate) steady_flags: Option<std::sync::Arc<[u8]>>,
    /// What the volume's last full update plan read (in this frame's slot of
    /// the set, with the batch it vouches for), where a later frame may keep
    /// that plan (`steady_frames`).
    pub(crate) plan_snapshot: Option<steady_frames::PlanSnapshot>,
    /// What the volume's last full update plan read for its trace alone,
    /// where a later frame may keep the batch's entries (the usage scheme,
    /// `steady_frames`).
    pub(crate) trace_snapshot: Option<steady_frames::TraceSnapshot>,
}

impl VolumeFrame {
    /// Whether probe `p` blends this frame: its state updates now and it traced.
    pub(crate) fn blends(&self, p: usize) -> bool {
        self.active.get(p).copied().unwrap_or(false) && self.first_ray.get(p).is_some_and(|f| *f != u32::MAX)
    }

    /// [`Self::blends`] of every probe planned this frame, in probe order.
    pub(crate) fn blending(&self) -> Vec<bool> {
        self.active.iter().zip(&self.first_ray).map(|(a, f)| *a && *f != u32::MAX).collect()
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
        let bounds = settings.volume_tracking_bounds_m;
        // A window held inside bounds starts at their centre until a camera is given.
        let start = camera_m.or(bounds.map(|[lo, hi]| (lo + hi) * 0.5));
        let grid = match (settings.volume_tracks_camera, start) {
            (true, Some(c)) => {
                let anchor = ProbeGrid::tracking_anchor(settings.probe_origin_m, bounds, counts, spacing);
                let c = match bounds {
                    Some(b) => ProbeGrid::new(anchor, counts, spacing).tracking_target_within(c, b),
                    None => c,
                };
                ProbeGrid::centred_on(c, anchor, counts, spacing)
            }
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
            usage_pending: Default::default(),
            probe_usage_from_batch: vec![0; probes],
            probe_pending_init: vec![true; probes],
            probe_relocation_settled: vec![false; probes],
            probe_init_hits: Vec::new(),
            probe_init_hits_current: vec![false; probes],
            initialized: false,
            irradiance_events: Vec::new(),
            visibility_events: Vec::new(),
            traced_probes_last: 0,
            active_probes_last: 0,
            probes_reset_since_blend: Vec::new(),
            shadow: settings.shadow_field.then(|| ShadowField::new(probes, settings.shadow_field_texels)),
            probe_change: vec![1.0; probes],
            probe_untraced_frames: vec![0; probes],
            change_pending: Default::default(),
            probe_change_from_batch: vec![0; probes],
            probe_occlusion_change: vec![0.0; probes],
            probe_unblended_frames: vec![0; probes],
            probe_trace_run: vec![0; probes],
            scroll_leading: glam::IVec3::ZERO,
            probe_seeded: vec![false; probes],
            pending_seeds: Vec::new(),
            probe_request_countdown: vec![0; probes],
            probe_requested: vec![false; probes],
            probe_blends: vec![0; probes],
            irradiance_texel_hysteresis: Vec::new(),
            steady_owed: None,
            idle_phases: (None, Vec::new()),
            probe_rows_id: RowsId(crate::device_plans::next_plan_id()),
            settings,
        }
    }

    /// The field as queries read it: atlases, offsets and which probes are
    /// usable. No identity of the rows (`DdgiFieldView::probe_rows_id`): a
    /// volume's public fields may have changed since its last write; the set
    /// that owns it gives one ([`crate::DdgiFieldSet::view`]).
    pub fn view(&self) -> DdgiFieldView<'_> {
        DdgiFieldView {
            grid: &self.grid,
            settings: &self.settings,
            irradiance: &self.irradiance,
            distance: &self.distance,
            probe_offsets_m: &self.probe_offsets,
            probe_usable: &self.probe_usable,
            probe_fallback: &self.probe_fallback,
            probe_rows_id: None,
        }
    }

    /// [`Self::view`] with the rows' identity, for a set that owns the
    /// volume (every change to its rows since goes through its methods or
    /// `DdgiFieldSet::volumes_mut`, which draw a new one).
    pub(crate) fn view_with_rows_id(&self) -> DdgiFieldView<'_> {
        DdgiFieldView { probe_rows_id: Some(self.probe_rows_id.0), ..self.view() }
    }

    /// Draws a new identity of the probe rows (see `probe_rows_id`): after
    /// any write to them, or where they may be written from outside.
    pub(crate) fn renew_probe_rows_id(&mut self) {
        self.probe_rows_id = RowsId(crate::device_plans::next_plan_id());
    }

    /// Probe rays traced by the last update (tracing probes × rays per probe).
    pub fn rays_per_frame(&self) -> u64 {
        self.traced_probes_last as u64 * self.settings.probe_rays_per_probe as u64
    }

    /// Probes shaded and blended in the last update.
    pub fn active_probe_count(&self) -> usize {
        self.active_probes_last
    }

    /// The factor the fast-convergence heuristics (seed 004 §4.3) put on the
    /// irradiance hysteresis now: the product of the scene events' reductions
    /// still running, 1 when none runs or `probe_fast_convergence` is off.
    pub fn irradiance_hysteresis_scale(&self) -> f32 {
        if !self.settings.probe_fast_convergence {
            return 1.0;
        }
        self.irradiance_events.iter().map(|e| e.scale).product()
    }

    /// Whether queries may read probe `p` now.
    pub fn probe_usable(&self, p: usize) -> bool {
        self.probe_usable[p]
    }

    /// Probe `p`'s change in its last blend (`probegi_core::probe_change`; 1
    /// before its first), measured while a ray budget runs.
    pub fn probe_change(&self, p: usize) -> f32 {
        self.probe_change[p]
    }

    /// Frames since probe `p` last traced (0: it traced in the last update).
    pub fn probe_frames_since_traced(&self, p: usize) -> u32 {
        match &self.steady_owed {
            Some(owed) => owed.untraced(p, self.probe_untraced_frames[p]),
            None => self.probe_untraced_frames[p],
        }
    }

    /// Whether probe `p` has been blended since it was created or last reset.
    pub fn probe_has_history(&self, p: usize) -> bool {
        self.probe_has_history[p]
    }

    /// Whether probe `p` was seeded since its reset and has not blended yet
    /// (`probegi_field::probe_seeding`).
    pub fn probe_seeded(&self, p: usize) -> bool {
        self.probe_seeded.get(p).copied().unwrap_or(false)
    }

    /// Marks probe `p` seeded (`probegi_field::probe_seeding`).
    pub(crate) fn mark_seeded(&mut self, p: usize) {
        if let Some(s) = self.probe_seeded.get_mut(p) {
            *s = true;
        }
    }

    /// The probes reset since the last blend (scrolled in).
    pub(crate) fn probes_reset_since_blend(&self) -> &[u32] {
        &self.probes_reset_since_blend
    }

    /// Whether every probe is initialised (relocated and classified).
    pub fn is_initialized(&self) -> bool {
        self.initialized && !self.probe_pending_init.iter().any(|p| *p)
    }

    /// The per-ray RNG seed of this volume for `seed` (the seed itself for volume 0).
    pub fn stream_seed(&self, seed: u64) -> u64 {
        if self.stream == 0 { seed } else { hash_combine(&[seed, self.stream, 0x766f_6c75]) }
    }

    /// The distance limit of the blend: RTXGI's 1.5 × the cell diagonal, or the
    /// trace limit if shorter.
    pub fn distance_clamp_m(&self) -> f32 {
        (1.5 * self.grid.spacing_m.length()).min(self.settings.probe_max_ray_distance_m)
    }

    /// Atlas invariants: every texel finite and non-negative, every border equal to
    /// its source texel, and no probe readable before its first blend (or,
    /// under the screen scheme, its seed).
    pub fn validate(&self) {
        assert!(self.irradiance.texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0), "irradiance atlas");
        assert!(self.distance.texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0), "distance atlas");
        for p in 0..self.grid.probe_count() {
            check_borders(self.irradiance.tile(p), self.irradiance.interior);
            check_borders(self.distance.tile(p), self.distance.interior);
            assert!(
                !self.probe_usable[p] || self.probe_has_content(p),
                "probe {p} is readable before its first blend or seed"
            );
        }
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
    use probegi_core::ddgi_settings::ProbeStatesMode;

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

    /// The screen scheme's idle phases kept per grid are each probe's phase
    /// from its world cell: at a negative origin, after the window scrolls
    /// (stale until kept again), and for another interval; other schemes keep none.
    #[test]
    fn kept_idle_phases_are_every_probes_phase_and_follow_the_grid() {
        let settings = DdgiVolumeSettings {
            probe_counts: UVec3::new(5, 3, 4),
            probe_spacing_m: Some(Vec3::splat(0.75)),
            probe_states: ProbeStatesMode::Screen,
            volume_tracks_camera: true,
            ..Default::default()
        };
        let mut v = DdgiVolume::placed(settings.clone(), (Vec3::ZERO, Vec3::ONE), Some(Vec3::splat(-7.3)));
        let direct = |v: &DdgiVolume| {
            let interval = v.settings.probe_screen_idle_interval_frames.max(1);
            (0..v.grid.probe_count())
                .map(|p| probegi_core::probe_classification::screen_idle_phase(v.world_cell(p), interval))
                .collect::<Vec<u32>>()
        };
        assert!(v.grid.origin_m.x < 0.0 && v.idle_phases().is_none());
        v.keep_idle_phases();
        assert_eq!(v.idle_phases(), Some(direct(&v).as_slice()));
        // Every phase of the interval occurs (the phases are not all one value).
        assert_eq!(direct(&v).iter().collect::<std::collections::BTreeSet<_>>().len(), 8);
        assert!(v.scroll_to(Vec3::new(-5.2, -7.3, -9.9)) > 0);
        assert!(v.idle_phases().is_none(), "stale after a scroll");
        v.keep_idle_phases();
        assert_eq!(v.idle_phases(), Some(direct(&v).as_slice()));
        v.settings.probe_screen_idle_interval_frames = 5;
        assert!(v.idle_phases().is_none(), "stale for another interval");
        v.keep_idle_phases();
        assert_eq!(v.idle_phases(), Some(direct(&v).as_slice()));
        let mut jcgt = DdgiVolume::placed(
            DdgiVolumeSettings { probe_states: ProbeStatesMode::Jcgt, ..settings },
            (Vec3::ZERO, Vec3::ONE),
            None,
        );
        jcgt.keep_idle_phases();
        assert!(jcgt.idle_phases().is_none());
    }

    /// A scroll moves every probe's position: its rows draw a new identity
    /// even where no usable flag changes (no probe has blended yet, so none
    /// is usable before or after).
    #[test]
    fn a_scroll_draws_a_new_rows_identity_with_the_usable_flags_unchanged() {
        let settings = DdgiVolumeSettings {
            probe_counts: UVec3::new(4, 3, 4),
            probe_spacing_m: Some(Vec3::splat(0.5)),
            volume_tracks_camera: true,
            ..Default::default()
        };
        let mut v = DdgiVolume::placed(settings, (Vec3::ZERO, Vec3::ONE), Some(Vec3::ZERO));
        let (id, usable, positions) = (v.probe_rows_id.0, v.probe_usable.clone(), v.probe_positions.clone());
        assert!(v.scroll_to(Vec3::new(1.3, 0.0, 0.0)) > 0);
        assert_eq!(v.probe_usable, usable);
        assert_ne!(v.probe_positions, positions);
        assert_ne!(v.probe_rows_id.0, id);
    }

    /// `extend_tracing` with the kept phases gives `traces_in_frame` of every
    /// probe, every frame of the interval, with and without a shadowing field
    /// (an Idle probe then traces in its phase and the frame after) and a
    /// budget's choice, over Requested, Idle, content-less and seeded probes.
    #[test]
    fn every_probes_tracing_flag_is_traces_in_frame() {
        for shadow_field in [false, true] {
            let settings = DdgiVolumeSettings {
                probe_counts: UVec3::new(5, 3, 4),
                probe_states: ProbeStatesMode::Screen,
                shadow_field,
                ..Default::default()
            };
            let mut v = DdgiVolume::new(settings, (Vec3::ZERO, Vec3::splat(3.0)));
            let n = v.grid.probe_count();
            for p in 0..n {
                v.probe_states[p] = if p % 5 == 0 { ProbeState::Requested } else { ProbeState::Idle };
                v.probe_has_history[p] = p % 7 != 3;
                v.probe_seeded[p] = p % 11 == 3;
            }
            v.keep_idle_phases();
            let chosen: Vec<bool> = (0..n).map(|p| p % 4 != 1).collect();
            let mut idle_traced = 0;
            for frame in 0..2 * v.settings.probe_screen_idle_interval_frames + 1 {
                for budget in [None, Some(chosen.as_slice())] {
                    let mut fast = Vec::new();
                    v.extend_tracing(&mut fast, frame, v.idle_phases(), budget);
                    let each: Vec<bool> =
                        (0..n).map(|p| v.traces_in_frame(p, frame, None) && budget.is_none_or(|c| c[p])).collect();
                    assert_eq!(fast, each, "frame {frame}, shadow field {shadow_field}");
                    idle_traced += (0..n).filter(|&p| fast[p] && v.probe_states[p] == ProbeState::Idle).count();
                }
            }
            assert!(idle_traced > 0 && idle_traced < 17 * n, "{idle_traced}");
        }
    }

    #[test]
    fn edge_buffers_are_the_planes_nearest_the_faces_the_window_scrolled_toward() {
        let settings = DdgiVolumeSettings {
            probe_counts: UVec3::new(6, 4, 5),
            probe_spacing_m: Some(Vec3::ONE),
            volume_tracks_camera: true,
            volume_edge_buffer_planes: 2,
            ..Default::default()
        };
        let mut v = DdgiVolume::placed(settings.clone(), (Vec3::ZERO, Vec3::ONE), Some(Vec3::ZERO));
        let buffered = |v: &DdgiVolume| (0..v.grid.probe_count()).filter(|&p| v.in_edge_buffer(p)).collect::<Vec<_>>();
        assert!(buffered(&v).is_empty(), "a window that never scrolled has no leading face");
        // Toward +x, then toward −z: the two +x planes and the two −z planes.
        assert!(v.scroll_to(Vec3::new(3.0, 0.0, 0.0)) > 0);
        assert!(v.scroll_to(Vec3::new(3.0, 0.0, -2.0)) > 0);
        let want: Vec<usize> = (0..v.grid.probe_count())
            .filter(|&p| {
                let c = v.grid.probe_coords(p);
                c.x >= 4 || c.z < 2
            })
            .collect();
        assert_eq!(buffered(&v), want);
        assert_eq!(want.len(), 2 * 4 * 5 + 6 * 4 * 2 - 2 * 4 * 2);
        // Off, or a fixed volume: none.
        v.settings.volume_edge_buffer_planes = 0;
        assert!(buffered(&v).is_empty());
        let fixed = DdgiVolumeSettings { volume_tracks_camera: false, ..settings };
        let mut f = DdgiVolume::placed(fixed, (Vec3::ZERO, Vec3::ONE), None);
        assert_eq!(f.scroll_to(Vec3::splat(5.0)), 0);
        assert!(buffered(&f).is_empty());
    }
}
