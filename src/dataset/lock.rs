//! The lock that keeps a second `jem batch` out of a results folder while one writes to it (issue 41: two batches
//! into one folder overwrote each other's results, both exiting 0).
//!
//! A lock is a file created atomically (`create_new`, `O_EXCL`) in the folder, holding the writer's pid, host and
//! process start time; [`ResultsLock`] removes it when the run ends. A lock whose process is gone (this host, and
//! no such pid, or the pid now another process: another start time) is stale, as after `kill -9`: the next run
//! takes it over and says so. A lock of another host, or one that cannot be read, counts as live: the error names
//! the file to remove if no run is going on.
//!
//! MiddEval3 results live in the scene folders: each scene a run writes gets its own lock, `.jem-lock-ALG`. A
//! KITTI or ETH3D results folder gets `.jem-lock`, or `.jem-lock-I-of-N` for part I of N of a sharded run (the
//! parts of one job array write disjoint files into one folder): a lock of another part of the same N does not
//! conflict; any other live one does.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::{Layout, Pair};
use crate::error::{Error, Result};
use crate::process::process_start;

/// The locks a run holds; dropping it removes them (each only while it is still this run's).
#[derive(Debug)]
pub struct ResultsLock {
    files: Vec<PathBuf>,
    token: String,
    taken_over: Vec<String>,
}

impl ResultsLock {
    /// One line per stale lock this run took over (its file and the process that is gone).
    pub fn taken_over(&self) -> &[String] {
        &self.taken_over
    }
}

impl Drop for ResultsLock {
    fn drop(&mut self) {
        for f in &self.files {
            if std::fs::read_to_string(f).is_ok_and(|t| t == self.token) {
                let _ = std::fs::remove_file(f);
            }
        }
    }
}

/// Who holds a lock, as its file says.
struct Holder {
    pid: u32,
    host: String,
    start: Option<u64>,
}

impl Holder {
    fn parse(text: &str) -> Option<Holder> {
        let field = |key: &str| text.lines().find_map(|l| l.strip_prefix(key).map(str::trim));
        Some(Holder {
            pid: field("pid ")?.parse().ok()?,
            host: field("host ")?.to_string(),
            start: field("start ").and_then(|s| s.parse().ok()),
        })
    }

    /// `Some(false)` if the process is gone for sure; `None` if this machine cannot tell (another host, no `/proc`).
    fn alive(&self) -> Option<bool> {
        if self.host != crate::process::host_name() || !crate::process::proc_available() {
            return None;
        }
        match process_start(&self.pid.to_string()) {
            None => Some(false),
            Some(now) => Some(self.start.is_none_or(|s| s == now)),
        }
    }

    fn describe(&self) -> String {
        format!("pid {} on {}", self.pid, if self.host.is_empty() { "an unnamed host" } else { &self.host })
    }
}

/// Locks the results of `alg` for these pairs against a second writer (see the module doc): the scene folders of
/// MiddEval3 pairs, the results folders of the others (created if missing). `shard` is `(I, N)` for part I of N.
///
/// # Errors
/// [`Error::Input`] naming the folder, the lock file and the run holding it when another live run (or one this
/// machine cannot check) holds a conflicting lock; [`Error::Io`] if a folder or lock cannot be made. No lock is
/// kept on error.
pub fn lock_results(
    pairs: &[Pair],
    alg: &str,
    results: Option<&Path>,
    shard: Option<(usize, usize)>,
) -> Result<ResultsLock> {
    let start = process_start("self").map_or(String::new(), |s| format!("start {s}\n"));
    let token = format!("pid {}\nhost {}\n{start}", std::process::id(), crate::process::host_name());
    let mut lock = ResultsLock { files: Vec::new(), token, taken_over: Vec::new() };
    let mut dirs = std::collections::BTreeSet::new();
    for pair in pairs {
        let (dir, scene_lock) = lock_dir(pair, alg, results);
        let name = scene_lock.unwrap_or_else(|| match shard.filter(|&(_, n)| n > 1) {
            Some((i, n)) => format!(".jem-lock-{i}-of-{n}"),
            None => ".jem-lock".to_string(),
        });
        if !dirs.insert(dir.clone()) {
            continue;
        }
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let file = dir.join(&name);
        match acquire(&file, &mut lock) {
            Ok(()) => lock.files.push(file),
            // A scene folder no file can be made in: its results cannot be written either, and that scene fails
            // alone (as it did), instead of the whole run.
            Err(Error::Io { .. }) if pair.layout == Layout::Middlebury => continue,
            Err(e) => return Err(e),
        }
        if pair.layout != Layout::Middlebury {
            check_other_parts(&dir, &name, shard)?;
        }
    }
    Ok(lock)
}

/// The live runs holding a lock on the results of `alg` for these pairs, one line each (the folder and who holds
/// it), for `jem eval`, which reads results that a batch may still be writing. Stale locks are not listed; a lock
/// this machine cannot check (another host, unreadable) is.
pub fn writers(pairs: &[Pair], alg: &str, results: Option<&Path>) -> Vec<String> {
    let mut dirs = std::collections::BTreeSet::new();
    let mut found = Vec::new();
    for pair in pairs {
        let (dir, scene_lock) = lock_dir(pair, alg, results);
        if !dirs.insert(dir.clone()) {
            continue;
        }
        let names = match scene_lock {
            Some(name) => vec![name],
            None => {
                let Ok(entries) = std::fs::read_dir(&dir) else { continue };
                let mut names: Vec<String> = entries
                    .flatten()
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|name| is_folder_lock(name))
                    .collect();
                names.sort();
                names
            }
        };
        for name in names {
            let Ok(text) = std::fs::read_to_string(dir.join(&name)) else { continue };
            let holder = Holder::parse(&text);
            if may_be_live(holder.as_ref()) {
                found.push(format!("{}: {} is writing these results ({name})", dir.display(), who(holder.as_ref())));
            }
        }
    }
    found
}

/// Where the lock of `pair`'s results of `alg` lives: its MiddEval3 scene folder with the scene's own lock name
/// (`.jem-lock-ALG`), or a KITTI/ETH3D results folder (`None`: the run's name there depends on its shard).
fn lock_dir(pair: &Pair, alg: &str, results: Option<&Path>) -> (PathBuf, Option<String>) {
    match pair.results_dir(alg, results) {
        None => (pair.root.clone(), Some(format!(".jem-lock-{alg}"))),
        Some(dir) => (dir, None),
    }
}

/// Part I of N in a results folder lock's name (`.jem-lock-I-of-N`).
fn shard_part(name: &str) -> Option<(usize, usize)> {
    let (i, n) = name.strip_prefix(".jem-lock-")?.split_once("-of-")?;
    Some((i.parse().ok()?, n.parse().ok()?))
}

/// Whether `name` is a results folder's lock: `.jem-lock`, or a shard's `.jem-lock-I-of-N`.
fn is_folder_lock(name: &str) -> bool {
    name == ".jem-lock" || shard_part(name).is_some()
}

/// Whether the holder of a lock may still be running: unless this machine can tell it is gone.
fn may_be_live(holder: Option<&Holder>) -> bool {
    holder.and_then(Holder::alive) != Some(false)
}

/// Who holds a lock, in words.
fn who(holder: Option<&Holder>) -> String {
    holder.map_or("a run whose lock cannot be read".to_string(), |h| format!("another jem run ({})", h.describe()))
}

/// The error for a live (or unknown) holder of `file`.
fn held(file: &Path, holder: Option<&Holder>) -> Error {
    let dir = file.parent().unwrap_or(Path::new("."));
    Error::Input(format!(
        "{}: {} is writing these results; wait for it to end, or remove {} if no such run is going on",
        dir.display(),
        who(holder),
        file.display()
    ))
}

/// Creates the lock `file` holding `lock.token`, taking over a stale one (a few tries, against a race with
/// another run taking it over at the same moment).
fn acquire(file: &Path, lock: &mut ResultsLock) -> Result<()> {
    for _ in 0..4 {
        match std::fs::OpenOptions::new().write(true).create_new(true).open(file) {
            Ok(mut f) => {
                return f.write_all(lock.token.as_bytes()).map_err(|e| {
                    let _ = std::fs::remove_file(file);
                    Error::io(file, e)
                });
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(Error::io(file, e)),
        }
        let Ok(text) = std::fs::read_to_string(file) else { continue }; // gone meanwhile: try again
        let holder = Holder::parse(&text);
        if may_be_live(holder.as_ref()) {
            return Err(held(file, holder.as_ref()));
        }
        // Stale: move it aside (one run wins the rename), and check that what moved is the stale lock read
        // above, not a lock another run has just made in its place; that one is put back.
        let aside = file.with_file_name(format!(".jem-stale-{}", std::process::id()));
        if std::fs::rename(file, &aside).is_err() {
            continue;
        }
        let moved = std::fs::read_to_string(&aside).unwrap_or_default();
        if moved != text {
            let _ = std::fs::hard_link(&aside, file);
        } else if let Some(h) = holder {
            lock.taken_over.push(format!(
                "{}: took over the lock of {}, which is no longer running",
                file.display(),
                h.describe()
            ));
        }
        let _ = std::fs::remove_file(&aside);
    }
    Err(Error::Input(format!(
        "{}: could not take the lock (other runs are taking it at the same time)",
        file.display()
    )))
}

/// Errors if `dir` holds a live lock of another run that conflicts with this one's `own` lock: any but another
/// part of the same number of parts.
fn check_other_parts(dir: &Path, own: &str, shard: Option<(usize, usize)>) -> Result<()> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name == own || !is_folder_lock(&name) {
            continue;
        }
        let other = shard_part(&name);
        let compatible =
            matches!((shard.filter(|&(_, n)| n > 1), other), (Some((i, n)), Some((j, m))) if n == m && i != j);
        if compatible {
            continue;
        }
        let Ok(text) = std::fs::read_to_string(entry.path()) else { continue };
        let holder = Holder::parse(&text);
        if may_be_live(holder.as_ref()) {
            return Err(held(&entry.path(), holder.as_ref()));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn empty_lock() -> ResultsLock {
        let token = format!("pid {}\nhost {}\n", std::process::id(), crate::process::host_name());
        ResultsLock { files: Vec::new(), token, taken_over: Vec::new() }
    }

    #[test]
    fn live_locks_are_refused_stale_ones_taken_over_and_only_ours_removed() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join(".jem-lock");
        let host = crate::process::host_name();
        assert!(process_start("self").is_some(), "this test needs /proc");

        // Live: this process, with and without its start time; another host; unreadable.
        let start = process_start("self").unwrap();
        for text in [
            format!("pid {}\nhost {host}\nstart {start}\n", std::process::id()),
            format!("pid {}\nhost {host}\n", std::process::id()),
            "pid 1\nhost another-host.example\n".to_string(),
            String::new(),
        ] {
            std::fs::write(&file, &text).unwrap();
            let e = acquire(&file, &mut empty_lock()).unwrap_err().to_string();
            assert!(e.contains("is writing these results") && e.contains(".jem-lock"), "{text:?}: {e}");
            assert_eq!(std::fs::read_to_string(&file).unwrap(), text, "left alone");
        }
        // Stale: a process that is gone, or this pid with another start time (a reused pid).
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        for text in [
            format!("pid {dead}\nhost {host}\n"),
            format!("pid {}\nhost {host}\nstart {}\n", std::process::id(), start + 1),
        ] {
            std::fs::write(&file, &text).unwrap();
            let mut lock = empty_lock();
            acquire(&file, &mut lock).unwrap();
            assert_eq!(lock.taken_over().len(), 1, "{text:?}");
            assert_eq!(std::fs::read_to_string(&file).unwrap(), lock.token);
            lock.files.push(file.clone());
            drop(lock);
            assert!(!file.exists(), "removed at the end");
        }
        // Dropping a lock that another run has replaced meanwhile leaves that one.
        let mut lock = empty_lock();
        acquire(&file, &mut lock).unwrap();
        lock.files.push(file.clone());
        std::fs::write(&file, "pid 1\nhost another-host.example\n").unwrap();
        drop(lock);
        assert!(file.exists());
        assert_eq!(names_in(dir.path()), [".jem-lock"], "no file left aside");
    }

    fn names_in(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        names.sort();
        names
    }
}
