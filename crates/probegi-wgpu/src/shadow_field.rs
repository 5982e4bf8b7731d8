//! The shadowing field's update on the device (`shaders/shadow_field.wgsl`,
//! seed 003 §5.1–5.2), the twin of `probegi_field`'s `ddgi_volume::shadow_rays`:
//! from the hits of the previous frame's update batch, which the device kept,
//! one shadow ray per served light from every front-face surfel (the two-frame
//! ray generation of Fig. 5.2), traced any-hit through `bvh.wgsl`, then eq.
//! 5.2–5.3 into the occlusion maps the resident field holds after its distance
//! atlases, and their borders. The host uploads per frame the volume's
//! `probegi_field::device_plans::DeviceShadowBlend`: 32 bytes per blending
//! probe, 16 per light, and the texel directions; nothing comes back.
//!
//! Surfels are found here as on the host (`origin + dir·t`, the facing shading
//! normal of `scene.wgsl`), so on an adapter whose hits equal the CPU's the
//! maps agree with the CPU's to float rounding (`tests/it/shadow_field_equivalence.rs`).

use bytemuck::{Pod, Zeroable};
use probegi_core::octahedral::{oct_decode, texel_center_uv};
use probegi_field::device_plans::DeviceShadowBlend;
use probegi_scene::LightKind;

use crate::bvh_trace::{GpuBvh, GpuRayBatch, GpuRayTrace, bvh_bind_group_layout, dispatch_2d};
use crate::gpu_context::{GpuContext, GpuError};
use crate::gpu_scene::{GpuScene, scene_bind_group_layout};
use crate::shader_registry::{BVH_GROUP, BVH_STORAGE_BUFFERS, SCENE_GROUP, SCENE_STORAGE_BUFFERS, SHADOW_FIELD};

/// Must match `ShadowParams` in `shadow_field.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct ShadowParams {
    pub(crate) entry_count: u32,
    pub(crate) light_count: u32,
    pub(crate) slot_count: u32,
    pub(crate) groups_x: u32,
    pub(crate) interior: u32,
    pub(crate) occlusion_first: u32,
    pub(crate) surfel_reach_m: f32,
    pub(crate) _pad: u32,
}
const _: () = assert!(std::mem::size_of::<ShadowParams>() == 32);

/// One probe that blends this frame from its previous-frame rays; must match
/// `ShadowProbe` in `shadow_field.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct ShadowProbe {
    pub(crate) prev_first_ray: u32,
    pub(crate) ray_count: u32,
    pub(crate) probe: u32,
    pub(crate) first_slot: u32,
    pub(crate) hysteresis: f32,
    pub(crate) _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<ShadowProbe>() == 32);

/// Where a volume's occlusion maps lie in the resident field: the distance
/// buffer, from texel `first`, `interior`² texels inside each tile.
pub struct OcclusionTarget<'a> {
    /// The field's distance buffer (`GpuDdgiField`).
    pub buffer: &'a wgpu::Buffer,
    /// The volume's first occlusion texel (a `vec2<f32>`, visibility in x).
    pub first: u32,
    /// Interior texels per tile side.
    pub interior: u32,
    /// Tiles (the volume's probes).
    pub probes: u32,
}

/// The shadowing field's pipelines (ray generation, blend, border).
pub struct GpuShadowField {
    layout: wgpu::BindGroupLayout,
    pipelines: [wgpu::ComputePipeline; 3],
}

impl GpuShadowField {
    /// Storage buffers per stage: its own 8, the BVH's and the scene's.
    pub const STORAGE_BUFFERS: u32 = 8 + BVH_STORAGE_BUFFERS + SCENE_STORAGE_BUFFERS;

    /// The pipelines on `ctx`; an error where the device binds too few storage buffers.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        ctx.check_pipeline(Self::STORAGE_BUFFERS, "the shadowing field's passes")?;
        let layout = ctx.pass_layout("shadow field", &[true, true, true, true, false, false, true, false]);
        let (bvh, scene) = (bvh_bind_group_layout(&ctx.device), scene_bind_group_layout(&ctx.device));
        let pipelines = ctx.compute_pipelines(
            &SHADOW_FIELD,
            &[Some(&layout), Some(&bvh), None, Some(&scene)],
            ["generate_shadow_rays", "blend_shadow_maps", "border_shadow_maps"],
        );
        Ok(Self { layout, pipelines })
    }

    /// One volume's update by `plan` from `prev` (the kept batch its first rays
    /// refer to) into `target`.
    #[allow(clippy::too_many_arguments)]
    pub fn update(
        &self,
        ctx: &GpuContext,
        trace: &GpuRayTrace,
        bvh: &GpuBvh,
        scene: &GpuScene,
        prev: &GpuRayBatch,
        plan: &DeviceShadowBlend,
        target: &OcclusionTarget<'_>,
    ) -> Result<(), GpuError> {
        let lights = plan.lights.len() as u32;
        if lights == 0 || plan.probes.is_empty() {
            return Ok(());
        }
        let (entries, slots) = shadow_entries(plan, prev, target)?;
        if slots > GpuRayTrace::max_batch_rays(ctx) as u64 {
            return Err(GpuError::Input(format!("{slots} shadow rays exceed one batch")));
        }
        let shadow = trace.empty_batch(ctx, slots as u32, true)?;
        let (gx, gy) = dispatch_2d(slots as u32);
        let (ex, ey) = dispatch_2d(entries.len() as u32 * 64);
        let params = |groups_x| ShadowParams {
            entry_count: entries.len() as u32,
            light_count: lights,
            slot_count: slots as u32,
            groups_x,
            interior: target.interior,
            occlusion_first: target.first,
            surfel_reach_m: plan.surfel_reach_m,
            _pad: 0,
        };
        let storage = wgpu::BufferUsages::STORAGE;
        let table = ctx.buffer_with("shadow probes", bytemuck::cast_slice(&entries), storage);
        let light_rows = light_rows(plan, target.interior);
        let light_rows = ctx.buffer_with("shadow lights", bytemuck::cast_slice(&light_rows), storage);
        let slot_rows = ctx.output_buffer("shadow slots", slots * 16);
        let bind = |p: ShadowParams| {
            let p = ctx.buffer_with("shadow params", bytemuck::bytes_of(&p), wgpu::BufferUsages::UNIFORM);
            let buffers = [
                p,
                prev.rays_buffer().clone(),
                prev.hits_buffer().clone(),
                table.clone(),
                light_rows.clone(),
                shadow.rays_buffer().clone(),
                slot_rows.clone(),
                shadow.hits_buffer().clone(),
                target.buffer.clone(),
            ];
            crate::gpu_context::buffers_bind_group(ctx, "shadow field", &self.layout, &buffers)
        };
        let (gen_group, blend_group) = (bind(params(gx)), bind(params(ex)));
        let groups = |g| {
            let mut b = vec![Some(g), None, None, None];
            b[BVH_GROUP as usize] = Some(bvh.bind_group());
            b[SCENE_GROUP as usize] = Some(scene.bind_group());
            b
        };
        ctx.run_passes("shadow rays", &[(&self.pipelines[0], groups(&gen_group), (gx, gy))]);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        trace.record(&mut encoder, bvh, &shadow, None);
        ctx.submit(encoder.finish());
        ctx.run_passes(
            "shadow blend",
            &[
                (&self.pipelines[1], groups(&blend_group), (ex, ey)),
                (&self.pipelines[2], groups(&blend_group), (ex, ey)),
            ],
        );
        Ok(())
    }
}

/// The pass's per-probe table from `plan` (each probe's slots follow the ones
/// before it, `lights` per previous-frame ray) and the slot count; an error for
/// a ray range outside `prev` or a probe outside `target`.
fn shadow_entries(
    plan: &DeviceShadowBlend,
    prev: &GpuRayBatch,
    target: &OcclusionTarget<'_>,
) -> Result<(Vec<ShadowProbe>, u64), GpuError> {
    let lights = plan.lights.len() as u64;
    let mut entries = Vec::with_capacity(plan.probes.len());
    let mut slots = 0u64;
    for &(probe, first, count, h) in &plan.probes {
        prev.check_rays(first, count)?;
        if probe >= target.probes {
            return Err(GpuError::Input(format!("shadow probe {probe} of {} tiles", target.probes)));
        }
        let first_slot = u32::try_from(slots).map_err(|_| GpuError::Input("too many shadow rays".into()))?;
        entries.push(ShadowProbe {
            prev_first_ray: first,
            ray_count: count,
            probe,
            first_slot,
            hysteresis: h,
            _pad: [0; 3],
        });
        slots += count as u64 * lights;
    }
    Ok((entries, slots))
}

/// The lights buffer: per light (position, or the direction of travel, in xyz;
/// w's bits 1 for a point or spot light, 0 for a directional one), then the
/// occlusion texels' unit directions, as the CPU's blend decodes them.
fn light_rows(plan: &DeviceShadowBlend, interior: u32) -> Vec<[f32; 4]> {
    let mut rows: Vec<[f32; 4]> = plan
        .lights
        .iter()
        .map(|l| match l.kind {
            LightKind::Directional => [l.direction.x, l.direction.y, l.direction.z, f32::from_bits(0)],
            _ => [l.position.x, l.position.y, l.position.z, f32::from_bits(1)],
        })
        .collect();
    for j in 0..interior {
        for i in 0..interior {
            rows.push(oct_decode(texel_center_uv(i, j, interior)).extend(0.0).into());
        }
    }
    rows
}
