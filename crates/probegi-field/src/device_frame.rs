//! The backend-neutral interface of a camera frame that stays on its device
//! (issue 44): the frame's images, their running sums between frames, the
//! composed and tone-mapped image and the frame's statistics live where the
//! camera pass writes them; the host hands each frame its camera and what
//! happens to the history, and gets back only a few bytes a frame (means and
//! counts for `--stats` and the black-frame guard, the screen scheme's probe
//! requests), one or more frames late, without waiting.
//!
//! The CPU frame loop (`probegi_frame::frame_loop::accumulation`) is the
//! reference: a device implementing [`DeviceFrame`] mirrors its accumulation,
//! temporal filter, composition and statistics. Pixels cross to the host only
//! when asked ([`DeviceFrame::read_layer`], [`DeviceFrame::read_rgba8`]): the
//! final image of a render, each frame of a sequence, a screenshot.

use glam::Vec3;
use probegi_core::camera::CameraRays;
use probegi_core::ddgi_volume_blend::DdgiFieldSetView;

use crate::backend::BackendError;

/// What a frame does to the image's running sums before adding to them (the
/// CPU's `accumulation::History`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FrameHistory {
    /// A still camera in a still scene: the frame adds to the sums.
    Accumulate,
    /// The scene changed: the sums start again from this frame.
    Restart,
    /// The camera moved from `from`: the sums are reprojected first, each
    /// pixel's history capped to `history_frames` − 1 frames and its direct
    /// term clamped to the new frame's 3 × 3 neighbourhood mean ±
    /// `clip_sigma` σ (0: unclamped). `history_frames` ≤ 1 restarts instead.
    Reproject {
        /// The last frame's camera.
        from: CameraRays,
        /// `TemporalSettings::temporal_history_frames`.
        history_frames: u32,
        /// `TemporalSettings::temporal_clip_sigma`.
        clip_sigma: f32,
    },
}

/// One frame for [`DeviceFrame::render_frame`].
#[derive(Clone, Copy)]
pub struct DeviceFrameInput<'a> {
    /// The frame's camera (its resolution sizes the device's images, which are
    /// made again when it changes).
    pub camera: &'a CameraRays,
    /// What happens to the running sums.
    pub history: FrameHistory,
    /// The field as queries read it (per-probe data current; its atlases
    /// current too unless `field_on_device`).
    pub field: &'a DdgiFieldSetView<'a>,
    /// The device's own atlases are the current ones.
    pub field_on_device: bool,
    /// Area-light samples per pixel.
    pub area_samples: u32,
    /// Sky-map samples per pixel (`DirectSettings::direct_sky_samples`; used
    /// under a sky map only).
    pub sky_samples: u32,
    /// Second-order glossy on glossy rays' hits.
    pub second_order: bool,
    /// The frame number.
    pub frame: u32,
    /// The render's seed.
    pub seed: u64,
    /// Words of the screen scheme's request bitset (`DdgiFieldSet::probe_request_layout`), 0 for none.
    pub request_words: u32,
    /// How many frames late the statistics may come back: 0 waits for this
    /// frame's (what `probegi render` does, so that its bookkeeping is the
    /// CPU's frame for frame); 1 or 2 never wait while the device keeps up
    /// (the viewer).
    pub readback_lag_frames: u32,
}

/// What a frame's statistics say, read back from the device (48 bytes and
/// the request words).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DeviceFrameReadout {
    /// The frame these figures belong to.
    pub frame: u32,
    /// The mean of the composed image.
    pub mean: Vec3,
    /// The mean of its field term.
    pub indirect_mean: Vec3,
    /// Pixels on a surface with a diffuse albedo.
    pub surfaces: u64,
    /// Those of them the field left unlit.
    pub unlit: u64,
    /// Pixels whose direct radiance came out NaN or infinite (written as 0).
    pub nonfinite: u64,
    /// The screen scheme's request bitset (empty without requests).
    pub requests: Vec<u32>,
    /// The device's own milliseconds for each of the frame's passes, named by
    /// [`DEVICE_FRAME_PASSES`], where the device has timestamp queries (empty otherwise).
    pub gpu_pass_ms: Vec<f64>,
}

/// The passes of a frame kept on the device, as `RenderStats::pass_ms` names
/// their device times: the camera pass, then the resolve (accumulation or the
/// temporal filter), compose (+ tone map) and statistics passes.
pub const DEVICE_FRAME_PASSES: [&str; 4] = ["gpu_camera", "gpu_frame_resolve", "gpu_frame_compose", "gpu_frame_stats"];

/// Which image of the frame to read back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameLayer {
    /// The composed frame: mean direct + mean albedo × irradiance/π.
    Full,
    /// The direct term's mean.
    Direct,
    /// The field term.
    Indirect,
}

/// A camera frame kept on the device (see the module docs).
pub trait DeviceFrame: Sync {
    /// Renders, accumulates (or reprojects), composes and reduces one frame on
    /// the device, and returns the readouts of earlier frames (or, with
    /// `readback_lag_frames` 0, of this one) that have come back meanwhile,
    /// oldest first.
    fn render_frame(&self, input: &DeviceFrameInput<'_>) -> Result<Vec<DeviceFrameReadout>, BackendError>;

    /// Waits for every readout still in flight and returns them, oldest first.
    fn drain_readouts(&self) -> Result<Vec<DeviceFrameReadout>, BackendError>;

    /// The last frame's `layer`, linear, row-major (a blocking read-back).
    fn read_layer(&self, layer: FrameLayer) -> Result<Vec<Vec3>, BackendError>;

    /// The last frame's `layer` tone-mapped on the device (`probegi_core::color::tonemap_rgb8`),
    /// RGBA8 row-major, alpha 255 (a blocking read-back of 4 bytes a pixel).
    fn read_rgba8(&self, layer: FrameLayer) -> Result<Vec<u8>, BackendError>;
}
