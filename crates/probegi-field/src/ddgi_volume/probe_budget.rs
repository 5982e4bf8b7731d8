//! The volume's share of the ray budget (`crate::ray_budget`): its candidates
//! with their priorities and floor, and each probe's change
//! (`probegi_core::probe_change`), as the host blend reports it or as the
//! device measured it.

use probegi_core::probe_change::probe_change;

use crate::ray_budget::BudgetCandidate;

use super::{DdgiVolume, VolumeFrame};

impl DdgiVolume {
    /// Appends this volume's probes whose state traces, with their priority
    /// and whether the floor makes them trace.
    pub(crate) fn budget_candidates(&self, volume: u32, out: &mut Vec<BudgetCandidate>) {
        let interval = self.settings.ray_budget_max_interval_frames;
        // While a scene event's window lasts (seed 004 §4.3: 4–10 frames), every
        // probe counts as fully changed: the budget visits them in turn,
        // longest-waiting first, so light that fades through the bounces is
        // followed everywhere, not only where the first blend saw it change.
        let change = if self.irradiance_events.is_empty() && self.visibility_events.is_empty() {
            self.neighbourhood_change()
        } else {
            vec![1.0; self.grid.probe_count()]
        };
        for (p, state) in self.probe_states.iter().enumerate() {
            if !state.traces() {
                continue;
            }
            let age = self.probe_untraced_frames[p].saturating_add(1);
            out.push(BudgetCandidate {
                volume,
                probe: p as u32,
                rays: self.settings.probe_rays_per_probe,
                change: change[p],
                age_frames: age,
                mandatory: !self.probe_has_history[p] || state.is_new() || age >= interval,
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
                            m = m.max(self.probe_change[grid.probe_index(n.as_uvec3())]);
                        }
                    }
                }
                m
            })
            .collect()
    }

    /// Per probe, the frames its blend this frame stands for: under a budget
    /// with `ray_budget_hysteresis_per_frame`, the frames since it last blended
    /// (capped at the floor's interval), so that each texel's hysteresis, after
    /// Listing 3, is raised to that power; else 1.
    pub(super) fn blend_frames(&self, frame: &VolumeFrame) -> Vec<u32> {
        if frame.budget_traces.is_none() || !self.settings.ray_budget_hysteresis_per_frame {
            return vec![1; self.grid.probe_count()];
        }
        let cap = self.settings.ray_budget_max_interval_frames;
        self.probe_unblended_frames.iter().map(|n| n.saturating_add(1).min(cap)).collect()
    }

    /// Every probe counts as fully changed until it traces again (a scene event).
    pub(super) fn mark_all_changed(&mut self) {
        self.probe_change.fill(1.0);
    }

    /// Probes inside `aabbs` grown by a cell (moving objects' boxes) count as
    /// fully changed until they trace again: under a ray budget they trace
    /// before the still ones. Returns how many.
    pub fn mark_changed_near(&mut self, aabbs: &[(glam::Vec3, glam::Vec3)]) -> usize {
        let grow = self.grid.spacing_m;
        let mut marked = 0;
        for (p, pos) in self.probe_positions.iter().enumerate() {
            if aabbs.iter().any(|&(lo, hi)| probegi_core::probe_classification::inside_grown_aabb(*pos, lo, hi, grow)) {
                self.probe_change[p] = 1.0;
                marked += 1;
            }
        }
        marked
    }

    /// Counts the frames since each probe last traced, after `frame` was planned.
    pub(super) fn count_untraced_frames(&mut self, frame: &VolumeFrame) {
        for (n, &traced) in self.probe_untraced_frames.iter_mut().zip(&frame.tracing) {
            *n = if traced { 0 } else { n.saturating_add(1) };
        }
    }

    /// The changes a host blend reported (`probegi_core::probe_change`):
    /// per probe, its irradiance change if it blended and its occlusion
    /// change if its occlusion tile blended.
    pub(super) fn record_change(&mut self, irradiance: &[Option<f32>], occlusion: &[Option<f32>]) {
        for (p, o) in occlusion.iter().enumerate() {
            if let Some(o) = o {
                self.probe_occlusion_change[p] = *o;
            }
        }
        for (p, e) in irradiance.iter().enumerate() {
            if let Some(e) = e {
                let occ = self.shadow.is_some().then(|| self.probe_occlusion_change[p]);
                self.probe_change[p] = probe_change(*e, occ);
            }
        }
    }

    /// The change a device measured for each probe it blended, in increasing
    /// probe order (`DeviceVolumeBlend::measure_change`; the larger of the
    /// irradiance and last occlusion change, as [`Self::record_change`] keeps it).
    pub(super) fn accept_device_change(&mut self, updated: &[bool], change: &[f32]) {
        let blended = updated.iter().enumerate().filter(|(_, u)| **u).map(|(p, _)| p);
        for (p, &c) in blended.zip(change) {
            self.probe_change[p] = probe_change(c, None);
        }
    }
}
