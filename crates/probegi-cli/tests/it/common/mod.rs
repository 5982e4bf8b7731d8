//! What the CLI's test files share: their scratch folder.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Mutex, OnceLock};

/// `name` in this test process's scratch folder for `prefix` (`prefix`-pid),
/// emptied at its first use: a folder left by an earlier run whose process had
/// the same id would otherwise hold outputs that checks of "nothing written"
/// find. Each test module passes its own prefix, so modules of the one test
/// binary never share a folder.
pub fn scratch(prefix: &str, name: &str) -> PathBuf {
    static DIRS: OnceLock<Mutex<HashMap<String, PathBuf>>> = OnceLock::new();
    let mut dirs = DIRS.get_or_init(Default::default).lock().unwrap_or_else(|e| e.into_inner());
    let dir = dirs.entry(prefix.to_owned()).or_insert_with(|| {
        let dir = std::env::temp_dir().join(format!("{prefix}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("mkdir");
        dir
    });
    dir.join(name)
}
