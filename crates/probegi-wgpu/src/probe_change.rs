//! The ray budget's change measure on the device (`shaders/probe_change.wgsl`),
//! the twin of `probegi_core::probe_change` as `probegi_field`'s host blend
//! reports it: the blends leave each texel's change beside its value (the
//! irradiance texel's w, the occlusion texel's y); after the blend and the
//! shadowing field's, one thread per blended probe averages its tiles' and
//! the host reads back 4 bytes a probe. It runs only under a ray budget
//! (`probegi_field::device_plans::DeviceVolumeBlend::measure_change`).

use bytemuck::{Pod, Zeroable};

use crate::bvh_trace::dispatch_2d;
use crate::gpu_context::{GpuContext, GpuError};
use crate::probe_blend::GpuVolumeAtlases;
use crate::shader_registry::PROBE_CHANGE;
use crate::shadow_field::OcclusionTarget;

/// Must match `ChangeParams` in `probe_change.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct ChangeParams {
    pub(crate) entry_count: u32,
    pub(crate) groups_x: u32,
    pub(crate) irradiance_interior: u32,
    pub(crate) irradiance_first: u32,
    pub(crate) occlusion_interior: u32,
    pub(crate) occlusion_first: u32,
    pub(crate) _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<ChangeParams>() == 32);

/// The change pass's pipeline.
pub struct GpuProbeChange {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl GpuProbeChange {
    /// The pipeline on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("probe change", &[true, true, true, false]);
        let [pipeline] = ctx.compute_pipelines(&PROBE_CHANGE, &[Some(&layout)], ["measure_change"]);
        Self { layout, pipeline }
    }

    /// After the blends: the change of each of `probes` (increasing storage
    /// slots of the volume whose atlases are `atlases`, occlusion maps
    /// `occlusion`), in their order, read back.
    pub fn measure(
        &self,
        ctx: &GpuContext,
        atlases: &GpuVolumeAtlases,
        occlusion: Option<&OcclusionTarget<'_>>,
        probes: &[u32],
    ) -> Result<Vec<f32>, GpuError> {
        if probes.is_empty() {
            return Ok(Vec::new());
        }
        if probes.iter().any(|&p| p as usize >= atlases.probe_count) {
            return Err(GpuError::Input("a probe to measure lies outside its volume".into()));
        }
        let groups = dispatch_2d(probes.len() as u32);
        let params = ChangeParams {
            entry_count: probes.len() as u32,
            groups_x: groups.0,
            irradiance_interior: atlases.irradiance_interior,
            irradiance_first: atlases.irradiance_first,
            occlusion_interior: occlusion.map_or(0, |o| o.interior),
            occlusion_first: occlusion.map_or(0, |o| o.first),
            _pad: [0; 2],
        };
        let params = ctx.buffer_with("change params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let list = ctx.buffer_with("change probes", bytemuck::cast_slice(probes), wgpu::BufferUsages::STORAGE);
        let out = ctx.output_buffer("probe change", probes.len() as u64 * 4);
        let buffers = [params, list, atlases.irradiance.clone(), atlases.distance.clone(), out.clone()];
        let bind_group = crate::gpu_context::buffers_bind_group(ctx, "probe change", &self.layout, &buffers);
        ctx.run_passes("probe change", &[(&self.pipeline, vec![Some(&bind_group)], groups)]);
        let bytes = ctx.read_back(&out)?;
        Ok(bytemuck::cast_slice::<u8, f32>(&bytes).iter().take(probes.len()).copied().collect())
    }
}
