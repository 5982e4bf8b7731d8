//! The usage counts of seed 003's probe states on the GPU (`shaders/probe_usage.wgsl`,
//! mirroring `probegi_core::probe_classification::probe_usage`, eq. 6.1–6.2): per
//! probe of a traced batch, (usage, relevant samples, backfaces) from the hits
//! where they lie on the device. The usage scheme classifies every probe from
//! these each frame, so a device that keeps the hits reads back 16 bytes a
//! probe instead of 24 a ray. The batch's probes (`probegi_field::seam::BatchProbe`,
//! `#[repr(C)]` + `Pod`) are uploaded as they are, with one cage diagonal per volume.

use bytemuck::{Pod, Zeroable};
use probegi_core::probe_classification::ProbeUsageCounts;
use probegi_field::seam::BatchProbe;

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

/// The usage counts' pipeline.
pub struct GpuProbeUsage {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl GpuProbeUsage {
    /// The pipeline on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("probe usage", &[true, true, true, false]);
        let [pipeline] = ctx.compute_pipelines(&PROBE_USAGE, &[Some(&layout)], ["probe_usage"]);
        Self { layout, pipeline }
    }

    /// (usage, relevant, backfaces) of every probe in `probes` (a batch's), from
    /// `batch`'s hits; a probe's cage diagonal is `cage_diagonals_m[probe.volume]`
    /// (0 past its end).
    pub fn counts(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        probes: &[BatchProbe],
        cage_diagonals_m: &[f32],
    ) -> Result<Vec<ProbeUsageCounts>, GpuError> {
        if probes.is_empty() {
            return Ok(vec![]);
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
        let bytes = ctx.read_back(&out)?;
        let counts: &[[i32; 4]] = bytemuck::cast_slice(&bytes);
        Ok(counts.iter().take(probes.len()).map(|c| (c[0], c[1] as u32, c[2] as u32)).collect())
    }
}
