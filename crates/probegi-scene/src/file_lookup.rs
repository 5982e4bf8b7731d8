//! Resolving file names written inside scene files: relative to the referencing
//! file, with `\` accepted as a separator, and case-insensitive per path component
//! when the exact name does not exist (Dabrovic Sponza's MTL says `SP_LUK.JPG` for
//! `sp_luk.JPG`).

use std::path::{Component, Path, PathBuf};

/// The existing file `name` refers to, relative to `base_dir`, or `None`.
pub fn resolve_case_insensitive(base_dir: &Path, name: &str) -> Option<PathBuf> {
    let name = name.replace('\\', "/");
    let rel = Path::new(&name);
    let exact = base_dir.join(rel);
    if exact.exists() {
        return Some(exact);
    }
    let mut current = if rel.is_absolute() { PathBuf::from("/") } else { base_dir.to_path_buf() };
    for comp in rel.components() {
        match comp {
            Component::Normal(part) => {
                let candidate = current.join(part);
                if candidate.exists() {
                    current = candidate;
                    continue;
                }
                let wanted = part.to_string_lossy().to_lowercase();
                let found = std::fs::read_dir(&current)
                    .ok()?
                    .filter_map(|e| e.ok())
                    .find(|e| e.file_name().to_string_lossy().to_lowercase() == wanted)?;
                current = found.path();
            }
            Component::ParentDir => current.push(".."),
            Component::CurDir | Component::RootDir | Component::Prefix(_) => {}
        }
    }
    current.exists().then_some(current)
}

/// The environment variable that names the shared folder (the one holding `scenes/`).
pub const SHARED_DIR_ENV: &str = "PROBEGI_SHARED_DIR";

/// The shared data folder (`shared/`, holding `scenes/`): `$PROBEGI_SHARED_DIR`,
/// else a `shared` folder in the working directory or any of its ancestors (the
/// repository sits beside it), else beside the executable's ancestors. The error
/// says where it looked.
pub fn shared_dir() -> Result<PathBuf, String> {
    if let Some(dir) = std::env::var_os(SHARED_DIR_ENV) {
        let dir = PathBuf::from(dir);
        return if dir.join("scenes").is_dir() {
            Ok(dir)
        } else {
            Err(format!("${SHARED_DIR_ENV} = {} has no scenes/ folder", dir.display()))
        };
    }
    let mut starts = vec![];
    starts.extend(std::env::current_dir().ok());
    starts.extend(std::env::current_exe().ok().and_then(|e| e.parent().map(Path::to_path_buf)));
    for start in &starts {
        for dir in start.ancestors() {
            let candidate = dir.join("shared");
            if candidate.join("scenes").is_dir() {
                return Ok(candidate);
            }
        }
    }
    Err(format!(
        "the shared scene folder was not found: set ${SHARED_DIR_ENV}, or run from inside a directory that has \
         shared/scenes beside it (looked above {})",
        starts.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(" and ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_files_whose_case_differs() {
        let dir = std::env::temp_dir().join(format!("probegi-lookup-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("Sub")).expect("mkdir");
        std::fs::write(dir.join("Sub").join("tex.JPG"), b"x").expect("write");
        assert_eq!(resolve_case_insensitive(&dir, "sub/TEX.jpg"), Some(dir.join("Sub").join("tex.JPG")));
        assert_eq!(resolve_case_insensitive(&dir, "Sub\\tex.JPG"), Some(dir.join("Sub").join("tex.JPG")));
        assert_eq!(resolve_case_insensitive(&dir, "nope.png"), None);
        std::fs::remove_dir_all(&dir).ok();
    }
}
