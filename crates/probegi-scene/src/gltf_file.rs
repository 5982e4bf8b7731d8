//! glTF 2.0 loader (.gltf with external or embedded buffers, and .glb): the
//! default scene's node hierarchy with transforms, triangle primitives, metallic-
//! roughness materials with base-colour and emissive textures (texture set 0,
//! repeat addressing), KHR_materials_emissive_strength, KHR_lights_punctual and
//! the first perspective camera.
//!
//! Units: light intensities are used as the spec's photometric numbers without a
//! lm→W conversion (candela → W·sr⁻¹, lux → W·m⁻²), which is what a renderer
//! working in relative radiance expects (see `probegi_core::punctual`).

use std::collections::HashMap;
use std::path::Path;

use glam::{Mat4, Vec2, Vec3};
use probegi_core::camera::Camera;

use crate::error::{Result, SceneError};
use crate::light::{LightKind, PunctualLight};
use crate::material::Material;
use crate::mesh::Mesh;
use crate::scene::Scene;
use crate::texture::Texture;

struct Loader<'a> {
    path: &'a Path,
    buffers: Vec<gltf::buffer::Data>,
    images: Vec<gltf::image::Data>,
    scene: Scene,
    material_ids: HashMap<Option<usize>, u32>,
    texture_ids: HashMap<usize, Option<usize>>,
}

pub fn load_gltf(path: &Path) -> Result<Scene> {
    if !path.exists() {
        return Err(SceneError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "file not found"),
        });
    }
    let (doc, buffers, images) =
        gltf::import(path).map_err(|e| SceneError::Gltf { path: path.to_path_buf(), message: e.to_string() })?;
    let mut loader = Loader {
        path,
        buffers,
        images,
        scene: Scene { name: path.display().to_string(), ..Default::default() },
        material_ids: HashMap::new(),
        texture_ids: HashMap::new(),
    };
    let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => doc.nodes().collect(),
    };
    for node in roots {
        loader.visit(&node, Mat4::IDENTITY)?;
    }
    if loader.scene.mesh.triangles.is_empty() {
        return Err(SceneError::Invalid { path: path.to_path_buf(), message: "no triangle primitives".into() });
    }
    Ok(loader.scene)
}

impl Loader<'_> {
    fn err(&self, message: String) -> SceneError {
        SceneError::Gltf { path: self.path.to_path_buf(), message }
    }

    fn visit(&mut self, node: &gltf::Node, parent: Mat4) -> Result<()> {
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if !world.is_finite() {
            return Err(self.err(format!("node {} has a non-finite transform", node.index())));
        }
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                self.add_primitive(&mesh, &prim, world)?;
            }
        }
        if let Some(light) = node.light() {
            let position = world.transform_point3(Vec3::ZERO);
            let direction = world.transform_vector3(Vec3::NEG_Z).normalize_or_zero();
            let (kind, inner, outer) = match light.kind() {
                gltf::khr_lights_punctual::Kind::Directional => (LightKind::Directional, 0.0, 0.0),
                gltf::khr_lights_punctual::Kind::Point => (LightKind::Point, 0.0, 0.0),
                gltf::khr_lights_punctual::Kind::Spot { inner_cone_angle, outer_cone_angle } => {
                    (LightKind::Spot, inner_cone_angle, outer_cone_angle)
                }
            };
            let l = PunctualLight {
                kind,
                position,
                direction,
                color: Vec3::from(light.color()),
                intensity: light.intensity(),
                range: light.range(),
                inner_cone_angle: inner,
                outer_cone_angle: if kind == LightKind::Spot { outer } else { std::f32::consts::FRAC_PI_4 },
                keyframes: Vec::new(),
            };
            l.validate().map_err(|e| self.err(format!("light {}: {e}", light.index())))?;
            self.scene.lights.push(l);
        }
        if let (Some(cam), None) = (node.camera(), self.scene.camera)
            && let gltf::camera::Projection::Perspective(p) = cam.projection()
        {
            let position = world.transform_point3(Vec3::ZERO);
            self.scene.camera = Some(Camera {
                position,
                target: position + world.transform_vector3(Vec3::NEG_Z).normalize_or_zero(),
                up: world.transform_vector3(Vec3::Y).normalize_or_zero(),
                fov_y_deg: p.yfov().to_degrees(),
            });
        }
        for child in node.children() {
            self.visit(&child, world)?;
        }
        Ok(())
    }

    fn add_primitive(&mut self, mesh: &gltf::Mesh, prim: &gltf::Primitive, world: Mat4) -> Result<()> {
        let what = format!("mesh {} (`{}`) primitive {}", mesh.index(), mesh.name().unwrap_or(""), prim.index());
        if prim.mode() != gltf::mesh::Mode::Triangles {
            self.scene.warnings.push(format!("{}: {what}: mode {:?} skipped", self.path.display(), prim.mode()));
            return Ok(());
        }
        let buffers = &self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<Vec3> = reader
            .read_positions()
            .ok_or_else(|| self.err(format!("{what}: no POSITION attribute")))?
            .map(Vec3::from)
            .collect();
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(self.err(format!("{what}: vertex {i} has a non-finite position")));
        }
        let n = positions.len();
        let normals: Option<Vec<Vec3>> = reader.read_normals().map(|it| it.map(Vec3::from).collect());
        let uvs: Vec<Vec2> = match reader.read_tex_coords(0) {
            Some(tc) => tc.into_f32().map(Vec2::from).collect(),
            None => vec![Vec2::ZERO; n],
        };
        let indices: Vec<u32> = match reader.read_indices() {
            Some(ix) => ix.into_u32().collect(),
            None => (0..n as u32).collect(),
        };
        if !indices.len().is_multiple_of(3) {
            return Err(self.err(format!("{what}: index count {} is not a multiple of 3", indices.len())));
        }
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= n) {
            return Err(self.err(format!("{what}: index {bad} out of range ({n} vertices)")));
        }
        if uvs.len() != n || normals.as_ref().is_some_and(|v| v.len() != n) {
            return Err(self.err(format!("{what}: attribute counts differ from POSITION ({n})")));
        }
        let material = self.material(prim.material())?;
        let mut local = Mesh {
            positions,
            normals: normals.clone().unwrap_or_else(|| vec![Vec3::ZERO; n]),
            uvs,
            triangles: indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
            triangle_materials: vec![material; indices.len() / 3],
        };
        let needs: Vec<bool> = local.normals.iter().map(|v| !(v.is_finite() && v.length_squared() > 0.0)).collect();
        if needs.iter().any(|&b| b) {
            local.generate_normals(&needs);
        }
        local.transform(world);
        self.scene.mesh.append(&local, 0);
        Ok(())
    }

    fn material(&mut self, mat: gltf::Material) -> Result<u32> {
        let key = mat.index();
        if let Some(&id) = self.material_ids.get(&key) {
            return Ok(id);
        }
        let pbr = mat.pbr_metallic_roughness();
        let bc = pbr.base_color_factor();
        let base_color_texture = match pbr.base_color_texture() {
            Some(info) => self.texture(info.texture(), info.tex_coord())?,
            None => None,
        };
        let emissive_texture = match mat.emissive_texture() {
            Some(info) => self.texture(info.texture(), info.tex_coord())?,
            None => None,
        };
        let m = Material {
            name: mat.name().unwrap_or("gltf-default").to_string(),
            base_color_factor: Vec3::new(bc[0], bc[1], bc[2]),
            base_color_texture,
            emissive_factor: Vec3::from(mat.emissive_factor()),
            emissive_texture,
            emissive_strength: mat.emissive_strength().unwrap_or(1.0),
            roughness: pbr.roughness_factor(),
            metallic: pbr.metallic_factor(),
            specular_color: Vec3::ZERO,
            specular_exponent: 0.0,
            specular_model: crate::material::SpecularModel::MetallicRoughness,
        };
        self.scene.materials.push(m);
        let id = (self.scene.materials.len() - 1) as u32;
        self.material_ids.insert(key, id);
        Ok(id)
    }

    fn texture(&mut self, tex: gltf::Texture, tex_coord: u32) -> Result<Option<usize>> {
        if tex_coord != 0 {
            self.scene.warnings.push(format!(
                "{}: texture {} uses TEXCOORD_{tex_coord}; only set 0 is supported, texture ignored",
                self.path.display(),
                tex.index()
            ));
            return Ok(None);
        }
        let img_index = tex.source().index();
        if let Some(&id) = self.texture_ids.get(&img_index) {
            return Ok(id);
        }
        let data = self.images.get(img_index).ok_or_else(|| self.err(format!("image {img_index} missing")))?;
        use gltf::image::Format;
        let channels = match data.format {
            Format::R8 => 1,
            Format::R8G8 => 2,
            Format::R8G8B8 => 3,
            Format::R8G8B8A8 => 4,
            other => {
                self.scene.warnings.push(format!(
                    "{}: image {img_index} has unsupported format {other:?}; texture ignored",
                    self.path.display()
                ));
                self.texture_ids.insert(img_index, None);
                return Ok(None);
            }
        };
        let texels: Vec<[u8; 3]> = data
            .pixels
            .chunks_exact(channels)
            .map(|p| match channels {
                1 | 2 => [p[0]; 3],
                _ => [p[0], p[1], p[2]],
            })
            .collect();
        let t =
            Texture::from_rgb8(data.width, data.height, texels, format!("{} image {img_index}", self.path.display()))
                .ok_or_else(|| self.err(format!("image {img_index}: pixel data does not match its size")))?;
        self.scene.textures.push(t);
        let id = Some(self.scene.textures.len() - 1);
        self.texture_ids.insert(img_index, id);
        Ok(id)
    }
}
