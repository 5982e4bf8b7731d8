//! What the seam's GPU tests share: the path of a shared scene.

#![allow(dead_code)]

/// A file under `../shared/scenes` beside the repository.
pub fn shared(path: &str) -> String {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/scenes")
        .join(path)
        .to_string_lossy()
        .into_owned()
}
