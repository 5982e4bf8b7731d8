//! Ray generation on the device (`shaders/probe_ray_gen.wgsl`): every probe's
//! rotated spherical Fibonacci rays written straight into a trace batch, so a
//! device-resident update uploads 16 bytes per probe instead of 32 per ray. The
//! frame's rotation is drawn on the CPU from (seed, frame) exactly as
//! `probegi_field::probe_ray_gen::probe_ray_directions` draws it; the directions
//! agree with the CPU's to the rounding of sin and cos, 2.4e-5 on lavapipe
//! (`tests/it/ray_gen_equivalence.rs`).
//!
//! The seam's update batches are planned on the CPU (which probes trace, their
//! relocated origins), and record how their rays were made
//! (`probegi_field::ddgi_field_set::GeneratedProbeRays`), so the device-resident
//! update generates them here ([`GpuProbeRayGen::generate_into`]) instead of
//! receiving them; `bench --backend wgpu` times this pass alone.

use bytemuck::{Pod, Zeroable};
use glam::{Quat, Vec3};

use crate::bvh_trace::{GpuRayBatch, GpuRayTrace, dispatch_2d};
use crate::gpu_context::{GpuContext, GpuError};
use crate::shader_registry::PROBE_RAY_GEN;

/// The pass's uniform block; must match `RayGenParams` in `probe_ray_gen.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct RayGenParams {
    /// The frame's rotation quaternion (x, y, z, w).
    pub(crate) rotation: [f32; 4],
    pub(crate) rays_per_probe: u32,
    pub(crate) probe_count: u32,
    pub(crate) groups_x: u32,
    /// Where the probes' rays start in the batch.
    pub(crate) first_ray: u32,
}
const _: () = assert!(std::mem::size_of::<RayGenParams>() == 32);

/// One volume's rays for [`GpuProbeRayGen::generate_kept`]: from ray
/// `first_ray` on, `rays_per_probe` for each of `origins`, turned by `rotation`.
#[derive(Clone, Copy)]
pub(crate) struct RayGenRays<'a> {
    pub first_ray: u32,
    pub origins: &'a [Vec3],
    pub max_distance_m: f32,
    pub rotation: Quat,
    pub rays_per_probe: u32,
}

/// The ray generation pipeline.
pub struct GpuProbeRayGen {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl GpuProbeRayGen {
    /// The pipeline on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("probe ray gen", &[true, false]);
        let [pipeline] = ctx.compute_pipelines(&PROBE_RAY_GEN, &[Some(&layout)], ["generate_probe_rays"]);
        Self { layout, pipeline }
    }

    /// A trace batch of `origins.len() × rays_per_probe` rays, probe-major, each
    /// probe's along the `rotation`-rotated spherical Fibonacci set, up to
    /// `max_distance_m`; with `timer`, the pass writes its timestamps at `timer.1`.
    #[allow(clippy::too_many_arguments)]
    pub fn generate(
        &self,
        ctx: &GpuContext,
        trace: &GpuRayTrace,
        origins: &[Vec3],
        max_distance_m: f32,
        rotation: Quat,
        rays_per_probe: u32,
        timer: Option<(&crate::gpu_timer::GpuTimer, u32)>,
    ) -> Result<GpuRayBatch, GpuError> {
        let n = origins.len() as u64 * rays_per_probe as u64;
        if n > GpuRayTrace::max_batch_rays(ctx) as u64 || rays_per_probe == 0 {
            return Err(GpuError::Input(format!(
                "{} probes × {rays_per_probe} rays: not a batch this device holds",
                origins.len()
            )));
        }
        let batch = trace.empty_batch(ctx, n as u32, false)?;
        self.generate_into(ctx, &batch, 0, origins, max_distance_m, rotation, rays_per_probe, timer)?;
        Ok(batch)
    }

    /// Writes `origins.len() × rays_per_probe` rays, as [`Self::generate`] makes
    /// them, into `batch` from ray `first_ray` on (one volume's share of a
    /// batch several volumes trace together).
    #[allow(clippy::too_many_arguments)]
    pub fn generate_into(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        first_ray: u32,
        origins: &[Vec3],
        max_distance_m: f32,
        rotation: Quat,
        rays_per_probe: u32,
        timer: Option<(&crate::gpu_timer::GpuTimer, u32)>,
    ) -> Result<(), GpuError> {
        let rays = RayGenRays { first_ray, origins, max_distance_m, rotation, rays_per_probe };
        self.generate_kept(ctx, batch, rays, None, timer)
    }

    /// As [`Self::generate_into`]; with `kept` (a key per volume, and the
    /// records' identity, `GeneratedProbeRays::plan_id`), the probe records
    /// are [`GpuContext::buffer_identified`]'s under that key: a still
    /// volume's update uploads none of them after its first frame, and a kept
    /// plan's (the same id) packs and compares none either.
    pub(crate) fn generate_kept(
        &self,
        ctx: &GpuContext,
        batch: &GpuRayBatch,
        rays: RayGenRays<'_>,
        kept: Option<(u64, Option<u64>)>,
        timer: Option<(&crate::gpu_timer::GpuTimer, u32)>,
    ) -> Result<(), GpuError> {
        let RayGenRays { first_ray, origins, max_distance_m, rotation, rays_per_probe } = rays;
        let n = origins.len() as u64 * rays_per_probe as u64;
        if first_ray as u64 + n > batch.ray_count as u64 {
            return Err(GpuError::Input(format!(
                "rays {first_ray}..{} lie past the batch's {}",
                first_ray as u64 + n,
                batch.ray_count
            )));
        }
        if n == 0 {
            return Ok(());
        }
        let (gx, gy) = dispatch_2d(n as u32);
        let params = RayGenParams {
            rotation: rotation.normalize().to_array(),
            rays_per_probe,
            probe_count: origins.len() as u32,
            groups_x: gx,
            first_ray,
        };
        let t_max = max_distance_m.min(f32::MAX);
        let records = || -> Vec<u8> {
            origins.iter().flat_map(|o| bytemuck::cast::<[f32; 4], [u8; 16]>([o.x, o.y, o.z, t_max])).collect()
        };
        let usage = wgpu::BufferUsages::STORAGE;
        let params = bytemuck::bytes_of(&params);
        let bind_group = match kept {
            // A still volume's update: its records, uniform block and bind
            // group are the ones of the frame before (two batches alternate).
            Some((key, id)) => {
                let params = ctx.buffer_rewritten("ray gen params", key, params, wgpu::BufferUsages::UNIFORM);
                let id = id.as_ref().map(std::slice::from_ref);
                let probes = ctx.buffer_identified("ray gen probes", key, id, || Ok(records()), usage)?;
                ctx.bind_group_kept("probe ray gen", key, &self.layout, &[&params, &probes, batch.rays_buffer()])
            }
            None => {
                let params = ctx.buffer_with("ray gen params", params, wgpu::BufferUsages::UNIFORM);
                let probes = ctx.buffer_with("ray gen probes", &records(), usage);
                crate::gpu_context::buffers_bind_group(
                    ctx,
                    "probe ray gen",
                    &self.layout,
                    &[params, probes, batch.rays_buffer().clone()],
                )
            }
        };
        ctx.record(|encoder| {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("probe ray gen"),
                timestamp_writes: timer.and_then(|(t, i)| t.writes(i)),
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        });
        Ok(())
    }
}
