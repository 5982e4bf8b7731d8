//! The ray budget's change measure on the device (`shaders/probe_change.wgsl`),
//! the twin of `probegi_core::probe_change` as `probegi_field`'s host blend
//! applies it: before the blend the listed probes' interior irradiance and
//! occlusion texels are copied aside; after the blend (and the shadowing
//! field's) each probe's change is measured against the copy and read back,
//! 4 bytes per blended probe. Nothing runs without a ray budget
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

/// The change passes' pipelines.
pub struct GpuProbeChange {
    layout: wgpu::BindGroupLayout,
    pipelines: [wgpu::ComputePipeline; 2],
}

/// One volume's measure between [`GpuProbeChange::snapshot`] and
/// [`GpuProbeChange::measure`].
pub struct ChangeMeasure {
    bind_group: wgpu::BindGroup,
    out: wgpu::Buffer,
    entries: u32,
    groups: (u32, u32),
}

impl GpuProbeChange {
    /// The pipelines on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("probe change", &[true, true, true, false, false]);
        let pipelines = ctx.compute_pipelines(&PROBE_CHANGE, &[Some(&layout)], ["snapshot_tiles", "measure_change"]);
        Self { layout, pipelines }
    }

    /// Copies aside the tiles of `probes` (increasing storage slots of the
    /// volume whose atlases are `atlases`, occlusion maps `occlusion`) before
    /// they blend; `None` when there are none.
    pub fn snapshot(
        &self,
        ctx: &GpuContext,
        atlases: &GpuVolumeAtlases,
        occlusion: Option<&OcclusionTarget<'_>>,
        probes: &[u32],
    ) -> Result<Option<ChangeMeasure>, GpuError> {
        if probes.is_empty() {
            return Ok(None);
        }
        if probes.iter().any(|&p| p as usize >= atlases.probe_count) {
            return Err(GpuError::Input("a probe to measure lies outside its volume".into()));
        }
        let n = atlases.irradiance_interior;
        let m = occlusion.map_or(0, |o| o.interior);
        let stride = 3 * (n * n) as u64 + (m * m) as u64;
        let snapshot_bytes = probes.len() as u64 * stride * 4;
        ctx.check_buffer(snapshot_bytes, "the ray budget's tile snapshot")?;
        let groups = dispatch_2d(probes.len() as u32);
        let params = ChangeParams {
            entry_count: probes.len() as u32,
            groups_x: groups.0,
            irradiance_interior: n,
            irradiance_first: atlases.irradiance_first,
            occlusion_interior: m,
            occlusion_first: occlusion.map_or(0, |o| o.first),
            _pad: [0; 2],
        };
        let params = ctx.buffer_with("change params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let list = ctx.buffer_with("change probes", bytemuck::cast_slice(probes), wgpu::BufferUsages::STORAGE);
        let snapshot = ctx.output_buffer("change snapshot", snapshot_bytes);
        let out = ctx.output_buffer("probe change", probes.len() as u64 * 4);
        let buffers = [params, list, atlases.irradiance.clone(), atlases.distance.clone(), snapshot, out.clone()];
        let bind_group = crate::gpu_context::buffers_bind_group(&ctx.device, "probe change", &self.layout, &buffers);
        ctx.run_passes("change snapshot", &[(&self.pipelines[0], vec![Some(&bind_group)], groups)]);
        Ok(Some(ChangeMeasure { bind_group, out, entries: probes.len() as u32, groups }))
    }

    /// Each snapshot probe's change since [`Self::snapshot`], in its order.
    pub fn measure(&self, ctx: &GpuContext, measure: &ChangeMeasure) -> Result<Vec<f32>, GpuError> {
        ctx.run_passes("probe change", &[(&self.pipelines[1], vec![Some(&measure.bind_group)], measure.groups)]);
        let bytes = ctx.read_back(&measure.out)?;
        Ok(bytemuck::cast_slice::<u8, f32>(&bytes).iter().take(measure.entries as usize).copied().collect())
    }
}
