//! probegi-scene's integration tests, one binary (each former test file a
//! module): one link instead of one per file. Run one file's tests with
//! `cargo test -p probegi-scene --test it MODULE::`.

mod common;

mod assimp_gltf2;
mod camera_keyframes;
mod degenerate_rays;
mod fuzz_cameras_and_rays;
mod fuzz_loaders;
mod gltf_and_toml;
mod gltf_features;
mod hostile_inputs;
mod khronos_gltf_samples;
mod objects_and_builtins;
mod real_assets;
mod shared_scenes;
