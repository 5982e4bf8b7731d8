//! The shade pass of the probe rays on the GPU (`shaders/probe_shade.wgsl` over
//! `scene.wgsl`, `bvh.wgsl` and `ddgi_query.wgsl`), mirroring
//! `probegi_cpu::probe_shade::shade_probe_rays`: sky for misses, zero for back
//! faces, direct light (punctual lights with shadow rays, emitters by stratified
//! NEE with `probe_area_light_samples`), diffuse albedo/π × the set's previous
//! irradiance, and second-order glossy where the volume enables it. It reads the
//! trace pass's rays and hits where they lie on the device ([`GpuRayBatch`]).
//!
//! *Deviation:* random numbers come from a PCG hash per ray, not the CPU's PCG32
//! stream per probe, so area-light estimates agree with the CPU's in
//! distribution, not bit for bit (`probegi-wgpu/tests/it/field_equivalence.rs`).

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

use crate::bvh_trace::{GpuBvh, GpuRayBatch, bvh_bind_group_layout, dispatch_2d};
use crate::ddgi_query::GpuDdgiField;
use crate::gpu_context::{GpuContext, GpuError};
use crate::gpu_scene::{GpuScene, scene_bind_group_layout};
use crate::shader_registry::{
    BVH_GROUP, BVH_STORAGE_BUFFERS, FIELD_GROUP, FIELD_STORAGE_BUFFERS, PASS_GROUP, PROBE_SHADE, SCENE_GROUP,
    SCENE_STORAGE_BUFFERS,
};

/// The shade pass's uniform block; must match `ShadeParams` in `probe_shade.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct ShadeParams {
    pub(crate) ray_count: u32,
    pub(crate) groups_x: u32,
    pub(crate) seed: u32,
    pub(crate) frame: u32,
    pub(crate) probe_count: u32,
    pub(crate) _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<ShadeParams>() == 32);

/// One probe's rays in a shade pass and its shading flags ([`shade_info`]):
/// the pass reads flags per probe, so a frame uploads 16 bytes a probe, not 4
/// a ray. Must match `ShadeProbe` in `probe_shade.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct ShadeProbe {
    /// The probe's first ray in the batch; probes are given in increasing order of it.
    pub first_ray: u32,
    /// The probe's rays, consecutive from `first_ray`.
    pub ray_count: u32,
    /// The rays' shading flags ([`shade_info`]).
    pub info: u32,
    /// The bits of the `f32` length (m) of `probe_hit_ao_radius_rel`'s ray at
    /// each front hit (`probegi_cpu::probe_shade::hit_ao`); 0: no AO.
    pub hit_ao_radius_bits: u32,
}
const _: () = assert!(std::mem::size_of::<ShadeProbe>() == 16);

/// The shade pass's per-probe records as [`GpuProbeShade::shade_on_device`]
/// takes them: `count` records, made by `records` only where the device
/// does not hold them already, and each probe's radiance flag apart. With
/// `ids` (a kept plan's: one plan id per volume of the batch,
/// `GeneratedProbeRays::plan_id`), records last written under the same ids
/// stand, and `records` is not called. The flags move where the records do
/// not (the usage scheme's states, a sleeping probe's phase), so they go up
/// on their own: one bit a probe ([`radiance_bits`]), kept while
/// `radiance_id` repeats (`ProbeRayBatch::probe_needs_radiance_id`).
pub struct ShadeProbes<'a> {
    /// How many records there are.
    pub count: usize,
    /// The records' identity, where they have one.
    pub ids: Option<&'a [u64]>,
    /// Makes the records (their `info` without the radiance flag, bit 31;
    /// a flag set there still counts).
    pub records: &'a dyn Fn() -> Vec<ShadeProbe>,
    /// Per record, whether its probe's radiance is needed (past the end: not).
    pub radiance: &'a [bool],
    /// The flags' identity, where they have one (equal ids, equal flags).
    pub radiance_id: Option<u64>,
}

/// The fewest words [`GpuProbeShade::shade_on_device`] uploads the radiance
/// flags in (256 bytes: 2 048 probes). A batch whose size moves (the screen
/// scheme's) then keeps one flag buffer from its first frame: a kept buffer
/// serves smaller needs for a while (`GpuContext::buffer_rewritten`), but one
/// made at a few words would grow, making a buffer, in whichever frame first
/// brought more probes; past the floor the flags move with the count as the
/// records do.
pub const SHADE_RADIANCE_WORDS_MIN: usize = 64;

/// One bit per record of `flags` (record k: bit k % 32 of word k / 32), as
/// `probe_shade.wgsl` reads `shade_probe_radiance`; at least one word.
pub fn radiance_bits(flags: &[bool], count: usize) -> Vec<u32> {
    let mut words = vec![0u32; count.div_ceil(32).max(1)];
    for (k, _) in flags.iter().take(count).enumerate().filter(|(_, f)| **f) {
        words[k / 32] |= 1 << (k % 32);
    }
    words
}

/// Shading flags of `probe_shade.wgsl`'s `ShadeProbe::info`: whether the
/// probe's radiance is needed (bit 31), second-order glossy (bit 30), the
/// sky-map samples (bits 16..26; `probe_sky_light_samples`, at most 1024) and
/// the area-light samples (low 16 bits).
pub fn shade_info(needs_radiance: bool, glossy_second_order: bool, area_samples: u32, sky_samples: u32) -> u32 {
    (needs_radiance as u32) << 31
        | (glossy_second_order as u32) << 30
        | sky_samples.min(SHADE_SKY_SAMPLES_MAX) << 16
        | area_samples.min(0xffff)
}

/// [`shade_info`]'s flag (bit 29): punctual lights' visibility from the
/// shadowing field (`shadow_field_probe_shading`) instead of shadow rays.
pub const SHADE_SHADOW_FIELD: u32 = 1 << 29;

/// The most sky-map samples [`shade_info`] holds (bits 16..26).
pub const SHADE_SKY_SAMPLES_MAX: u32 = 0x7ff;

/// [`shade_info`]'s flag (bit 27): the hit AO's occluded rays carry the
/// occluder's radiance (`probe_hit_ao_near_field`).
pub const SHADE_HIT_AO_NEAR_FIELD: u32 = 1 << 27;

/// [`shade_info`]'s flag (bit 28): misses read the sky map
/// (`probe_sky_map_on_miss`; the hits then take no sky samples).
pub const SHADE_SKY_MAP_ON_MISS: u32 = 1 << 28;

/// The [`ShadeProbe`] records of a seam batch: each probe's rays, flagged as
/// needing radiance where `batch.probe_needs_radiance` says so, with its
/// volume's glossy and area-light settings.
pub fn batch_shade_probes(
    batch: &probegi_field::seam::ProbeRayBatch,
    volumes: &[probegi_field::ddgi_volume::DdgiVolume],
) -> Vec<ShadeProbe> {
    let mut records = batch_shade_records(batch, volumes);
    for (r, _) in records.iter_mut().zip(&batch.probe_needs_radiance).filter(|(_, needed)| **needed) {
        r.info |= shade_info(true, false, 0, 0);
    }
    records
}

/// [`batch_shade_probes`] without the radiance flags (which
/// [`ShadeProbes::radiance`] carries apart): what stays while a kept plan's
/// probes keep their rays and volumes.
pub fn batch_shade_records(
    batch: &probegi_field::seam::ProbeRayBatch,
    volumes: &[probegi_field::ddgi_volume::DdgiVolume],
) -> Vec<ShadeProbe> {
    // Per volume once: its flags and its hit-AO reach.
    let per_volume: Vec<(u32, u32)> =
        volumes.iter().map(|v| (volume_shade_info(false, &v.settings), hit_ao_radius_m(v).to_bits())).collect();
    batch
        .probes
        .iter()
        .map(|bp| {
            let (info, hit_ao_radius_bits) = per_volume[bp.volume as usize];
            ShadeProbe { first_ray: bp.first_ray, ray_count: bp.ray_count, info, hit_ao_radius_bits }
        })
        .collect()
}

/// [`shade_info`] and its flags for a probe of a volume of settings `s`:
/// glossy, area and sky-map samples (none where the misses read the map; the
/// shader takes none without a map), the shadowing field, the misses' map.
pub fn volume_shade_info(needs_radiance: bool, s: &probegi_core::ddgi_settings::DdgiVolumeSettings) -> u32 {
    let sky_samples = if s.probe_sky_map_on_miss { 0 } else { s.probe_sky_light_samples };
    shade_info(needs_radiance, s.glossy_second_order, s.probe_area_light_samples, sky_samples)
        | if s.shadow_field && s.shadow_field_probe_shading { SHADE_SHADOW_FIELD } else { 0 }
        | if s.probe_sky_map_on_miss { SHADE_SKY_MAP_ON_MISS } else { 0 }
        | if s.probe_hit_ao_near_field { SHADE_HIT_AO_NEAR_FIELD } else { 0 }
}

/// The length of `volume`'s hit-AO rays (`probe_hit_ao_radius_rel` × its
/// smallest spacing; 0: off), as `probegi_cpu::probe_shade` takes it.
pub fn hit_ao_radius_m(volume: &probegi_field::ddgi_volume::DdgiVolume) -> f32 {
    volume.settings.probe_hit_ao_radius_rel * volume.grid.min_spacing_m()
}

/// The shade pass's pipeline (`probe_shade.wgsl` with the BVH, the field and
/// the scene in their groups, `shader_registry`).
pub struct GpuProbeShade {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl GpuProbeShade {
    /// Storage buffers the pass binds per stage: its own 5, the BVH's, the
    /// field's and the scene's.
    pub const STORAGE_BUFFERS: u32 = 5 + BVH_STORAGE_BUFFERS + FIELD_STORAGE_BUFFERS + SCENE_STORAGE_BUFFERS;

    /// The pipeline on `ctx`; an error where the device binds too few storage buffers.
    pub fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        ctx.check_pipeline(Self::STORAGE_BUFFERS, "the probe shade pass")?;
        let layout = ctx.pass_layout("probe shade", &[true, true, true, false, true]);
        let bvh = bvh_bind_group_layout(&ctx.device);
        let field = GpuDdgiField::bind_group_layout(&ctx.device);
        let scene = scene_bind_group_layout(&ctx.device);
        let layouts = [Some(&layout), Some(&bvh), Some(&field), Some(&scene)];
        let [pipeline] = ctx.compute_pipelines(&PROBE_SHADE, &layouts, ["shade_probe_rays"]);
        Ok(Self { layout, pipeline })
    }

    /// Radiance of every ray of `batch` (traced already), by its probe's record
    /// in `probes` (sorted by first ray; a ray no probe holds gives zero);
    /// with `timer`, the pass writes its timestamps at index `timer.1`.
    #[allow(clippy::too_many_arguments)]
    pub fn shade(
        &self,
        ctx: &GpuContext,
        bvh: &GpuBvh,
        field: &GpuDdgiField,
        scene: &GpuScene,
        batch: &GpuRayBatch,
        probes: &[ShadeProbe],
        seed: u32,
        frame: u32,
        timer: Option<(&crate::gpu_timer::GpuTimer, u32)>,
    ) -> Result<Vec<Vec3>, GpuError> {
        if batch.ray_count == 0 {
            return Ok(vec![]);
        }
        // Each record carries its own flag (bit 31), which the shader keeps: no flags apart.
        let probes = ShadeProbes {
            count: probes.len(),
            ids: None,
            records: &|| probes.to_vec(),
            radiance: &[],
            radiance_id: None,
        };
        let results = self.shade_on_device(ctx, bvh, field, scene, batch, probes, seed, frame, timer)?;
        // The batch's rays alone: the kept buffer may hold more.
        let bytes = ctx.read_back_range(&results, 0, batch.ray_count as u64 * 16)?;
        let v: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(v.iter().map(|l| Vec3::new(l[0], l[1], l[2])).collect())
    }

    /// The shade pass submitted, its output left on the device: per ray a
    /// `vec4<f32>` of radiance and the blend's signed distance, which
    /// `probe_blend`'s passes read as they lie (`GpuProbeBlend::prepare_resident`).
    /// The output is one buffer kept from call to call
    /// ([`GpuContext::scratch_buffer`]): what reads it is recorded before the
    /// next shade (queue order keeps the next shade's writes after it), and it
    /// is not zeroed, since the pass writes every ray's entry.
    #[allow(clippy::too_many_arguments)]
    pub fn shade_on_device(
        &self,
        ctx: &GpuContext,
        bvh: &GpuBvh,
        field: &GpuDdgiField,
        scene: &GpuScene,
        batch: &GpuRayBatch,
        probes: ShadeProbes<'_>,
        seed: u32,
        frame: u32,
        timer: Option<(&crate::gpu_timer::GpuTimer, u32)>,
    ) -> Result<wgpu::Buffer, GpuError> {
        let n = batch.ray_count;
        let (gx, gy) = dispatch_2d(n);
        let params =
            ShadeParams { ray_count: n, groups_x: gx, seed, frame, probe_count: probes.count as u32, _pad: [0; 3] };
        // One shade a frame: its uniform block, probe records, output and bind
        // group are the frame before's while the batch keeps its size.
        let params = ctx.buffer_rewritten("shade params", 0, bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let records = || -> Result<Vec<u8>, GpuError> {
            let records = (probes.records)();
            if records.len() != probes.count || records.windows(2).any(|w| w[1].first_ray < w[0].first_ray) {
                return Err(GpuError::Input(format!(
                    "{} shade probes, not {}, or out of ray order",
                    records.len(),
                    probes.count
                )));
            }
            let records = if records.is_empty() { vec![ShadeProbe::default()] } else { records };
            Ok(bytemuck::cast_slice(&records).to_vec())
        };
        let info = ctx.buffer_identified("shade probes", 0, probes.ids, records, wgpu::BufferUsages::STORAGE)?;
        let bits = || {
            let mut words = radiance_bits(probes.radiance, probes.count);
            words.resize(words.len().max(SHADE_RADIANCE_WORDS_MIN), 0);
            Ok(bytemuck::cast_slice(&words).to_vec())
        };
        let radiance_id = probes.radiance_id.map(|id| [id]);
        let radiance_flags = ctx.buffer_identified(
            "shade radiance flags",
            0,
            radiance_id.as_ref().map(|id| &id[..]),
            bits,
            wgpu::BufferUsages::STORAGE,
        )?;
        let radiance = ctx.scratch_buffer(
            "probe ray radiance",
            0,
            // The batch's capacity: the same buffer while a reused batch's size moves.
            (batch.capacity() as u64).max(1) * 16,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let bind_group = ctx.bind_group_kept(
            "probe shade",
            0,
            &self.layout,
            &[&params, batch.rays_buffer(), batch.hits_buffer(), &info, &radiance, &radiance_flags],
        );
        ctx.record(|encoder| {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("shade probe rays"),
                timestamp_writes: timer.and_then(|(t, i)| t.writes(i)),
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(PASS_GROUP, &bind_group, &[]);
            pass.set_bind_group(BVH_GROUP, bvh.bind_group(), &[]);
            pass.set_bind_group(FIELD_GROUP, field.bind_group(), &[]);
            pass.set_bind_group(SCENE_GROUP, scene.bind_group(), &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        });
        Ok(radiance)
    }
}
