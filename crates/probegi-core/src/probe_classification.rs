//! Probe states: two selectable schemes (`probe_states` setting).
//!
//! **jcgt** — seed 004 §6, Listing 5: Off, Sleeping, Newly Awake, Newly Vigilant,
//! Awake, Vigilant. After relocation a probe still inside geometry is Off; one
//! with a front face closer than the minimum spacing is Newly Vigilant; otherwise
//! Sleeping. Sleeping probes inside a dynamic object's AABB (grown by one cell plus
//! the self-shadow bias) become Newly Awake. Newly * probes update once with
//! hysteresis 0, then become Awake / Vigilant. Only those trace and update.
//!
//! **usage** — seed 003 §6.1, eq. 6.1–6.2: Usage(P) = Σ R(dᵢ) over a probe's
//! samples, R = 1 for a hit within the cage diagonal r, −1 for a backface, 0
//! otherwise. More than half of the relevant samples backfaces → DEAD (updated
//! once, culled from queries); usage > 0 → ALIVE (updated every frame, hysteresis
//! raised toward the maximum); else SLEEPING (updated every
//! `probe_sleeping_update_interval` frames, hysteresis lowered).
//!
//! Off, Sleeping (jcgt) and Dead (usage) probes are excluded from queries: they are
//! not updated, so their data would be stale. Deviation: the thesis's "logarithmic"
//! hysteresis ramps are not specified further; we move the hysteresis 10 % of the
//! way toward its target per update (up to the volume's `probe_hysteresis` for
//! ALIVE, down to half of it for SLEEPING).

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::probe_relocation::{ProbeRayStats, is_inside_geometry};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ProbeStatesMode {
    /// Every probe traces and updates every frame.
    AllActive,
    /// Seed 004's six-state machine.
    Jcgt,
    /// Seed 003's ALIVE / SLEEPING / DEAD usage classification.
    Usage,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ProbeState {
    Active,
    Off,
    Sleeping,
    NewlyAwake,
    NewlyVigilant,
    Awake,
    Vigilant,
    Alive,
    UsageSleeping,
    Dead,
}

impl ProbeState {
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
        }
    }

    /// Whether queries may read this probe.
    pub fn usable_in_queries(self) -> bool {
        !matches!(self, Self::Off | Self::Sleeping | Self::Dead)
    }

    /// Whether the probe traces and updates in frame `frame` (usage scheme:
    /// sleeping probes every `sleep_interval` frames).
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

/// Seed 004 Listing 5's initial classification from the post-relocation trace.
pub fn classify_jcgt(stats: &ProbeRayStats, min_spacing_m: f32) -> ProbeState {
    if is_inside_geometry(stats) {
        ProbeState::Off
    } else if stats.closest_frontface.is_some_and(|(_, d)| d < min_spacing_m) {
        ProbeState::NewlyVigilant
    } else {
        ProbeState::Sleeping
    }
}

/// Whether `point` lies in the box `[lo, hi]` grown by `grow` on every side.
pub fn inside_grown_aabb(point: Vec3, lo: Vec3, hi: Vec3, grow: Vec3) -> bool {
    point.cmpge(lo - grow).all() && point.cmple(hi + grow).all()
}

/// Seed 003 eq. 6.1–6.2 over one probe's signed distances (negative = backface,
/// infinite = miss) with cage diagonal `r`: (usage, relevant samples, backfaces).
pub fn probe_usage(signed_distance: impl IntoIterator<Item = f32>, cage_diagonal_m: f32) -> (i32, u32, u32) {
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
    fn jcgt_classification_follows_listing_5() {
        let inside = ProbeRayStats { backface_fraction: 0.5, ..Default::default() };
        assert_eq!(classify_jcgt(&inside, 1.0), ProbeState::Off);
        let near = ProbeRayStats { closest_frontface: Some((Vec3::X, 0.4)), ..Default::default() };
        assert_eq!(classify_jcgt(&near, 1.0), ProbeState::NewlyVigilant);
        let far = ProbeRayStats { closest_frontface: Some((Vec3::X, 4.0)), ..Default::default() };
        assert_eq!(classify_jcgt(&far, 1.0), ProbeState::Sleeping);
        assert_eq!(ProbeState::NewlyVigilant.after_update(), ProbeState::Vigilant);
        assert!(!ProbeState::Off.usable_in_queries() && ProbeState::Vigilant.usable_in_queries());
    }

    #[test]
    fn usage_counts_follow_eq_6_2() {
        let d = [0.5, 1.5, -0.2, f32::INFINITY, 0.9];
        assert_eq!(probe_usage(d, 1.0), (1, 3, 1));
        assert_eq!(classify_usage(1, 3, 1), ProbeState::Alive);
        assert_eq!(classify_usage(0, 0, 0), ProbeState::UsageSleeping);
        assert_eq!(classify_usage(-3, 4, 3), ProbeState::Dead);
        assert!(ProbeState::UsageSleeping.updates_in_frame(20, 10));
        assert!(!ProbeState::UsageSleeping.updates_in_frame(21, 10));
    }
}
