//! The classification round of seed 004's jcgt probe states on the GPU
//! (`shaders/probe_classification.wgsl`), mirroring `probegi_field::ddgi_volume`'s
//! `classify_jcgt_pending` with `probegi_core::probe_classification::{probe_watches,
//! uncovered_point_probe}`: per probe of one volume, whether it is inside geometry
//! and whether it is kept (it watches a front face, or the covering pass chose it
//! for a surface point no front-side cage probe served). The covering pass is
//! `probegi_core::probe_classification::cover_proposals`: a list of proposals
//! (one thread per ray), then [`COVER_ITERATIONS`] Jacobi rounds of the greedy
//! pass's recursion (two dispatches each, the per-point one dispatched
//! indirectly over the list), the keepers marked, a fix-up; every step an
//! atomic minimum or an idempotent flag, so both backends keep the same probes. (It
//! replaced one invocation walking every ray in order, the likely cause of an
//! 11.5 s start-up at 32³ probes on an H200.) It is the last step of the
//! initialisation chain (`probe_relocation`): the rays and hits are the
//! chain's kept ones, the positions where its relocation left the probes, and
//! the host reads back 16 bytes a probe with the chain's offsets.
//!
//! The round is the field's own plan (`probegi_field::device_plans::DeviceClassification`).
//! Its probes are packed into a row each, not uploaded as they are:
//! `probegi_core::probe_classification::ClassificationProbe` holds an
//! `Option<u32>` and two `bool`s, which have no GPU layout.

use bytemuck::{Pod, Zeroable};
use probegi_core::probe_classification::COVER_ITERATIONS;
use probegi_field::device_plans::DeviceClassification;

use crate::bvh_trace::{GpuBvh, GpuRayBatch, bvh_bind_group_layout, dispatch_2d};
use crate::gpu_context::{Dispatch, GpuContext, GpuError};
use crate::gpu_scene::{GpuScene, scene_bind_group_layout};
use crate::shader_registry::{
    BVH_GROUP, BVH_STORAGE_BUFFERS, PROBE_CLASSIFICATION, SCENE_GROUP, SCENE_STORAGE_BUFFERS,
};

/// Must match `ClassifyParams` in `probe_classification.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct ClassifyParams {
    pub(crate) origin_m: [f32; 3],
    pub(crate) probe_count: u32,
    pub(crate) spacing_m: [f32; 3],
    pub(crate) rays_per_probe: u32,
    pub(crate) probe_counts: [u32; 3],
    pub(crate) groups_x: u32,
    pub(crate) scroll_offsets: [u32; 3],
    /// The Jacobi round of `classify_clear` / `classify_round` (its parity picks the keeper arrays).
    pub(crate) cover_round: u32,
    pub(crate) reach_rel: f32,
    pub(crate) bias_m: f32,
    /// Rounds run: `classify_mark` reads the last round's keeper array.
    pub(crate) cover_rounds: u32,
    /// Threads of the per-ray passes: probes × rays per probe.
    pub(crate) ray_threads: u32,
    /// Workgroups along x of the per-ray passes.
    pub(crate) ray_groups_x: u32,
    pub(crate) _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<ClassifyParams>() == 96);

/// The classification round's pipelines: the first pass, then the covering
/// pass's proposals, rounds (clear, round), marks and fix-up.
pub struct GpuProbeClassification {
    layout: wgpu::BindGroupLayout,
    first: wgpu::ComputePipeline,
    propose: wgpu::ComputePipeline,
    args: wgpu::ComputePipeline,
    clear: wgpu::ComputePipeline,
    round: wgpu::ComputePipeline,
    mark: wgpu::ComputePipeline,
    fixup: wgpu::ComputePipeline,
}

impl GpuProbeClassification {
    /// Storage buffers per stage: its own 7, the BVH's and the scene's.
    pub const STORAGE_BUFFERS: u32 = 7 + BVH_STORAGE_BUFFERS + SCENE_STORAGE_BUFFERS;

    /// The pipelines on `ctx`; an error where the device binds too few storage buffers.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        ctx.check_pipeline(Self::STORAGE_BUFFERS, "the probe classification pass")?;
        let layout = ctx.pass_layout("probe classification", &[true, true, true, true, false, false, false]);
        let (bvh_layout, scene_layout) = (bvh_bind_group_layout(&ctx.device), scene_bind_group_layout(&ctx.device));
        let [first, propose, args, clear, round, mark, fixup] = ctx.compute_pipelines(
            &PROBE_CLASSIFICATION,
            &[Some(&layout), Some(&bvh_layout), None, Some(&scene_layout)],
            [
                "classify_first",
                "classify_propose",
                "classify_args",
                "classify_clear",
                "classify_round",
                "classify_mark",
                "classify_fixup",
            ],
        );
        Ok(Self { layout, first, propose, args, clear, round, mark, fixup })
    }

    /// Records the classification of `round` (the field's plan for one
    /// volume) from `batch`'s rays and hits, with each probe's position read
    /// from `positions` (xyz per probe: where the chain's relocation left it),
    /// into `ctx`'s submission. Returns the buffer to read back with
    /// [`classification_results`] (16 bytes a probe).
    pub(crate) fn record(
        &self,
        ctx: &GpuContext,
        (bvh, scene): (&GpuBvh, &GpuScene),
        batch: &GpuRayBatch,
        round: &DeviceClassification<'_>,
        positions: &wgpu::Buffer,
    ) -> Result<wgpu::Buffer, GpuError> {
        let n = round.probes.len();
        if n != round.grid.probe_count() {
            return Err(GpuError::Input(format!("{n} probes for a grid of {}", round.grid.probe_count())));
        }
        for first in round.probes.iter().filter_map(|p| p.first_ray) {
            batch.check_rays(first, round.rays_per_probe)?;
        }
        let params = classify_params(round)?;
        let b = ClassifyBuffers::new(ctx, round, positions.clone());
        let bind = |p: &ClassifyParams| {
            let params = ctx.buffer_with("classify params", bytemuck::bytes_of(p), wgpu::BufferUsages::UNIFORM);
            let buffers = [params, batch.rays_buffer().clone(), batch.hits_buffer().clone()];
            let own = [b.rows.clone(), b.positions.clone(), b.out.clone(), b.list.clone(), b.keepers.clone()];
            let buffers = [buffers.as_slice(), &own].concat();
            crate::gpu_context::buffers_bind_group(ctx, "probe classification", &self.layout, &buffers)
        };
        let base = bind(&params);
        let rounds: Vec<wgpu::BindGroup> =
            (0..COVER_ITERATIONS).map(|k| bind(&ClassifyParams { cover_round: k, ..params })).collect();
        // The first pass, the proposals, the rounds (each reads what the step
        // before it wrote), the marks and the fix-up.
        let per_probe = || Dispatch::Groups(params.groups_x, dispatch_2d(n as u32).1);
        let listed = || Dispatch::Indirect { args: &b.list, offset: 0, via: &b.indirect };
        let per_ray = Dispatch::Groups(params.ray_groups_x, dispatch_2d(params.ray_threads).1);
        let mut order = vec![
            (&self.first, &base, per_probe()),
            (&self.propose, &base, per_ray),
            (&self.args, &base, Dispatch::Groups(1, 1)),
        ];
        for g in &rounds {
            order.push((&self.clear, g, per_probe()));
            order.push((&self.round, g, listed()));
        }
        order.push((&self.mark, &base, per_probe()));
        order.push((&self.fixup, &base, listed()));
        let steps: Vec<_> = order
            .into_iter()
            .map(|(pipeline, g, dispatch)| {
                let mut bind = vec![Some(g), None, None, None];
                bind[BVH_GROUP as usize] = Some(bvh.bind_group());
                bind[SCENE_GROUP as usize] = Some(scene.bind_group());
                (pipeline, bind, dispatch)
            })
            .collect();
        ctx.run_dispatches("probe classification", &steps);
        Ok(b.out)
    }
}

/// Per probe (inside geometry, kept) from the bytes of the buffer
/// [`GpuProbeClassification::record`] returned.
pub(crate) fn classification_results(bytes: &[u8], probes: usize) -> Vec<(bool, bool)> {
    let v: &[[u32; 4]] = bytemuck::cast_slice(bytes);
    v.iter().take(probes).map(|o| (o[0] != 0, o[1] != 0 || o[3] != 0)).collect()
}

/// The round's uniform block (the covering rounds differ only in `cover_round`);
/// an error where its per-ray threads overflow a `u32`.
fn classify_params(round: &DeviceClassification<'_>) -> Result<ClassifyParams, GpuError> {
    let (g, n) = (round.grid, round.probes.len() as u32);
    let ray_threads = n
        .checked_mul(round.rays_per_probe)
        .ok_or_else(|| GpuError::Input(format!("{n} probes × {} rays overflow a u32", round.rays_per_probe)))?;
    Ok(ClassifyParams {
        origin_m: g.origin_m.into(),
        probe_count: n,
        spacing_m: g.spacing_m.into(),
        rays_per_probe: round.rays_per_probe,
        probe_counts: g.probe_counts.into(),
        groups_x: dispatch_2d(n).0,
        scroll_offsets: g.probe_scroll_offsets.into(),
        cover_round: 0,
        reach_rel: round.reach_rel,
        bias_m: round.bias_m,
        cover_rounds: COVER_ITERATIONS,
        ray_threads,
        ray_groups_x: dispatch_2d(ray_threads).0,
        _pad: [0; 3],
    })
}

/// The round's own buffers: its probes packed in a row (first ray, pending,
/// traces), their positions (the chain's), the per-probe output, the proposal list with its
/// indirect workgroups, and the two keeper arrays.
struct ClassifyBuffers {
    rows: wgpu::Buffer,
    positions: wgpu::Buffer,
    out: wgpu::Buffer,
    list: wgpu::Buffer,
    indirect: wgpu::Buffer,
    keepers: wgpu::Buffer,
}

impl ClassifyBuffers {
    fn new(ctx: &GpuContext, round: &DeviceClassification<'_>, positions: wgpu::Buffer) -> Self {
        let n = round.probes.len() as u64;
        let rows: Vec<[u32; 4]> = round
            .probes
            .iter()
            .map(|p| [p.first_ray.unwrap_or(u32::MAX), p.pending as u32, p.traces as u32, 0])
            .collect();
        // At most one proposal a traced ray: sized by the rays the round traced.
        let traced_rays =
            round.probes.iter().filter(|p| p.first_ray.is_some()).count() as u64 * round.rays_per_probe as u64;
        let storage = wgpu::BufferUsages::STORAGE;
        let buffer = |label, size, usage| {
            ctx.create_buffer(&wgpu::BufferDescriptor { label: Some(label), size, usage, mapped_at_creation: false })
        };
        Self {
            rows: ctx.buffer_with("classify probes", bytemuck::cast_slice(&rows), storage),
            positions,
            out: ctx.output_buffer("classify out", n * 16),
            // Indirect workgroups, count, then (ray, probe) per proposal.
            list: buffer("classify proposals", (4 + 2 * traced_rays) * 4, storage | wgpu::BufferUsages::COPY_SRC),
            indirect: buffer("classify indirect", 16, wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST),
            keepers: ctx.output_buffer("classify keepers", 2 * n * 4),
        }
    }
}
