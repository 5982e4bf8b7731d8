//! Seeding new probes on the device (`shaders/probe_seeding.wgsl`), the twin
//! of `probegi_field::probe_seeding::apply_seeds`: when the device holds the
//! field, the seeds the host planned at a scroll
//! (`probegi_field::device_plans::DeviceVolumeBlend::seeds`) are mixed in the
//! resident atlases after the reset tiles are cleared and before any blend.
//! One thread per texel per seed.

use bytemuck::{Pod, Zeroable};
use probegi_core::probe_atlas::tile_texel_count;
use probegi_field::probe_seeding::ProbeSeed;

use crate::gpu_context::{GpuContext, GpuError};
use crate::probe_blend::GpuVolumeAtlases;
use crate::shader_registry::PROBE_SEEDING;

/// Must match `SeedParams` in `probe_seeding.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct SeedParams {
    seed_count: u32,
    groups_x: u32,
    _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<SeedParams>() == 16);

/// Must match `SeedEntry` in `probe_seeding.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct SeedEntry {
    dest: [u32; 4],
    source_irradiance: [u32; 8],
    source_distance: [u32; 8],
    weights: [f32; 8],
    encoding: [f32; 4],
    position: [f32; 4],
    source_positions: [[f32; 4]; 8],
}
const _: () = assert!(std::mem::size_of::<SeedEntry>() == 272);

/// Largest dispatch dimension (WebGPU's default limit).
const MAX_GROUPS: usize = 65_535;

/// The seeding pass's pipeline.
pub struct GpuProbeSeeding {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl GpuProbeSeeding {
    /// The pipeline on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("probe seeding", &[true, false, false]);
        let [pipeline] = ctx.compute_pipelines(&PROBE_SEEDING, &[Some(&layout)], ["seed_tiles"]);
        Self { layout, pipeline }
    }

    /// Mixes `seeds` into the tiles of `target`, from the volumes `source(i)`
    /// gives (the same resident buffers), encoding irradiance with `gamma`.
    pub fn seed(
        &self,
        ctx: &GpuContext,
        target: &GpuVolumeAtlases,
        source: impl Fn(usize) -> Option<GpuVolumeAtlases>,
        seeds: &[ProbeSeed],
        gamma: f32,
    ) -> Result<(), GpuError> {
        let irr_len = tile_texel_count(target.irradiance_interior) as u32;
        let dist_len = tile_texel_count(target.distance_interior) as u32;
        let mut entries = Vec::with_capacity(seeds.len());
        for s in seeds {
            let src = source(s.source_volume as usize)
                .ok_or_else(|| GpuError::Input(format!("seed source volume {} is not resident", s.source_volume)))?;
            let same = src.irradiance_interior == target.irradiance_interior
                && src.distance_interior == target.distance_interior
                && src.irradiance == target.irradiance
                && src.distance == target.distance;
            if !same
                || s.probe as usize >= target.probe_count
                || s.source_probes.iter().any(|&q| q as usize >= src.probe_count)
            {
                return Err(GpuError::Input("a seed's tiles do not match the resident field".into()));
            }
            let mut e = SeedEntry {
                dest: [
                    target.irradiance_first + s.probe * irr_len,
                    target.distance_first + s.probe * dist_len,
                    irr_len,
                    dist_len,
                ],
                weights: s.weights,
                encoding: [gamma, target.distance_interior as f32, 0.0, 0.0],
                position: s.position_m.extend(0.0).to_array(),
                source_positions: s.source_positions_m.map(|p| p.extend(0.0).to_array()),
                ..Default::default()
            };
            for (i, &q) in s.source_probes.iter().enumerate() {
                e.source_irradiance[i] = src.irradiance_first + q * irr_len;
                e.source_distance[i] = src.distance_first + q * dist_len;
            }
            entries.push(e);
        }
        let groups_x = irr_len.max(dist_len).div_ceil(64);
        for chunk in entries.chunks(MAX_GROUPS) {
            let params = SeedParams { seed_count: chunk.len() as u32, groups_x, _pad: [0; 2] };
            let params = ctx.buffer_with("seed params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
            let list = ctx.buffer_with("seeds", bytemuck::cast_slice(chunk), wgpu::BufferUsages::STORAGE);
            let buffers = [params, list, target.irradiance.clone(), target.distance.clone()];
            let bind_group = crate::gpu_context::buffers_bind_group(ctx, "probe seeding", &self.layout, &buffers);
            ctx.run_passes(
                "probe seeding",
                &[(&self.pipeline, vec![Some(&bind_group)], (groups_x, chunk.len() as u32))],
            );
        }
        Ok(())
    }
}
