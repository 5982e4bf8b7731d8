//! probegi-frame: the per-frame loop of `probegi render` and `probegi view`, for
//! both backends. It orchestrates; the passes live with their backend.
//!
//! - [`frame_loop`]: a frame's steps in order ([`render_frames`], [`FrameStepper`]):
//!   pose the scene, update the field through the seam, then the camera frame.
//!   On the host that frame is `probegi_cpu`'s G-buffer and shading with this
//!   crate's accumulation and temporal filter (`frame_loop::accumulation`,
//!   `frame_loop::camera_pass`); where the backend keeps the camera frame on
//!   its device (`probegi_field::DeviceFrame`) the loop only records it there
//!   and reads its statistics late (`frame_loop::device_resident`), and runs
//!   none of `probegi_cpu`'s passes.
//! - [`field_update`]: one field update of a [`probegi_field::DdgiFieldSet`]
//!   through its seam: traced and shaded by `probegi_cpu`, or by a
//!   [`probegi_field::ProbeBatchTracer`], or kept whole on its device.
//! - [`scene_events`]: scene changes (light toggles, a turning sky map, moving objects) reported
//!   to the field.

#![warn(missing_docs)]

pub mod field_update;
pub mod frame_loop;
pub mod scene_events;

pub use field_update::{FieldSetUpdate, VolumeUpdate};
pub use frame_loop::{
    FIELD_UPDATE_PASSES, FrameLayers, FrameStepper, GiMethod, RenderOutput, RenderSettings, RenderStats, SceneEdit,
    TemporalSettings, render_frames,
};
