//! probegi-field: the DDGI field's host side, the same for every backend.
//!
//! RTXGI's split: an API-neutral volume base here, and one peer per backend
//! (`probegi-cpu`, `probegi-wgpu`) that traces, shades and, on a device, keeps
//! the atlases. Nothing here starts a thread of its own except the host blend
//! (rayon over probe tiles), which either backend falls back to.
//!
//! - [`ddgi_volume`]: one volume's persistent field (grid, atlases, offsets,
//!   states, hysteresis) and its share of each update step, one file per pass:
//!   `init_rounds`, `update_plan`, `usage_states`, `blend_inputs`, `scrolling`,
//!   `shadow_rays` (the shadowing field), `probe_budget` (its share of the
//!   ray budget);
//! - [`ddgi_field_set`]: any number of volumes (multiple volumes, cascades)
//!   updated through one ray batch per frame: the seam's state machine;
//! - [`seam`]: the seam's vocabulary (the ray batch, hits, steps, errors);
//! - [`device_plans`]: the inputs of a device that runs the relocation,
//!   classification and blend passes where the hits lie;
//! - [`probe_ray_gen`]: the rotated spherical Fibonacci rays and their blend weights;
//! - [`ray_budget`]: which probes trace under a per-frame ray budget;
//! - [`backend`]: the traits a backend implements ([`ProbeBatchTracer`] for
//!   trace and shade, [`DeviceField`] for the field-resident passes) and their
//!   typed error;
//! - [`device_frame`]: the interface of a camera frame that stays on its
//!   device ([`DeviceFrame`]).
//!
//! Depends on `probegi-core` (maths, layouts, settings) and `probegi-scene`
//! (the backend trait hands hits as the scene's `RayHit` and poses the scene).

#![warn(missing_docs)]

pub mod atlas_view;
pub mod backend;
pub mod ddgi_field_set;
pub mod ddgi_volume;
pub mod device_frame;
pub mod device_plans;
pub mod probe_ray_gen;
pub mod probe_seeding;
pub mod ray_budget;
pub mod seam;

pub use backend::{BackendError, CameraFrameOut, DeviceField, ProbeBatchTracer, ProbeTracerHandle};
pub use ddgi_field_set::DdgiFieldSet;
pub use ddgi_volume::{DdgiVolume, SceneEvent};
pub use device_frame::{
    DEVICE_FRAME_PASSES, DeviceFrame, DeviceFrameInput, DeviceFrameReadout, FrameHistory, FrameLayer,
};
pub use device_plans::{DeviceBlendOutput, DeviceChangeKey, DeviceProbeChanges, DeviceUsageCounts, DeviceUsageRequest};
pub use seam::{ProbeRayBatch, ProbeRayHit, SeamError, UpdateStep};
