//! Typed loader errors. Every variant names the file, and the line or field where
//! there is one, so the binary can print it as is.

use std::path::PathBuf;

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    // The message carries the I/O error itself, so it is not also a `source`
    // (error chains would print it twice).
    #[error("{path}: {cause}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        cause: std::io::Error,
    },
    /// A malformed line of a text format (OBJ, MTL, the TOML camera).
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The 1-based line.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// The file parsed, but the scene breaks an invariant (`Scene::validate`) or is empty.
    #[error("{path}: {message}")]
    Invalid {
        /// The file or scene spec.
        path: PathBuf,
        /// The broken invariant.
        message: String,
    },
    /// A texture file that exists but cannot be used.
    #[error("{path}: texture: {message}")]
    Texture {
        /// The texture file.
        path: PathBuf,
        /// Why it could not be decoded or used.
        message: String,
    },
    /// A glTF or GLB file that cannot be read as a scene.
    #[error("{path}: glTF: {message}")]
    Gltf {
        /// The glTF or GLB file.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// A TOML scene file that does not parse or whose entries are wrong.
    #[error("{path}: {message}")]
    Toml {
        /// The scene file.
        path: PathBuf,
        /// What is wrong with it, naming the entry.
        message: String,
    },
    /// `builtin:NAME` with a name no built-in scene has.
    #[error("unknown built-in scene `builtin:{name}`; available: {available}")]
    UnknownBuiltin {
        /// The name asked for.
        name: String,
        /// The names there are, comma-separated.
        available: String,
    },
    /// A file whose extension no loader reads.
    #[error("{path}: unsupported scene format (expected .obj, .gltf, .glb or .toml)")]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
    },
}

/// The result of every loader.
pub type Result<T> = std::result::Result<T, SceneError>;
