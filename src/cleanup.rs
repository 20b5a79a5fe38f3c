//! What a run must not leave behind when a signal stops it: the temporary files of writes under way, the result
//! locks it holds, the temporary tree of `jem degrade`.
//!
//! Each is registered here while it exists. The `jem` binary turns SIGTERM and SIGINT into a call to
//! [`remove_all`], which removes them, and then ends the process while it still holds the registry. Renames into
//! place happen while the registry is held (`hold`), so a signal waits for them: files written as one are all
//! renamed, or none (a temporary file removed under a write stays unrenamed, and the write fails).

// Without the toolkit nothing removes what is registered (only the CLI handles signals): the registry is kept so
// that the writes stay the same code either way.
#![cfg_attr(not(feature = "toolkit"), allow(dead_code, unreachable_pub))]

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// Something to remove when the process is stopped.
enum Entry {
    /// A file, removed only while it holds exactly `token` (`None`: whatever it holds).
    File(PathBuf, Option<String>),
    /// A folder and everything in it.
    Tree(PathBuf),
}

impl Entry {
    fn path(&self) -> &Path {
        match self {
            Entry::File(p, _) | Entry::Tree(p) => p,
        }
    }
}

static PENDING: Mutex<Vec<Entry>> = Mutex::new(Vec::new());

/// The registry, held: while a `Held` lives, no signal ends the process (the handler waits for it).
pub struct Held(MutexGuard<'static, Vec<Entry>>);

/// Holds the registry (see [`Held`]).
pub(crate) fn hold() -> Held {
    Held(PENDING.lock().unwrap_or_else(|poisoned| poisoned.into_inner()))
}

impl Held {
    /// Registers a file to remove on a signal, only while it holds `token` when one is given (a lock another
    /// run has taken over meanwhile is left alone).
    pub(crate) fn add_file(&mut self, path: &Path, token: Option<&str>) {
        self.0.push(Entry::File(path.to_path_buf(), token.map(str::to_string)));
    }

    /// Registers a folder to remove, with everything in it, on a signal.
    pub(crate) fn add_tree(&mut self, path: &Path) {
        self.0.push(Entry::Tree(path.to_path_buf()));
    }

    /// Forgets `path` (renamed into place, removed, or released).
    pub(crate) fn forget(&mut self, path: &Path) {
        self.0.retain(|e| e.path() != path);
    }
}

/// Removes everything registered (a file with a token only while it still holds it) and returns the registry
/// held, so that no write starts or finishes before the caller ends the process.
pub fn remove_all() -> Held {
    let mut held = hold();
    remove(held.0.drain(..));
    held
}

fn remove(entries: impl Iterator<Item = Entry>) {
    for entry in entries {
        match entry {
            Entry::File(path, token) => {
                if still_held(&path, token.as_deref()) {
                    let _ = std::fs::remove_file(&path);
                }
            }
            Entry::Tree(path) => {
                let _ = std::fs::remove_dir_all(&path);
            }
        }
    }
}

/// Whether a file registered with `token` is still this run's to remove: a file without a token always is; one with
/// a data set's lock token only while that lock still holds it (the toolkit's data sets are the only holders).
#[cfg(feature = "toolkit")]
fn still_held(path: &Path, token: Option<&str>) -> bool {
    token.is_none_or(|t| crate::dataset::lock_holds(path, t))
}

/// Whether a file registered with `token` is still this run's to remove (without the toolkit no file has a token).
#[cfg(not(feature = "toolkit"))]
fn still_held(_path: &Path, token: Option<&str>) -> bool {
    token.is_none()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn removes_what_is_registered_and_only_locks_still_held() {
        let dir = tempfile::tempdir().unwrap();
        let (tmp, ours, theirs, tree) =
            (dir.path().join("t"), dir.path().join("l1"), dir.path().join("l2"), dir.path().join("tree"));
        std::fs::write(&tmp, b"partial").unwrap();
        std::fs::write(&ours, "pid 1\n").unwrap();
        std::fs::write(&theirs, "pid 2\n").unwrap();
        std::fs::create_dir_all(tree.join("sub")).unwrap();
        std::fs::write(dir.path().join("kept"), b"x").unwrap();
        // A local list: the process's registry is shared with the tests writing files at the same time.
        let entries = vec![
            Entry::File(tmp, None),
            Entry::File(ours, Some("pid 1\n".into())),
            Entry::File(theirs, Some("pid 1\n".into())),
            Entry::Tree(tree),
        ];
        remove(entries.into_iter());
        let mut left: Vec<String> =
            std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        left.sort();
        assert_eq!(left, ["kept", "l2"]);
    }
}
