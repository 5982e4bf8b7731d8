//! A DDGI volume on the CPU: the probe grid, its two atlases, and the per-frame
//! field update of seed 000 §3 / seed 003 §4.2–4.5 as four passes plus the border
//! refresh, each in its own module:
//! `probe_ray_gen` → `probe_trace` → `probe_shade` → blend (`probegi_core::probe_blend`)
//! → border (`probegi_core::probe_border`).
//!
//! Production extensions (seed 004), each switchable in the settings:
//! - initialisation, against the static geometry (`RayTracer::static_part`):
//!   `probe_relocation_iterations` distance-only traces with the position
//!   optimizer (`probegi_core::probe_relocation`), then the state classification
//!   (`probegi_core::probe_classification`); each frame, probes around moving
//!   objects wake up (`wake_probes_near`, called by the frame loop);
//! - per frame only probes whose state traces trace (jcgt: not Off or Sleeping;
//!   usage: all, then classified from the frame's rays before the blend), and only
//!   probes whose state updates are shaded and blended; queries skip probes that
//!   are culled or not yet blended, and fall back to the nearest usable probe when
//!   a whole cage is unusable (`probegi_core::ddgi_query`);
//! - fast convergence: Listing 3's per-texel thresholds, and scene events
//!   ([`SceneEvent`]) that lower the hysteresis of all probes for a few frames.
//!
//! A probe's first update (and a Newly Awake / Newly Vigilant probe's) replaces
//! its history, i.e. blends with hysteresis 0. Buffers are sized once.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::{UVec3, Vec2, Vec3};
use probegi_core::ddgi_query::{DdgiFieldView, max_surface_bias_m, nearest_usable_probes};
use probegi_core::ddgi_settings::{DdgiVolumeSettings, ProbeStatesMode};
use probegi_core::probe_atlas::ProbeAtlas;
use probegi_core::probe_blend::{TexelThresholds, blend_distance_tile, blend_irradiance_tile};
use probegi_core::probe_border::update_tile_border;
use probegi_core::probe_classification::{
    ProbeState, classify_jcgt, classify_usage, inside_grown_aabb, probe_usage, probe_watches, uncovered_point_probe,
};
use probegi_core::probe_grid::ProbeGrid;
use probegi_core::probe_relocation::{is_inside_geometry, probe_ray_stats, relocation_step};
use probegi_scene::{RayTracer, Scene};
use rayon::prelude::*;

use crate::direct::DirectLighting;
use crate::probe_ray_gen::{generate_probe_rays, probe_ray_directions};
use crate::probe_shade::{ProbeShadeInputs, shade_probe_rays};
use crate::probe_trace::{Surfel, signed_distance, trace_probe_rays};

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

pub struct DdgiVolume {
    pub grid: ProbeGrid,
    pub settings: DdgiVolumeSettings,
    /// Encoded mean radiance per texel (see `probe_blend`).
    pub irradiance: ProbeAtlas<Vec3>,
    /// (mean distance, mean squared distance) per texel.
    pub distance: ProbeAtlas<Vec2>,
    /// Probe positions including relocation offsets.
    pub probe_positions: Vec<Vec3>,
    pub probe_offsets: Vec<Vec3>,
    pub probe_states: Vec<ProbeState>,
    pub frames_updated: u32,
    probe_hysteresis: Vec<f32>,
    probe_usable: Vec<bool>,
    /// Per probe, the nearest usable probe (the query's fallback for empty cages).
    probe_fallback: Vec<u32>,
    /// False until the probe's first blend, and again when its history is stale
    /// (leaving DEAD): the next blend then replaces the history.
    probe_has_history: Vec<bool>,
    /// Usage scheme: consecutive frames the probe has been ALIVE.
    probe_alive_frames: Vec<u32>,
    /// Probes that trace this frame.
    tracing: Vec<bool>,
    /// Probes that are shaded and blended this frame.
    active: Vec<bool>,
    initialized: bool,
    irradiance_events: Vec<HysteresisReduction>,
    visibility_events: Vec<HysteresisReduction>,
    surfels: Vec<Surfel>,
    ray_radiance: Vec<Vec3>,
    ray_distance: Vec<f32>,
}

/// Bytes a volume with these settings holds (atlases and per-ray buffers).
pub fn ddgi_volume_bytes(settings: &DdgiVolumeSettings) -> u64 {
    let probes = settings.probe_count();
    let rays = probes * settings.probe_rays_per_probe as u64;
    let tile = |n: u32| ((n + 2) * (n + 2)) as u64;
    rays * (std::mem::size_of::<Surfel>() + std::mem::size_of::<Vec3>() + 4) as u64
        + probes * (tile(settings.probe_irradiance_texels) * 12 + tile(settings.probe_distance_texels) * 8 + 64)
}

impl DdgiVolume {
    /// A volume over `scene_bounds` (used when the settings give no origin/spacing).
    /// Probes are placed and classified on the first [`Self::update`].
    pub fn new(settings: DdgiVolumeSettings, scene_bounds: (Vec3, Vec3)) -> Self {
        let counts: UVec3 = settings.probe_counts;
        let fitted = ProbeGrid::fit_to_bounds(scene_bounds.0, scene_bounds.1, counts);
        let grid = ProbeGrid {
            origin_m: settings.probe_origin_m.unwrap_or(fitted.origin_m),
            probe_counts: counts,
            spacing_m: settings.probe_spacing_m.unwrap_or(fitted.spacing_m),
        };
        let probes = grid.probe_count();
        let rays = probes * settings.probe_rays_per_probe as usize;
        let probe_positions = (0..probes).map(|i| grid.probe_position(grid.probe_coords(i))).collect();
        Self {
            irradiance: ProbeAtlas::new(probes, settings.probe_irradiance_texels),
            distance: ProbeAtlas::new(probes, settings.probe_distance_texels),
            grid,
            probe_positions,
            probe_offsets: vec![Vec3::ZERO; probes],
            probe_states: vec![ProbeState::Active; probes],
            frames_updated: 0,
            probe_hysteresis: vec![settings.probe_hysteresis; probes],
            probe_usable: vec![false; probes],
            probe_fallback: vec![u32::MAX; probes],
            probe_has_history: vec![false; probes],
            probe_alive_frames: vec![0; probes],
            tracing: vec![true; probes],
            active: vec![true; probes],
            initialized: false,
            irradiance_events: Vec::new(),
            visibility_events: Vec::new(),
            surfels: vec![Surfel::default(); rays],
            ray_radiance: vec![Vec3::ZERO; rays],
            ray_distance: vec![0.0; rays],
            settings,
        }
    }

    pub fn view(&self) -> DdgiFieldView<'_> {
        DdgiFieldView {
            grid: &self.grid,
            settings: &self.settings,
            irradiance: &self.irradiance,
            distance: &self.distance,
            probe_offsets_m: &self.probe_offsets,
            probe_usable: &self.probe_usable,
            probe_fallback: &self.probe_fallback,
        }
    }

    /// Probe rays traced by the last update (tracing probes × rays per probe).
    pub fn rays_per_frame(&self) -> u64 {
        self.tracing.iter().filter(|a| **a).count() as u64 * self.settings.probe_rays_per_probe as u64
    }

    /// Probes shaded and blended in the last update.
    pub fn active_probe_count(&self) -> usize {
        self.active.iter().filter(|a| **a).count()
    }

    /// Whether queries may read probe `p` now.
    pub fn probe_usable(&self, p: usize) -> bool {
        self.probe_usable[p]
    }

    /// Recomputes which probes queries may read, and the fallback table if that changed.
    fn refresh_usable(&mut self) {
        let mut changed = false;
        for (p, u) in self.probe_usable.iter_mut().enumerate() {
            let now = self.probe_states[p].usable_in_queries() && self.probe_has_history[p];
            changed |= *u != now;
            *u = now;
        }
        if changed {
            self.probe_fallback = nearest_usable_probes(&self.grid, &self.probe_usable);
        }
    }

    /// The distance limit of the blend: RTXGI's 1.5 × the cell diagonal, or the
    /// trace limit if shorter.
    pub fn distance_clamp_m(&self) -> f32 {
        (1.5 * self.grid.spacing_m.length()).min(self.settings.probe_max_ray_distance_m)
    }

    /// Number of probes per state name.
    pub fn state_counts(&self) -> BTreeMap<&'static str, usize> {
        let mut m = BTreeMap::new();
        for s in &self.probe_states {
            *m.entry(s.name()).or_default() += 1;
        }
        m
    }

    /// Reports a scene change (seed 004 §4.3 per-probe heuristics; they apply to all
    /// probes). No effect unless `probe_fast_convergence` is on. Repeating an event
    /// while its reduction lasts restarts the reduction's window.
    pub fn notify_scene_event(&mut self, event: SceneEvent) {
        let (irr, vis) = match event {
            SceneEvent::SmallLightChange => (Some((0.85, 4)), None),
            SceneEvent::LargeLightChange => (Some((0.5, 10)), None),
            SceneEvent::LargeObjectChange => (Some((0.5, 10)), Some((0.5, 7))),
        };
        // The same reduction reported again (an object moving on every frame) restarts
        // its window rather than compounding: different reductions still multiply.
        let add = |events: &mut Vec<HysteresisReduction>, (scale, frames_left): (f32, u32)| match events
            .iter_mut()
            .find(|e| e.scale == scale)
        {
            Some(e) => e.frames_left = e.frames_left.max(frames_left),
            None => events.push(HysteresisReduction { scale, frames_left }),
        };
        if let Some(r) = irr {
            add(&mut self.irradiance_events, r);
        }
        if let Some(r) = vis {
            add(&mut self.visibility_events, r);
        }
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

    /// Distance-only trace from every probe with directions of pseudo-frame `frame`;
    /// returns signed true distances per ray (probe-major).
    fn trace_distances(&mut self, scene: &Scene, tracer: &dyn RayTracer, seed: u64, frame: u32) -> (Vec<Vec3>, u64) {
        let dirs = probe_ray_directions(&self.settings, seed, frame);
        let max = self.settings.probe_max_ray_distance_m;
        let n = trace_probe_rays(scene, tracer, &self.probe_positions, &[], &dirs, max, &mut self.surfels);
        (dirs, n)
    }

    /// Relocation and classification (seed 004 Listing 5, first step). Returns rays traced.
    fn initialize(&mut self, scene: &Scene, tracer: &dyn RayTracer, seed: u64) -> u64 {
        // Against static geometry only: moving objects wake probes instead.
        let static_part = tracer.static_part();
        let tracer = static_part.as_deref().unwrap_or(tracer);
        let n = self.settings.probe_rays_per_probe as usize;
        let mut traced = 0;
        // Pseudo-frames far from real ones, so initialisation directions differ from frame 0's.
        let init_frame = |i: u32| u32::MAX - i;
        if self.settings.probe_relocation {
            for it in 0..self.settings.probe_relocation_iterations {
                let (dirs, k) = self.trace_distances(scene, tracer, seed, init_frame(it));
                traced += k;
                let spacing = self.grid.spacing_m;
                let settings = &self.settings;
                let surfels = &self.surfels;
                self.probe_offsets.par_iter_mut().enumerate().for_each(|(p, offset)| {
                    let d: Vec<f32> = surfels[p * n..(p + 1) * n].iter().map(signed_distance).collect();
                    *offset = relocation_step(*offset, &probe_ray_stats(&dirs, &d), spacing, settings);
                });
                for (p, pos) in self.probe_positions.iter_mut().enumerate() {
                    *pos = self.grid.probe_position(self.grid.probe_coords(p)) + self.probe_offsets[p];
                }
            }
        }
        match self.settings.probe_states {
            ProbeStatesMode::AllActive => self.probe_states.fill(ProbeState::Active),
            ProbeStatesMode::Usage => self.probe_states.fill(ProbeState::Alive),
            ProbeStatesMode::Jcgt => {
                let (dirs, k) = self.trace_distances(scene, tracer, seed, init_frame(1000));
                traced += k;
                let bias = max_surface_bias_m(&self.settings, &self.grid);
                let reach = self.settings.probe_classification_reach_rel;
                let (grid, surfels) = (&self.grid, &self.surfels);
                let front_hits = |p: usize| {
                    surfels[p * n..(p + 1) * n].iter().filter_map(|s| s.surface.as_ref().filter(|sp| sp.front_face))
                };
                let first: Vec<(bool, bool)> = (0..grid.probe_count())
                    .into_par_iter()
                    .map(|p| {
                        let d: Vec<f32> = surfels[p * n..(p + 1) * n].iter().map(signed_distance).collect();
                        let coords = grid.probe_coords(p);
                        let grid_point = grid.probe_position(coords);
                        let watches =
                            front_hits(p).any(|sp| probe_watches(grid, coords, sp.position - grid_point, reach, bias));
                        (is_inside_geometry(&probe_ray_stats(&dirs, &d)), watches)
                    })
                    .collect();
                let eligible: Vec<bool> = first.iter().map(|(inside, _)| !inside).collect();
                let mut kept: Vec<bool> = first.iter().map(|&(inside, watches)| !inside && watches).collect();
                // Second pass, in probe and ray order (sequential, so deterministic and
                // greedy: a probe added for one point covers the points after it):
                // every seen surface point keeps a front-side cage probe.
                let positions = &self.probe_positions;
                for p in 0..grid.probe_count() {
                    for sp in front_hits(p) {
                        let add =
                            uncovered_point_probe(grid, positions, &kept, &eligible, sp.position, sp.facing_normal());
                        if let Some(q) = add {
                            kept[q] = true;
                        }
                    }
                }
                for (p, state) in self.probe_states.iter_mut().enumerate() {
                    *state = classify_jcgt(first[p].0, kept[p]);
                }
            }
        }
        self.refresh_usable();
        self.initialized = true;
        traced
    }

    /// Usage scheme (seed 003 §6.1): every probe's state from this frame's rays, and
    /// which probes blend this frame (see `probegi_core::probe_classification`).
    fn classify_usage_from_rays(&mut self, frame: u32) {
        let n = self.settings.probe_rays_per_probe as usize;
        let cage_diagonal = self.grid.spacing_m.length();
        let (interval, min_alive) =
            (self.settings.probe_sleeping_update_interval, self.settings.probe_alive_min_frames);
        for p in 0..self.grid.probe_count() {
            let rays = &self.surfels[p * n..(p + 1) * n];
            let (usage, relevant, backfaces) = probe_usage(rays.iter().map(signed_distance), cage_diagonal);
            let prev = self.probe_states[p];
            let mut next = classify_usage(usage, relevant, backfaces);
            if prev == ProbeState::Alive && next == ProbeState::UsageSleeping && self.probe_alive_frames[p] < min_alive
            {
                next = ProbeState::Alive;
            }
            self.probe_alive_frames[p] = if next == ProbeState::Alive { self.probe_alive_frames[p] + 1 } else { 0 };
            if prev == ProbeState::Dead && next != ProbeState::Dead {
                // Uncovered: the atlas holds light from before, so start over.
                self.probe_has_history[p] = false;
            }
            self.active[p] = match next {
                ProbeState::Dead => prev != ProbeState::Dead,
                s => s.updates_in_frame(frame, interval) || !self.probe_has_history[p],
            };
            self.probe_states[p] = next;
        }
    }

    /// Probes inside geometry by their rays (> 25 % backfaces), from a fresh trace.
    pub fn count_probes_inside_geometry(&mut self, scene: &Scene, tracer: &dyn RayTracer, seed: u64) -> usize {
        let n = self.settings.probe_rays_per_probe as usize;
        let (dirs, _) = self.trace_distances(scene, tracer, seed, u32::MAX - 2000);
        (0..self.grid.probe_count())
            .filter(|&p| {
                let d: Vec<f32> = self.surfels[p * n..(p + 1) * n].iter().map(signed_distance).collect();
                is_inside_geometry(&probe_ray_stats(&dirs, &d))
            })
            .count()
    }

    /// One field update. Adds per-pass milliseconds to `pass_ms` and returns the
    /// rays traced (probe rays plus shading shadow rays).
    pub fn update(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        direct: &DirectLighting<'_>,
        seed: u64,
        frame: u32,
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) -> u64 {
        let mut traced = 0;
        if !self.initialized {
            let t = Instant::now();
            traced += self.initialize(scene, tracer, seed);
            *pass_ms.entry("probe_init").or_default() += t.elapsed().as_secs_f64() * 1e3;
        }
        let mut time =
            |name: &'static str, t: Instant| *pass_ms.entry(name).or_default() += t.elapsed().as_secs_f64() * 1e3;
        let interval = self.settings.probe_sleeping_update_interval;
        for ((t, a), s) in self.tracing.iter_mut().zip(self.active.iter_mut()).zip(&self.probe_states) {
            *t = s.traces();
            *a = s.updates_in_frame(frame, interval);
        }

        let t = Instant::now();
        let rays = generate_probe_rays(&self.settings, seed, frame);
        time("ray_gen", t);

        let t = Instant::now();
        traced += trace_probe_rays(
            scene,
            tracer,
            &self.probe_positions,
            &self.tracing,
            &rays.dirs,
            self.settings.probe_max_ray_distance_m,
            &mut self.surfels,
        );
        if self.settings.probe_states == ProbeStatesMode::Usage {
            self.classify_usage_from_rays(frame);
        }
        time("trace", t);

        let t = Instant::now();
        let inputs = ProbeShadeInputs {
            scene,
            direct,
            field: DdgiFieldView {
                grid: &self.grid,
                settings: &self.settings,
                irradiance: &self.irradiance,
                distance: &self.distance,
                probe_offsets_m: &self.probe_offsets,
                probe_usable: &self.probe_usable,
                probe_fallback: &self.probe_fallback,
            },
            dirs: &rays.dirs,
            surfels: &self.surfels,
            active: &self.active,
            seed,
            frame,
        };
        traced += shade_probe_rays(&inputs, &mut self.ray_radiance, &mut self.ray_distance);
        time("shade", t);

        let t = Instant::now();
        let event_scale = |events: &[HysteresisReduction]| events.iter().map(|e| e.scale).product::<f32>();
        let (irr_scale, vis_scale) = if self.settings.probe_fast_convergence {
            (event_scale(&self.irradiance_events), event_scale(&self.visibility_events))
        } else {
            (1.0, 1.0)
        };
        let thresholds = self.settings.probe_fast_convergence.then_some(TexelThresholds {
            significant: self.settings.probe_significant_change_threshold,
            new_distribution: self.settings.probe_new_distribution_threshold,
        });
        let n = rays.dirs.len();
        let (irr_n, dist_n) = (self.irradiance.interior, self.distance.interior);
        let gamma = self.settings.probe_irradiance_gamma;
        let clamp = self.distance_clamp_m();
        let irr_len = self.irradiance.tile_len();
        let dist_len = self.distance.tile_len();
        let base: Vec<Option<f32>> = (0..self.grid.probe_count())
            .map(|p| {
                self.active[p].then(|| {
                    if !self.probe_has_history[p] || self.probe_states[p].is_new() {
                        0.0
                    } else {
                        self.probe_hysteresis[p]
                    }
                })
            })
            .collect();
        self.irradiance
            .texels
            .par_chunks_mut(irr_len)
            .zip(self.ray_radiance.par_chunks(n))
            .zip(base.par_iter())
            .for_each(|((tile, radiance), h)| {
                if let Some(h) = h {
                    blend_irradiance_tile(
                        tile,
                        irr_n,
                        &rays.irradiance_weights,
                        radiance,
                        h * irr_scale,
                        gamma,
                        thresholds.as_ref(),
                    );
                }
            });
        self.distance
            .texels
            .par_chunks_mut(dist_len)
            .zip(self.ray_distance.par_chunks(n))
            .zip(base.par_iter())
            .for_each(|((tile, distance), h)| {
                if let Some(h) = h {
                    blend_distance_tile(tile, dist_n, &rays.distance_weights, distance, h * vis_scale, clamp);
                }
            });
        time("blend", t);

        let t = Instant::now();
        let active = &self.active;
        self.irradiance.texels.par_chunks_mut(irr_len).zip(active.par_iter()).for_each(|(tile, a)| {
            if *a {
                update_tile_border(tile, irr_n)
            }
        });
        self.distance.texels.par_chunks_mut(dist_len).zip(active.par_iter()).for_each(|(tile, a)| {
            if *a {
                update_tile_border(tile, dist_n)
            }
        });
        time("border", t);

        self.after_update();
        self.frames_updated += 1;
        #[cfg(debug_assertions)]
        self.validate();
        traced
    }

    /// State transitions and hysteresis ramps after a blend.
    fn after_update(&mut self) {
        let max_h = self.settings.probe_hysteresis;
        for p in 0..self.grid.probe_count() {
            if !self.active[p] {
                continue;
            }
            self.probe_has_history[p] = true;
            let state = self.probe_states[p].after_update();
            if matches!(state, ProbeState::Alive | ProbeState::UsageSleeping) {
                let target = if state == ProbeState::Alive { max_h } else { 0.5 * max_h };
                self.probe_hysteresis[p] += 0.1 * (target - self.probe_hysteresis[p]);
            }
            self.probe_states[p] = state;
        }
        self.refresh_usable();
        for events in [&mut self.irradiance_events, &mut self.visibility_events] {
            for e in events.iter_mut() {
                e.frames_left = e.frames_left.saturating_sub(1);
            }
            events.retain(|e| e.frames_left > 0);
        }
    }

    /// Atlas invariants: every texel finite and non-negative, every border equal to
    /// its source texel.
    pub fn validate(&self) {
        assert!(self.irradiance.texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0), "irradiance atlas");
        assert!(self.distance.texels.iter().all(|t| t.is_finite() && t.min_element() >= 0.0), "distance atlas");
        for p in 0..self.grid.probe_count() {
            check_borders(self.irradiance.tile(p), self.irradiance.interior);
            check_borders(self.distance.tile(p), self.distance.interior);
        }
    }
}

fn check_borders<T: PartialEq + Copy + std::fmt::Debug>(tile: &[T], interior: u32) {
    let s = (interior + 2) as usize;
    for ((dx, dy), (sx, sy)) in probegi_core::probe_border::border_sources(interior) {
        assert_eq!(tile[dy as usize * s + dx as usize], tile[sy as usize * s + sx as usize], "border texel");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
