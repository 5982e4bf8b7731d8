//! What the GPU tests share: the device (or a clear skip) and the shared scenes.

#![allow(dead_code)]

use probegi_wgpu::GpuContext;

/// A headless device, or `None` (the test says why and passes) when there is no
/// adapter, unless `PROBEGI_REQUIRE_GPU` is set (`scripts/test.sh` sets it once
/// lavapipe is installed): then a missing adapter fails the test.
pub fn context() -> Option<GpuContext> {
    match GpuContext::headless() {
        Ok(c) => {
            eprintln!("adapter: {}", c.adapter_name);
            Some(c)
        }
        Err(e) if std::env::var_os("PROBEGI_REQUIRE_GPU").is_none() => {
            eprintln!("skipping the GPU test: {e}");
            None
        }
        Err(e) => panic!("PROBEGI_REQUIRE_GPU is set but {e}"),
    }
}

/// A file under `../shared/scenes`.
pub fn shared(path: &str) -> String {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/scenes")
        .join(path)
        .to_string_lossy()
        .into_owned()
}
