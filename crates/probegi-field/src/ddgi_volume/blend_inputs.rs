//! Blend inputs and the blend: scene events lower the hysteresis for a few
//! frames (seed 004 §4.3); `blend_inputs` applies the backface rule once per ray
//! (zero radiance, distance −0.2·t, seed 004 §4.1); `blend_results` blends
//! (`probegi_core::probe_blend`, hysteresis with seed 004 Listing 3's thresholds
//! and the scene-event reductions) and fixes borders (`probegi_core::probe_border`)
//! only for the probes that update this frame. `device_blend` /
//! `accept_device_blend` are the same step when the device holds the atlases.
//!
//! Deliberate deviation: with `probe_hysteresis_startup_ramp` (on by default)
//! the volume's first blends cap the hysteresis at 1 − 1/(n + 1), a running
//! mean, before seed 004's α: from α on, the field's bounces build up at
//! (1 − α)(1 − λ) a frame, and a field started from black took hundreds of
//! frames (docs/RESULTS.md, "Convergence over the view set").

use std::collections::BTreeMap;

use glam::Vec3;
use probegi_core::probe_blend::{
    BACKFACE_DISTANCE_SCALE, IrradianceBlendRule, blend_distance_tile, blend_irradiance_tile, hysteresis_over_frames,
};
use probegi_core::probe_border::update_tile_border;
use probegi_core::probe_classification::ProbeState;
use rayon::prelude::*;

use crate::device_plans::DeviceVolumeBlend;
use crate::seam::{ProbeRayBatch, ProbeRayHit};

use super::{DdgiVolume, HysteresisReduction, SceneEvent, VolumeFrame};

impl DdgiVolume {
    /// Reports a scene change (seed 004 §4.3 per-probe heuristics; they apply to all
    /// probes). The hysteresis reductions need `probe_fast_convergence`; repeating
    /// an event while its reduction lasts restarts the reduction's window. Under
    /// a ray budget every probe also counts as changed until it traces again
    /// (`probe_budget`), so the budget visits them all, longest-waiting first.
    pub fn notify_scene_event(&mut self, event: SceneEvent) {
        self.mark_all_changed();
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

    /// Blend and border (seed 003 §4.5, seed 004 §2.3–4.3) for the probes that
    /// update this frame, from the batch's per-ray blend inputs (radiance and
    /// signed distance after the backface rule, [`blend_inputs`]). Adds
    /// milliseconds to `pass_ms` under `blend` and `border`.
    pub(crate) fn blend_results(
        &mut self,
        frame: &VolumeFrame,
        batch: u64,
        ray_radiance: &[Vec3],
        ray_distance: &[f32],
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) {
        let t = std::time::Instant::now();
        let n = frame.ray_count;
        let (base, irr_scale, vis_scale) = self.blend_plan(frame);
        let frames = self.blend_frames(frame);
        let rule = self.irradiance_blend_rule();
        let (irr_n, dist_n) = (self.irradiance.interior, self.distance.interior);
        let clamp = self.distance_clamp_m();
        let irr_len = self.irradiance.tile_len();
        let dist_len = self.distance.tile_len();
        let weights = &frame.rays;
        if rule.adaptive_hysteresis {
            self.irradiance_texel_hysteresis.resize(self.irradiance.texels.len(), 0.0);
        }
        // Per tile its adaptive-hysteresis states, or none.
        let states: Vec<&mut [f32]> = if rule.adaptive_hysteresis {
            self.irradiance_texel_hysteresis.chunks_mut(irr_len).collect()
        } else {
            base.iter().map(|_| &mut [][..]).collect()
        };
        let irradiance_change: Vec<Option<f32>> = self
            .irradiance
            .texels
            .par_chunks_mut(irr_len)
            .zip(states)
            .zip(base.par_iter().zip(&frames))
            .map(|((tile, state), (b, k))| {
                b.map(|(first, h)| {
                    blend_irradiance_tile(
                        tile,
                        irr_n,
                        weights.irradiance_weights(),
                        &ray_radiance[first..first + n],
                        (h * irr_scale, *k),
                        &rule,
                        state,
                    )
                })
            })
            .collect();
        self.distance.texels.par_chunks_mut(dist_len).zip(base.par_iter().zip(&frames)).for_each(|(tile, (b, k))| {
            if let Some((first, h)) = *b {
                blend_distance_tile(
                    tile,
                    dist_n,
                    weights.distance_weights(),
                    &ray_distance[first..first + n],
                    hysteresis_over_frames(h * vis_scale, *k),
                    clamp,
                );
            }
        });
        *pass_ms.entry("blend").or_default() += t.elapsed().as_secs_f64() * 1e3;

        let updated: Vec<bool> = base.iter().map(|b| b.is_some()).collect();
        self.border_tiles(&updated, pass_ms);
        let mut occlusion_change = Vec::new();
        if self.shadow.is_some() {
            // A light that changes changes the shadows: the irradiance scale applies.
            let t = std::time::Instant::now();
            let hysteresis: Vec<Option<f32>> =
                shadow_base(&base, irr_scale, &frames).iter().map(|b| b.map(|(_, h)| h)).collect();
            occlusion_change = self.blend_shadow_maps(frame, &hysteresis);
            *pass_ms.entry("shadow_blend").or_default() += t.elapsed().as_secs_f64() * 1e3;
        }
        self.record_change(batch, &irradiance_change, &occlusion_change);
        self.count_unblended_frames(frame);
        self.after_update(&updated);
        #[cfg(debug_assertions)]
        self.validate();
    }

    /// How this volume's irradiance texels take their estimates: γ, Listing 3's
    /// thresholds with `probe_fast_convergence`, and PGI's safeguards.
    pub(crate) fn irradiance_blend_rule(&self) -> IrradianceBlendRule {
        IrradianceBlendRule::from_settings(&self.settings)
    }

    /// The border pass over the tiles that blended (seed 004 §2.3), timed under `border`.
    fn border_tiles(&mut self, updated: &[bool], pass_ms: &mut BTreeMap<&'static str, f64>) {
        let t = std::time::Instant::now();
        let (irr_n, dist_n) = (self.irradiance.interior, self.distance.interior);
        let (irr_len, dist_len) = (self.irradiance.tile_len(), self.distance.tile_len());
        self.irradiance.texels.par_chunks_mut(irr_len).zip(updated.par_iter()).for_each(|(tile, a)| {
            if *a {
                update_tile_border(tile, irr_n)
            }
        });
        self.distance.texels.par_chunks_mut(dist_len).zip(updated.par_iter()).for_each(|(tile, a)| {
            if *a {
                update_tile_border(tile, dist_n)
            }
        });
        *pass_ms.entry("border").or_default() += t.elapsed().as_secs_f64() * 1e3;
    }

    /// Per probe, its first ray and the hysteresis of its blend this frame (`None`:
    /// no blend), and the scene events' irradiance and visibility scales.
    fn blend_plan(&self, frame: &VolumeFrame) -> (Vec<Option<(usize, f32)>>, f32, f32) {
        self.blend_plan_with(frame, true)
    }

    /// The start-up ramp's cap on every probe's hysteresis this frame: the
    /// volume's blends so far as a running mean (1: no ramp).
    fn startup_hysteresis_cap(&self) -> f32 {
        if self.settings.probe_hysteresis_startup_ramp { ramp_cap(self.frames_updated) } else { 1.0 }
    }

    /// [`Self::blend_plan`], its hysteresis capped by the start-up ramp or
    /// (`startup_cap` false) not yet.
    pub(super) fn blend_plan_with(
        &self,
        frame: &VolumeFrame,
        startup_cap: bool,
    ) -> (Vec<Option<(usize, f32)>>, f32, f32) {
        let cap = if startup_cap { self.startup_hysteresis_cap() } else { 1.0 };
        let (irr_scale, vis_scale) = self.event_scales();
        (self.blend_entries(frame, cap, |first| first as usize), irr_scale, vis_scale)
    }

    /// Per probe, its first ray (as `first` makes it) and its blend's
    /// hysteresis capped at `cap` where it blends this frame, else `None`.
    fn blend_entries<T>(&self, frame: &VolumeFrame, cap: f32, first: impl Fn(u32) -> T) -> Vec<Option<(T, f32)>> {
        // `frame.blends(p)` over the frame's arrays in step; a probe past them does not blend.
        let probes = self.grid.probe_count();
        let planned = frame.active.iter().zip(&frame.first_ray).take(probes).enumerate();
        let mut entries: Vec<_> = planned
            .map(|(p, (&active, &ray))| {
                (active && ray != u32::MAX).then(|| (first(ray), self.blend_hysteresis(p).min(cap)))
            })
            .collect();
        entries.resize_with(probes, || None);
        entries
    }

    /// Probe `p`'s blend hysteresis before the start-up cap: 0 for a fresh
    /// probe (not seeded), the edge buffer's where it lies there, and the
    /// per-probe ramp's cap where that runs.
    fn blend_hysteresis(&self, p: usize) -> f32 {
        let fresh = !self.probe_has_history[p] || self.probe_states[p].is_new();
        let h = if fresh && !self.probe_seeded[p] {
            0.0
        } else if self.in_edge_buffer(p) {
            self.probe_hysteresis[p].min(self.settings.volume_edge_buffer_hysteresis)
        } else {
            self.probe_hysteresis[p]
        };
        if self.settings.probe_hysteresis_ramp {
            // Blends so far, the seed counting as one: 0 for a fresh probe.
            let n = if fresh { self.probe_seeded[p] as u32 } else { self.probe_blends[p] };
            h.min(ramp_cap(n))
        } else {
            h
        }
    }

    /// The scene events' irradiance and visibility hysteresis scales now
    /// (1 without `probe_fast_convergence`).
    fn event_scales(&self) -> (f32, f32) {
        let event_scale = |events: &[HysteresisReduction]| events.iter().map(|e| e.scale).product::<f32>();
        if self.settings.probe_fast_convergence {
            (event_scale(&self.irradiance_events), event_scale(&self.visibility_events))
        } else {
            (1.0, 1.0)
        }
    }

    /// This frame's blend as data, for a device that holds the atlases.
    pub(crate) fn device_blend<'a>(
        &'a self,
        frame: &'a VolumeFrame,
        lights: &[probegi_scene::PunctualLight],
    ) -> DeviceVolumeBlend<'a> {
        // The start-up cap goes apart (`DeviceVolumeBlend::hysteresis_cap`);
        // the shadowing field's plan takes it in.
        let (irradiance_scale, visibility_scale) = self.event_scales();
        let hysteresis_cap = self.startup_hysteresis_cap();
        let (probe_blend, shadow) = match &frame.steady_blend {
            // A steady frame's plan is the one kept (`steady_frames`).
            Some(kept) => (std::borrow::Cow::Borrowed(kept.as_slice()), None),
            None if self.shadow.is_some() => {
                let (base, _, _) = self.blend_plan_with(frame, false);
                let capped: Vec<_> = base.iter().map(|b| b.map(|(first, h)| (first, h.min(hysteresis_cap)))).collect();
                let shadow_plan = shadow_base(&capped, irradiance_scale, &self.blend_frames(frame));
                (device_entries(base).into(), self.device_shadow_blend(&shadow_plan, lights))
            }
            // The device's entries made as they are (no plan in `usize` first).
            None => (self.blend_entries(frame, 1.0, |first| first).into(), None),
        };
        DeviceVolumeBlend {
            shadow,
            settings: &self.settings,
            ray_dirs: &frame.rays.dirs,
            probe_blend,
            probe_blend_id: frame.steady_blend.as_ref().map(|_| frame.steady_blend_id),
            hysteresis_cap,
            irradiance_scale,
            visibility_scale,
            distance_clamp_m: self.distance_clamp_m(),
            reset_probes: &self.probes_reset_since_blend,
            seeds: &self.pending_seeds,
            measure_change: frame.measure_change,
            // The set fills it in (`DdgiFieldSet::device_blend_plan`).
            change_key: Default::default(),
            probe_blend_frames: self.blend_frames_borrowed(frame),
        }
    }

    /// The bookkeeping of a blend another device ran by [`Self::device_blend`]
    /// for update batch `batch`; `earlier_changes`: the probe changes it
    /// measured after earlier batches' blends and read back since
    /// (`DeviceVolumeBlend::measure_change`), by batch.
    pub(crate) fn accept_device_blend(
        &mut self,
        frame: &VolumeFrame,
        lights: &[probegi_scene::PunctualLight],
        batch: u64,
        earlier_changes: &[(u64, &[f32])],
    ) {
        if self.shadow.is_some() {
            // The shadowing field's bookkeeping needs the plan's hysteresis;
            // without one, which probes blended is all (no second plan).
            let (base, irr_scale, _) = self.blend_plan(frame);
            let frames = self.blend_frames(frame);
            if let Some(plan) = self.device_shadow_blend(&shadow_base(&base, irr_scale, &frames), lights) {
                self.accept_device_shadow_blend(&plan);
            }
        }
        let updated = frame.blending();
        match frame.measure_change {
            true => self.accept_device_change(batch, &updated, earlier_changes),
            // No budget: the device measures nothing, and what it measured
            // before is stale by the time a budget runs again.
            false => self.forget_pending_changes(),
        }
        self.count_unblended_frames(frame);
        self.after_update(&updated);
    }

    /// State transitions and hysteresis ramps after a blend.
    fn after_update(&mut self, updated: &[bool]) {
        self.frames_updated += 1;
        self.probes_reset_since_blend.clear();
        self.pending_seeds.clear();
        let max_h = self.settings.probe_hysteresis;
        self.active_probes_last = updated.iter().filter(|a| **a).count();
        for (p, _) in updated.iter().enumerate().filter(|(_, u)| **u) {
            let fresh = !self.probe_has_history[p] || self.probe_states[p].is_new();
            let seed = self.probe_seeded[p] as u32;
            self.probe_blends[p] = if fresh { 1 + seed } else { self.probe_blends[p].saturating_add(1) };
            self.probe_has_history[p] = true;
            self.probe_seeded[p] = false;
            let state = self.probe_states[p].after_update();
            if matches!(state, ProbeState::Alive | ProbeState::UsageSleeping) {
                let target = if state == ProbeState::Alive { max_h } else { 0.5 * max_h };
                self.probe_hysteresis[p] += 0.1 * (target - self.probe_hysteresis[p]);
            }
            self.probe_states[p] = state;
        }
        self.refresh_usable();
        self.tick_scene_events();
    }

    /// One update less for each scene event's hysteresis reduction.
    pub(super) fn tick_scene_events(&mut self) {
        for events in [&mut self.irradiance_events, &mut self.visibility_events] {
            for e in events.iter_mut() {
                e.frames_left = e.frames_left.saturating_sub(1);
            }
            events.retain(|e| e.frames_left > 0);
        }
    }
}

/// A blend plan's per-probe entries as a device takes them
/// (`DeviceVolumeBlend::probe_blend`: first ray as `u32`).
pub(super) fn device_entries(base: Vec<Option<(usize, f32)>>) -> Vec<Option<(u32, f32)>> {
    base.into_iter().map(|b| b.map(|(first, h)| (first as u32, h))).collect()
}

/// The hysteresis cap of a ramp's blend `n` (from 0): 1 − 1/(n + 1), the
/// running mean of n + 1 samples.
fn ramp_cap(n: u32) -> f32 {
    1.0 - 1.0 / (n as f32 + 1.0)
}

/// The shadowing field's blend plan from the irradiance one: per probe its
/// first ray and its occlusion hysteresis, (α · the scene-event scale)^k (a
/// light that changes changes the shadows, so the irradiance scale applies).
fn shadow_base(base: &[Option<(usize, f32)>], irr_scale: f32, frames: &[u32]) -> Vec<Option<(usize, f32)>> {
    base.iter()
        .zip(frames)
        .map(|(b, k)| b.map(|(first, h)| (first, hysteresis_over_frames(h * irr_scale, *k))))
        .collect()
}

/// The blend's per-ray inputs from a batch's hits and the caller's radiance, the
/// backface rule applied once per ray (seed 004 §4.1; RTXGI stores −0.2·t): a
/// backface hit gets zero radiance and a short negative distance, so the probe
/// reads as shadowed there; a miss keeps the caller's radiance (the sky) and the
/// ray's max distance. Fills `radiance_out` and `distance_out`.
pub(crate) fn blend_inputs(
    batch: &ProbeRayBatch,
    hits: &[ProbeRayHit],
    radiance: &[Vec3],
    radiance_out: &mut Vec<Vec3>,
    distance_out: &mut Vec<f32>,
) {
    radiance_out.clear();
    distance_out.clear();
    for ((h, &l), &max) in hits.iter().zip(radiance).zip(&batch.max_distances_m) {
        let d = h.distance_m;
        let (l, d) = if d < 0.0 {
            (Vec3::ZERO, BACKFACE_DISTANCE_SCALE * d)
        } else if d.is_finite() {
            (l, d)
        } else {
            (l, max)
        };
        radiance_out.push(l);
        distance_out.push(d);
    }
}
