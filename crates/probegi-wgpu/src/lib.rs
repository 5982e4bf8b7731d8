//! probegi-wgpu: DDGI on the GPU as wgpu compute shaders (WGSL), on any adapter,
//! software ones included (issue "The whole frame on the GPU…").
//!
//! Built, and tested against the CPU path on Mesa's lavapipe, one module per pass:
//! - [`bvh_trace`]: the trace: the CPU's compressed-wide BVH (obvhs) uploaded as
//!   it is and traversed in `bvh.wgsl`, closest and any hit, alpha cutouts
//!   inside the traversal; also over a caller's own triangle soup;
//! - [`camera_frame`]: the camera frame (primary rays, direct light, glossy
//!   rays, the field query);
//! - [`device_frame`]: the camera frame kept on the device start to finish
//!   (accumulation, the temporal filter, composition, tone mapping and the
//!   frame's statistics), one submission a frame, statistics read late;
//! - [`ddgi_query`]: the query of a set of volumes as WGSL an engine includes,
//!   the field on the device, and a batch query over points;
//! - [`gpu_context`]: a headless device on any adapter, or a device and queue
//!   the caller owns;
//! - [`gpu_scene`]: a scene's surfaces, materials, textures and lights in
//!   `scene.wgsl`'s layout;
//! - [`gpu_timer`]: per-pass GPU times from timestamp queries;
//! - [`probe_blend`]: the blend (γ encoding, seed 004 Listing 3's thresholds,
//!   distance moments, over the CPU's own weight tables) and border passes over
//!   device-resident atlases (a volume's own, or its range of a resident field);
//! - [`probe_seeding`]: new probes' tiles mixed from a coarser volume's
//!   (`probegi_field::probe_seeding`) in the resident field;
//! - [`probe_change`]: each blended probe's change, the ray budget's signal
//!   (`probegi_core::probe_change`), read back 4 bytes a probe, late;
//! - [`probe_classification`]: seed 004 Listing 5's classification round;
//! - [`probe_ray_gen`]: rotated spherical Fibonacci rays written straight into
//!   a trace batch;
//! - [`probe_relocation`]: seed 004 Listing 4's relocation iteration;
//! - [`probe_shade`]: the shade pass of the probe rays (sky, back faces, direct
//!   light with shadow rays, the previous field, second-order glossy);
//! - [`probe_usage`]: seed 003's usage counts over a traced batch where it lies, read back late;
//! - `late_readback` (crate-private): results read some update batches after
//!   their pass, so that an update does not wait on the device for them;
//! - [`shadow_field`]: the shadowing field's shadow rays and occlusion blend (seed 003 ch. 5);
//! - `shader_registry` (crate-private): the one owner of the WGSL: each pass's
//!   files in order, the constants prelude generated from the Rust `const`s,
//!   and the bind-group convention (0 the pass, 1 the BVH, 2 the field, 3 the
//!   scene) with each shared group's storage-buffer count;
//! - [`wgpu_field_backend`]: the field set's seam driven by these passes.
//!
//! [`wgpu_field_backend`] drives these passes through the field set's seam
//! (`probegi-field`'s `ProbeBatchTracer` and `DeviceField`), the atlases kept
//! on the device; moving objects and instanced meshes go through
//! the CPU's top level, placed on the device each frame ([`bvh_trace::GpuBvh::place`]).
//! Not built: a ray-query trace path (the compute traversal runs everywhere).
//! This crate depends on `probegi-core` (settings, layouts, encodings),
//! `probegi-scene` (the BVH and the scene) and `probegi-field` (the field's host
//! side), and never on the CPU backend, its peer.

#![warn(missing_docs)]

pub mod bvh_trace;
pub mod camera_frame;
pub mod ddgi_query;
pub mod device_frame;
pub mod gpu_context;
pub mod gpu_scene;
pub mod gpu_timer;
mod late_readback;
pub mod probe_blend;
pub mod probe_change;
pub mod probe_classification;
pub mod probe_ray_gen;
pub mod probe_relocation;
pub mod probe_seeding;
pub mod probe_shade;
pub mod probe_usage;
pub(crate) mod shader_registry;
pub mod shadow_field;
pub mod sky_from_cubemap;
pub mod wgpu_field_backend;

pub use gpu_context::{GpuContext, GpuCounters, GpuError};
/// The wgpu this crate is built on: an engine that shares its device
/// (`GpuContext::from_device`) or binds its buffers names the same types.
pub use wgpu;
pub use wgpu_field_backend::WgpuProbeTracer;
