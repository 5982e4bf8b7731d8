//! Probe relocation on the GPU (`shaders/probe_relocation.wgsl`): one iteration
//! of seed 004 Listing 4's position optimizer per probe of a traced
//! initialisation batch, mirroring `probegi_core::probe_relocation::{probe_ray_stats,
//! relocation_step}` (RTXGI `ProbeRelocationCS`). The rays and hits stay where the
//! trace left them; the host reads back one offset per probe (16 bytes) instead
//! of one hit per ray. The probes are the field's own plan
//! (`probegi_field::device_plans::DeviceRelocationProbe`, `#[repr(C)]` + `Pod`),
//! uploaded as they are.

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use probegi_field::device_plans::DeviceRelocationProbe;

use crate::bvh_trace::{GpuRayBatch, dispatch_2d};
use crate::gpu_context::{GpuContext, GpuError};
use crate::shader_registry::PROBE_RELOCATION;

/// Must match `RelocationParams` in `probe_relocation.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct RelocationParams {
    pub(crate) probe_count: u32,
    pub(crate) groups_x: u32,
    pub(crate) _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<RelocationParams>() == 16);

/// The relocation iteration's pipeline.
pub struct GpuProbeRelocation {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl GpuProbeRelocation {
    /// The pipeline on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("probe relocation", &[true, true, true, false]);
        let [pipeline] = ctx.compute_pipelines(&PROBE_RELOCATION, &[Some(&layout)], ["relocate_probes"]);
        Self { layout, pipeline }
    }

    /// Every probe's new offset after one iteration, from `batch`'s rays and hits.
    pub fn relocate(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        probes: &[DeviceRelocationProbe],
    ) -> Result<Vec<Vec3>, GpuError> {
        if probes.is_empty() {
            return Ok(vec![]);
        }
        for p in probes {
            batch.check_rays(p.first_ray, p.ray_count)?;
        }
        let (gx, gy) = dispatch_2d(probes.len() as u32);
        let params = RelocationParams { probe_count: probes.len() as u32, groups_x: gx, _pad: [0; 2] };
        let params = ctx.buffer_with("relocation params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let rows = ctx.buffer_with("relocation probes", bytemuck::cast_slice(probes), wgpu::BufferUsages::STORAGE);
        let out = ctx.output_buffer("relocation offsets", probes.len() as u64 * 16);
        let bind_group = crate::gpu_context::buffers_bind_group(
            &ctx.device,
            "probe relocation",
            &self.layout,
            &[params, batch.rays_buffer().clone(), batch.hits_buffer().clone(), rows, out.clone()],
        );
        ctx.run_passes("probe relocation", &[(&self.pipeline, vec![Some(&bind_group)], (gx, gy))]);
        let bytes = ctx.read_back(&out)?;
        let v: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
        Ok(v.iter().take(probes.len()).map(|o| Vec3::new(o[0], o[1], o[2])).collect())
    }
}
