//! The convenience update: the field set's seam (`probegi_field::ddgi_field_set`)
//! driven with probegi's own scene, ray tracer and shading, the way an engine
//! would drive it with its own; [`FieldSetUpdate`] and [`VolumeUpdate`] add it
//! to the field's types. One call per frame; per-pass milliseconds go to `pass_ms` under
//! `ray_gen`, `probe_init` (initialisation rounds: trace and apply), `trace`
//! (update rays, plus the usage classification), `shade`, `blend` and `border`.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::Vec3;
use probegi_scene::{RayHit, RayTracer, Scene};

use probegi_field::backend::{BackendError, DeviceField, ProbeBatchTracer};
use probegi_field::ddgi_field_set::{DdgiFieldSet, HostHits, ProbeRayHit, UpdateStep};
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_field::probe_ray_gen::probe_ray_directions;

use probegi_cpu::direct::DirectLighting;
use probegi_cpu::probe_shade::{ProbeShadeInputs, shade_probe_rays};
use probegi_cpu::probe_trace::{HitNormal, probe_ray_hits, trace_probe_batch, trace_probe_distances};

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

    /// [`Self::update_traced_by`] on a batch tracer that keeps the field on its
    /// device ([`ProbeBatchTracer::device_field`]) and shades there: no CPU
    /// lighting is built or read, so a frame whose update and camera frame
    /// both stay on the device runs none of `probegi_cpu`'s passes. Where a
    /// round would need the CPU to shade after all, the update ends with
    /// [`BackendError::Unsupported`] (use `update_traced_by`).
    fn update_on_device(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        device: &dyn ProbeBatchTracer,
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
        let driver = SeamDriver::new(scene, tracer, batch_tracer, Some(direct), seed, frame);
        drive_seam(self, driver, pass_ms)
    }

    fn update_on_device(
        &mut self,
        scene: &Scene,
        tracer: &dyn RayTracer,
        device: &dyn ProbeBatchTracer,
        seed: u64,
        frame: u32,
        pass_ms: &mut BTreeMap<&'static str, f64>,
    ) -> Result<u64, BackendError> {
        if device.device_field().is_none() {
            return Err(BackendError::Unsupported("update_on_device: the batch tracer keeps no field".into()));
        }
        let driver = SeamDriver::new(scene, tracer, Some(device), None, seed, frame);
        drive_seam(self, driver, pass_ms)
    }
}

/// One update of `set` through its seam by `driver`; see [`FieldSetUpdate`].
fn drive_seam(
    set: &mut DdgiFieldSet,
    mut driver: SeamDriver<'_>,
    pass_ms: &mut BTreeMap<&'static str, f64>,
) -> Result<u64, BackendError> {
    // A device that makes the update rays itself gets them per probe: no
    // O(rays) arrays on the host (filled after all if the host traces them).
    set.set_update_rays_on_device(driver.device.is_some_and(|d| d.generates_update_rays()));
    // The shadowing field serves the lights as posed for this frame.
    set.set_shadow_lights(&driver.scene.lights);
    set.set_shadow_on_device(driver.device.is_some_and(|d| d.blends_shadow_field()));
    let t = Instant::now();
    let mut step = set.begin_update(driver.seed, driver.frame);
    time(HOST_PLAN_PASS, t, &mut driver.own_ms);
    loop {
        step = match step {
            UpdateStep::TraceRays => driver.trace_rays(set)?,
            UpdateStep::ShadeRays if driver.on_device => driver.shade_and_blend_on_device(set)?,
            UpdateStep::ShadeRays => driver.shade_on_host(set)?,
            UpdateStep::Done => break,
        };
    }
    // The set's own passes (ray_gen, blend, border; init and classify bookkeeping
    // are inside the timed trace steps above).
    for (k, v) in &set.last_pass_ms {
        if !matches!(*k, "probe_init" | "classify") {
            *pass_ms.entry(k).or_default() += v;
        }
    }
    for (k, v) in driver.own_ms {
        *pass_ms.entry(k).or_default() += v;
    }
    Ok(driver.traced)
}

/// The `pass_ms` entry of the field set's own host work in an update:
/// planning (probe states, the batch's probe records) and, where the device
/// traces, shades and blends, the blend plan and the bookkeeping of the
/// results (state transitions, hysteresis ramps). Neither the passes nor the
/// recording of their commands are in it.
pub const HOST_PLAN_PASS: &str = "host_plan";

/// Adds the milliseconds since `t` to pass `name` in `ms`.
fn time(name: &'static str, t: Instant, ms: &mut BTreeMap<&'static str, f64>) {
    *ms.entry(name).or_default() += t.elapsed().as_secs_f64() * 1e3
}

/// Any seam error here is a bug of this driver, not of the caller's input.
fn seam_bug(e: probegi_field::SeamError) -> UpdateStep {
    debug_assert!(false, "field set seam: {e}");
    UpdateStep::Done
}

/// [`FieldSetUpdate::update_traced_by`] between the seam's steps: the caller's
/// scene, tracers and shading, the buffers every round reuses, the rays traced
/// and this driver's own pass milliseconds.
struct SeamDriver<'u> {
    scene: &'u Scene,
    tracer: &'u dyn RayTracer,
    batch_tracer: Option<&'u dyn ProbeBatchTracer>,
    /// The CPU's lighting, for rays the CPU shades (`None`: the device shades
    /// them all, `FieldSetUpdate::update_on_device`).
    direct: Option<&'u DirectLighting<'u>>,
    seed: u64,
    frame: u32,
    /// Static geometry alone, for initialisation rounds (`None`: all of it is).
    static_part: Option<Box<dyn RayTracer + 'u>>,
    /// The device that keeps the field, when the batch tracer has one.
    device: Option<&'u dyn DeviceField>,
    traced: u64,
    /// The closest hits of the last batch traced on the host side.
    batch_hits: Vec<Option<RayHit>>,
    hits: Vec<ProbeRayHit>,
    radiance: Vec<Vec3>,
    own_ms: BTreeMap<&'static str, f64>,
    /// The update batch was traced on the device, which keeps its hits.
    on_device: bool,
}

impl<'u> SeamDriver<'u> {
    fn new(
        scene: &'u Scene,
        tracer: &'u dyn RayTracer,
        batch_tracer: Option<&'u dyn ProbeBatchTracer>,
        direct: Option<&'u DirectLighting<'u>>,
        seed: u64,
        frame: u32,
    ) -> Self {
        Self {
            scene,
            tracer,
            batch_tracer,
            direct,
            seed,
            frame,
            static_part: tracer.static_part(),
            device: batch_tracer.and_then(|bt| bt.device_field()),
            traced: 0,
            batch_hits: Vec::new(),
            hits: Vec::new(),
            radiance: Vec::new(),
            own_ms: BTreeMap::new(),
            on_device: false,
        }
    }

    /// `UpdateStep::TraceRays`: one round of the set's batch, on the device when
    /// it runs that round, else closest hits (from the batch tracer or the CPU)
    /// into the seam's hits.
    fn trace_rays(&mut self, set: &mut DdgiFieldSet) -> Result<UpdateStep, BackendError> {
        let t = Instant::now();
        let init = set.ray_batch().static_geometry_only();
        if let Some(step) = self.trace_on_device(set, init, t)? {
            return Ok(step);
        }
        // The host traces after all: the batch's rays in arrays.
        set.fill_ray_arrays();
        // Initialisation sees static geometry only: moving objects wake probes instead.
        let tr: &dyn RayTracer = if init { self.static_part.as_deref().unwrap_or(self.tracer) } else { self.tracer };
        self.traced += match self.batch_tracer {
            Some(bt) => {
                bt.closest_hits(set.ray_batch(), init, &mut self.batch_hits)?;
                if self.batch_hits.len() != set.ray_batch().len() {
                    return Err(BackendError::Seam(probegi_field::SeamError::WrongLength {
                        what: "the batch tracer's hits",
                        expected: set.ray_batch().len(),
                        got: self.batch_hits.len(),
                    }));
                }
                set.ray_batch().len() as u64
            }
            None => trace_probe_batch(tr, set.ray_batch(), &mut self.batch_hits),
        };
        let normal = HitNormal::for_round(set.hit_normals_needed(), init);
        probe_ray_hits(self.scene, &self.batch_hits, normal, &mut self.hits);
        let step = if init {
            // The plane normals of the hits the set keeps for its classification round.
            let (scene, batch_hits) = (self.scene, &self.batch_hits);
            let normal_of = |r: usize| batch_hits[r].as_ref().map_or(Vec3::ZERO, |h| scene.facing_geometric_normal(h));
            set.submit_init_hits(&self.hits, &normal_of)
        } else {
            set.submit_hits(&self.hits)
        };
        let step = step.unwrap_or_else(seam_bug);
        time(if init { "probe_init" } else { "trace" }, t, &mut self.own_ms);
        Ok(step)
    }

    /// The rounds a device that keeps the field runs itself: the
    /// initialisation rounds, chained, and the update batch. `None` when this round is not one
    /// of them (or the device leaves it to the host).
    fn trace_on_device(
        &mut self,
        set: &mut DdgiFieldSet,
        init: bool,
        t: Instant,
    ) -> Result<Option<UpdateStep>, BackendError> {
        // Every initialisation round on a device that chains them: each
        // probe's offset and (inside, kept) come back once, after all of them.
        if let (Some(bt), true) = (self.device, init)
            && let Ok(plan) = set.device_init_plan()
            && let Some(results) = bt.initialise(&plan)
        {
            drop(plan);
            let (results, before) = (results?, set.last_init_rays);
            let step = set.submit_device_init(&results).unwrap_or_else(seam_bug);
            self.traced += set.last_init_rays - before;
            time("probe_init", t, &mut self.own_ms);
            return Ok(Some(step));
        }
        // The update batch on a device that keeps the field: the hits stay there.
        if let (Some(bt), false, false) = (self.device, init, set.hits_needed_on_host() == HostHits::All) {
            let usage = set.device_usage_request();
            if let Some(counts) = bt.trace_resident(set.ray_batch(), usage.as_ref()) {
                self.traced += set.ray_batch().len() as u64;
                let counts = counts?;
                let t_plan = Instant::now();
                let step = set.submit_device_hits(&counts).unwrap_or_else(seam_bug);
                time(HOST_PLAN_PASS, t_plan, &mut self.own_ms);
                self.on_device = true;
                time("trace", t, &mut self.own_ms);
                return Ok(Some(step));
            }
        }
        Ok(None)
    }

    /// `UpdateStep::ShadeRays` after a trace on the device: it shades and blends
    /// there; its per-pass milliseconds join this driver's.
    fn shade_and_blend_on_device(&mut self, set: &mut DdgiFieldSet) -> Result<UpdateStep, BackendError> {
        let bt = self
            .batch_tracer
            .and_then(|bt| bt.device_field())
            .ok_or_else(|| BackendError::Unsupported("the device that traced the batch is gone".into()))?;
        let t_plan = Instant::now();
        let plan = set.device_blend_plan()?;
        time(HOST_PLAN_PASS, t_plan, &mut self.own_ms);
        let view = set.view();
        let output = bt.shade_and_blend(
            set.ray_batch(),
            &view,
            !set.field_on_device(),
            &plan,
            set.volumes(),
            self.seed,
            self.frame,
        )?;
        drop((view, plan));
        for (pass, ms) in output.pass_ms {
            *self.own_ms.entry(pass).or_default() += ms;
        }
        let t_plan = Instant::now();
        let step = set.submit_device_blend(&output.probe_change)?;
        time(HOST_PLAN_PASS, t_plan, &mut self.own_ms);
        Ok(step)
    }

    /// `UpdateStep::ShadeRays` after a trace whose hits are on the host: the
    /// batch tracer shades when it does, else the CPU; the set blends.
    fn shade_on_host(&mut self, set: &mut DdgiFieldSet) -> Result<UpdateStep, BackendError> {
        let (seed, frame) = (self.seed, self.frame);
        let t = Instant::now();
        // The host shades (the field's previous light) and blends.
        set.sync_host_atlases(self.batch_tracer)?;
        let view = set.view();
        let (batch, volumes) = (set.ray_batch(), set.volumes());
        let on_device =
            self.batch_tracer.and_then(|bt| bt.shade_batch(batch, &view, volumes, seed, frame, &mut self.radiance));
        match on_device {
            Some(result) => result?,
            None => {
                let direct = self.direct.ok_or_else(|| {
                    BackendError::Unsupported("the device left the probe rays to the CPU to shade".into())
                })?;
                let hits = &self.batch_hits;
                let inputs =
                    ProbeShadeInputs { scene: self.scene, direct, field: &view, volumes, batch, hits, seed, frame };
                self.traced += shade_probe_rays(&inputs, &mut self.radiance);
            }
        }
        drop(view);
        time("shade", t, &mut self.own_ms);
        Ok(set.submit_radiance(&self.radiance).unwrap_or_else(seam_bug))
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
