//! Walking folders for data sets: every folder under some roots, or those holding a given set of files.
//!
//! Complexity: linear in the number of directory entries; symlinked folders are followed once (cycles are cut by
//! canonical path).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

use super::SCENE_FILES;

/// Folders under each root (recursively, the roots included) that contain every file in `files`, sorted by path
/// and without duplicates. A matching folder is not searched further. Hidden folders (`.name`) are skipped.
///
/// # Errors
/// [`Error::Io`] if a root cannot be read (unreadable sub-folders are skipped).
pub fn find_dirs_with(roots: &[PathBuf], files: &[&str]) -> Result<Vec<PathBuf>> {
    let mut found = Vec::new();
    walk_folders(roots, &mut |dir| {
        let matches = files.iter().all(|f| dir.join(f).is_file());
        if matches {
            found.push(dir.to_path_buf());
        }
        matches
    })?;
    found.sort();
    found.dedup();
    Ok(found)
}

/// Calls `visit` on every folder under the roots (recursively, the roots included, each sub-folder list in path
/// order); a folder for which it returns true is not searched further. Hidden folders (`.name`) are skipped, and
/// a folder reached twice (symbolic links, cycles) is visited once (by canonical path).
///
/// # Errors
/// [`Error::Io`] if a root cannot be read, [`Error::Dataset`] if one is not a folder (unreadable sub-folders are
/// skipped).
pub(crate) fn walk_folders(roots: &[PathBuf], visit: &mut dyn FnMut(&Path) -> bool) -> Result<()> {
    let mut seen = BTreeSet::new();
    for root in roots {
        let meta = std::fs::metadata(root).map_err(|e| Error::io(root, e))?;
        if !meta.is_dir() {
            return Err(Error::dataset(format!("{} is not a folder", root.display())));
        }
        walk(root, visit, &mut seen, true)?;
    }
    Ok(())
}

fn walk(dir: &Path, visit: &mut dyn FnMut(&Path) -> bool, seen: &mut BTreeSet<PathBuf>, is_root: bool) -> Result<()> {
    let key = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    if !seen.insert(key) || visit(dir) {
        return Ok(());
    }
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if is_root => return Err(Error::io(dir, e)),
        Err(_) => return Ok(()),
    };
    let mut subdirs: Vec<PathBuf> = entries
        .filter_map(|e| e.ok())
        .filter(|e| !e.file_name().to_string_lossy().starts_with('.'))
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .collect();
    subdirs.sort();
    for sub in subdirs {
        walk(&sub, visit, seen, false)?;
    }
    Ok(())
}

/// Every MiddEval3-style scene folder (with `im0.png`, `im1.png`, `calib.txt`) under the roots, sorted by path.
///
/// # Errors
/// As [`find_dirs_with`].
pub fn find_scenes(roots: &[PathBuf]) -> Result<Vec<PathBuf>> {
    find_dirs_with(roots, &SCENE_FILES)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_nested_scenes_sorted_and_skips_incomplete() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        for (scene, files) in [
            ("b/Teddy", &SCENE_FILES[..]),
            ("a/Zebra", &SCENE_FILES[..]),
            ("a/Half", &SCENE_FILES[..2]),
            (".hidden/X", &SCENE_FILES[..]),
        ] {
            std::fs::create_dir_all(root.join(scene)).unwrap();
            for f in files {
                std::fs::write(root.join(scene).join(f), b"").unwrap();
            }
        }
        let found = find_scenes(&[root.to_path_buf(), root.join("b")]).unwrap();
        assert_eq!(found, vec![root.join("a/Zebra"), root.join("b/Teddy")]);
        assert_eq!(find_scenes(&[root.join("b/Teddy")]).unwrap(), vec![root.join("b/Teddy")]);
        assert!(find_scenes(&[root.join("missing")]).is_err());
    }
}
