//! The probegi scene from Bevy's ECS: every entity with `Mesh3d` and a
//! `GlobalTransform` becomes world-space triangles, its
//! `MeshMaterial3d<StandardMaterial>` a probegi material, and Bevy's
//! `PointLight`, `SpotLight` and `DirectionalLight` probegi's punctual lights
//! (units: [`crate::light_units`]).
//!
//! What is read, and how:
//! - Meshes: `TriangleList` topology, `ATTRIBUTE_POSITION` (required),
//!   `ATTRIBUTE_NORMAL` (else smooth, area-weighted face normals), `ATTRIBUTE_UV_0`, indices (else
//!   one triangle per three vertices). Positions go through the entity's
//!   `GlobalTransform`, normals through its inverse transpose; a mirroring
//!   transform reverses the winding so the front face stays the front face.
//!   A mesh whose data Bevy has moved to the render world
//!   (`RenderAssetUsages::RENDER_WORLD` only) cannot be read: an error names it.
//! - `StandardMaterial`: `base_color` (to linear) and `base_color_texture`,
//!   `emissive` and `emissive_texture`, `perceptual_roughness`, `metallic`,
//!   `reflectance` and `specular_tint`, `alpha_mode`. The specular lobe is
//!   Bevy's: a dielectric (`metallic` 0) has F0 = 0.16 × (reflectance ×
//!   tint)² (`calculate_F0_dielectric`), probegi's MTL model with that F0;
//!   a metallic one, or one with a metallic-roughness texture, probegi's
//!   metallic-roughness model, F0 = mix(0.04, base, metallic), which is
//!   Bevy's at its default reflectance 0.5 and white tint (others are not
//!   expressible there and read as that). `metallic_roughness_texture` (G
//!   roughness, B metalness) is kept as its linear values, as probegi reads
//!   it. `AlphaMode::Mask(c)` cuts out below `c`; the blended modes cut out
//!   below 0.5, as probegi's glTF loader reads glTF `BLEND` (the field has no
//!   partial coverage). `unlit` materials keep their base colour as albedo
//!   (they reflect the field's light in probegi, not in Bevy). An entity
//!   without a `StandardMaterial` gets probegi's default grey 0.5.
//! - Textures: `Rgba8UnormSrgb` and `Rgba8Unorm` images with their data in the
//!   main world; others are an error that names the entity and the format.
//!
//! Deliberate limits: normal maps are not read (the field's surfaces keep
//! their interpolated normals).

use std::collections::HashMap;

use bevy::asset::{AssetId, Assets, UntypedAssetId};
use bevy::image::Image;
use bevy::mesh::{Indices, Mesh, PrimitiveTopology, VertexAttributeValues};
use bevy::pbr::StandardMaterial;
use bevy::render::render_resource::TextureFormat;
use glam::{Mat3, Mat4, Vec2, Vec3};
use probegi_scene::material::{AlphaMode, SpecularModel};
use probegi_scene::texture::{Sampler, Texture};
use probegi_scene::{Material, Scene};
use probegi_scene::{ObjectAnimation, SceneObject, TransformKeyframe};

/// Why part of the ECS could not become probegi geometry: the entity (its
/// `Name`, else its id) and what was wrong.
#[derive(Clone, Debug, PartialEq)]
pub struct ExtractError {
    /// The entity's `Name`, or its id.
    pub entity: String,
    /// What was wrong with it.
    pub what: String,
}

impl std::fmt::Display for ExtractError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "probegi-bevy: entity {}: {}", self.entity, self.what)
    }
}

impl std::error::Error for ExtractError {}

/// One mesh entity as the extraction reads it.
pub struct MeshEntity<'a> {
    /// The entity's `Name`, or its id (for messages).
    pub name: String,
    /// Its mesh asset.
    pub mesh: &'a Mesh,
    /// Its `GlobalTransform` as a matrix.
    pub world_from_local: Mat4,
    /// Its `StandardMaterial` (a `ProbegiMaterial`'s base), if it has one,
    /// with its asset's id.
    pub material: Option<(UntypedAssetId, &'a StandardMaterial)>,
}

/// Builds a probegi scene up from mesh entities, sharing materials and
/// textures between the entities that use the same assets.
pub struct SceneBuilder {
    scene: Scene,
    materials: HashMap<Option<UntypedAssetId>, u32>,
    /// Each image's texture: sRGB-encoded (`false`, colours) or its linear
    /// values as they are (`true`, the metallic-roughness channels).
    textures: HashMap<(AssetId<Image>, bool), usize>,
    /// The camera's exposure, for display-weighted emissives
    /// (`light_units::emissive_luminance`).
    camera_exposure: f32,
}

impl SceneBuilder {
    /// An empty scene named `name`, its sky the constant `sky_radiance`.
    pub fn new(name: &str, sky_radiance: Vec3) -> Self {
        let scene = Scene { name: name.to_owned(), sky_radiance, ..Scene::default() };
        let camera_exposure = bevy::camera::Exposure::default().exposure();
        Self { scene, materials: HashMap::new(), textures: HashMap::new(), camera_exposure }
    }

    /// Reads display-weighted emissives through a camera of `exposure`
    /// (Bevy's `Exposure::exposure()`; Bevy's default camera's without it).
    pub fn with_camera_exposure(mut self, exposure: f32) -> Self {
        self.camera_exposure = exposure;
        self
    }

    /// Adds `entity`'s triangles in world space, with its material.
    pub fn add_mesh(&mut self, entity: &MeshEntity<'_>, images: &Assets<Image>) -> Result<(), ExtractError> {
        let error = |what: String| ExtractError { entity: entity.name.clone(), what };
        let material = self.material_index(entity, images).map_err(error)?;
        let mesh = entity.mesh;
        if mesh.primitive_topology() != PrimitiveTopology::TriangleList {
            return Err(error(format!(
                "its mesh is {:?}; the field traces TriangleList meshes only",
                mesh.primitive_topology()
            )));
        }
        let positions = float3(mesh, Mesh::ATTRIBUTE_POSITION)
            .map_err(error)?
            .ok_or_else(|| error("its mesh has no ATTRIBUTE_POSITION".to_owned()))?;
        let normals = float3(mesh, Mesh::ATTRIBUTE_NORMAL).map_err(error)?;
        let uvs = float2(mesh, Mesh::ATTRIBUTE_UV_0).map_err(error)?;
        let triangles = triangle_indices(mesh, positions.len()).map_err(error)?;
        let m = entity.world_from_local;
        if !m.is_finite() || m.determinant() == 0.0 {
            return Err(error("its GlobalTransform is singular or not finite".to_owned()));
        }
        let normal_matrix = Mat3::from_mat4(m).inverse().transpose();
        let mirrored = m.determinant() < 0.0;
        let out = &mut self.scene.mesh;
        let base = out.positions.len() as u32;
        out.positions.extend(positions.iter().map(|p| m.transform_point3(Vec3::from(*p))));
        match &normals {
            Some(n) => out.normals.extend(n.iter().map(|n| (normal_matrix * Vec3::from(*n)).normalize_or_zero())),
            None => out.normals.extend(std::iter::repeat_n(Vec3::ZERO, positions.len())),
        }
        match &uvs {
            Some(uv) => out.uvs.extend(uv.iter().map(|t| Vec2::from(*t))),
            None => out.uvs.extend(std::iter::repeat_n(Vec2::ZERO, positions.len())),
        }
        for t in &triangles {
            let [a, b, c] = t.map(|i| base + i);
            let corners = if mirrored { [a, c, b] } else { [a, b, c] };
            if normals.is_none() {
                add_face_normal(out, corners);
            }
            out.triangles.push(corners);
            out.triangle_materials.push(material);
        }
        if normals.is_none() {
            for n in &mut out.normals[base as usize..] {
                *n = n.normalize_or_zero();
            }
        }
        Ok(())
    }

    /// Adds `entity` as a moving object (probegi's top level: its own BLAS,
    /// placed every frame by a TLAS instance): its triangles in world space
    /// as they are now, its rest pose, and an animation of one key that
    /// [`moving_key`] sets to each frame's pose. Returns the object's index.
    pub fn add_moving_mesh(&mut self, entity: &MeshEntity<'_>, images: &Assets<Image>) -> Result<usize, ExtractError> {
        let (first_triangle, first_vertex) = (self.scene.mesh.triangles.len(), self.scene.mesh.positions.len());
        self.add_mesh(entity, images)?;
        let mesh = &self.scene.mesh;
        let rest_key = TransformKeyframe { frame: 0.0, translation: Some(Vec3::ZERO), rotation: None, scale: None };
        self.scene.objects.push(SceneObject {
            name: entity.name.clone(),
            first_triangle: first_triangle as u32,
            triangle_count: (mesh.triangles.len() - first_triangle) as u32,
            first_vertex: first_vertex as u32,
            vertex_count: (mesh.positions.len() - first_vertex) as u32,
            pivot_m: Vec3::ZERO,
            animation: ObjectAnimation { keyframes: vec![rest_key], ..Default::default() },
            placement: Mat4::IDENTITY,
        });
        Ok(self.scene.objects.len() - 1)
    }

    /// The scene built so far.
    pub fn finish(self) -> Scene {
        self.scene
    }

    fn material_index(&mut self, entity: &MeshEntity<'_>, images: &Assets<Image>) -> Result<u32, String> {
        let key = entity.material.map(|(id, _)| id);
        if let Some(i) = self.materials.get(&key) {
            return Ok(*i);
        }
        let material = match entity.material {
            Some((id, m)) => self.material(&format!("{id:?}"), m, images)?,
            None => Material::default_grey("default grey"),
        };
        let i = self.scene.materials.len() as u32;
        self.scene.materials.push(material);
        self.materials.insert(key, i);
        Ok(i)
    }

    /// A probegi material from a `StandardMaterial` (see the module docs).
    fn material(&mut self, name: &str, m: &StandardMaterial, images: &Assets<Image>) -> Result<Material, String> {
        let base = m.base_color.to_linear();
        let cutoff = match m.alpha_mode {
            bevy::prelude::AlphaMode::Opaque => None,
            bevy::prelude::AlphaMode::Mask(c) => Some(c),
            _ => Some(0.5),
        };
        let mut out = Material {
            base_color_factor: Vec3::new(base.red, base.green, base.blue),
            alpha_factor: base.alpha,
            emissive_factor: crate::light_units::emissive_luminance(
                Vec3::new(m.emissive.red, m.emissive.green, m.emissive.blue),
                m.emissive_exposure_weight,
                self.camera_exposure,
            ),
            roughness: m.perceptual_roughness,
            metallic: m.metallic,
            specular_model: SpecularModel::MetallicRoughness,
            specular_color: Vec3::ZERO,
            alpha_mode: cutoff.map_or(AlphaMode::Opaque, |cutoff| AlphaMode::Mask { cutoff }),
            ..Material::default_grey(name)
        };
        // Bevy's metallic-roughness texture: roughness in G, metalness in B,
        // linear (probegi reads its bytes as they are).
        let mr = m.metallic_roughness_texture.as_ref();
        out.metallic_roughness_texture = mr.map(|h| self.texture(h.id(), images, true)).transpose()?.flatten();
        // A dielectric without that texture: Bevy's own F0 (MTL model).
        if m.metallic == 0.0 && m.metallic_roughness_texture.is_none() {
            (out.specular_model, out.specular_color) = (SpecularModel::Mtl, dielectric_f0(m));
        }
        // A texture still loading is left out until it arrives (its asset
        // event rebuilds the geometry then), as a loading mesh is.
        if let Some(t) =
            m.base_color_texture.as_ref().map(|h| self.texture(h.id(), images, false)).transpose()?.flatten()
        {
            out.base_color_texture = Some(t);
            out.alpha_texture = cutoff.is_some().then_some(t);
        }
        out.emissive_texture =
            m.emissive_texture.as_ref().map(|h| self.texture(h.id(), images, false)).transpose()?.flatten();
        Ok(out)
    }

    /// The image's index in the scene's textures, its values `linear` as
    /// they are or sRGB-encoded; `None` while it loads.
    fn texture(&mut self, id: AssetId<Image>, images: &Assets<Image>, linear: bool) -> Result<Option<usize>, String> {
        if let Some(i) = self.textures.get(&(id, linear)) {
            return Ok(Some(*i));
        }
        let Some(image) = images.get(id) else { return Ok(None) };
        let texture = texture_from_image(image, &format!("{id:?}"), linear)?;
        let i = self.scene.textures.len();
        self.scene.textures.push(texture);
        self.textures.insert((id, linear), i);
        Ok(Some(i))
    }
}

/// A probegi texture (RGB8 and alpha) from an RGBA8 Bevy image: colours
/// sRGB-encoded, or (`linear`) its linear values, as probegi reads a
/// metallic-roughness texture.
fn texture_from_image(image: &Image, source: &str, linear: bool) -> Result<Texture, String> {
    let format = image.texture_descriptor.format;
    let srgb = match format {
        TextureFormat::Rgba8UnormSrgb => true,
        TextureFormat::Rgba8Unorm => false,
        other => {
            return Err(format!("its texture {source} is {other:?}; the field reads Rgba8UnormSrgb and Rgba8Unorm"));
        }
    };
    let data = image.data.as_ref().ok_or_else(|| {
        format!("its texture {source} has no data in the main world (RenderAssetUsages::RENDER_WORLD only)")
    })?;
    let (width, height) = (image.width(), image.height());
    if data.len() < width as usize * height as usize * 4 {
        return Err(format!("its texture {source} holds {} bytes for {width}×{height} RGBA8", data.len()));
    }
    let pixels = data.chunks_exact(4).take(width as usize * height as usize);
    // probegi keeps colours sRGB-encoded (a linear Unorm image is encoded)
    // and data textures linear (an sRGB image is decoded, as Bevy samples it).
    let encode = |v: u8| match (srgb, linear) {
        (true, true) => (probegi_core::color::srgb_to_linear(v as f32 / 255.0) * 255.0).round() as u8,
        (false, false) => linear_to_srgb8(v),
        _ => v,
    };
    let texels = pixels.clone().map(|p| [encode(p[0]), encode(p[1]), encode(p[2])]).collect();
    let alpha: Vec<u8> = pixels.map(|p| p[3]).collect();
    let alpha = alpha.iter().any(|a| *a < 255).then_some(alpha);
    Ok(Texture { width, height, texels, alpha, source: source.to_owned(), sampler: Sampler::default() })
}

/// Bevy's F0 of a dielectric `StandardMaterial`: 0.16 × (reflectance ×
/// linear specular tint)² (`bevy_pbr`'s `calculate_F0_dielectric`; the
/// default reflectance 0.5 gives 0.04).
pub fn dielectric_f0(m: &StandardMaterial) -> Vec3 {
    let t = m.specular_tint.to_linear();
    let r = Vec3::new(t.red, t.green, t.blue) * m.reflectance;
    0.16 * r * r
}

fn linear_to_srgb8(v: u8) -> u8 {
    let l = v as f32 / 255.0;
    let s = if l <= 0.003_130_8 { 12.92 * l } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0).round().clamp(0.0, 255.0) as u8
}

fn float3(mesh: &Mesh, id: bevy::mesh::MeshVertexAttribute) -> Result<Option<Vec<[f32; 3]>>, String> {
    match mesh.try_attribute_option(id) {
        Err(e) => Err(format!("its mesh cannot be read in the main world ({e}); keep RenderAssetUsages::MAIN_WORLD")),
        Ok(None) => Ok(None),
        Ok(Some(VertexAttributeValues::Float32x3(v))) => Ok(Some(v.clone())),
        Ok(Some(_)) => Err(format!("its mesh's {} is not Float32x3", id.name)),
    }
}

fn float2(mesh: &Mesh, id: bevy::mesh::MeshVertexAttribute) -> Result<Option<Vec<[f32; 2]>>, String> {
    match mesh.try_attribute_option(id) {
        Err(e) => Err(format!("its mesh cannot be read in the main world ({e}); keep RenderAssetUsages::MAIN_WORLD")),
        Ok(None) => Ok(None),
        Ok(Some(VertexAttributeValues::Float32x2(v))) => Ok(Some(v.clone())),
        Ok(Some(_)) => Err(format!("its mesh's {} is not Float32x2", id.name)),
    }
}

/// The mesh's triangles as local vertex indices, checked against its vertex count.
fn triangle_indices(mesh: &Mesh, vertices: usize) -> Result<Vec<[u32; 3]>, String> {
    let indices: Vec<u32> = match mesh.try_indices_option() {
        Err(e) => return Err(format!("its mesh's indices cannot be read in the main world ({e})")),
        Ok(Some(Indices::U16(v))) => v.iter().map(|i| *i as u32).collect(),
        Ok(Some(Indices::U32(v))) => v.clone(),
        Ok(None) => (0..vertices as u32).collect(),
    };
    if !indices.len().is_multiple_of(3) {
        return Err(format!("its mesh has {} indices, not a multiple of 3", indices.len()));
    }
    if let Some(bad) = indices.iter().find(|i| **i as usize >= vertices) {
        return Err(format!("its mesh indexes vertex {bad} of {vertices}"));
    }
    Ok(indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect())
}

/// Adds the triangle's area-weighted face normal to its corners' (a mesh
/// without normals: smooth normals, normalised once every face is in).
fn add_face_normal(mesh: &mut probegi_scene::mesh::Mesh, [a, b, c]: [u32; 3]) {
    let p = |i: u32| mesh.positions[i as usize];
    let n = (p(b) - p(a)).cross(p(c) - p(a));
    for i in [a, b, c] {
        mesh.normals[i as usize] += n;
    }
}

/// The one key of a moving object (about the origin, as
/// [`SceneBuilder::add_moving_mesh`] sets its pivot) that places it by
/// `world_from_rest`: the entity's transform now times the inverse of its
/// transform when the geometry was built. `None` where that is not a
/// translation, rotation and positive scale (not finite, mirroring, or
/// sheared by a parent's non-uniform scale): the geometry is then made again.
pub fn moving_key(world_from_rest: Mat4) -> Option<TransformKeyframe> {
    let (scale, rotation, translation) = world_from_rest.to_scale_rotation_translation();
    let rebuilt = Mat4::from_scale_rotation_translation(scale, rotation, translation);
    // The linear part must come back (its own size sets the tolerance; the
    // translation comes back as it is).
    let linear = |m: Mat4| Mat3::from_mat4(m);
    let size = linear(world_from_rest).to_cols_array().iter().fold(1.0f32, |m, x| m.max(x.abs()));
    let exact = linear(rebuilt).abs_diff_eq(linear(world_from_rest), 1e-4 * size);
    (world_from_rest.is_finite() && scale.cmpgt(Vec3::ZERO).all() && exact).then_some(TransformKeyframe {
        frame: 0.0,
        translation: Some(translation),
        rotation: Some(rotation),
        scale: Some(scale),
    })
}
