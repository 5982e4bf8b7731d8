//! The volume's share of the ray budget (`crate::ray_budget`): its candidates
//! with their priorities and floor, and the change each blend leaves
//! (`probegi_core::probe_change`), measured here for a host blend and taken
//! from the device for a device blend.

use glam::Vec3;
use probegi_core::probe_change::{irradiance_tile_change, occlusion_tile_change, probe_change};
use rayon::prelude::*;

use crate::ray_budget::{BudgetCandidate, budget_priority};

use super::{DdgiVolume, VolumeFrame};

/// The tiles a host blend is about to change, kept to measure the change.
pub(crate) struct TilesBefore {
    irradiance: Vec<Vec3>,
    occlusion: Option<Vec<f32>>,
}

impl DdgiVolume {
    /// Appends this volume's probes whose state traces, with their priority
    /// and whether the floor makes them trace.
    pub(crate) fn budget_candidates(&self, volume: u32, out: &mut Vec<BudgetCandidate>) {
        let interval = self.settings.ray_budget_max_interval_frames;
        for (p, state) in self.probe_states.iter().enumerate() {
            if !state.traces() {
                continue;
            }
            let age = self.probe_untraced_frames[p].saturating_add(1);
            out.push(BudgetCandidate {
                volume,
                probe: p as u32,
                rays: self.settings.probe_rays_per_probe,
                priority: budget_priority(self.probe_change[p], age),
                mandatory: !self.probe_has_history[p] || state.is_new() || age >= interval,
            });
        }
    }

    /// Counts the frames since each probe last traced, after `frame` was planned.
    pub(super) fn count_untraced_frames(&mut self, frame: &VolumeFrame) {
        for (n, &traced) in self.probe_untraced_frames.iter_mut().zip(&frame.tracing) {
            *n = if traced { 0 } else { n.saturating_add(1) };
        }
    }

    /// The tiles before a host blend, when the frame measures change.
    pub(super) fn tiles_before(&self, frame: &VolumeFrame) -> Option<TilesBefore> {
        frame.measure_change.then(|| TilesBefore {
            irradiance: self.irradiance.texels.clone(),
            occlusion: self.shadow.as_ref().map(|s| s.occlusion.texels.clone()),
        })
    }

    /// Each blended probe's change from `before` to the atlases now.
    pub(super) fn record_change(&mut self, updated: &[bool], before: &TilesBefore) {
        let (irr_len, n) = (self.irradiance.tile_len(), self.irradiance.interior);
        let occ = self.shadow.as_ref().map(|s| (&s.occlusion, &before.occlusion));
        let irradiance = &self.irradiance;
        let changes: Vec<Option<f32>> = (0..updated.len())
            .into_par_iter()
            .map(|p| {
                updated[p].then(|| {
                    let tile = p * irr_len..(p + 1) * irr_len;
                    let e = irradiance_tile_change(&before.irradiance[tile.clone()], &irradiance.texels[tile], n);
                    let v = occ.and_then(|(atlas, old)| {
                        let old = old.as_ref()?;
                        let len = atlas.tile_len();
                        let tile = p * len..(p + 1) * len;
                        Some(occlusion_tile_change(&old[tile.clone()], &atlas.texels[tile], atlas.interior))
                    });
                    probe_change(e, v)
                })
            })
            .collect();
        for (p, c) in changes.into_iter().enumerate() {
            if let Some(c) = c {
                self.probe_change[p] = c;
            }
        }
    }

    /// The change a device measured for each probe it blended, in increasing
    /// probe order (`DeviceVolumeBlend::measure_change`).
    pub(super) fn accept_device_change(&mut self, updated: &[bool], change: &[f32]) {
        let blended = updated.iter().enumerate().filter(|(_, u)| **u).map(|(p, _)| p);
        for (p, &c) in blended.zip(change) {
            self.probe_change[p] = probe_change(c, None);
        }
    }
}
