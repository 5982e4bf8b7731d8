//! `probegi compare`: LDR-FLIP (Andersson et al. 2020, NVIDIA's implementation via
//! the nv-flip crate) between a reference and a test image, and the contact sheet
//! reference | test | error map in the magma colour map, as the seed papers show
//! their figures.
//!
//! HDR (EXR) input is first mapped to 8-bit sRGB with the one fixed operator of
//! `probegi_core::color::tonemap`; PNG input is taken as already display-referred.

use std::path::Path;

use crate::io::{ImageError, LoadedImage, read_image, write_png};

/// FLIP's default viewing condition: 0.7 m from a 0.68 m wide 3840-pixel monitor.
pub const FLIP_PIXELS_PER_DEGREE: f32 = nv_flip::DEFAULT_PIXELS_PER_DEGREE;

/// FLIP between two images: the mean and the per-pixel error map.
pub struct FlipResult {
    /// Width of the compared images in pixels.
    pub width: u32,
    /// Height of the compared images in pixels.
    pub height: u32,
    /// Mean of the per-pixel FLIP error, in [0, 1].
    pub mean_flip: f32,
    /// Per-pixel error, row-major.
    pub error_map: Vec<f32>,
}

/// FLIP between two 8-bit sRGB images of equal size.
pub fn flip_srgb8(width: u32, height: u32, reference: &[u8], test: &[u8]) -> FlipResult {
    let r = nv_flip::FlipImageRgb8::with_data(width, height, reference);
    let t = nv_flip::FlipImageRgb8::with_data(width, height, test);
    let err = nv_flip::flip(r, t, FLIP_PIXELS_PER_DEGREE);
    let mean_flip = nv_flip::FlipPool::from_image(&err).mean();
    FlipResult { width, height, mean_flip, error_map: err.to_vec() }
}

/// Mean FLIP between two in-memory HDR images, both through the fixed tone map;
/// `None` when their sizes differ.
pub fn mean_flip_hdr(reference: &probegi_core::image::Image, test: &probegi_core::image::Image) -> Option<f32> {
    if (reference.width, reference.height) != (test.width, test.height) {
        return None;
    }
    let (r, t) = (LoadedImage::Hdr(reference.clone()).to_srgb8(), LoadedImage::Hdr(test.clone()).to_srgb8());
    Some(flip_srgb8(reference.width, reference.height, &r, &t).mean_flip)
}

/// FLIP between two loaded images; sizes must match.
pub fn flip_images(
    reference: &LoadedImage,
    reference_path: &Path,
    test: &LoadedImage,
    test_path: &Path,
) -> Result<FlipResult, ImageError> {
    let (rw, rh) = reference.size();
    let (tw, th) = test.size();
    if (rw, rh) != (tw, th) {
        return Err(ImageError::SizeMismatch {
            reference: reference_path.to_path_buf(),
            rw,
            rh,
            test: test_path.to_path_buf(),
            tw,
            th,
        });
    }
    Ok(flip_srgb8(rw, rh, &reference.to_srgb8(), &test.to_srgb8()))
}

/// Magma-mapped error map as 8-bit RGB.
pub fn error_map_magma(result: &FlipResult) -> Vec<u8> {
    let err = nv_flip::FlipImageFloat::with_data(result.width, result.height, &result.error_map);
    err.apply_color_lut(&nv_flip::magma_lut()).to_vec()
}

/// Three images side by side: reference | test | magma error map.
pub fn contact_sheet(width: u32, height: u32, reference: &[u8], test: &[u8], magma: &[u8]) -> Vec<u8> {
    let (w, h) = (width as usize, height as usize);
    let mut sheet = vec![0u8; 3 * w * h * 3];
    for y in 0..h {
        for (panel, src) in [reference, test, magma].iter().enumerate() {
            let dst = (y * 3 * w + panel * w) * 3;
            sheet[dst..dst + 3 * w].copy_from_slice(&src[y * w * 3..(y + 1) * w * 3]);
        }
    }
    sheet
}

/// A pixel is *lit* in the reference when its luminance is at least this
/// share of the reference's mean luminance.
pub const DARK_LIT_SHARE_OF_MEAN: f32 = 0.05;
/// A lit pixel is *dark* in the test below this share of the reference's luminance.
pub const DARK_BELOW_SHARE: f32 = 0.25;

/// The share of the reference's lit pixels that the test renders dark (the
/// issue "Denser is better…"'s measure of black walls and stale probes that a
/// mean error hides): lit is luminance ≥ [`DARK_LIT_SHARE_OF_MEAN`] × the
/// reference's mean, dark is under [`DARK_BELOW_SHARE`] × the reference's
/// pixel. `None` when the sizes differ or nothing is lit.
pub fn dark_fraction(reference: &probegi_core::image::Image, test: &probegi_core::image::Image) -> Option<f32> {
    if (reference.width, reference.height) != (test.width, test.height) {
        return None;
    }
    let lum = |p: glam::Vec3| p.dot(glam::Vec3::new(0.2126, 0.7152, 0.0722));
    let n = reference.pixels.len().max(1) as f32;
    let mean = reference.pixels.iter().map(|p| lum(*p)).sum::<f32>() / n;
    let (mut lit, mut dark) = (0usize, 0usize);
    for (r, t) in reference.pixels.iter().zip(&test.pixels) {
        let lr = lum(*r);
        if lr >= DARK_LIT_SHARE_OF_MEAN * mean && lr > 0.0 {
            lit += 1;
            dark += usize::from(lum(*t) < DARK_BELOW_SHARE * lr);
        }
    }
    (lit > 0).then(|| dark as f32 / lit as f32)
}

/// The test's mean radiance over the reference's, per channel (R, G, B): an
/// energy difference (a leak, missing light) that FLIP, which also counts noise,
/// does not tell apart. A channel whose reference mean is zero gives NaN.
/// `None` when the sizes differ.
pub fn mean_ratio(reference: &probegi_core::image::Image, test: &probegi_core::image::Image) -> Option<glam::Vec3> {
    if (reference.width, reference.height) != (test.width, test.height) {
        return None;
    }
    // Summed in f64: a 1080p image's sum in f32 loses the last digits the ratio shows.
    let sum = |img: &probegi_core::image::Image| img.pixels.iter().fold(glam::DVec3::ZERO, |s, p| s + p.as_dvec3());
    let (r, t) = (sum(reference), sum(test));
    let ratio = |t: f64, r: f64| if r > 0.0 { (t / r) as f32 } else { f32::NAN };
    Some(glam::Vec3::new(ratio(t.x, r.x), ratio(t.y, r.y), ratio(t.z, r.z)))
}

/// The whole `compare` command: loads both files, computes FLIP, optionally
/// writes the contact sheet. Returns the mean FLIP.
pub fn compare_files(reference_path: &Path, test_path: &Path, sheet_path: Option<&Path>) -> Result<f32, ImageError> {
    let reference = read_image(reference_path)?;
    let test = read_image(test_path)?;
    // A score over NaN or Inf pixels would be silently meaningless.
    for (img, path) in [(&reference, reference_path), (&test, test_path)] {
        if let LoadedImage::Hdr(hdr) = img {
            crate::io::check_finite(path, hdr)?;
        }
    }
    let result = flip_images(&reference, reference_path, &test, test_path)?;
    if let Some(sheet) = sheet_path {
        let magma = error_map_magma(&result);
        let rgb = contact_sheet(result.width, result.height, &reference.to_srgb8(), &test.to_srgb8(), &magma);
        write_png(sheet, result.width * 3, result.height, rgb)?;
    }
    Ok(result.mean_flip)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32, shift: u8) -> Vec<u8> {
        (0..w * h)
            .flat_map(|i| {
                let v = ((i % w) * 255 / w) as u8;
                [v.saturating_add(shift), v, 255 - v]
            })
            .collect()
    }

    #[test]
    fn dark_fraction_counts_lit_pixels_rendered_under_a_quarter() {
        use probegi_core::image::Image;
        let mut reference = Image::new(4, 1);
        reference.pixels = vec![glam::Vec3::ONE, glam::Vec3::ONE, glam::Vec3::ONE, glam::Vec3::ZERO];
        let mut test = reference.clone();
        assert_eq!(dark_fraction(&reference, &test), Some(0.0));
        test.pixels[0] = glam::Vec3::splat(0.2);
        test.pixels[1] = glam::Vec3::splat(0.3);
        assert_eq!(dark_fraction(&reference, &test), Some(1.0 / 3.0), "one of three lit pixels under a quarter");
        assert_eq!(dark_fraction(&Image::new(4, 1), &test), None, "nothing lit");
    }

    #[test]
    fn mean_ratio_is_the_test_over_the_reference_per_channel() {
        use probegi_core::image::Image;
        let mut reference = Image::new(2, 1);
        reference.pixels = vec![glam::Vec3::new(1.0, 2.0, 0.0), glam::Vec3::new(3.0, 2.0, 0.0)];
        let mut test = reference.clone();
        test.pixels[0] = glam::Vec3::new(2.0, 2.0, 1.0);
        let r = mean_ratio(&reference, &test).expect("equal sizes");
        assert_eq!((r.x, r.y), (1.25, 1.0), "(2 + 3) / (1 + 3) and equal greens");
        assert!(r.z.is_nan(), "a black reference channel has no ratio");
        assert!(mean_ratio(&Image::new(3, 1), &test).is_none(), "sizes differ");
    }

    #[test]
    fn identical_images_have_zero_flip_and_different_ones_do_not() {
        let a = ramp(32, 16, 0);
        assert_eq!(flip_srgb8(32, 16, &a, &a).mean_flip, 0.0);
        let b = ramp(32, 16, 40);
        let small = flip_srgb8(32, 16, &a, &b).mean_flip;
        let black = vec![0u8; a.len()];
        let large = flip_srgb8(32, 16, &a, &black).mean_flip;
        assert!(small > 0.01 && large > small && large <= 1.0, "small {small}, large {large}");
    }

    #[test]
    fn hdr_flip_is_zero_for_equal_images_and_none_for_different_sizes() {
        let mut a = probegi_core::image::Image::new(8, 8);
        a.set(3, 3, glam::Vec3::splat(2.0));
        assert_eq!(mean_flip_hdr(&a, &a), Some(0.0));
        assert!(mean_flip_hdr(&a, &probegi_core::image::Image::new(8, 8)).expect("same size") > 0.0);
        assert_eq!(mean_flip_hdr(&a, &probegi_core::image::Image::new(8, 9)), None);
    }

    #[test]
    fn contact_sheet_places_three_panels() {
        let (w, h) = (4, 2);
        let a = vec![10u8; 24];
        let b = vec![20u8; 24];
        let c = vec![30u8; 24];
        let s = contact_sheet(w, h, &a, &b, &c);
        assert_eq!(s.len(), 3 * 24);
        assert_eq!(&s[0..3], &[10, 10, 10]);
        assert_eq!(&s[12..15], &[20, 20, 20]);
        assert_eq!(&s[24..27], &[30, 30, 30]);
        assert_eq!(&s[36..39], &[10, 10, 10], "second row starts with the reference again");
    }

    #[test]
    fn comparing_an_image_with_nan_is_an_error_not_a_score() {
        let dir = std::env::temp_dir().join(format!("probegi-compare-nan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("mkdir");
        let (good, bad) = (dir.join("good.exr"), dir.join("bad.exr"));
        exr::prelude::write_rgb_file(&good, 4, 4, |_, _| (0.5f32, 0.5f32, 0.5f32)).expect("write");
        exr::prelude::write_rgb_file(
            &bad,
            4,
            4,
            |x, y| if (x, y) == (2, 3) { (f32::NAN, 0.0, 0.0) } else { (0.5, 0.5, 0.5) },
        )
        .expect("write");
        assert!(compare_files(&good, &good, None).is_ok());
        let e = compare_files(&good, &bad, None).expect_err("NaN").to_string();
        assert!(e.contains("bad.exr") && e.contains("(2, 3)"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
