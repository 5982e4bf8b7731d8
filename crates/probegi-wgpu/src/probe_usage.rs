//! The usage counts of seed 003's probe states on the GPU (`shaders/probe_usage.wgsl`,
//! mirroring `probegi_core::probe_classification::probe_usage`, eq. 6.1–6.2): per
//! probe of a traced batch, (usage, relevant samples, backfaces) from the hits
//! where they lie on the device. The usage scheme classifies every probe from
//! these, so a device that keeps the hits reads back 16 bytes a probe instead
//! of 24 a ray. The batch's probes (`probegi_field::seam::BatchProbe`,
//! `#[repr(C)]` + `Pod`) are uploaded as they are, with one cage diagonal per volume.
//!
//! The counts come back late ([`GpuProbeUsage::counts_late`]): each batch's
//! are copied into a staging buffer in the batch's own submission and mapped
//! once it is made, and the set reads them `probe_usage_lag_updates` batches
//! later (`probegi_field::ddgi_volume`'s `usage_states`), so the update does
//! not wait on the device for them.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use bytemuck::{Pod, Zeroable};
use probegi_core::probe_classification::ProbeUsageCounts;
use probegi_field::seam::BatchProbe;
use probegi_field::{DeviceUsageCounts, DeviceUsageRequest};

use crate::bvh_trace::{GpuRayBatch, dispatch_2d};
use crate::gpu_context::{GpuContext, GpuError};
use crate::shader_registry::PROBE_USAGE;

/// Must match `UsageParams` in `probe_usage.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct UsageParams {
    pub(crate) probe_count: u32,
    pub(crate) groups_x: u32,
    pub(crate) _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<UsageParams>() == 16);

/// Batches kept waiting at most: beyond it, other sets' oldest are let go (a
/// set that stopped updating leaves its last batches behind); the asking
/// set's own are at most its lag + 1.
const USAGE_SLOTS_KEPT: usize = 32;

/// The usage counts' pipeline, and the batches' counts on their way back.
pub struct GpuProbeUsage {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    readback: std::sync::Mutex<UsageReadback>,
}

impl GpuProbeUsage {
    /// The pipeline on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("probe usage", &[true, true, true, false]);
        let [pipeline] = ctx.compute_pipelines(&PROBE_USAGE, &[Some(&layout)], ["probe_usage"]);
        Self { layout, pipeline, readback: Default::default() }
    }

    /// (usage, relevant, backfaces) of every probe in `probes` (a batch's), from
    /// `batch`'s hits, read back at once (a blocking wait); a probe's cage
    /// diagonal is `cage_diagonals_m[probe.volume]` (0 past its end).
    pub fn counts(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        probes: &[BatchProbe],
        cage_diagonals_m: &[f32],
    ) -> Result<Vec<ProbeUsageCounts>, GpuError> {
        let Some(out) = self.record(ctx, batch, probes, cage_diagonals_m)? else { return Ok(vec![]) };
        Ok(decode(&ctx.read_back(&out)?, probes.len()))
    }

    /// Counts `probes` of `batch` as [`Self::counts`] does, under `request`'s
    /// batch number, with a copy into a staging buffer recorded behind the
    /// pass (in the batch's own submission while the context defers); then
    /// returns the counts of the request's set's batches now
    /// `request.lag_updates` old, oldest first. A batch's map starts once its
    /// submission is made; the host waits for one only when it is due and
    /// the device has not finished it (lag 0: always).
    pub fn counts_late(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        probes: &[BatchProbe],
        request: &DeviceUsageRequest,
    ) -> Result<Vec<DeviceUsageCounts>, GpuError> {
        let staging = match self.record(ctx, batch, probes, &request.cage_diagonals_m)? {
            Some(out) => {
                let mut ring = self.readback.lock().unwrap_or_else(|e| e.into_inner());
                let staging = ring.staging(ctx, out.size());
                ctx.record(|encoder| encoder.copy_buffer_to_buffer(&out, 0, &staging, 0, out.size()));
                Some(staging)
            }
            None => None,
        };
        let mut slot = UsageSlot {
            set_id: request.set_id,
            batch: request.batch,
            probes: probes.len(),
            buffer: staging,
            recorded_at: ctx.queue_submissions(),
            submission: None,
            mapped: Arc::new(AtomicBool::new(false)),
        };
        if !ctx.deferring() {
            // The copy went with its own submission, the last one.
            slot.start_map(ctx.last_submission());
        }
        let mut ring = self.readback.lock().unwrap_or_else(|e| e.into_inner());
        // A batch counted again (its update failed after the count and the
        // set asks under the same number) replaces the first count.
        let same = |s: &UsageSlot| s.set_id == request.set_id && s.batch == request.batch;
        if let Some(i) = ring.slots.iter().position(same)
            && let Some(stale) = ring.slots.remove(i)
        {
            ring.release(stale);
        }
        ring.slots.push_back(slot);
        ring.start_maps(ctx);
        ring.take_due(ctx, request)
    }

    /// Records the usage pass over `probes` of `batch`; its output buffer
    /// (16 bytes a probe), or `None` for no probe.
    fn record(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        probes: &[BatchProbe],
        cage_diagonals_m: &[f32],
    ) -> Result<Option<wgpu::Buffer>, GpuError> {
        if probes.is_empty() {
            return Ok(None);
        }
        for p in probes {
            batch.check_rays(p.first_ray, p.ray_count)?;
        }
        let (gx, gy) = dispatch_2d(probes.len() as u32);
        let params = UsageParams { probe_count: probes.len() as u32, groups_x: gx, _pad: [0; 2] };
        let storage = wgpu::BufferUsages::STORAGE;
        let params = ctx.buffer_with("usage params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let rows = ctx.buffer_with("usage probes", bytemuck::cast_slice(probes), storage);
        // An empty table still binds one entry; the shader reads 0 for it, as past the end.
        let diagonals = if cage_diagonals_m.is_empty() { &[0.0][..] } else { cage_diagonals_m };
        let diagonals = ctx.buffer_with("usage cage diagonals", bytemuck::cast_slice(diagonals), storage);
        let out = ctx.output_buffer("usage counts", probes.len() as u64 * 16);
        let bind_group = crate::gpu_context::buffers_bind_group(
            ctx,
            "probe usage",
            &self.layout,
            &[params, batch.hits_buffer().clone(), rows, diagonals, out.clone()],
        );
        ctx.run_passes("probe usage", &[(&self.pipeline, vec![Some(&bind_group)], (gx, gy))]);
        Ok(Some(out))
    }
}

/// The first `probes` counts of a read-back output (16 bytes a probe).
fn decode(bytes: &[u8], probes: usize) -> Vec<ProbeUsageCounts> {
    let counts: &[[i32; 4]] = bytemuck::cast_slice(bytes);
    counts.iter().take(probes).map(|c| (c[0], c[1] as u32, c[2] as u32)).collect()
}

/// One batch's counts on their way back.
struct UsageSlot {
    set_id: u64,
    batch: u64,
    probes: usize,
    /// The staging buffer the counts are copied into (`None`: no probe).
    buffer: Option<wgpu::Buffer>,
    /// `GpuContext::queue_submissions` once the copy was recorded (deferred):
    /// a larger count since means a flush has submitted it.
    recorded_at: u64,
    /// A submission at or after the copy's, once made; its map has started then.
    submission: Option<wgpu::SubmissionIndex>,
    mapped: Arc<AtomicBool>,
}

/// The batches whose counts are on their way back, in the order recorded,
/// and staging buffers free for reuse.
#[derive(Default)]
struct UsageReadback {
    free: Vec<wgpu::Buffer>,
    slots: VecDeque<UsageSlot>,
}

impl UsageReadback {
    /// A staging buffer of `bytes`, reused when a free one has the size.
    fn staging(&mut self, ctx: &GpuContext, bytes: u64) -> wgpu::Buffer {
        if let Some(i) = self.free.iter().position(|b| b.size() == bytes) {
            return self.free.swap_remove(i);
        }
        ctx.create_buffer(&wgpu::BufferDescriptor {
            label: Some("usage counts readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Starts the map of every slot whose copy has been submitted since.
    fn start_maps(&mut self, ctx: &GpuContext) {
        let submitted = ctx.queue_submissions();
        for slot in self.slots.iter_mut().filter(|s| s.submission.is_none() && submitted > s.recorded_at) {
            slot.start_map(ctx.last_submission());
        }
    }

    /// The counts of `request`'s set's slots now due, oldest first (see
    /// [`GpuProbeUsage::counts_late`]); other sets' slots beyond
    /// [`USAGE_SLOTS_KEPT`] are let go, oldest first. On an error the due
    /// slots already read are lost: the set classifies nothing from them.
    fn take_due(&mut self, ctx: &GpuContext, request: &DeviceUsageRequest) -> Result<Vec<DeviceUsageCounts>, GpuError> {
        let due = |s: &UsageSlot| s.set_id == request.set_id && s.batch + request.lag_updates as u64 <= request.batch;
        let mut out = Vec::new();
        while let Some(i) = self.slots.iter().position(due) {
            let Some(slot) = self.slots.remove(i) else { break };
            out.push(DeviceUsageCounts { batch: slot.batch, counts: self.read(ctx, slot)? });
        }
        while self.slots.len() > USAGE_SLOTS_KEPT {
            let Some(i) = self.slots.iter().position(|s| s.set_id != request.set_id) else { break };
            if let Some(slot) = self.slots.remove(i) {
                self.release(slot);
            }
        }
        Ok(out)
    }

    /// A due slot's counts: submitted first if its copy is still deferred,
    /// waited for if the device has not finished it.
    fn read(&mut self, ctx: &GpuContext, mut slot: UsageSlot) -> Result<Vec<ProbeUsageCounts>, GpuError> {
        if slot.buffer.is_none() {
            return Ok(vec![]);
        }
        if slot.submission.is_none() {
            slot.start_map(ctx.flush());
        }
        if !slot.mapped.load(Ordering::Acquire) {
            let _ = ctx.device.poll(wgpu::PollType::Poll);
        }
        if !slot.mapped.load(Ordering::Acquire) {
            let submission =
                slot.submission.clone().ok_or_else(|| GpuError::Readback("usage counts unsubmitted".into()))?;
            ctx.wait_for(submission)?;
        }
        let counts = match (&slot.buffer, slot.mapped.load(Ordering::Acquire)) {
            (Some(buffer), true) => {
                let view = buffer.slice(..).get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?;
                ctx.count_read_back(view.len() as u64);
                Ok(decode(&view, slot.probes))
            }
            _ => Err(GpuError::Readback("usage counts could not be mapped".into())),
        };
        self.release(slot);
        counts
    }

    /// Keeps a slot's staging buffer for reuse where its map has completed
    /// (unmapped first); one whose copy or map is still pending is dropped.
    fn release(&mut self, slot: UsageSlot) {
        let Some(buffer) = slot.buffer else { return };
        if slot.mapped.load(Ordering::Acquire) {
            buffer.unmap();
            if self.free.len() < 4 {
                self.free.push(buffer);
            }
        }
    }
}

impl UsageSlot {
    /// Records the submission that holds the copy (or a later one) and starts the map.
    fn start_map(&mut self, submission: Option<wgpu::SubmissionIndex>) {
        let (Some(buffer), Some(submission)) = (&self.buffer, submission) else { return };
        let flag = self.mapped.clone();
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| flag.store(r.is_ok(), Ordering::Release));
        self.submission = Some(submission);
    }
}
