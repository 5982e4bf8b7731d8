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
