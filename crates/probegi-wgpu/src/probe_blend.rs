//! The blend and border passes on the GPU (`shaders/probe_blend.wgsl`), mirroring
//! `probegi_core::probe_blend::{blend_irradiance_tile, blend_distance_tile}` and
//! `probegi_core::probe_border::update_tile_border` (seed 003 §4.5, seed 004
//! §2.3 eq. 1, §4.2 Listing 1, §4.3 Listing 3). One thread per interior texel per
//! probe; the texel-to-ray weights are computed in the shader from the frame's
//! ray directions with the CPU table's cutoff (`BLEND_WEIGHT_EPSILON`), summed
//! in the same ray order.
//!
//! Atlases stay on the device ([`GpuVolumeAtlases`]) in the CPU's tile-major
//! layout (`probegi_core::probe_atlas`); irradiance texels are `vec4<f32>` there
//! (xyz used) for alignment.

use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3};
use probegi_core::ddgi_settings::DdgiVolumeSettings;
use probegi_core::probe_atlas::{ProbeAtlas, tile_texel_count};
use wgpu::util::DeviceExt;

use crate::bvh_trace::{storage_entry, uniform_entry};
use crate::gpu_context::{GpuContext, GpuError};

/// The blend passes' uniform block; must match `BlendParams` in `probe_blend.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct BlendParams {
    pub probe_count: u32,
    pub rays_per_probe: u32,
    pub irradiance_interior: u32,
    pub distance_interior: u32,
    pub gamma: f32,
    pub irradiance_scale: f32,
    pub visibility_scale: f32,
    pub use_thresholds: u32,
    pub significant: f32,
    pub new_distribution: f32,
    pub distance_exponent: f32,
    pub distance_clamp_m: f32,
    pub probes_per_row: u32,
    pub _pad: [u32; 3],
}

const _: () = assert!(std::mem::size_of::<BlendParams>() == 64);

/// Largest workgroup count per dispatch dimension (WebGPU's default limit).
const MAX_GROUPS: u32 = 65_535;
const WORKGROUP: u32 = 64;

/// One volume's atlases on the device.
pub struct GpuVolumeAtlases {
    pub probe_count: usize,
    pub irradiance_interior: u32,
    pub distance_interior: u32,
    irradiance: wgpu::Buffer,
    distance: wgpu::Buffer,
}

impl GpuVolumeAtlases {
    /// Zeroed atlases for `probe_count` probes.
    pub fn new(ctx: &GpuContext, probe_count: usize, irradiance_interior: u32, distance_interior: u32) -> Self {
        let make = |label: &str, bytes: usize| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
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
            irradiance: make("irradiance atlas", probe_count * tile_texel_count(irradiance_interior) * 16),
            distance: make("distance atlas", probe_count * tile_texel_count(distance_interior) * 8),
        }
    }

    /// Replaces the device atlases with the CPU ones.
    pub fn upload(&self, ctx: &GpuContext, irradiance: &ProbeAtlas<Vec3>, distance: &ProbeAtlas<Vec2>) {
        let irr: Vec<[f32; 4]> = irradiance.texels.iter().map(|t| [t.x, t.y, t.z, 0.0]).collect();
        let dist: Vec<[f32; 2]> = distance.texels.iter().map(|t| [t.x, t.y]).collect();
        ctx.queue.write_buffer(&self.irradiance, 0, bytemuck::cast_slice(&irr));
        ctx.queue.write_buffer(&self.distance, 0, bytemuck::cast_slice(&dist));
    }

    /// Reads both atlases back.
    pub fn download(&self, ctx: &GpuContext) -> Result<(ProbeAtlas<Vec3>, ProbeAtlas<Vec2>), GpuError> {
        let read = |buffer: &wgpu::Buffer| {
            let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("atlas readback"),
                size: buffer.size(),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, buffer.size());
            ctx.queue.submit([encoder.finish()]);
            ctx.read_buffer(&staging)
        };
        let irr_bytes = read(&self.irradiance)?;
        let dist_bytes = read(&self.distance)?;
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
    pub visibility_scale: f32,
    /// The distance limit of the blend (`DdgiVolume::distance_clamp_m`).
    pub distance_clamp_m: f32,
}

/// The four compute pipelines (blend irradiance / distance, border irradiance / distance).
pub struct GpuProbeBlend {
    layout: wgpu::BindGroupLayout,
    pipelines: [wgpu::ComputePipeline; 4],
}

impl GpuProbeBlend {
    pub fn new(ctx: &GpuContext) -> Self {
        let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("probe_blend.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shaders/probe_blend.wgsl").into()),
        });
        let layout = ctx.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("probe blend"),
            entries: &[
                uniform_entry(0),
                storage_entry(1, true),
                storage_entry(2, true),
                storage_entry(3, true),
                storage_entry(4, true),
                storage_entry(5, false),
                storage_entry(6, false),
            ],
        });
        let pipeline_layout = ctx.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("probe blend"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |entry: &str| {
            ctx.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let pipelines = [
            pipeline("blend_irradiance"),
            pipeline("blend_distance"),
            pipeline("border_irradiance"),
            pipeline("border_distance"),
        ];
        Self { layout, pipelines }
    }

    /// Blends `frame` into `atlases` and refreshes the borders of the probes that updated.
    pub fn run(&self, ctx: &GpuContext, atlases: &GpuVolumeAtlases, frame: &BlendFrame<'_>) -> Result<(), GpuError> {
        let bindings = self.prepare(ctx, atlases, frame)?;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.record(&mut encoder, &bindings, None);
        ctx.queue.submit([encoder.finish()]);
        ctx.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(())
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
        if frame.probe_hysteresis.len() != probes || probes == 0 || rays == 0 {
            return Err(GpuError::Input(format!(
                "{} hysteresis values for {probes} probes",
                frame.probe_hysteresis.len()
            )));
        }
        let s = frame.settings;
        let per_row = (probes as u32).min(MAX_GROUPS);
        let params = BlendParams {
            probe_count: probes as u32,
            rays_per_probe: rays as u32,
            irradiance_interior: atlases.irradiance_interior,
            distance_interior: atlases.distance_interior,
            gamma: s.probe_irradiance_gamma,
            irradiance_scale: frame.irradiance_scale,
            visibility_scale: frame.visibility_scale,
            use_thresholds: s.probe_fast_convergence as u32,
            significant: s.probe_significant_change_threshold,
            new_distribution: s.probe_new_distribution_threshold,
            distance_exponent: s.probe_distance_exponent,
            distance_clamp_m: frame.distance_clamp_m,
            probes_per_row: per_row,
            _pad: [0; 3],
        };
        let init = |label: &str, contents: &[u8], usage: wgpu::BufferUsages| {
            ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
        };
        let dirs: Vec<[f32; 4]> = frame.ray_dirs.iter().map(|d| [d.x, d.y, d.z, 0.0]).collect();
        let radiance: Vec<[f32; 4]> = frame.ray_radiance.iter().map(|l| [l.x, l.y, l.z, 0.0]).collect();
        let hysteresis: Vec<f32> = frame.probe_hysteresis.iter().map(|h| h.unwrap_or(-1.0)).collect();
        let storage = wgpu::BufferUsages::STORAGE;
        let buffers = [
            init("blend params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM),
            init("ray directions", bytemuck::cast_slice(&dirs), storage),
            init("ray radiance", bytemuck::cast_slice(&radiance), storage),
            init("ray distance", bytemuck::cast_slice(frame.ray_distance), storage),
            init("probe hysteresis", bytemuck::cast_slice(&hysteresis), storage),
        ];
        let mut entries: Vec<wgpu::BindGroupEntry<'_>> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
            .collect();
        entries.push(wgpu::BindGroupEntry { binding: 5, resource: atlases.irradiance.as_entire_binding() });
        entries.push(wgpu::BindGroupEntry { binding: 6, resource: atlases.distance.as_entire_binding() });
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("probe blend"),
            layout: &self.layout,
            entries: &entries,
        });
        let rows = (probes as u32).div_ceil(per_row);
        let groups = |texels: u32| texels.div_ceil(WORKGROUP);
        let (ni, nd) = (atlases.irradiance_interior, atlases.distance_interior);
        let dispatches = [groups(ni * ni), groups(nd * nd), groups((ni + 2) * (ni + 2)), groups((nd + 2) * (nd + 2))];
        Ok(BlendBindings { bind_group, dispatches, per_row, rows })
    }

    /// Records the four passes (blend irradiance, blend distance, border
    /// irradiance, border distance); with `timer`, pass k writes its timestamps
    /// at `timer.1 + k`.
    pub fn record(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bindings: &BlendBindings,
        timer: Option<(&crate::gpu_timer::GpuTimer, u32)>,
    ) {
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

/// The names of [`GpuProbeBlend::record`]'s passes, in order.
pub const PASS_NAMES: [&str; 4] = ["blend_irradiance", "blend_distance", "border_irradiance", "border_distance"];

/// One frame's blend inputs on the device, bound to a volume's atlases.
pub struct BlendBindings {
    bind_group: wgpu::BindGroup,
    dispatches: [u32; 4],
    per_row: u32,
    rows: u32,
}
