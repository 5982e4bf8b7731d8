//! The linear-RGB float image every renderer writes: row-major, row 0 at the top,
//! one `Vec3` of radiance (W·sr⁻¹·m⁻², per channel) per pixel.

use glam::Vec3;

#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
}

impl Image {
    pub fn new(width: u32, height: u32) -> Self {
        Self { width, height, pixels: vec![Vec3::ZERO; width as usize * height as usize] }
    }

    pub fn from_pixels(width: u32, height: u32, pixels: Vec<Vec3>) -> Option<Self> {
        (pixels.len() == width as usize * height as usize).then_some(Self { width, height, pixels })
    }

    pub fn get(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[y as usize * self.width as usize + x as usize]
    }

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
