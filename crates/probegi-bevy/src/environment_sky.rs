//! Bevy's sky as the field's: a `Skybox` on the camera (its cubemap ×
//! `brightness`, in cd·m⁻²), else the camera's `EnvironmentMapLight` (its
//! specular map's sharpest level × `intensity`), made into probegi's
//! equirectangular sky map (`probegi_scene::environment_map`, Mitsuba's
//! convention) that the field's probe rays read where they leave the scene
//! (`probe_sky_map_on_miss`, which the plugin sets on its volumes: Bevy does
//! not sample the map at its pixels, so the field carries its light).
//!
//! The lookup is Bevy's own (`skybox.wesl`, `environment_map.wesl`): a world
//! direction `d` reads the cubemap along `s = rotation⁻¹ · d` with `s.z`
//! negated (cubemaps are left-handed), on the face of `s`'s major axis with
//! the face coordinates of the Vulkan and WebGPU specifications. Each texel
//! of the equirectangular map reads the cube at its centre's direction,
//! nearest texel: the map has 4 × the face's width across (at most 1 024), so
//! it resolves what the cube does.
//!
//! The host reads `Rgba32Float`, `Rgba16Float`, `Rgb9e5Ufloat`,
//! `Rg11b10Ufloat`, `Rgba8Unorm` and `Rgba8UnormSrgb` ([`host_reads`]). Any
//! other cubemap (block-compressed KTX2: BC6H, ASTC; or one whose texels live
//! only on the device, as a render target's do) is made into the map on the
//! device instead, by the same lookup (`probegi_wgpu::sky_from_cubemap`): the
//! scene then carries a map of the same size, black ([`device_sky_placeholder`]),
//! whose texels the render world writes from Bevy's `GpuImage` each frame.

use std::path::Path;

use bevy::image::{Image, TextureFormatPixelInfo};
use bevy::math::Quat;
use bevy::render::render_resource::{TextureDataOrder, TextureDimension, TextureFormat, TextureSampleType};
use glam::{Vec2, Vec3};
use probegi_core::color::srgb_to_linear;
use probegi_scene::EnvironmentMap;
use probegi_scene::environment_map::uv_to_direction;

/// The widest equirectangular map made from a cubemap.
pub const MAX_SKY_WIDTH: u32 = 1024;

/// An sRGB-encoded byte as linear (the core's transfer function).
fn srgb(c: u8) -> f32 {
    srgb_to_linear(c as f32 / 255.0)
}

/// Linear RGB of one texel of `format`, `None` for a format not read here.
fn decode(format: TextureFormat, b: &[u8]) -> Option<Vec3> {
    let f32_at = |i: usize| f32::from_le_bytes([b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]]);
    let half_at = |i: usize| half_to_f32(u16::from_le_bytes([b[2 * i], b[2 * i + 1]]));
    let word = || u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    Some(match format {
        TextureFormat::Rgba32Float => Vec3::new(f32_at(0), f32_at(1), f32_at(2)),
        TextureFormat::Rgba16Float => Vec3::new(half_at(0), half_at(1), half_at(2)),
        TextureFormat::Rgb9e5Ufloat => rgb9e5(word()),
        TextureFormat::Rg11b10Ufloat => {
            let w = word();
            Vec3::new(small_float(w & 0x7ff, 6), small_float((w >> 11) & 0x7ff, 6), small_float(w >> 22, 5))
        }
        TextureFormat::Rgba8Unorm => Vec3::new(b[0] as f32, b[1] as f32, b[2] as f32) / 255.0,
        TextureFormat::Rgba8UnormSrgb => Vec3::new(srgb(b[0]), srgb(b[1]), srgb(b[2])),
        _ => return None,
    })
}

/// IEEE 754 binary16.
pub fn half_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let (e, m) = (((h >> 10) & 0x1f) as i32, (h & 0x3ff) as f32);
    match e {
        0 => sign * m * 2f32.powi(-24),
        31 if m == 0.0 => sign * f32::INFINITY,
        31 => f32::NAN,
        e => sign * (1.0 + m / 1024.0) * 2f32.powi(e - 15),
    }
}

/// The shared-exponent format: three 9-bit mantissas, a 5-bit exponent
/// (bias 15), no implicit one: `m · 2^(e − 15 − 9)`.
pub fn rgb9e5(w: u32) -> Vec3 {
    let scale = 2f32.powi((w >> 27) as i32 - 24);
    Vec3::new((w & 0x1ff) as f32, ((w >> 9) & 0x1ff) as f32, ((w >> 18) & 0x1ff) as f32) * scale
}

/// An unsigned float of a 5-bit exponent (bias 15) and `mantissa_bits` bits.
fn small_float(bits: u32, mantissa_bits: u32) -> f32 {
    let (e, m) = ((bits >> mantissa_bits) as i32, (bits & ((1 << mantissa_bits) - 1)) as f32);
    let one = (1u32 << mantissa_bits) as f32;
    match e {
        0 => m / one * 2f32.powi(-14),
        31 => f32::INFINITY,
        e => (1.0 + m / one) * 2f32.powi(e - 15),
    }
}

/// Face (0..6: +X, −X, +Y, −Y, +Z, −Z) and (u, v) ∈ [0, 1]² of cube direction `s`.
pub fn cube_face(s: Vec3) -> (usize, Vec2) {
    let a = s.abs();
    let (face, sc, tc, ma) = if a.x >= a.y && a.x >= a.z {
        if s.x > 0.0 { (0, -s.z, -s.y, a.x) } else { (1, s.z, -s.y, a.x) }
    } else if a.y >= a.z {
        if s.y > 0.0 { (2, s.x, s.z, a.y) } else { (3, s.x, -s.z, a.y) }
    } else if s.z > 0.0 {
        (4, s.x, -s.y, a.z)
    } else {
        (5, -s.x, -s.y, a.z)
    };
    (face, Vec2::new(sc / ma + 1.0, tc / ma + 1.0) * 0.5)
}

/// The linear map from a world direction to the direction Bevy reads a
/// cubemap turned by `rotation` along: `rotation⁻¹`, then z negated (the one
/// owner of the lookup, on the host and in `probegi_wgpu::sky_from_cubemap`).
pub fn to_cube(rotation: Quat) -> glam::Mat3 {
    let flip_z = glam::Mat3::from_diagonal(Vec3::new(1.0, 1.0, -1.0));
    flip_z * glam::Mat3::from_quat(glam::Quat::from_array(rotation.inverse().to_array()))
}

/// Whether the host reads `image`'s texels: they are in the main world, in a
/// format [`decode`] knows.
pub fn host_reads(image: &Image) -> bool {
    let format = image.texture_descriptor.format;
    let bpp = format.pixel_size().ok();
    let data = image.data.as_deref();
    matches!((bpp, data), (Some(n), Some(d)) if d.len() >= n && decode(format, &d[..n]).is_some())
}

/// The width of the equirectangular map made from a cube of `face` texels a side.
fn map_width(face: u32) -> u32 {
    (4 * face).clamp(4, MAX_SKY_WIDTH)
}

/// Checks that `image` is a cubemap (6 square layers); returns its face width.
fn cube_width(image: &Image, name: &str) -> Result<u32, String> {
    let d = &image.texture_descriptor;
    let (w, h, layers) = (d.size.width, d.size.height, d.size.depth_or_array_layers);
    if layers != 6 || w != h || w == 0 {
        return Err(format!("{name}: a cubemap has 6 square layers; this image is {w}×{h}×{layers}"));
    }
    Ok(w)
}

/// The black map, of the size [`equirect_from_cubemap`] would make, that a
/// cubemap the host cannot read stands for until the device writes it; an
/// error for an image the device pass cannot read either (not a 2D cubemap
/// of a float format: `probegi_wgpu::sky_from_cubemap`).
pub fn device_sky_placeholder(image: &Image, name: &str) -> Result<EnvironmentMap, String> {
    let face = cube_width(image, name)?;
    let d = &image.texture_descriptor;
    let float = matches!(d.format.sample_type(None, None), Some(TextureSampleType::Float { .. }));
    if d.dimension != TextureDimension::D2 || !float {
        return Err(format!("{name}: a {:?} {:?} image is no cubemap the field can read", d.dimension, d.format));
    }
    let width = map_width(face);
    let texels = vec![Vec3::ZERO; (width * width / 2) as usize];
    EnvironmentMap::from_texels(Path::new(name), width, width / 2, texels).map_err(|e| format!("{name}: {e}"))
}

/// The radiance map of cubemap `image` turned by `rotation` (as Bevy turns
/// a skybox or environment map), its texels scaled by nothing: the caller's
/// `SkyMap::intensity` carries the brightness. `name` names it in messages.
pub fn equirect_from_cubemap(image: &Image, rotation: Quat, name: &str) -> Result<EnvironmentMap, String> {
    let d = &image.texture_descriptor;
    let w = cube_width(image, name)?;
    let bpp = d.format.pixel_size().map_err(|_| {
        format!("{name}: its format {:?} is block-compressed: the device makes its map (module docs)", d.format)
    })?;
    let data = image.data.as_deref().ok_or(format!("{name}: its texels are not in the main world"))?;
    let face_bytes = (w * w) as usize * bpp;
    // Bytes from one layer's first level to the next layer's.
    let layer_stride = match image.data_order {
        TextureDataOrder::LayerMajor => (0..d.mip_level_count).map(|m| ((w >> m).max(1) as usize).pow(2) * bpp).sum(),
        TextureDataOrder::MipMajor => face_bytes,
    };
    if data.len() < 5 * layer_stride + face_bytes {
        return Err(format!("{name}: {} bytes of texels for six {w}×{w} faces of {bpp} bytes", data.len()));
    }
    if decode(d.format, &data[..bpp]).is_none() {
        return Err(format!("{name}: its format {:?} is not one the field reads (module docs)", d.format));
    }
    let to_cube = to_cube(rotation);
    let width = map_width(w);
    let height = width / 2;
    let texels = (0..height)
        .flat_map(|j| (0..width).map(move |i| (i, j)))
        .map(|(i, j)| {
            let uv = Vec2::new((i as f32 + 0.5) / width as f32, (j as f32 + 0.5) / height as f32);
            let (face, st) = cube_face(to_cube * uv_to_direction(uv));
            let texel = |t: f32| ((t * w as f32) as u32).min(w - 1);
            let (x, y) = (texel(st.x), texel(st.y));
            let at = face * layer_stride + (y * w + x) as usize * bpp;
            decode(d.format, &data[at..at + bpp]).unwrap_or(Vec3::ZERO)
        })
        .collect();
    EnvironmentMap::from_texels(Path::new(name), width, height, texels).map_err(|e| format!("{name}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_float_formats_decode_to_their_values() {
        // 9-bit mantissas 256, 128, 0 at exponent 16: 256·2^(16−24) = 1, 0.5, 0.
        assert_eq!(rgb9e5(256 | 128 << 9 | 16 << 27), Vec3::new(1.0, 0.5, 0.0));
        assert_eq!(half_to_f32(0x3c00), 1.0);
        assert_eq!(half_to_f32(0xc000), -2.0);
        // 11-bit 1.0 (e 15, m 0) and 10-bit 2.0 (e 16, m 0).
        let w = (15 << 6) | (15 << 6) << 11 | (16 << 5) << 22;
        assert_eq!(decode(TextureFormat::Rg11b10Ufloat, &u32::to_le_bytes(w)), Some(Vec3::new(1.0, 1.0, 2.0)));
        assert!((srgb(128) - 0.2158605).abs() < 1e-6);
    }

    #[test]
    fn each_axis_reads_the_centre_of_its_face() {
        let axes = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        for (k, a) in axes.iter().enumerate() {
            assert_eq!(cube_face(*a), (k, Vec2::splat(0.5)), "{a}");
        }
        // +X's face: u runs toward −z, v toward −y (the specification's table).
        let (_, st) = cube_face(Vec3::new(1.0, -0.5, -0.5));
        assert_eq!(st, Vec2::new(0.75, 0.75));
    }
}
