//! 8-bit textures: colour lookups decode sRGB to linear; data lookups (normal
//! maps, height maps, metallic-roughness maps, alpha) read the stored values as
//! unorm without decoding.
//!
//! Sampling follows the texture's [`Sampler`] (glTF 2.0 §3.8.4 "Samplers"):
//! wrapping per axis (§3.8.4.3: repeat, mirrored repeat, clamp to edge, on the
//! integer texel index as OpenGL does) and the filter (§3.8.4.2: nearest or
//! linear). Every lookup is a point lookup without a footprint (the tracers
//! carry no ray differentials), so it is treated as magnification and there are
//! no mipmaps: the sampler's filter is glTF's `magFilter`, or, where that is
//! undefined, the §3.8.4.2 fallback of its `minFilter` (the mipmap modes fall
//! back to nearest or linear), else linear. OBJ textures repeat and filter
//! linearly. Alpha cutouts are tested inside traversal (`bvh/cutouts.rs`) with repeat
//! addressing and bilinear filtering whatever the sampler; the glTF loader
//! warns where a cut-out material's sampler says otherwise.
//!
//! Layout: `texels` is row-major RGB8, row 0 at the top of the image, with an
//! optional alpha plane beside it; texture coordinate `v = 0` is the top row
//! (glTF convention; the OBJ loader flips `v`).

use glam::{Vec2, Vec3};
use std::path::Path;
use std::sync::LazyLock;

use crate::error::{Result, SceneError};

static SRGB8_TO_LINEAR: LazyLock<[f32; 256]> = LazyLock::new(probegi_core::color::srgb8_to_linear_table);

/// How a texture coordinate outside [0, 1) picks a texel along one axis (glTF
/// 2.0 §3.8.4.3, sampler `wrapS` / `wrapT`), applied to the integer texel index.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    /// Texel index modulo the size: only the fractional part of the coordinate counts.
    #[default]
    Repeat,
    /// Repeat, flipped where the integer part (towards −∞) is odd.
    MirroredRepeat,
    /// The nearest edge texel.
    ClampToEdge,
}

/// How the texels around a coordinate are combined (glTF 2.0 §3.8.4.2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Filter {
    /// Bilinear interpolation of the four nearest texel centres.
    #[default]
    Linear,
    /// The texel the coordinate falls in.
    Nearest,
}

/// A texture's addressing and filtering (glTF `sampler`); the default, repeat
/// and linear on both axes, is OBJ's and glTF's for a texture without one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sampler {
    /// Along `u` (glTF `wrapS`).
    pub wrap_u: Wrap,
    /// Along `v` (glTF `wrapT`).
    pub wrap_v: Wrap,
    /// How the texels around a lookup are combined, on both axes.
    pub filter: Filter,
}

/// A decoded image a material reads: sRGB texels, an optional alpha plane and its sampler.
#[derive(Clone, Debug)]
pub struct Texture {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Row-major sRGB-encoded RGB8, row 0 at the top.
    pub texels: Vec<[u8; 3]>,
    /// The alpha channel, row-major like `texels`; `None` when the image had no
    /// alpha channel or every texel was opaque.
    pub alpha: Option<Vec<u8>>,
    /// Where it came from, for messages.
    pub source: String,
    /// Addressing and filtering of every lookup.
    pub sampler: Sampler,
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

    /// A texture from a decoded image, named `source` in messages; an alpha plane
    /// with every texel opaque is dropped.
    pub fn from_dynamic(img: image::DynamicImage, source: String) -> Self {
        let alpha = img.color().has_alpha().then(|| img.to_rgba8().pixels().map(|p| p.0[3]).collect::<Vec<u8>>());
        let rgb = img.to_rgb8();
        let (width, height) = rgb.dimensions();
        let texels = rgb.pixels().map(|p| p.0).collect();
        let alpha = alpha.filter(|a| a.iter().any(|&v| v < 255));
        Self { width, height, texels, alpha, source, sampler: Sampler::default() }
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
            sampler: Sampler::default(),
        })
    }

    /// The same texels read through `sampler`.
    pub fn with_sampler(mut self, sampler: Sampler) -> Self {
        self.sampler = sampler;
        self
    }

    fn footprint(&self, uv: Vec2) -> Footprint {
        Footprint::sampled(self.width, self.height, self.sampler, uv)
    }

    /// Colour lookup through the sampler, decoded to linear before filtering.
    /// Texel centres are at half-integers.
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        let f = self.footprint(uv);
        let lut = &*SRGB8_TO_LINEAR;
        f.blend(|i| {
            let t = self.texels[i];
            Vec3::new(lut[t[0] as usize], lut[t[1] as usize], lut[t[2] as usize])
        })
    }

    /// Lookup through the sampler of the stored values as unorm in [0, 1], not
    /// decoded: the lookup for data textures (normal, height and
    /// metallic-roughness maps).
    pub fn sample_raw(&self, uv: Vec2) -> Vec3 {
        self.footprint(uv).blend(|i| Vec3::from(self.texels[i].map(unorm)))
    }

    /// Coverage for alpha testing, one byte per texel: the alpha channel when
    /// the texture has one, else the stored grey level (an MTL `map_d` saved as
    /// a grey image). The tracer filters it bilinearly (`bvh/cutouts.rs`).
    pub fn coverage_plane(&self) -> Vec<u8> {
        match &self.alpha {
            Some(a) => a.clone(),
            None => self.texels.iter().map(|t| (grey(*t) * 255.0).round() as u8).collect(),
        }
    }

    /// A height-map lookup (the stored grey level, not decoded) and its
    /// gradient per unit of `u` and `v`: the derivative of the bilinear
    /// interpolant, as Mitsuba's `bitmap.eval_1_grad` computes it (zero under
    /// nearest filtering, whose interpolant is flat within a texel).
    pub fn sample_height_gradient(&self, uv: Vec2) -> (f32, Vec2) {
        let f = self.footprint(uv);
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
pub(crate) struct Footprint {
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

    /// The footprint of a lookup at `uv` through `sampler`: [`Footprint::at`]
    /// for the default sampler; otherwise each axis wrapped by its mode, and
    /// under nearest filtering the one texel `uv` falls in, four times with
    /// zero fractions (so [`Footprint::blend`] returns it exactly).
    pub fn sampled(width: u32, height: u32, sampler: Sampler, uv: Vec2) -> Self {
        if sampler == Sampler::default() {
            return Self::at(width, height, uv);
        }
        if !uv.is_finite() {
            return Self { texel: [0; 4], fx: 0.0, fy: 0.0 };
        }
        let (cols, fx) = axis_texels(uv.x, width, sampler.wrap_u, sampler.filter);
        let (rows, fy) = axis_texels(uv.y, height, sampler.wrap_v, sampler.filter);
        let (r0, r1) = (rows[0] * width as usize, rows[1] * width as usize);
        Self { texel: [r0 + cols[0], r0 + cols[1], r1 + cols[0], r1 + cols[1]], fx, fy }
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

/// The two texel indices along one axis of `size` texels that a lookup at
/// coordinate `c` reads (the same one twice under nearest filtering) and the
/// fraction between them. The coordinate is first brought into one period of
/// the wrap mode (a huge coordinate times the size would overflow), which
/// changes no texel: repeat has period 1, mirrored repeat 2, and a clamped
/// coordinate beyond [−1, 2] reads the same edge texel.
fn axis_texels(c: f32, size: u32, wrap: Wrap, filter: Filter) -> ([usize; 2], f32) {
    let c = match wrap {
        Wrap::Repeat => c.rem_euclid(1.0),
        Wrap::MirroredRepeat => c.rem_euclid(2.0),
        Wrap::ClampToEdge => c.clamp(-1.0, 2.0),
    };
    let n = size as i64;
    let address = |i: i64| -> usize {
        (match wrap {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                if m >= n { 2 * n - 1 - m } else { m }
            }
            Wrap::ClampToEdge => i.clamp(0, n - 1),
        }) as usize
    };
    match filter {
        Filter::Nearest => {
            let i = address((c * size as f32).floor() as i64);
            ([i, i], 0.0)
        }
        Filter::Linear => {
            let x = c * size as f32 - 0.5;
            let x0 = x.floor();
            ([address(x0 as i64), address(x0 as i64 + 1)], x - x0)
        }
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
        assert_eq!(t.sample(Vec2::new(0.25, 0.25)), Vec3::ZERO);
        assert_eq!(t.sample(Vec2::new(0.75, 0.25)), Vec3::ONE);
        assert_eq!(t.sample(Vec2::new(0.25, 0.75)), Vec3::ONE);
    }

    #[test]
    fn bilinear_midpoint_averages_in_linear_space_and_wraps() {
        let t = checker();
        // Halfway between a black and a white texel: 0.5 linear, not sRGB 0.5.
        let m = t.sample(Vec2::new(0.5, 0.25));
        assert!((m - Vec3::splat(0.5)).length() < 1e-6);
        // u = 0 sits between texel column 1 (wrapped) and column 0.
        let w = t.sample(Vec2::new(0.0, 0.25));
        assert!((w - Vec3::splat(0.5)).length() < 1e-6);
        // Repeat: shifting by whole periods changes nothing.
        assert_eq!(t.sample(Vec2::new(3.75, -1.75)), t.sample(Vec2::new(0.75, 0.25)));
    }

    #[test]
    fn huge_texture_coordinates_stay_finite() {
        let t = checker();
        for uv in [Vec2::new(3e38, -3e38), Vec2::new(-1e-9, 1e20), Vec2::new(f32::MAX, 0.25)] {
            assert!(t.sample(uv).is_finite() && t.sample_raw(uv).is_finite(), "{uv}");
            assert!(t.sample_height_gradient(uv).1.is_finite());
        }
    }

    /// A 4×2 ramp: grey 0, 85, 170, 255 along u; the second row is the first
    /// plus 10 (so rows are told apart).
    fn ramp(sampler: Sampler) -> Texture {
        let texels = [0u8, 85, 170, 255, 10, 95, 180, 255].map(|g| [g; 3]).to_vec();
        Texture::from_rgb8(4, 2, texels, "ramp".into()).expect("valid").with_sampler(sampler)
    }

    fn grey_at(t: &Texture, u: f32, v: f32) -> f32 {
        t.sample_raw(Vec2::new(u, v)).x * 255.0
    }

    #[test]
    fn wrap_modes_address_texels_as_gltf_says() {
        let sampler = |wrap_u| Sampler { wrap_u, ..Sampler::default() };
        let (repeat, mirror, clamp) =
            (ramp(sampler(Wrap::Repeat)), ramp(sampler(Wrap::MirroredRepeat)), ramp(sampler(Wrap::ClampToEdge)));
        // u = 1.125 is texel 0's centre one period on: repeat reads texel 0,
        // mirrored repeat the flipped period's texel 3, clamp the edge texel 3.
        for (t, want) in [(&repeat, 0.0), (&mirror, 255.0), (&clamp, 255.0)] {
            assert!((grey_at(t, 1.125, 0.25) - want).abs() < 1e-3, "{:?}: {}", t.sampler, grey_at(t, 1.125, 0.25));
        }
        // §3.8.4.3's examples: mirrored 2.2 reads as 0.2 and −0.4 as 0.4.
        for (u, as_u) in [(2.375, 0.375), (-0.375, 0.375), (-1.625, 0.375)] {
            assert_eq!(grey_at(&mirror, u, 0.25), grey_at(&mirror, as_u, 0.25), "mirrored {u}");
        }
        // Clamp: far outside reads the edge texel, at the edge no wrap-around blend.
        assert_eq!(grey_at(&clamp, -7.0, 0.25), 0.0);
        assert_eq!(grey_at(&clamp, 1e30, 0.25), 255.0);
        assert!((grey_at(&clamp, 0.0, 0.25)).abs() < 1e-3, "{}", grey_at(&clamp, 0.0, 0.25));
        assert!((grey_at(&repeat, 0.0, 0.25) - 127.5).abs() < 1e-3, "repeat blends texels 3 and 0 at u = 0");
        // Per axis: v repeats while u clamps (row 1 + one period reads row 1).
        assert!((grey_at(&clamp, 5.0, 1.75) - 255.0).abs() < 1e-3);
        assert!((grey_at(&clamp, 0.125, 1.75) - 10.0).abs() < 1e-3);
    }

    #[test]
    fn nearest_filtering_reads_one_texel_and_linear_blends() {
        let nearest = ramp(Sampler { filter: Filter::Nearest, ..Sampler::default() });
        let linear = ramp(Sampler::default());
        // u = 0.49 lies in texel 1 (0.25–0.5), 0.46 texels past its centre.
        assert_eq!(grey_at(&nearest, 0.49, 0.25), 85.0);
        assert!((grey_at(&linear, 0.49, 0.25) - (85.0 + 0.46 * 85.0)).abs() < 1e-2);
        assert_eq!(grey_at(&nearest, 0.51, 0.9), 180.0);
        // Nearest with every wrap mode, and its flat height gradient.
        for wrap in [Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge] {
            let t = ramp(Sampler { wrap_u: wrap, wrap_v: wrap, filter: Filter::Nearest });
            assert_eq!(grey_at(&t, 0.3, 0.2), 85.0, "{wrap:?}");
            assert_eq!(t.sample_height_gradient(Vec2::new(0.3, 0.2)).1, Vec2::ZERO);
        }
        assert_eq!(grey_at(&ramp(Sampler { filter: Filter::Nearest, ..Sampler::default() }), 1.3, 0.2), 85.0);
    }

    #[test]
    fn the_default_sampler_is_the_repeat_footprint() {
        for uv in [Vec2::new(0.3, 0.7), Vec2::new(-2.6, 5.1), Vec2::new(3e38, -1e-9)] {
            let (a, b) = (Footprint::at(4, 2, uv), Footprint::sampled(4, 2, Sampler::default(), uv));
            assert_eq!((a.texel, a.fx, a.fy), (b.texel, b.fx, b.fy));
            let general = Sampler { wrap_u: Wrap::Repeat, wrap_v: Wrap::Repeat, filter: Filter::Linear };
            let (c, d) = (axis_texels(uv.x, 4, general.wrap_u, general.filter), (a.texel[0] % 4, a.fx));
            assert_eq!((c.0[0], c.1), d, "the general path agrees with Footprint::at at {uv}");
        }
    }

    #[test]
    fn srgb_decoding_of_mid_grey() {
        let t = Texture::from_rgb8(1, 1, vec![[128; 3]], "grey".into()).expect("valid");
        let v = t.sample(Vec2::new(0.3, 0.9));
        assert!((v.x - 0.215_860_5).abs() < 1e-5, "{v}");
        assert!((t.mean_linear().x - v.x).abs() < 1e-6);
    }
}
