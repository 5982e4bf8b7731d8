//! The linear-RGB float image every renderer writes: row-major, row 0 at the top,
//! one `Vec3` of radiance (W·sr⁻¹·m⁻², per channel) per pixel.

use glam::Vec3;

/// A linear-RGB float image: `width × height` pixels of radiance, row-major with row 0
/// at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Pixels per row.
    pub width: u32,
    /// Number of rows.
    pub height: u32,
    /// Radiance per pixel (W·sr⁻¹·m⁻² per channel); pixel `(x, y)` is at
    /// `y · width + x`, `width · height` in all.
    pub pixels: Vec<Vec3>,
}

impl Image {
    /// A black (all-zero) image of `width × height` pixels.
    pub fn new(width: u32, height: u32) -> Self {
        Self { width, height, pixels: vec![Vec3::ZERO; width as usize * height as usize] }
    }

    /// Wraps row-major `pixels` as a `width × height` image; `None` unless
    /// `pixels.len() == width · height`.
    pub fn from_pixels(width: u32, height: u32, pixels: Vec<Vec3>) -> Option<Self> {
        (pixels.len() == width as usize * height as usize).then_some(Self { width, height, pixels })
    }

    /// Radiance of pixel `(x, y)` (x right, y down from the top row); panics if
    /// `y · width + x` is past the last pixel.
    pub fn get(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[y as usize * self.width as usize + x as usize]
    }

    /// Sets pixel `(x, y)` (x right, y down from the top row) to `value`; panics if
    /// `y · width + x` is past the last pixel.
    pub fn set(&mut self, x: u32, y: u32, value: Vec3) {
        let w = self.width as usize;
        self.pixels[y as usize * w + x as usize] = value;
    }

    /// Mean of all pixels, accumulated in f64.
    pub fn mean(&self) -> Vec3 {
        if self.pixels.is_empty() {
            return Vec3::ZERO;
        }
        let mut s = glam::DVec3::ZERO;
        for p in &self.pixels {
            s += p.as_dvec3();
        }
        (s / self.pixels.len() as f64).as_vec3()
    }

    /// Index of the first pixel that is NaN, infinite or negative.
    pub fn first_invalid_pixel(&self) -> Option<usize> {
        self.pixels.iter().position(|p| !p.is_finite() || p.min_element() < 0.0)
    }
}
