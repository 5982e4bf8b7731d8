//! 8-bit sRGB textures, decoded to linear on lookup, sampled bilinearly with
//! wrap (repeat) addressing.
//!
//! Layout: `texels` is row-major RGB8, row 0 at the top of the image; texture
//! coordinate `v = 0` is the top row (glTF convention; the OBJ loader flips `v`).

use glam::{Vec2, Vec3};
use std::path::Path;
use std::sync::LazyLock;

use crate::error::{Result, SceneError};

static SRGB8_TO_LINEAR: LazyLock<[f32; 256]> = LazyLock::new(probegi_core::color::srgb8_to_linear_table);

#[derive(Clone, Debug)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    /// Row-major sRGB-encoded RGB8, row 0 at the top.
    pub texels: Vec<[u8; 3]>,
    /// Where it came from, for messages.
    pub source: String,
}

impl Texture {
    /// Decodes a PNG or JPEG file. Alpha is dropped.
    pub fn load(path: &Path) -> Result<Self> {
        let img = image::ImageReader::open(path)
            .map_err(|source| SceneError::Io { path: path.to_path_buf(), source })?
            .with_guessed_format()
            .map_err(|source| SceneError::Io { path: path.to_path_buf(), source })?
            .decode()
            .map_err(|e| SceneError::Texture { path: path.to_path_buf(), message: e.to_string() })?;
        Ok(Self::from_dynamic(img, path.display().to_string()))
    }

    pub fn from_dynamic(img: image::DynamicImage, source: String) -> Self {
        let rgb = img.to_rgb8();
        let (width, height) = rgb.dimensions();
        let texels = rgb.pixels().map(|p| p.0).collect();
        Self { width, height, texels, source }
    }

    /// A texture from raw RGB8 texels; `None` if the count does not match.
    pub fn from_rgb8(width: u32, height: u32, texels: Vec<[u8; 3]>, source: String) -> Option<Self> {
        (width > 0 && height > 0 && texels.len() == width as usize * height as usize).then_some(Self {
            width,
            height,
            texels,
            source,
        })
    }

    fn texel_linear(&self, x: i64, y: i64) -> Vec3 {
        let xi = x.rem_euclid(self.width as i64) as usize;
        let yi = y.rem_euclid(self.height as i64) as usize;
        let t = self.texels[yi * self.width as usize + xi];
        let lut = &*SRGB8_TO_LINEAR;
        Vec3::new(lut[t[0] as usize], lut[t[1] as usize], lut[t[2] as usize])
    }

    /// Bilinear, wrap-addressed, linear-space lookup. Texel centres are at half-integers.
    pub fn sample_bilinear(&self, uv: Vec2) -> Vec3 {
        if !uv.is_finite() {
            return self.texel_linear(0, 0);
        }
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        let x0 = x.floor();
        let y0 = y.floor();
        let fx = x - x0;
        let fy = y - y0;
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = self.texel_linear(x0, y0).lerp(self.texel_linear(x0 + 1, y0), fx);
        let bottom = self.texel_linear(x0, y0 + 1).lerp(self.texel_linear(x0 + 1, y0 + 1), fx);
        top.lerp(bottom, fy)
    }

    /// Mean linear colour over all texels (used to weight emissive triangles).
    pub fn mean_linear(&self) -> Vec3 {
        let lut = &*SRGB8_TO_LINEAR;
        let mut s = glam::DVec3::ZERO;
        for t in &self.texels {
            s += glam::DVec3::new(lut[t[0] as usize] as f64, lut[t[1] as usize] as f64, lut[t[2] as usize] as f64);
        }
        (s / self.texels.len().max(1) as f64).as_vec3()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker() -> Texture {
        // 2×2: black, white / white, black.
        Texture::from_rgb8(2, 2, vec![[0; 3], [255; 3], [255; 3], [0; 3]], "test".into()).expect("valid")
    }

    #[test]
    fn texel_centres_return_exact_decoded_values() {
        let t = checker();
        assert_eq!(t.sample_bilinear(Vec2::new(0.25, 0.25)), Vec3::ZERO);
        assert_eq!(t.sample_bilinear(Vec2::new(0.75, 0.25)), Vec3::ONE);
        assert_eq!(t.sample_bilinear(Vec2::new(0.25, 0.75)), Vec3::ONE);
    }

    #[test]
    fn bilinear_midpoint_averages_in_linear_space_and_wraps() {
        let t = checker();
        // Halfway between a black and a white texel: 0.5 linear, not sRGB 0.5.
        let m = t.sample_bilinear(Vec2::new(0.5, 0.25));
        assert!((m - Vec3::splat(0.5)).length() < 1e-6);
        // u = 0 sits between texel column 1 (wrapped) and column 0.
        let w = t.sample_bilinear(Vec2::new(0.0, 0.25));
        assert!((w - Vec3::splat(0.5)).length() < 1e-6);
        // Repeat: shifting by whole periods changes nothing.
        assert_eq!(t.sample_bilinear(Vec2::new(3.75, -1.75)), t.sample_bilinear(Vec2::new(0.75, 0.25)));
    }

    #[test]
    fn srgb_decoding_of_mid_grey() {
        let t = Texture::from_rgb8(1, 1, vec![[128; 3]], "grey".into()).expect("valid");
        let v = t.sample_bilinear(Vec2::new(0.3, 0.9));
        assert!((v.x - 0.215_860_5).abs() < 1e-5, "{v}");
        assert!((t.mean_linear().x - v.x).abs() < 1e-6);
    }
}
