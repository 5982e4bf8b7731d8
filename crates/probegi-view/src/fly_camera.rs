//! A fly camera as RTXGI's test harness and kajiya's viewer have it: W/S
//! forward and back, A/D left and right, Q/E down and up (world up), the mouse
//! turns (yaw about world up, pitch clamped short of the poles), the scroll
//! wheel scales the speed, R resets to the scene's camera.

use glam::Vec3;
use probegi_core::camera::Camera;

/// Radians of turn per pixel of mouse motion.
pub const FLY_LOOK_RAD_PER_PIXEL: f32 = 0.0025;
/// Speed factor per scroll-wheel step.
pub const FLY_SPEED_STEP: f32 = 1.25;
/// Pitch limit, radians: just short of straight up or down.
pub const FLY_PITCH_LIMIT_RAD: f32 = 1.55;

/// What the user holds or moved since the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FlyInput {
    /// W held.
    pub forward: bool,
    /// S held.
    pub back: bool,
    /// A held.
    pub left: bool,
    /// D held.
    pub right: bool,
    /// Q held.
    pub down: bool,
    /// E held.
    pub up: bool,
    /// Mouse motion since the last frame, pixels (x right, y down).
    pub look_px: glam::Vec2,
    /// Scroll-wheel steps since the last frame (up positive).
    pub scroll_steps: f32,
}

/// A camera that flies: position, yaw and pitch, field of view and speed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlyCamera {
    /// Eye position, metres, world space.
    pub position_m: Vec3,
    /// Heading about world +Y, radians (0 looks along −Z).
    pub yaw_rad: f32,
    /// Elevation, radians, within ±[`FLY_PITCH_LIMIT_RAD`].
    pub pitch_rad: f32,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
    /// Metres per second.
    pub speed_m_per_s: f32,
    home: Camera,
}

impl FlyCamera {
    /// Flying from `camera` (the scene's), at `speed_m_per_s`.
    pub fn from_camera(camera: &Camera, speed_m_per_s: f32) -> Self {
        let d = (camera.target - camera.position).normalize_or(Vec3::NEG_Z);
        let pitch = d.y.clamp(-1.0, 1.0).asin().clamp(-FLY_PITCH_LIMIT_RAD, FLY_PITCH_LIMIT_RAD);
        let yaw = (-d.x).atan2(-d.z);
        Self {
            position_m: camera.position,
            yaw_rad: yaw,
            pitch_rad: pitch,
            fov_y_deg: camera.fov_y_deg,
            speed_m_per_s,
            home: *camera,
        }
    }

    /// The unit view direction.
    pub fn forward(&self) -> Vec3 {
        let (sy, cy) = self.yaw_rad.sin_cos();
        let (sp, cp) = self.pitch_rad.sin_cos();
        Vec3::new(-sy * cp, sp, -cy * cp)
    }

    /// The camera to render with: the scene camera's up and lens, this
    /// position and direction.
    pub fn camera(&self) -> Camera {
        Camera {
            position: self.position_m,
            target: self.position_m + self.forward(),
            fov_y_deg: self.fov_y_deg,
            ..self.home
        }
    }

    /// One frame of `dt_s` seconds under `input`: turn, rescale the speed, then move.
    pub fn advance(&mut self, input: &FlyInput, dt_s: f32) {
        // Motion that sums past f32 (a script's huge numbers) turns nothing.
        let look = if input.look_px.is_finite() { input.look_px } else { glam::Vec2::ZERO };
        let scroll = if input.scroll_steps.is_finite() { input.scroll_steps } else { 0.0 };
        let input = &FlyInput { look_px: look, scroll_steps: scroll, ..*input };
        self.yaw_rad -= input.look_px.x * FLY_LOOK_RAD_PER_PIXEL;
        self.pitch_rad = (self.pitch_rad - input.look_px.y * FLY_LOOK_RAD_PER_PIXEL)
            .clamp(-FLY_PITCH_LIMIT_RAD, FLY_PITCH_LIMIT_RAD);
        if input.scroll_steps != 0.0 {
            self.speed_m_per_s = (self.speed_m_per_s * FLY_SPEED_STEP.powf(input.scroll_steps)).clamp(1e-3, 1e4);
        }
        let forward = self.forward();
        let right = forward.cross(Vec3::Y).normalize_or(Vec3::X);
        let axis = |plus: bool, minus: bool| plus as i32 as f32 - minus as i32 as f32;
        let step = forward * axis(input.forward, input.back)
            + right * axis(input.right, input.left)
            + Vec3::Y * axis(input.up, input.down);
        self.position_m += step * self.speed_m_per_s * dt_s;
    }

    /// Back to the scene's camera (the R key).
    pub fn reset(&mut self) {
        *self = Self::from_camera(&self.home, self.speed_m_per_s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene_camera() -> Camera {
        Camera { position: Vec3::new(0.0, 1.0, 3.0), target: Vec3::new(0.0, 1.0, 0.0), ..Camera::default() }
    }

    #[test]
    fn it_starts_looking_where_the_scene_camera_looks() {
        let fly = FlyCamera::from_camera(&scene_camera(), 2.0);
        assert!((fly.forward() - Vec3::NEG_Z).length() < 1e-6);
        let c = fly.camera();
        assert!(((c.target - c.position).normalize() - Vec3::NEG_Z).length() < 1e-6);
        let side = Camera { target: Vec3::new(5.0, 1.0, 3.0), ..scene_camera() };
        assert!((FlyCamera::from_camera(&side, 1.0).forward() - Vec3::X).length() < 1e-6);
    }

    #[test]
    fn keys_move_along_the_view_and_world_up_at_the_speed() {
        let mut fly = FlyCamera::from_camera(&scene_camera(), 2.0);
        fly.advance(&FlyInput { forward: true, ..Default::default() }, 0.5);
        assert!((fly.position_m - Vec3::new(0.0, 1.0, 2.0)).length() < 1e-5);
        fly.advance(&FlyInput { right: true, up: true, ..Default::default() }, 0.5);
        assert!((fly.position_m - Vec3::new(1.0, 2.0, 2.0)).length() < 1e-5);
        fly.advance(&FlyInput { forward: true, back: true, ..Default::default() }, 1.0);
        assert!((fly.position_m - Vec3::new(1.0, 2.0, 2.0)).length() < 1e-5, "opposite keys cancel");
    }

    #[test]
    fn the_mouse_turns_the_pitch_stops_short_of_the_pole_and_r_resets() {
        let mut fly = FlyCamera::from_camera(&scene_camera(), 1.0);
        let quarter = std::f32::consts::FRAC_PI_2 / FLY_LOOK_RAD_PER_PIXEL;
        fly.advance(&FlyInput { look_px: glam::Vec2::new(quarter, 0.0), ..Default::default() }, 0.0);
        assert!((fly.forward() - Vec3::X).length() < 1e-4, "{}", fly.forward());
        fly.advance(&FlyInput { look_px: glam::Vec2::new(0.0, -10.0 * quarter), ..Default::default() }, 0.0);
        assert_eq!(fly.pitch_rad, FLY_PITCH_LIMIT_RAD);
        assert!(fly.camera().position.is_finite() && fly.forward().y > 0.99);
        fly.advance(&FlyInput { scroll_steps: 2.0, ..Default::default() }, 0.0);
        assert!((fly.speed_m_per_s - FLY_SPEED_STEP * FLY_SPEED_STEP).abs() < 1e-5);
        fly.reset();
        assert!((fly.forward() - Vec3::NEG_Z).length() < 1e-6);
        assert_eq!(fly.position_m, scene_camera().position);
        // Motion summed past f32 turns nothing instead of making the camera NaN.
        let huge =
            FlyInput { look_px: glam::Vec2::new(f32::INFINITY, 0.0), scroll_steps: f32::NAN, ..Default::default() };
        fly.advance(&huge, 0.1);
        assert!(fly.camera().target.is_finite() && fly.speed_m_per_s.is_finite());
    }
}
