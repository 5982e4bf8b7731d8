//! The usage counts of seed 003's probe states on the GPU (`shaders/probe_usage.wgsl`,
//! mirroring `probegi_core::probe_classification::probe_usage`, eq. 6.1–6.2): per
//! probe of a traced batch, (usage, relevant samples, backfaces) from the hits
//! where they lie on the device. The usage scheme classifies every probe from
//! these each frame, so a device that keeps the hits reads back 16 bytes a
//! probe instead of 24 a ray.

use bytemuck::{Pod, Zeroable};
use probegi_core::probe_classification::ProbeUsageCounts;

use crate::bvh_trace::{GpuRayBatch, dispatch_2d, storage_entry, uniform_entry};
use crate::gpu_context::{GpuContext, GpuError};

/// Must match `UsageParams` in `probe_usage.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct UsageParams {
    pub probe_count: u32,
    pub groups_x: u32,
    pub _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<UsageParams>() == 16);

/// One probe of the batch: its rays and its cage diagonal.
#[derive(Clone, Copy, Debug)]
pub struct UsageProbe {
    pub first_ray: u32,
    pub ray_count: u32,
    pub cage_diagonal_m: f32,
}

pub struct GpuProbeUsage {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl GpuProbeUsage {
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("probe usage"),
            entries: &[uniform_entry(0), storage_entry(1, true), storage_entry(2, true), storage_entry(3, false)],
        });
        let [pipeline] = ctx.compute_pipelines(
            "probe_usage.wgsl",
            include_str!("shaders/probe_usage.wgsl").into(),
            &[Some(&layout)],
            ["probe_usage"],
        );
        Self { layout, pipeline }
    }

    /// (usage, relevant, backfaces) of every probe in `probes`, from `batch`'s hits.
    pub fn counts(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        probes: &[UsageProbe],
    ) -> Result<Vec<ProbeUsageCounts>, GpuError> {
        if probes.is_empty() {
            return Ok(vec![]);
        }
        for p in probes {
            batch.check_rays(p.first_ray, p.ray_count)?;
        }
        let (gx, gy) = dispatch_2d(probes.len() as u32);
        let params = UsageParams { probe_count: probes.len() as u32, groups_x: gx, _pad: [0; 2] };
        let rows: Vec<[u32; 4]> =
            probes.iter().map(|p| [p.first_ray, p.ray_count, p.cage_diagonal_m.to_bits(), 0]).collect();
        let params = ctx.buffer_with("usage params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let rows = ctx.buffer_with("usage probes", bytemuck::cast_slice(&rows), wgpu::BufferUsages::STORAGE);
        let out = ctx.output_buffer("usage counts", probes.len() as u64 * 16);
        let bind_group = crate::bvh_trace::buffers_bind_group(
            &ctx.device,
            "probe usage",
            &self.layout,
            &[params, batch.hits_buffer().clone(), rows, out.clone()],
        );
        ctx.run_passes("probe usage", &[(&self.pipeline, vec![Some(&bind_group)], (gx, gy))]);
        let bytes = ctx.read_back(&out)?;
        let counts: &[[i32; 4]] = bytemuck::cast_slice(&bytes);
        Ok(counts.iter().take(probes.len()).map(|c| (c[0], c[1] as u32, c[2] as u32)).collect())
    }
}
