//! The field set's seam (`probegi_field::ddgi_field_set`) driven by the wgpu
//! passes: [`WgpuProbeTracer`] is a `ProbeBatchTracer` (and, keeping the field,
//! a `DeviceField`) whose probe ray batches are traced by `bvh_trace` (the WGSL
//! CWBVH traversal) and, where the scene allows, shaded by `probe_shade`. Two ways to run an
//! update batch:
//!
//! - **field on the device** ([`WgpuProbeTracer::keeping_field`], what
//!   `--backend wgpu` uses): trace, shade, blend and border all run there; the
//!   atlases live in the resident `GpuDdgiField` that the shade and camera
//!   queries read, and the host sends per frame only the set's per-probe data
//!   (offsets, usable flags, the blend's per-probe hysteresis) and reads back
//!   nothing but, under the usage scheme, 16 bytes of usage counts a probe
//!   (`probegi_wgpu::probe_usage`). The atlases come back only when asked
//!   (`download_field`: a CPU camera frame, the end of a render, a test);
//! - **field on the host**: the hits and the shaded radiance come back, the set
//!   blends on the CPU and the field is uploaded for the next frame's queries.
//!
//! Either way the host plans the batches and keeps the set's bookkeeping (probe
//! states, hysteresis ramps). With the field kept there the initialisation
//! rounds run on the device, every relocation round and the classification
//! chained in one submission with one read-back of 32 bytes a probe
//! (`probe_relocation`, `probe_classification`; [`DeviceField::initialise`]);
//! on the host from the hits read back otherwise, and also where a volume's
//! rounds exceed a batch the device holds, or the adapter binds too few
//! storage buffers for the classification pass ([`WgpuProbeTracer::classification_note`]).
//!
//! The CPU backend is this backend's peer: both implement `probegi-field`'s
//! traits, neither depends on the other.

use std::sync::Mutex;

use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_volume_blend::DdgiFieldSetView;
use probegi_field::backend::{BackendError, CameraFrameOut, DeviceField, ProbeBatchTracer};
use probegi_field::ddgi_volume::DdgiVolume;
use probegi_field::device_frame::{DeviceFrame, DeviceFrameInput, DeviceFrameReadout, FrameLayer};
use probegi_field::device_plans::{
    DeviceBlendOutput, DeviceChangeKey, DeviceInitChain, DeviceInitResult, DeviceProbeChanges, DeviceUsageCounts,
    DeviceUsageRequest, DeviceVolumeBlend,
};
use probegi_field::seam::ProbeRayBatch;
use probegi_scene::{BvhTracer, RayHit, Scene, TlasLayout};

use crate::bvh_trace::{GpuBvh, GpuRay, GpuRayBatch, GpuRayTrace, TraceSegment};
use crate::camera_frame::{CameraFrame, GpuCameraPass};
use crate::ddgi_query::GpuDdgiField;
use crate::device_frame::{GpuFrame, GpuFrameInput};
use crate::gpu_scene::GpuScene;
use crate::gpu_timer::GpuTimer;
use crate::probe_blend::GpuProbeBlend;
use crate::probe_classification::{GpuProbeClassification, classification_results};
use crate::probe_ray_gen::GpuProbeRayGen;
use crate::probe_relocation::GpuProbeRelocation;
use crate::probe_shade::{GpuProbeShade, ShadeProbes, batch_shade_probes, batch_shade_records};
use crate::probe_usage::GpuProbeUsage;
use crate::shadow_field::GpuShadowField;
use crate::{GpuContext, GpuError};

impl From<GpuError> for BackendError {
    fn from(e: GpuError) -> Self {
        BackendError::Device(e.to_string())
    }
}

/// A poisoned lock of the tracer's resident state (a pass panicked earlier).
fn poisoned<T>(_: T) -> BackendError {
    BackendError::Device("a GPU pass panicked earlier; the tracer's resident state is lost".into())
}

/// A batch's rays as the GPU trace reads them (made from its `generated`
/// records where it has no per-ray arrays).
pub(crate) fn batch_rays(batch: &ProbeRayBatch) -> Vec<GpuRay> {
    let batch = batch.expanded();
    (0..batch.len())
        .map(|i| GpuRay::new(batch.origins_m[i], batch.directions[i], 0.0, batch.max_distances_m[i]))
        .collect()
}

impl WgpuProbeTracer {
    /// The shadowing field's update of every volume `plan` has one for, from the
    /// kept previous batch when it is the frame the plan refers to.
    fn shadow_update(
        &self,
        field: &GpuDdgiField,
        scene: &GpuScene,
        plan: &[DeviceVolumeBlend<'_>],
    ) -> Result<(), GpuError> {
        let Some(pass) = self.shadow.as_ref() else { return Ok(()) };
        let prev = self.prev_update.lock().map_err(|_| GpuError::Input("a GPU pass panicked earlier".into()))?;
        for (i, p) in plan.iter().enumerate() {
            let (Some(shadow), Some((frame, batch))) = (p.shadow.as_ref(), prev.as_ref()) else { continue };
            if *frame != shadow.prev_frame {
                continue;
            }
            let target = field.member_occlusion(i).ok_or_else(|| GpuError::Input("no occlusion maps".into()))?;
            pass.update(&self.ctx, &self.trace, &self.bvh, scene, batch, shadow, &target)?;
        }
        Ok(())
    }
}

impl WgpuProbeTracer {
    /// After the blends: per volume, the change of each probe it blended where
    /// `plan` asks for it (the ray budget's), kept on its way back; returns
    /// those of earlier blends now due (`DeviceChangeKey`).
    fn measure_changes(
        &self,
        field: &GpuDdgiField,
        plan: &[DeviceVolumeBlend<'_>],
    ) -> Result<Vec<DeviceProbeChanges>, GpuError> {
        let Some(pass) = self.change.as_ref() else {
            return match plan.iter().any(|p| p.measure_change) {
                true => Err(GpuError::Input("a ray budget's changes, and this device has no change pass".into())),
                false => Ok(Vec::new()),
            };
        };
        let mut keys: Vec<DeviceChangeKey> = Vec::new();
        for (i, p) in plan.iter().enumerate().filter(|(_, p)| p.measure_change) {
            let atlases = field.member_atlases(i).ok_or_else(|| GpuError::Input("member".into()))?;
            let probes: Vec<u32> =
                p.probe_blend.iter().enumerate().filter(|(_, b)| b.is_some()).map(|(k, _)| k as u32).collect();
            let occlusion = field.member_occlusion(i);
            pass.measure_late(&self.ctx, &atlases, occlusion.as_ref(), &probes, &p.change_key, i as u32)?;
            if !keys.iter().any(|k| k.set_id == p.change_key.set_id && k.lag_updates == p.change_key.lag_updates) {
                keys.push(p.change_key);
            }
        }
        let mut out = Vec::new();
        for key in &keys {
            out.extend(pass.take_due(&self.ctx, key)?);
        }
        Ok(out)
    }
}

/// The identity of an update batch's probe records (`BatchProbe`): every
/// volume's plan id, where the field set made every probe's records
/// (`GeneratedProbeRays::plan_id`); `None` otherwise.
fn probe_records_ids(batch: &ProbeRayBatch) -> Option<Vec<u64>> {
    let covered: usize = batch.generated.iter().map(|g| g.probe_count as usize).sum();
    let update = batch.kind == probegi_field::seam::ProbeRayBatchKind::Update;
    (update && covered == batch.probes.len()).then(|| batch.generated.iter().map(|g| g.plan_id).collect())?
}

/// The identity of an update batch's radiance flags
/// (`ProbeRayBatch::probe_needs_radiance_id`), where its probe records have
/// one ([`probe_records_ids`]) and the batch drew it (a batch built as
/// `Default` holds 0: no identity).
fn radiance_flags_id(batch: &ProbeRayBatch) -> Option<u64> {
    let id = batch.probe_needs_radiance_id();
    (id != 0 && probe_records_ids(batch).is_some()).then_some(id)
}

/// The update volumes of `batch` whose probes cast the same rays each and lie
/// consecutively, as the trace's direction-major segments (`bvh_trace::TraceSegment`).
fn trace_segments(batch: &ProbeRayBatch) -> Vec<TraceSegment> {
    batch
        .generated
        .iter()
        .filter_map(|g| {
            let probes = batch.probes.get(g.first_probe as usize..(g.first_probe + g.probe_count) as usize)?;
            let first = probes.first()?;
            let uniform = probes.iter().enumerate().all(|(k, p)| {
                p.ray_count == g.rays_per_probe && p.first_ray == first.first_ray + k as u32 * g.rays_per_probe
            });
            uniform.then_some(TraceSegment {
                first_ray: first.first_ray,
                probe_count: g.probe_count,
                rays_per_probe: g.rays_per_probe,
            })
        })
        .collect()
}

/// The GPU behind the seam: trace always, shade where [`WgpuProbeTracer::shades`].
pub struct WgpuProbeTracer {
    /// The device the passes run on.
    pub ctx: GpuContext,
    /// The trace pipeline.
    pub trace: GpuRayTrace,
    /// The scene's BVH on the device.
    pub bvh: GpuBvh,
    /// The top level's layout and the bottom levels' root nodes, for a scene
    /// with moving objects or instanced meshes (`pose_scene` places them).
    tlas: Option<(TlasLayout, Vec<u32>)>,
    /// The shade pass and the scene on the device; `None` when the scene needs
    /// what the GPU shading lacks (see `shading_note`).
    shading: Option<(GpuProbeShade, GpuScene)>,
    /// The camera pass (with `shading`, unless asked to leave the camera to the CPU).
    camera: Option<GpuCameraPass>,
    /// The sky of the scene as last posed (the camera pass's misses).
    sky_radiance: Mutex<Vec3>,
    /// Why the probe rays are shaded on the CPU, when they are.
    pub shading_note: Option<String>,
    /// The last traced batch, resident for the shade pass.
    last: Mutex<Option<GpuRayBatch>>,
    /// The batch traced before `last` (or, where the shadowing field's passes
    /// keep the last update batch as `prev_update`, the one before that): the
    /// next batch generated on the device with as many rays takes its buffers
    /// (rays, hits, parameters, bind group) instead of allocating new ones, so
    /// a still field's update allocates no ray batch. Two traces old when it
    /// is taken, its passes were submitted before the new batch's, which the
    /// queue orders after them.
    spare_batch: Mutex<Option<GpuRayBatch>>,
    /// Keep the field on the device (see the crate docs); needs GPU shading.
    keep_field: bool,
    /// The passes of the device-resident update, made with `keeping_field`.
    resident_passes: Option<(GpuProbeBlend, GpuProbeUsage, GpuProbeRelocation)>,
    /// Ray generation for update batches (with `keeping_field`).
    ray_gen: Option<GpuProbeRayGen>,
    /// The classification round's pass (with `keeping_field`, where the adapter binds enough buffers).
    classification: Option<GpuProbeClassification>,
    /// Why the classification round runs on the host with the field kept, when it does.
    pub classification_note: Option<String>,
    /// Initialisation rounds run on the device: relocation iterations, classification rounds.
    rounds_on_device: [std::sync::atomic::AtomicU32; 2],
    /// The resident field (atlases and per-probe data), once an update made it.
    field: Mutex<Option<GpuDdgiField>>,
    /// The shadowing field's passes (with `keeping_field`, where the adapter binds enough buffers).
    shadow: Option<GpuShadowField>,
    /// The ray budget's change measure (with `keeping_field`).
    change: Option<crate::probe_change::GpuProbeChange>,
    /// New probes' seeds mixed on the device (with `keeping_field`).
    seeding: Option<crate::probe_seeding::GpuProbeSeeding>,
    /// The last update batch blended on the device, kept with its frame: the
    /// shadowing field casts the next frame's shadow rays from its hits.
    prev_update: Mutex<Option<(u32, GpuRayBatch)>>,
    /// The camera frame kept on the device (`device_frame`), made with the
    /// first frame, where `device_frame_on` (and the camera is on the GPU).
    frame: Mutex<Option<GpuFrame>>,
    device_frame_on: bool,
    /// The host waits after each pass of the update so that its wall times are
    /// the device's (`bench`; [`WgpuProbeTracer::timing_passes`]).
    timing: std::sync::atomic::AtomicBool,
}

impl WgpuProbeTracer {
    /// The scene's BVH (and, where supported, its shading data) on `ctx`.
    /// `gpu_shading` false keeps the shade and the camera on the CPU; `gpu_camera`
    /// false keeps only the camera there.
    pub fn new(ctx: GpuContext, scene: &Scene, bvh: &BvhTracer, gpu_shading: bool) -> Result<Self, GpuError> {
        Self::with_camera(ctx, scene, bvh, gpu_shading, gpu_shading)
    }

    /// [`Self::new`], with the camera frame on the GPU only where `gpu_camera`
    /// (and `gpu_shading`).
    pub fn with_camera(
        ctx: GpuContext,
        scene: &Scene,
        bvh: &BvhTracer,
        gpu_shading: bool,
        gpu_camera: bool,
    ) -> Result<Self, GpuError> {
        // A tracer built from the mesh alone (`BvhTracer::build`) has no top level
        // to place the moving objects with; the CPU rebuilds then, the device cannot.
        if scene.has_moving_geometry() && !bvh.tlas_layout().is_some_and(|l| l.moves()) {
            return Err(GpuError::Input(format!(
                "scene {} has moving objects, but its BVH has none instanced: build it with BvhTracer::for_scene",
                scene.name
            )));
        }
        let export = bvh.export();
        let gpu_bvh = GpuBvh::upload(&ctx, &export)?;
        let tlas = bvh.tlas_layout().map(|l| (l.clone(), export.blas_root_nodes.clone()));
        let trace = GpuRayTrace::new(&ctx);
        let note = if gpu_shading { None } else { Some("CPU shading asked for".into()) };
        let shading = match note {
            None => Some((GpuProbeShade::new(&ctx)?, GpuScene::upload(&ctx, scene)?)),
            Some(_) => None,
        };
        let camera = if shading.is_some() && gpu_camera { Some(GpuCameraPass::new(&ctx)?) } else { None };
        Ok(Self {
            ctx,
            trace,
            bvh: gpu_bvh,
            tlas,
            shading,
            camera,
            sky_radiance: Mutex::new(scene.sky_radiance),
            shading_note: note,
            last: Mutex::new(None),
            spare_batch: Mutex::new(None),
            keep_field: false,
            resident_passes: None,
            classification: None,
            classification_note: None,
            ray_gen: None,
            rounds_on_device: Default::default(),
            field: Mutex::new(None),
            shadow: None,
            change: None,
            seeding: None,
            prev_update: Mutex::new(None),
            frame: Mutex::new(None),
            device_frame_on: true,
            timing: std::sync::atomic::AtomicBool::new(false),
        })
    }

    /// With `keep` (and GPU shading), update batches are shaded, blended and
    /// bordered on the device and the atlases stay there (see the crate docs).
    pub fn keeping_field(mut self, keep: bool) -> Self {
        self.keep_field = keep && self.shading.is_some();
        self.resident_passes = self.keep_field.then(|| {
            (GpuProbeBlend::new(&self.ctx), GpuProbeUsage::new(&self.ctx), GpuProbeRelocation::new(&self.ctx))
        });
        // Without it the classification round reads the hits back and runs on the host.
        self.classification = None;
        self.classification_note = None;
        if self.keep_field {
            match GpuProbeClassification::new(&self.ctx) {
                Ok(c) => self.classification = Some(c),
                Err(e) => self.classification_note = Some(format!("classification on the host: {e}")),
            }
        }
        self.ray_gen = self.keep_field.then(|| GpuProbeRayGen::new(&self.ctx));
        // Without it the shadowing field's rays and blend run on the host.
        self.shadow = if self.keep_field { GpuShadowField::new(&self.ctx).ok() } else { None };
        self.change = self.keep_field.then(|| crate::probe_change::GpuProbeChange::new(&self.ctx));
        self.seeding = self.keep_field.then(|| crate::probe_seeding::GpuProbeSeeding::new(&self.ctx));
        self
    }

    /// Initialisation rounds this tracer ran on the device so far, summed over
    /// the volumes of each chain: (relocation iterations recorded, every one
    /// of the plan's even where all its probes had settled; classifications).
    pub fn init_rounds_on_device(&self) -> (u32, u32) {
        use std::sync::atomic::Ordering::Relaxed;
        (self.rounds_on_device[0].load(Relaxed), self.rounds_on_device[1].load(Relaxed))
    }

    /// With `generate` false (and `keeping_field`), update batches upload the
    /// host's rays instead of generating them on the device (the directions then
    /// equal the host's bit for bit, not to the 2.4e-5 of sin and cos on the device).
    pub fn generating_rays(mut self, generate: bool) -> Self {
        self.ray_gen = (self.keep_field && generate).then(|| GpuProbeRayGen::new(&self.ctx));
        self
    }

    /// With `device` false, the camera frame comes back to the host every
    /// frame (`ProbeBatchTracer::camera_frame`) instead of staying on the
    /// device (`device_frame`); the CPU then accumulates and composes it.
    pub fn keeping_frame(mut self, device: bool) -> Self {
        self.device_frame_on = device;
        self
    }

    /// With `timing`, the host waits for the device after each pass of the
    /// update and reads its timestamps back, so that `pass_ms` holds the
    /// device's times (`probegi bench`); without (the default), the update's
    /// passes are submitted without waiting.
    pub fn timing_passes(self, timing: bool) -> Self {
        self.set_timing_passes(timing);
        self
    }

    /// [`Self::timing_passes`] on a tracer in use: `bench` times the same
    /// field's update both ways, passes waited for one by one and pipelined.
    pub fn set_timing_passes(&self, timing: bool) {
        self.timing.store(timing, std::sync::atomic::Ordering::Relaxed);
    }

    /// Whether the update's passes are waited for one by one ([`Self::timing_passes`]).
    fn timing(&self) -> bool {
        self.timing.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Rays of the last batch traced on the device for an update (tests and
    /// benchmarks: the screen scheme's size moves from frame to frame).
    pub fn last_batch_rays(&self) -> Option<u32> {
        let last = self.last.lock().ok()?.as_ref().map(|b| b.ray_count);
        last.or_else(|| self.prev_update.lock().ok()?.as_ref().map(|(_, b)| b.ray_count))
    }

    /// Whether update batches keep the field on the device.
    pub fn keeps_field(&self) -> bool {
        self.keep_field
    }

    /// Device memory of the resident field (0 before the first update on the device).
    pub fn field_bytes(&self) -> u64 {
        self.field.lock().ok().and_then(|f| f.as_ref().map(|f| f.bytes())).unwrap_or(0)
    }

    /// The resident field's query buffers (`GpuDdgiField::query_buffers`),
    /// for an engine's shaders that read the field where the update writes
    /// it (`ddgi_query::query_wgsl_at`); `None` before the first update on
    /// the device. They change only when the field is uploaded again.
    pub fn resident_query_buffers(&self) -> Option<[wgpu::Buffer; 4]> {
        self.field.lock().ok().and_then(|f| f.as_ref().map(GpuDdgiField::query_buffers))
    }

    /// Records and submits the blend and border passes of every member of
    /// `plan` that blends this frame, over the shade pass's `results` (its
    /// buffer and the batch's rays) in the resident field `f` (with `timer`, member i's passes at slots from
    /// 1 + i × `probe_blend::PASS_NAMES.len()`). Returns the members recorded.
    fn record_blends(
        &self,
        blend: &GpuProbeBlend,
        f: &GpuDdgiField,
        plan: &[DeviceVolumeBlend<'_>],
        results: (&wgpu::Buffer, u64),
        timer: Option<&GpuTimer>,
    ) -> Result<Vec<usize>, GpuError> {
        let per_member = crate::probe_blend::PASS_NAMES.len() as u32;
        // Every member's inputs first (their writes go through the context),
        // then their passes into one encoder.
        let mut prepared = vec![];
        for (i, p) in plan.iter().enumerate() {
            let atlases = f.member_atlases(i).ok_or_else(|| GpuError::Input("member".into()))?;
            // A member in which no probe blends records nothing.
            if let Some(bindings) = blend.prepare_blending(&self.ctx, &atlases, p, results)? {
                prepared.push((i, bindings));
            }
        }
        self.ctx.record(|encoder| {
            for (i, bindings) in &prepared {
                blend.record(encoder, bindings, timer.map(|t| (t, 1 + per_member * *i as u32)));
            }
            if let Some(t) = timer {
                t.resolve(encoder);
            }
        });
        Ok(prepared.into_iter().map(|(i, _)| i).collect())
    }

    /// `batch`'s rays generated on the device, when it records how to make all
    /// of them and this tracer keeps the field.
    fn generate_rays(&self, batch: &ProbeRayBatch) -> Result<Option<GpuRayBatch>, GpuError> {
        let Some(ray_gen) = self.ray_gen.as_ref() else { return Ok(None) };
        let covered: u64 = batch.generated.iter().map(|g| g.probe_count as u64 * g.rays_per_probe as u64).sum();
        if batch.generated.is_empty() || covered != batch.len() as u64 {
            return Ok(None);
        }
        let n = batch.len() as u32;
        let mut spare = self.spare_batch.lock().map_err(|_| GpuError::Input("a GPU pass panicked".into()))?;
        let out = match spare.take() {
            Some(batch) if batch.reusable_for(n, false) => batch.reused_for(n),
            // A batch of another size: the field's batches change size from
            // frame to frame (the screen scheme's), so leave room for more.
            Some(_) => self.trace.empty_batch_holding(&self.ctx, n, n.saturating_add(n / 4), false)?,
            None => self.trace.empty_batch(&self.ctx, n, false)?,
        };
        drop(spare);
        for g in &batch.generated {
            let probes = batch.probes.get(g.first_probe as usize..(g.first_probe + g.probe_count) as usize);
            let Some(probes) = probes.filter(|p| p.iter().all(|p| p.ray_count == g.rays_per_probe)) else {
                return Ok(None);
            };
            let Some(first) = probes.first() else { continue };
            // Contiguous, probe-major: the volume's rays start at its first probe's.
            if probes.iter().enumerate().any(|(k, p)| p.first_ray != first.first_ray + k as u32 * g.rays_per_probe) {
                return Ok(None);
            }
            let range = g.first_probe as usize..(g.first_probe + g.probe_count) as usize;
            let Some(origins) = batch.probe_origins_m.get(range) else { return Ok(None) };
            let rays = crate::probe_ray_gen::RayGenRays {
                first_ray: first.first_ray,
                origins,
                max_distance_m: g.max_distance_m,
                rotation: g.rotation,
                rays_per_probe: g.rays_per_probe,
            };
            // Kept per volume and batch kind: an update's records repeat while
            // the volume's probes and states stay as they are.
            let key = (g.volume as u64) << 1 | (batch.kind == probegi_field::seam::ProbeRayBatchKind::Update) as u64;
            ray_gen.generate_kept(&self.ctx, &out, rays, Some((key, g.plan_id)), None)?;
        }
        Ok(Some(out))
    }

    /// Makes `resident` the last batch; the one it replaces becomes the spare.
    fn keep_last(&self, resident: GpuRayBatch) -> Result<(), BackendError> {
        let before = self.last.lock().map_err(poisoned)?.replace(resident);
        if let Some(before) = before {
            *self.spare_batch.lock().map_err(poisoned)? = Some(before);
        }
        Ok(())
    }

    /// Traces `batch` on the device and keeps it there as the last batch. An
    /// update batch whose rays record how they were made (`batch.generated`) has
    /// them generated on the device (`probe_ray_gen.wgsl`), with the field kept
    /// there; others are uploaded. `static_only`: an initialisation round, which
    /// leaves moving objects out.
    fn trace_resident(&self, batch: &ProbeRayBatch, static_only: bool) -> Result<GpuRayBatch, GpuError> {
        let resident = match self.generate_rays(batch)? {
            Some(generated) => generated,
            None => self.trace.batch(&self.ctx, &batch_rays(batch), false)?,
        };
        resident.configure(&self.ctx, static_only, &trace_segments(batch));
        self.ctx.record(|encoder| self.trace.record(encoder, &self.bvh, &resident, None));
        Ok(resident)
    }

    /// [`DeviceField::initialise`]: every volume's chain recorded, then its
    /// offsets and states read back together (one submission, one wait).
    fn run_init_chains(
        &self,
        relocation: &GpuProbeRelocation,
        plan: &[Option<DeviceInitChain<'_>>],
    ) -> Result<Vec<Option<DeviceInitResult>>, GpuError> {
        let mut recorded = Vec::new();
        for chain in plan.iter().flatten() {
            let r = relocation.record_chain(&self.ctx, &self.trace, &self.bvh, chain)?;
            let states = match (&chain.classification, &self.classification, &self.shading) {
                (Some(round), Some(c), Some((_, scene))) => {
                    Some(c.record(&self.ctx, (&self.bvh, scene), &r.kept, round, &r.positions)?)
                }
                _ => None,
            };
            recorded.push((r, states));
        }
        let buffers: Vec<&wgpu::Buffer> =
            recorded.iter().flat_map(|(r, states)| std::iter::once(&r.offsets).chain(states.as_ref())).collect();
        let mut bytes = self.ctx.read_back_all(&buffers)?.into_iter();
        let mut results = recorded.into_iter().map(|(r, states)| -> Result<DeviceInitResult, GpuError> {
            let missing = || GpuError::Readback("an initialisation result".into());
            let offsets = bytes.next().ok_or_else(missing)?;
            let offsets: &[[f32; 4]] = bytemuck::cast_slice(&offsets);
            let n = r.rays_per_probe as u64;
            let classification = match states {
                Some(_) => Some(classification_results(&bytes.next().ok_or_else(missing)?, offsets.len())),
                None => None,
            };
            use std::sync::atomic::Ordering::Relaxed;
            self.rounds_on_device[0].fetch_add(r.relocation_rounds, Relaxed);
            self.rounds_on_device[1].fetch_add(classification.is_some() as u32, Relaxed);
            Ok(DeviceInitResult {
                offsets_m: offsets.iter().map(|o| Vec3::new(o[0], o[1], o[2])).collect(),
                classification,
                rays_traced: offsets.iter().map(|o| o[3] as u64).sum::<u64>() * n,
            })
        });
        plan.iter()
            .map(|c| c.as_ref().map(|_| results.next().ok_or_else(|| GpuError::Input("chain".into()))?).transpose())
            .collect()
    }

    /// The resident field for an update's shade and blend: uploaded whole when
    /// the host's atlases are current (`upload_atlases`), else only its
    /// per-probe data (the device's blend wrote the atlases last frame), and
    /// the tiles of the probes `plan` reset cleared on the device.
    fn resident_field<'f>(
        &self,
        gpu_field: &'f mut Option<GpuDdgiField>,
        field: &DdgiFieldSetView<'_>,
        upload_atlases: bool,
        plan: &[DeviceVolumeBlend<'_>],
    ) -> Result<&'f GpuDdgiField, GpuError> {
        match (gpu_field.as_ref(), upload_atlases) {
            (Some(f), _) if f.refresh(&self.ctx, field, upload_atlases).is_ok() => {}
            // First frame, or the set changed shape while the host held the field.
            (_, true) => *gpu_field = Some(GpuDdgiField::upload(&self.ctx, field)?),
            (Some(f), false) => f.refresh(&self.ctx, field, false)?,
            (None, false) => return Err(GpuError::Input("the device lost the field it held".into())),
        }
        let f = gpu_field.as_ref().ok_or_else(|| GpuError::Input("no field".into()))?;
        if plan.len() != f.volumes {
            return Err(GpuError::Input(format!("{} volume plans for {} volumes", plan.len(), f.volumes)));
        }
        for (i, p) in plan.iter().enumerate() {
            if !p.reset_probes.is_empty() && !upload_atlases {
                f.member_atlases(i)
                    .ok_or_else(|| GpuError::Input("member".into()))?
                    .zero_tiles(&self.ctx, p.reset_probes);
                f.reset_occlusion_tiles(&self.ctx, i, p.reset_probes);
            }
        }
        // Seeds read other volumes' tiles: after every clear, before any blend.
        for (i, p) in plan.iter().enumerate().filter(|(_, p)| !p.seeds.is_empty() && !upload_atlases) {
            let seeding = self.seeding.as_ref().ok_or_else(|| GpuError::Input("no seeding pass".into()))?;
            let target = f.member_atlases(i).ok_or_else(|| GpuError::Input("member".into()))?;
            seeding.seed(&self.ctx, &target, |v| f.member_atlases(v), p.seeds, p.settings.probe_irradiance_gamma)?;
        }
        Ok(f)
    }

    /// Whether the camera frame is rendered on the GPU.
    pub fn renders_camera(&self) -> bool {
        self.camera.is_some()
    }

    /// Whether the probe rays are shaded on the GPU.
    pub fn shades(&self) -> bool {
        self.shading.is_some()
    }

    /// The shade pass and the scene on the device, when the GPU shades.
    pub fn shading(&self) -> Option<(&GpuProbeShade, &GpuScene)> {
        self.shading.as_ref().map(|(p, s)| (p, s))
    }

    /// The adapter's name and driver.
    pub fn adapter_name(&self) -> &str {
        &self.ctx.adapter_name
    }
}

impl ProbeBatchTracer for WgpuProbeTracer {
    fn closest_hits(
        &self,
        batch: &ProbeRayBatch,
        static_only: bool,
        hits: &mut Vec<Option<RayHit>>,
    ) -> Result<(), BackendError> {
        let rays = batch_rays(batch);
        hits.clear();
        if rays.len() > GpuRayTrace::max_batch_rays(&self.ctx) {
            // Larger than one binding: trace in pieces, shade on the CPU.
            let gpu = self.trace.trace_static_only(&self.ctx, &self.bvh, &rays, false, static_only)?;
            hits.extend(gpu.iter().map(|h| h.ray_hit()));
            *self.last.lock().map_err(poisoned)? = None;
            return Ok(());
        }
        let resident = self.trace_resident(batch, static_only)?;
        let gpu = self.trace.download(&self.ctx, &resident)?;
        hits.extend(gpu.iter().map(|h| h.ray_hit()));
        self.keep_last(resident)
    }

    fn shade_batch(
        &self,
        batch: &ProbeRayBatch,
        field: &DdgiFieldSetView<'_>,
        volumes: &[DdgiVolume],
        seed: u64,
        frame: u32,
        radiance: &mut Vec<Vec3>,
    ) -> Option<Result<(), BackendError>> {
        let (shade, scene) = self.shading.as_ref()?;
        let last = self.last.lock().ok()?;
        let resident = last.as_ref().filter(|b| b.ray_count as usize == batch.len())?;
        let run = || -> Result<Vec<Vec3>, GpuError> {
            let probes = batch_shade_probes(batch, volumes);
            let gpu_field = GpuDdgiField::upload(&self.ctx, field)?;
            let seed32 = (seed ^ (seed >> 32)) as u32;
            shade.shade(&self.ctx, &self.bvh, &gpu_field, scene, resident, &probes, seed32, frame, None)
        };
        Some(run().map(|l| *radiance = l).map_err(BackendError::from))
    }

    fn pose_scene(&self, scene: &Scene, frame: f32) -> Result<(), BackendError> {
        if let Ok(mut sky) = self.sky_radiance.lock() {
            *sky = scene.sky_radiance;
        }
        if scene.has_moving_geometry() {
            let Some((layout, roots)) = self.tlas.as_ref().filter(|(l, _)| l.moves()) else {
                return Err(BackendError::Unsupported(format!(
                    "scene {} moves, but this tracer was made without its moving objects",
                    scene.name
                )));
            };
            let tlas = layout.export_at(scene, frame).map_err(BackendError::Device)?;
            self.bvh.place(&self.ctx, &tlas, roots)?;
        }
        match &self.shading {
            Some((_, gpu_scene)) => {
                gpu_scene.pose_lights(&self.ctx, scene)?;
                gpu_scene.pose_geometry(&self.ctx, scene).map_err(BackendError::from)
            }
            None => Ok(()),
        }
    }

    fn camera_frame(
        &self,
        camera: &CameraRays,
        field: &DdgiFieldSetView<'_>,
        field_on_device: bool,
        area_samples: u32,
        sky_samples: u32,
        second_order: bool,
        frame: u32,
        seed: u64,
        out: CameraFrameOut<'_>,
        mut probe_requests: Option<&mut Vec<u32>>,
    ) -> Option<Result<(usize, usize), BackendError>> {
        let pass = self.camera.as_ref()?;
        let (_, scene) = self.shading.as_ref()?;
        let ([_, _, _], [_, _, w, h]) = camera.basis();
        let resident = self.field.lock().ok()?;
        let mut run = || -> Result<(usize, usize), GpuError> {
            // The field the device holds (its atlases current), or the host's uploaded.
            let uploaded;
            let gpu_field = match (field_on_device, resident.as_ref()) {
                (true, Some(f)) => {
                    f.refresh(&self.ctx, field, false)?;
                    f
                }
                (true, None) => return Err(GpuError::Input("the device lost the field it held".into())),
                (false, _) => {
                    uploaded = GpuDdgiField::upload(&self.ctx, field)?;
                    &uploaded
                }
            };
            let f = CameraFrame {
                camera,
                width: w as u32,
                height: h as u32,
                frame,
                seed: (seed ^ (seed >> 32)) as u32,
                area_samples,
                sky_samples,
                second_order,
                sky_radiance: *self.sky_radiance.lock().unwrap_or_else(|e| e.into_inner()),
                request_words: probe_requests.as_ref().map_or(0, |r| r.len() as u32),
            };
            let image = pass.render(&self.ctx, &self.bvh, gpu_field, scene, &f)?;
            if let Some(r) = probe_requests.as_deref_mut() {
                r.copy_from_slice(&image.requests);
            }
            let pixels = out.direct.len();
            let produced = [
                image.direct.len(),
                image.irradiance_over_pi.len(),
                image.albedo.len(),
                image.position_m.len(),
                image.normal.len(),
            ];
            let given = [out.irradiance_over_pi.len(), out.albedo.len(), out.position_m.len(), out.normal.len()];
            if produced != [pixels; 5] || given != [pixels; 4] {
                return Err(GpuError::Input(format!(
                    "{} camera pixels for a {pixels}-pixel frame",
                    image.direct.len()
                )));
            }
            out.direct.copy_from_slice(&image.direct);
            out.irradiance_over_pi.copy_from_slice(&image.irradiance_over_pi);
            out.albedo.copy_from_slice(&image.albedo);
            out.position_m.copy_from_slice(&image.position_m);
            out.normal.copy_from_slice(&image.normal);
            Ok((image.surfaces, image.unlit))
        };
        Some(run().map_err(BackendError::from))
    }

    fn device_field(&self) -> Option<&dyn DeviceField> {
        self.resident_passes.is_some().then_some(self as &dyn DeviceField)
    }

    fn device_wait_ms(&self) -> Option<f64> {
        Some(self.ctx.counters().wait_ms)
    }

    fn device_frame(&self) -> Option<&dyn DeviceFrame> {
        (self.device_frame_on && self.camera.is_some()).then_some(self as &dyn DeviceFrame)
    }
}

impl WgpuProbeTracer {
    /// Runs `f` with the field the camera reads: the one the device holds
    /// (its atlases current) or, without one, the host's uploaded.
    fn with_camera_field<T>(
        &self,
        field: &DdgiFieldSetView<'_>,
        field_on_device: bool,
        f: impl FnOnce(&GpuDdgiField) -> Result<T, GpuError>,
    ) -> Result<T, GpuError> {
        let resident = self.field.lock().map_err(|_| GpuError::Input("a GPU pass panicked earlier".into()))?;
        match (field_on_device, resident.as_ref()) {
            (true, Some(gpu_field)) => {
                gpu_field.refresh(&self.ctx, field, false)?;
                f(gpu_field)
            }
            (true, None) => Err(GpuError::Input("the device lost the field it held".into())),
            (false, _) => f(&GpuDdgiField::upload(&self.ctx, field)?),
        }
    }

    /// The last frame's `layer`, tone-mapped, in a texture on this tracer's
    /// device (`GpuFrame::present`): what a window that shares the device
    /// (`GpuContext::from_device`) draws, no pixel crossing to the host.
    pub fn present_frame(&self, layer: FrameLayer) -> Result<wgpu::Texture, BackendError> {
        let mut frame = self.frame_state()?;
        let frame = frame.as_mut().ok_or_else(|| BackendError::Unsupported("no device frame yet".into()))?;
        frame.present(&self.ctx, layer).map_err(BackendError::from)
    }

    /// The device frame, locked.
    fn frame_state(&self) -> Result<std::sync::MutexGuard<'_, Option<GpuFrame>>, BackendError> {
        self.frame.lock().map_err(poisoned)
    }
}

impl DeviceFrame for WgpuProbeTracer {
    fn render_frame(&self, input: &DeviceFrameInput<'_>) -> Result<Vec<DeviceFrameReadout>, BackendError> {
        let (Some(pass), Some((_, scene))) = (self.camera.as_ref(), self.shading.as_ref()) else {
            return Err(BackendError::Unsupported("this tracer renders no camera frame".into()));
        };
        let ([_, _, _], [_, _, w, h]) = input.camera.basis();
        // From the first frame kept here on, each frame's passes (update and
        // camera) reach the queue as one submission, at the frame's end.
        self.ctx.defer_submissions(true);
        let mut frame = self.frame_state()?;
        let frame = frame.get_or_insert_with(|| GpuFrame::new(&self.ctx));
        let camera = CameraFrame {
            camera: input.camera,
            width: w as u32,
            height: h as u32,
            frame: input.frame,
            seed: (input.seed ^ (input.seed >> 32)) as u32,
            area_samples: input.area_samples,
            sky_samples: input.sky_samples,
            second_order: input.second_order,
            sky_radiance: *self.sky_radiance.lock().unwrap_or_else(|e| e.into_inner()),
            request_words: input.request_words,
        };
        let frame_input =
            GpuFrameInput { camera, history: input.history, readback_lag_frames: input.readback_lag_frames };
        self.with_camera_field(input.field, input.field_on_device, |gpu_field| {
            frame.render(&self.ctx, pass, (&self.bvh, gpu_field, scene), &frame_input)
        })
        .map_err(BackendError::from)
    }

    fn drain_readouts(&self) -> Result<Vec<DeviceFrameReadout>, BackendError> {
        match self.frame_state()?.as_mut() {
            Some(frame) => frame.drain(&self.ctx).map_err(BackendError::from),
            None => Ok(Vec::new()),
        }
    }

    fn read_layer(&self, layer: FrameLayer) -> Result<Vec<Vec3>, BackendError> {
        let frame = self.frame_state()?;
        let frame = frame.as_ref().ok_or_else(|| BackendError::Unsupported("no device frame yet".into()))?;
        frame.read_layer(&self.ctx, layer).map_err(BackendError::from)
    }

    fn read_rgba8(&self, layer: FrameLayer) -> Result<Vec<u8>, BackendError> {
        let frame = self.frame_state()?;
        let frame = frame.as_ref().ok_or_else(|| BackendError::Unsupported("no device frame yet".into()))?;
        frame.read_rgba8(&self.ctx, layer).map_err(BackendError::from)
    }
}

impl DeviceField for WgpuProbeTracer {
    fn trace_resident(
        &self,
        batch: &ProbeRayBatch,
        usage: Option<&DeviceUsageRequest>,
    ) -> Option<Result<Vec<DeviceUsageCounts>, BackendError>> {
        let (_, usage_pass, _) = self.resident_passes.as_ref()?;
        if batch.len() > GpuRayTrace::max_batch_rays(&self.ctx) {
            return None;
        }
        let run = || -> Result<Vec<DeviceUsageCounts>, BackendError> {
            let resident = self.trace_resident(batch, false)?;
            if self.timing() {
                self.ctx.wait()?;
            }
            let counts = match usage {
                Some(request) => {
                    let ids = probe_records_ids(batch);
                    usage_pass.counts_late(&self.ctx, &resident, &batch.probes, ids.as_deref(), request)?
                }
                None => vec![],
            };
            self.keep_last(resident)?;
            Ok(counts)
        };
        Some(run())
    }
    fn initialise(
        &self,
        plan: &[Option<DeviceInitChain<'_>>],
    ) -> Option<Result<Vec<Option<DeviceInitResult>>, BackendError>> {
        let (_, _, relocation) = self.resident_passes.as_ref()?;
        let max = GpuRayTrace::max_batch_rays(&self.ctx) as u64;
        let too_large = |c: &DeviceInitChain<'_>| c.grid.probe_count() as u64 * c.dirs.len() as u64 > max;
        let classifies = plan.iter().flatten().any(|c| c.classification.is_some());
        if plan.iter().flatten().any(too_large)
            || (classifies && (self.classification.is_none() || self.shading.is_none()))
        {
            return None;
        }
        let deferring = self.ctx.deferring();
        self.ctx.defer_submissions(true);
        let result = self.run_init_chains(relocation, plan);
        if !deferring {
            self.ctx.defer_submissions(false);
        }
        Some(result.map_err(BackendError::from))
    }
    fn shade_and_blend(
        &self,
        batch: &ProbeRayBatch,
        field: &DdgiFieldSetView<'_>,
        upload_atlases: bool,
        plan: &[DeviceVolumeBlend<'_>],
        volumes: &[DdgiVolume],
        seed: u64,
        frame: u32,
    ) -> Result<DeviceBlendOutput, BackendError> {
        let ((shade, scene), Some((blend, _, _))) = (
            self.shading
                .as_ref()
                .ok_or_else(|| BackendError::Unsupported("the GPU does not shade this scene".into()))?,
            self.resident_passes.as_ref(),
        ) else {
            return Err(BackendError::Unsupported("this tracer does not keep the field on the device".into()));
        };
        let last = self.last.lock().map_err(poisoned)?;
        let resident = last
            .as_ref()
            .filter(|b| b.ray_count as usize == batch.len())
            .ok_or_else(|| BackendError::Device("the batch to shade is not the one traced on the device".into()))?;
        let mut gpu_field = self.field.lock().map_err(poisoned)?;
        let run = |gpu_field: &mut Option<GpuDdgiField>| -> Result<DeviceBlendOutput, GpuError> {
            let t = std::time::Instant::now();
            let f = self.resident_field(gpu_field, field, upload_atlases, plan)?;
            let ids = probe_records_ids(batch);
            let records = || batch_shade_records(batch, volumes);
            let probes = ShadeProbes {
                count: batch.probes.len(),
                ids: ids.as_deref(),
                records: &records,
                radiance: &batch.probe_needs_radiance,
                radiance_id: radiance_flags_id(batch),
            };
            let seed32 = (seed ^ (seed >> 32)) as u32;
            // Timestamp queries where the device has them: the shade pass, then
            // each member's blend and border passes.
            let per_member = crate::probe_blend::PASS_NAMES.len() as u32;
            let timer = (self.timing() && self.ctx.timestamps)
                .then(|| GpuTimer::new(&self.ctx, 1 + per_member * plan.len() as u32));
            let shade_timer = timer.as_ref().map(|t| (t, 0));
            let results =
                shade.shade_on_device(&self.ctx, &self.bvh, f, scene, resident, probes, seed32, frame, shade_timer)?;
            // With `timing` the host waits after each pass so that its wall times
            // are the device's (`bench`); otherwise the passes queue up unwaited.
            if self.timing() {
                self.ctx.wait()?;
            }
            let shade_ms = t.elapsed().as_secs_f64() * 1e3;
            let t = std::time::Instant::now();
            let results = (&results, resident.ray_count as u64);
            let recorded = self.record_blends(blend, f, plan, results, timer.as_ref())?;
            if self.timing() {
                self.ctx.wait()?;
            }
            let blend_ms = t.elapsed().as_secs_f64() * 1e3;
            let t = std::time::Instant::now();
            self.shadow_update(f, scene, plan)?;
            if self.timing() {
                self.ctx.wait()?;
            }
            let mut pass_ms =
                vec![("shade", shade_ms), ("blend", blend_ms), ("shadow_blend", t.elapsed().as_secs_f64() * 1e3)];
            if let Some(ms) = timer.as_ref().map(|t| t.read_ms(&self.ctx)).transpose()?.flatten() {
                pass_ms.extend(gpu_pass_ms(&ms, &recorded));
            }
            let t = std::time::Instant::now();
            let probe_change = self.measure_changes(f, plan)?;
            if plan.iter().any(|p| p.measure_change) {
                pass_ms.push(("probe_change", t.elapsed().as_secs_f64() * 1e3));
            }
            Ok(DeviceBlendOutput { pass_ms, probe_change })
        };
        let result = run(&mut gpu_field).map_err(BackendError::from);
        drop(last);
        // This batch's hits are where the next frame's shadow rays start.
        if let (Ok(_), Some(_)) = (&result, &self.shadow) {
            let batch = self.last.lock().map_err(poisoned)?.take();
            let before = std::mem::replace(&mut *self.prev_update.lock().map_err(poisoned)?, batch.map(|b| (frame, b)));
            // The batch it replaces is the spare (`spare_batch`), as `keep_last` makes it.
            if let Some((_, before)) = before {
                *self.spare_batch.lock().map_err(poisoned)? = Some(before);
            }
        }
        result
    }
    fn generates_update_rays(&self) -> bool {
        self.ray_gen.is_some()
    }
    fn blends_shadow_field(&self) -> bool {
        self.shadow.is_some()
    }
    fn download_field(&self, index: usize, volume: &mut DdgiVolume) -> Result<(), BackendError> {
        let field = self.field.lock().map_err(poisoned)?;
        let atlases = field
            .as_ref()
            .and_then(|f| f.member_atlases(index))
            .ok_or_else(|| BackendError::Unsupported(format!("the device holds no field for volume {index}")))?;
        let (irradiance, distance) = atlases.download(&self.ctx)?;
        if irradiance.texels.len() != volume.irradiance.texels.len()
            || distance.texels.len() != volume.distance.texels.len()
        {
            return Err(BackendError::Device(format!("the device's atlases of volume {index} do not match its grid")));
        }
        volume.irradiance = irradiance;
        volume.distance = distance;
        if let (Some(shadow), Some(f)) = (volume.shadow.as_mut(), field.as_ref()) {
            match f.download_occlusion(&self.ctx, index)? {
                Some(maps) if maps.len() == shadow.occlusion.texels.len() => shadow.occlusion.texels = maps,
                _ => {
                    return Err(BackendError::Device(format!("the device holds no occlusion maps for volume {index}")));
                }
            }
        }
        Ok(())
    }
}

/// The device's own times of `shade_and_blend`'s passes from its timestamps
/// (`ms`: the shade pass, then `probe_blend::PASS_NAMES` per member), summed
/// over the `recorded` members: `gpu_shade`, `gpu_blend` (both atlases) and
/// `gpu_border`.
fn gpu_pass_ms(ms: &[f64], recorded: &[usize]) -> [(&'static str, f64); 3] {
    let per_member = crate::probe_blend::PASS_NAMES.len();
    let member = |k: usize| recorded.iter().filter_map(|&i| ms.get(1 + per_member * i + k)).sum::<f64>();
    [("gpu_shade", ms.first().copied().unwrap_or(0.0)), ("gpu_blend", member(0)), ("gpu_border", member(1) + member(2))]
}
