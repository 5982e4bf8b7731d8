//! Pinhole camera maths. Conventions: y-up world, right-handed, the camera looks
//! from `position` toward `target`; `fov_y_deg` is the full vertical field of
//! view; pixel (0,0) is the top-left corner of the image and pixel centres are at
//! half-integers (box filter = uniform jitter inside `[x, x+1) × [y, y+1)`).

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// A pinhole camera as written in scene files and on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Eye position, metres, world space.
    pub position: Vec3,
    /// Point looked at, metres, world space.
    pub target: Vec3,
    /// World-space up hint.
    #[serde(default = "default_up")]
    pub up: Vec3,
    /// Full vertical field of view in degrees.
    pub fov_y_deg: f32,
}

fn default_up() -> Vec3 {
    Vec3::Y
}

impl Default for Camera {
    /// The Cornell-box camera of the foundation issue: from (0,1,3.9) at (0,1,0), 39.3° vertical.
    fn default() -> Self {
        Self { position: Vec3::new(0.0, 1.0, 3.9), target: Vec3::new(0.0, 1.0, 0.0), up: Vec3::Y, fov_y_deg: 39.3 }
    }
}

impl Camera {
    /// Why this camera cannot produce an image, if it cannot.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.position.is_finite() && self.target.is_finite() && self.up.is_finite()) {
            return Err("camera position, target and up must be finite".into());
        }
        if (self.target - self.position).length_squared() < 1e-12 {
            return Err("camera target equals camera position".into());
        }
        if (self.target - self.position).normalize().cross(self.up.normalize_or_zero()).length_squared() < 1e-10 {
            return Err("camera up is parallel to the view direction".into());
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 179.0) {
            return Err(format!("fov_y_deg = {} must be in (0, 179)", self.fov_y_deg));
        }
        Ok(())
    }
}

/// A camera prepared for one image size: maps continuous pixel coordinates to world rays.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraRays {
    pub origin_world: Vec3,
    forward_world: Vec3,
    right_world: Vec3,
    up_world: Vec3,
    tan_half_fov_y: f32,
    aspect: f32,
    width: f32,
    height: f32,
}

impl CameraRays {
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        let forward_world = (camera.target - camera.position).normalize();
        let right_world = forward_world.cross(camera.up).normalize();
        let up_world = right_world.cross(forward_world);
        Self {
            origin_world: camera.position,
            forward_world,
            right_world,
            up_world,
            tan_half_fov_y: (camera.fov_y_deg.to_radians() * 0.5).tan(),
            aspect: width as f32 / height as f32,
            width: width as f32,
            height: height as f32,
        }
    }

    /// Unit world direction through continuous pixel position (`x` right, `y` down).
    pub fn ray_dir_world(&self, x: f32, y: f32) -> Vec3 {
        let ndc_x = 2.0 * x / self.width - 1.0;
        let ndc_y = 1.0 - 2.0 * y / self.height;
        (self.forward_world
            + self.right_world * (ndc_x * self.tan_half_fov_y * self.aspect)
            + self.up_world * (ndc_y * self.tan_half_fov_y))
            .normalize()
    }

    /// What [`Self::ray_dir_world`] computes from, for a GPU camera pass:
    /// forward, right, up, then (tan ½ fov_y, aspect, width, height) in pixels.
    pub fn basis(&self) -> ([Vec3; 3], [f32; 4]) {
        (
            [self.forward_world, self.right_world, self.up_world],
            [self.tan_half_fov_y, self.aspect, self.width, self.height],
        )
    }

    /// Unit viewing direction (the optical axis).
    pub fn forward_world(&self) -> Vec3 {
        self.forward_world
    }

    /// Solid angle of the pixel whose ray runs along `dir_world` (unit): the pixel's
    /// area on the image plane at distance 1, times cos³ of its angle off the axis.
    pub fn pixel_solid_angle_sr(&self, dir_world: Vec3) -> f32 {
        let pixel = 2.0 * self.tan_half_fov_y / self.height;
        let cos = dir_world.dot(self.forward_world).max(0.0);
        pixel * pixel * cos * cos * cos
    }

    /// Continuous pixel position a world point projects to, if it is in front of the camera.
    pub fn project_world(&self, point_world: glam::Vec3) -> Option<glam::Vec2> {
        let d = point_world - self.origin_world;
        let z = d.dot(self.forward_world);
        if z <= 0.0 {
            return None;
        }
        let ndc_x = d.dot(self.right_world) / (z * self.tan_half_fov_y * self.aspect);
        let ndc_y = d.dot(self.up_world) / (z * self.tan_half_fov_y);
        Some(glam::Vec2::new((ndc_x + 1.0) * 0.5 * self.width, (1.0 - ndc_y) * 0.5 * self.height))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_at_target_and_edges_span_fov() {
        let cam = Camera::default();
        let rays = CameraRays::new(&cam, 200, 100);
        let c = rays.ray_dir_world(100.0, 50.0);
        assert!((c - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        let top = rays.ray_dir_world(100.0, 0.0);
        let angle = top.dot(c).acos().to_degrees();
        assert!((angle - 39.3 / 2.0).abs() < 1e-3, "{angle}");
        assert!(top.y > 0.0, "row 0 is the top of the image");
        assert!(rays.ray_dir_world(200.0, 50.0).x > 0.0, "last column is to the right");
    }

    #[test]
    fn project_inverts_ray_dir() {
        let rays = CameraRays::new(&Camera::default(), 64, 48);
        for &(x, y) in &[(0.5, 0.5), (10.25, 40.0), (63.5, 1.0)] {
            let p = rays.origin_world + rays.ray_dir_world(x, y) * 3.0;
            let back = rays.project_world(p).expect("in front");
            assert!((back - glam::Vec2::new(x, y)).length() < 1e-3);
        }
    }

    #[test]
    fn pixel_solid_angles_sum_to_the_frustum() {
        // A 90°×90° frustum spans 2π/3 sr.
        let cam = Camera { fov_y_deg: 90.0, ..Camera::default() };
        let rays = CameraRays::new(&cam, 200, 200);
        let mut sum = 0.0f64;
        for y in 0..200 {
            for x in 0..200 {
                sum += rays.pixel_solid_angle_sr(rays.ray_dir_world(x as f32 + 0.5, y as f32 + 0.5)) as f64;
            }
        }
        assert!((sum - 2.0 * std::f64::consts::PI / 3.0).abs() < 1e-3, "{sum}");
    }

    #[test]
    fn validate_rejects_degenerate_cameras() {
        let mut c = Camera::default();
        assert!(c.validate().is_ok());
        c.fov_y_deg = 0.0;
        assert!(c.validate().is_err());
        let mut c = Camera::default();
        c.target = c.position;
        assert!(c.validate().is_err());
        let mut c = Camera::default();
        c.up = c.target - c.position;
        assert!(c.validate().is_err());
    }
}
