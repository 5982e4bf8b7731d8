//! Probe usage states: which probes queries may read (and the fallback table for
//! empty cages), the state counts a caller reports, waking probes near dynamic
//! objects, and the usage scheme's classification of every probe from the
//! hits of an update batch (seed 003 §6.1).
//!
//! Deliberate deviation: the classification reads the usage counts of the
//! batch `probe_usage_lag_updates` batches back (default 2; 0 is seed 003's
//! same-frame rule). A device that keeps the hits counts usage there and the
//! host reads the counts back that late, so an update never waits on the
//! device for them; the host path holds its own counts as long, so every
//! backend gives the same states. Counts traced before a probe was reset
//! (scrolled in, initialised again) describe another place and are dropped
//! for it. A batch whose counts never come (its update failed, or a later
//! update went the host way while the device still held them) classifies
//! nothing: the states hold until the next batch's counts.

use std::collections::BTreeMap;

use glam::Vec3;
use probegi_core::ddgi_query::nearest_usable_probes;
use probegi_core::ddgi_settings::ProbeStatesMode;
use probegi_core::probe_classification::{ProbeState, ProbeUsageCounts, classify_usage, inside_grown_aabb};

use super::{DdgiVolume, VolumeFrame};

impl DdgiVolume {
    /// Recomputes which probes queries may read, and the fallback table if that changed.
    pub(super) fn refresh_usable(&mut self) {
        let mut changed = false;
        // The state's usability (a table) and `probes_have_content`, over the arrays in step.
        let usable = ProbeState::ALL.map(ProbeState::usable_in_queries);
        let screen = self.settings.probe_states == ProbeStatesMode::Screen;
        let content = have_content(&self.probe_has_history, &self.probe_seeded, screen);
        for ((u, &state), content) in self.probe_usable.iter_mut().zip(&self.probe_states).zip(content) {
            let now = usable[state as usize] && content;
            changed |= *u != now;
            *u = now;
        }
        if changed {
            self.probe_fallback = nearest_usable_probes(&self.grid, &self.probe_usable);
            self.renew_probe_rows_id();
        }
    }

    /// Whether probe `p`'s tiles hold light a query may read: it has blended
    /// since its reset or, under the screen scheme, it was seeded (Timberdoodle
    /// PGI's seeded probes wait for their interleaved update; under the other
    /// schemes a seeded probe blends in the frame it was seeded anyway).
    pub(super) fn probe_has_content(&self, p: usize) -> bool {
        self.probe_has_history[p] || (self.probe_seeded[p] && self.settings.probe_states == ProbeStatesMode::Screen)
    }

    /// [`Self::probe_has_content`] of every probe, in probe order, read from
    /// the arrays in step (for loops over every probe each frame).
    pub(super) fn probes_have_content(&self) -> impl Iterator<Item = bool> + '_ {
        let screen = self.settings.probe_states == ProbeStatesMode::Screen;
        have_content(&self.probe_has_history, &self.probe_seeded, screen)
    }

    /// Number of probes per state name.
    pub fn state_counts(&self) -> BTreeMap<&'static str, usize> {
        let mut m = BTreeMap::new();
        for s in &self.probe_states {
            *m.entry(s.name()).or_default() += 1;
        }
        m
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

    /// Usage scheme: queues the counts of the set's update batch `batch` (per
    /// probe, `None` where it did not trace), then classifies from the batch
    /// now `probe_usage_lag_updates` old.
    pub(super) fn queue_usage(
        &mut self,
        frame: &mut VolumeFrame,
        frame_index: u32,
        batch: u64,
        counts: Vec<Option<ProbeUsageCounts>>,
    ) {
        self.usage_pending.push(batch, (), Some(counts));
        self.classify_due_usage(frame, frame_index);
    }

    /// As [`Self::queue_usage`] where batch `batch`'s counts stay on the
    /// device for now: `earlier_counts` are those of earlier batches that came
    /// back, by batch number.
    pub(super) fn queue_device_usage(
        &mut self,
        frame: &mut VolumeFrame,
        frame_index: u32,
        batch: u64,
        earlier_counts: Vec<(u64, Vec<Option<ProbeUsageCounts>>)>,
    ) {
        self.usage_pending.push(batch, (), None);
        for (batch, counts) in earlier_counts {
            self.usage_pending.fill(batch, counts);
        }
        self.classify_due_usage(frame, frame_index);
    }

    /// One past the last update batch number queued (the set numbers its
    /// batches from the largest of its volumes').
    pub(crate) fn usage_batches(&self) -> u64 {
        self.usage_pending.next_batch()
    }

    /// Classifies from every queued batch now `probe_usage_lag_updates` old
    /// (a batch whose counts never came, its device gone, classifies nothing).
    fn classify_due_usage(&mut self, frame: &mut VolumeFrame, frame_index: u32) {
        for (batch, (), counts) in self.usage_pending.take_due(self.settings.probe_usage_lag_updates) {
            self.classify_usage_states(frame, frame_index, batch, &counts);
        }
    }

    /// From the next update batch on, probe `p`'s counts describe it where it
    /// is now: the queued ones are dropped for it (a reset, a new start).
    /// (The set's batch numbers only grow, so the next one is at least
    /// the queue's next.)
    pub(super) fn restart_usage(&mut self, p: usize) {
        self.probe_usage_from_batch[p] = self.usage_pending.next_batch();
    }

    /// Usage scheme (seed 003 §6.1): every probe's state from the usage counts
    /// of update batch `batch` (per probe, `None` when it did not trace), and
    /// which probes blend this frame (see `probegi_core::probe_classification`).
    /// One pass over the per-probe arrays in step, with the frame's blending
    /// flags by state as a table (`ProbeState::updates_in_frame_table`).
    fn classify_usage_states(
        &mut self,
        frame: &mut VolumeFrame,
        frame_index: u32,
        batch: u64,
        counts: &[Option<ProbeUsageCounts>],
    ) {
        let (interval, min_alive) =
            (self.settings.probe_sleeping_update_interval, self.settings.probe_alive_min_frames);
        let updates = ProbeState::updates_in_frame_table(frame_index, interval);
        // `frame.active` may be shorter (no frame planned): past its end a
        // probe's blend flag is not kept.
        let mut no_flag = false;
        let mut active = frame.active.iter_mut();
        let probes = self
            .probe_states
            .iter_mut()
            .zip(self.probe_alive_frames.iter_mut())
            .zip(self.probe_has_history.iter_mut())
            .zip(&self.probe_usage_from_batch)
            .zip(counts.iter().take(self.grid.probe_count()));
        for ((((state, alive_frames), history), &from_batch), &counts) in probes {
            let flag = active.next().unwrap_or(&mut no_flag);
            let Some((usage, relevant, backfaces)) = counts else { continue };
            if batch < from_batch {
                continue;
            }
            let prev = *state;
            let mut next = classify_usage(usage, relevant, backfaces);
            if prev == ProbeState::Alive && next == ProbeState::UsageSleeping && *alive_frames < min_alive {
                next = ProbeState::Alive;
            }
            *alive_frames = if next == ProbeState::Alive { *alive_frames + 1 } else { 0 };
            if prev == ProbeState::Dead && next != ProbeState::Dead {
                // Uncovered: the atlas holds light from before, so start over.
                *history = false;
            }
            *flag = match next {
                ProbeState::Dead => prev != ProbeState::Dead,
                s => updates[s as usize] || !*history,
            };
            *state = next;
        }
    }
}

/// [`DdgiVolume::probe_has_content`] over the per-probe histories and seeds
/// in step (`screen`: the volume runs the screen scheme, whose seeded probes
/// count as having content); apart from the volume, so a loop may borrow
/// its other arrays mutably beside it.
fn have_content<'a>(history: &'a [bool], seeded: &'a [bool], screen: bool) -> impl Iterator<Item = bool> + 'a {
    history.iter().zip(seeded).map(move |(&history, &seeded)| history || (seeded && screen))
}
