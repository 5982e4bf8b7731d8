//! The usage counts of seed 003's probe states on the GPU (`shaders/probe_usage.wgsl`,
//! mirroring `probegi_core::probe_classification::probe_usage`, eq. 6.1–6.2): per
//! probe of a traced batch, (usage, relevant samples, backfaces) from the hits
//! where they lie on the device. The usage scheme classifies every probe from
//! these each frame, so a device that keeps the hits reads back 16 bytes a
//! probe instead of 16 a ray.

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

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
        let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("probe_usage.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shaders/probe_usage.wgsl").into()),
        });
        let layout = ctx.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("probe usage"),
            entries: &[uniform_entry(0), storage_entry(1, true), storage_entry(2, true), storage_entry(3, false)],
        });
        let pipeline_layout = ctx.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("probe usage"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = ctx.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("probe_usage"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("probe_usage"),
            compilation_options: Default::default(),
            cache: None,
        });
        Self { layout, pipeline }
    }

    /// (usage, relevant, backfaces) of every probe in `probes`, from `batch`'s hits.
    pub fn counts(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        probes: &[UsageProbe],
    ) -> Result<Vec<(i32, u32, u32)>, GpuError> {
        if probes.is_empty() {
            return Ok(vec![]);
        }
        if let Some(p) = probes.iter().find(|p| p.first_ray as u64 + p.ray_count as u64 > batch.ray_count as u64) {
            return Err(GpuError::Input(format!(
                "a probe's rays {}..{} lie past the batch's {} rays",
                p.first_ray,
                p.first_ray as u64 + p.ray_count as u64,
                batch.ray_count
            )));
        }
        let (gx, gy) = dispatch_2d(probes.len() as u32);
        let params = UsageParams { probe_count: probes.len() as u32, groups_x: gx, _pad: [0; 2] };
        let rows: Vec<[u32; 4]> =
            probes.iter().map(|p| [p.first_ray, p.ray_count, p.cage_diagonal_m.to_bits(), 0]).collect();
        let init = |label: &str, contents: &[u8], usage: wgpu::BufferUsages| {
            ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        let params = init("usage params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let rows = init("usage probes", bytemuck::cast_slice(&rows), wgpu::BufferUsages::STORAGE);
        let out = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("usage counts"),
            size: probes.len() as u64 * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let bind_group = crate::bvh_trace::buffers_bind_group(
            &ctx.device,
            "probe usage",
            &self.layout,
            &[params, batch.hits_buffer().clone(), rows, out.clone()],
        );
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("probe usage"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        ctx.queue.submit([encoder.finish()]);
        let bytes = ctx.read_back(&out)?;
        let counts: &[[i32; 4]] = bytemuck::cast_slice(&bytes);
        Ok(counts.iter().map(|c| (c[0], c[1] as u32, c[2] as u32)).collect())
    }
}
