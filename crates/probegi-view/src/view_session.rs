//! One viewer frame at a time, the same for the headless run and the window:
//! input events reach the fly camera (a keyframed camera plays until the
//! input first moves it; R returns to it), the camera moves by the frame's
//! time step, and the field updates and the frame renders through
//! `probegi_frame::frame_loop::FrameStepper`, the stepper `probegi render`
//! drives, on the CPU or (with the settings' probe tracer) on the GPU.
//!
//! The scene clock is a frame count of its own: it advances one per frame
//! unless paused, and steps one at a time while paused; the field and the
//! camera keep running either way.

use probegi_core::camera::{Camera, CameraRays};
use probegi_core::image::Image;
use probegi_frame::frame_loop::{FrameStepper, RenderSettings};
use probegi_scene::{RayTracer, Scene};

use crate::fly_camera::{FlyCamera, FlyInput};
use crate::input_script::{InputState, ScriptEvent};

/// Frames late the viewer takes a device frame's statistics
/// (`RenderSettings::device_readback_lag_frames`): with two frames in flight
/// the host never waits for the device while it keeps up.
pub const VIEWER_READBACK_LAG_FRAMES: u32 = 2;

/// The viewer's per-frame state over a [`FrameStepper`].
pub struct ViewSession<'a> {
    stepper: FrameStepper<'a>,
    fly: FlyCamera,
    input: InputState,
    camera_path: Vec<Camera>,
    on_path: bool,
    size: (u32, u32),
    scene_frame: u32,
    paused: bool,
    step_once: bool,
    last_camera: Camera,
    last_scene_frame: u32,
}

/// What a viewer keeps when its session is built anew (a rebuild or a
/// reload): the fly camera, whether the keyframed path still plays, and the
/// scene clock.
#[derive(Clone, Copy, Debug)]
pub struct ViewCarry {
    /// The fly camera.
    pub fly: FlyCamera,
    /// The keyframed path still plays.
    pub on_path: bool,
    /// The scene clock.
    pub scene_frame: u32,
    /// The clock is paused.
    pub paused: bool,
}

impl<'a> ViewSession<'a> {
    /// A session over `scene` rendered by `settings` (its size; its `frames`
    /// and `camera_path` are not read), the fly camera starting at `camera`
    /// with `fly_speed_m_per_s`; `camera_path` (one camera per frame, may be
    /// empty) plays until the input takes over.
    pub fn new(
        scene: &'a Scene,
        tracer: &'a dyn RayTracer,
        camera: &Camera,
        settings: &RenderSettings,
        fly_speed_m_per_s: f32,
        camera_path: Vec<Camera>,
    ) -> Self {
        let size = (settings.width, settings.height);
        let start = camera_path.first().copied().unwrap_or(*camera);
        let stepper = FrameStepper::new(scene, tracer, &CameraRays::new(&start, size.0, size.1), settings);
        let fly = FlyCamera::from_camera(camera, fly_speed_m_per_s);
        // The camera the next frame takes without input (a reference asked for
        // before the first frame must see that frame's camera).
        let next = if camera_path.is_empty() { fly.camera() } else { start };
        Self {
            stepper,
            fly,
            input: InputState::default(),
            on_path: !camera_path.is_empty(),
            camera_path,
            size,
            scene_frame: 0,
            paused: false,
            step_once: false,
            last_camera: next,
            last_scene_frame: 0,
        }
    }

    /// What a new session over the same scene should take over.
    pub fn carry(&self) -> ViewCarry {
        ViewCarry { fly: self.fly, on_path: self.on_path, scene_frame: self.scene_frame, paused: self.paused }
    }

    /// Takes over a previous session's camera and clock.
    pub fn restore(&mut self, carry: ViewCarry) {
        self.fly = carry.fly;
        self.on_path = carry.on_path && !self.camera_path.is_empty();
        self.scene_frame = carry.scene_frame;
        self.paused = carry.paused;
        let keyed = self.camera_path.get(self.scene_frame as usize).or(self.camera_path.last());
        self.last_camera = match (self.on_path, keyed) {
            (true, Some(k)) => *k,
            _ => self.fly.camera(),
        };
    }

    /// Applies one input event (it takes effect at the next frame).
    pub fn apply(&mut self, event: ScriptEvent) {
        self.input.apply(event);
    }

    /// Renders the next frame, the camera moved by `dt_s` seconds of input.
    /// An error names the frame and the pass that failed.
    pub fn frame(&mut self, dt_s: f32) -> Result<Image, String> {
        let camera = self.next_camera(dt_s);
        self.stepper.set_scene_frame(Some(self.scene_frame));
        let image = self.stepper.step(&CameraRays::new(&camera, self.size.0, self.size.1))?;
        self.last_scene_frame = self.scene_frame;
        let step = std::mem::take(&mut self.step_once);
        if !self.paused || step {
            self.scene_frame += 1;
        }
        self.last_camera = camera;
        Ok(image)
    }

    /// [`Self::frame`] without the image: a device that keeps the frame
    /// reads nothing back ([`Self::image`] reads it when needed).
    pub fn advance(&mut self, dt_s: f32) -> Result<(), String> {
        let camera = self.next_camera(dt_s);
        self.stepper.set_scene_frame(Some(self.scene_frame));
        self.stepper.advance(&CameraRays::new(&camera, self.size.0, self.size.1))?;
        self.last_scene_frame = self.scene_frame;
        let step = std::mem::take(&mut self.step_once);
        if !self.paused || step {
            self.scene_frame += 1;
        }
        self.last_camera = camera;
        Ok(())
    }

    /// The last frame's image (read back where a device keeps it).
    pub fn image(&self) -> Result<Image, String> {
        self.stepper.image()
    }

    /// The camera of the next frame (see the module docs).
    fn next_camera(&mut self, dt_s: f32) -> Camera {
        let keyed = self.camera_path.get(self.scene_frame as usize).or(self.camera_path.last());
        let input = &mut self.input;
        if input.reset {
            self.fly.reset();
            self.on_path = keyed.is_some();
        }
        if self.on_path && input.fly != FlyInput::default() {
            // The user takes over where the path is.
            self.on_path = false;
            if let Some(k) = keyed {
                self.fly = FlyCamera::from_camera(k, self.fly.speed_m_per_s);
            }
        }
        let camera = match (self.on_path, keyed) {
            (true, Some(k)) => *k,
            _ => {
                self.fly.advance(&input.fly, dt_s);
                self.fly.camera()
            }
        };
        input.end_frame();
        camera
    }

    /// Renders later frames at `width` × `height` (the CPU backend's adaptive
    /// resolution); the field is kept.
    pub fn set_size(&mut self, width: u32, height: u32) {
        self.size = (width.max(1), height.max(1));
        self.stepper.set_size(self.size.0, self.size.1);
    }

    /// The frame size, pixels.
    pub fn size(&self) -> (u32, u32) {
        self.size
    }

    /// Pauses or resumes the scene clock.
    pub fn set_paused(&mut self, paused: bool) {
        self.paused = paused;
    }

    /// Whether the scene clock is paused.
    pub fn paused(&self) -> bool {
        self.paused
    }

    /// While paused: the next frame advances the scene clock by one (a
    /// running clock ignores it).
    pub fn step_scene_clock(&mut self) {
        self.step_once = self.paused;
    }

    /// The scene clock of the last frame rendered.
    pub fn last_scene_frame(&self) -> u32 {
        self.last_scene_frame
    }

    /// The scene clock, frames.
    pub fn scene_frame(&self) -> u32 {
        self.scene_frame
    }

    /// The fly camera.
    pub fn fly_camera(&self) -> &FlyCamera {
        &self.fly
    }

    /// The camera of the last frame rendered.
    pub fn last_camera(&self) -> Camera {
        self.last_camera
    }

    /// The stepper (the field, its statistics, the frame's layers).
    pub fn stepper(&self) -> &FrameStepper<'a> {
        &self.stepper
    }

    /// The stepper, to change the field's settings or edit the scene.
    pub fn stepper_mut(&mut self) -> &mut FrameStepper<'a> {
        &mut self.stepper
    }

    /// Ends the session: the stepper's output (field, statistics, image).
    pub fn finish(self) -> (probegi_frame::frame_loop::RenderOutput, FlyCamera) {
        (self.stepper.finish(), self.fly)
    }
}
