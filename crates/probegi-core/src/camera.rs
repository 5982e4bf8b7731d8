//! Pinhole camera maths. Conventions: y-up world, right-handed, the camera looks
//! from `position` toward `target`; `fov_y_deg` is the full vertical field of
//! view; pixel (0,0) is the top-left corner of the image and pixel centres are at
//! half-integers (box filter = uniform jitter inside `[x, x+1) × [y, y+1)`).
//!
//! **The view basis** ([`Camera::view_basis`]) is never degenerate. `up` is a
//! hint: the image's up is the hint made orthogonal to the view direction.
//! Where the view is parallel to the hint (a camera looking straight up or
//! down), the hint says nothing, and the basis falls back:
//! - on a path, to the previous frame's image up (made orthogonal to this
//!   frame's view), so the image turns continuously through the vertical;
//! - for a single camera, to the world axis least aligned with the view
//!   (ties broken Z, X, Y), signed by the view's side of the hint: looking down
//!   a y-up world the image's up is −Z, looking up it is +Z — where a camera
//!   looking along −Z ends when it pitches down or up.
//!
//! On a path the hint's sign is also carried from frame to frame: once a path
//! has turned over the vertical (looking along +x, up, then along −x), it keeps
//! the image upright relative to the frames before instead of flipping it by
//! 180°, i.e. it continues upside down relative to the hint, as a real camera
//! pitched over the top does. A hint that the keys themselves reverse (up +Y at
//! one key, −Y at the next) is followed: that roll is asked for. Far from the
//! vertical a single camera's basis is the classic look-at (right = forward × up).

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
        let view = self.target - self.position;
        if !view.is_finite() {
            return Err("camera target and position are too far apart to subtract in f32".into());
        }
        if view.length_squared() < 1e-12 {
            return Err("camera target equals camera position".into());
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 179.0) {
            return Err(format!("fov_y_deg = {} must be in (0, 179)", self.fov_y_deg));
        }
        Ok(())
    }
}

/// |forward × hint|² below which the hint gives no usable right vector
/// (the view is within about 0.006° of the hint).
const PARALLEL_SIN2: f32 = 1e-8;

/// A camera's orthonormal view basis, and what a following frame of a path
/// continues from (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewBasis {
    /// Unit view direction, from `position` toward `target`, world space.
    pub forward_world: Vec3,
    /// Unit image right (pixel x grows along it), world space, orthogonal to
    /// `forward_world` and `up_world`.
    pub right_world: Vec3,
    /// Unit image up (pixel y grows against it), world space:
    /// `right_world × forward_world`.
    pub up_world: Vec3,
    /// The unit up hint this frame used (zero for a zero hint).
    pub hint_world: Vec3,
    /// +1, or −1 once a path has turned over the vertical: the image up is on
    /// the side of `−hint`.
    pub hint_sign: f32,
}

impl Camera {
    /// The view basis of this camera; `previous` is the basis of the previous
    /// frame of a path (`None` for a single camera). Needs a camera that
    /// passes [`Camera::validate`].
    pub fn view_basis(&self, previous: Option<&ViewBasis>) -> ViewBasis {
        let forward_world = unit(self.target - self.position);
        let hint_world = unit(self.up);
        let mut hint_sign = previous.map_or(1.0, |p| p.hint_sign);
        let mut right = forward_world.cross(hint_world) * hint_sign;
        // With the hint as before (not a keyed reversal), an image up that turned
        // against the previous frame's means the view crossed the hint: the path
        // continues over the vertical instead of flipping.
        if let Some(p) = previous
            && p.hint_world.dot(hint_world) > 0.0
            && right.cross(forward_world).dot(p.up_world) < 0.0
        {
            hint_sign = -hint_sign;
            right = -right;
        }
        if right.length_squared() < PARALLEL_SIN2 {
            let up = match previous {
                Some(p) if forward_world.cross(p.up_world).length_squared() >= PARALLEL_SIN2 => p.up_world,
                _ => fallback_up(forward_world, hint_world),
            };
            right = forward_world.cross(up);
        }
        let right_world = right.normalize();
        let up_world = right_world.cross(forward_world);
        ViewBasis { forward_world, right_world, up_world, hint_world, hint_sign }
    }

    /// A camera of a path whose `up` is the image up of `basis`, so that
    /// [`CameraRays::new`] gives that basis; unchanged where the hint already
    /// gives it (so a path far from the vertical renders as before).
    pub fn with_basis(&self, basis: &ViewBasis) -> Camera {
        let single = self.view_basis(None);
        let same = single.right_world == basis.right_world && single.up_world == basis.up_world;
        if same { *self } else { Camera { up: basis.up_world, ..*self } }
    }
}

/// `v` normalised without overflow (its largest component scaled to 1 first),
/// zero for a zero vector.
fn unit(v: Vec3) -> Vec3 {
    if v.length_squared().is_finite() {
        // The plain normalisation wherever it does not overflow, so that ordinary
        // cameras keep their bases bit for bit.
        return v.normalize_or_zero();
    }
    let largest = v.abs().max_element();
    if largest > 0.0 { (v / largest).normalize_or_zero() } else { Vec3::ZERO }
}

/// The single camera's fallback image up (module docs): the world axis least
/// aligned with `forward` (ties Z, X, Y), on the side of the hint `forward`
/// points to.
fn fallback_up(forward: Vec3, hint: Vec3) -> Vec3 {
    let a = forward.abs();
    let axis = if a.z <= a.x && a.z <= a.y {
        Vec3::Z
    } else if a.x <= a.y {
        Vec3::X
    } else {
        Vec3::Y
    };
    if forward.dot(hint) < 0.0 { -axis } else { axis }
}

/// A camera prepared for one image size: maps continuous pixel coordinates to world rays.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraRays {
    /// Origin of every ray: the camera's eye position, metres, world space.
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
    /// The camera's rays with its single-camera basis ([`Camera::view_basis`]
    /// without a previous frame); a path's frames come from
    /// `Scene::camera_path`, whose cameras already carry their frame's up.
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        let ViewBasis { forward_world, right_world, up_world, .. } = camera.view_basis(None);
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
    use glam::Quat;

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
        c.position.x = f32::NAN;
        assert!(c.validate().is_err());
        let mut c = Camera::default();
        c.up = c.target - c.position;
        assert!(c.validate().is_ok(), "an up along the view falls back, it is not an error");
    }

    fn orthonormal(b: &ViewBasis) -> bool {
        let unit = |v: Vec3| (v.length() - 1.0).abs() < 1e-5;
        unit(b.forward_world)
            && unit(b.right_world)
            && unit(b.up_world)
            && b.forward_world.dot(b.right_world).abs() < 1e-5
            && b.forward_world.dot(b.up_world).abs() < 1e-5
            && b.right_world.dot(b.up_world).abs() < 1e-5
    }

    #[test]
    fn straight_down_and_up_fall_back_to_minus_and_plus_z() {
        let down = Camera { position: Vec3::new(0.0, 1.9, 0.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 60.0 };
        let b = down.view_basis(None);
        assert!(orthonormal(&b), "{b:?}");
        assert!((b.up_world - Vec3::NEG_Z).length() < 1e-6, "{b:?}");
        let up = Camera { target: Vec3::new(0.0, 3.8, 0.0), ..down };
        let b = up.view_basis(None);
        assert!((b.up_world - Vec3::Z).length() < 1e-6, "{b:?}");
        // The fallback is where a camera looking along −Z ends when it pitches.
        let tilt =
            |deg: f32| Camera { target: down.position + Quat::from_rotation_x(deg.to_radians()) * Vec3::NEG_Z, ..down };
        assert!(tilt(-89.9).view_basis(None).up_world.dot(Vec3::NEG_Z) > 0.99);
        assert!(tilt(89.9).view_basis(None).up_world.dot(Vec3::Z) > 0.99);
        let rays = CameraRays::new(&down, 8, 8);
        assert!(rays.ray_dir_world(4.0, 4.0).is_finite() && rays.ray_dir_world(4.0, 4.0).y < -0.99);
    }

    #[test]
    fn a_path_through_the_vertical_turns_continuously_without_flipping() {
        // Turn in place from looking along +x, over the top, to looking along −x.
        let mut prev: Option<ViewBasis> = None;
        let steps = 300;
        for i in 0..=steps {
            let a = std::f32::consts::PI * i as f32 / steps as f32;
            let dir = Vec3::new(a.cos(), a.sin(), 0.0);
            let c = Camera { position: Vec3::ZERO, target: dir, up: Vec3::Y, fov_y_deg: 60.0 };
            let b = c.view_basis(prev.as_ref());
            assert!(orthonormal(&b), "step {i}: {b:?}");
            if let Some(p) = prev {
                assert!(b.right_world.dot(p.right_world) > 0.999, "step {i}: right flipped {b:?} after {p:?}");
                assert!(b.up_world.dot(p.up_world) > 0.99, "step {i}: up jumped {b:?} after {p:?}");
            }
            // The camera the path hands to CameraRays reproduces the basis.
            let rays = CameraRays::new(&c.with_basis(&b), 4, 4);
            assert!((rays.basis().0[1] - b.right_world).length() < 1e-5, "step {i}");
            prev = Some(b);
        }
        let end = prev.expect("frames");
        assert!(end.up_world.y < -0.99, "over the top the image continues upside down: {end:?}");
    }
}
