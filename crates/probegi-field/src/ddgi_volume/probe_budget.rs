//! The volume's share of the ray budget (`crate::ray_budget`): its candidates
//! with their priorities and floor, and each probe's change
//! (`probegi_core::probe_change`), as the host blend reports it or as the
//! device measured it.
//!
//! Deliberate deviation: a blend's changes are recorded
//! `ray_budget_change_lag_updates` batches after it (default 2; 0 is seed
//! 003 §8.2's next plan). A device measures them after its blend and the
//! host reads them back that late, so an update never waits on the device
//! for them; the host blend holds its own as long, so both backends choose
//! the same probes. A probe marked changed since a blend (a reset, a scene
//! event, a moving object nearby) keeps its mark against that blend's
//! change.

use probegi_core::probe_change::probe_change;
use probegi_core::probe_classification::ProbeState;

use crate::ray_budget::BudgetCandidate;

use super::{DdgiVolume, VolumeFrame};

impl DdgiVolume {
    /// Appends this volume's probes whose state traces, with their priority
    /// and whether the floor makes them trace in frame `frame_index`.
    /// - A probe whose state does not blend this frame (usage scheme: DEAD, or
    ///   SLEEPING off its interval) traces only for its classification: change
    ///   0, at the floor. A SLEEPING probe on its interval frame is its own
    ///   schedule's amortisation and traces whatever the budget.
    /// - With a shadowing field a probe that traced last frame alone counts as
    ///   fully changed: its occlusion maps blend from the surfels of the frame
    ///   before, so a probe needs two frames in a row to update them, and a
    ///   floor update comes in pairs where the budget leaves room (ties go to
    ///   the longer wait, so a scene event's round still comes first).
    pub(crate) fn budget_candidates(&self, volume: u32, frame_index: u32, out: &mut Vec<BudgetCandidate>) {
        let interval = self.settings.ray_budget_max_interval_frames;
        let sleep = self.settings.probe_sleeping_update_interval;
        // While a scene event's window lasts (seed 004 §4.3: 4–10 frames), every
        // probe counts as fully changed: the budget visits them in turn,
        // longest-waiting first, so light that fades through the bounces is
        // followed everywhere, not only where the first blend saw it change.
        let change = if self.irradiance_events.is_empty() && self.visibility_events.is_empty() {
            self.neighbourhood_change()
        } else {
            vec![1.0; self.grid.probe_count()]
        };
        let phases = self.idle_phases();
        for (p, state) in self.probe_states.iter().enumerate() {
            if !self.traces_in_frame(p, frame_index, phases) {
                continue;
            }
            let age = self.probe_untraced_frames[p].saturating_add(1);
            let blends = state.updates_in_frame(frame_index, sleep);
            let own_schedule = *state == ProbeState::UsageSleeping && blends;
            let shadow_pair = self.shadow.is_some() && self.probe_trace_run[p] == 1;
            let floor = !self.probe_has_history[p] || state.is_new() || age >= interval;
            out.push(BudgetCandidate {
                volume,
                probe: p as u32,
                rays: self.settings.probe_rays_per_probe,
                change: match (blends, shadow_pair) {
                    (false, _) => 0.0,
                    (true, true) => 1.0,
                    (true, false) => change[p],
                },
                age_frames: age,
                mandatory: floor || own_schedule,
            });
        }
    }

    /// Per probe, the largest last change of it and its six grid neighbours:
    /// light that changed at one probe has likely changed at the next, which
    /// then traces before its own age would let it (`crate::ray_budget`).
    fn neighbourhood_change(&self) -> Vec<f32> {
        let grid = &self.grid;
        let counts = grid.probe_counts.as_ivec3();
        (0..grid.probe_count())
            .map(|p| {
                let c = grid.probe_coords(p).as_ivec3();
                let mut m = self.probe_change[p];
                for axis in 0..3 {
                    for step in [-1, 1] {
                        let mut n = c;
                        n[axis] += step;
                        if n[axis] >= 0 && n[axis] < counts[axis] {
                            let q = grid.probe_index(n.as_uvec3());
                            // Only neighbours that measure: one that never blends keeps its
                            // initial 1 and would pin its neighbours at the top.
                            if self.probe_states[q].traces() && self.probe_has_history[q] {
                                m = m.max(self.probe_change[q]);
                            }
                        }
                    }
                }
                m
            })
            .collect()
    }

    /// Per probe, the frames its blend this frame stands for: under the screen
    /// scheme the frames since it last traced, capped at the idle interval
    /// (`screen_requests`); under a budget
    /// with `ray_budget_hysteresis_per_frame`, the frames since it last blended
    /// (capped at the floor's interval), so that each texel's hysteresis, after
    /// Listing 3, is raised to that power; else 1.
    pub(super) fn blend_frames(&self, frame: &VolumeFrame) -> Vec<u32> {
        self.blend_frames_beyond_one(frame).unwrap_or_else(|| vec![1; self.grid.probe_count()])
    }

    /// [`Self::blend_frames_beyond_one`] for a device plan: the screen
    /// scheme's frames borrowed from `frame`, none where every blend stands
    /// for one frame.
    pub(super) fn blend_frames_borrowed<'a>(&self, frame: &'a VolumeFrame) -> std::borrow::Cow<'a, [u32]> {
        if !frame.screen_blend_frames.is_empty() {
            return std::borrow::Cow::Borrowed(&frame.screen_blend_frames);
        }
        self.blend_frames_beyond_one(frame).unwrap_or_default().into()
    }

    /// [`Self::blend_frames`], or `None` where every probe's blend stands for
    /// one frame (no screen scheme, no budget's waits): a device plan then
    /// carries no per-probe array for it (`DeviceVolumeBlend::probe_blend_frames`
    /// empty).
    pub(super) fn blend_frames_beyond_one(&self, frame: &VolumeFrame) -> Option<Vec<u32>> {
        if !frame.screen_blend_frames.is_empty() {
            return Some(frame.screen_blend_frames.clone());
        }
        if frame.budget_traces.is_none() || !self.settings.ray_budget_hysteresis_per_frame {
            return None;
        }
        let cap = self.settings.ray_budget_max_interval_frames;
        Some(self.probe_unblended_frames.iter().map(|n| n.saturating_add(1).min(cap)).collect())
    }

    /// Every probe counts as fully changed until it traces again (a scene event).
    pub(super) fn mark_all_changed(&mut self) {
        self.probe_change.fill(1.0);
        self.probe_change_from_batch.fill(self.change_pending.next_batch());
    }

    /// Probe `p` counts as fully changed until it blends again: the changes
    /// of blends before now, still on their way, no longer count for it.
    pub(super) fn mark_changed(&mut self, p: usize) {
        self.probe_change[p] = 1.0;
        self.probe_change_from_batch[p] = self.change_pending.next_batch();
    }

    /// Probes inside `aabbs` grown by a cell (moving objects' boxes) count as
    /// fully changed until they trace again: under a ray budget they trace
    /// before the still ones. Returns how many.
    pub fn mark_changed_near(&mut self, aabbs: &[(glam::Vec3, glam::Vec3)]) -> usize {
        let grow = self.grid.spacing_m;
        let mut marked = Vec::new();
        for (p, pos) in self.probe_positions.iter().enumerate() {
            if aabbs.iter().any(|&(lo, hi)| probegi_core::probe_classification::inside_grown_aabb(*pos, lo, hi, grow)) {
                marked.push(p);
            }
        }
        marked.iter().for_each(|&p| self.mark_changed(p));
        marked.len()
    }

    /// Counts the frames since each probe last traced, and how many frames in
    /// a row it has traced, after `frame` was planned.
    pub(super) fn count_untraced_frames(&mut self, frame: &VolumeFrame) {
        for (n, &traced) in self.probe_untraced_frames.iter_mut().zip(&frame.tracing) {
            *n = if traced { 0 } else { n.saturating_add(1) };
        }
        for (run, &traced) in self.probe_trace_run.iter_mut().zip(&frame.tracing) {
            *run = if traced { run.saturating_add(1) } else { 0 };
        }
    }

    /// After a blend: a probe that blended (`VolumeFrame::blends`) starts
    /// counting again; one its state wanted to blend (`frame.active`) but the
    /// budget held back counts the frame (so the frames its next blend stands
    /// for are the budget's alone, not its state's own schedule).
    pub(super) fn count_unblended_frames(&mut self, frame: &VolumeFrame) {
        let planned = frame.active.iter().zip(&frame.first_ray);
        for (n, (&active, &first)) in self.probe_unblended_frames.iter_mut().zip(planned) {
            let blended = active && first != u32::MAX;
            *n = if blended { 0 } else { n.saturating_add(active as u32) };
        }
    }

    /// The changes a host blend of update batch `batch` reported
    /// (`probegi_core::probe_change`): per probe, its irradiance change if it
    /// blended and its occlusion change if its occlusion tile blended;
    /// recorded `ray_budget_change_lag_updates` batches later, budget or not
    /// (a budget switched on finds them; a device measures them only under
    /// one).
    pub(super) fn record_change(&mut self, batch: u64, irradiance: &[Option<f32>], occlusion: &[Option<f32>]) {
        for (p, o) in occlusion.iter().enumerate() {
            if let Some(o) = o {
                self.probe_occlusion_change[p] = *o;
            }
        }
        let (mut probes, mut changes) = (Vec::new(), Vec::new());
        for (p, e) in irradiance.iter().enumerate() {
            if let Some(e) = e {
                let occ = self.shadow.is_some().then(|| self.probe_occlusion_change[p]);
                probes.push(p as u32);
                changes.push(probe_change(*e, occ));
            }
        }
        self.change_pending.push(batch, probes, Some(changes));
        self.record_due_changes();
    }

    /// The changes a device measured after the blend of batch `batch` come
    /// later (`DeviceVolumeBlend::measure_change`): its blended probes are
    /// queued for them, and `earlier` (by batch, each per blended probe in
    /// increasing probe order; the larger of the irradiance and last
    /// occlusion change, as [`Self::record_change`] keeps it) fill their
    /// batches' places.
    pub(super) fn accept_device_change(&mut self, batch: u64, updated: &[bool], earlier: &[(u64, &[f32])]) {
        let probes = updated.iter().enumerate().filter(|(_, u)| **u).map(|(p, _)| p as u32).collect();
        self.change_pending.push(batch, probes, None);
        for &(batch, changes) in earlier {
            self.change_pending.fill(batch, changes.to_vec());
        }
        self.record_due_changes();
    }

    /// Drops the changes still waiting for a device (no budget runs this
    /// frame, so it measures none): when one runs again, it starts from the
    /// changes measured from then on.
    pub(super) fn forget_pending_changes(&mut self) {
        self.change_pending.clear();
    }

    /// One past the last update batch number whose changes were queued.
    pub(crate) fn change_batches(&self) -> u64 {
        self.change_pending.next_batch()
    }

    /// The number of changes batch `batch`'s blend measures (its blended
    /// probes), where the volume waits for them; `None` otherwise.
    pub(crate) fn changes_awaited(&self, batch: u64) -> Option<usize> {
        self.change_pending.waiting(batch).map(Vec::len)
    }

    /// Records the changes of every queued blend now `ray_budget_change_lag_updates`
    /// old (changes that never came, their device gone, record nothing).
    fn record_due_changes(&mut self) {
        for (batch, probes, changes) in self.change_pending.take_due(self.settings.ray_budget_change_lag_updates) {
            for (&p, &c) in probes.iter().zip(&changes) {
                let p = p as usize;
                if p < self.probe_change.len() && batch >= self.probe_change_from_batch[p] {
                    self.probe_change[p] = probe_change(c, None);
                }
            }
        }
    }
}
