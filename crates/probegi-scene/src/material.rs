//! Materials: glTF metallic-roughness semantics, with the OBJ/MTL fields kept
//! beside them. Surfaces shade as two-sided Lambertian with `base_color`, plus
//! the GGX lobe of [`SpecularModel`].
//!
//! Alpha cutouts ([`AlphaMode::Mask`]): coverage = `alpha_factor` × the alpha
//! texture's coverage (its alpha channel, else its grey level), filtered
//! bilinearly in unorm (not sRGB-decoded); a point is opaque when coverage ≥
//! the cutoff, else every ray passes through it (the tracers test it inside
//! traversal, see `bvh.rs`). glTF: `alphaMode` MASK with `alphaCutoff`
//! (default 0.5), BLEND treated as MASK at 0.5 (a ray tracer without ordered
//! compositing; RTXGI and most path tracers do the same for any-hit alpha),
//! OPAQUE ignores alpha. MTL: `map_d`, else the alpha channel of `map_Kd`
//! when it has one (the convention of most OBJ viewers), times `d` (or
//! 1 − `Tr`), cut at 0.5.
//!
//! Normal perturbation (`Scene::surface_point`): glTF `normalTexture` in
//! tangent space with its `scale`; MTL `bump`/`map_bump` height maps with
//! `-bm` read with the scale McGuire's G3D (the engine the shared archive
//! scenes were published for) uses by default when it turns a bump map into a
//! normal map ([`BUMP_WHITE_HEIGHT_REL`]).
//!
//! Deliberate deviation from pbrt/Mitsuba (`bumpmap`, height in scene units
//! per unit of grey, `scale = bm`): with `bm` = 1, as the Sponza MTL leaves it,
//! that reading tilts the median visible normal of Sponza by 37° (60 % of the
//! pixels by more than 30°) and makes the reference 12–21 % darker than face
//! normals, three times Mitsuba's noise floor in FLIP — a height unit of one
//! metre is not what those files meant. G3D's reading is independent of the
//! scene's units and its UV density.

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

/// How a material's alpha is used.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AlphaMode {
    /// Alpha ignored: every point is opaque.
    Opaque,
    /// Opaque where coverage ≥ `cutoff`, absent elsewhere.
    Mask { cutoff: f32 },
}

/// Height of a white texel in a height map, as a fraction of the map's larger
/// side in texels: a grey step of 1 over one texel rises `0.02 · max(w, h)`
/// texels. The default of G3D's `BumpMapPreprocess::zExtentPixels` (−0.02,
/// where negative means relative to the larger side); MTL `-bm` multiplies it
/// (our reading of the multiplier).
pub const BUMP_WHITE_HEIGHT_REL: f32 = 0.02;

/// The cutoff glTF gives `alphaCutoff` when absent, and the one MTL cutouts use.
pub const DEFAULT_ALPHA_CUTOFF: f32 = 0.5;

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
    pub alpha_mode: AlphaMode,
    /// Constant coverage factor (glTF `baseColorFactor.a`, MTL `d` or 1 − `Tr`).
    pub alpha_factor: f32,
    /// Index into `Scene::textures` whose coverage multiplies `alpha_factor`.
    pub alpha_texture: Option<usize>,
    /// Tangent-space normal map (glTF `normalTexture`), read as unorm.
    pub normal_texture: Option<usize>,
    /// glTF `normalTexture.scale`: scales the map's X and Y.
    pub normal_scale: f32,
    /// Height map (MTL `bump` / `map_bump`), grey level read as unorm.
    pub bump_texture: Option<usize>,
    /// MTL `-bm`: multiplies the height map's white height.
    pub bump_multiplier: f32,
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
            alpha_mode: AlphaMode::Opaque,
            alpha_factor: 1.0,
            alpha_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            bump_texture: None,
            bump_multiplier: 1.0,
        }
    }

    /// Shifts every texture index by `offset` (the material's textures moved).
    pub fn offset_textures(&mut self, offset: usize) {
        for t in [
            &mut self.base_color_texture,
            &mut self.emissive_texture,
            &mut self.alpha_texture,
            &mut self.normal_texture,
            &mut self.bump_texture,
        ] {
            *t = t.map(|i| i + offset);
        }
    }

    /// Whether some points of this material are cut out.
    pub fn has_cutout(&self) -> bool {
        match self.alpha_mode {
            AlphaMode::Opaque => false,
            AlphaMode::Mask { cutoff } => self.alpha_texture.is_some() || self.alpha_factor < cutoff,
        }
    }

    /// Whether a normal or bump map perturbs this material's shading normals.
    pub fn perturbs_normals(&self) -> bool {
        self.normal_texture.is_some() || self.bump_texture.is_some()
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
