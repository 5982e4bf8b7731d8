//! probegi-core: the GI maths and data layouts.
//!
//! Nothing here knows about threads, files or scenes, so that a GPU backend can
//! reuse every function as-is (STYLE.md, "Layout shows the architecture").
//!
//! Shared maths:
//! - [`color`]: luminance, sRGB transfer functions and the one tone-mapping operator.
//! - [`sampling`]: Monte Carlo sampling sets (`sample_x`, `x_pdf`, `invert_x`).
//! - [`rng`]: a small deterministic PCG32 and seed hashing.
//! - [`camera`]: pinhole camera maths.
//! - [`image`]: the linear-RGB float image every renderer writes.
//! - [`punctual`]: glTF KHR_lights_punctual attenuation maths.
//! - [`bsdf`]: the shared surface BSDF (Lambert plus GGX with Smith masking).
//! - [`fibonacci`]: spherical Fibonacci point sets, the probe-ray directions.
//! - [`octahedral`]: octahedral mapping of the unit sphere to a square.
//!
//! DDGI (seeds 003 and 004):
//! - [`ddgi_settings`]: per-volume and per-set settings with the papers' defaults.
//! - [`probe_grid`]: the uniform probe grid of a volume and its circular storage.
//! - [`probe_atlas`]: octahedral tiles per probe with a 1-texel guard border.
//! - [`irradiance_encoding`]: the perceptual (gamma) encoding of irradiance texels.
//! - [`probe_blend`]: the blend pass, one frame folded in with hysteresis.
//! - [`probe_border`]: the border pass, guard texels from their interior sources.
//! - [`probe_change`]: how much a blend changed a probe (the ray budget's priority).
//! - [`probe_relocation`]: the probe-position optimizer.
//! - [`probe_classification`]: probe states (jcgt and usage schemes).
//! - [`ddgi_query`]: irradiance at a point from the 8-probe cage.
//! - [`ddgi_volume_blend`]: which volumes of a set shade a point, and how much.
//!
//! Screen-space SH probes (seed 001):
//! - [`sh`]: real spherical harmonics to band 2 and their irradiance convolution.
//! - [`sh_settings`]: the method's settings with the paper's defaults.
//! - [`shadow_field`]: seed 003 ch. 5's occlusion maps: their blend (eq. 5.2–5.3) and sampling.
//! - [`sh_cascades`]: nested camera-centred probe grids and their interpolation.
//! - [`sh_probe_update`]: the screen-space splat of lit samples into the probes.

#![warn(missing_docs)]

pub mod bsdf;
pub mod camera;
pub mod color;
pub mod ddgi_query;
pub mod ddgi_settings;
pub mod ddgi_volume_blend;
pub mod fibonacci;
pub mod image;
pub mod irradiance_encoding;
pub mod octahedral;
pub mod probe_atlas;
pub mod probe_blend;
pub mod probe_border;
pub mod probe_change;
pub mod probe_classification;
pub mod probe_grid;
pub mod probe_relocation;
pub mod punctual;
pub mod rng;
pub mod sampling;
pub mod sh;
pub mod sh_cascades;
pub mod sh_probe_update;
pub mod sh_settings;
pub mod shadow_field;

pub use glam::{Vec2, Vec3, Vec4};
