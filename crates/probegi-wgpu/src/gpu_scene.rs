//! A scene's surfaces, materials, textures and lights on the device, in the
//! layout `shaders/scene.wgsl` reads (documented there): what the GPU shade and
//! camera passes need to light a hit as the CPU does, normal and bump maps
//! included; keyframed lights are posed each frame ([`GpuScene::pose_lights`]).
//! Moving or instanced geometry is refused by name (the GPU trace has no TLAS
//! yet).

use probegi_core::bsdf::{ALBEDO_TABLE_SIZE, specular_albedo_table};
use probegi_core::color::srgb8_to_linear_table;
use probegi_core::sampling::Distribution1d;
use probegi_scene::material::SpecularModel;
use probegi_scene::{LightKind, Scene};
use wgpu::util::DeviceExt;

use crate::gpu_context::{GpuContext, GpuError};

/// The bind-group layout of `scene.wgsl` (group 3): four read-only storage buffers.
pub fn scene_bind_group_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    let e = |b| crate::bvh_trace::storage_entry(b, true);
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("scene"),
        entries: &[e(0), e(1), e(2), e(3)],
    })
}

/// Why a scene cannot be shaded on the GPU yet, or `None`.
pub fn unsupported_by_gpu_shading(scene: &Scene) -> Option<String> {
    if scene.has_moving_geometry() || !scene.instances.is_empty() {
        return Some("moving objects and instanced meshes need a TLAS, which the GPU trace lacks".into());
    }
    None
}

/// The scene's shading data on the device.
pub struct GpuScene {
    pub triangles: usize,
    pub emitters: usize,
    bytes: u64,
    bind_group: wgpu::BindGroup,
    lights: wgpu::Buffer,
}

/// `scene_lights`' header, sky and punctual lights (emitters follow them).
fn pack_punctual_lights(scene: &Scene) -> Vec<[f32; 4]> {
    let mut lights: Vec<[f32; 4]> =
        vec![[f32::from_bits(scene.lights.len() as u32), 0.0, 0.0, 0.0], scene.sky_radiance.extend(0.0).into()];
    for l in &scene.lights {
        let kind = match l.kind {
            LightKind::Point => 0u32,
            LightKind::Spot => 1,
            LightKind::Directional => 2,
        };
        lights.push([f32::from_bits(kind), l.range.unwrap_or(-1.0), l.inner_cone_angle, l.outer_cone_angle]);
        lights.push(l.position.extend(0.0).into());
        lights.push(l.direction.extend(0.0).into());
        lights.push((l.color * l.intensity).extend(0.0).into());
    }
    lights
}

impl GpuScene {
    pub fn upload(ctx: &GpuContext, scene: &Scene) -> Result<Self, GpuError> {
        if let Some(why) = unsupported_by_gpu_shading(scene) {
            return Err(GpuError::Input(format!("scene {}: {why}", scene.name)));
        }
        let mesh = &scene.mesh;
        let nt = mesh.triangle_count();
        let none = f32::from_bits(u32::MAX);
        let mut triangles: Vec<[f32; 4]> = Vec::with_capacity(nt.max(1) * 11);
        for t in 0..nt {
            let [a, b, c] = mesh.triangles[t];
            let (a, b, c) = (a as usize, b as usize, c as usize);
            let p = |i: usize| mesh.positions[i];
            let n = |i: usize| mesh.normals.get(i).copied().unwrap_or(glam::Vec3::ZERO);
            let uv = |i: usize| mesh.uvs.get(i).copied().unwrap_or(glam::Vec2::ZERO);
            let m = f32::from_bits(mesh.triangle_materials[t]);
            triangles.push([p(a).x, p(a).y, p(a).z, m]);
            triangles.push(p(b).extend(0.0).into());
            triangles.push(p(c).extend(0.0).into());
            triangles.push(n(a).extend(0.0).into());
            triangles.push(n(b).extend(0.0).into());
            triangles.push(n(c).extend(0.0).into());
            triangles.push([uv(a).x, uv(a).y, uv(b).x, uv(b).y]);
            triangles.push([uv(c).x, uv(c).y, 0.0, 0.0]);
            let tan = |i: usize| mesh.tangents.get(i).copied().unwrap_or(glam::Vec4::ZERO);
            triangles.extend([tan(a).to_array(), tan(b).to_array(), tan(c).to_array()]);
        }
        if triangles.is_empty() {
            triangles.push([0.0; 4]);
        }
        let tex_bits = |t: Option<usize>| match t {
            Some(t) if t < scene.textures.len() => f32::from_bits(t as u32),
            _ => none,
        };
        let mut materials: Vec<[f32; 4]> = Vec::with_capacity(scene.materials.len().max(1) * 5);
        for m in &scene.materials {
            let alpha = (m.roughness * m.roughness).clamp(probegi_core::bsdf::MIN_ALPHA, 1.0);
            let model = match m.specular_model {
                SpecularModel::None => 0,
                SpecularModel::Mtl => 1,
                SpecularModel::MetallicRoughness => 2,
            };
            let e = m.emissive_factor * m.emissive_strength;
            materials.push(m.base_color_factor.extend(tex_bits(m.base_color_texture)).into());
            materials.push(m.specular_color.extend(alpha).into());
            materials.push([f32::from_bits(model), m.metallic, 0.0, 0.0]);
            materials.push(e.extend(tex_bits(m.emissive_texture)).into());
            materials.push([tex_bits(m.normal_texture), m.normal_scale, tex_bits(m.bump_texture), m.bump_multiplier]);
        }
        if materials.is_empty() {
            materials.push([0.0; 4]);
        }
        // Textures: the sRGB table, the GGX albedo table, headers, texels.
        let lut = srgb8_to_linear_table();
        let table = specular_albedo_table();
        let mut words: Vec<u32> = lut.iter().map(|v| v.to_bits()).collect();
        let headers = 260 + 3 * scene.textures.len();
        words.extend([scene.textures.len() as u32, ALBEDO_TABLE_SIZE as u32, headers as u32, 0]);
        let mut first = headers + table.len() * 2;
        for t in &scene.textures {
            words.extend([t.width, t.height, first as u32]);
            first += t.texels.len();
        }
        for ab in table {
            words.extend([ab[0].to_bits(), ab[1].to_bits()]);
        }
        for t in &scene.textures {
            words.extend(t.texels.iter().map(|c| c[0] as u32 | (c[1] as u32) << 8 | (c[2] as u32) << 16));
        }
        // Lights: punctual lights, then the emitters' power-weighted distribution
        // (`Scene::emitter_powers`, as the CPU's AreaLights).
        let (emitters, weights) = scene.emitter_powers();
        let distribution = Distribution1d::new(&weights);
        let mut lights = pack_punctual_lights(scene);
        lights[0][1] = f32::from_bits(emitters.len() as u32);
        let mut cdf = 0.0f32;
        for (i, &t) in emitters.iter().enumerate() {
            let pmf = distribution.pmf(i);
            cdf = if i + 1 == emitters.len() { 1.0 } else { cdf + pmf };
            lights.push([f32::from_bits(t), cdf, pmf / mesh.area(t as usize), 0.0]);
        }
        for (what, bytes) in [
            ("the scene's triangles", triangles.len() * 16),
            ("its materials", materials.len() * 16),
            ("its textures", words.len() * 4),
            ("its lights", lights.len() * 16),
        ] {
            ctx.check_buffer(bytes as u64, &format!("scene {}: {what}", scene.name))?;
        }
        let init = |label: &str, contents: &[u8]| {
            ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let init_rw = |label: &str, contents: &[u8]| {
            ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            })
        };
        let buffers = [
            init("scene triangles", bytemuck::cast_slice(&triangles)),
            init("scene materials", bytemuck::cast_slice(&materials)),
            init("scene textures", bytemuck::cast_slice(&words)),
            init_rw("scene lights", bytemuck::cast_slice(&lights)),
        ];
        let bind_group =
            crate::bvh_trace::buffers_bind_group(&ctx.device, "scene", &scene_bind_group_layout(&ctx.device), &buffers);
        let bytes = buffers.iter().map(|b| b.size()).sum();
        let [_, _, _, lights] = buffers;
        Ok(Self { triangles: nt, emitters: emitters.len(), bytes, bind_group, lights })
    }

    /// Rewrites the punctual lights (and the sky) from `scene` posed at a frame:
    /// the same scene this was uploaded from, its lights moved, dimmed or
    /// switched by their keyframes (the count and the emitters stay).
    pub fn pose_lights(&self, ctx: &GpuContext, scene: &Scene) -> Result<(), GpuError> {
        let mut lights = pack_punctual_lights(scene);
        lights[0][1] = f32::from_bits(self.emitters as u32);
        let bytes: &[u8] = bytemuck::cast_slice(&lights);
        if bytes.len() as u64 > self.lights.size() {
            return Err(GpuError::Input(format!(
                "scene {} has {} lights, more than the {} it was uploaded with",
                scene.name,
                scene.lights.len(),
                (self.lights.size() as usize / 16).saturating_sub(2 + self.emitters) / 4
            )));
        }
        ctx.queue.write_buffer(&self.lights, 0, bytes);
        Ok(())
    }

    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    pub(crate) fn bind_group(&self) -> &wgpu::BindGroup {
        &self.bind_group
    }
}
