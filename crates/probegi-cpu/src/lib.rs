//! probegi-cpu: the CPU renderers. Threads live here (rayon), never in the core.
//!
//! - [`path_tracer`]: the unbiased reference (`probegi reference`).
//! - [`gbuffer`], [`direct`], [`frame_loop`]: the real-time-style frame: primary
//!   rays into a G-buffer, then shading passes (`probegi render`).
//! - [`light_sampling`], [`shading`]: light sampling and the surface model they share.

pub mod direct;
pub mod frame_loop;
pub mod gbuffer;
pub mod glossy;
pub mod light_sampling;
pub mod parallel;
pub mod path_tracer;
pub mod shading;

pub use direct::{DirectLighting, DirectSettings};
pub use frame_loop::{GiMethod, RenderOutput, RenderSettings, RenderStats, render_frames};
pub use path_tracer::{PathTracer, PathTracerSettings};
pub mod field_update;
pub mod probe_shade;
pub mod probe_trace;
pub mod probe_vis;
pub mod scene_events;
pub mod sh_inject;
pub mod sh_probes;
pub mod sh_screen_samples;
