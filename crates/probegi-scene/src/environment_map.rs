//! The environment-map sky: an equirectangular (latitude-longitude) HDR image
//! of the radiance arriving from every direction, read from OpenEXR or
//! Radiance `.hdr` files, looked up bilinearly and importance-sampled.
//!
//! **Convention** (Mitsuba 3's `envmap`, y up; checked against Mitsuba by
//! `scripts/mitsuba-check.py --sky-map`): a unit direction `d` in the map's
//! own frame has
//! - `u = atan2(d.x, −d.z) / 2π`, wrapped to [0, 1): the left edge looks
//!   along −z, a quarter across along +x, the centre along +z, three
//!   quarters along −x;
//! - `v = acos(d.y) / π`: the top row is straight up (+y), the bottom row
//!   straight down. Straight up or down, `u` is whatever `atan2` gives (the
//!   row is one point).
//!
//! Texel `(i, j)` (row 0 at the top of the file) covers
//! `u ∈ [i/W, (i+1)/W)`, `v ∈ [j/H, (j+1)/H)`; lookups are bilinear between
//! texel centres, wrapping in `u` and clamped in `v`.
//!
//! [`SkyMap`] places a map in a scene: its `intensity` scales every texel,
//! and `rotation_deg` turns it about +y (right-handed: +90° brings what the
//! map shows along +z round to +x), as Mitsuba's
//! `to_world = rotate([0, 1, 0], rotation_deg)`.
//!
//! **Sampling** (pbrt-v3 §14.2.4, "Infinite area lights"): a piecewise-
//! constant density over the texels proportional to luminance × sin θ at the
//! row's centre (the solid angle of a texel row), chosen by a marginal CDF
//! over rows and a conditional CDF over each row's texels; the density of a
//! direction is `p(u, v) / (2π² sin θ)`. Deliberate deviation: a texel's
//! luminance is the mean of the bilinear radiance over it (its 3 × 3
//! neighbourhood under the tent's weights), not its own value, so that every
//! direction the bilinear radiance lights has a density and the density
//! follows the radiance a sample reads (with the texel's own value, a
//! one-texel sun's bilinear skirt is found only by rare, huge samples: 5 %
//! low at 20 000 samples). The density is of the texels, the
//! radiance bilinear: MIS against BSDF sampling keeps the estimate unbiased
//! where the two differ (a black texel beside a bright one).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Vec2, Vec3};

use crate::error::SceneError;

/// Negative texel components down to −this × the map's mean luminance are
/// the noise of lossy compression and colour conversion, and read as 0; below
/// that, a map is refused. Blender's eight studio-light maps have negatives
/// down to −0.0039 (sunrise.exr, mean 0.47) and −0.0033 (night.exr, mean
/// 0.13): 2.5 % of the mean at most.
pub const NEGATIVE_NOISE_OF_MEAN: f32 = 0.05;

/// The most texels a map may have (as `probegi-image` reads): 2¹⁵ × 2¹⁴.
pub const MAX_MAP_TEXELS: u64 = 1 << 29;

/// An equirectangular radiance map as read (see the module docs).
pub struct EnvironmentMap {
    /// The file it was read from (or a name, for a map made in memory).
    pub path: PathBuf,
    width: u32,
    height: u32,
    /// Linear radiance, row-major from the top row.
    texels: Vec<Vec3>,
    /// The sampling density's tables.
    sampling: MapSampling,
}

impl std::fmt::Debug for EnvironmentMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "EnvironmentMap({}, {}×{})", self.path.display(), self.width, self.height)
    }
}

/// A map placed in a scene: shared texels, a scale and a turn about +y, each
/// of which may follow keyframes (a moving sun: [`SkyMap::at_frame`]).
#[derive(Clone, Debug)]
pub struct SkyMap {
    /// The map.
    pub map: Arc<EnvironmentMap>,
    /// Radiance scale applied to every texel (1: as in the file).
    pub intensity: f32,
    /// Rotation about the up axis, degrees (see the module docs).
    pub rotation_deg: f32,
    /// Keys of `intensity` and `rotation_deg` over frames, in increasing frame
    /// order (empty: a still sky). Between keys each channel interpolates
    /// linearly; it holds before the first key and after the last.
    pub keyframes: Vec<SkyMapKeyframe>,
}

/// One key of a sky map's animation; either channel may be absent.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SkyMapKeyframe {
    /// Frame number (fractional frames allowed).
    pub frame: f32,
    /// The map's intensity from this key on.
    #[serde(default)]
    pub intensity: Option<f32>,
    /// The map's rotation about +y from this key on, degrees (not wrapped:
    /// 0 → 360 turns the sky once).
    #[serde(default)]
    pub rotation_deg: Option<f32>,
}

impl crate::animation::Keyed for SkyMapKeyframe {
    fn frame(&self) -> f32 {
        self.frame
    }
}

/// The marginal and conditional CDFs of the texel density.
#[derive(Clone, Debug, Default)]
struct MapSampling {
    /// Per texel, its weight (luminance × sin θ of its row).
    weights: Vec<f32>,
    /// Per row, the running sum of its texels' weights, `W + 1` entries a row.
    row_cdf: Vec<f64>,
    /// The running sum of the rows' weights, `H + 1` entries.
    marginal_cdf: Vec<f64>,
}

impl EnvironmentMap {
    /// Reads `path` (`.exr`: the first RGB(A) layer; `.hdr`: Radiance RGBE)
    /// and checks it ([`Self::from_texels`]).
    pub fn load(path: &Path) -> Result<Self, SceneError> {
        let err = |message: String| SceneError::Texture { path: path.to_path_buf(), message };
        if !path.is_file() {
            return Err(SceneError::Io {
                path: path.to_path_buf(),
                cause: std::io::Error::new(std::io::ErrorKind::NotFound, "environment map not found"),
            });
        }
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        let (width, height, texels) = match ext.as_deref() {
            Some("exr") => read_exr(path).map_err(err)?,
            Some("hdr") => read_radiance_hdr(path).map_err(err)?,
            _ => return Err(err("an environment map must be an .exr or a Radiance .hdr file".into())),
        };
        Self::from_texels(path, width, height, texels).map_err(err)
    }

    /// A map of `width` × `height` texels (row-major from the top row): it must
    /// be twice as wide as high (equirectangular), no larger than
    /// [`MAX_MAP_TEXELS`], and every texel finite and non-negative (small
    /// negatives read as 0: [`NEGATIVE_NOISE_OF_MEAN`]).
    pub fn from_texels(path: &Path, width: u32, height: u32, texels: Vec<Vec3>) -> Result<Self, String> {
        if width == 0 || height == 0 || width != 2 * height {
            return Err(format!("an equirectangular map is twice as wide as high; this one is {width}×{height}"));
        }
        if width as u64 * height as u64 > MAX_MAP_TEXELS {
            return Err(format!("{width}×{height} texels is more than a map may have ({MAX_MAP_TEXELS})"));
        }
        if texels.len() != width as usize * height as usize {
            return Err(format!("{} texels for a {width}×{height} map", texels.len()));
        }
        if let Some(k) = texels.iter().position(|t| !t.is_finite()) {
            let (x, y) = (k as u32 % width, k as u32 / width);
            return Err(format!("texel ({x}, {y}) is {:?}: radiance must be finite", texels[k].to_array()));
        }
        let mean = texels.iter().map(|t| probegi_core::color::luminance(*t).max(0.0) as f64).sum::<f64>()
            / texels.len() as f64;
        let floor = -(NEGATIVE_NOISE_OF_MEAN as f64 * mean) as f32;
        if let Some(k) = texels.iter().position(|t| t.min_element() < floor) {
            let (x, y) = (k as u32 % width, k as u32 / width);
            return Err(format!(
                "texel ({x}, {y}) is {:?}: radiance must be non-negative (down to {floor}, \
                 {NEGATIVE_NOISE_OF_MEAN} × the map's mean luminance, reads as 0)",
                texels[k].to_array()
            ));
        }
        let texels = texels.into_iter().map(|t| t.max(Vec3::ZERO)).collect::<Vec<_>>();
        let sampling = MapSampling::new(width, height, &texels);
        Ok(Self { path: path.to_path_buf(), width, height, texels, sampling })
    }

    /// Width and height in texels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The texels as read, row-major from the top row.
    pub fn texels(&self) -> &[Vec3] {
        &self.texels
    }

    /// The radiance the map stores along `uv` (bilinear between texel centres).
    pub fn lookup_uv(&self, uv: Vec2) -> Vec3 {
        let (w, h) = (self.width as i64, self.height as i64);
        let x = uv.x * w as f32 - 0.5;
        let y = uv.y * h as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let col = |i: i64| i.rem_euclid(w) as usize;
        let row = |j: i64| j.clamp(0, h - 1) as usize;
        let (i0, j0) = (x0 as i64, y0 as i64);
        let t = |i: i64, j: i64| self.texels[row(j) * w as usize + col(i)];
        let top = t(i0, j0) * (1.0 - fx) + t(i0 + 1, j0) * fx;
        let bottom = t(i0, j0 + 1) * (1.0 - fx) + t(i0 + 1, j0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// The sampling density's tables (module docs), for a device that samples
    /// the map itself: the running sum of the rows' weights (`H + 1` entries,
    /// from 0), then each row's running sum of its texels' weights (`W + 1`
    /// entries a row, from 0).
    pub fn sampling_cdfs(&self) -> (&[f64], &[f64]) {
        (&self.sampling.marginal_cdf, &self.sampling.row_cdf)
    }

    /// Whether any texel gives light.
    pub fn is_black(&self) -> bool {
        self.sampling.marginal_cdf.last().is_none_or(|&t| t <= 0.0)
    }
}

/// `(u, v)` of a unit direction in the map's own frame (module docs).
pub fn direction_to_uv(d: Vec3) -> Vec2 {
    let u = d.x.atan2(-d.z) * (0.5 * std::f32::consts::FRAC_1_PI);
    let u = if u < 0.0 { u + 1.0 } else { u };
    Vec2::new(u.min(1.0 - f32::EPSILON * 0.5), d.y.clamp(-1.0, 1.0).acos() * std::f32::consts::FRAC_1_PI)
}

/// The unit direction in the map's own frame at `uv` (inverse of [`direction_to_uv`]).
pub fn uv_to_direction(uv: Vec2) -> Vec3 {
    let (phi, theta) = (uv.x * std::f32::consts::TAU, uv.y * std::f32::consts::PI);
    let (sin_t, cos_t) = theta.sin_cos();
    let (sin_p, cos_p) = phi.sin_cos();
    Vec3::new(sin_t * sin_p, cos_t, -sin_t * cos_p)
}

/// One direction drawn from a map's density.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkySample {
    /// The unit world direction toward the sky.
    pub wi: Vec3,
    /// The radiance arriving from it (intensity applied).
    pub radiance: Vec3,
    /// Its density per unit solid angle.
    pub pdf_solid_angle: f32,
}

impl SkyMap {
    /// `map` at intensity 1, unturned, still.
    pub fn new(map: Arc<EnvironmentMap>) -> Self {
        Self { map, intensity: 1.0, rotation_deg: 0.0, keyframes: Vec::new() }
    }

    /// This sky at `frame` with its keyframes applied (itself if it has none).
    pub fn at_frame(&self, frame: f32) -> SkyMap {
        let mut sky = self.clone();
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        if let Some(i) = crate::animation::channel(&self.keyframes, frame, |k| k.intensity, lerp) {
            sky.intensity = i;
        }
        if let Some(r) = crate::animation::channel(&self.keyframes, frame, |k| k.rotation_deg, lerp) {
            sky.rotation_deg = r;
        }
        sky
    }

    /// Why its settings are unusable, if they are: a non-finite or negative
    /// intensity, a non-finite rotation, keys out of order.
    pub fn validate(&self) -> Result<(), String> {
        crate::animation::validate_key_frames(&self.keyframes)?;
        let intensities = std::iter::once(Some(self.intensity)).chain(self.keyframes.iter().map(|k| k.intensity));
        if let Some(i) = intensities.flatten().find(|i| !i.is_finite() || *i < 0.0) {
            return Err(format!("sky map intensity {i} must be finite and non-negative"));
        }
        let rotations = std::iter::once(Some(self.rotation_deg)).chain(self.keyframes.iter().map(|k| k.rotation_deg));
        if let Some(r) = rotations.flatten().find(|r| !r.is_finite()) {
            return Err(format!("sky map rotation {r} must be finite"));
        }
        Ok(())
    }

    /// The direction in the map's frame of world direction `d`.
    fn to_map(&self, d: Vec3) -> Vec3 {
        let (s, c) = (-self.rotation_deg.to_radians()).sin_cos();
        Vec3::new(c * d.x + s * d.z, d.y, -s * d.x + c * d.z)
    }

    /// The world direction of direction `l` in the map's frame.
    fn to_world(&self, l: Vec3) -> Vec3 {
        let (s, c) = self.rotation_deg.to_radians().sin_cos();
        Vec3::new(c * l.x + s * l.z, l.y, -s * l.x + c * l.z)
    }

    /// The radiance arriving along world direction `-d` from the sky, i.e. seen
    /// looking toward unit direction `d`.
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        self.map.lookup_uv(direction_to_uv(self.to_map(d))) * self.intensity
    }

    /// A direction drawn with density ∝ the map's luminance (module docs);
    /// `None` for a black map or an intensity of zero.
    pub fn sample(&self, u: Vec2) -> Option<SkySample> {
        if self.intensity <= 0.0 {
            return None;
        }
        let (uv, pdf_uv) = self.map.sampling.sample(self.map.width, self.map.height, u)?;
        let sin_theta = (uv.y * std::f32::consts::PI).sin();
        if sin_theta <= 0.0 {
            return None;
        }
        let wi = self.to_world(uv_to_direction(uv));
        let pdf_solid_angle = pdf_uv / (2.0 * std::f32::consts::PI * std::f32::consts::PI * sin_theta);
        Some(SkySample { wi, radiance: self.map.lookup_uv(uv) * self.intensity, pdf_solid_angle })
    }

    /// The density per unit solid angle with which [`Self::sample`] draws world
    /// direction `d` (0 where it never does).
    pub fn pdf(&self, d: Vec3) -> f32 {
        if self.intensity <= 0.0 {
            return 0.0;
        }
        let uv = direction_to_uv(self.to_map(d));
        let sin_theta = (uv.y * std::f32::consts::PI).sin();
        if sin_theta <= 0.0 {
            return 0.0;
        }
        self.map.sampling.pdf_uv(self.map.width, self.map.height, uv)
            / (2.0 * std::f32::consts::PI * std::f32::consts::PI * sin_theta)
    }

    /// Whether it gives light at all.
    pub fn is_black(&self) -> bool {
        self.intensity <= 0.0 || self.map.is_black()
    }
}

impl MapSampling {
    fn new(width: u32, height: u32, texels: &[Vec3]) -> Self {
        let (w, h) = (width as usize, height as usize);
        let mut weights = Vec::with_capacity(w * h);
        let mut row_cdf = Vec::with_capacity((w + 1) * h);
        let mut marginal_cdf = Vec::with_capacity(h + 1);
        marginal_cdf.push(0.0);
        let lum = |i: usize, j: usize| probegi_core::color::luminance(texels[j * w + i]).max(0.0);
        for j in 0..h {
            let sin_theta = ((j as f32 + 0.5) / h as f32 * std::f32::consts::PI).sin();
            let mut sum = 0.0f64;
            row_cdf.push(0.0);
            for i in 0..w {
                // The mean of the bilinear luminance over this texel: its 3 × 3
                // neighbourhood under the tent's weights, ¾ for the texel and ⅛
                // for each side per axis (rows clamped, columns wrapped, as lookups).
                let mut mean = 0.0f32;
                for (dj, kj) in [(-1i64, 0.125f32), (0, 0.75), (1, 0.125)] {
                    let jj = (j as i64 + dj).clamp(0, h as i64 - 1) as usize;
                    for (di, ki) in [(w - 1, 0.125f32), (0, 0.75), (1, 0.125)] {
                        mean += kj * ki * lum((i + di) % w, jj);
                    }
                }
                let weight = mean * sin_theta;
                weights.push(weight);
                sum += weight as f64;
                row_cdf.push(sum);
            }
            let last = *marginal_cdf.last().unwrap_or(&0.0);
            marginal_cdf.push(last + sum);
        }
        Self { weights, row_cdf, marginal_cdf }
    }

    /// The sum of every texel's weight.
    fn total(&self) -> f64 {
        self.marginal_cdf.last().copied().unwrap_or(0.0)
    }

    /// `uv` drawn ∝ the texel weights (uniform inside the texel), with its
    /// density over the unit square.
    fn sample(&self, width: u32, height: u32, u: Vec2) -> Option<(Vec2, f32)> {
        let total = self.total();
        if total <= 0.0 {
            return None;
        }
        let (w, h) = (width as usize, height as usize);
        let (j, dv) = pick(&self.marginal_cdf, u.y as f64 * total)?;
        let row = &self.row_cdf[j * (w + 1)..(j + 1) * (w + 1)];
        let (i, du) = pick(row, u.x as f64 * row[w])?;
        let uv = Vec2::new((i as f32 + du) / w as f32, (j as f32 + dv) / h as f32);
        let pdf = (self.weights[j * w + i] as f64 / total * (w * h) as f64) as f32;
        Some((uv, pdf))
    }

    /// The density over the unit square of `uv`.
    fn pdf_uv(&self, width: u32, height: u32, uv: Vec2) -> f32 {
        let total = self.total();
        if total <= 0.0 {
            return 0.0;
        }
        let (w, h) = (width as usize, height as usize);
        let i = ((uv.x * w as f32) as usize).min(w - 1);
        let j = ((uv.y * h as f32) as usize).min(h - 1);
        (self.weights[j * w + i] as f64 / total * (w * h) as f64) as f32
    }
}

/// The interval of a running sum `cdf` (first entry 0) that holds `x`, and
/// where in it `x` lies (0..1); never an interval of zero weight.
fn pick(cdf: &[f64], x: f64) -> Option<(usize, f32)> {
    let n = cdf.len().checked_sub(1)?;
    // The last k with cdf[k] <= x: its interval holds x, unless x reached the
    // total (u rounded to 1), where it is the last of non-zero weight.
    let mut k = cdf.partition_point(|&c| c <= x).saturating_sub(1).min(n - 1);
    while k > 0 && cdf[k + 1] <= cdf[k] {
        k -= 1;
    }
    let width = cdf[k + 1] - cdf[k];
    if width <= 0.0 {
        return None;
    }
    Some((k, (((x - cdf[k]) / width).clamp(0.0, 1.0 - 1e-7)) as f32))
}

/// The first RGB(A) layer of an OpenEXR file, bounded before it is read.
fn read_exr(path: &Path) -> Result<(u32, u32, Vec<Vec3>), String> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| e.to_string())?;
    for h in &meta.headers {
        let (w, hh) = (h.layer_size.x() as u64, h.layer_size.y() as u64);
        if w * hh > MAX_MAP_TEXELS {
            return Err(format!("{w}×{hh} texels is more than a map may have ({MAX_MAP_TEXELS})"));
        }
    }
    let img = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![Vec3::ZERO; res.width() * res.height()]),
        |(w, t): &mut (usize, Vec<Vec3>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            t[pos.y() * *w + pos.x()] = Vec3::new(r, g, b);
        },
    )
    .map_err(|e| e.to_string())?;
    let size = img.layer_data.size;
    let (_, texels) = img.layer_data.channel_data.pixels;
    Ok((size.width() as u32, size.height() as u32, texels))
}

/// A Radiance RGBE (`.hdr`) file.
fn read_radiance_hdr(path: &Path) -> Result<(u32, u32, Vec<Vec3>), String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let decoder = image::codecs::hdr::HdrDecoder::new(std::io::BufReader::new(file))
        .map_err(|e| format!("Radiance header: {e}"))?;
    let meta = decoder.metadata();
    if meta.width as u64 * meta.height as u64 > MAX_MAP_TEXELS {
        return Err(format!("{}×{} texels is more than a map may have ({MAX_MAP_TEXELS})", meta.width, meta.height));
    }
    let img = image::DynamicImage::from_decoder(decoder).map_err(|e| e.to_string())?.into_rgb32f();
    let (w, h) = img.dimensions();
    let texels = img.pixels().map(|p| Vec3::new(p.0[0], p.0[1], p.0[2])).collect();
    Ok((w, h, texels))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(width: u32, texel: impl Fn(u32, u32) -> Vec3) -> Arc<EnvironmentMap> {
        let h = width / 2;
        let texels = (0..h).flat_map(|y| (0..width).map(move |x| (x, y))).map(|(x, y)| texel(x, y)).collect();
        Arc::new(EnvironmentMap::from_texels(Path::new("test"), width, h, texels).expect("map"))
    }

    #[test]
    fn the_map_faces_mitsubas_way() {
        let cases = [
            (Vec3::Z, Vec2::new(0.5, 0.5)),
            (Vec3::X, Vec2::new(0.25, 0.5)),
            (-Vec3::X, Vec2::new(0.75, 0.5)),
            (-Vec3::Z, Vec2::new(0.0, 0.5)),
        ];
        assert_eq!(direction_to_uv(Vec3::Y).y, 0.0);
        assert_eq!(direction_to_uv(-Vec3::Y).y, 1.0);
        for (d, uv) in cases {
            let got = direction_to_uv(d);
            assert!((got - uv).abs().max_element() < 1e-6, "{d}: {got} against {uv}");
            if d.y.abs() < 0.5 {
                assert!((uv_to_direction(got) - d).length() < 1e-6);
            }
        }
        // A turn of +90° about +y brings the map's +z (its centre) round to +x.
        let centre_bright = map(64, |x, _| if (31..33).contains(&x) { Vec3::ONE } else { Vec3::ZERO });
        let turned = SkyMap { rotation_deg: 90.0, ..SkyMap::new(centre_bright) };
        assert!(turned.radiance(Vec3::X).x > 0.4 && turned.radiance(Vec3::Z).x == 0.0);
    }

    #[test]
    fn the_density_integrates_to_one_and_matches_its_samples() {
        // A sun of 1 000 on a dim sky: the density follows luminance × sin θ.
        let sky = SkyMap {
            intensity: 2.0,
            rotation_deg: 30.0,
            ..SkyMap::new(map(64, |x, y| if x == 40 && y == 10 { Vec3::splat(1000.0) } else { Vec3::splat(0.5) }))
        };
        // ∫ pdf dω over the sphere by a fine midpoint rule in (u, v).
        let n = 512;
        let mut integral = 0.0f64;
        for j in 0..n / 2 {
            for i in 0..n {
                let uv = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / (n / 2) as f32);
                let d = sky.to_world(uv_to_direction(uv));
                let d_omega =
                    2.0 * std::f64::consts::PI * std::f64::consts::PI * (uv.y as f64 * std::f64::consts::PI).sin()
                        / (n * n / 2) as f64;
                integral += sky.pdf(d) as f64 * d_omega;
            }
        }
        assert!((integral - 1.0).abs() < 0.01, "∫ pdf = {integral}");
        // Each sample's density is the one pdf() gives its direction, and a
        // quarter of the samples or more land on the sun's texel.
        let mut rng = probegi_core::rng::Pcg32::new(7, 1);
        let mut on_sun = 0;
        for _ in 0..2000 {
            let s = sky.sample(rng.next_vec2()).expect("sample");
            let pdf = sky.pdf(s.wi);
            assert!((s.pdf_solid_angle - pdf).abs() <= 1e-3 * pdf, "{} against {pdf}", s.pdf_solid_angle);
            on_sun += (s.radiance.x > 100.0) as u32;
        }
        assert!(on_sun > 500, "{on_sun} of 2000 samples near the sun");
        // An estimate of the irradiance of the whole sphere, ∫ L dω, by the sampled density.
        let truth: f64 = {
            let m = &sky.map;
            let (w, h) = m.size();
            (0..h)
                .map(|j| {
                    let row = (0..w).map(|i| m.texels()[(j * w + i) as usize].x as f64).sum::<f64>();
                    row * ((j as f64 + 0.5) / h as f64 * std::f64::consts::PI).sin()
                })
                .sum::<f64>()
                * 2.0
                * std::f64::consts::PI
                * std::f64::consts::PI
                / (w * h) as f64
                * 2.0
        };
        let mut est = 0.0f64;
        let k = 20000;
        for _ in 0..k {
            let s = sky.sample(rng.next_vec2()).expect("sample");
            est += (s.radiance.x / s.pdf_solid_angle) as f64;
        }
        est /= k as f64;
        assert!((est / truth - 1.0).abs() < 0.05, "∫ L dω: {est} against {truth}");
    }

    #[test]
    fn bad_maps_are_refused_with_the_texel() {
        let bad = |w: u32, h: u32, t: Vec<Vec3>| {
            EnvironmentMap::from_texels(Path::new("m.exr"), w, h, t).expect_err("refused")
        };
        assert!(bad(4, 4, vec![Vec3::ONE; 16]).contains("twice as wide"));
        let mut t = vec![Vec3::ONE; 8];
        t[5] = Vec3::new(0.0, f32::NAN, 0.0);
        assert!(bad(4, 2, t).contains("texel (1, 1)"));
        let mut t = vec![Vec3::ONE; 8];
        t[6] = Vec3::new(0.0, f32::INFINITY, 0.0);
        assert!(bad(4, 2, t).contains("texel (2, 1)"));
        let mut t = vec![Vec3::ONE; 8];
        t[2] = Vec3::new(-1.0, 0.0, 0.0);
        assert!(bad(4, 2, t).contains("texel (2, 0)"));
        // Compression noise just below zero reads as black.
        let mut t = vec![Vec3::ONE; 8];
        t[3] = Vec3::new(2.0, -0.04, 0.0);
        let m = EnvironmentMap::from_texels(Path::new("m.exr"), 4, 2, t).expect("noise is not an error");
        assert_eq!(m.texels()[3], Vec3::new(2.0, 0.0, 0.0));
        // A black map samples nothing and reports it.
        let black = SkyMap::new(map(8, |_, _| Vec3::ZERO));
        assert!(black.is_black() && black.sample(Vec2::splat(0.5)).is_none() && black.pdf(Vec3::Y) == 0.0);
    }
}
