//! The usage counts of seed 003's probe states on the GPU (`shaders/probe_usage.wgsl`,
//! mirroring `probegi_core::probe_classification::probe_usage`, eq. 6.1–6.2): per
//! probe of a traced batch, (usage, relevant samples, backfaces) from the hits
//! where they lie on the device. The usage scheme classifies every probe from
//! these, so a device that keeps the hits reads back 16 bytes a probe instead
//! of 24 a ray. The batch's probes (`probegi_field::seam::BatchProbe`,
//! `#[repr(C)]` + `Pod`) are uploaded as they are, with one cage diagonal per volume.
//!
//! The counts come back late ([`GpuProbeUsage::counts_late`],
//! `late_readback`): the set reads each batch's `probe_usage_lag_updates`
//! batches later (`probegi_field::ddgi_volume`'s `usage_states`), so the
//! update does not wait on the device for them.

use bytemuck::{Pod, Zeroable};
use probegi_core::probe_classification::ProbeUsageCounts;
use probegi_field::seam::BatchProbe;
use probegi_field::{DeviceUsageCounts, DeviceUsageRequest};

use crate::bvh_trace::{GpuRayBatch, dispatch_2d};
use crate::gpu_context::{GpuContext, GpuError};
use crate::late_readback::{LateKey, LateReadback};
use crate::shader_registry::PROBE_USAGE;

/// Must match `UsageParams` in `probe_usage.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct UsageParams {
    pub(crate) probe_count: u32,
    pub(crate) groups_x: u32,
    /// The cage diagonals given: the kept buffer may hold more from an
    /// earlier batch, which the shader must not read.
    pub(crate) diagonal_count: u32,
    pub(crate) _pad: u32,
}
const _: () = assert!(std::mem::size_of::<UsageParams>() == 16);

/// The usage counts' pipeline, and the batches' counts on their way back.
pub struct GpuProbeUsage {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    readback: std::sync::Mutex<LateReadback>,
}

impl GpuProbeUsage {
    /// The pipeline on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("probe usage", &[true, true, true, false]);
        let [pipeline] = ctx.compute_pipelines(&PROBE_USAGE, &[Some(&layout)], ["probe_usage"]);
        Self { layout, pipeline, readback: Default::default() }
    }

    /// (usage, relevant, backfaces) of every probe in `probes` (a batch's),
    /// from `batch`'s hits, with a probe's cage diagonal
    /// `request.cage_diagonals_m[probe.volume]` (0 past its end), counted
    /// under `request`'s batch number and read late (`late_readback`); returns
    /// the counts of the request's set's batches now `request.lag_updates`
    /// old, oldest first. `records_id`: an identity of `probes` (equal ids,
    /// equal records; `None`: none), so a kept batch's are not uploaded again.
    pub fn counts_late(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        probes: &[BatchProbe],
        records_id: Option<&[u64]>,
        request: &DeviceUsageRequest,
    ) -> Result<Vec<DeviceUsageCounts>, GpuError> {
        // (The output is 16 bytes a probe, exactly: one probe at least.)
        let out = self.record(ctx, batch, probes, records_id, &request.cage_diagonals_m)?;
        let key = LateKey { set_id: request.set_id, batch: request.batch, part: 0 };
        let mut ring = self.readback.lock().unwrap_or_else(|e| e.into_inner());
        // (The scratch output may hold more than this batch's probes.)
        ring.push(ctx, key, out.as_ref().map(|o| (o, probes.len() as u64 * 16)));
        let Some(last) = request.batch.checked_sub(request.lag_updates as u64) else { return Ok(vec![]) };
        let due = ring.take_due(ctx, request.set_id, last, |bytes| decode(bytes, bytes.len() / 16))?;
        Ok(due.into_iter().map(|(key, counts)| DeviceUsageCounts { batch: key.batch, counts }).collect())
    }

    /// Records the usage pass over `probes` of `batch`; its output buffer
    /// (16 bytes a probe), or `None` for no probe. Its inputs, output and
    /// bind group are kept from one batch to the next (`GpuContext`'s
    /// `buffer_identified`, `scratch_buffer`, `bind_group_kept`): a still
    /// field's batch (`records_id`: the batch's `GeneratedProbeRays::plan_id`s,
    /// equal for equal records) uploads and makes nothing. The output is read
    /// by the copy `counts_late` records behind the pass (in the same
    /// submission while the context defers; otherwise the next one, before
    /// any later pass), so the next batch's pass may write it again. (One
    /// thread records a set's update; two threads recording usage passes on
    /// one context at once could interleave a pass between another's pass
    /// and its copy.)
    fn record(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        probes: &[BatchProbe],
        records_id: Option<&[u64]>,
        cage_diagonals_m: &[f32],
    ) -> Result<Option<wgpu::Buffer>, GpuError> {
        if probes.is_empty() {
            return Ok(None);
        }
        if records_id.is_none() {
            for p in probes {
                batch.check_rays(p.first_ray, p.ray_count)?;
            }
        }
        let (gx, gy) = dispatch_2d(probes.len() as u32);
        let params = UsageParams {
            probe_count: probes.len() as u32,
            groups_x: gx,
            diagonal_count: cage_diagonals_m.len() as u32,
            _pad: 0,
        };
        let storage = wgpu::BufferUsages::STORAGE;
        let params = ctx.buffer_rewritten("usage params", 0, bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let records = || {
            // A kept batch's records were checked when they were written.
            for p in probes {
                batch.check_rays(p.first_ray, p.ray_count)?;
            }
            Ok(bytemuck::cast_slice(probes).to_vec())
        };
        let rows = ctx.buffer_identified("usage probes", 0, records_id, records, storage)?;
        // An empty table still binds one entry; the shader reads 0 past
        // `diagonal_count`, as for no table.
        let diagonals = if cage_diagonals_m.is_empty() { &[0.0][..] } else { cage_diagonals_m };
        let diagonals = ctx.buffer_rewritten("usage cage diagonals", 0, bytemuck::cast_slice(diagonals), storage);
        let out_usage = storage | wgpu::BufferUsages::COPY_SRC;
        let out = ctx.scratch_buffer("usage counts", 0, probes.len() as u64 * 16, out_usage);
        let bind_group = ctx.bind_group_kept(
            "probe usage",
            0,
            &self.layout,
            &[&params, batch.hits_buffer(), &rows, &diagonals, &out],
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
