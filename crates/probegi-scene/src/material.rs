//! Materials: glTF metallic-roughness semantics (glTF 2.0 §3.9.2), with the
//! OBJ/MTL fields kept beside them. Surfaces shade as two-sided Lambertian with
//! `base_color`, plus the GGX lobe of [`SpecularModel`].
//!
//! Inputs at a surface point ([`VertexAttributes`]): two texture coordinate
//! sets and a vertex colour. Base colour = factor × `COLOR_0` × texture
//! (§3.9.2: the vertex colour is "an additional linear multiplier"); roughness
//! = `roughness` × the metallic-roughness texture's green channel, metalness =
//! `metallic` × its blue channel, both read as unorm (§3.9.2: that texture is
//! linear). Each texture reference has a [`UvMapping`]: which coordinate set
//! it reads (`textureInfo.texCoord`) and the KHR_texture_transform affine map
//! applied to it.
//!
//! Alpha cutouts ([`AlphaMode::Mask`]): coverage = `alpha_factor` × the alpha
//! texture's coverage (its alpha channel, else its grey level), filtered
//! bilinearly in unorm (not sRGB-decoded); a point is opaque when coverage ≥
//! the cutoff, else every ray passes through it (the tracers test it inside
//! traversal, see `bvh/cutouts.rs`). glTF: `alphaMode` MASK with `alphaCutoff`
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

/// The interpolated vertex attributes a material reads at a surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VertexAttributes {
    /// Texture coordinate sets 0 and 1 (glTF `TEXCOORD_0`, `TEXCOORD_1`; a mesh
    /// without set 1 repeats set 0).
    pub uv: [Vec2; 2],
    /// Linear vertex colour (glTF `COLOR_0`'s RGB; white where there is none).
    pub color: Vec3,
}

impl VertexAttributes {
    /// One coordinate set (both sets `uv`) and a white vertex colour.
    pub fn at_uv(uv: Vec2) -> Self {
        Self { uv: [uv, uv], color: Vec3::ONE }
    }
}

/// Which texture coordinate set a texture reference reads and how it is
/// transformed: `uv' = (rows[0] · (u, v, 1), rows[1] · (u, v, 1))`.
///
/// KHR_texture_transform: the matrix is translation × rotation × scale, with
/// the rotation turning the UVs counter-clockwise by `rotation` radians (the
/// image clockwise): `u' = sx·cos(r)·u + sy·sin(r)·v + ox`, `v' = −sx·sin(r)·u +
/// sy·cos(r)·v + oy`. (The extension's GLSL builds its rotation with `mat3`,
/// which is column-major; read that way it would turn the other way, and its
/// own example, "only the lower left quadrant of the source image", would
/// fall outside the image. We follow the example; Khronos' TextureTransformTest
/// sample checks the direction, see `tests/it/khronos_gltf_samples.rs`.)
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvMapping {
    /// 0 or 1: which of [`VertexAttributes::uv`] it reads.
    pub set: u32,
    /// The two rows of the 2×3 affine matrix applied to `(u, v, 1)`.
    pub rows: [Vec3; 2],
}

impl Default for UvMapping {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl UvMapping {
    /// Set 0, untransformed.
    pub const IDENTITY: Self = Self { set: 0, rows: [Vec3::X, Vec3::Y] };

    /// KHR_texture_transform's `offset`, `rotation` (radians) and `scale` on
    /// coordinate set `set`.
    pub fn texture_transform(set: u32, offset: Vec2, rotation: f32, scale: Vec2) -> Self {
        let (sin, cos) = rotation.sin_cos();
        Self {
            set,
            rows: [
                Vec3::new(scale.x * cos, scale.y * sin, offset.x),
                Vec3::new(-scale.x * sin, scale.y * cos, offset.y),
            ],
        }
    }

    /// Whether it leaves its set's coordinates as they are.
    pub fn is_untransformed(&self) -> bool {
        self.rows == Self::IDENTITY.rows
    }

    /// The texture coordinates it gives at a point. An untransformed mapping
    /// returns the set's coordinates exactly (even non-finite ones).
    pub fn apply(&self, at: &VertexAttributes) -> Vec2 {
        let uv = at.uv[(self.set as usize).min(1)];
        if self.is_untransformed() {
            return uv;
        }
        let [r0, r1] = self.rows;
        Vec2::new(r0.x * uv.x + r0.y * uv.y + r0.z, r1.x * uv.x + r1.y * uv.y + r1.z)
    }
}

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
    Mask {
        /// Coverage at or above this is opaque.
        cutoff: f32,
    },
}

/// Height of a white texel in a height map, as a fraction of the map's larger
/// side in texels: a grey step of 1 over one texel rises `0.02 · max(w, h)`
/// texels. The default of G3D's `BumpMapPreprocess::zExtentPixels` (−0.02,
/// where negative means relative to the larger side); MTL `-bm` multiplies it
/// (our reading of the multiplier).
pub const BUMP_WHITE_HEIGHT_REL: f32 = 0.02;

/// The cutoff glTF gives `alphaCutoff` when absent, and the one MTL cutouts use.
pub const DEFAULT_ALPHA_CUTOFF: f32 = 0.5;

/// A surface's appearance: diffuse base colour, emission, specular lobe, alpha
/// cutout and normal perturbation, each a factor and an optional texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The name the file gave it, for messages.
    pub name: String,
    /// Linear base colour factor (glTF `baseColorFactor.rgb`, MTL `Kd`).
    pub base_color_factor: Vec3,
    /// Index into `Scene::textures`; multiplied by the factor (MTL `map_Kd`, per the MTL
    /// specification "the texture map is multiplied by the Kd value").
    pub base_color_texture: Option<usize>,
    /// Linear emissive factor (glTF `emissiveFactor`, MTL `Ke`), W·sr⁻¹·m⁻² per channel.
    pub emissive_factor: Vec3,
    /// Index into `Scene::textures`; multiplied by `emissive_factor` (glTF `emissiveTexture`, MTL `map_Ke`).
    pub emissive_texture: Option<usize>,
    /// KHR_materials_emissive_strength multiplier; 1 when absent.
    pub emissive_strength: f32,
    /// Perceptual roughness r (GGX α = r²). glTF: `roughnessFactor`; MTL: from the
    /// Phong exponent via the Beckmann equivalence α = sqrt(2 / (Ns + 2)), i.e.
    /// r = (2 / (Ns + 2))^¼.
    pub roughness: f32,
    /// Metalness in [0, 1] (glTF `metallicFactor`; 0 for MTL).
    pub metallic: f32,
    /// MTL `Ks`, kept verbatim.
    pub specular_color: Vec3,
    /// MTL `Ns` (Phong exponent), kept verbatim.
    pub specular_exponent: f32,
    /// How the specular lobe is derived from the fields above.
    pub specular_model: SpecularModel,
    /// Whether coverage cuts points out.
    pub alpha_mode: AlphaMode,
    /// Constant coverage factor (glTF `baseColorFactor.a`, MTL `d` or 1 − `Tr`).
    pub alpha_factor: f32,
    /// Index into `Scene::textures` whose coverage multiplies `alpha_factor`.
    pub alpha_texture: Option<usize>,
    /// Tangent-space normal map (glTF `normalTexture`), read as unorm.
    pub normal_texture: Option<usize>,
    /// glTF `metallicRoughnessTexture`: green × `roughness`, blue × `metallic`,
    /// read as unorm (only [`SpecularModel::MetallicRoughness`] reads it).
    pub metallic_roughness_texture: Option<usize>,
    /// Coordinates of `base_color_texture` (and of the alpha texture, which is
    /// the base-colour texture in glTF).
    pub base_color_uv: UvMapping,
    /// Coordinates of `emissive_texture`.
    pub emissive_uv: UvMapping,
    /// Coordinates of `normal_texture` and `bump_texture`.
    pub normal_uv: UvMapping,
    /// Coordinates of `metallic_roughness_texture`.
    pub metallic_roughness_uv: UvMapping,
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
            metallic_roughness_texture: None,
            base_color_uv: UvMapping::IDENTITY,
            emissive_uv: UvMapping::IDENTITY,
            normal_uv: UvMapping::IDENTITY,
            metallic_roughness_uv: UvMapping::IDENTITY,
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
            &mut self.metallic_roughness_texture,
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

    /// A plain Lambertian material of albedo `base_color`.
    pub fn diffuse(name: &str, base_color: Vec3) -> Self {
        Self { base_color_factor: base_color, ..Self::default_grey(name) }
    }

    /// A Lambertian material of albedo `base_color` that emits radiance `emission` (W·sr⁻¹·m⁻²).
    pub fn emissive(name: &str, base_color: Vec3, emission: Vec3) -> Self {
        Self { emissive_factor: emission, ..Self::diffuse(name, base_color) }
    }

    /// Whether any texel of this material can emit.
    pub fn is_emissive(&self) -> bool {
        (self.emissive_factor * self.emissive_strength).max_element() > 0.0
    }

    /// Diffuse albedo at a point (factor × vertex colour × texture), linear.
    pub fn base_color(&self, textures: &[Texture], at: &VertexAttributes) -> Vec3 {
        let c = self.base_color_factor * at.color;
        match self.base_color_texture.and_then(|t| textures.get(t)) {
            Some(t) => c * t.sample(self.base_color_uv.apply(at)),
            None => c,
        }
    }

    /// Perceptual roughness and metalness at a point: the factors, times the
    /// metallic-roughness texture's green and blue channels for glTF materials.
    pub fn roughness_metallic(&self, textures: &[Texture], at: &VertexAttributes) -> (f32, f32) {
        let texture = self.metallic_roughness_texture.and_then(|t| textures.get(t));
        match (self.specular_model, texture) {
            (SpecularModel::MetallicRoughness, Some(t)) => {
                let texel = t.sample_raw(self.metallic_roughness_uv.apply(at));
                (self.roughness * texel.y, self.metallic * texel.z)
            }
            _ => (self.roughness, self.metallic),
        }
    }

    /// The BSDF at a point (see `probegi_core::bsdf`).
    pub fn bsdf(&self, textures: &[Texture], at: &VertexAttributes) -> SurfaceBsdf {
        let base = self.base_color(textures, at);
        let (roughness, metallic) = self.roughness_metallic(textures, at);
        let alpha = (roughness * roughness).clamp(probegi_core::bsdf::MIN_ALPHA, 1.0);
        match self.specular_model {
            SpecularModel::None => SurfaceBsdf::lambertian(base),
            SpecularModel::Mtl => SurfaceBsdf { diffuse: base, specular_f0: self.specular_color, alpha },
            SpecularModel::MetallicRoughness => SurfaceBsdf {
                diffuse: base * (1.0 - metallic),
                specular_f0: Vec3::splat(0.04).lerp(base, metallic),
                alpha,
            },
        }
    }

    /// Emitted radiance at a point from the front face (factor × texture × strength).
    pub fn emission(&self, textures: &[Texture], at: &VertexAttributes) -> Vec3 {
        let e = self.emissive_factor * self.emissive_strength;
        if e == Vec3::ZERO {
            return e;
        }
        match self.emissive_texture.and_then(|t| textures.get(t)) {
            Some(t) => e * t.sample(self.emissive_uv.apply(at)),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_transform_example_reads_the_lower_left_quadrant() {
        // KHR_texture_transform's first example: offset (0, 1), rotation π/2,
        // scale 0.5 "utilizes only the lower left quadrant of the source image".
        let m = UvMapping::texture_transform(0, Vec2::new(0.0, 1.0), std::f32::consts::FRAC_PI_2, Vec2::splat(0.5));
        for (u, v) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (0.3, 0.8)] {
            let t = m.apply(&VertexAttributes::at_uv(Vec2::new(u, v)));
            assert!(
                (-1e-6..=0.5 + 1e-6).contains(&t.x) && (0.5 - 1e-6..=1.0 + 1e-6).contains(&t.y),
                "({u}, {v}) → {t}"
            );
        }
        // Its second example, offset (0, 1) and scale (1, −1), flips v.
        let flip = UvMapping::texture_transform(0, Vec2::new(0.0, 1.0), 0.0, Vec2::new(1.0, -1.0));
        assert_eq!(flip.apply(&VertexAttributes::at_uv(Vec2::new(0.25, 0.125))), Vec2::new(0.25, 0.875));
        // The set is chosen before the transform.
        let at = VertexAttributes { uv: [Vec2::ZERO, Vec2::new(0.5, 0.25)], color: Vec3::ONE };
        let offset = UvMapping::texture_transform(1, Vec2::new(0.25, 0.0), 0.0, Vec2::ONE);
        assert_eq!(offset.apply(&at), Vec2::new(0.75, 0.25));
        assert!(UvMapping::texture_transform(0, Vec2::ZERO, 0.0, Vec2::ONE).is_untransformed());
    }

    #[test]
    fn metallic_roughness_texture_scales_the_factors_by_green_and_blue() {
        // One texel: R (occlusion, unused) 255, G 64 (roughness), B 128 (metalness).
        let texture = Texture::from_rgb8(1, 1, vec![[255, 64, 128]], "mr".into()).expect("texture");
        let mut m = Material {
            roughness: 0.5,
            metallic: 1.0,
            metallic_roughness_texture: Some(0),
            specular_model: SpecularModel::MetallicRoughness,
            ..Material::diffuse("m", Vec3::new(0.8, 0.4, 0.2))
        };
        let at = VertexAttributes { uv: [Vec2::splat(0.5); 2], color: Vec3::new(1.0, 0.5, 1.0) };
        let (r, metal) = m.roughness_metallic(std::slice::from_ref(&texture), &at);
        assert!((r - 0.5 * 64.0 / 255.0).abs() < 1e-6 && (metal - 128.0 / 255.0).abs() < 1e-6, "{r} {metal}");
        let b = m.bsdf(std::slice::from_ref(&texture), &at);
        // COLOR_0 multiplies the base colour: (0.8, 0.2, 0.2), then metalness splits it.
        let base = Vec3::new(0.8, 0.2, 0.2);
        assert!((b.diffuse - base * (1.0 - metal)).abs().max_element() < 1e-6, "{}", b.diffuse);
        assert!((b.alpha - r * r).abs() < 1e-6);
        // Without the texture, the factors alone.
        m.metallic_roughness_texture = None;
        assert_eq!(m.roughness_metallic(&[texture], &at), (0.5, 1.0));
    }
}
