//! The per-frame ray budget (`ray_budget`): seed 003 §8.2 and seed 000 §5.2
//! leave it as future work ("change the budget of each probe based on its
//! surroundings … gradually reduced to a set minimum"); production engines
//! ship one. N rays per frame are shared by the tracing probes of every volume
//! of a set.
//!
//! **Unit: whole probe updates.** A probe that traces casts its volume's full
//! `probe_rays_per_probe` (the same spherical Fibonacci set, blend weights and
//! classification as without a budget); the budget decides *which* probes
//! trace this frame. A probe that does not trace keeps its atlases and state
//! and is read as before, like a SLEEPING probe. *Deviation:* seed 000 speaks
//! of fewer rays per probe; a probe's rays per second are what converge it,
//! and whole updates keep one ray count per volume, which the blend weights,
//! the classification counts, the device's ray generation and the shadowing
//! field's two-frame rays all rely on.
//!
//! **Priority.** The probe's change in its last blend
//! (`probegi_core::probe_change`: SMAPE in YCoCg of this frame's encoded
//! irradiance against the history, or the occlusion maps' change when larger),
//! across the probe and its six grid neighbours (light that changed at one
//! probe has likely changed at the next); ties go to the probe that waited
//! longer, then to the lower (volume, probe). Seed 000's rule, "probes with low
//! error … have their budget gradually reduced to a set minimum": the probes
//! that keep changing trace every frame, the still ones at the floor.
//! *Measured* (`tests/it/ray_budget.rs`, shadow box, a quarter of the rays):
//! after a spotlight switches off, the eighth of the probes that changed most
//! trace on 99 % of the next frames, the still half on 1 %; `change × age`
//! (rate proportional to change) gave 40 % and 17 %.
//!
//! **Floor.** A probe that has not traced for `ray_budget_max_interval_frames`
//! frames, a probe without history (new, scrolled in, leaving DEAD) and a
//! Newly Awake / Vigilant probe trace whatever the budget: every tracing probe
//! keeps at least rays_per_probe / interval rays per frame, and nothing waits
//! forever. The floor wins over the budget, so a frame may exceed it (the first
//! frame, where every probe is new, always does).
//!
//! **Both backends.** The choice is host work of the update plan, O(probes),
//! like the probe states. The change it reads is measured where the atlases
//! are: by the CPU blend, or on the device by `probegi_wgpu`'s `probe_change`
//! pass, which reads back 4 bytes per blended probe.

/// One probe that may trace this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BudgetCandidate {
    /// Its volume (index in the set).
    pub volume: u32,
    /// Its storage slot in the volume.
    pub probe: u32,
    /// The rays it casts if chosen (its volume's rays per probe).
    pub rays: u32,
    /// Its (neighbourhood's) change in its last blend; higher traces first.
    pub change: f32,
    /// Frames since it last traced, plus one; breaks ties in `change`.
    pub age_frames: u32,
    /// Traces whatever the budget (the floor).
    pub mandatory: bool,
}

/// Which candidates trace (same order as `candidates`): every mandatory one,
/// then the others by descending change while their rays fit in what is
/// left of `budget_rays`. A candidate that does not fit is passed over for a
/// cheaper one behind it (volumes may differ in rays per probe).
pub fn select_budget_probes(candidates: &[BudgetCandidate], budget_rays: u64) -> Vec<bool> {
    let mut chosen: Vec<bool> = candidates.iter().map(|c| c.mandatory).collect();
    let spent: u64 = candidates.iter().filter(|c| c.mandatory).map(|c| c.rays as u64).sum();
    let mut left = budget_rays.saturating_sub(spent);
    let mut order: Vec<usize> = (0..candidates.len()).filter(|&i| !candidates[i].mandatory).collect();
    order.sort_by(|&a, &b| {
        let (ca, cb) = (&candidates[a], &candidates[b]);
        let by_change = budget_change(cb.change).total_cmp(&budget_change(ca.change));
        by_change.then(cb.age_frames.cmp(&ca.age_frames)).then((ca.volume, ca.probe).cmp(&(cb.volume, cb.probe)))
    });
    for i in order {
        let rays = candidates[i].rays as u64;
        if rays <= left {
            chosen[i] = true;
            left -= rays;
        }
    }
    chosen
}

/// A change as the order reads it: anything not a number is a full change.
pub fn budget_change(change: f32) -> f32 {
    if change.is_finite() { change.max(0.0) } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(probe: u32, change: f32, mandatory: bool) -> BudgetCandidate {
        BudgetCandidate { volume: 0, probe, rays: 10, change, age_frames: 1, mandatory }
    }

    #[test]
    fn mandatory_probes_first_then_by_priority_within_the_budget() {
        let cands = [c(0, 0.1, false), c(1, 5.0, false), c(2, 0.0, true), c(3, 3.0, false), c(4, 4.0, false)];
        // 35 rays: the mandatory 10, then priorities 5 and 4; 3.0 no longer fits.
        assert_eq!(select_budget_probes(&cands, 35), vec![false, true, true, false, true]);
        // The floor wins over a budget it exceeds.
        assert_eq!(select_budget_probes(&cands, 0), vec![false, false, true, false, false]);
        // Enough for everyone.
        assert_eq!(select_budget_probes(&cands, 1000), vec![true; 5]);
    }

    #[test]
    fn a_probe_that_does_not_fit_yields_to_a_cheaper_one_and_ties_go_to_the_lower_index() {
        let mut cands = [c(0, 1.0, false), c(1, 9.0, false), c(2, 1.0, false)];
        cands[1].rays = 30;
        assert_eq!(select_budget_probes(&cands, 25), vec![true, false, true]);
        assert_eq!(select_budget_probes(&cands, 15), vec![true, false, false]);
    }

    #[test]
    fn equal_changes_go_to_the_probe_that_waited_longer_and_nan_counts_as_full() {
        let mut cands = [c(0, 0.5, false), c(1, 0.5, false), c(2, f32::NAN, false)];
        cands[1].age_frames = 3;
        assert_eq!(select_budget_probes(&cands, 20), vec![false, true, true]);
        assert_eq!(budget_change(-1.0), 0.0);
    }
}
