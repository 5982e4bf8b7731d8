//! probegi-wgpu: the DDGI field passes as wgpu compute shaders (issue "The whole
//! frame on the GPU…", in progress).
//!
//! Built so far, and tested against the CPU path on Mesa's lavapipe:
//! - [`gpu_context`]: a headless device on any adapter (software ones included),
//!   or a device and queue the caller owns;
//! - [`probe_blend`]: the blend pass (irradiance with γ encoding and seed 004
//!   Listing 3's thresholds; distance moments with the power-cosine weight) and
//!   the border pass, over atlases that stay on the device.
//!
//! Not built yet: ray generation, the trace (CWBVH traversal in WGSL), shading,
//! relocation and classification, the query shader, the camera frame, the
//! field set's volumes and cascades. The CPU backend (`probegi-cpu`) does all of
//! them today. This crate depends on `probegi-core` for settings, layouts and
//! encodings, and never on the CPU backend.

pub mod bvh_trace;
pub mod camera_frame;
pub mod ddgi_query;
pub mod gpu_context;
pub mod gpu_scene;
pub mod gpu_timer;
pub mod probe_blend;
pub mod probe_shade;

pub use gpu_context::{GpuContext, GpuError};
