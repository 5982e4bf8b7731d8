//! The DDGI query on the GPU: `shaders/ddgi_query.wgsl`, a WGSL library an engine
//! includes in its own shaders ([`query_wgsl`]), over a set of volumes uploaded by
//! [`GpuDdgiField`] from the same view the CPU query reads
//! (`probegi_core::ddgi_volume_blend::DdgiFieldSetView`). The shader mirrors
//! `probegi_core::ddgi_query::irradiance` and
//! `probegi_core::ddgi_volume_blend::field_set_irradiance` function by function
//! (each cites its original); `tests/it/query_equivalence.rs` holds them together.
//!
//! Bind-group layout ([`GpuDdgiField::bind_group_layout`], visible to compute and
//! fragment stages; group 2 in the crate's own passes, `shader_registry`), all
//! read-only storage buffers:
//! - binding 0: `DdgiSet` — header (member count, blending 0 density / 1
//!   cascades, has camera), the camera position, then one `GpuDdgiVolume` per
//!   member in sampling order;
//! - binding 1: every member's irradiance atlas, `vec4<f32>` texels (xyz γ-encoded),
//!   tile-major as `probegi_core::probe_atlas` lays them out;
//! - binding 2: every member's distance atlas, `vec2<f32>` (mean, mean²);
//! - binding 3: per probe `vec4<f32>`: relocation offset (m), and in `w`'s bits
//!   31 = usable by queries, 0..30 = the nearest usable probe (`0x7fffffff`: none).
//!
//! [`GpuFieldQuery`] runs the query over a batch of points (what the tests and a
//! deferred renderer's compute pass do).

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use probegi_core::ddgi_query::DdgiFieldView;
use probegi_core::ddgi_settings::ProbeBiasMode;
use probegi_core::ddgi_volume_blend::{DdgiFieldSetView, VolumeBlending};

use crate::bvh_trace::dispatch_2d;
use crate::gpu_context::{GpuContext, GpuError};
use crate::shader_registry::{FIELD_GROUP, FIELD_QUERY, FIELD_STORAGE_BUFFERS, PASS_GROUP};

/// The query library's WGSL source with its bindings in group `group`: the
/// constants prelude it reads (`shader_registry`) and `ddgi_query.wgsl`, for
/// an engine to put before its own shader. The prelude's `const` names are
/// taken.
pub fn query_wgsl(group: u32) -> String {
    crate::shader_registry::query_library(group, 0)
}

/// [`query_wgsl`] with its four bindings numbered from `first_binding`
/// instead of 0, in the same order, for a group an engine shares with its
/// own bindings (a Bevy material's group keeps 0–99 for the material:
/// `probegi-bevy` puts the query at 100). Bind it with
/// [`GpuDdgiField::layout_entries`] and [`GpuDdgiField::query_buffers`].
pub fn query_wgsl_at(group: u32, first_binding: u32) -> String {
    crate::shader_registry::query_library(group, first_binding)
}

/// One member volume; must match `DdgiVolume` in `ddgi_query.wgsl` (128 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct GpuDdgiVolume {
    /// xyz: probe (0, 0, 0) before scrolling; w: min spacing (m).
    pub(crate) origin_m: [f32; 4],
    /// xyz: spacing (m); w: irradiance γ.
    pub(crate) spacing_m: [f32; 4],
    /// xyz: probes per axis; w: weight flags (1 backface, 2 Chebyshev, 4 crush, 8 trilinear).
    pub(crate) probe_counts: [u32; 4],
    /// xyz: circular-buffer phase; w: bias mode (0 none, 1 self-shadow, 2 normal).
    pub(crate) scroll_offsets: [u32; 4],
    /// Irradiance interior, distance interior, first irradiance texel, first distance texel.
    pub(crate) texels: [u32; 4],
    /// Self-shadow bias, normal bias (m), crush threshold, energy conservation.
    pub(crate) params: [f32; 4],
    /// First probe in the probe buffer, tracks the camera, 0, 0.
    pub(crate) extra: [u32; 4],
    /// The shadowing field (seed 003 ch. 5): first occlusion texel in the
    /// distance buffer (its `x`), occlusion interior (0: no field), sharpness
    /// (f32 bits), 0.
    pub(crate) shadow: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuDdgiVolume>() == 128);

/// The set's header; must match the first 32 bytes of `DdgiSet` in `ddgi_query.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct GpuDdgiSetHeader {
    /// Member count, blending (0 density, 1 cascades), has camera, 0.
    pub(crate) header: [u32; 4],
    /// xyz: the camera (m), for a set that blends around it.
    pub(crate) camera_m: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuDdgiSetHeader>() == 32);

const NO_PROBE: u32 = 0x7fff_ffff;

/// A set of DDGI volumes on the device, ready for `ddgi_query.wgsl`. Its
/// atlases may also be the blend's targets ([`Self::member_atlases`]): the field
/// then stays resident and only its per-probe data is refreshed each frame
/// ([`Self::refresh`]).
pub struct GpuDdgiField {
    /// Member volumes.
    pub volumes: usize,
    /// Probes of all members (at least 1: an empty set keeps one entry).
    pub probes: usize,
    /// Whether a member keeps shadowing-field occlusion maps (`ddgi_shadow_visibility` reads them).
    pub shadow_field: bool,
    bytes: u64,
    /// Per member in sampling order: probes, irradiance / distance interior,
    /// first irradiance / distance texel, its index among the set's volumes.
    members: Vec<[u32; 6]>,
    /// Per shadowing-field member: volume, first occlusion texel, interior, probes.
    occlusion: Vec<[u32; 4]>,
    /// Set, irradiance, distance, probes.
    buffers: [wgpu::Buffer; 4],
    /// The blend's adaptive-hysteresis states, one `f32` per irradiance texel
    /// where a member has `probe_adaptive_hysteresis` (16 bytes otherwise;
    /// [`Self::refresh`] allocates them, zeroed, when a member turns it on).
    texel_hysteresis: std::sync::Mutex<wgpu::Buffer>,
    bind_group: wgpu::BindGroup,
    /// What the set and probes buffers were written from (only `upload` and
    /// `refresh` write them; the query binds them read-only): `refresh`
    /// writes them only when the host's differ.
    written: std::sync::Mutex<WrittenField>,
}

/// The set buffer's bytes and, per member in sampling order, the per-probe
/// arrays its probe rows were packed from. A still field's arrays repeat, and
/// comparing them costs less than packing the rows to compare those.
struct WrittenField {
    set: Vec<u8>,
    rows: Vec<ProbeRowSources>,
}

/// One member's per-probe arrays as they were when its rows were written:
/// their identity where the view gave one (`DdgiFieldView::probe_rows_id`),
/// with the arrays' addresses and lengths (a view whose arrays were swapped
/// for others keeps no identity of theirs); else a copy, offsets bit for bit
/// (so a NaN offset is still "the same").
enum ProbeRowSources {
    Identified { id: u64, arrays: [(usize, usize); 3] },
    Copied { offsets: Vec<u8>, usable: Vec<bool>, fallback: Vec<u32> },
}

/// Where `f`'s three per-probe arrays lie: (address, length) each.
fn row_arrays(f: &DdgiFieldView<'_>) -> [(usize, usize); 3] {
    [
        (f.probe_offsets_m.as_ptr() as usize, f.probe_offsets_m.len()),
        (f.probe_usable.as_ptr() as usize, f.probe_usable.len()),
        (f.probe_fallback.as_ptr() as usize, f.probe_fallback.len()),
    ]
}

impl ProbeRowSources {
    fn of(f: &DdgiFieldView<'_>) -> Self {
        match f.probe_rows_id {
            Some(id) => Self::Identified { id, arrays: row_arrays(f) },
            None => Self::Copied {
                offsets: bytemuck::cast_slice(f.probe_offsets_m).to_vec(),
                usable: f.probe_usable.to_vec(),
                fallback: f.probe_fallback.to_vec(),
            },
        }
    }

    fn holds(&self, f: &DdgiFieldView<'_>) -> bool {
        match self {
            Self::Identified { id, arrays } => f.probe_rows_id == Some(*id) && *arrays == row_arrays(f),
            Self::Copied { offsets, usable, fallback } => {
                f.probe_rows_id.is_none()
                    && offsets.as_slice() == bytemuck::cast_slice::<Vec3, u8>(f.probe_offsets_m)
                    && usable == f.probe_usable
                    && fallback == f.probe_fallback
            }
        }
    }
}

impl WrittenField {
    fn of(set: &DdgiFieldSetView<'_>, set_bytes: Vec<u8>) -> Self {
        Self { set: set_bytes, rows: Self::rows_of(set) }
    }

    fn rows_of(set: &DdgiFieldSetView<'_>) -> Vec<ProbeRowSources> {
        set.members.iter().map(|m| ProbeRowSources::of(&m.field)).collect()
    }

    /// Whether every member's probe rows would pack as they were written.
    fn holds_rows(&self, set: &DdgiFieldSetView<'_>) -> bool {
        self.rows.len() == set.members.len() && self.rows.iter().zip(&set.members).all(|(r, m)| r.holds(&m.field))
    }
}

/// A zeroed buffer of adaptive-hysteresis states (`texel_hysteresis_bytes`).
fn texel_hysteresis_buffer(ctx: &GpuContext, bytes: u64) -> Result<wgpu::Buffer, GpuError> {
    ctx.check_buffer(bytes, "the adaptive-hysteresis states")?;
    Ok(ctx.create_buffer(&wgpu::BufferDescriptor {
        label: Some("ddgi irradiance texel hysteresis"),
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    }))
}

/// Bytes of a field's adaptive-hysteresis states: one `f32` per irradiance
/// texel where a member of `set` blends with them, else a 16-byte stand-in.
fn texel_hysteresis_bytes(set: &DdgiFieldSetView<'_>, irradiance_texels: usize) -> u64 {
    if set.members.iter().any(|m| m.field.settings.probe_adaptive_hysteresis) {
        (irradiance_texels as u64 * 4).max(16)
    } else {
        16
    }
}

/// A set packed in the shader's layout; atlases left empty unless asked for.
struct PackedField {
    set: Vec<u8>,
    irradiance: Vec<[f32; 4]>,
    distance: Vec<[f32; 2]>,
    /// The probe rows; left empty unless asked for.
    probes: Vec<[f32; 4]>,
    /// Rows of the probes buffer (packed or not; at least 1).
    probe_rows: usize,
    /// Texels of the atlases (packed or not).
    irradiance_texels: usize,
    distance_texels: usize,
    members: Vec<[u32; 6]>,
    /// Per shadowing-field member: its volume index, first occlusion texel,
    /// interior and probes.
    occlusion: Vec<[u32; 4]>,
}

/// A member's `DdgiVolume` (grid, weights, bias, atlas interiors) with its first
/// irradiance and distance texels; `extra` left for the caller.
fn gpu_volume(f: &DdgiFieldView<'_>, [irr_first, dist_first]: [u32; 2]) -> GpuDdgiVolume {
    let (g, s) = (f.grid, f.settings);
    let flags = s.probe_backface_weight as u32
        | (s.probe_chebyshev_weight as u32) << 1
        | (s.probe_crush_weight as u32) << 2
        | (s.probe_trilinear_weight as u32) << 3;
    let bias = match s.probe_bias_mode {
        ProbeBiasMode::None => 0,
        ProbeBiasMode::SelfShadow => 1,
        ProbeBiasMode::Normal => 2,
    };
    GpuDdgiVolume {
        origin_m: [g.origin_m.x, g.origin_m.y, g.origin_m.z, g.min_spacing_m()],
        spacing_m: [g.spacing_m.x, g.spacing_m.y, g.spacing_m.z, s.probe_irradiance_gamma],
        probe_counts: [g.probe_counts.x, g.probe_counts.y, g.probe_counts.z, flags],
        scroll_offsets: [g.probe_scroll_offsets.x, g.probe_scroll_offsets.y, g.probe_scroll_offsets.z, bias],
        texels: [f.irradiance.interior, f.distance.interior, irr_first, dist_first],
        params: [s.probe_self_shadow_bias, s.probe_normal_bias_m, s.probe_crush_threshold, s.probe_energy_conservation],
        extra: [0; 4],
        shadow: [0; 4],
    }
}

/// `ddgi_probes`' rows of a member: offset, and the usable flag with the fallback.
fn push_probe_rows(f: &DdgiFieldView<'_>, probes: &mut Vec<[f32; 4]>) {
    use std::iter::repeat;
    // A view without some array reads its default (usable, no fallback, no offset).
    let offsets = f.probe_offsets_m.iter().copied().chain(repeat(Vec3::ZERO));
    let usable = f.probe_usable.iter().copied().chain(repeat(true));
    let fallback = f.probe_fallback.iter().copied().chain(repeat(u32::MAX));
    let rows = offsets.zip(usable).zip(fallback).take(f.grid.probe_count());
    probes.extend(rows.map(|((o, usable), fallback)| {
        let fallback = if fallback == u32::MAX || fallback >= NO_PROBE { NO_PROBE } else { fallback };
        [o.x, o.y, o.z, f32::from_bits(fallback | (usable as u32) << 31)]
    }));
}

/// The shadowing field's occlusion maps after every distance atlas in the
/// distance buffer, one texel as (visibility, 0), their place written into
/// each member's `GpuDdgiVolume::shadow`: per such member (volume, first
/// texel, interior, probes). `distance` grows only `with_atlases`.
fn pack_occlusion(
    set: &DdgiFieldSetView<'_>,
    volumes: &mut [GpuDdgiVolume],
    distance: &mut Vec<[f32; 2]>,
    distance_texels: &mut usize,
    with_atlases: bool,
) -> Vec<[u32; 4]> {
    let mut rows = vec![];
    for (v, m) in volumes.iter_mut().zip(&set.members) {
        let Some(occlusion) = m.occlusion else { continue };
        let first = *distance_texels as u32;
        v.shadow = [first, occlusion.interior, m.field.settings.shadow_field_sharpness.to_bits(), 0];
        rows.push([m.volume as u32, first, occlusion.interior, occlusion.probe_count as u32]);
        *distance_texels += occlusion.texels.len();
        if with_atlases {
            distance.extend(occlusion.texels.iter().map(|&t| [t, 0.0]));
        }
    }
    rows
}

fn pack_field(set: &DdgiFieldSetView<'_>, with_atlases: bool, with_probes: bool) -> Result<PackedField, GpuError> {
    let header = GpuDdgiSetHeader {
        header: [
            set.members.len() as u32,
            matches!(set.blending, VolumeBlending::Cascades) as u32,
            set.camera_m.is_some() as u32,
            0,
        ],
        camera_m: set.camera_m.map_or([0.0; 4], |c| [c.x, c.y, c.z, 0.0]),
    };
    let mut volumes: Vec<GpuDdgiVolume> = Vec::with_capacity(set.members.len());
    let mut irradiance: Vec<[f32; 4]> = vec![];
    let mut distance: Vec<[f32; 2]> = vec![];
    let mut probes: Vec<[f32; 4]> = vec![];
    let (mut irradiance_texels, mut distance_texels, mut probe_rows) = (0usize, 0usize, 0usize);
    let mut members = vec![];
    for m in &set.members {
        let f = &m.field;
        let n = f.grid.probe_count();
        if f.irradiance.texels.len() != n * f.irradiance.tile_len()
            || f.distance.texels.len() != n * f.distance.tile_len()
        {
            return Err(GpuError::Input(format!(
                "atlases of {} probes do not match the grid's {n}",
                f.irradiance.probe_count
            )));
        }
        let (irr_first, dist_first) = (irradiance_texels as u32, distance_texels as u32);
        members.push([n as u32, f.irradiance.interior, f.distance.interior, irr_first, dist_first, m.volume as u32]);
        let mut v = gpu_volume(f, [irr_first, dist_first]);
        v.extra = [probe_rows as u32, m.tracks_camera as u32, 0, 0];
        volumes.push(v);
        irradiance_texels += f.irradiance.texels.len();
        distance_texels += f.distance.texels.len();
        if with_atlases {
            irradiance.extend(f.irradiance.texels.iter().map(|t| [t.x, t.y, t.z, 0.0]));
            distance.extend(f.distance.texels.iter().map(|t| [t.x, t.y]));
        }
        probe_rows += n;
        if with_probes {
            push_probe_rows(f, &mut probes);
        }
    }
    // The shadowing field's occlusion maps follow every distance atlas in the
    // distance buffer, one texel as (visibility, 0).
    let occlusion_rows = pack_occlusion(set, &mut volumes, &mut distance, &mut distance_texels, with_atlases);
    let mut set_bytes = bytemuck::bytes_of(&header).to_vec();
    if volumes.is_empty() {
        set_bytes.extend_from_slice(bytemuck::bytes_of(&GpuDdgiVolume::default()));
    }
    set_bytes.extend_from_slice(bytemuck::cast_slice(&volumes));
    probe_rows = probe_rows.max(1);
    if with_probes && probes.is_empty() {
        probes.push([0.0; 4]);
    }
    // Empty sets keep one texel so every binding has a size.
    irradiance_texels = irradiance_texels.max(1);
    distance_texels = distance_texels.max(1);
    if with_atlases {
        irradiance.resize(irradiance_texels, [0.0; 4]);
        distance.resize(distance_texels, [0.0; 2]);
    }
    Ok(PackedField {
        set: set_bytes,
        irradiance,
        distance,
        probes,
        probe_rows,
        irradiance_texels,
        distance_texels,
        members,
        occlusion: occlusion_rows,
    })
}

impl GpuDdgiField {
    /// The layout of `ddgi_query.wgsl`'s group (compute and fragment stages).
    pub fn bind_group_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
        let entries = Self::layout_entries(0);
        device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("ddgi query"), entries: &entries })
    }

    /// The query's layout entries, numbered from `first_binding` as
    /// [`query_wgsl_at`] numbers them: read-only storage buffers seen by the
    /// compute and fragment stages, in [`Self::query_buffers`]' order.
    pub fn layout_entries(first_binding: u32) -> Vec<wgpu::BindGroupLayoutEntry> {
        let entry = |b: u32| wgpu::BindGroupLayoutEntry {
            binding: first_binding + b,
            visibility: wgpu::ShaderStages::COMPUTE | wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        (0..FIELD_STORAGE_BUFFERS).map(entry).collect()
    }

    /// The query's buffers (set, irradiance, distance, probes), for an
    /// engine's own bind group ([`Self::layout_entries`]). They stay this
    /// field's for its life: a field made again has new ones.
    pub fn query_buffers(&self) -> [wgpu::Buffer; 4] {
        self.buffers.clone()
    }

    /// Uploads every member of `set` (grids, settings, atlases, relocation offsets,
    /// usable flags and fallback table) in the shader's layout.
    pub fn upload(ctx: &GpuContext, set: &DdgiFieldSetView<'_>) -> Result<Self, GpuError> {
        let packed = pack_field(set, true, true)?;
        for (what, bytes) in [
            ("the irradiance atlases", packed.irradiance.len() * 16),
            ("the distance atlases", packed.distance.len() * 8),
            ("the probes", packed.probes.len() * 16),
        ] {
            ctx.check_buffer(bytes as u64, what)?;
        }
        let init = |label: &str, contents: &[u8]| {
            ctx.buffer_with(
                label,
                contents,
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            )
        };
        let buffers = [
            init("ddgi set", &packed.set),
            init("ddgi irradiance", bytemuck::cast_slice(&packed.irradiance)),
            init("ddgi distance", bytemuck::cast_slice(&packed.distance)),
            init("ddgi probes", bytemuck::cast_slice(&packed.probes)),
        ];
        let bind_group =
            crate::gpu_context::buffers_bind_group(ctx, "ddgi query", &Self::bind_group_layout(&ctx.device), &buffers);
        let texel_hysteresis = texel_hysteresis_buffer(ctx, texel_hysteresis_bytes(set, packed.irradiance_texels))?;
        Ok(Self {
            volumes: set.members.len(),
            shadow_field: set.members.iter().any(|m| m.occlusion.is_some()),
            probes: packed.probes.len(),
            bytes: buffers.iter().map(|b| b.size()).sum::<u64>(),
            members: packed.members,
            occlusion: packed.occlusion,
            buffers,
            texel_hysteresis: std::sync::Mutex::new(texel_hysteresis),
            bind_group,
            written: std::sync::Mutex::new(WrittenField::of(set, packed.set)),
        })
    }

    /// Rewrites the per-frame data of `set` (grids and scroll phases, relocation
    /// offsets, usable flags, fallbacks) into the resident buffers and, with
    /// `atlases`, the atlases too. `set` must have the shape the field was
    /// uploaded with (members, probe counts, texels).
    pub fn refresh(&self, ctx: &GpuContext, set: &DdgiFieldSetView<'_>, atlases: bool) -> Result<(), GpuError> {
        let mut written = self.written.lock().map_err(|_| GpuError::Input("a GPU pass panicked".into()))?;
        // A still field's per-probe data repeats: packed and written only
        // where it changed.
        let rows_held = written.holds_rows(set);
        let packed = pack_field(set, atlases, !rows_held)?;
        let sizes = [
            packed.set.len() as u64,
            packed.irradiance_texels as u64 * 16,
            packed.distance_texels as u64 * 8,
            packed.probe_rows as u64 * 16,
        ];
        if packed.members != self.members
            || packed.occlusion != self.occlusion
            || sizes.iter().zip(&self.buffers).any(|(s, b)| *s != b.size())
        {
            return Err(GpuError::Input("the field set changed shape since its upload".into()));
        }
        let hysteresis_bytes = texel_hysteresis_bytes(set, packed.irradiance_texels);
        let mut states = self.texel_hysteresis.lock().map_err(|_| GpuError::Input("a GPU pass panicked".into()))?;
        if hysteresis_bytes > states.size() {
            // A member turned the adaptive hysteresis on: its states start at 0.
            *states = texel_hysteresis_buffer(ctx, hysteresis_bytes)?;
        }
        if written.set == packed.set {
            ctx.count_kept(packed.set.len() as u64);
        } else {
            ctx.write_buffer(&self.buffers[0], 0, &packed.set);
            written.set = packed.set;
        }
        if rows_held {
            ctx.count_kept(packed.probe_rows as u64 * 16);
        } else {
            ctx.write_buffer(&self.buffers[3], 0, bytemuck::cast_slice(&packed.probes));
            written.rows = WrittenField::rows_of(set);
        }
        if atlases {
            ctx.write_buffer(&self.buffers[1], 0, bytemuck::cast_slice(&packed.irradiance));
            ctx.write_buffer(&self.buffers[2], 0, bytemuck::cast_slice(&packed.distance));
        }
        Ok(())
    }

    /// The atlases of the set's volume `volume` (its index among the set's
    /// volumes as given, `SetMember::volume`, not its place in sampling order) as
    /// the blend's targets: its range of the field's buffers.
    pub fn member_atlases(&self, volume: usize) -> Option<crate::probe_blend::GpuVolumeAtlases> {
        let [probes, ni, nd, irr_first, dist_first, _] = *self.members.iter().find(|m| m[5] as usize == volume)?;
        Some(crate::probe_blend::GpuVolumeAtlases {
            probe_count: probes as usize,
            irradiance_interior: ni,
            distance_interior: nd,
            irradiance_first: irr_first,
            distance_first: dist_first,
            irradiance: self.buffers[1].clone(),
            distance: self.buffers[2].clone(),
            texel_hysteresis: self.texel_hysteresis.lock().ok()?.clone(),
        })
    }

    /// Where volume `volume`'s occlusion maps lie (its index among the set's
    /// volumes as given), when it keeps a shadowing field.
    pub fn member_occlusion(&self, volume: usize) -> Option<crate::shadow_field::OcclusionTarget<'_>> {
        let [_, first, interior, probes] = *self.occlusion.iter().find(|o| o[0] as usize == volume)?;
        Some(crate::shadow_field::OcclusionTarget { buffer: &self.buffers[2], first, interior, probes })
    }

    /// Resets volume `volume`'s occlusion tiles of `probes` to 1 (lit, no
    /// history), as the host resets a probe that scrolled in; nothing without a
    /// shadowing field.
    pub fn reset_occlusion_tiles(&self, ctx: &GpuContext, volume: usize, probes: &[u32]) {
        let Some(t) = self.member_occlusion(volume) else { return };
        let tile = (t.interior as usize + 2).pow(2);
        let lit: Vec<[f32; 2]> = vec![[1.0, 0.0]; tile];
        for &p in probes.iter().filter(|p| **p < t.probes) {
            let offset = (t.first as u64 + p as u64 * tile as u64) * 8;
            ctx.write_buffer(t.buffer, offset, bytemuck::cast_slice(&lit));
        }
    }

    /// Volume `volume`'s occlusion maps read back (`None` without a shadowing field).
    pub fn download_occlusion(&self, ctx: &GpuContext, volume: usize) -> Result<Option<Vec<f32>>, GpuError> {
        let Some(t) = self.member_occlusion(volume) else { return Ok(None) };
        let texels = t.probes as u64 * (t.interior as u64 + 2).pow(2);
        let bytes = ctx.read_back_range(t.buffer, t.first as u64 * 8, texels * 8)?;
        let v: &[[f32; 2]] = bytemuck::cast_slice(&bytes);
        Ok(Some(v.iter().map(|t| t[0]).collect()))
    }

    /// The bind group to set at the group `query_wgsl` was built for.
    pub fn bind_group(&self) -> &wgpu::BindGroup {
        &self.bind_group
    }

    /// Device memory of the field's buffers.
    pub fn bytes(&self) -> u64 {
        self.bytes + self.texel_hysteresis.lock().map_or(0, |b| b.size())
    }
}

/// A query point; must match `QueryPoint` in `field_query.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct QueryPoint {
    /// xyz: the surface point (m).
    pub position: [f32; 4],
    /// Unit surface normal.
    pub normal: [f32; 4],
    /// Unit direction from the surface toward the viewer.
    pub view_dir: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<QueryPoint>() == 48);

impl QueryPoint {
    /// A query at `position` with unit `normal`, seen along unit `view_dir` (surface → viewer).
    pub fn new(position: Vec3, normal: Vec3, view_dir: Vec3) -> Self {
        Self {
            position: position.extend(0.0).into(),
            normal: normal.extend(0.0).into(),
            view_dir: view_dir.extend(0.0).into(),
        }
    }
}

/// `field_query.wgsl`'s uniform block.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct FieldQueryParams {
    pub(crate) point_count: u32,
    pub(crate) groups_x: u32,
    pub(crate) _pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<FieldQueryParams>() == 16);

/// The query over a batch of points (`field_query.wgsl` with `ddgi_query.wgsl`
/// in the field's group, `shader_registry::FIELD_GROUP`).
pub struct GpuFieldQuery {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl GpuFieldQuery {
    /// The query pipeline on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let layout = ctx.pass_layout("field query", &[true, false]);
        let field_layout = GpuDdgiField::bind_group_layout(&ctx.device);
        let [pipeline] =
            ctx.compute_pipelines(&FIELD_QUERY, &[Some(&layout), None, Some(&field_layout)], ["query_field"]);
        Self { layout, pipeline }
    }

    /// Irradiance (W/m²) at every point.
    pub fn query(&self, ctx: &GpuContext, field: &GpuDdgiField, points: &[QueryPoint]) -> Result<Vec<Vec3>, GpuError> {
        let n = points.len() as u32;
        if points.is_empty() {
            return Ok(vec![]);
        }
        let (groups_x, groups_y) = dispatch_2d(n);
        let device = &ctx.device;
        let params = FieldQueryParams { point_count: n, groups_x, _pad: [0; 2] };
        let params = ctx.buffer_with("query params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let input = ctx.buffer_with("query points", bytemuck::cast_slice(points), wgpu::BufferUsages::STORAGE);
        let output = ctx.create_buffer(&wgpu::BufferDescriptor {
            label: Some("query irradiance"),
            size: points.len() as u64 * 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let bind_group = ctx.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("field query"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: input.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: output.as_entire_binding() },
            ],
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(PASS_GROUP, &bind_group, &[]);
            pass.set_bind_group(FIELD_GROUP, field.bind_group(), &[]);
            pass.dispatch_workgroups(groups_x, groups_y, 1);
        }
        ctx.submit(encoder.finish());
        let bytes = ctx.read_back(&output)?;
        let v: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
        Ok(v.iter().map(|e| Vec3::new(e[0], e[1], e[2])).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use probegi_core::ddgi_volume_blend::SetMember;
    use probegi_field::ddgi_volume::DdgiVolume;

    fn one_member<'a>(field: DdgiFieldView<'a>) -> DdgiFieldSetView<'a> {
        let member = SetMember { field, volume: 0, tracks_camera: false, occlusion: None };
        DdgiFieldSetView { members: vec![member], blending: VolumeBlending::Density, camera_m: None }
    }

    fn with_rows<'a>(base: DdgiFieldView<'a>, offsets: &'a [Vec3], usable: &'a [bool]) -> DdgiFieldView<'a> {
        DdgiFieldView { probe_offsets_m: offsets, probe_usable: usable, ..base }
    }

    /// `refresh` compares the per-probe arrays the rows come from instead of
    /// the rows: a still field's rows are kept, and a moved offset or a probe
    /// turned unusable writes them all, as `pack_field` packs them.
    #[test]
    fn refresh_writes_the_probe_rows_only_when_their_arrays_change() {
        let Some(ctx) = GpuContext::headless_unless_absent().expect("device") else { return };
        let settings = probegi_core::ddgi_settings::DdgiVolumeSettings {
            probe_counts: glam::UVec3::new(4, 3, 2),
            ..Default::default()
        };
        let volume = DdgiVolume::new(settings, (Vec3::ZERO, Vec3::splat(4.0)));
        let n = volume.grid.probe_count();
        let mut offsets = vec![Vec3::ZERO; n];
        let mut usable = vec![true; n];
        let fallback: Vec<u32> = (0..n as u32).collect();
        let base = DdgiFieldView { probe_fallback: &fallback, ..volume.view() };
        let field = GpuDdgiField::upload(&ctx, &one_member(with_rows(base, &offsets, &usable))).expect("upload");
        let rows_bytes = n as u64 * 16;
        let refresh_and_check = |o: &[Vec3], u: &[bool], written: bool| {
            let set = one_member(with_rows(base, o, u));
            let before = ctx.counters();
            field.refresh(&ctx, &set, false).expect("refresh");
            let d = ctx.counters() - before;
            assert_eq!(d.bytes_up, if written { rows_bytes } else { 0 }, "rows written: {written}");
            let rows = ctx.read_back(&field.buffers[3]).expect("read back");
            let packed = pack_field(&set, false, true).expect("pack");
            assert_eq!(rows, bytemuck::cast_slice::<[f32; 4], u8>(&packed.probes));
        };
        refresh_and_check(&offsets, &usable, false);
        offsets[5] = Vec3::new(0.1, -0.2, 0.05);
        refresh_and_check(&offsets, &usable, true);
        refresh_and_check(&offsets, &usable, false);
        usable[7] = false;
        refresh_and_check(&offsets, &usable, true);
        // −0 equals 0 as a float but not as the row's bits: written.
        offsets[6].x = -0.0;
        refresh_and_check(&offsets, &usable, true);
    }

    /// A field set's view names its rows (`DdgiFieldView::probe_rows_id`):
    /// `refresh` keeps them by that identity with the arrays' addresses, and
    /// writes them when the set may have changed them (`volumes_mut`,
    /// `into_volumes`) or a view carries the identity over other arrays.
    #[test]
    fn refresh_keeps_a_sets_rows_by_their_identity() {
        let Some(ctx) = GpuContext::headless_unless_absent().expect("device") else { return };
        let settings = probegi_core::ddgi_settings::DdgiVolumeSettings {
            probe_counts: glam::UVec3::new(4, 3, 2),
            ..Default::default()
        };
        let mut set = probegi_field::DdgiFieldSet::single(DdgiVolume::new(settings, (Vec3::ZERO, Vec3::splat(4.0))));
        let rows_bytes = set.volumes()[0].grid.probe_count() as u64 * 16;
        let field = GpuDdgiField::upload(&ctx, &set.view()).expect("upload");
        let refresh_and_check = |view: &DdgiFieldSetView<'_>, written: bool| {
            assert!(view.members[0].field.probe_rows_id.is_some());
            let before = ctx.counters();
            field.refresh(&ctx, view, false).expect("refresh");
            let d = ctx.counters() - before;
            assert_eq!(d.bytes_up, if written { rows_bytes } else { 0 }, "rows written: {written}");
            let rows = ctx.read_back(&field.buffers[3]).expect("read back");
            let packed = pack_field(view, false, true).expect("pack");
            assert_eq!(rows, bytemuck::cast_slice::<[f32; 4], u8>(&packed.probes));
        };
        // The upload wrote the rows under the set's identity.
        refresh_and_check(&set.view(), false);
        set.volumes_mut()[0].probe_offsets[2] = Vec3::new(0.1, 0.0, 0.0);
        refresh_and_check(&set.view(), true);
        refresh_and_check(&set.view(), false);
        // The same identity over a copy of the offsets (other addresses): written.
        let copy = set.volumes()[0].probe_offsets.clone();
        let mut swapped = set.view();
        swapped.members[0].field.probe_offsets_m = &copy;
        refresh_and_check(&swapped, true);
        refresh_and_check(&set.view(), true);
        // The volume taken out, changed in place (the same arrays, moved with
        // it) and put in another set's place: written.
        let mut volumes = set.into_volumes();
        volumes[0].probe_offsets[5] = Vec3::new(0.0, 0.2, 0.0);
        let mut other = probegi_field::DdgiFieldSet::single(volumes[0].clone());
        other.volumes_mut()[0] = volumes.remove(0);
        refresh_and_check(&other.view(), true);
        refresh_and_check(&other.view(), false);
    }
}
