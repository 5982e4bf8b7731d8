//! Initialisation rounds of a volume (seed 004 Listing 5, first step): before a
//! probe traces for the field it is placed and classified against the static
//! geometry in distance-only rounds of `probe_init_rays_per_probe` rays a probe
//! (RTXGI's 32 fixed rays), `probe_relocation_iterations` rounds of the
//! position optimizer (`probegi_core::probe_relocation`), then with jcgt states
//! one classification round (`probegi_core::probe_classification`). The rounds
//! run for every probe when the volume is created, and for the planes a tracking
//! window scrolls in.
//!
//! The relocation rounds trace one set of directions, as RTXGI's fixed rays do
//! (its relocation runs every frame on the same 32 directions "to produce
//! temporally stable results"). A probe whose round left its offset as it was
//! would trace the same rays from the same point in the next round and stay put
//! again, so it skips the rounds after: the result is that of every round run
//! in full, for a fraction of the rays (most probes in open space never move).
//! The classification round traces the same directions from the probes'
//! final positions, as RTXGI's `ProbeClassificationCS` reads the same fixed
//! rays as its relocation. So a probe whose last relocation round left it in
//! place has traced the classification's rays already: where the host read
//! those hits it keeps them (`probe_init_hits`), and the classification round
//! traces only the probes that moved in their last round (every probe without
//! relocation). The states are those of a classification round traced in
//! full; start-up traces most probes once instead of twice.
//!
//! `plan_init_round` / `accept_init_round` are the host path, one round at a
//! time; `device_init_chain` / `accept_device_init` the field-resident device
//! path, every round chained there (the same rounds, skips and kept hits).

use glam::Vec3;
use probegi_core::ddgi_query::max_surface_bias_m;
use probegi_core::ddgi_settings::ProbeStatesMode;
use probegi_core::probe_classification::{
    COVER_ITERATIONS, ClassificationProbe, CoverProposal, ProbeState, classify_jcgt, cover_proposals,
    front_side_cage_probes, probe_watches, uncovered_point_probe,
};
use probegi_core::probe_relocation::{is_inside_geometry, probe_ray_stats, relocation_step};
use rayon::prelude::*;

use crate::device_plans::{DeviceClassification, DeviceInitChain, DeviceInitResult};
use crate::probe_ray_gen::{probe_ray_rotation, rotated_fibonacci};
use crate::seam::{ProbeRayBatch, ProbeRayHit};

use super::{DdgiVolume, VolumeFrame};

impl DdgiVolume {
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

    /// Every initialisation round of this volume's pending probes as one chain
    /// for a device that runs them back to back (`DeviceInitChain`): the
    /// rounds the host would run, on the same directions.
    pub(crate) fn device_init_chain(&self, seed: u64) -> DeviceInitChain<'_> {
        let rounds = self.init_rounds();
        let relocation_rounds = rounds.iter().filter(|r| matches!(r, InitRound::Relocation(_))).count() as u32;
        let rotation = probe_ray_rotation(self.stream_seed(seed), INIT_ROUNDS_FRAME);
        let dirs = rotated_fibonacci(rotation, self.settings.probe_init_rays_per_probe);
        let n = dirs.len() as u32;
        let classification = rounds.contains(&InitRound::Classification).then(|| DeviceClassification {
            grid: &self.grid,
            rays_per_probe: n,
            reach_rel: self.settings.probe_classification_reach_rel,
            bias_m: max_surface_bias_m(&self.settings, &self.grid),
            probes: (0..self.grid.probe_count())
                .map(|p| ClassificationProbe {
                    first_ray: self.probe_pending_init[p].then_some(p as u32 * n),
                    pending: self.probe_pending_init[p],
                    traces: self.probe_states[p].traces(),
                    position_m: self.probe_positions[p],
                })
                .collect(),
        });
        DeviceInitChain {
            settings: &self.settings,
            grid: &self.grid,
            pending: &self.probe_pending_init,
            offsets_m: &self.probe_offsets,
            relocation_rounds,
            dirs,
            classification,
        }
    }

    /// Applies a [`Self::device_init_chain`] another device ran and ends the
    /// initialisation. A non-finite offset keeps the probe where it was.
    pub(crate) fn accept_device_init(&mut self, result: &DeviceInitResult) {
        let probes = self.grid.probe_count();
        self.renew_probe_rows_id();
        for (p, &o) in result.offsets_m.iter().enumerate().take(probes) {
            if self.probe_pending_init[p] && o.is_finite() {
                self.probe_offsets[p] = o;
                self.probe_positions[p] = self.grid.probe_position(self.grid.probe_coords(p)) + o;
            }
        }
        if let Some(states) = &result.classification {
            for (p, &(inside, kept)) in states.iter().enumerate().take(probes) {
                if self.probe_pending_init[p] {
                    self.probe_states[p] = classify_jcgt(inside, kept);
                }
            }
        }
        self.finish_init();
    }

    /// Forgets the hits an earlier exchange kept and did not finish with (a
    /// new `begin_update`): they need not be where their probes are now.
    pub(crate) fn forget_init_hits(&mut self) {
        if !self.probe_init_hits.is_empty() {
            self.probe_init_hits = Vec::new();
            self.probe_init_hits_current.fill(false);
        }
    }

    /// Whether this volume's initialisation ends with the jcgt classification.
    pub(crate) fn init_classifies(&self) -> bool {
        self.init_rounds().contains(&InitRound::Classification)
    }

    /// Whether this volume's initialisation round `round` is a relocation iteration.
    pub(crate) fn init_round_is_relocation(&self, round: usize) -> bool {
        matches!(self.init_rounds().get(round), Some(InitRound::Relocation(_)))
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
        let rotation = probe_ray_rotation(self.stream_seed(seed), INIT_ROUNDS_FRAME);
        frame.init_dirs = rotated_fibonacci(rotation, self.settings.probe_init_rays_per_probe);
        frame.ray_count = frame.init_dirs.len();
        frame.first_ray = vec![u32::MAX; self.grid.probe_count()];
        let first_probe = batch.probes.len() as u32;
        // After the first relocation round only the probes that moved trace;
        // the classification round only those whose hits from where they are
        // the host does not hold.
        let skips = |p: usize| match kind {
            InitRound::Relocation(i) => i > 0 && self.probe_relocation_settled[p],
            InitRound::Classification => self.probe_init_hits_current[p],
        };
        frame.init_reuses_hits = false;
        for p in 0..self.grid.probe_count() {
            if self.probe_pending_init[p] && skips(p) {
                frame.init_reuses_hits |= kind == InitRound::Classification;
            } else if self.probe_pending_init[p] {
                frame.first_ray[p] = batch.push_probe(
                    volume,
                    p as u32,
                    self.probe_positions[p],
                    &frame.init_dirs,
                    self.settings.probe_max_ray_distance_m,
                );
            }
        }
        // How the rays were made, for a device that makes them itself (as the
        // update's): then the batch holds no per-ray arrays.
        batch.generated.push(crate::seam::GeneratedProbeRays {
            volume,
            first_probe,
            probe_count: batch.probes.len() as u32 - first_probe,
            rays_per_probe: frame.ray_count as u32,
            rotation,
            max_distance_m: self.settings.probe_max_ray_distance_m,
            plan_id: Some(crate::device_plans::next_plan_id()),
        });
        true
    }

    /// Applies the hits of initialisation round `round` (see [`Self::plan_init_round`]).
    /// `distances` are the hits' signed distances (one per batch ray).
    pub(crate) fn accept_init_round(
        &mut self,
        frame: &VolumeFrame,
        round: usize,
        hits: &[ProbeRayHit],
        distances: &[f32],
        normal_of: Option<&HitNormals<'_>>,
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
                let offsets = self.probe_offsets.par_iter_mut().zip(self.probe_relocation_settled.par_iter_mut());
                offsets.enumerate().for_each(|(p, (offset, settled))| {
                    if !pending[p] || planned[p] == u32::MAX {
                        return;
                    }
                    let next =
                        relocation_step(*offset, &probe_ray_stats(dirs, &distances[rays_of(p)]), spacing, settings);
                    *settled = next == *offset;
                    *offset = next;
                });
                for p in 0..self.grid.probe_count() {
                    self.probe_positions[p] =
                        self.grid.probe_position(self.grid.probe_coords(p)) + self.probe_offsets[p];
                }
                self.renew_probe_rows_id();
                // A settled probe traced from where it stays: its hits are the
                // classification's, kept where the caller gives their normals.
                if let (true, Some(normal_of)) = (self.keeps_init_hits(), normal_of) {
                    let settled = self.probe_relocation_settled.clone();
                    self.keep_init_hits(frame, hits, &settled, Some(normal_of));
                }
            }
            InitRound::Classification => {
                let all = vec![true; self.grid.probe_count()];
                self.keep_init_hits(frame, hits, &all, None);
                self.classify_jcgt_pending(frame);
            }
        }
    }

    /// Whether the host keeps the relocation rounds' hits for the
    /// classification round (jcgt states after relocation).
    pub(crate) fn keeps_init_hits(&self) -> bool {
        self.settings.probe_states == ProbeStatesMode::Jcgt
            && self.settings.probe_relocation
            && self.settings.probe_relocation_iterations > 0
    }

    /// Keeps the hits of every probe that traced in this round from where it
    /// now is (`current`) in `probe_init_hits`, with their normals from
    /// `normal_of` (a batch ray's facing plane normal) where given, else as the hits
    /// carry them. Only front hits' normals are read (by the classification).
    fn keep_init_hits(
        &mut self,
        frame: &VolumeFrame,
        hits: &[ProbeRayHit],
        current: &[bool],
        normal_of: Option<&HitNormals<'_>>,
    ) {
        let n = frame.ray_count;
        let probes = self.grid.probe_count();
        if self.probe_init_hits.len() != probes * n {
            self.probe_init_hits = vec![ProbeRayHit::MISS; probes * n];
            self.probe_init_hits_current.fill(false);
        }
        let pending = &self.probe_pending_init;
        let kept = self.probe_init_hits.par_chunks_mut(n).zip(self.probe_init_hits_current.par_iter_mut());
        kept.enumerate().for_each(|(p, (out, is_current))| {
            let first = frame.first_ray[p];
            if first == u32::MAX || !pending[p] {
                return;
            }
            *is_current = current[p];
            if !current[p] {
                return;
            }
            for (i, o) in out.iter_mut().enumerate() {
                let r = first as usize + i;
                *o = hits[r];
                if let (Some(normal_of), true) = (normal_of, o.distance_m > 0.0 && o.distance_m.is_finite()) {
                    // As `submit_hits` reads a hit with a non-finite normal: a miss.
                    let n = normal_of(r);
                    *o = if n.is_finite() { ProbeRayHit { normal: n, ..*o } } else { ProbeRayHit::MISS };
                }
            }
        });
    }

    /// Seed 004 Listing 5's classification of the pending probes from one
    /// distance round (see `probegi_core::probe_classification`), each probe's
    /// hits read from `probe_init_hits` (traced from where it is, with the
    /// round's directions): a first pass per
    /// probe (inside geometry → Off; watching a front face → kept), then a covering
    /// pass in probe and ray order (sequential, so deterministic and greedy) that
    /// keeps a front-side cage probe for every surface point a pending probe saw.
    /// Probes that are not pending keep their states and count as covering when
    /// they are kept already (they trace: not Off or Sleeping).
    fn classify_jcgt_pending(&mut self, frame: &VolumeFrame) {
        let n = frame.ray_count;
        let bias = max_surface_bias_m(&self.settings, &self.grid);
        let reach = self.settings.probe_classification_reach_rel;
        let (grid, pending) = (&self.grid, &self.probe_pending_init);
        let dirs = &frame.init_dirs;
        let (hits, positions) = (&self.probe_init_hits, &self.probe_positions);
        let classified = |p: usize| pending[p] && self.probe_init_hits_current[p];
        // Front-face hits of probe p as (ray in probe order, position, facing normal).
        let front_hits = |p: usize| {
            (0..n).filter_map(move |i| {
                let h = hits[p * n + i];
                (h.distance_m > 0.0 && h.distance_m.is_finite())
                    .then(|| ((p * n + i) as u32, positions[p] + dirs[i] * h.distance_m, h.normal))
            })
        };
        let first: Vec<(bool, bool)> = (0..grid.probe_count())
            .into_par_iter()
            .map(|p| {
                if !classified(p) {
                    return (false, false);
                }
                let d: Vec<f32> = hits[p * n..(p + 1) * n].iter().map(|h| h.distance_m).collect();
                let coords = grid.probe_coords(p);
                let grid_point = grid.probe_position(coords);
                let watches =
                    front_hits(p).any(|(_, pos, _)| probe_watches(grid, coords, pos - grid_point, reach, bias));
                (is_inside_geometry(&probe_ray_stats(dirs, &d)), watches)
            })
            .collect();
        let eligible: Vec<bool> = (0..grid.probe_count()).map(|p| pending[p] && !first[p].0).collect();
        let kept: Vec<bool> = (0..grid.probe_count())
            .map(|p| if pending[p] { !first[p].0 && first[p].1 } else { self.probe_states[p].traces() })
            .collect();
        // The covering pass, order-free (`cover_proposals`): what each point the
        // first pass left uncovered would keep, then the greedy rounds over them.
        let (kept_first, eligible) = (&kept, &eligible);
        let proposals: Vec<CoverProposal> = (0..grid.probe_count())
            .into_par_iter()
            .filter(|&p| classified(p))
            .flat_map_iter(|p| {
                front_hits(p).filter_map(move |(ray, pos, normal)| {
                    let q = uncovered_point_probe(grid, positions, kept_first, eligible, pos, normal)?;
                    let (front, front_count) = front_side_cage_probes(grid, positions, pos, normal);
                    Some(CoverProposal { ray, probe: q as u32, front, front_count })
                })
            })
            .collect();
        let kept = cover_proposals(&kept, &proposals, COVER_ITERATIONS);
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
                ProbeStatesMode::Screen => {
                    let requested = self.probe_request_countdown[p] > 0;
                    self.probe_states[p] = if requested { ProbeState::Requested } else { ProbeState::Idle };
                }
                ProbeStatesMode::Jcgt => {}
            }
            self.probe_pending_init[p] = false;
            self.probe_init_hits_current[p] = false;
            self.restart_usage(p);
        }
        self.probe_init_hits = Vec::new();
        self.initialized = true;
        self.refresh_usable();
    }
}

/// A batch ray's facing plane normal at its hit (its triangle's geometric
/// normal turned toward the ray's origin, what the classification's
/// front-side test reads), computed where a round's hits are
/// kept (`DdgiFieldSet::submit_init_hits`).
pub type HitNormals<'a> = dyn Fn(usize) -> Vec3 + Sync + 'a;

/// What an initialisation round of a volume does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum InitRound {
    Relocation(u32),
    Classification,
}

/// The pseudo-frame of every initialisation round's directions, far from real
/// ones, so they differ from frame 0's: every round the same (RTXGI's fixed
/// rays, which its relocation and classification both read).
const INIT_ROUNDS_FRAME: u32 = u32::MAX;
