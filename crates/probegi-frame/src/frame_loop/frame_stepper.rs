//! One frame at a time: [`FrameStepper`] runs the frame loop's steps (pose,
//! field update, camera image) for the frame after the last, seen through the
//! camera its caller gives, so an interactive viewer can move the camera
//! between frames while the field keeps updating. [`super::render_frames`] is
//! a stepper driven over the settings' camera path.

use std::ops::ControlFlow::{self, Break};

use probegi_core::camera::CameraRays;
use probegi_core::image::Image;
use probegi_field::ddgi_field_set::DdgiFieldSet;
use probegi_scene::{RayTracer, Scene};

use super::{Frame, FrameLoop, RenderOutput, RenderSettings};
use probegi_cpu::direct::DirectLighting;

/// A frame's two terms, as [`FrameStepper::layers`] returns them.
pub struct FrameLayers {
    /// The direct term (averaged over the frames it has accumulated).
    pub direct: Image,
    /// The indirect term: the last frame's irradiance × the accumulated albedo.
    pub indirect: Image,
}

/// A render stepped one frame at a time (see the module docs). The scene
/// clock is the frame index: an animated scene is posed at each frame's.
pub struct FrameStepper<'a> {
    tracer: &'a dyn RayTracer,
    static_direct: DirectLighting<'a>,
    /// The scene as it stands at the current frame (animated scenes only).
    frame_scene: Option<Scene>,
    frame_loop: FrameLoop<'a>,
    next_frame: u32,
    failed: bool,
}

impl<'a> FrameStepper<'a> {
    /// A render of `base_scene` by `settings` (its `frames` and `camera_path`
    /// are not read: the caller steps), the field placed around `camera`. The
    /// stepper keeps its own copy of both.
    pub fn new(
        base_scene: &'a Scene,
        tracer: &'a dyn RayTracer,
        camera: &CameraRays,
        settings: &RenderSettings,
    ) -> Self {
        Self {
            tracer,
            static_direct: DirectLighting::new(base_scene, tracer, settings.direct),
            frame_scene: base_scene.is_animated().then(|| base_scene.clone()),
            frame_loop: FrameLoop::new(base_scene, camera, settings),
            next_frame: 0,
            failed: false,
        }
    }

    /// Renders the next frame through `camera` (of the settings' size) and
    /// returns its image; an error names the frame and the pass that failed,
    /// and every later step fails too.
    pub fn step(&mut self, camera: &CameraRays) -> Result<Image, String> {
        let mut image = None;
        match self.step_with(camera, &mut |_, compose| image = Some(compose())) {
            ControlFlow::Continue(()) => image.ok_or_else(|| "the frame produced no image".into()),
            Break(()) => Err(self.error()),
        }
    }

    /// Renders the next frame through `camera` without composing its image
    /// (a device that keeps the frame reads nothing back; [`Self::image`]
    /// reads it when needed). Errors as [`Self::step`].
    pub fn advance(&mut self, camera: &CameraRays) -> Result<(), String> {
        match self.step_with(camera, &mut |_, _| {}) {
            ControlFlow::Continue(()) => Ok(()),
            Break(()) => Err(self.error()),
        }
    }

    /// The last frame's image: from the device that keeps it (a read-back),
    /// else composed from the host's sums.
    pub fn image(&self) -> Result<Image, String> {
        let fl = &self.frame_loop;
        match fl.device_layer(probegi_field::FrameLayer::Full) {
            Some(image) => image,
            None => Ok(Image { width: fl.settings.width, height: fl.settings.height, pixels: fl.acc.pixels() }),
        }
    }

    /// [`Self::step`] handing the frame to `on_frame_done` (its image composed
    /// only when called).
    pub(crate) fn step_with(
        &mut self,
        camera: &CameraRays,
        on_frame_done: &mut impl FnMut(u32, &dyn Fn() -> Image),
    ) -> ControlFlow<()> {
        if self.failed {
            return Break(());
        }
        let f = self.next_frame;
        let Self { tracer, static_direct, frame_scene, frame_loop, .. } = self;
        let ControlFlow::Continue((scene, frame_tracer)) = frame_loop.pose(*tracer, frame_scene, f) else {
            self.failed = true;
            return Break(());
        };
        let tracer: &dyn RayTracer = frame_tracer.as_deref().unwrap_or(*tracer);
        let posed = std::cell::OnceCell::new();
        let direct =
            super::FrameDirect { base: static_direct, posed: &posed, animated: frame_loop.animated, scene, tracer };
        let frame = Frame { index: f, scene, tracer, direct: &direct, camera };
        let flow = match frame_loop.update_field(&frame) {
            ControlFlow::Continue(()) => frame_loop.camera_image(&frame, on_frame_done),
            Break(()) => Break(()),
        };
        if flow.is_continue() {
            frame_loop.prev_camera = Some(*camera);
            frame_loop.scene_edit_changed = false;
        }
        self.failed = flow.is_break();
        self.next_frame += 1;
        flow
    }

    /// Edits the scene of every later frame after it is posed (`edit(base,
    /// posed)`; a viewer's light switches and sky): from now on the scene is
    /// posed each frame, on the device too, so the field sees the change as
    /// it sees a keyframed light's, through its scene-change detector. `None`
    /// takes the edit away (the scene is still posed each frame). What the
    /// edit may change is what posing a frame carries to a device: punctual
    /// lights and the sky (emitters stay as uploaded).
    pub fn set_scene_edit(&mut self, edit: Option<super::SceneEdit<'a>>) {
        if self.frame_scene.is_none() {
            self.frame_scene = Some(self.frame_loop.base_scene.clone());
        }
        // The scene as rendered so far is what the edit changes.
        let last = self.frame_scene.as_ref().unwrap_or(self.frame_loop.base_scene);
        self.frame_loop.detector.remember_lights(last);
        self.frame_loop.animated = true;
        self.frame_loop.scene_edit = edit;
        self.frame_loop.scene_edit_changed = true;
    }

    /// Holds the scene clock at `frame` (a paused viewer; the field and the
    /// camera keep running), or lets it follow the frame index again (`None`).
    pub fn set_scene_frame(&mut self, frame: Option<u32>) {
        self.frame_loop.scene_frame = frame;
    }

    /// Renders later frames at `width` × `height` (a viewer's adaptive
    /// resolution): the camera image's sums restart, the field is kept. The
    /// cameras passed to [`Self::step`] must then have this size.
    pub fn set_size(&mut self, width: u32, height: u32) {
        let fl = &mut self.frame_loop;
        if (fl.settings.width, fl.settings.height) == (width, height) {
            return;
        }
        fl.settings.width = width;
        fl.settings.height = height;
        fl.acc = super::Accumulation::new(width, height);
        // The device's image is of the old size until the next frame.
        fl.device_image = false;
        fl.prev_camera = None;
        fl.last_gbuffer = None;
    }

    /// The last frame's layers: the direct term (its mean over the frames it
    /// has accumulated) and the indirect term, each of the frame's size.
    /// An error when the device that keeps the frame could not read it back.
    pub fn layers(&self) -> Result<FrameLayers, String> {
        let fl = &self.frame_loop;
        let (width, height) = (fl.settings.width, fl.settings.height);
        if let (Some(direct), Some(indirect)) =
            (fl.device_layer(probegi_field::FrameLayer::Direct), fl.device_layer(probegi_field::FrameLayer::Indirect))
        {
            return Ok(FrameLayers { direct: direct?, indirect: indirect? });
        }
        let direct = (0..fl.acc.len()).map(|p| fl.acc.direct(p)).collect();
        Ok(FrameLayers {
            direct: Image { width, height, pixels: direct },
            indirect: Image { width, height, pixels: fl.acc.indirect_image() },
        })
    }

    /// The statistics so far (pass times are totals until [`Self::finish`]
    /// divides them; see [`Self::pass_totals_ms`]).
    pub fn stats(&self) -> &super::RenderStats {
        &self.frame_loop.stats
    }

    /// Total wall milliseconds of each pass over the frames so far.
    pub fn pass_totals_ms(&self) -> &std::collections::BTreeMap<&'static str, f64> {
        &self.frame_loop.pass_totals
    }

    /// The index of the frame the next step renders (frames rendered so far).
    pub fn frame_index(&self) -> u32 {
        self.next_frame
    }

    /// Why the last step failed, if it did.
    fn error(&self) -> String {
        self.frame_loop.stats.error.clone().unwrap_or_else(|| "a pass failed".into())
    }

    /// The DDGI field as it stands (`None` without `--gi ddgi`); its atlases
    /// may be stale on the host while a device holds them
    /// (`DdgiFieldSet::field_on_device`).
    pub fn field(&self) -> Option<&DdgiFieldSet> {
        self.frame_loop.field.as_ref()
    }

    /// The DDGI field with its atlases current on the host (read back from a
    /// device that holds them), for views that read it; `None` without
    /// `--gi ddgi`.
    pub fn sync_field_to_host(&mut self) -> Result<Option<&DdgiFieldSet>, String> {
        let fl = &mut self.frame_loop;
        let Some(set) = fl.field.as_mut() else { return Ok(None) };
        set.sync_host_atlases(fl.settings.probe_tracer.as_ref().map(|h| &*h.0))
            .map_err(|e| format!("reading the field back: {e}"))?;
        Ok(Some(set))
    }

    /// The scene as the last frame saw it: posed at its scene clock and
    /// edited ([`Self::set_scene_edit`]); the loaded scene when nothing poses it.
    pub fn frame_scene(&self) -> &Scene {
        self.frame_scene.as_ref().unwrap_or(self.frame_loop.base_scene)
    }

    /// The render's settings as the stepper keeps them.
    pub fn settings(&self) -> &RenderSettings {
        &self.frame_loop.settings
    }

    /// The DDGI field, to change its settings or report scene events between frames.
    pub fn field_mut(&mut self) -> Option<&mut DdgiFieldSet> {
        self.frame_loop.field.as_mut()
    }

    /// After the last step: the field back on the host, the statistics, the
    /// last frame's image (with `show_probes`, the probes drawn on it).
    pub fn finish(self) -> RenderOutput {
        self.frame_loop.finish()
    }
}
