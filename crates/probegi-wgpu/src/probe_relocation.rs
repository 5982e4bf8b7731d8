//! The initialisation rounds chained on the GPU (`shaders/probe_relocation.wgsl`):
//! one volume's `probegi_field::device_plans::DeviceInitChain`, the host's
//! `ddgi_volume::init_rounds` with no result crossing to the host between
//! rounds. Each relocation round writes every probe's rays from where it is
//! (`init_chain_rays`), traces them (static geometry) and runs one iteration of
//! seed 004 Listing 4 (`init_chain_relocate`, mirroring
//! `probegi_core::probe_relocation::{probe_ray_stats, relocation_step}`; RTXGI
//! `ProbeRelocationCS`). A probe its iteration left in place leaves the rounds
//! (its rays get t_max −1) and, where a classification follows, its rays and
//! hits are kept: they are the classification's. After the last relocation
//! round the probes it moved trace once more and are kept (`init_chain_keep`),
//! and the classification (`probe_classification`) reads every pending probe
//! from the kept batch. Everything is recorded into the context's pending
//! submission; the caller reads the offsets back with the classification's
//! results, once.

use bytemuck::{Pod, Zeroable};
use probegi_field::device_plans::DeviceInitChain;

use crate::bvh_trace::{GpuBvh, GpuRayBatch, GpuRayTrace, dispatch_2d};
use crate::gpu_context::{GpuContext, GpuError};
use crate::shader_registry::PROBE_RELOCATION;

/// Must match `ChainParams` in `probe_relocation.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct ChainParams {
    pub(crate) spacing_m: [f32; 3],
    pub(crate) offset_limit_rel: f32,
    pub(crate) probe_count: u32,
    pub(crate) rays_per_probe: u32,
    pub(crate) groups_x: u32,
    pub(crate) ray_groups_x: u32,
    pub(crate) min_frontface_rel: f32,
    pub(crate) keep: u32,
    pub(crate) _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<ChainParams>() == 48);

/// The chain's pipelines: rays, relocation, keep.
pub struct GpuProbeRelocation {
    layout: wgpu::BindGroupLayout,
    rays: wgpu::ComputePipeline,
    relocate: wgpu::ComputePipeline,
    keep: wgpu::ComputePipeline,
}

/// One volume's chain once recorded: what the classification and the read-back use.
pub(crate) struct RecordedChain {
    /// Per probe: offset (xyz, m), w = rounds it traced.
    pub(crate) offsets: wgpu::Buffer,
    /// Per probe: its position after the rounds (xyz, m).
    pub(crate) positions: wgpu::Buffer,
    /// Each pending probe's rays and hits from where it ended, at probe × rays
    /// per probe (kept only where a classification follows).
    pub(crate) kept: GpuRayBatch,
    /// Relocation rounds recorded.
    pub(crate) relocation_rounds: u32,
    /// Rays each probe traces a round.
    pub(crate) rays_per_probe: u32,
}

impl GpuProbeRelocation {
    /// The pipelines on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("init rounds", &[false, true, true, true, false, false, false, false]);
        let [rays, relocate, keep] = ctx.compute_pipelines(
            &PROBE_RELOCATION,
            &[Some(&layout)],
            ["init_chain_rays", "init_chain_relocate", "init_chain_keep"],
        );
        Self { layout, rays, relocate, keep }
    }

    /// Records `chain`'s relocation rounds and, where it classifies, the
    /// trace of the probes the last round moved, into `ctx`'s submission.
    pub(crate) fn record_chain(
        &self,
        ctx: &GpuContext,
        trace: &GpuRayTrace,
        bvh: &GpuBvh,
        chain: &DeviceInitChain<'_>,
    ) -> Result<RecordedChain, GpuError> {
        let probes = chain.grid.probe_count() as u32;
        let n = chain.dirs.len() as u32;
        let rays = probes.checked_mul(n).filter(|r| (*r as usize) <= GpuRayTrace::max_batch_rays(ctx) && n > 0);
        let rays = rays.ok_or_else(|| GpuError::Input(format!("{probes} probes × {n} rays: not a batch here")))?;
        let keep = chain.classification.is_some();
        let round = trace.empty_batch(ctx, rays, false)?;
        // Threads in batch order, a probe's rays together: a workgroup of probes out
        // of the round ends at once (the probe-interleaved order would spread the
        // few probes still moving over every workgroup).
        round.configure(ctx, true, &[]);
        let kept = trace.empty_batch(ctx, if keep { rays } else { 1 }, false)?;
        let buffers = ChainBuffers::new(ctx, chain, &round, &kept, keep);
        let bind = crate::gpu_context::buffers_bind_group(ctx, "init rounds", &self.layout, &buffers.all);
        let per_probe = dispatch_2d(probes);
        let per_ray = dispatch_2d(rays);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        let pass = |encoder: &mut wgpu::CommandEncoder, pipeline: &wgpu::ComputePipeline, (x, y): (u32, u32)| {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(x, y, 1);
        };
        for _ in 0..chain.relocation_rounds {
            pass(&mut encoder, &self.rays, per_ray);
            trace.record(&mut encoder, bvh, &round, None);
            pass(&mut encoder, &self.relocate, per_probe);
        }
        if keep {
            pass(&mut encoder, &self.rays, per_ray);
            trace.record(&mut encoder, bvh, &round, None);
            pass(&mut encoder, &self.keep, per_probe);
        }
        ctx.submit(encoder.finish());
        let [_, _, _, _, _, offsets, positions, ..] = buffers.all;
        Ok(RecordedChain { offsets, positions, kept, relocation_rounds: chain.relocation_rounds, rays_per_probe: n })
    }
}

/// The chain's bind group, in binding order: parameters, the round's rays and
/// hits, directions, grid points, offsets, probes, kept rays and hits.
struct ChainBuffers {
    all: [wgpu::Buffer; 9],
}

impl ChainBuffers {
    fn new(ctx: &GpuContext, chain: &DeviceInitChain<'_>, round: &GpuRayBatch, kept: &GpuRayBatch, keep: bool) -> Self {
        let g = chain.grid;
        let probes = g.probe_count() as u32;
        let n = chain.dirs.len() as u32;
        let s = chain.settings;
        let params = ChainParams {
            spacing_m: g.spacing_m.into(),
            offset_limit_rel: s.probe_relocation_offset_limit_rel,
            probe_count: probes,
            rays_per_probe: n,
            groups_x: dispatch_2d(probes).0,
            ray_groups_x: dispatch_2d(probes * n).0,
            min_frontface_rel: s.probe_relocation_min_frontface_rel,
            keep: keep as u32,
            _pad: [0; 2],
        };
        let t_max = s.probe_max_ray_distance_m.min(f32::MAX);
        let grid_points: Vec<[f32; 4]> =
            (0..g.probe_count()).map(|p| g.probe_position(g.probe_coords(p)).extend(0.0).into()).collect();
        let offsets: Vec<[f32; 4]> = chain.offsets_m.iter().map(|o| o.extend(0.0).into()).collect();
        // Where each probe is, and its rays' t_max: −1 for a probe not pending (it traces no round).
        let positions: Vec<[f32; 4]> = (0..g.probe_count())
            .map(|p| {
                let position = g.probe_position(g.probe_coords(p)) + chain.offsets_m[p];
                position.extend(if chain.pending[p] { t_max } else { -1.0 }).into()
            })
            .collect();
        let dirs: Vec<[f32; 4]> = chain.dirs.iter().map(|d| d.extend(0.0).into()).collect();
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
        let all = [
            ctx.buffer_with("init params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM),
            round.rays_buffer().clone(),
            round.hits_buffer().clone(),
            ctx.buffer_with("init directions", bytemuck::cast_slice(&dirs), storage),
            ctx.buffer_with("init grid points", bytemuck::cast_slice(&grid_points), storage),
            ctx.buffer_with("init offsets", bytemuck::cast_slice(&offsets), storage),
            ctx.buffer_with("init probes", bytemuck::cast_slice(&positions), storage),
            kept.rays_buffer().clone(),
            kept.hits_buffer().clone(),
        ];
        Self { all }
    }
}
