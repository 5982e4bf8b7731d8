//! probegi-scene: the scene model, its loaders and ray casting.
//!
//! - [`scene`], [`animation`] (rigid objects over frames), [`mesh`], [`material`], [`texture`], [`light`]: the model.
//! - [`obj`], [`gltf_file`], [`scene_file`], [`builtin`], [`load`]: loaders.
//! - [`tracer`]: the ray-casting trait; [`bvh`]: its obvhs CWBVH implementation; [`bvh_walk`]: the ray rule
//!   and the bounded walks every ray goes through.

pub mod animation;
mod bounds;
pub mod builtin;
pub mod bvh;
pub mod bvh_walk;
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
pub use error::SceneError;
pub use light::{LightKind, PunctualLight};
pub use load::load_scene;
pub use material::Material;
pub use ray::{Ray, RayHit};
pub use scene::{CameraKeyframe, Scene, SurfacePoint};
pub use tracer::RayTracer;
