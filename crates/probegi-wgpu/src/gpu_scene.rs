//! A scene's surfaces, materials, textures and lights on the device, in the
//! layout `shaders/scene.wgsl` reads (documented there): what the GPU shade and
//! camera passes need to light a hit as the CPU does, normal and bump maps
//! included; keyframed lights are posed each frame ([`GpuScene::pose_lights`]),
//! and so are moving objects' triangles ([`GpuScene::pose_geometry`]: the
//! scene's mesh as `Scene::set_frame_from` leaves it). Instanced meshes keep
//! one copy of their prototype's triangles and a transform per instance.

use probegi_core::bsdf::{ALBEDO_TABLE_SIZE, specular_albedo_table};
use probegi_core::color::srgb8_to_linear_table;
use probegi_core::sampling::Distribution1d;
use probegi_scene::material::{SpecularModel, UvMapping};
use probegi_scene::texture::{Filter, Sampler, Wrap};
use probegi_scene::{LightKind, Scene};

use crate::gpu_context::{GpuContext, GpuError};
use crate::shader_registry::SCENE_STORAGE_BUFFERS;

/// The bind-group layout of `scene.wgsl` (`shader_registry::SCENE_GROUP`):
/// `SCENE_STORAGE_BUFFERS` read-only storage buffers.
pub(crate) fn scene_bind_group_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    let entries: Vec<_> = (0..SCENE_STORAGE_BUFFERS).map(|b| crate::gpu_context::storage_entry(b, true)).collect();
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("scene"), entries: &entries })
}

/// `scene_triangles`' 15 vec4s of triangle `t` of `mesh`.
fn pack_triangle(mesh: &probegi_scene::mesh::Mesh, t: usize, out: &mut Vec<[f32; 4]>) {
    let [a, b, c] = mesh.triangles[t];
    let (a, b, c) = (a as usize, b as usize, c as usize);
    let p = |i: usize| mesh.positions[i];
    let n = |i: usize| mesh.normals.get(i).copied().unwrap_or(glam::Vec3::ZERO);
    let uv = |i: usize| mesh.uvs.get(i).copied().unwrap_or(glam::Vec2::ZERO);
    let (uv1, color) = (|i: usize| mesh.uv1(i), |i: usize| mesh.color(i));
    let m = f32::from_bits(mesh.triangle_materials[t]);
    out.push([p(a).x, p(a).y, p(a).z, m]);
    out.push(p(b).extend(0.0).into());
    out.push(p(c).extend(0.0).into());
    out.push(n(a).extend(0.0).into());
    out.push(n(b).extend(0.0).into());
    out.push(n(c).extend(0.0).into());
    out.push([uv(a).x, uv(a).y, uv(b).x, uv(b).y]);
    out.push([uv(c).x, uv(c).y, uv1(a).x, uv1(a).y]);
    let tan = |i: usize| mesh.tangents.get(i).copied().unwrap_or(glam::Vec4::ZERO);
    out.extend([tan(a).to_array(), tan(b).to_array(), tan(c).to_array()]);
    out.push([uv1(b).x, uv1(b).y, uv1(c).x, uv1(c).y]);
    out.extend([color(a), color(b), color(c)].map(|c| c.extend(1.0).to_array()));
}

const TRIANGLE_VEC4S: usize = 15;

/// `scene_materials`' vec4s per material.
const MATERIAL_VEC4S: usize = 13;

/// A texture reference's coordinates as `scene_materials` holds them: the
/// mapping's rows, the set's bits in the first row's w.
fn pack_uv_mapping(m: &UvMapping) -> [[f32; 4]; 2] {
    let [r0, r1] = m.rows;
    [r0.extend(f32::from_bits(m.set)).to_array(), r1.extend(0.0).to_array()]
}

/// A texture's sampler as the header word `scene.wgsl` reads: wrap u (0
/// repeat, 1 mirrored repeat, 2 clamp to edge), wrap v << 2, nearest << 4.
fn sampler_bits(s: &Sampler) -> u32 {
    let wrap = |w: Wrap| match w {
        Wrap::Repeat => 0u32,
        Wrap::MirroredRepeat => 1,
        Wrap::ClampToEdge => 2,
    };
    wrap(s.wrap_u) | wrap(s.wrap_v) << 2 | u32::from(s.filter == Filter::Nearest) << 4
}

/// `scene_materials`: [`MATERIAL_VEC4S`] vec4s per material (one zero vec4
/// for a scene without materials).
fn pack_materials(scene: &Scene) -> Vec<[f32; 4]> {
    let tex_bits = |t: Option<usize>| match t {
        Some(t) if t < scene.textures.len() => f32::from_bits(t as u32),
        _ => f32::from_bits(u32::MAX),
    };
    let mut materials: Vec<[f32; 4]> = Vec::with_capacity(scene.materials.len().max(1) * MATERIAL_VEC4S);
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
        materials.push([f32::from_bits(model), m.metallic, m.roughness, tex_bits(m.metallic_roughness_texture)]);
        materials.push(e.extend(tex_bits(m.emissive_texture)).into());
        materials.push([tex_bits(m.normal_texture), m.normal_scale, tex_bits(m.bump_texture), m.bump_multiplier]);
        for uv in [&m.base_color_uv, &m.emissive_uv, &m.normal_uv, &m.metallic_roughness_uv] {
            materials.extend(pack_uv_mapping(uv));
        }
    }
    if materials.is_empty() {
        materials.push([0.0; 4]);
    }
    materials
}

/// `scene_textures`: the sRGB table, the counts, the texture headers, the GGX
/// albedo table, the texels and the sky map's (the layout `scene.wgsl`
/// documents); and where the sky map starts with its width, if there is one.
fn pack_textures(scene: &Scene, instance_records: u32) -> (Vec<u32>, Option<SkyMapPlace>) {
    let lut = srgb8_to_linear_table();
    let table = specular_albedo_table();
    let mut words: Vec<u32> = lut.iter().map(|v| v.to_bits()).collect();
    let headers = 260 + 4 * scene.textures.len();
    words.extend([scene.textures.len() as u32, ALBEDO_TABLE_SIZE as u32, headers as u32, instance_records]);
    let mut first = headers + table.len() * 2;
    for t in &scene.textures {
        words.extend([t.width, t.height, first as u32, sampler_bits(&t.sampler)]);
        first += t.texels.len();
    }
    for ab in table {
        words.extend([ab[0].to_bits(), ab[1].to_bits()]);
    }
    for t in &scene.textures {
        words.extend(t.texels.iter().map(|c| c[0] as u32 | (c[1] as u32) << 8 | (c[2] as u32) << 16));
    }
    let sky_map = scene.sky_map.as_ref().map(|m| {
        let place = SkyMapPlace { first_word: words.len() as u32, width: m.map.size().0 };
        words.extend(m.map.texels().iter().flat_map(|t| t.to_array().map(f32::to_bits)));
        // Its sampling density's CDFs, as f32: the rows' (H + 1), then each row's (W + 1).
        let (marginal, rows) = m.map.sampling_cdfs();
        words.extend(marginal.iter().chain(rows).map(|&c| (c as f32).to_bits()));
        place
    });
    (words, sky_map)
}

/// Where a scene's environment map lies in `scene_textures`: its first word
/// and its width (three f32 words a texel, row-major from the top row).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct SkyMapPlace {
    first_word: u32,
    width: u32,
}

/// `scene_lights`: the punctual lights, then the emitters' power-weighted
/// distribution (`Scene::emitter_powers`, as the CPU's AreaLights); and the
/// emitter count.
fn pack_lights(scene: &Scene, sky_map: Option<SkyMapPlace>) -> (Vec<[f32; 4]>, usize) {
    let (emitters, weights) = scene.emitter_powers();
    let distribution = Distribution1d::new(&weights);
    let mut lights = pack_punctual_lights(scene, sky_map);
    lights[0][1] = f32::from_bits(emitters.len() as u32);
    let mut cdf = 0.0f32;
    for (i, &t) in emitters.iter().enumerate() {
        let pmf = distribution.pmf(i);
        cdf = if i + 1 == emitters.len() { 1.0 } else { cdf + pmf };
        lights.push([f32::from_bits(t), cdf, pmf / scene.mesh.area(t as usize), 0.0]);
    }
    (lights, emitters.len())
}

/// Whether an emitting triangle belongs to a moving object (its area, and so
/// the emitters' distribution, may change per frame: `DirectLighting::for_frame`).
fn emitter_moves(scene: &Scene) -> bool {
    scene
        .objects
        .iter()
        .filter(|o| o.is_animated())
        .any(|o| o.triangles().any(|t| scene.material(scene.mesh.triangle_materials[t]).is_emissive()))
}

/// The scene's shading data on the device.
pub struct GpuScene {
    /// Triangles of the scene's own mesh.
    pub triangles: usize,
    /// Emitting triangles (the area lights).
    pub emitters: usize,
    bytes: u64,
    bind_group: wgpu::BindGroup,
    lights: wgpu::Buffer,
    triangle_buffer: wgpu::Buffer,
    /// Triangle ranges of the moving objects (rewritten by `pose_geometry`).
    moving: Vec<std::ops::Range<usize>>,
    /// An emitter moves: `pose_lights` rewrites the emitters' distribution too.
    emitter_moves: bool,
    /// Where the sky map lies in `scene_textures`, if the scene has one.
    sky_map: Option<SkyMapPlace>,
    /// `scene_textures`, which `sky_from_cubemap` writes a sky map into.
    textures: wgpu::Buffer,
}

/// `scene_lights`' header, sky and punctual lights (emitters follow them).
/// With a sky map (`sky_map`: where it lies in `scene_textures`), the sky
/// vec4 holds its intensity and the sine and cosine of minus its rotation
/// (`SkyMap::radiance`'s turn into the map's frame).
fn pack_punctual_lights(scene: &Scene, sky_map: Option<SkyMapPlace>) -> Vec<[f32; 4]> {
    let (map_first, map_width) = sky_map.map_or((u32::MAX, 0), |p| (p.first_word, p.width));
    let sky: [f32; 4] = match (&scene.sky_map, sky_map) {
        (Some(m), Some(_)) => {
            let (sin, cos) = (-m.rotation_deg.to_radians()).sin_cos();
            [m.intensity, sin, cos, 0.0]
        }
        _ => scene.sky_radiance.extend(0.0).into(),
    };
    let header = [f32::from_bits(scene.lights.len() as u32), 0.0, f32::from_bits(map_first), f32::from_bits(map_width)];
    let mut lights: Vec<[f32; 4]> = vec![header, sky];
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

/// `scene_triangles`: the scene mesh's triangles, each prototype's, then the
/// instance records; and where the instance records start (in vec4s).
fn pack_scene_triangles(scene: &Scene) -> (Vec<[f32; 4]>, u32) {
    let mesh = &scene.mesh;
    let nt = mesh.triangle_count();
    let stored = nt + scene.prototypes.iter().map(|p| p.mesh.triangle_count()).sum::<usize>();
    let mut triangles: Vec<[f32; 4]> = Vec::with_capacity(stored.max(1) * TRIANGLE_VEC4S + scene.instances.len() * 7);
    for t in 0..nt {
        pack_triangle(mesh, t, &mut triangles);
    }
    // Each prototype's triangles once, then a placement per instance.
    let mut first_triangle = vec![];
    for proto in &scene.prototypes {
        first_triangle.push((triangles.len() / TRIANGLE_VEC4S) as u32);
        for t in 0..proto.mesh.triangle_count() {
            pack_triangle(&proto.mesh, t, &mut triangles);
        }
    }
    if triangles.is_empty() {
        triangles.push([0.0; 4]);
    }
    let instance_records = triangles.len() as u32;
    for inst in &scene.instances {
        let m = inst.world_from_local.matrix3;
        let first = first_triangle.get(inst.prototype as usize).copied().unwrap_or(0);
        triangles.push(glam::Vec3::from(m.x_axis).extend(f32::from_bits(first)).into());
        triangles.push(glam::Vec3::from(m.y_axis).extend(0.0).into());
        triangles.push(glam::Vec3::from(m.z_axis).extend(0.0).into());
        triangles.push(glam::Vec3::from(inst.world_from_local.translation).extend(0.0).into());
        let n = inst.normal_from_local;
        triangles.extend([n.x_axis, n.y_axis, n.z_axis].map(|c| glam::Vec3::from(c).extend(0.0).to_array()));
    }
    (triangles, instance_records)
}

impl GpuScene {
    /// Uploads `scene`'s triangles, materials, textures and lights in `scene.wgsl`'s layout.
    pub fn upload(ctx: &GpuContext, scene: &Scene) -> Result<Self, GpuError> {
        let (triangles, instance_records) = pack_scene_triangles(scene);
        let materials = pack_materials(scene);
        let (words, sky_map) = pack_textures(scene, instance_records);
        // Lights: punctual lights, then the emitters' power-weighted distribution
        // (`Scene::emitter_powers`, as the CPU's AreaLights).
        let (lights, emitters) = pack_lights(scene, sky_map);
        let textures = if sky_map.is_some() { "its textures and sky map" } else { "its textures" };
        for (what, bytes) in [
            ("the scene's triangles", triangles.len() * 16),
            ("its materials", materials.len() * 16),
            (textures, words.len() * 4),
            ("its lights", lights.len() * 16),
        ] {
            ctx.check_buffer(bytes as u64, &format!("scene {}: {what}", scene.name))?;
        }
        let init = |label: &str, contents: &[u8]| ctx.buffer_with(label, contents, wgpu::BufferUsages::STORAGE);
        let init_rw = |label: &str, contents: &[u8]| {
            ctx.buffer_with(label, contents, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST)
        };
        let buffers = [
            init_rw("scene triangles", bytemuck::cast_slice(&triangles)),
            init("scene materials", bytemuck::cast_slice(&materials)),
            // Read back where a sky map is written on the device (`sky_map_texels`).
            ctx.buffer_with(
                "scene textures",
                bytemuck::cast_slice(&words),
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            ),
            init_rw("scene lights", bytemuck::cast_slice(&lights)),
        ];
        let bind_group =
            crate::gpu_context::buffers_bind_group(ctx, "scene", &scene_bind_group_layout(&ctx.device), &buffers);
        let bytes = buffers.iter().map(|b| b.size()).sum();
        let moving = scene.objects.iter().filter(|o| o.is_animated()).map(|o| o.triangles()).collect();
        let [triangle_buffer, _, textures, lights] = buffers;
        Ok(Self {
            triangles: scene.mesh.triangle_count(),
            emitters,
            bytes,
            bind_group,
            lights,
            triangle_buffer,
            moving,
            emitter_moves: emitter_moves(scene),
            sky_map,
            textures,
        })
    }

    /// Rewrites the punctual lights (and the sky) from `scene` posed at a frame:
    /// the same scene this was uploaded from, its lights moved, dimmed or
    /// switched by their keyframes (the count stays); and, when an emitter is
    /// on a moving object, the emitters' distribution from their posed areas.
    pub fn pose_lights(&self, ctx: &GpuContext, scene: &Scene) -> Result<(), GpuError> {
        let same_map = match (&scene.sky_map, self.sky_map) {
            (Some(m), Some(p)) => m.map.size().0 == p.width,
            (None, None) => true,
            _ => false,
        };
        if !same_map {
            return Err(GpuError::Input(format!(
                "scene {}: its sky map is not the one it was uploaded with (a map's intensity and rotation may change, not the map)",
                scene.name
            )));
        }
        let lights = if self.emitter_moves {
            let (lights, emitters) = pack_lights(scene, self.sky_map);
            if emitters != self.emitters {
                return Err(GpuError::Input(format!(
                    "scene {} has {emitters} emitting triangles at this frame, {} when uploaded",
                    scene.name, self.emitters
                )));
            }
            lights
        } else {
            let mut lights = pack_punctual_lights(scene, self.sky_map);
            lights[0][1] = f32::from_bits(self.emitters as u32);
            lights
        };
        let bytes: &[u8] = bytemuck::cast_slice(&lights);
        if bytes.len() as u64 > self.lights.size() {
            return Err(GpuError::Input(format!(
                "scene {} has {} lights, more than the {} it was uploaded with",
                scene.name,
                scene.lights.len(),
                (self.lights.size() as usize / 16).saturating_sub(2 + self.emitters) / 4
            )));
        }
        ctx.write_buffer(&self.lights, 0, bytes);
        Ok(())
    }

    /// Rewrites the moving objects' triangles from `scene` posed at a frame
    /// (`Scene::set_frame_from`: world-space vertices, normals and tangents),
    /// the same scene this was uploaded from.
    pub fn pose_geometry(&self, ctx: &GpuContext, scene: &Scene) -> Result<(), GpuError> {
        let mut words = vec![];
        for range in &self.moving {
            if range.end > scene.mesh.triangle_count() {
                return Err(GpuError::Input(format!(
                    "scene {} has {} triangles, fewer than the moving objects it was uploaded with",
                    scene.name,
                    scene.mesh.triangle_count()
                )));
            }
            words.clear();
            for t in range.clone() {
                pack_triangle(&scene.mesh, t, &mut words);
            }
            let offset = (range.start * TRIANGLE_VEC4S * 16) as u64;
            ctx.write_buffer(&self.triangle_buffer, offset, bytemuck::cast_slice(&words));
        }
        Ok(())
    }

    /// Whether the scene has moving objects whose triangles `pose_geometry` rewrites.
    pub fn has_moving_geometry(&self) -> bool {
        !self.moving.is_empty()
    }

    /// Where the sky map's texels lie, if the scene has one: `scene_textures`,
    /// the map's first word there and its width (three f32 words a texel,
    /// row-major, half as many rows; `sky_from_cubemap` writes them).
    pub fn sky_map_words(&self) -> Option<(&wgpu::Buffer, u32, u32)> {
        self.sky_map.map(|p| (&self.textures, p.first_word, p.width))
    }

    /// The sky map's texels as the device holds them (a read-back and a
    /// wait: for checks, not for a frame), `None` without a map.
    pub fn sky_map_texels(&self, ctx: &GpuContext) -> Result<Option<Vec<glam::Vec3>>, GpuError> {
        let Some((buffer, first, width)) = self.sky_map_words() else { return Ok(None) };
        let texels = width as u64 * (width / 2) as u64;
        let bytes = ctx.read_back_range(buffer, first as u64 * 4, texels * 12)?;
        let words: &[f32] = bytemuck::cast_slice(&bytes);
        Ok(Some(words.chunks_exact(3).map(|c| glam::Vec3::new(c[0], c[1], c[2])).collect()))
    }

    /// Device memory of the scene's buffers.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    pub(crate) fn bind_group(&self) -> &wgpu::BindGroup {
        &self.bind_group
    }
}
