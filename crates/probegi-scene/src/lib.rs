//! probegi-scene: the scene model, its loaders and ray casting.
//!
//! The model:
//! - [`scene`]: the [`Scene`]: one merged mesh, materials, textures, lights, sky, camera, instances.
//! - [`animation`]: rigid objects over frames (keyframes and closed-form motion paths).
//! - [`mesh`]: indexed triangle meshes and their shading normals.
//! - [`material`]: metallic-roughness materials with the OBJ/MTL fields beside them.
//! - [`texture`]: 8-bit textures, their samplers and lookups.
//! - [`light`]: punctual lights (KHR_lights_punctual semantics and units).
//! - [`environment_map`]: the equirectangular HDR sky (EXR, Radiance `.hdr`), its lookup and sampling.
//! - [`shapes`]: hand-made geometry: polygons, boxes, rooms.
//! - `bounds`: axis-aligned bounds under a transform (crate-internal).
//!
//! The loaders:
//! - [`load`]: the one entry point, [`load_scene`], choosing by prefix and extension.
//! - [`obj`]: Wavefront OBJ/MTL.
//! - [`gltf_file`]: glTF 2.0 (.gltf and .glb).
//! - [`scene_file`]: the TOML scene file, which places other files (through [`load`]).
//! - [`builtin`]: the scenes compiled in, `builtin:NAME`.
//! - [`file_lookup`]: file names inside scene files (separators, case, the shared folder).
//! - [`error`]: the typed loader error, [`SceneError`].
//!
//! Ray casting:
//! - [`ray`]: the ray and hit records.
//! - [`tracer`]: the [`RayTracer`] trait renderers trace through.
//! - [`bvh`]: its obvhs CWBVH implementation, [`BvhTracer`], and the flat form a GPU reads.
//! - [`bvh_walk`]: the ray rule and the bounded walks every ray goes through.

#![warn(missing_docs)]

pub mod animation;
mod bounds;
pub mod builtin;
pub mod bvh;
pub mod bvh_walk;
pub mod environment_map;
pub mod error;
pub mod file_lookup;
pub mod gltf_file;
pub mod light;
pub mod load;
pub mod material;
pub mod mesh;
pub mod obj;
pub mod ray;
pub mod scene;
pub mod scene_file;
pub mod shapes;
pub mod texture;
pub mod tracer;

pub use animation::{MotionPath, ObjectAnimation, SceneObject, TransformKeyframe};
pub use bvh::{BvhCutTriangle, BvhCutoutMask, BvhExport, BvhSettings, BvhTracer, TlasExport, TlasInstance, TlasLayout};
pub use bvh_walk::TraceGuardCounts;
pub use environment_map::{EnvironmentMap, SkyMap, SkySample};
pub use error::SceneError;
pub use light::{LightKind, PunctualLight};
pub use load::load_scene;
pub use material::Material;
pub use ray::{Ray, RayHit};
pub use scene::{CameraKeyframe, Scene, SurfacePoint};
pub use tracer::RayTracer;
