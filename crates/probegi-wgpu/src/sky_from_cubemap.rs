//! A cubemap texture on the device made into the scene's equirectangular sky
//! map where it lies (`shaders/sky_from_cubemap.wgsl`), for an engine whose
//! sky the host cannot read: a block-compressed cubemap (BC6H, ASTC: the
//! device decodes it) or one whose texels live only on the device. Every
//! texel of the scene's sky map (`GpuScene`; Mitsuba's convention,
//! `probegi_scene::environment_map::uv_to_direction` at its centre) reads the
//! cube's first level at `to_cube · d`, nearest texel, on the face of that
//! direction's major axis with the Vulkan and WebGPU face coordinates: what
//! `probegi_bevy::environment_sky::equirect_from_cubemap` does on the host.
//!
//! Only the texels are written: the map's sampling CDFs stay as the host made
//! them for the placeholder the scene was uploaded with. So a scene whose sky
//! comes from here reads it where probe rays miss
//! (`DdgiVolumeSettings::probe_sky_map_on_miss`) and must not sample light
//! from it (the camera pass's and the probes' sky-map next-event estimation).

use bytemuck::{Pod, Zeroable};

use crate::gpu_context::{GpuContext, GpuError, storage_entry, uniform_entry};
use crate::gpu_scene::GpuScene;
use crate::shader_registry::SKY_FROM_CUBEMAP;

/// Must match `SkyFromCubemapParams` in `sky_from_cubemap.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub(crate) struct SkyFromCubemapParams {
    /// The rows of `to_cube` (w unused).
    pub(crate) to_cube: [[f32; 4]; 3],
    pub(crate) first_word: u32,
    pub(crate) width: u32,
    pub(crate) face_width: u32,
    pub(crate) _pad: u32,
}
const _: () = assert!(std::mem::size_of::<SkyFromCubemapParams>() == 64);

/// The pass that makes a scene's sky map from a cubemap texture.
pub struct GpuSkyFromCubemap {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl GpuSkyFromCubemap {
    /// The pipeline on `ctx`.
    pub fn new(ctx: &GpuContext) -> Self {
        let cube = wgpu::BindGroupLayoutEntry {
            binding: 1,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2Array,
                multisampled: false,
            },
            count: None,
        };
        let layout = ctx.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sky from cubemap"),
            entries: &[uniform_entry(0), cube, storage_entry(2, false)],
        });
        let [pipeline] = ctx.compute_pipelines(&SKY_FROM_CUBEMAP, &[Some(&layout)], ["sky_from_cubemap"]);
        Self { layout, pipeline }
    }

    /// Records into `encoder` the pass that fills `scene`'s sky map from the
    /// first level of `cube` (6 square layers, a float format: any the device
    /// samples, compressed ones included), each map direction `d` reading the
    /// cube along `to_cube · d`. An error names what does not fit: a scene
    /// without a sky map, a texture that is no cubemap or cannot be bound.
    pub fn record(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        cube: &wgpu::Texture,
        to_cube: glam::Mat3,
        scene: &GpuScene,
    ) -> Result<(), GpuError> {
        let (words, first_word, width) =
            scene.sky_map_words().ok_or_else(|| GpuError::Input("the scene has no sky map to write".into()))?;
        let size = cube.size();
        let square_layers = size.depth_or_array_layers == 6 && size.width == size.height && size.width > 0;
        if cube.dimension() != wgpu::TextureDimension::D2 || !square_layers {
            return Err(GpuError::Input(format!(
                "a cubemap has 6 square layers; this texture is {}×{}×{}",
                size.width, size.height, size.depth_or_array_layers
            )));
        }
        let float = matches!(cube.format().sample_type(None, None), Some(wgpu::TextureSampleType::Float { .. }));
        if !float || !cube.usage().contains(wgpu::TextureUsages::TEXTURE_BINDING) || cube.sample_count() != 1 {
            return Err(GpuError::Input(format!(
                "the cubemap ({:?}, {:?}) is not a float texture the pass can bind",
                cube.format(),
                cube.usage()
            )));
        }
        let rows = [to_cube.row(0), to_cube.row(1), to_cube.row(2)].map(|r| r.extend(0.0).to_array());
        let params = SkyFromCubemapParams { to_cube: rows, first_word, width, face_width: size.width, _pad: 0 };
        let params = ctx.buffer_with("sky params", bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM);
        let view = cube.create_view(&wgpu::TextureViewDescriptor {
            label: Some("sky cube layers"),
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            base_mip_level: 0,
            mip_level_count: Some(1),
            base_array_layer: 0,
            array_layer_count: Some(6),
            ..Default::default()
        });
        let bind_group = ctx.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sky from cubemap"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&view) },
                wgpu::BindGroupEntry { binding: 2, resource: words.as_entire_binding() },
            ],
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("sky from cubemap"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(width.div_ceil(8), (width / 2).div_ceil(8), 1);
        Ok(())
    }
}
