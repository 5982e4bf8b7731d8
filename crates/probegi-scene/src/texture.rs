//! 8-bit textures sampled bilinearly with wrap (repeat) addressing: colour
//! lookups decode sRGB to linear; data lookups (normal maps, height maps,
//! alpha) read the stored values as unorm without decoding.
//!
//! Layout: `texels` is row-major RGB8, row 0 at the top of the image, with an
//! optional alpha plane beside it; texture coordinate `v = 0` is the top row
//! (glTF convention; the OBJ loader flips `v`).

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
    /// The alpha channel, row-major like `texels`; `None` when the image had no
    /// alpha channel or every texel was opaque.
    pub alpha: Option<Vec<u8>>,
    /// Where it came from, for messages.
    pub source: String,
}

impl Texture {
    /// Decodes a PNG or JPEG file, keeping its alpha channel if it has one.
    pub fn load(path: &Path) -> Result<Self> {
        let img = image::ImageReader::open(path)
            .map_err(|source| SceneError::Io { path: path.to_path_buf(), cause: source })?
            .with_guessed_format()
            .map_err(|source| SceneError::Io { path: path.to_path_buf(), cause: source })?
            .decode()
            .map_err(|e| SceneError::Texture { path: path.to_path_buf(), message: e.to_string() })?;
        Ok(Self::from_dynamic(img, path.display().to_string()))
    }

    pub fn from_dynamic(img: image::DynamicImage, source: String) -> Self {
        let alpha = img.color().has_alpha().then(|| img.to_rgba8().pixels().map(|p| p.0[3]).collect::<Vec<u8>>());
        let rgb = img.to_rgb8();
        let (width, height) = rgb.dimensions();
        let texels = rgb.pixels().map(|p| p.0).collect();
        Self { width, height, texels, alpha: alpha.filter(|a| a.iter().any(|&v| v < 255)), source }
    }

    /// Attaches an alpha plane (one value per texel); `None` if the count does
    /// not match. A plane with every texel opaque is dropped.
    pub fn with_alpha(mut self, alpha: Vec<u8>) -> Option<Self> {
        if alpha.len() != self.texels.len() {
            return None;
        }
        self.alpha = alpha.iter().any(|&a| a < 255).then_some(alpha);
        Some(self)
    }

    /// A texture from raw RGB8 texels; `None` if the count does not match.
    pub fn from_rgb8(width: u32, height: u32, texels: Vec<[u8; 3]>, source: String) -> Option<Self> {
        (width > 0 && height > 0 && texels.len() == width as usize * height as usize).then_some(Self {
            width,
            height,
            texels,
            alpha: None,
            source,
        })
    }

    /// Bilinear, wrap-addressed, linear-space lookup. Texel centres are at half-integers.
    pub fn sample_bilinear(&self, uv: Vec2) -> Vec3 {
        let f = Footprint::at(self.width, self.height, uv);
        let lut = &*SRGB8_TO_LINEAR;
        f.blend(|i| {
            let t = self.texels[i];
            Vec3::new(lut[t[0] as usize], lut[t[1] as usize], lut[t[2] as usize])
        })
    }

    /// Bilinear lookup of the stored values as unorm in [0, 1], not decoded:
    /// the lookup for data textures (normal maps, height maps).
    pub fn sample_raw(&self, uv: Vec2) -> Vec3 {
        Footprint::at(self.width, self.height, uv).blend(|i| Vec3::from(self.texels[i].map(unorm)))
    }

    /// Coverage for alpha testing, one byte per texel: the alpha channel when
    /// the texture has one, else the stored grey level (an MTL `map_d` saved as
    /// a grey image). The tracer filters it bilinearly (`bvh.rs`).
    pub fn coverage_plane(&self) -> Vec<u8> {
        match &self.alpha {
            Some(a) => a.clone(),
            None => self.texels.iter().map(|t| (grey(*t) * 255.0).round() as u8).collect(),
        }
    }

    /// A height-map lookup (the stored grey level, not decoded) and its
    /// gradient per unit of `u` and `v`: the derivative of the bilinear
    /// interpolant, as Mitsuba's `bitmap.eval_1_grad` computes it.
    pub fn sample_height_gradient(&self, uv: Vec2) -> (f32, Vec2) {
        let f = Footprint::at(self.width, self.height, uv);
        let h = |k: usize| grey(self.texels[f.texel[k]]);
        let (h00, h10, h01, h11) = (h(0), h(1), h(2), h(3));
        let value = f.blend(|i| grey(self.texels[i]));
        let d_dx = (1.0 - f.fy) * (h10 - h00) + f.fy * (h11 - h01);
        let d_dy = (1.0 - f.fx) * (h01 - h00) + f.fx * (h11 - h10);
        (value, Vec2::new(d_dx * self.width as f32, d_dy * self.height as f32))
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

fn unorm(v: u8) -> f32 {
    v as f32 * (1.0 / 255.0)
}

/// The grey level of a texel as unorm: Rec. 709 luminance of the stored values
/// (MTL's `-imfchan l`, the default channel of `bump` and `map_d`).
fn grey(t: [u8; 3]) -> f32 {
    0.2126 * unorm(t[0]) + 0.7152 * unorm(t[1]) + 0.0722 * unorm(t[2])
}

/// The four texels (wrap addressing) and weights of a bilinear lookup at `uv`;
/// texel centres at half-integers. A non-finite `uv` reads texel (0, 0).
#[derive(Clone, Copy, Debug)]
pub struct Footprint {
    /// Row-major indices of (x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1).
    pub texel: [usize; 4],
    pub fx: f32,
    pub fy: f32,
}

impl Footprint {
    pub fn at(width: u32, height: u32, uv: Vec2) -> Self {
        if !uv.is_finite() {
            return Self { texel: [0; 4], fx: 0.0, fy: 0.0 };
        }
        // Wrap first: a huge but finite coordinate (`vt 3e38`) times the width would overflow.
        let uv = Vec2::new(uv.x.rem_euclid(1.0), uv.y.rem_euclid(1.0));
        let x = uv.x * width as f32 - 0.5;
        let y = uv.y * height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (w, h) = (width as i64, height as i64);
        let col = |c: i64| c.rem_euclid(w) as usize;
        let row = |r: i64| r.rem_euclid(h) as usize * width as usize;
        let (x0, y0) = (x0 as i64, y0 as i64);
        Self {
            texel: [row(y0) + col(x0), row(y0) + col(x0 + 1), row(y0 + 1) + col(x0), row(y0 + 1) + col(x0 + 1)],
            fx,
            fy,
        }
    }

    /// Bilinear blend of `value` at the four texels.
    pub fn blend<T>(&self, value: impl Fn(usize) -> T) -> T
    where
        T: std::ops::Mul<f32, Output = T> + std::ops::Add<Output = T>,
    {
        let [a, b, c, d] = self.texel.map(value);
        let (fx, fy) = (self.fx, self.fy);
        (a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy
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
    fn huge_texture_coordinates_stay_finite() {
        let t = checker();
        for uv in [Vec2::new(3e38, -3e38), Vec2::new(-1e-9, 1e20), Vec2::new(f32::MAX, 0.25)] {
            assert!(t.sample_bilinear(uv).is_finite() && t.sample_raw(uv).is_finite(), "{uv}");
            assert!(t.sample_height_gradient(uv).1.is_finite());
        }
    }

    #[test]
    fn srgb_decoding_of_mid_grey() {
        let t = Texture::from_rgb8(1, 1, vec![[128; 3]], "grey".into()).expect("valid");
        let v = t.sample_bilinear(Vec2::new(0.3, 0.9));
        assert!((v.x - 0.215_860_5).abs() < 1e-5, "{v}");
        assert!((t.mean_linear().x - v.x).abs() < 1e-6);
    }
}
