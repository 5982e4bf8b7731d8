//! probegi-cpu: the CPU renderers. Threads live here (rayon), never in the core.
//!
//! The passes of the host's camera frame (the loop that runs them in order is
//! `probegi-frame`'s):
//! - [`gbuffer`]: the G-buffer pass, one primary ray per pixel.
//! - [`direct`]: direct light (emission, punctual, area lights and sky).
//! - [`glossy`]: second-order glossy reflections read from the probes.
//! - [`probe_vis`]: `--show-probes`, probes drawn as spheres in the image.
//! - [`light_visibility`]: `--ao`, punctual lights' visibility from the shadowing field or shadow rays.
//!
//! The DDGI field update's passes on the CPU (seeds 003 and 004; the seam is
//! driven by `probegi-frame`'s `field_update`):
//! - [`probe_trace`]: the trace pass, probe rays to closest hits and seam hits.
//! - [`probe_shade`]: the shade pass, the radiance each probe ray brings back.
//!
//! Screen-space SH probes (seed 001):
//! - [`sh_probes`]: the cascades and their per-frame update.
//! - [`sh_screen_samples`]: the screen-sample pass, one lit sample per tile.
//! - [`sh_inject`]: light injection of emitters and sky into the probes.
//!
//! The reference and what every renderer shares:
//! - [`path_tracer`]: the unbiased reference (`probegi reference`).
//! - [`light_sampling`]: emitter sampling by power and punctual light irradiance.
//! - [`shading`]: the surface model, shadow rays and punctual direct light.
//! - [`parallel`]: row-parallel image loops, bit-identical for any thread count.

#![warn(missing_docs)]

pub mod direct;
pub mod gbuffer;
pub mod glossy;
pub mod light_sampling;
pub mod light_visibility;
pub mod parallel;
pub mod path_tracer;
pub mod shading;

pub use direct::{DirectLighting, DirectSettings};
pub use path_tracer::{PathTracer, PathTracerSettings};
pub mod probe_shade;
pub mod probe_trace;
pub mod probe_vis;
pub mod sh_inject;
pub mod sh_probes;
pub mod sh_screen_samples;
