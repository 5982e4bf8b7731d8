//! Materials: glTF metallic-roughness semantics, with the OBJ/MTL fields kept
//! beside them. In this release surfaces shade as two-sided Lambertian with
//! `base_color`; roughness, metallic and the MTL specular fields are stored for
//! the glossy work that follows.

use glam::{Vec2, Vec3};
use probegi_core::bsdf::SurfaceBsdf;

use crate::texture::Texture;

/// How a material's specular lobe is derived (seed 004 §4.4's glossy materials).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpecularModel {
    /// Lambertian only.
    None,
    /// MTL: F0 = `Ks`, diffuse = `Kd`, α from `Ns`.
    Mtl,
    /// glTF metallic-roughness: F0 = lerp(0.04, base, metallic), diffuse = base·(1 − metallic).
    MetallicRoughness,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Linear base colour factor (glTF `baseColorFactor.rgb`, MTL `Kd`).
    pub base_color_factor: Vec3,
    /// Index into `Scene::textures`; multiplied by the factor (MTL `map_Kd`, per the MTL
    /// specification "the texture map is multiplied by the Kd value").
    pub base_color_texture: Option<usize>,
    /// Linear emissive factor (glTF `emissiveFactor`, MTL `Ke`), W·sr⁻¹·m⁻² per channel.
    pub emissive_factor: Vec3,
    pub emissive_texture: Option<usize>,
    /// KHR_materials_emissive_strength multiplier; 1 when absent.
    pub emissive_strength: f32,
    /// Perceptual roughness r (GGX α = r²). glTF: `roughnessFactor`; MTL: from the
    /// Phong exponent via the Beckmann equivalence α = sqrt(2 / (Ns + 2)), i.e.
    /// r = (2 / (Ns + 2))^¼.
    pub roughness: f32,
    pub metallic: f32,
    /// MTL `Ks`, kept verbatim.
    pub specular_color: Vec3,
    /// MTL `Ns` (Phong exponent), kept verbatim.
    pub specular_exponent: f32,
    pub specular_model: SpecularModel,
}

impl Material {
    /// The fallback for faces with no or an unknown material: grey 0.5, the default
    /// diffuse reflectance of Mitsuba and pbrt.
    pub fn default_grey(name: &str) -> Self {
        Self {
            name: name.to_string(),
            base_color_factor: Vec3::splat(0.5),
            base_color_texture: None,
            emissive_factor: Vec3::ZERO,
            emissive_texture: None,
            emissive_strength: 1.0,
            roughness: 1.0,
            metallic: 0.0,
            specular_color: Vec3::ZERO,
            specular_exponent: 0.0,
            specular_model: SpecularModel::None,
        }
    }

    pub fn diffuse(name: &str, base_color: Vec3) -> Self {
        Self { base_color_factor: base_color, ..Self::default_grey(name) }
    }

    pub fn emissive(name: &str, base_color: Vec3, emission: Vec3) -> Self {
        Self { emissive_factor: emission, ..Self::diffuse(name, base_color) }
    }

    /// Whether any texel of this material can emit.
    pub fn is_emissive(&self) -> bool {
        (self.emissive_factor * self.emissive_strength).max_element() > 0.0
    }

    /// Diffuse albedo at `uv` (factor × texture), linear.
    pub fn base_color(&self, textures: &[Texture], uv: Vec2) -> Vec3 {
        match self.base_color_texture.and_then(|t| textures.get(t)) {
            Some(t) => self.base_color_factor * t.sample_bilinear(uv),
            None => self.base_color_factor,
        }
    }

    /// The BSDF at `uv` (see `probegi_core::bsdf`).
    pub fn bsdf(&self, textures: &[Texture], uv: Vec2) -> SurfaceBsdf {
        let base = self.base_color(textures, uv);
        let alpha = (self.roughness * self.roughness).clamp(probegi_core::bsdf::MIN_ALPHA, 1.0);
        match self.specular_model {
            SpecularModel::None => SurfaceBsdf::lambertian(base),
            SpecularModel::Mtl => SurfaceBsdf { diffuse: base, specular_f0: self.specular_color, alpha },
            SpecularModel::MetallicRoughness => SurfaceBsdf {
                diffuse: base * (1.0 - self.metallic),
                specular_f0: Vec3::splat(0.04).lerp(base, self.metallic),
                alpha,
            },
        }
    }

    /// Emitted radiance at `uv` from the front face (factor × texture × strength).
    pub fn emission(&self, textures: &[Texture], uv: Vec2) -> Vec3 {
        let e = self.emissive_factor * self.emissive_strength;
        if e == Vec3::ZERO {
            return e;
        }
        match self.emissive_texture.and_then(|t| textures.get(t)) {
            Some(t) => e * t.sample_bilinear(uv),
            None => e,
        }
    }

    /// Mean emitted radiance over the texture, for weighting area lights by power.
    pub fn mean_emission(&self, textures: &[Texture]) -> Vec3 {
        let e = self.emissive_factor * self.emissive_strength;
        match self.emissive_texture.and_then(|t| textures.get(t)) {
            Some(t) => e * t.mean_linear(),
            None => e,
        }
    }
}
