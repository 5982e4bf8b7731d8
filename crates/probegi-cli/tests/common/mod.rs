//! What the CLI's test files share: their scratch folder.

use std::path::PathBuf;
use std::sync::OnceLock;

/// `name` in this test process's scratch folder (`prefix`-pid), emptied at its
/// first use: a folder left by an earlier run whose process had the same id
/// would otherwise hold outputs that checks of "nothing written" find.
pub fn scratch(prefix: &str, name: &str) -> PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    let dir = DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("{prefix}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("mkdir");
        dir
    });
    dir.join(name)
}
