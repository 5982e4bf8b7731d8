//! Steady frames: a still volume's update plan kept from one frame to the next
//! (issue 45, "the host off the critical path").
//!
//! Not a pass of the seeds, and no change to one: the plan kept is the one
//! seed 003 §4.2 and seed 004 Listing 5's states make (which probes trace and
//! blend, with seed 004 Listing 3's hysteresis), made once instead of every
//! frame while its inputs stand still. No parameter: it is on by default and
//! gives the same plans (`DdgiFieldSet::set_steady_plans` turns it off).
//!
//! Under the all-active and jcgt schemes a probe's state decides alone
//! whether it traces and blends, and a probe in a lasting state (Active, Off,
//! Sleeping, Awake, Vigilant) that has blended before keeps its state,
//! history and hysteresis through the update. So when a volume's plan inputs
//! (states, histories, hysteresis, positions, grid, window edges, settings;
//! no probe seeded or reset) are what they were when its last plan was made, this frame's plan
//! is that plan with the frame's ray rotation: which probes trace, their
//! first rays, which blend and with what hysteresis. The set then keeps its
//! batch and the volume's blend plan, and the host visits no probe but to
//! count the frames its counters count (`probe_budget`), instead of planning,
//! classifying and bookkeeping each probe again.
//!
//! Those counters (frames since a probe traced, frames in a row it traced,
//! frames its blend waited, its blends) move by the same step every kept
//! frame, so a kept frame only counts itself ([`OwedCounts`]); they are
//! brought up to date, probe by probe, before anything else reads or writes
//! them: a full plan, an initialisation round, a probe's reset, the ray
//! budget's choice ([`DdgiVolume::settle_steady_counts`]). A volume's
//! derived `Debug` and `Clone` see the counters as held, with what is owed
//! beside them: settle first to compare two volumes whole.
//!
//! The check is a comparison with a snapshot taken at the last full plan
//! (the positions by their identity, `DdgiVolume::probe_rows_id`, which every
//! write to them, a clone and `DdgiFieldSet::volumes_mut` draw anew, not a
//! copy),
//! kept by the set beside the plan (a volume swapped or restored into
//! another's place meets another's snapshot), so a change through the set
//! or through the volume's public fields makes the next plan a full one; so
//! does an update left unfinished (the snapshot stands for a plan whose
//! blend ran). Left out (always a full plan): the usage and
//! screen schemes (their states move with the hits and the camera; but see
//! below), a ray budget (its choice moves every frame), the shadowing field
//! (its pairs of frames), the per-probe hysteresis ramp (a probe's cap moves
//! with its blends), probes reset or seeded since the last blend, and Newly
//! Awake / Newly Vigilant probes.
//!
//! **The usage scheme's kept trace.** Under the usage scheme every probe
//! traces every frame (seed 003 §6.1: Dead probes too, to see them
//! uncovered), while the states, and so which probes blend and with what
//! hysteresis, move with the counts every frame. Its trace plan alone is
//! kept ([`TraceSnapshot`]): where every probe of every volume still traces
//! and the positions, grid, window edges and settings are as at the last
//! full plan, the batch keeps its probes, first rays and records'
//! identities (`GeneratedProbeRays::plan_id`, so a device keeps the ray
//! generation's and the usage pass's records) with the frame's rotation, and
//! the rest of the update (the classification, which probes need radiance,
//! the blend plan, the bookkeeping after the blend) runs in full, as it
//! would have.

use glam::IVec3;
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::probe_classification::ProbeState;
use probegi_core::probe_grid::ProbeGrid;

use super::{DdgiVolume, VolumeFrame};

/// What a volume's update plan read when it was made (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct PlanSnapshot {
    states: Vec<ProbeState>,
    has_history: Vec<bool>,
    hysteresis: Vec<f32>,
    /// The positions' identity (`DdgiVolume::probe_rows_id`, drawn anew by
    /// every write to them and by `DdgiFieldSet::volumes_mut`), in place of
    /// a copy: the largest of the arrays, compared every still frame.
    probe_rows_id: u64,
    grid: ProbeGrid,
    scroll_leading: IVec3,
    stream: u64,
    settings: DdgiVolumeSettings,
}

/// What a volume's last full update plan read for its trace alone, under the
/// usage scheme (see the module docs): with every probe tracing, its batch
/// entries depend on nothing else. The positions are a copy, compared bit
/// for bit, not the rows' identity (`DdgiVolume::probe_rows_id`), which the
/// usable flags renew as the states move.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct TraceSnapshot {
    probe_positions: Vec<glam::Vec3>,
    grid: ProbeGrid,
    scroll_leading: IVec3,
    stream: u64,
    settings: DdgiVolumeSettings,
}

/// The frame counters a run of kept frames owes a volume: how many kept
/// frames were planned (they count the frames since each probe traced and
/// the frames in a row it traced) and how many of them blended (the frames
/// each probe's blend waited, and its blends), with the kept plan's flags per
/// probe ([`STEADY_TRACED`], [`STEADY_ACTIVE`], [`STEADY_BLENDED`]).
/// Adding `n` frames at once gives what `n` frames one by one give: each
/// counter either restarts every frame or adds the same step, saturating.
#[derive(Clone, Debug)]
pub(crate) struct OwedCounts {
    planned: u32,
    blended: u32,
    flags: std::sync::Arc<[u8]>,
}

/// [`OwedCounts`]'s flag: the probe traces in the kept plan.
const STEADY_TRACED: u8 = 1;
/// The probe's state wants a blend in the kept plan (`VolumeFrame::active`).
const STEADY_ACTIVE: u8 = 2;
/// The probe blends in the kept plan (`VolumeFrame::blends`).
const STEADY_BLENDED: u8 = 4;

impl OwedCounts {
    /// Probe `p`'s frames since it traced, from `counted` (what the volume
    /// holds) and what is owed.
    pub(crate) fn untraced(&self, p: usize, counted: u32) -> u32 {
        match (self.flags[p] & STEADY_TRACED != 0, self.planned) {
            (_, 0) => counted,
            (true, _) => 0,
            (false, n) => counted.saturating_add(n),
        }
    }
}

/// A kept plan's per-probe flags for [`OwedCounts`].
fn steady_flags(frame: &VolumeFrame) -> std::sync::Arc<[u8]> {
    let planned = frame.tracing.iter().zip(&frame.active).zip(&frame.first_ray);
    planned
        .map(|((&traced, &active), &first)| {
            let blended = active && first != u32::MAX;
            traced as u8 * STEADY_TRACED + active as u8 * STEADY_ACTIVE + blended as u8 * STEADY_BLENDED
        })
        .collect()
}

/// A slice's bytes: floats compared bit for bit (stricter than `==`, and a
/// memory comparison rather than one per float).
fn bits<T: bytemuck::Pod>(values: &[T]) -> &[u8] {
    bytemuck::cast_slice(values)
}

/// Whether two probes' state lists are equal: compared whole, without the
/// early exit of `==` on a slice of enums, so the loop vectorises (a still
/// field compares every probe's state every frame).
fn same_states(a: &[ProbeState], b: &[ProbeState]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(true, |same, (x, y)| same & (*x as u8 == *y as u8))
}

/// Whether a probe in `state` keeps it through an update, traces and blends
/// on the same frames whatever the frame, and keeps its hysteresis.
fn lasting(state: ProbeState) -> bool {
    matches!(
        state,
        ProbeState::Active | ProbeState::Off | ProbeState::Sleeping | ProbeState::Awake | ProbeState::Vigilant
    )
}

impl DdgiVolume {
    /// The snapshot of the plan just made, where a later frame may reuse it
    /// (`None` where the volume's scheme or state rules that out).
    pub(crate) fn steady_snapshot(&self) -> Option<PlanSnapshot> {
        let s = &self.settings;
        let scheme = matches!(s.probe_states, ProbeStatesMode::AllActive | ProbeStatesMode::Jcgt);
        let eligible = scheme
            && self.initialized
            && s.ray_budget == 0
            && self.shadow.is_none()
            && !s.probe_hysteresis_ramp
            && self.probes_reset_since_blend.is_empty()
            && self.pending_seeds.is_empty()
            && !self.probe_seeded.iter().any(|s| *s)
            && !self.probe_pending_init.iter().any(|p| *p)
            && self.probe_states.iter().all(|s| lasting(*s));
        eligible.then(|| PlanSnapshot {
            states: self.probe_states.clone(),
            has_history: self.probe_has_history.clone(),
            hysteresis: self.probe_hysteresis.clone(),
            probe_rows_id: self.probe_rows_id.0,
            grid: self.grid,
            scroll_leading: self.scroll_leading,
            stream: self.stream,
            settings: self.settings.clone(),
        })
    }

    /// Whether this frame's plan would be the last one's (with the frame's
    /// rotation): the volume is as its snapshot says. (A probe whose first
    /// blend was in that plan has a history now, and so differs from it.)
    pub(crate) fn plan_is_steady(&self, frame: &VolumeFrame) -> bool {
        let Some(snap) = frame.plan_snapshot.as_ref() else { return false };
        let unchanged = same_states(&snap.states, &self.probe_states)
            && snap.has_history == self.probe_has_history
            && bits(&snap.hysteresis) == bits(&self.probe_hysteresis)
            && snap.probe_rows_id == self.probe_rows_id.0
            && snap.grid == self.grid
            && snap.scroll_leading == self.scroll_leading
            && snap.stream == self.stream
            && snap.settings == self.settings;
        unchanged
            && self.shadow.is_none()
            && self.probes_reset_since_blend.is_empty()
            && self.pending_seeds.is_empty()
            && frame.first_ray.len() == self.grid.probe_count()
    }

    /// The trace snapshot of the plan just made in `frame` (or none): the
    /// usage scheme, initialised, every probe tracing, no ray budget and no
    /// shadowing field.
    fn trace_snapshot(&self, frame: &VolumeFrame) -> Option<TraceSnapshot> {
        let s = &self.settings;
        let eligible = s.probe_states == ProbeStatesMode::Usage
            && self.initialized
            && s.ray_budget == 0
            && self.shadow.is_none()
            && !self.probe_pending_init.iter().any(|p| *p)
            && frame.tracing.len() == self.grid.probe_count()
            && frame.tracing.iter().all(|t| *t)
            && frame.first_ray.len() == self.grid.probe_count();
        eligible.then(|| TraceSnapshot {
            probe_positions: self.probe_positions.clone(),
            grid: self.grid,
            scroll_leading: self.scroll_leading,
            stream: self.stream,
            settings: self.settings.clone(),
        })
    }

    /// Whether this frame's trace plan would be the last one's (with the
    /// frame's rotation): every probe still traces, and the volume is as its
    /// trace snapshot says.
    pub(crate) fn trace_plan_is_steady(&self, frame: &VolumeFrame) -> bool {
        let Some(snap) = frame.trace_snapshot.as_ref() else { return false };
        bits(&snap.probe_positions) == bits(&self.probe_positions)
            && snap.grid == self.grid
            && snap.scroll_leading == self.scroll_leading
            && snap.stream == self.stream
            && snap.settings == self.settings
            && self.shadow.is_none()
            && frame.first_ray.len() == self.grid.probe_count()
            && !self.probe_pending_init.iter().any(|p| *p)
            && self.probe_states.iter().all(|s| s.traces())
    }

    /// A kept trace plan's frame (the usage scheme, module docs): what
    /// `plan_update` does but for the batch, whose probes and first rays stay:
    /// the frame counters, which probes' states want a blend this frame, and
    /// the frame's rays. Returns the frame's rotation.
    pub(crate) fn plan_kept_trace_update(
        &mut self,
        frame: &mut VolumeFrame,
        seed: u64,
        frame_index: u32,
    ) -> glam::Quat {
        self.settle_steady_counts();
        self.count_untraced_frames(frame);
        // Every probe traces (the snapshot's and the check's condition).
        self.traced_probes_last = self.grid.probe_count();
        let updates = ProbeState::updates_in_frame_table(frame_index, self.settings.probe_sleeping_update_interval);
        frame.active.clear();
        frame.active.extend(self.probe_states.iter().map(|&s| updates[s as usize]));
        let stream = self.stream_seed(seed);
        frame.rays = crate::probe_ray_gen::generate_probe_rays(&self.settings, stream, frame_index);
        debug_assert_eq!(frame.ray_count, frame.rays.dirs.len());
        crate::probe_ray_gen::probe_ray_rotation(stream, frame_index)
    }

    /// Forgets the snapshots (and `frame`'s kept blend plan): the next plan
    /// is a full one.
    pub(crate) fn forget_plan_snapshot(frame: &mut VolumeFrame) {
        frame.plan_snapshot = None;
        frame.trace_snapshot = None;
        frame.steady_blend = None;
        frame.steady_flags = None;
    }

    /// Takes the snapshot of the plan just made (or none) into `frame`.
    pub(crate) fn keep_plan_snapshot(&self, frame: &mut VolumeFrame) {
        frame.plan_snapshot = self.steady_snapshot();
        frame.trace_snapshot = self.trace_snapshot(frame);
        frame.steady_blend = None;
        frame.steady_flags = None;
    }

    /// A steady frame's plan: the frame's rays (the rotation turns every
    /// frame) and the frames since each probe traced, with the last plan's
    /// tracing probes, first rays and blends. Returns the frame's rotation.
    pub(crate) fn plan_steady_update(&mut self, frame: &mut VolumeFrame, seed: u64, frame_index: u32) -> glam::Quat {
        let stream = self.stream_seed(seed);
        frame.rays = crate::probe_ray_gen::generate_probe_rays(&self.settings, stream, frame_index);
        debug_assert_eq!(frame.ray_count, frame.rays.dirs.len());
        if frame.steady_blend.is_none() {
            let (base, _, _) = self.blend_plan_with(frame, false);
            frame.steady_blend = Some(super::blend_inputs::device_entries(base));
            frame.steady_blend_id = crate::device_plans::next_plan_id();
            frame.steady_flags = Some(steady_flags(frame));
        }
        self.owe_steady_frame(frame, true);
        crate::probe_ray_gen::probe_ray_rotation(stream, frame_index)
    }

    /// Counts a kept frame in [`OwedCounts`]: planned (`planning`) or
    /// blended. Counters owed for another kept plan are settled first.
    fn owe_steady_frame(&mut self, frame: &VolumeFrame, planning: bool) {
        let Some(flags) = frame.steady_flags.as_ref() else {
            // Not reached (a kept plan's first frame makes the flags); count eagerly.
            self.settle_steady_counts();
            match planning {
                true => self.count_untraced_frames(frame),
                false => self.count_blended_frames(frame),
            }
            return;
        };
        if self.steady_owed.as_ref().is_some_and(|o| !std::sync::Arc::ptr_eq(&o.flags, flags)) {
            self.settle_steady_counts();
        }
        let owed = self.steady_owed.get_or_insert_with(|| OwedCounts { planned: 0, blended: 0, flags: flags.clone() });
        match planning {
            true => owed.planned += 1,
            false => owed.blended += 1,
        }
    }

    /// Brings the frame counters that a run of kept plans (module docs) left
    /// owing up to date: each probe's frames since it traced, frames in a row
    /// it traced, frames its blend waited and blends. The volume does this
    /// itself before anything else reads or writes them; a caller that
    /// compares two volumes whole (their `Debug`) calls it first.
    pub fn settle_steady_counts(&mut self) {
        let Some(OwedCounts { planned, blended, flags }) = self.steady_owed.take() else { return };
        for (p, &f) in flags.iter().enumerate() {
            let (traced, active, blends) = (f & STEADY_TRACED != 0, f & STEADY_ACTIVE != 0, f & STEADY_BLENDED != 0);
            if planned > 0 {
                let untraced = &mut self.probe_untraced_frames[p];
                *untraced = if traced { 0 } else { untraced.saturating_add(planned) };
                let run = &mut self.probe_trace_run[p];
                *run = if traced { run.saturating_add(planned) } else { 0 };
            }
            if blended > 0 {
                let waited = &mut self.probe_unblended_frames[p];
                *waited = if blends { 0 } else { waited.saturating_add(active as u32 * blended) };
                self.probe_blends[p] = self.probe_blends[p].saturating_add(blends as u32 * blended);
            }
        }
    }

    /// A frame's blend counters, one frame at once: the frames each probe's
    /// blend waited, and its blends (`after_update`'s, for a probe with a history).
    fn count_blended_frames(&mut self, frame: &VolumeFrame) {
        self.count_unblended_frames(frame);
        let planned = frame.active.iter().zip(&frame.first_ray);
        for (b, (&active, &first)) in self.probe_blends.iter_mut().zip(planned) {
            *b = b.saturating_add((active && first != u32::MAX) as u32);
        }
    }

    /// A steady frame's bookkeeping after its blend (`after_update`'s, where
    /// no state, history or hysteresis moves): the blend counts, the frames a
    /// probe waited, and the scene events' remaining frames.
    pub(crate) fn accept_steady_blend(&mut self, frame: &VolumeFrame) {
        self.frames_updated += 1;
        self.owe_steady_frame(frame, false);
        self.tick_scene_events();
    }
}
