//! The ray budget's change measure on the device (`shaders/probe_change.wgsl`),
//! the twin of `probegi_core::probe_change` as `probegi_field`'s host blend
//! reports it: the blends leave each texel's change beside its value (the
//! irradiance texel's w, the occlusion texel's y); after the blend and the
//! shadowing field's, one thread per blended probe averages its tiles' and
//! the host reads back 4 bytes a probe, `ray_budget_change_lag_updates`
//! batches later (`late_readback`), without waiting inside an update. It runs
//! only under a ray budget
//! (`probegi_field::device_plans::DeviceVolumeBlend::measure_change`).

use bytemuck::{Pod, Zeroable};

use crate::bvh_trace::dispatch_2d;
use crate::gpu_context::{GpuContext, GpuError};
use crate::late_readback::{LateKey, LateReadback};
use crate::probe_blend::GpuVolumeAtlases;
use crate::shader_registry::PROBE_CHANGE;
use crate::shadow_field::OcclusionTarget;
use probegi_field::{DeviceChangeKey, DeviceProbeChanges};

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

/// The change pass's pipeline, and the measured changes on their way back.
pub struct GpuProbeChange {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    readback: std::sync::Mutex<LateReadback>,
}

impl GpuProbeChange {
    /// The pipeline on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("probe change", &[true, true, true, false]);
        let [pipeline] = ctx.compute_pipelines(&PROBE_CHANGE, &[Some(&layout)], ["measure_change"]);
        Self { layout, pipeline, readback: Default::default() }
    }

    /// After the blends: the change of each of `probes` (increasing storage
    /// slots of the volume whose atlases are `atlases`, occlusion maps
    /// `occlusion`), in their order, kept on its way back under volume
    /// `volume` of `key`'s batch (read by [`Self::take_due`]).
    pub fn measure_late(
        &self,
        ctx: &GpuContext,
        atlases: &GpuVolumeAtlases,
        occlusion: Option<&OcclusionTarget<'_>>,
        probes: &[u32],
        key: &DeviceChangeKey,
        volume: u32,
    ) -> Result<(), GpuError> {
        let out = self.record(ctx, atlases, occlusion, probes)?;
        let key = LateKey { set_id: key.set_id, batch: key.batch, part: volume };
        let mut ring = self.readback.lock().unwrap_or_else(|e| e.into_inner());
        // (4 bytes a probe, exactly: one probe at least.)
        ring.push(ctx, key, out.as_ref().map(|o| (o, 4 * probes.len() as u64)));
        Ok(())
    }

    /// The changes of `key`'s set measured after the blends of batches up to
    /// `key.batch − key.lag_updates` not yet returned, oldest first.
    pub fn take_due(&self, ctx: &GpuContext, key: &DeviceChangeKey) -> Result<Vec<DeviceProbeChanges>, GpuError> {
        let Some(last) = key.batch.checked_sub(key.lag_updates as u64) else { return Ok(Vec::new()) };
        let mut ring = self.readback.lock().unwrap_or_else(|e| e.into_inner());
        let due = ring.take_due(ctx, key.set_id, last, bytemuck::pod_collect_to_vec::<u8, f32>)?;
        Ok(due.into_iter().map(|(k, changes)| DeviceProbeChanges { volume: k.part, batch: k.batch, changes }).collect())
    }

    /// Records the change pass over `probes`; its output (4 bytes a probe),
    /// or `None` for no probe.
    fn record(
        &self,
        ctx: &GpuContext,
        atlases: &GpuVolumeAtlases,
        occlusion: Option<&OcclusionTarget<'_>>,
        probes: &[u32],
    ) -> Result<Option<wgpu::Buffer>, GpuError> {
        if probes.is_empty() {
            return Ok(None);
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
        Ok(Some(out))
    }
}
