//! One entry point for every scene source: `builtin:NAME`, `.obj`, `.gltf`,
//! `.glb` or `.toml`, decided by prefix and extension.

use std::path::Path;

use crate::error::{Result, SceneError};
use crate::scene::Scene;

/// Loads and validates a scene.
pub fn load_scene(spec: &str) -> Result<Scene> {
    let mut scene = if let Some(name) = spec.strip_prefix("builtin:") {
        crate::builtin::load_builtin(name)?
    } else {
        let path = Path::new(spec);
        let ext = path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
        match ext.as_str() {
            "obj" => crate::obj::load_obj(path)?,
            "gltf" | "glb" => crate::gltf_file::load_gltf(path)?,
            "toml" => crate::scene_file::load_scene_file(path)?,
            _ => return Err(SceneError::UnsupportedFormat { path: path.to_path_buf() }),
        }
    };
    scene.validate().map_err(|message| SceneError::Invalid { path: spec.into(), message })?;
    let warnings = scene.energy_warnings();
    scene.warnings.extend(warnings);
    Ok(scene)
}
