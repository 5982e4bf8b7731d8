//! `--backend wgpu`: what of a frame runs on the GPU today. The DDGI probe ray
//! batches (update and initialisation rounds) are traced by probegi-wgpu's
//! compute-shader CWBVH traversal, over the same BVH the CPU builds; the rest of
//! the frame (shading, blend, border, the camera image) is still the CPU's.

use anyhow::{Context, Result};
use probegi_cpu::ddgi_field_set::ProbeRayBatch;
use probegi_cpu::probe_trace::ProbeBatchTracer;
use probegi_scene::{BvhTracer, RayHit};
use probegi_wgpu::GpuContext;
use probegi_wgpu::bvh_trace::{GpuBvh, GpuRay, GpuRayTrace};

/// Which device traces the probe rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Backend {
    Cpu,
    Wgpu,
}

/// The GPU trace behind the field set's seam.
pub struct WgpuProbeTracer {
    ctx: GpuContext,
    trace: GpuRayTrace,
    bvh: GpuBvh,
}

impl WgpuProbeTracer {
    /// A headless device and the scene's BVH on it; a clear error when there is no
    /// adapter or the scene needs what the GPU trace lacks (a TLAS).
    pub fn new(bvh: &BvhTracer, scene_name: &str) -> Result<Self> {
        let export = bvh.export_static().map_err(anyhow::Error::msg).with_context(|| {
            format!("--backend wgpu cannot trace scene {scene_name}; use --backend cpu for moving or instanced geometry")
        })?;
        let ctx = GpuContext::headless().context("--backend wgpu")?;
        let gpu_bvh = GpuBvh::upload(&ctx, &export).context("uploading the BVH")?;
        let trace = GpuRayTrace::new(&ctx);
        Ok(Self { ctx, trace, bvh: gpu_bvh })
    }

    pub fn adapter_name(&self) -> &str {
        &self.ctx.adapter_name
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    pub fn gpu_bvh(&self) -> &GpuBvh {
        &self.bvh
    }

    pub fn ray_trace(&self) -> &GpuRayTrace {
        &self.trace
    }
}

/// A batch's rays as the GPU trace reads them.
pub fn batch_rays(batch: &ProbeRayBatch) -> Vec<GpuRay> {
    (0..batch.len())
        .map(|i| GpuRay::new(batch.origins_m[i], batch.directions[i], 0.0, batch.max_distances_m[i]))
        .collect()
}

impl ProbeBatchTracer for WgpuProbeTracer {
    fn closest_hits(&self, batch: &ProbeRayBatch, _static_only: bool, hits: &mut Vec<Option<RayHit>>) -> Result<(), String> {
        // The GPU BVH holds static geometry only (`export_static`), so every batch
        // already sees what an initialisation round must.
        let gpu = self.trace.trace(&self.ctx, &self.bvh, &batch_rays(batch), false).map_err(|e| e.to_string())?;
        hits.clear();
        hits.extend(gpu.iter().map(|h| h.ray_hit()));
        Ok(())
    }
}
