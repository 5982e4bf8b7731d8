//! Typed loader errors. Every variant names the file, and the line or field where
//! there is one, so the binary can print it as is.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    // The message carries the I/O error itself, so it is not also a `source`
    // (error chains would print it twice).
    #[error("{path}: {cause}")]
    Io { path: PathBuf, cause: std::io::Error },
    #[error("{path}:{line}: {message}")]
    Parse { path: PathBuf, line: usize, message: String },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("{path}: texture: {message}")]
    Texture { path: PathBuf, message: String },
    #[error("{path}: glTF: {message}")]
    Gltf { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Toml { path: PathBuf, message: String },
    #[error("unknown built-in scene `builtin:{name}`; available: {available}")]
    UnknownBuiltin { name: String, available: String },
    #[error("{path}: unsupported scene format (expected .obj, .gltf, .glb or .toml)")]
    UnsupportedFormat { path: PathBuf },
}

pub type Result<T> = std::result::Result<T, SceneError>;
