//! The shadowing field's share of a volume's update (seed 003 ch. 5,
//! `probegi_core::shadow_field`): two-frame ray generation (§5.1, Fig. 5.2) and
//! the occlusion blend (eq. 5.1–5.3).
//!
//! In frame f the probes cast their primary rays (the irradiance field's own:
//! the maps share the volume's grid, relocation, states, tracking window and
//! batch). Their hits become the probe's surfels. In frame f+1 each front-face
//! surfel casts one shadow ray per served light, appended to the same batch
//! after every volume's primary rays; a miss or back-face surfel casts none but
//! still counts, as the seed's zero-length dummy ray does: visible, in the
//! direction from the probe to the light.
//!
//! **Lights.** A probe serves the `shadow_field_max_lights` punctual lights
//! brightest at the volume's centre (irradiance `I/d²` of point and spot lights,
//! `E` of directional ones, max over the colour channels), every one of them
//! weighted alike in eq. 5.2. Emitters (area lights) are not served yet: their
//! shadows stay ray-traced.
//!
//! *Deviation:* a surfel facing away from a light (`n·l ≤ 0`) casts no shadow ray
//! and adds no sample for it: it says nothing about whether surfaces facing the
//! light see it, and as a zero it would darken them.
//!
//! *Extension:* with `shadow_field_surfel_reach_rel` > 0, front-face surfels
//! farther from their probe than that many cage diagonals cast no shadow ray
//! either. The seed averages every surfel a probe sees, so a probe in a large
//! shadow that sees lit walls beyond it reads mostly lit; keeping the surfels
//! near the probe (those its cage's shading points resemble) brings such
//! shadows out: on `builtin:shadow-box` the visibility image's HDR-FLIP against
//! exact shadow rays falls from 0.134 (0, the seed) to 0.089 (1) and 0.085 (0.5).

use glam::Vec3;
use probegi_core::probe_atlas::ProbeAtlas;
use probegi_core::shadow_field::{ShadowSample, blend_shadow_tile};
use probegi_scene::{LightKind, PunctualLight};
use rayon::prelude::*;

use crate::device_plans::DeviceShadowBlend;
use crate::seam::{ProbeRayBatch, ProbeRayHit};

use super::{DdgiVolume, VolumeFrame};

/// One primary ray's result kept for the next frame's shadow rays.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Surfel {
    /// A miss or a back face: no shadow ray; counts as visible (seed §5.1).
    Free,
    /// A front-face hit: position and unit facing normal.
    Front(Vec3, Vec3),
}

/// A volume's occlusion maps and the surfels its probes found last frame.
#[derive(Clone, Debug)]
pub struct ShadowField {
    /// Per probe storage slot, the octahedral map of mean light visibility
    /// (`shadow_field_texels`² inside, guard border).
    pub occlusion: ProbeAtlas<f32>,
    /// Per probe, its last frame's primary results (`surfel_rays` each), or
    /// empty when it has none (it did not trace, or was reset).
    surfels: Vec<Vec<Surfel>>,
    /// Per probe, whether its map has blended shadow samples: the first blend
    /// that has some replaces the initial 1 (hysteresis 0), as the irradiance
    /// blend's first does.
    has_history: Vec<bool>,
    /// The last update batch: each probe's first ray in it (`u32::MAX`: none),
    /// its rays per probe and its frame, which a device that kept that batch
    /// casts this frame's shadow rays from ([`DeviceShadowBlend`]).
    prev_first_ray: Vec<u32>,
    prev_ray_count: u32,
    prev_frame: Option<u32>,
}

impl ShadowField {
    /// Maps for `probes` probes of `texels`² texels, every texel 1 (lit) until blended.
    pub(crate) fn new(probes: usize, texels: u32) -> Self {
        let mut occlusion = ProbeAtlas::new(probes, texels);
        occlusion.texels.fill(1.0);
        Self {
            occlusion,
            surfels: vec![Vec::new(); probes],
            has_history: vec![false; probes],
            prev_first_ray: vec![u32::MAX; probes],
            prev_ray_count: 0,
            prev_frame: None,
        }
    }

    /// Forgets probe `p`'s map and surfels (scrolled in, re-initialised).
    pub(crate) fn reset_probe(&mut self, p: usize) {
        self.occlusion.tile_mut(p).fill(1.0);
        self.surfels[p].clear();
        self.has_history[p] = false;
        self.prev_first_ray[p] = u32::MAX;
    }
}

/// One shadow sample slot of a frame: its probe, the direction to the light,
/// and the shadow ray that decides it (`None`: a free surfel, visible).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ShadowSlot {
    probe: u32,
    dir_to_light: Vec3,
    ray: Option<u32>,
}

/// The lights a volume's probes serve: the `max` brightest at `centre`.
pub(crate) fn served_lights(lights: &[PunctualLight], centre: Vec3, max: u32) -> Vec<PunctualLight> {
    let brightness = |l: &PunctualLight| {
        let power = (l.color * l.intensity).max_element().max(0.0);
        match l.kind {
            LightKind::Directional => power,
            _ => power / (l.position - centre).length_squared().max(1e-6),
        }
    };
    let mut ranked: Vec<(f32, &PunctualLight)> = lights.iter().map(|l| (brightness(l), l)).collect();
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
    ranked.into_iter().filter(|(b, _)| *b > 0.0).take(max as usize).map(|(_, l)| l.clone()).collect()
}

/// Unit direction and distance from `from` to `light` (infinite for a directional light).
fn toward(light: &PunctualLight, from: Vec3) -> Option<(Vec3, f32)> {
    match light.kind {
        LightKind::Directional => Some((-light.direction.normalize_or_zero(), f32::INFINITY)),
        _ => {
            let to = light.position - from;
            let d = to.length();
            (d > 0.0 && d.is_finite()).then(|| (to / d, d))
        }
    }
}

impl DdgiVolume {
    /// Appends this frame's shadow rays (§5.1) for the probes that blend this
    /// frame, from the surfels their last frame's rays found, toward `lights`.
    pub(crate) fn plan_shadow_rays(
        &mut self,
        frame: &mut VolumeFrame,
        lights: &[PunctualLight],
        batch: &mut ProbeRayBatch,
    ) {
        frame.shadow_slots.clear();
        frame.shadow_first_ray = batch.len();
        let Some(shadow) = self.shadow.as_ref() else { return };
        let centre = self.grid.origin_m + self.grid.spacing_m * (self.grid.probe_counts.as_vec3() - 1.0) * 0.5;
        let served = served_lights(lights, centre, self.settings.shadow_field_max_lights);
        let (mut origins, mut dirs, mut maxes) = (Vec::new(), Vec::new(), Vec::new());
        let first = batch.len() as u32;
        let reach_m = self.shadow_surfel_reach_m();
        for p in (0..self.grid.probe_count()).filter(|&p| frame.active[p] && frame.first_ray[p] != u32::MAX) {
            for surfel in &shadow.surfels[p] {
                for light in &served {
                    match *surfel {
                        Surfel::Free => {
                            if let Some((dir, _)) = toward(light, self.probe_positions[p]) {
                                frame.shadow_slots.push(ShadowSlot { probe: p as u32, dir_to_light: dir, ray: None });
                            }
                        }
                        Surfel::Front(pos, n) => {
                            if reach_m > 0.0 && (pos - self.probe_positions[p]).length() > reach_m {
                                continue;
                            }
                            let Some((dir, d)) = toward(light, pos) else { continue };
                            if n.dot(dir) <= 0.0 {
                                continue;
                            }
                            let eps = 1e-4 * (1.0 + pos.abs().max_element());
                            let ray = first + origins.len() as u32;
                            origins.push(pos + n * eps);
                            dirs.push(dir);
                            maxes.push(if d.is_finite() { d * (1.0 - 1e-4) } else { f32::INFINITY });
                            frame.shadow_slots.push(ShadowSlot { probe: p as u32, dir_to_light: dir, ray: Some(ray) });
                        }
                    }
                }
            }
        }
        batch.push_rays(&origins, &dirs, &maxes);
    }

    /// After the trace: the shadow rays' visibility into the frame's samples,
    /// then this frame's primary hits kept as the next frame's surfels.
    pub(crate) fn accept_shadow_hits(
        &mut self,
        frame: &mut VolumeFrame,
        frame_index: u32,
        batch: &ProbeRayBatch,
        hits: &[ProbeRayHit],
    ) {
        self.record_shadow_batch(frame, frame_index);
        let Some(shadow) = self.shadow.as_mut() else { return };
        frame.shadow_samples.clear();
        frame.shadow_samples.extend(frame.shadow_slots.iter().map(|s| {
            // Any hit before the light occludes it (either face); a miss sees it.
            let visible = s.ray.is_none_or(|r| hits.get(r as usize).is_none_or(|h| h.distance_m == f32::INFINITY));
            (s.probe, ShadowSample { dir_to_light: s.dir_to_light, visible: if visible { 1.0 } else { 0.0 } })
        }));
        let n = frame.ray_count;
        for (p, surfels) in shadow.surfels.iter_mut().enumerate() {
            surfels.clear();
            let first = frame.first_ray[p];
            if first == u32::MAX {
                continue;
            }
            surfels.extend((first as usize..first as usize + n).map(|r| {
                let t = hits[r].distance_m;
                if t.is_finite() && t >= 0.0 && hits[r].normal != Vec3::ZERO {
                    Surfel::Front(batch.origins_m[r] + batch.directions[r] * t, hits[r].normal)
                } else {
                    Surfel::Free
                }
            }));
        }
    }

    /// Front-face surfels farther than this from their probe cast no shadow ray
    /// (`shadow_field_surfel_reach_rel` × the cage diagonal; 0: every surfel).
    pub(crate) fn shadow_surfel_reach_m(&self) -> f32 {
        self.settings.shadow_field_surfel_reach_rel.max(0.0) * self.grid.spacing_m.length()
    }

    /// This frame's update batch as the one the next frame's shadow rays start
    /// from on a device that keeps it.
    pub(crate) fn record_shadow_batch(&mut self, frame: &VolumeFrame, frame_index: u32) {
        if let Some(shadow) = self.shadow.as_mut() {
            shadow.prev_first_ray.clone_from(&frame.first_ray);
            shadow.prev_first_ray.resize(self.grid.probe_count(), u32::MAX);
            shadow.prev_ray_count = frame.ray_count as u32;
            shadow.prev_frame = Some(frame_index);
        }
    }

    /// The shadowing field's update as data for a device that kept the last
    /// update batch (`base`: per probe its first ray and occlusion hysteresis
    /// this frame, `None` where it does not blend): `None` without a field or
    /// a previous batch.
    pub(crate) fn device_shadow_blend(
        &self,
        base: &[Option<(usize, f32)>],
        lights: &[PunctualLight],
    ) -> Option<DeviceShadowBlend> {
        let shadow = self.shadow.as_ref()?;
        let prev_frame = shadow.prev_frame?;
        let centre = self.grid.origin_m + self.grid.spacing_m * (self.grid.probe_counts.as_vec3() - 1.0) * 0.5;
        let probes = base
            .iter()
            .enumerate()
            .filter_map(|(p, b)| {
                let (_, h) = (*b)?;
                let first = *shadow.prev_first_ray.get(p)?;
                (first != u32::MAX).then(|| {
                    let h = if shadow.has_history[p] { h } else { 0.0 };
                    (p as u32, first, shadow.prev_ray_count, h)
                })
            })
            .collect();
        Some(DeviceShadowBlend {
            surfel_reach_m: self.shadow_surfel_reach_m(),
            prev_frame,
            lights: served_lights(lights, centre, self.settings.shadow_field_max_lights),
            probes,
        })
    }

    /// The bookkeeping of a device's shadowing-field update by `plan`: the
    /// probes it blended have history; the host's surfels are stale.
    pub(crate) fn accept_device_shadow_blend(&mut self, plan: &DeviceShadowBlend) {
        let Some(shadow) = self.shadow.as_mut() else { return };
        if !plan.lights.is_empty() {
            for &(p, ..) in &plan.probes {
                shadow.has_history[p as usize] = true;
            }
        }
        shadow.surfels.iter_mut().for_each(Vec::clear);
    }

    /// Eq. 5.2–5.3 into the occlusion maps of the probes that blend this frame
    /// (`hysteresis[p]`: `Some(α)`), from the frame's samples. Returns per
    /// probe the change of the tiles it blended (`probegi_core::probe_change`).
    pub(crate) fn blend_shadow_maps(&mut self, frame: &VolumeFrame, hysteresis: &[Option<f32>]) -> Vec<Option<f32>> {
        let Some(shadow) = self.shadow.as_mut() else { return Vec::new() };
        let interior = shadow.occlusion.interior;
        let len = shadow.occlusion.tile_len();
        // Samples are in probe order: each probe's run, found once.
        let mut runs = vec![(0usize, 0usize); self.grid.probe_count()];
        let mut k = 0;
        while k < frame.shadow_samples.len() {
            let p = frame.shadow_samples[k].0 as usize;
            let start = k;
            while k < frame.shadow_samples.len() && frame.shadow_samples[k].0 as usize == p {
                k += 1;
            }
            runs[p] = (start, k);
        }
        let samples: Vec<ShadowSample> = frame.shadow_samples.iter().map(|s| s.1).collect();
        let history = &shadow.has_history;
        let change: Vec<Option<f32>> = shadow
            .occlusion
            .texels
            .par_chunks_mut(len)
            .enumerate()
            .map(|(p, tile)| match (hysteresis.get(p).copied().flatten(), runs[p]) {
                (Some(h), (a, b)) if b > a => {
                    Some(blend_shadow_tile(tile, interior, &samples[a..b], if history[p] { h } else { 0.0 }))
                }
                _ => None,
            })
            .collect();
        for (p, c) in change.iter().enumerate() {
            if c.is_some() {
                shadow.has_history[p] = true;
            }
        }
        change
    }
}
