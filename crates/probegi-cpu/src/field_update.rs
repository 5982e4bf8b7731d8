//! The convenience update: the field set's seam (`probegi_field::ddgi_field_set`)
//! driven with probegi's own scene, ray tracer and shading, the way an engine
//! would drive it with its own; [`FieldSetUpdate`] and [`VolumeUpdate`] add it
//! to the field's types. One call per frame; per-pass milliseconds go to `pass_ms` under
//! `ray_gen`, `probe_init` (initialisation rounds: trace and apply), `trace`
//! (update rays, plus the usage classification), `shade`, `blend` and `border`.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::Vec3;
use probegi_scene::{RayTracer, Scene};

use probegi_field::backend::{BackendError, ProbeBatchTracer};
use probegi_field::ddgi_field_set::{DdgiFieldSet, HostHits, ProbeRayHit, UpdateStep};
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_field::probe_ray_gen::probe_ray_directions;

use crate::direct::DirectLighting;
use crate::probe_shade::{ProbeShadeInputs, shade_probe_rays};
use crate::probe_trace::{Surfel, surfel_hit, surfels_from_hits, trace_probe_batch, trace_probe_distances};

/// The convenience update on a [`DdgiFieldSet`] (see the module docs).
pub trait FieldSetUpdate {
    /// One field update of every volume through the seam. Returns the rays traced
    /// (probe rays plus shading shadow rays). A set whose field a device holds
    /// (`field_on_device`) needs [`Self::update_traced_by`] with that device:
    /// here the update is skipped (a debug assertion names it).
    fn update(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        direct: &DirectLighting<'_>,
        seed: u64,
        frame: u32,
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) -> u64;

    /// [`Self::update`] with the probe ray batches traced by `batch_tracer`
    /// when given (a GPU trace), and shaded by it when it shades
    /// ([`ProbeBatchTracer::shade_batch`]; otherwise the CPU shades, its shadow
    /// rays going to `tracer` through `direct`); with its
    /// [`ProbeBatchTracer::device_field`] the whole update stays on the device.
    /// Returns the rays traced on the CPU plus the batch rays; shadow rays traced
    /// elsewhere are not counted. An error of the batch tracer, or hits of the
    /// wrong count, end the update with it.
    #[allow(clippy::too_many_arguments)]
    fn update_traced_by(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        batch_tracer: Option<&dyn ProbeBatchTracer>,
        direct: &DirectLighting<'_>,
        seed: u64,
        frame: u32,
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) -> Result<u64, BackendError>;
}

/// The convenience update on one [`DdgiVolume`], and a fresh count of its probes inside geometry.
pub trait VolumeUpdate {
    /// One field update of this volume alone (a set of one; see [`FieldSetUpdate::update`]).
    /// A tracking volume does not move here: drive it through a [`DdgiFieldSet`]
    /// and `set_tracking_target`.
    fn update(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        direct: &DirectLighting<'_>,
        seed: u64,
        frame: u32,
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) -> u64;

    /// Probes inside geometry by their rays (> 25 % backfaces), from a fresh trace.
    fn count_probes_inside_geometry(&self, tracer: &dyn RayTracer, seed: u64) -> usize;
}

impl FieldSetUpdate for DdgiFieldSet {
    fn update(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        direct: &DirectLighting<'_>,
        seed: u64,
        frame: u32,
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) -> u64 {
        // The CPU tracer cannot fail; a field held by a device is the caller's mistake.
        self.update_traced_by(scene, tracer, None, direct, seed, frame, pass_ms).unwrap_or_else(|e| {
            debug_assert!(false, "DdgiFieldSet::update: {e}");
            0
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn update_traced_by(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        batch_tracer: Option<&dyn ProbeBatchTracer>,
        direct: &DirectLighting<'_>,
        seed: u64,
        frame: u32,
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) -> Result<u64, BackendError> {
        let mut traced = 0;
        let mut batch_hits = Vec::new();
        let mut surfels: Vec<Surfel> = Vec::new();
        let mut hits: Vec<ProbeRayHit> = Vec::new();
        let mut radiance: Vec<Vec3> = Vec::new();
        let mut own_ms: BTreeMap<&'static str, f64> = BTreeMap::new();
        let time = |name: &'static str, t: Instant, ms: &mut BTreeMap<&'static str, f64>| {
            *ms.entry(name).or_default() += t.elapsed().as_secs_f64() * 1e3
        };
        let static_part = tracer.static_part();
        let mut on_device = false;
        let device = batch_tracer.and_then(|bt| bt.device_field());
        let mut step = self.begin_update(seed, frame);
        // Any seam error here is a bug of this driver, not of the caller's input.
        let fail = |e: probegi_field::SeamError| -> UpdateStep {
            debug_assert!(false, "field set seam: {e}");
            UpdateStep::Done
        };
        loop {
            match step {
                UpdateStep::TraceRays => {
                    let t = Instant::now();
                    let init = self.ray_batch().static_geometry_only();
                    // A relocation round on a device that runs it: only offsets come back.
                    if let (Some(bt), HostHits::Relocation) = (device, self.hits_needed_on_host()) {
                        let plan = self.device_relocation_plan()?;
                        if let Some(offsets) = bt.relocate(self.ray_batch(), &plan) {
                            traced += self.ray_batch().len() as u64;
                            step = self.submit_device_relocation(&offsets?).unwrap_or_else(fail);
                            time("probe_init", t, &mut own_ms);
                            continue;
                        }
                    }
                    // A classification round on a device that runs it: 16 bytes a probe come back.
                    if let (Some(bt), HostHits::Classification) = (device, self.hits_needed_on_host()) {
                        let plan = self.device_classification_plan()?;
                        if let Some(results) = bt.classify(self.ray_batch(), &plan) {
                            drop(plan);
                            traced += self.ray_batch().len() as u64;
                            step = self.submit_device_classification(&results?).unwrap_or_else(fail);
                            time("probe_init", t, &mut own_ms);
                            continue;
                        }
                    }
                    // The update batch on a device that keeps the field: the hits stay there.
                    if let (Some(bt), false) = (device, init) {
                        let usage = (self.hits_needed_on_host() == HostHits::ProbeUsage)
                            .then(|| self.volumes().iter().map(|v| v.grid.spacing_m.length()).collect::<Vec<_>>());
                        if let Some(counts) = bt.trace_resident(self.ray_batch(), usage.as_deref()) {
                            traced += self.ray_batch().len() as u64;
                            step = self.submit_device_hits(&counts?).unwrap_or_else(fail);
                            on_device = true;
                            time("trace", t, &mut own_ms);
                            continue;
                        }
                    }
                    // Initialisation sees static geometry only: moving objects wake probes instead.
                    let tr: &dyn RayTracer = if init { static_part.as_deref().unwrap_or(tracer) } else { tracer };
                    traced += match batch_tracer {
                        Some(bt) => {
                            bt.closest_hits(self.ray_batch(), init, &mut batch_hits)?;
                            if batch_hits.len() != self.ray_batch().len() {
                                return Err(BackendError::Seam(probegi_field::SeamError::WrongLength {
                                    what: "the batch tracer's hits",
                                    expected: self.ray_batch().len(),
                                    got: batch_hits.len(),
                                }));
                            }
                            surfels_from_hits(scene, self.ray_batch(), &batch_hits, &mut surfels);
                            self.ray_batch().len() as u64
                        }
                        None => trace_probe_batch(scene, tr, self.ray_batch(), &mut surfels),
                    };
                    hits.clear();
                    hits.extend(surfels.iter().map(surfel_hit));
                    step = self.submit_hits(&hits).unwrap_or_else(fail);
                    time(if init { "probe_init" } else { "trace" }, t, &mut own_ms);
                }
                UpdateStep::ShadeRays if on_device => {
                    let bt = batch_tracer
                        .and_then(|bt| bt.device_field())
                        .ok_or_else(|| BackendError::Unsupported("the device that traced the batch is gone".into()))?;
                    let plan = self.device_blend_plan()?;
                    let view = self.view();
                    let device_ms = bt.shade_and_blend(
                        self.ray_batch(),
                        &view,
                        !self.field_on_device(),
                        &plan,
                        self.volumes(),
                        seed,
                        frame,
                    )?;
                    drop((view, plan));
                    for (pass, ms) in device_ms {
                        *own_ms.entry(pass).or_default() += ms;
                    }
                    step = self.submit_device_blend().unwrap_or_else(fail);
                }
                UpdateStep::ShadeRays => {
                    let t = Instant::now();
                    // The host shades (the field's previous light) and blends.
                    self.sync_host_atlases(batch_tracer)?;
                    let view = self.view();
                    let inputs = ProbeShadeInputs {
                        scene,
                        direct,
                        field: &view,
                        volumes: self.volumes(),
                        batch: self.ray_batch(),
                        surfels: &surfels,
                        seed,
                        frame,
                    };
                    let on_device = batch_tracer
                        .and_then(|bt| bt.shade_batch(inputs.batch, &view, inputs.volumes, seed, frame, &mut radiance));
                    match on_device {
                        Some(result) => result?,
                        None => traced += shade_probe_rays(&inputs, &mut radiance),
                    }
                    drop(view);
                    time("shade", t, &mut own_ms);
                    step = self.submit_radiance(&radiance).unwrap_or_else(fail);
                }
                UpdateStep::Done => break,
            }
        }
        // The set's own passes (ray_gen, blend, border; init and classify bookkeeping
        // are inside the timed trace steps above).
        for (k, v) in &self.last_pass_ms {
            if !matches!(*k, "probe_init" | "classify") {
                *pass_ms.entry(k).or_default() += v;
            }
        }
        for (k, v) in own_ms {
            *pass_ms.entry(k).or_default() += v;
        }
        Ok(traced)
    }
}

impl VolumeUpdate for DdgiVolume {
    fn update(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        direct: &DirectLighting<'_>,
        seed: u64,
        frame: u32,
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) -> u64 {
        let placeholder = DdgiVolume::new(
            probegi_core::ddgi_settings::DdgiVolumeSettings {
                probe_counts: glam::UVec3::ONE,
                probe_rays_per_probe: 1,
                ..Default::default()
            },
            (Vec3::ZERO, Vec3::ONE),
        );
        let mut set = DdgiFieldSet::single(std::mem::replace(self, placeholder));
        let traced = set.update(scene, tracer, direct, seed, frame, pass_ms);
        if let Some(v) = set.into_volumes().pop() {
            *self = v;
        }
        traced
    }

    fn count_probes_inside_geometry(&self, tracer: &dyn RayTracer, seed: u64) -> usize {
        use probegi_core::probe_relocation::{is_inside_geometry, probe_ray_stats};
        let n = self.settings.probe_rays_per_probe as usize;
        let dirs = probe_ray_directions(&self.settings, seed, u32::MAX - 2000);
        let d = trace_probe_distances(tracer, &self.probe_positions, &dirs, self.settings.probe_max_ray_distance_m);
        (0..self.grid.probe_count())
            .filter(|&p| is_inside_geometry(&probe_ray_stats(&dirs, &d[p * n..(p + 1) * n])))
            .count()
    }
}
