//! Update planning: the frame's rays (`probe_ray_gen`) for the probes whose state
//! traces (jcgt: not Off or Sleeping; usage: all), and the acceptance of the
//! frame's hits, from a host batch or from the device. With the usage scheme the
//! hits' usage counts classify every probe `probe_usage_lag_updates` batches
//! later (see `usage_states`); the accepted hits mark which rays' radiance the
//! blend needs.

use probegi_core::ddgi_settings::ProbeStatesMode;
use probegi_core::probe_classification::{ProbeState, ProbeUsageCounts, probe_usage};

use crate::probe_ray_gen::generate_probe_rays;
use crate::seam::{ProbeRayBatch, ProbeRayHit};

use super::{DdgiVolume, VolumeFrame};

impl DdgiVolume {
    /// Adds the frame's update rays (seed 003 §4.2) of the probes whose state
    /// traces (and, under a ray budget, that it chose), and decides which
    /// probes update this frame.
    pub(crate) fn plan_update(
        &mut self,
        frame: &mut VolumeFrame,
        seed: u64,
        frame_index: u32,
        volume: u32,
        batch: &mut ProbeRayBatch,
    ) {
        self.settle_steady_counts();
        let probes = self.grid.probe_count();
        let interval = self.settings.probe_sleeping_update_interval;
        // The frame's per-probe arrays reuse last frame's storage: a still
        // field's planning allocates nothing per probe.
        self.keep_idle_phases();
        frame.tracing.clear();
        self.extend_tracing(&mut frame.tracing, frame_index, self.idle_phases(), frame.budget_traces.as_deref());
        self.screen_blend_frames(frame);
        self.count_untraced_frames(frame);
        frame.active.clear();
        // One match a state, not one a probe.
        let updates = ProbeState::updates_in_frame_table(frame_index, interval);
        frame.active.extend(self.probe_states.iter().map(|&s| updates[s as usize]));
        frame.rays = generate_probe_rays(&self.settings, self.stream_seed(seed), frame_index);
        frame.ray_count = frame.rays.dirs.len();
        frame.first_ray.clear();
        frame.first_ray.resize(probes, u32::MAX);
        let first_probe = batch.probes.len() as u32;
        let max_m = self.settings.probe_max_ray_distance_m;
        let planned = frame.tracing.iter().zip(&mut frame.first_ray).zip(&self.probe_positions);
        for (p, ((_, first), &origin)) in planned.enumerate().filter(|(_, ((t, _), _))| **t) {
            *first = batch.push_probe(volume, p as u32, origin, &frame.rays.dirs, max_m);
        }
        batch.generated.push(crate::seam::GeneratedProbeRays {
            volume,
            first_probe,
            probe_count: batch.probes.len() as u32 - first_probe,
            rays_per_probe: frame.ray_count as u32,
            rotation: crate::probe_ray_gen::probe_ray_rotation(self.stream_seed(seed), frame_index),
            max_distance_m: self.settings.probe_max_ray_distance_m,
            plan_id: Some(crate::device_plans::next_plan_id()),
        });
        self.traced_probes_last = (batch.probes.len() as u32 - first_probe) as usize;
    }

    /// After the trace: the usage scheme's counts from the hits queued, and the
    /// classification of a batch now due (seed 003 §6.1), then which rays the caller must shade (those of probes that update
    /// this frame, except backface hits, whose radiance is zero by rule).
    pub(crate) fn accept_update_hits(
        &mut self,
        frame: &mut VolumeFrame,
        frame_index: u32,
        batch: u64,
        hits: &[ProbeRayHit],
        needs_radiance: &mut [bool],
    ) {
        let n = frame.ray_count;
        if self.settings.probe_states == ProbeStatesMode::Usage {
            let cage_diagonal = self.grid.spacing_m.length();
            let counts: Vec<Option<ProbeUsageCounts>> = frame
                .first_ray
                .iter()
                .map(|&first| {
                    (first != u32::MAX).then(|| {
                        let rays = &hits[first as usize..first as usize + n];
                        probe_usage(rays.iter().map(|h| h.distance_m), cage_diagonal)
                    })
                })
                .collect();
            self.queue_usage(frame, frame_index, batch, counts);
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
    /// batch `batch`'s usage counts stay there for now (under the usage
    /// scheme), and `earlier_counts` holds those of earlier batches that came
    /// back, by batch number, per probe seed 003's (usage, relevant, backfaces) counted there
    /// (`probegi_core::probe_classification::probe_usage`; `None` where the
    /// probe did not trace). Which probes blend is then `frame.active`; the
    /// device zeroes backface radiance itself.
    pub(crate) fn accept_device_hits(
        &mut self,
        frame: &mut VolumeFrame,
        frame_index: u32,
        batch: u64,
        earlier_counts: Vec<(u64, Vec<Option<ProbeUsageCounts>>)>,
    ) {
        if self.settings.probe_states == ProbeStatesMode::Usage {
            self.queue_device_usage(frame, frame_index, batch, earlier_counts);
        }
    }
}
