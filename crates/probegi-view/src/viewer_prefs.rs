//! Viewer settings that persist between runs, in a small TOML file:
//! `$PROBEGI_VIEW_PREFS`, else `$XDG_CONFIG_HOME/probegi/view.toml`, else
//! `~/.config/probegi/view.toml`. A scripted run reads and writes none, so it
//! is the same on every machine.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::view_layers::ViewMode;

/// What persists.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ViewerPrefs {
    /// The view shown at start.
    pub view: ViewMode,
    /// The panels are shown.
    pub panels_visible: bool,
    /// Samples per pixel of the reference key.
    pub reference_spp: u32,
    /// The CPU backend's frame-time target, milliseconds (adaptive size).
    pub cpu_target_frame_ms: f64,
}

impl Default for ViewerPrefs {
    fn default() -> Self {
        Self { view: ViewMode::Full, panels_visible: true, reference_spp: 64, cpu_target_frame_ms: 100.0 }
    }
}

impl ViewerPrefs {
    /// Where the prefs live (see the module docs); `None` without a home.
    pub fn default_path() -> Option<PathBuf> {
        if let Some(p) = std::env::var_os("PROBEGI_VIEW_PREFS") {
            return Some(PathBuf::from(p));
        }
        let config = std::env::var_os("XDG_CONFIG_HOME")
            .map(PathBuf::from)
            .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".config")))?;
        Some(config.join("probegi").join("view.toml"))
    }

    /// The prefs in `path`; the defaults when it is absent. A file that does
    /// not parse is reported on stderr (file and place) and ignored.
    pub fn load(path: &Path) -> Self {
        let Ok(text) = std::fs::read_to_string(path) else { return Self::default() };
        match toml::from_str(&text) {
            Ok(p) => p,
            Err(e) => {
                eprintln!("probegi view: ignoring {}: {e}", path.display());
                Self::default()
            }
        }
    }

    /// Writes the prefs to `path` (its folder created).
    pub fn save(&self, path: &Path) -> Result<(), String> {
        let text = toml::to_string(self).map_err(|e| format!("prefs: {e}"))?;
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| format!("creating {}: {e}", dir.display()))?;
        }
        std::fs::write(path, text).map_err(|e| format!("writing {}: {e}", path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefs_round_trip_and_bad_files_fall_back() {
        let dir = std::env::temp_dir().join(format!("probegi-prefs-{}", std::process::id()));
        let path = dir.join("view.toml");
        let p = ViewerPrefs {
            view: ViewMode::Indirect,
            panels_visible: false,
            reference_spp: 16,
            cpu_target_frame_ms: 50.0,
        };
        p.save(&path).expect("saves");
        assert_eq!(ViewerPrefs::load(&path), p);
        std::fs::write(&path, "view = 3\n").expect("writes");
        assert_eq!(ViewerPrefs::load(&path), ViewerPrefs::default());
        assert_eq!(ViewerPrefs::load(&dir.join("absent.toml")), ViewerPrefs::default());
        let _ = std::fs::remove_dir_all(dir);
    }
}
