//! Image files. `.exr` holds linear HDR radiance (RGB, 32-bit float); `.png` holds
//! the tone-mapped 8-bit sRGB image (`probegi_core::color::tonemap`). Writes go to
//! a temporary file (`NAME.partial-PID-N.EXT`, unique per process and write) that
//! is renamed into place, so a failed or interrupted write never leaves a partial
//! image under the requested name and concurrent writers never share one. An image
//! with a non-finite or negative pixel is refused before anything is written.

use std::path::{Path, PathBuf};

use glam::Vec3;
use probegi_core::color::{srgb_to_linear, tonemap_rgb8};
use probegi_core::image::Image;

/// Why an image file could not be read, written or compared; each names its file.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// Reading, decoding, encoding or writing the file failed.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// The extension is neither `.exr` nor `.png`.
    #[error("{path}: unsupported image extension (expected .exr or .png)")]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
    /// A pixel to be written is NaN, infinite or negative.
    #[error("{path}: pixel ({x}, {y}) is {value} (radiance must be finite and non-negative)")]
    NonFinite {
        /// The file that was not written.
        path: PathBuf,
        /// Column of the first such pixel.
        x: u32,
        /// Row of the first such pixel.
        y: u32,
        /// Its value, as text.
        value: String,
    },
    /// The output's extension is not the one this output needs.
    #[error("{path}: the file name must end in .{expected} for this output")]
    WrongExtension {
        /// The file.
        path: PathBuf,
        /// The extension it needs, without the dot.
        expected: &'static str,
    },
    /// Two images to compare differ in size.
    #[error("image sizes differ: {reference} is {rw}×{rh}, {test} is {tw}×{th}")]
    SizeMismatch {
        /// The reference image.
        reference: PathBuf,
        /// The reference's width in pixels.
        rw: u32,
        /// The reference's height in pixels.
        rh: u32,
        /// The test image.
        test: PathBuf,
        /// The test image's width in pixels.
        tw: u32,
        /// The test image's height in pixels.
        th: u32,
    },
}

/// The file formats this crate reads and writes, by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ImageFormat {
    Exr,
    Png,
}

impl ImageFormat {
    pub(crate) fn from_path(path: &Path) -> Result<Self, ImageError> {
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
    /// Linear HDR radiance, from an `.exr`.
    Hdr(Image),
    /// Display-referred 8-bit sRGB, from a `.png`.
    Srgb8 {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// RGB bytes, row-major, three per pixel.
        rgb: Vec<u8>,
    },
}

impl LoadedImage {
    /// Width and height in pixels.
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

/// `NAME.partial-PID-N.EXT` beside `path`: unique per process and call, with the
/// real extension last so that format-sniffing writers accept it.
pub(crate) fn temp_path(path: &Path) -> PathBuf {
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut name = path.file_stem().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(format!(".partial-{}-{n}", std::process::id()));
    if let Some(ext) = path.extension() {
        name.push(".");
        name.push(ext);
    }
    path.with_file_name(name)
}

/// The image's first pixel that is not a finite, non-negative radiance, as an error
/// naming the output.
pub(crate) fn check_finite(path: &Path, img: &Image) -> Result<(), ImageError> {
    match img.first_invalid_pixel() {
        None => Ok(()),
        Some(i) => Err(ImageError::NonFinite {
            path: path.to_path_buf(),
            x: i as u32 % img.width.max(1),
            y: i as u32 / img.width.max(1),
            value: format!("{}", img.pixels[i]),
        }),
    }
}

/// Refuses a path whose extension is not `expected` (case-insensitive).
pub(crate) fn check_extension(path: &Path, expected: &'static str) -> Result<(), ImageError> {
    match path.extension().map(|e| e.to_string_lossy().to_lowercase()) {
        Some(e) if e == expected => Ok(()),
        _ => Err(ImageError::WrongExtension { path: path.to_path_buf(), expected }),
    }
}

/// Writes radiance to `.exr` (linear) or `.png` (tone-mapped), atomically.
pub fn write_image(path: &Path, img: &Image) -> Result<(), ImageError> {
    let format = ImageFormat::from_path(path)?;
    check_finite(path, img)?;
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
    commit(&tmp, path, result)
}

/// Renames the finished temporary file `tmp` onto `path`, or removes it: on
/// every failure (the write's, or the rename's, e.g. when `path` is a
/// directory) nothing is left behind.
pub(crate) fn commit(tmp: &Path, path: &Path, written: Result<(), ImageError>) -> Result<(), ImageError> {
    let result = written.and_then(|()| {
        if path.is_dir() {
            return Err(io_err(path, "is a directory"));
        }
        std::fs::rename(tmp, path).map_err(|e| io_err(path, e))
    });
    if result.is_err() {
        std::fs::remove_file(tmp).ok();
    }
    result
}

/// Whether an output file can be written at `path`, checked before a long
/// render instead of at its end: a supported image extension (when `image`),
/// not an existing directory, and a folder that exists or can be made (its
/// nearest existing ancestor a writable directory). Creates nothing that
/// stays.
pub fn check_output_path(path: &Path, image: bool) -> Result<(), ImageError> {
    if image {
        ImageFormat::from_path(path)?;
    }
    if path.is_dir() {
        return Err(io_err(path, "is a directory; give a file name"));
    }
    let parent = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let Some(existing) = parent.ancestors().find(|a| a.as_os_str().is_empty() || a.exists()) else {
        return Ok(());
    };
    let existing = if existing.as_os_str().is_empty() { Path::new(".") } else { existing };
    if !existing.is_dir() {
        return Err(io_err(path, format!("{} is not a directory", existing.display())));
    }
    let probe = temp_path(&existing.join(".probegi-write-check"));
    std::fs::write(&probe, b"").map_err(|e| io_err(path, format!("cannot write in {}: {e}", existing.display())))?;
    std::fs::remove_file(&probe).ok();
    Ok(())
}

/// Writes 8-bit sRGB data as PNG, atomically.
pub fn write_png(path: &Path, width: u32, height: u32, rgb: Vec<u8>) -> Result<(), ImageError> {
    check_extension(path, "png")?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| io_err(path, e))?;
    }
    let tmp = temp_path(path);
    let written = write_png_rgb8(&tmp, width, height, rgb).map_err(|e| io_err(path, e));
    commit(&tmp, path, written)
}

fn write_png_rgb8(path: &Path, width: u32, height: u32, rgb: Vec<u8>) -> Result<(), String> {
    let buf = image::RgbImage::from_raw(width, height, rgb).ok_or("pixel count does not match size")?;
    buf.save_with_format(path, image::ImageFormat::Png).map_err(|e| e.to_string())
}

/// The largest image `read_image` loads, in pixels (8192 × 4096), so a header
/// claiming more cannot exhaust memory.
pub const MAX_READ_PIXELS: u64 = 1 << 25;

/// Reads an `.exr` (first RGB(A) layer, linear) or `.png` (8-bit sRGB).
pub fn read_image(path: &Path) -> Result<LoadedImage, ImageError> {
    if !path.exists() {
        return Err(io_err(path, "file not found"));
    }
    match ImageFormat::from_path(path)? {
        ImageFormat::Exr => {
            // The header's size against a bound before the reader allocates for it.
            let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| io_err(path, e))?;
            for h in &meta.headers {
                let (w, hh) = (h.layer_size.x() as u64, h.layer_size.y() as u64);
                if w * hh > MAX_READ_PIXELS {
                    return Err(io_err(
                        path,
                        format!("{w}×{hh} pixels is more than this tool reads ({MAX_READ_PIXELS})"),
                    ));
                }
            }
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

    #[test]
    fn a_directory_as_output_fails_and_leaves_no_temporary_file() {
        let dir = std::env::temp_dir().join(format!("probegi-io-dir-{}", std::process::id()));
        let out = dir.join("taken.png");
        std::fs::create_dir_all(&out).expect("dir");
        let img = Image { width: 2, height: 1, pixels: vec![Vec3::ONE; 2] };
        assert!(check_output_path(&out, true).is_err());
        assert!(write_image(&out, &img).is_err());
        assert!(write_image(&out.with_extension("exr"), &img).is_ok());
        assert!(write_png(&out, 1, 1, vec![0, 0, 0]).is_err());
        let names: Vec<String> = std::fs::read_dir(&dir)
            .expect("list")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().all(|n| !n.contains("partial")), "{names:?}");
        assert!(check_output_path(&dir.join("new/deeper/o.exr"), true).is_ok());
        assert!(!dir.join("new").exists(), "the check creates nothing");
        assert!(check_output_path(&out.join("o.png"), true).is_ok(), "inside the directory is fine");
        assert!(check_output_path(&dir.join("taken.png.exr/x.png"), true).is_ok());
        std::fs::write(dir.join("file"), b"").expect("file");
        assert!(check_output_path(&dir.join("file/o.png"), true).is_err(), "a file as a folder");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn temporary_names_are_unique_and_keep_the_extension() {
        let (a, b) = (temp_path(Path::new("out/o.exr")), temp_path(Path::new("out/o.exr")));
        assert_ne!(a, b);
        let name = a.file_name().expect("name").to_string_lossy().into_owned();
        assert!(name.starts_with(&format!("o.partial-{}-", std::process::id())) && name.ends_with(".exr"), "{name}");
        assert!(!name.contains(".exr.exr"), "{name}");
    }

    #[test]
    fn non_finite_images_are_refused_and_leave_the_previous_file() {
        let dir = std::env::temp_dir().join(format!("probegi-io-nan-{}", std::process::id()));
        let path = dir.join("o.exr");
        write_image(&path, &gradient()).expect("first write");
        let mut bad = gradient();
        bad.pixels[7] = Vec3::new(0.0, f32::NAN, 0.0);
        let e = write_image(&path, &bad).expect_err("NaN").to_string();
        assert!(e.contains("o.exr") && e.contains("(2, 1)"), "{e}");
        let LoadedImage::Hdr(back) = read_image(&path).expect("read") else { panic!("HDR") };
        assert_eq!(back, gradient(), "the previous file is intact");
        let names: Vec<_> = std::fs::read_dir(&dir).expect("dir").flatten().map(|e| e.file_name()).collect();
        assert_eq!(names.len(), 1, "no temporary left: {names:?}");
        assert!(write_png(&dir.join("sheet.jpg"), 1, 1, vec![0, 0, 0]).is_err(), "PNG data under .jpg");
        std::fs::remove_dir_all(&dir).ok();
    }
}
