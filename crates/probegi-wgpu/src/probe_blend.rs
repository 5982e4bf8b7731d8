//! The blend and border passes on the GPU (`shaders/probe_blend.wgsl`), mirroring
//! `probegi_core::probe_blend::{blend_irradiance_tile, blend_distance_tile}` and
//! `probegi_core::probe_border::update_tile_border` (seed 003 §4.5, seed 004
//! §2.3 eq. 1, §4.2 Listing 1, §4.3 Listing 3). One workgroup per blending probe stages
//! the probe's rays in workgroup memory (RTXGI's `ProbeBlendingCS` with
//! `RTXGI_DDGI_BLEND_SHARED_MEMORY`; up to 512 rays, more are read from the
//! batch), then blends every interior texel of both atlases, over the frame's
//! sparse texel-to-ray weight tables. The device builds them once a frame per
//! volume (`blend_weights_table`, one thread per texel: the entries
//! `max(0, ω·r)^k ≥ ε` in ray order, as `probegi_core::probe_blend::BlendWeights`
//! builds them, from the frame's ray directions and the texels' directions,
//! `probegi_core::probe_blend::texel_directions`), as RTXGI's
//! `ProbeBlendingCS` weighs its rays on the device; each texel sums its
//! table's entries in ray order, as the CPU sums its own. The host builds no
//! table and uploads the ray directions only: 4 KB a frame at 256 rays,
//! against the 330 KB of tables it built (a `powf` per texel and ray) and
//! uploaded before. (A dense table, every ray read by every texel, made the
//! blend 2.5 to 3 times slower on lavapipe: the distance lobe `cos⁵⁰` leaves
//! a few tens of a texel's 256 rays.)
//!
//! Atlases stay on the device ([`GpuVolumeAtlases`]) in the CPU's tile-major
//! layout (`probegi_core::probe_atlas`); irradiance texels are `vec4<f32>` there
//! (xyz used) for alignment. A volume's atlases may be its own buffers or its
//! range of a resident field's (`GpuDdgiField::member_atlases`), so the passes
//! blend straight into what the queries read.
//!
//! The per-ray inputs are one `vec4<f32>` per batch ray: radiance in xyz and the
//! signed blend distance in w (backface −0.2·t, miss the ray's max distance:
//! `probegi_field::ddgi_volume::blend_inputs`), as the shade pass writes them, so a batch
//! shaded on the device is blended without leaving it ([`GpuProbeBlend::prepare_resident`]).
//! Per probe that blends the passes read its first ray in the batch, its
//! hysteresis and the frames its blend stands for (a ray budget's,
//! `probegi_field::device_plans::DeviceVolumeBlend::probe_blend_frames`): a
//! list of the blending probes alone, one workgroup each, so a frame that
//! blends an eighth of the probes (the screen scheme) packs, uploads and
//! dispatches an eighth.

use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3};
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::probe_atlas::{ProbeAtlas, tile_texel_count};
use probegi_core::probe_blend::texel_directions;

use probegi_field::device_plans::DeviceVolumeBlend;

use crate::gpu_context::{GpuContext, GpuError};
use crate::shader_registry::PROBE_BLEND;

/// The blend passes' uniform block; must match `BlendParams` in `probe_blend.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct BlendParams {
    /// Entries of the per-probe buffer: the probes that blend this frame.
    pub(crate) blend_count: u32,
    pub(crate) rays_per_probe: u32,
    pub(crate) irradiance_interior: u32,
    pub(crate) distance_interior: u32,
    pub(crate) gamma: f32,
    pub(crate) irradiance_scale: f32,
    pub(crate) visibility_scale: f32,
    pub(crate) use_thresholds: u32,
    pub(crate) significant: f32,
    pub(crate) new_distribution: f32,
    pub(crate) distance_exponent: f32,
    pub(crate) distance_clamp_m: f32,
    pub(crate) probes_per_row: u32,
    /// The volume's first texel in the irradiance / distance buffer.
    pub(crate) irradiance_first: u32,
    pub(crate) distance_first: u32,
    /// `u32`s of the weights buffer: texels × (1 + 2 × rays), texels both tiles' interiors.
    pub(crate) weight_count: u32,
    pub(crate) firefly_clamp_ratio: f32,
    pub(crate) adaptive_hysteresis: u32,
    pub(crate) adaptive_tolerance: f32,
    /// `DeviceVolumeBlend::hysteresis_cap`.
    pub(crate) hysteresis_cap: f32,
}

const _: () = assert!(std::mem::size_of::<BlendParams>() == 80);

/// Largest workgroup count per dispatch dimension (WebGPU's default limit).
const MAX_GROUPS: u32 = 65_535;
const WORKGROUP: u32 = 64;

/// One volume's atlases on the device: `probe_count` tiles from texel
/// `irradiance_first` / `distance_first` of the two buffers.
pub struct GpuVolumeAtlases {
    /// Probes (tiles) of the volume.
    pub probe_count: usize,
    /// Interior texels per side of an irradiance tile.
    pub irradiance_interior: u32,
    /// Interior texels per side of a distance tile.
    pub distance_interior: u32,
    /// The volume's first texel in the irradiance buffer.
    pub irradiance_first: u32,
    /// The volume's first texel in the distance buffer.
    pub distance_first: u32,
    pub(crate) irradiance: wgpu::Buffer,
    pub(crate) distance: wgpu::Buffer,
    /// One adaptive-hysteresis state (`f32`) per texel of `irradiance`, at the
    /// same index (`probe_adaptive_hysteresis`); a resident field that needs
    /// none holds a 16-byte stand-in.
    pub(crate) texel_hysteresis: wgpu::Buffer,
}

impl GpuVolumeAtlases {
    /// Zeroed atlases for `probe_count` probes.
    pub fn new(ctx: &GpuContext, probe_count: usize, irradiance_interior: u32, distance_interior: u32) -> Self {
        let make = |label: &str, bytes: usize| {
            ctx.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(16) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        Self {
            probe_count,
            irradiance_interior,
            distance_interior,
            irradiance_first: 0,
            distance_first: 0,
            irradiance: make("irradiance atlas", probe_count * tile_texel_count(irradiance_interior) * 16),
            distance: make("distance atlas", probe_count * tile_texel_count(distance_interior) * 8),
            texel_hysteresis: make(
                "irradiance texel hysteresis",
                probe_count * tile_texel_count(irradiance_interior) * 4,
            ),
        }
    }

    fn irradiance_bytes(&self) -> (u64, u64) {
        let tile = tile_texel_count(self.irradiance_interior) as u64 * 16;
        (self.irradiance_first as u64 * 16, self.probe_count as u64 * tile)
    }

    fn distance_bytes(&self) -> (u64, u64) {
        let tile = tile_texel_count(self.distance_interior) as u64 * 8;
        (self.distance_first as u64 * 8, self.probe_count as u64 * tile)
    }

    /// Replaces the device atlases with the CPU ones.
    pub fn upload(&self, ctx: &GpuContext, irradiance: &ProbeAtlas<Vec3>, distance: &ProbeAtlas<Vec2>) {
        let irr: Vec<[f32; 4]> = irradiance.texels.iter().map(|t| [t.x, t.y, t.z, 0.0]).collect();
        let dist: Vec<[f32; 2]> = distance.texels.iter().map(|t| [t.x, t.y]).collect();
        ctx.write_buffer(&self.irradiance, self.irradiance_bytes().0, bytemuck::cast_slice(&irr));
        ctx.write_buffer(&self.distance, self.distance_bytes().0, bytemuck::cast_slice(&dist));
    }

    /// Zeroes the tiles of `probes` (probes the host reset: scrolled in, re-initialised).
    pub fn zero_tiles(&self, ctx: &GpuContext, probes: &[u32]) {
        let irr_tile = tile_texel_count(self.irradiance_interior) as u64 * 16;
        let dist_tile = tile_texel_count(self.distance_interior) as u64 * 8;
        let zeros = vec![0u8; irr_tile.max(dist_tile) as usize];
        for &p in probes.iter().filter(|p| (**p as usize) < self.probe_count) {
            let p = p as u64;
            ctx.write_buffer(&self.irradiance, self.irradiance_bytes().0 + p * irr_tile, &zeros[..irr_tile as usize]);
            ctx.write_buffer(&self.distance, self.distance_bytes().0 + p * dist_tile, &zeros[..dist_tile as usize]);
        }
    }

    /// Reads both atlases back.
    pub fn download(&self, ctx: &GpuContext) -> Result<(ProbeAtlas<Vec3>, ProbeAtlas<Vec2>), GpuError> {
        let read = |buffer: &wgpu::Buffer, (offset, size): (u64, u64)| {
            let staging = ctx.create_buffer(&wgpu::BufferDescriptor {
                label: Some("atlas readback"),
                size: size.max(4),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, size);
            ctx.submit(encoder.finish());
            ctx.read_buffer(&staging)
        };
        let irr_bytes = read(&self.irradiance, self.irradiance_bytes())?;
        let dist_bytes = read(&self.distance, self.distance_bytes())?;
        let mut irr = ProbeAtlas::new(self.probe_count, self.irradiance_interior);
        let mut dist = ProbeAtlas::new(self.probe_count, self.distance_interior);
        let irr_f: &[[f32; 4]] = bytemuck::cast_slice(&irr_bytes);
        let dist_f: &[[f32; 2]] = bytemuck::cast_slice(&dist_bytes);
        for (d, s) in irr.texels.iter_mut().zip(irr_f) {
            *d = Vec3::new(s[0], s[1], s[2]);
        }
        for (d, s) in dist.texels.iter_mut().zip(dist_f) {
            *d = Vec2::new(s[0], s[1]);
        }
        Ok((irr, dist))
    }
}

/// One frame's blend inputs for one volume, probe-major like the CPU's.
pub struct BlendFrame<'a> {
    /// The volume's settings (γ, thresholds, distance exponent).
    pub settings: &'a DdgiVolumeSettings,
    /// The frame's unit ray directions (shared by every probe).
    pub ray_dirs: &'a [Vec3],
    /// Radiance per probe ray (`probes × rays`).
    pub ray_radiance: &'a [Vec3],
    /// Signed blend distance per probe ray (backfaces already −0.2·t).
    pub ray_distance: &'a [f32],
    /// Per probe: the hysteresis of its blend, or `None` when it does not update.
    pub probe_hysteresis: &'a [Option<f32>],
    /// Scene-event reductions of the irradiance and distance hysteresis.
    pub irradiance_scale: f32,
    /// The same for the distance (visibility) hysteresis.
    pub visibility_scale: f32,
    /// The distance limit of the blend (`DdgiVolume::distance_clamp_m`).
    pub distance_clamp_m: f32,
}

/// A kept plan checked against a batch: (plan id, rays a probe, batch rays).
type KeptPlanCheck = (u64, usize, u64);

/// The weights pass and the three compute pipelines of [`PASS_NAMES`].
pub struct GpuProbeBlend {
    layout: wgpu::BindGroupLayout,
    weights: wgpu::ComputePipeline,
    pipelines: [wgpu::ComputePipeline; 3],
    /// Per volume (where its atlas starts), the kept plan whose entries were
    /// last checked against a batch: (plan id, rays a probe, batch rays), and
    /// the probes it blends. A kept plan's entries are the same, so the same
    /// check passes again.
    checked: std::sync::Mutex<std::collections::HashMap<u64, (KeptPlanCheck, u32)>>,
}

impl GpuProbeBlend {
    /// The pipelines on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("probe blend", &[false, true, true, false, false, false, true, true]);
        let pipelines = ctx.compute_pipelines(&PROBE_BLEND, &[Some(&layout)], PASS_NAMES);
        let [weights] = ctx.compute_pipelines(&PROBE_BLEND, &[Some(&layout)], ["blend_weights_table"]);
        Self { layout, weights, pipelines, checked: Default::default() }
    }

    /// Blends `frame` into `atlases` and refreshes the borders of the probes that updated.
    pub fn run(&self, ctx: &GpuContext, atlases: &GpuVolumeAtlases, frame: &BlendFrame<'_>) -> Result<(), GpuError> {
        let bindings = self.prepare(ctx, atlases, frame)?;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.record(&mut encoder, &bindings, None);
        ctx.submit(encoder.finish());
        ctx.wait()
    }

    /// Uploads `frame`'s inputs and binds them with `atlases`.
    pub fn prepare(
        &self,
        ctx: &GpuContext,
        atlases: &GpuVolumeAtlases,
        frame: &BlendFrame<'_>,
    ) -> Result<BlendBindings, GpuError> {
        let probes = atlases.probe_count;
        let rays = frame.ray_dirs.len();
        if frame.ray_radiance.len() != probes * rays || frame.ray_distance.len() != probes * rays {
            return Err(GpuError::Input(format!(
                "{} radiances and {} distances for {probes} probes × {rays} rays",
                frame.ray_radiance.len(),
                frame.ray_distance.len()
            )));
        }
        if frame.probe_hysteresis.len() != probes {
            return Err(GpuError::Input(format!(
                "{} hysteresis values for {probes} probes",
                frame.probe_hysteresis.len()
            )));
        }
        let results: Vec<[f32; 4]> =
            frame.ray_radiance.iter().zip(frame.ray_distance).map(|(l, d)| [l.x, l.y, l.z, *d]).collect();
        let results = ctx.buffer_with("ray results", bytemuck::cast_slice(&results), wgpu::BufferUsages::STORAGE);
        let plan = DeviceVolumeBlend {
            settings: frame.settings,
            ray_dirs: frame.ray_dirs,
            probe_blend: (0..probes).map(|p| frame.probe_hysteresis[p].map(|h| ((p * rays) as u32, h))).collect(),
            probe_blend_id: None,
            hysteresis_cap: 1.0,
            irradiance_scale: frame.irradiance_scale,
            visibility_scale: frame.visibility_scale,
            distance_clamp_m: frame.distance_clamp_m,
            reset_probes: &[],
            seeds: &[],
            shadow: None,
            measure_change: false,
            change_key: Default::default(),
            probe_blend_frames: Default::default(),
        };
        self.prepare_resident(ctx, atlases, &plan, &results)
    }

    /// Binds a batch's per-ray results where they lie on the device
    /// (`ray_results`, the shade pass's output: one `vec4<f32>` per batch ray,
    /// radiance and signed blend distance) with `atlases`, uploading only
    /// `plan`'s per-probe inputs and weight tables. The plan is the field's own
    /// (`DdgiFieldSet::device_blend_plan`); its `reset_probes` are the caller's
    /// to clear first ([`GpuVolumeAtlases::zero_tiles`]). It is packed, not
    /// uploaded as it is: its tables are `Vec`s and its per-probe entries
    /// `Option`s.
    pub fn prepare_resident(
        &self,
        ctx: &GpuContext,
        atlases: &GpuVolumeAtlases,
        plan: &DeviceVolumeBlend<'_>,
        ray_results: &wgpu::Buffer,
    ) -> Result<BlendBindings, GpuError> {
        let batch_rays = ray_results.size() / 16;
        let (blending, packed) = self.entries_once(atlases, plan, batch_rays)?;
        self.bind_blend(ctx, atlases, plan, (ray_results, batch_rays), blending, packed)
    }

    /// [`Self::prepare_resident`] over the batch's `batch_rays` results (the
    /// shade's kept buffer may hold more), or `None` where no probe of `plan`
    /// blends (nothing to bind or record). The plan's entries are checked and
    /// packed in one pass over its probes, and not at all where the same kept
    /// plan passed last ([`Self::entries_once`]).
    pub(crate) fn prepare_blending(
        &self,
        ctx: &GpuContext,
        atlases: &GpuVolumeAtlases,
        plan: &DeviceVolumeBlend<'_>,
        (ray_results, batch_rays): (&wgpu::Buffer, u64),
    ) -> Result<Option<BlendBindings>, GpuError> {
        let (blending, packed) = self.entries_once(atlases, plan, batch_rays)?;
        if blending == 0 {
            return Ok(None);
        }
        self.bind_blend(ctx, atlases, plan, (ray_results, batch_rays), blending, packed).map(Some)
    }

    /// The buffers and bind group of `plan`'s blend of `blending` probes over
    /// the batch's `batch_rays` results, its entries `packed` where
    /// [`Self::entries_once`] packed them (else packed here, unless the device
    /// holds them under the plan's id).
    fn bind_blend(
        &self,
        ctx: &GpuContext,
        atlases: &GpuVolumeAtlases,
        plan: &DeviceVolumeBlend<'_>,
        (ray_results, batch_rays): (&wgpu::Buffer, u64),
        blending: u32,
        packed: Option<Vec<u8>>,
    ) -> Result<BlendBindings, GpuError> {
        let (ni, nd) = (atlases.irradiance_interior, atlases.distance_interior);
        let per_row = blending.clamp(1, MAX_GROUPS);
        let params = blend_params(atlases, plan, blending, per_row);
        let weight_count = params.weight_count;
        // A kept plan's entries (the same id) are packed once; its frame
        // counts are 1 (a kept plan has none).
        let per_probe_id = plan.probe_blend_id.filter(|_| plan.probe_blend_frames.is_empty());
        let storage = wgpu::BufferUsages::STORAGE;
        // Kept per volume, by where its atlas starts, and rewritten in place:
        // the uniform block, the per-probe entries (which repeat for a still
        // volume) and the frame's ray directions (which turn every frame);
        // the texels' directions never change (kept by the tile sizes); the
        // weight tables are the device's to rewrite each frame. A still
        // volume's blend then makes no buffer and no bind group.
        let key = atlases.irradiance_first as u64;
        let params =
            ctx.buffer_rewritten("blend params", key, bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let weights = ctx.scratch_buffer("blend weights", key, weight_count.max(4) as u64 * 4, storage);
        let per_probe_id = per_probe_id.as_ref().map(std::slice::from_ref);
        let entries = || packed.map_or_else(|| blend_entries(plan, batch_rays), Ok);
        let per_probe = ctx.buffer_identified("probe blend", key, per_probe_id, entries, storage)?;
        // The texels' directions follow from the tile sizes alone: made once.
        let texel_dirs = || {
            let dirs = texel_directions(ni).into_iter().chain(texel_directions(nd));
            Ok(dirs.flat_map(|d| bytemuck::cast::<[f32; 4], [u8; 16]>(d.extend(0.0).into())).collect())
        };
        let tiles = [ni as u64, nd as u64];
        let texel_dirs = ctx.buffer_identified("blend texel directions", key, Some(&tiles), texel_dirs, storage)?;
        let ray_dirs: Vec<[f32; 4]> = plan.ray_dirs.iter().map(|d| d.extend(0.0).into()).collect();
        let ray_dirs = ctx.buffer_rewritten("blend ray directions", key, bytemuck::cast_slice(&ray_dirs), storage);
        let buffers = [
            &params,
            &weights,
            ray_results,
            &per_probe,
            &atlases.irradiance,
            &atlases.distance,
            &atlases.texel_hysteresis,
            &texel_dirs,
            &ray_dirs,
        ];
        let bind_group = ctx.bind_group_kept("probe blend", key, &self.layout, &buffers);
        let rows = blending.div_ceil(per_row);
        let groups = |texels: u32| texels.div_ceil(WORKGROUP);
        // The blend: one workgroup per blending probe; the borders: one
        // thread per tile texel of each.
        let dispatches = [1, groups((ni + 2) * (ni + 2)), groups((nd + 2) * (nd + 2))];
        let weight_groups = crate::bvh_trace::dispatch_2d(ni * ni + nd * nd);
        Ok(BlendBindings { bind_group, dispatches, per_row, rows, weight_groups })
    }

    /// The probes of `plan` that blend and their packed entries
    /// ([`check_resident`], then [`blend_entries`]); where the same kept plan
    /// (its `probe_blend_id`) passed last with the same rays and batch, the
    /// count alone (its entries are on the device already).
    fn entries_once(
        &self,
        atlases: &GpuVolumeAtlases,
        plan: &DeviceVolumeBlend<'_>,
        batch_rays: u64,
    ) -> Result<(u32, Option<Vec<u8>>), GpuError> {
        let key = atlases.irradiance_first as u64;
        let mut checked = self.checked.lock().unwrap_or_else(|e| e.into_inner());
        let this = plan.probe_blend_id.map(|id| (id, plan.ray_dirs.len(), batch_rays));
        if let Some((kept, blending)) = checked.get(&key).copied()
            && this == Some(kept)
            && plan.probe_blend.len() == atlases.probe_count
        {
            return Ok((blending, None));
        }
        checked.remove(&key);
        check_resident(atlases, plan)?;
        let packed = blend_entries(plan, batch_rays)?;
        let blending = (packed.len() / BLEND_ENTRY_BYTES) as u32;
        if let Some(this) = this {
            checked.insert(key, (this, blending));
        }
        Ok((blending, Some(packed)))
    }

    /// Records the three passes ([`PASS_NAMES`]: blend, border irradiance,
    /// border distance); with `timer`, pass k writes its timestamps at
    /// `timer.1 + k`.
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bindings: &BlendBindings,
        timer: Option<(&crate::gpu_timer::GpuTimer, u32)>,
    ) {
        {
            // The frame's weight tables, before the blend reads them (untimed:
            // one thread per texel of one tile, against every probe's blend).
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.weights);
            pass.set_bind_group(0, &bindings.bind_group, &[]);
            pass.dispatch_workgroups(bindings.weight_groups.0, bindings.weight_groups.1, 1);
        }
        for (k, (pipeline, x)) in self.pipelines.iter().zip(bindings.dispatches).enumerate() {
            // One pass per dispatch: the borders read what the blends wrote.
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(PASS_NAMES[k]),
                timestamp_writes: timer.and_then(|(t, first)| t.writes(first + k as u32)),
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bindings.bind_group, &[]);
            pass.dispatch_workgroups(x, bindings.per_row, bindings.rows);
        }
    }
}

/// The names of [`GpuProbeBlend::record`]'s passes, in order: the blend of
/// both atlases (one workgroup per blending probe, its rays staged in workgroup memory),
/// then each atlas's borders.
pub const PASS_NAMES: [&str; 3] = ["blend_probe", "border_irradiance", "border_distance"];

/// One frame's blend inputs on the device, bound to a volume's atlases.
pub struct BlendBindings {
    bind_group: wgpu::BindGroup,
    dispatches: [u32; 3],
    per_row: u32,
    rows: u32,
    /// The weights pass's workgroups (x, y).
    weight_groups: (u32, u32),
}

/// An error unless `plan` fits `atlases`: its weights a buffer, one entry
/// per probe (the entries' rays are checked against the batch as
/// [`blend_entries`] packs them).
fn check_resident(atlases: &GpuVolumeAtlases, plan: &DeviceVolumeBlend<'_>) -> Result<(), GpuError> {
    let probes = atlases.probe_count;
    let rays = plan.ray_dirs.len();
    let (ni, nd) = (atlases.irradiance_interior as u64, atlases.distance_interior as u64);
    if (1 + 2 * rays as u64) * (ni * ni + nd * nd) > u32::MAX as u64 / 4 {
        return Err(GpuError::Input(format!("{rays} rays × {ni}² + {nd}² texels of weights")));
    }
    if plan.probe_blend.len() != probes || probes == 0 || rays == 0 {
        return Err(GpuError::Input(format!(
            "{} blend entries for {probes} probes with {rays} rays each",
            plan.probe_blend.len()
        )));
    }
    Ok(())
}

/// Bytes of one entry of [`blend_entries`].
const BLEND_ENTRY_BYTES: usize = 16;

/// The per-probe buffer of `probe_blend.wgsl`: one entry per probe that
/// blends, in probe order: (first ray, hysteresis bits, frames, probe). A
/// frame whose blends are a few of the probes (the screen scheme's eighth)
/// uploads and dispatches those alone. An error where a probe's rays lie
/// past the batch's `batch_rays` (checked in the same pass over the probes).
fn blend_entries(plan: &DeviceVolumeBlend<'_>, batch_rays: u64) -> Result<Vec<u8>, GpuError> {
    let rays = plan.ray_dirs.len() as u64;
    let frames = |p: usize| plan.probe_blend_frames.get(p).copied().unwrap_or(1).max(1);
    let mut packed = Vec::with_capacity(BLEND_ENTRY_BYTES * 64);
    for (p, b) in plan.probe_blend.iter().enumerate() {
        let Some((first, h)) = *b else { continue };
        if first as u64 + rays > batch_rays {
            return Err(GpuError::Input(format!(
                "a probe's rays {first}..{} lie past the batch's {batch_rays} rays",
                first as u64 + rays
            )));
        }
        let entry: [u32; 4] = [first, h.max(0.0).to_bits(), frames(p), p as u32];
        packed.extend_from_slice(bytemuck::bytes_of(&entry));
    }
    Ok(packed)
}

/// The blend passes' uniform block for `plan` into `atlases`.
fn blend_params(
    atlases: &GpuVolumeAtlases,
    plan: &DeviceVolumeBlend<'_>,
    blend_count: u32,
    probes_per_row: u32,
) -> BlendParams {
    let s = plan.settings;
    BlendParams {
        blend_count,
        rays_per_probe: plan.ray_dirs.len() as u32,
        irradiance_interior: atlases.irradiance_interior,
        distance_interior: atlases.distance_interior,
        gamma: s.probe_irradiance_gamma,
        irradiance_scale: plan.irradiance_scale,
        visibility_scale: plan.visibility_scale,
        use_thresholds: s.probe_fast_convergence as u32,
        significant: s.probe_significant_change_threshold,
        new_distribution: s.probe_new_distribution_threshold,
        distance_exponent: s.probe_distance_exponent,
        distance_clamp_m: plan.distance_clamp_m,
        probes_per_row,
        irradiance_first: atlases.irradiance_first,
        distance_first: atlases.distance_first,
        weight_count: (atlases.irradiance_interior * atlases.irradiance_interior
            + atlases.distance_interior * atlases.distance_interior)
            * (1 + 2 * plan.ray_dirs.len() as u32),
        firefly_clamp_ratio: s.probe_firefly_clamp_ratio,
        adaptive_hysteresis: s.probe_adaptive_hysteresis as u32,
        adaptive_tolerance: s.probe_adaptive_hysteresis_tolerance,
        hysteresis_cap: plan.hysteresis_cap,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use probegi_core::ddgi_settings::DdgiVolumeSettings;

    /// A plan of four probes with 2 rays each: probes 1 and 3 blend, probe 3
    /// standing for `frames_3` frames.
    fn plan<'a>(settings: &'a DdgiVolumeSettings, dirs: &'a [Vec3], frames_3: u32) -> DeviceVolumeBlend<'a> {
        DeviceVolumeBlend {
            settings,
            ray_dirs: dirs,
            probe_blend: vec![None, Some((0, 0.5)), None, Some((2, -1.0))].into(),
            probe_blend_id: None,
            hysteresis_cap: 1.0,
            irradiance_scale: 1.0,
            visibility_scale: 1.0,
            distance_clamp_m: 1.0,
            reset_probes: &[],
            seeds: &[],
            shadow: None,
            measure_change: false,
            change_key: Default::default(),
            probe_blend_frames: if frames_3 == 0 { Default::default() } else { vec![1, 1, 1, frames_3].into() },
        }
    }

    #[test]
    fn blend_entries_pack_the_blending_probes_alone_and_refuse_rays_past_the_batch() {
        let settings = DdgiVolumeSettings::default();
        let dirs = [Vec3::X, Vec3::Y];
        let words = |bytes: Vec<u8>| bytemuck::cast_slice::<u8, u32>(&bytes).to_vec();
        // (first ray, hysteresis bits, frames, probe), in probe order; a
        // negative hysteresis is sent as 0, missing frame counts as 1.
        let packed = words(blend_entries(&plan(&settings, &dirs, 0), 4).expect("fits the batch"));
        assert_eq!(packed, [0, 0.5f32.to_bits(), 1, 1, 2, 0.0f32.to_bits(), 1, 3]);
        let packed = words(blend_entries(&plan(&settings, &dirs, 5), 4).expect("fits the batch"));
        assert_eq!(packed[4..], [2, 0.0f32.to_bits(), 5, 3]);
        // Probe 3's rays 2..4 need a batch of 4 rays.
        let err = blend_entries(&plan(&settings, &dirs, 0), 3).expect_err("probe 3's rays pass the batch");
        assert!(err.to_string().contains("2..4"), "{err}");
    }
}
