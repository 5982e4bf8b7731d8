//! The classification round of seed 004's jcgt probe states on the GPU
//! (`shaders/probe_classification.wgsl`), mirroring `probegi_field::ddgi_volume`'s
//! `classify_jcgt_pending` with `probegi_core::probe_classification::{probe_watches,
//! uncovered_point_probe}`: per probe of one volume, whether it is inside geometry
//! and whether it is kept (it watches a front face, or the covering pass chose it
//! for a surface point no front-side cage probe served). The covering pass runs
//! one invocation at a time over chunks of probes (about 4096 rays each), in the
//! CPU's probe and ray order, so both backends keep the same probes (a single
//! invocation over the shared Sponza's 131 072 rays was cut short on lavapipe).
//! The rays and hits stay where the trace left them; the host reads back 16
//! bytes a probe.
//!
//! The round is the field's own plan (`probegi_field::device_plans::DeviceClassification`).
//! Its probes are packed into two rows each, not uploaded as they are:
//! `probegi_core::probe_classification::ClassificationProbe` holds an
//! `Option<u32>`, two `bool`s and a `Vec3`, which have no GPU layout.

use bytemuck::{Pod, Zeroable};
use probegi_field::device_plans::DeviceClassification;

use crate::bvh_trace::{GpuBvh, GpuRayBatch, bvh_bind_group_layout, dispatch_2d};
use crate::gpu_context::{GpuContext, GpuError};
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
    /// The covering pass's chunk: first probe and probe count.
    pub(crate) cover_first: u32,
    pub(crate) reach_rel: f32,
    pub(crate) bias_m: f32,
    pub(crate) cover_count: u32,
    pub(crate) _pad: f32,
}
const _: () = assert!(std::mem::size_of::<ClassifyParams>() == 80);

/// Rays one invocation of the covering pass walks per dispatch.
const COVER_CHUNK_RAYS: u32 = 4096;

/// The classification round's two pipelines (the first pass, the covering pass).
pub struct GpuProbeClassification {
    layout: wgpu::BindGroupLayout,
    first: wgpu::ComputePipeline,
    cover: wgpu::ComputePipeline,
}

impl GpuProbeClassification {
    /// Storage buffers per stage: its own 5, the BVH's and the scene's.
    pub const STORAGE_BUFFERS: u32 = 5 + BVH_STORAGE_BUFFERS + SCENE_STORAGE_BUFFERS;

    /// The pipelines on `ctx`; an error where the device binds too few storage buffers.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        ctx.check_pipeline(Self::STORAGE_BUFFERS, "the probe classification pass")?;
        let layout = ctx.pass_layout("probe classification", &[true, true, true, true, false]);
        let (bvh_layout, scene_layout) = (bvh_bind_group_layout(&ctx.device), scene_bind_group_layout(&ctx.device));
        let [first, cover] = ctx.compute_pipelines(
            &PROBE_CLASSIFICATION,
            &[Some(&layout), Some(&bvh_layout), None, Some(&scene_layout)],
            ["classify_first", "classify_cover"],
        );
        Ok(Self { first, cover, layout })
    }

    /// Per probe of `round` (the field's plan for one volume): (inside
    /// geometry, kept), from `batch`'s rays and hits.
    pub fn classify(
        &self,
        ctx: &GpuContext,
        bvh: &GpuBvh,
        scene: &GpuScene,
        batch: &GpuRayBatch,
        round: &DeviceClassification<'_>,
    ) -> Result<Vec<(bool, bool)>, GpuError> {
        let g = round.grid;
        let n = round.probes.len();
        if n != g.probe_count() {
            return Err(GpuError::Input(format!("{n} probes for a grid of {}", g.probe_count())));
        }
        if n == 0 {
            return Ok(vec![]);
        }
        for first in round.probes.iter().filter_map(|p| p.first_ray) {
            batch.check_rays(first, round.rays_per_probe)?;
        }
        let (gx, gy) = dispatch_2d(n as u32);
        let params = ClassifyParams {
            origin_m: g.origin_m.into(),
            probe_count: n as u32,
            spacing_m: g.spacing_m.into(),
            rays_per_probe: round.rays_per_probe,
            probe_counts: g.probe_counts.into(),
            groups_x: gx,
            scroll_offsets: g.probe_scroll_offsets.into(),
            cover_first: 0,
            reach_rel: round.reach_rel,
            bias_m: round.bias_m,
            cover_count: 0,
            _pad: 0.0,
        };
        // The covering pass in chunks of about COVER_CHUNK_RAYS rays, in probe order.
        let chunk = (COVER_CHUNK_RAYS / round.rays_per_probe.max(1)).max(1);
        let chunks: Vec<ClassifyParams> = (0..(n as u32).div_ceil(chunk))
            .map(|c| ClassifyParams { cover_first: c * chunk, cover_count: chunk, ..params })
            .collect();
        let rows: Vec<[u32; 4]> = round
            .probes
            .iter()
            .map(|p| [p.first_ray.unwrap_or(u32::MAX), p.pending as u32, p.traces as u32, 0])
            .collect();
        let positions: Vec<[f32; 4]> = round.probes.iter().map(|p| p.position_m.extend(0.0).into()).collect();
        let storage = wgpu::BufferUsages::STORAGE;
        let params = ctx.buffer_with("classify params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let rows = ctx.buffer_with("classify probes", bytemuck::cast_slice(&rows), storage);
        let positions = ctx.buffer_with("classify positions", bytemuck::cast_slice(&positions), storage);
        let out = ctx.output_buffer("classify out", n as u64 * 16);
        let bind = |params: wgpu::Buffer| {
            let buffers = [params, batch.rays_buffer().clone(), batch.hits_buffer().clone()];
            let buffers = [buffers.as_slice(), &[rows.clone(), positions.clone(), out.clone()]].concat();
            crate::gpu_context::buffers_bind_group(&ctx.device, "probe classification", &self.layout, &buffers)
        };
        let mut bind_groups = vec![bind(params)];
        for c in &chunks {
            let p = ctx.buffer_with("classify cover params", bytemuck::bytes_of(c), wgpu::BufferUsages::UNIFORM);
            bind_groups.push(bind(p));
        }
        // The first pass, then the covering pass chunk after chunk (each reads what
        // the steps before it wrote).
        let steps: Vec<_> = bind_groups
            .iter()
            .enumerate()
            .map(|(k, g)| {
                let (pipeline, groups) = if k == 0 { (&self.first, (gx, gy)) } else { (&self.cover, (1, 1)) };
                let mut bind = vec![Some(g), None, None, None];
                bind[BVH_GROUP as usize] = Some(bvh.bind_group());
                bind[SCENE_GROUP as usize] = Some(scene.bind_group());
                (pipeline, bind, groups)
            })
            .collect();
        ctx.run_passes("probe classification", &steps);
        let bytes = ctx.read_back(&out)?;
        let v: &[[u32; 4]] = bytemuck::cast_slice(&bytes);
        Ok(v.iter().take(n).map(|o| (o[0] != 0, o[1] != 0)).collect())
    }
}
