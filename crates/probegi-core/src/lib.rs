//! probegi-core: the GI maths and data layouts.
//!
//! Nothing here knows about threads, files or scenes, so that a GPU backend can
//! reuse every function as-is (STYLE.md, "Layout shows the architecture").
//!
//! - [`color`]: luminance, sRGB transfer functions and the one tone-mapping operator.
//! - [`sampling`]: Monte Carlo sampling sets (`sample_x`, `x_pdf`, `invert_x`).
//! - [`rng`]: a small deterministic PCG32 and seed hashing.
//! - [`camera`]: pinhole camera maths.
//! - [`image`]: the linear-RGB float image every renderer writes.
//! - [`punctual`]: glTF KHR_lights_punctual attenuation maths.

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
pub mod probe_classification;
pub mod probe_grid;
pub mod probe_relocation;
pub mod punctual;
pub mod rng;
pub mod sampling;
pub mod sh;

pub use glam::{Vec2, Vec3, Vec4};
pub mod sh_cascades;
pub mod sh_probe_update;
pub mod sh_settings;
