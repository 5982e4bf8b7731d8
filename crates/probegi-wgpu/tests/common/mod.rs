//! What the GPU tests share: the device (or a clear skip) and the shared scenes.

#![allow(dead_code)]

use probegi_wgpu::GpuContext;

/// A headless device, or `None` when there is none and `PROBEGI_REQUIRE_GPU` is
/// not set (see `GpuContext::headless_unless_absent`).
pub fn context() -> Option<GpuContext> {
    GpuContext::headless_unless_absent().expect("PROBEGI_REQUIRE_GPU is set")
}

/// A file under `../shared/scenes`.
pub fn shared(path: &str) -> String {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/scenes")
        .join(path)
        .to_string_lossy()
        .into_owned()
}
