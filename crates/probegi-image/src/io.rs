//! Image files. `.exr` holds linear HDR radiance (RGB, 32-bit float); `.png` holds
//! the tone-mapped 8-bit sRGB image (`probegi_core::color::tonemap`). Writes go to
//! a temporary file that is renamed into place, so a failed or interrupted write
//! never leaves a partial image under the requested name.

use std::path::{Path, PathBuf};

use glam::Vec3;
use probegi_core::color::{srgb_to_linear, tonemap_rgb8};
use probegi_core::image::Image;

#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("{path}: unsupported image extension (expected .exr or .png)")]
    UnsupportedFormat { path: PathBuf },
    #[error("image sizes differ: {reference} is {rw}×{rh}, {test} is {tw}×{th}")]
    SizeMismatch { reference: PathBuf, rw: u32, rh: u32, test: PathBuf, tw: u32, th: u32 },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    Exr,
    Png,
}

impl ImageFormat {
    pub fn from_path(path: &Path) -> Result<Self, ImageError> {
        match path.extension().map(|e| e.to_string_lossy().to_lowercase()).as_deref() {
            Some("exr") => Ok(Self::Exr),
            Some("png") => Ok(Self::Png),
            _ => Err(ImageError::UnsupportedFormat { path: path.to_path_buf() }),
        }
    }
}

/// An image file's content: HDR radiance (EXR) or display-referred 8-bit sRGB (PNG).
#[derive(Clone, Debug)]
pub enum LoadedImage {
    Hdr(Image),
    Srgb8 { width: u32, height: u32, rgb: Vec<u8> },
}

impl LoadedImage {
    pub fn size(&self) -> (u32, u32) {
        match self {
            Self::Hdr(i) => (i.width, i.height),
            Self::Srgb8 { width, height, .. } => (*width, *height),
        }
    }

    /// Display-referred 8-bit sRGB: HDR goes through the one fixed tone-map operator.
    pub fn to_srgb8(&self) -> Vec<u8> {
        match self {
            Self::Hdr(img) => img.pixels.iter().flat_map(|p| tonemap_rgb8(*p)).collect(),
            Self::Srgb8 { rgb, .. } => rgb.clone(),
        }
    }

    /// Linear radiance (PNG input is sRGB-decoded; it is display-referred, not radiance).
    pub fn to_linear(&self) -> Image {
        match self {
            Self::Hdr(img) => img.clone(),
            Self::Srgb8 { width, height, rgb } => Image {
                width: *width,
                height: *height,
                pixels: rgb
                    .chunks_exact(3)
                    .map(|c| {
                        Vec3::new(
                            srgb_to_linear(c[0] as f32 / 255.0),
                            srgb_to_linear(c[1] as f32 / 255.0),
                            srgb_to_linear(c[2] as f32 / 255.0),
                        )
                    })
                    .collect(),
            },
        }
    }
}

pub(crate) fn io_err(path: &Path, e: impl std::fmt::Display) -> ImageError {
    ImageError::Io { path: path.to_path_buf(), message: e.to_string() }
}

pub(crate) fn temp_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(format!(".partial-{}", std::process::id()));
    let ext = path.extension().map(|e| e.to_os_string()).unwrap_or_default();
    // Keep the real extension last so that format-sniffing writers accept it.
    let mut p = path.with_file_name(name);
    p.set_extension(ext);
    p
}

/// Writes radiance to `.exr` (linear) or `.png` (tone-mapped), atomically.
pub fn write_image(path: &Path, img: &Image) -> Result<(), ImageError> {
    let format = ImageFormat::from_path(path)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| io_err(path, e))?;
    }
    let tmp = temp_path(path);
    let result = match format {
        ImageFormat::Exr => {
            let w = img.width as usize;
            exr::prelude::write_rgb_file(&tmp, w, img.height as usize, |x, y| {
                let p = img.pixels[y * w + x];
                (p.x, p.y, p.z)
            })
            .map_err(|e| io_err(path, e))
        }
        ImageFormat::Png => {
            let rgb: Vec<u8> = img.pixels.iter().flat_map(|p| tonemap_rgb8(*p)).collect();
            write_png_rgb8(&tmp, img.width, img.height, rgb).map_err(|e| io_err(path, e))
        }
    };
    match result {
        Ok(()) => std::fs::rename(&tmp, path).map_err(|e| io_err(path, e)),
        Err(e) => {
            std::fs::remove_file(&tmp).ok();
            Err(e)
        }
    }
}

/// Writes 8-bit sRGB data as PNG, atomically.
pub fn write_png(path: &Path, width: u32, height: u32, rgb: Vec<u8>) -> Result<(), ImageError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| io_err(path, e))?;
    }
    let tmp = temp_path(path);
    match write_png_rgb8(&tmp, width, height, rgb) {
        Ok(()) => std::fs::rename(&tmp, path).map_err(|e| io_err(path, e)),
        Err(e) => {
            std::fs::remove_file(&tmp).ok();
            Err(io_err(path, e))
        }
    }
}

fn write_png_rgb8(path: &Path, width: u32, height: u32, rgb: Vec<u8>) -> Result<(), String> {
    let buf = image::RgbImage::from_raw(width, height, rgb).ok_or("pixel count does not match size")?;
    buf.save_with_format(path, image::ImageFormat::Png).map_err(|e| e.to_string())
}

/// Reads an `.exr` (first RGB(A) layer, linear) or `.png` (8-bit sRGB).
pub fn read_image(path: &Path) -> Result<LoadedImage, ImageError> {
    if !path.exists() {
        return Err(io_err(path, "file not found"));
    }
    match ImageFormat::from_path(path)? {
        ImageFormat::Exr => {
            let img = exr::prelude::read_first_rgba_layer_from_file(
                path,
                |res, _| Image::new(res.width() as u32, res.height() as u32),
                |img: &mut Image, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                    img.set(pos.x() as u32, pos.y() as u32, Vec3::new(r, g, b));
                },
            )
            .map_err(|e| io_err(path, e))?;
            Ok(LoadedImage::Hdr(img.layer_data.channel_data.pixels))
        }
        ImageFormat::Png => {
            let img = image::ImageReader::open(path)
                .map_err(|e| io_err(path, e))?
                .with_guessed_format()
                .map_err(|e| io_err(path, e))?
                .decode()
                .map_err(|e| io_err(path, e))?
                .to_rgb8();
            let (width, height) = img.dimensions();
            Ok(LoadedImage::Srgb8 { width, height, rgb: img.into_raw() })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient() -> Image {
        let mut img = Image::new(5, 3);
        for y in 0..3 {
            for x in 0..5 {
                img.set(x, y, Vec3::new(x as f32 * 3.7, y as f32 * 0.01, 1e-3));
            }
        }
        img
    }

    #[test]
    fn exr_round_trip_is_exact() {
        let path = std::env::temp_dir().join(format!("probegi-io-{}.exr", std::process::id()));
        let img = gradient();
        write_image(&path, &img).expect("write");
        let LoadedImage::Hdr(back) = read_image(&path).expect("read") else { panic!("EXR must load as HDR") };
        assert_eq!(back, img);
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn png_round_trip_is_the_tone_mapped_image() {
        let path = std::env::temp_dir().join(format!("probegi-io-{}.png", std::process::id()));
        let img = gradient();
        write_image(&path, &img).expect("write");
        let back = read_image(&path).expect("read");
        assert_eq!(back.size(), (5, 3));
        assert_eq!(back.to_srgb8(), LoadedImage::Hdr(img).to_srgb8());
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn bad_paths_are_errors_that_name_the_file() {
        let e = write_image(Path::new("/tmp/x.bmp"), &gradient()).expect_err("bmp unsupported");
        assert!(e.to_string().contains("x.bmp"));
        let e = read_image(Path::new("/nonexistent/y.exr")).expect_err("missing");
        assert!(e.to_string().contains("y.exr"));
        let bogus = std::env::temp_dir().join(format!("probegi-bogus-{}.exr", std::process::id()));
        std::fs::write(&bogus, b"not an exr").expect("write");
        assert!(read_image(&bogus).expect_err("corrupt").to_string().contains("probegi-bogus"));
        std::fs::remove_file(&bogus).ok();
    }
}
