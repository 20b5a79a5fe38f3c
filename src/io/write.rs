//! Writing files all or none: every output goes to a hidden temporary file in its folder, flushed, then renamed over
//! the destination (the module doc of `crate::io`); only a regular file (or none) is replaced.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::missing_folder;
use crate::error::{Error, Result};

/// Writes several files as one: each goes to its temporary file first; only when all of them are written and
/// flushed are they renamed into place. If any write fails, no destination is touched and the temporary files
/// are removed. If a rename fails (a destination that is a folder, say, or has become a special file:
/// [`check_replaceable`]), the files renamed before it are undone: a destination that existed gets its old file
/// back (kept under a hidden name, a hard link, until all are renamed), one that did not is removed; the error
/// names the file that failed. [`AllOrNone`] does the same for files produced one at a time.
///
/// # Errors
/// [`Error::Io`] naming the first file that could not be written, [`Error::Output`] for a destination that is not
/// a regular file.
pub fn write_all_or_none(files: &[(&Path, &[u8])]) -> Result<()> {
    for &(path, bytes) in files {
        check_file_size_limit(path, bytes.len() as u64)?;
    }
    let mut set = AllOrNone::new();
    for &(path, bytes) in files {
        set.add(path, bytes)?;
    }
    set.commit()
}

/// Files written as one, as [`write_all_or_none`] writes them, but added one at a time, so that only one of them
/// is in memory at once: [`AllOrNone::add`] writes a file to its temporary name, [`AllOrNone::commit`] renames
/// them all into place (or none). Dropped without a commit (an error on the way), it removes its temporary files
/// and no destination is touched.
#[derive(Debug, Default)]
pub struct AllOrNone {
    /// (temporary file, destination), in the order added.
    staged: Vec<(PathBuf, PathBuf)>,
}

impl AllOrNone {
    /// An empty set.
    pub fn new() -> Self {
        AllOrNone::default()
    }

    /// Writes `bytes` to `path`'s temporary file (flushed to disk); `path` itself is written at the commit.
    ///
    /// # Errors
    /// [`Error::Io`] naming `path`, or [`Error::Output`] for a file above the file-size limit (`ulimit -f`); the
    /// set should then be dropped.
    pub fn add(&mut self, path: &Path, bytes: &[u8]) -> Result<()> {
        check_file_size_limit(path, bytes.len() as u64)?;
        let tmp = stage(path, |file| file.write_all(bytes).map_err(|e| Error::io(path, e)))?;
        self.staged.push((tmp, path.to_path_buf()));
        Ok(())
    }

    /// Renames every file into place (see [`write_all_or_none`] for what a failed rename undoes).
    ///
    /// # Errors
    /// [`Error::Io`] or [`Error::Output`] naming the file whose rename failed.
    pub fn commit(mut self) -> Result<()> {
        let staged = std::mem::take(&mut self.staged);
        commit_staged(&staged)
    }
}

impl Drop for AllOrNone {
    fn drop(&mut self) {
        let mut held = crate::cleanup::hold();
        for (tmp, _) in &self.staged {
            let _ = std::fs::remove_file(tmp);
            held.forget(tmp);
        }
    }
}

/// Renames staged files (temporary name, destination) into place, all or none.
fn commit_staged(staged: &[(PathBuf, PathBuf)]) -> Result<()> {
    // How to undo each rename: remove the new file (there was none), or put the old one back (kept by a hard link
    // under a hidden name; `None` when it could not be kept, and the new file then stays).
    enum Undo {
        Remove,
        Restore(Option<PathBuf>),
    }
    // The renames happen with the registry of what a signal removes held: a signal waits until all are done or
    // undone, so it never leaves some of the files renamed.
    let mut held = crate::cleanup::hold();
    let mut done: Vec<(&Path, Undo)> = Vec::with_capacity(staged.len());
    for (i, (tmp, path)) in staged.iter().enumerate() {
        let undo = match std::fs::symlink_metadata(path) {
            Err(_) => Undo::Remove,
            Ok(_) => {
                let keep = temp_path(path);
                Undo::Restore(std::fs::hard_link(path, &keep).is_ok().then_some(keep))
            }
        };
        let renamed = check_replaceable(path).and_then(|()| std::fs::rename(tmp, path).map_err(|e| Error::io(path, e)));
        if let Err(e) = renamed {
            staged[i..].iter().for_each(|(tmp, _)| drop(std::fs::remove_file(tmp)));
            if let Undo::Restore(Some(keep)) = &undo {
                let _ = std::fs::remove_file(keep);
            }
            for (done_path, undo) in done.into_iter().rev() {
                let _ = match undo {
                    Undo::Remove => std::fs::remove_file(done_path),
                    Undo::Restore(Some(keep)) => std::fs::rename(keep, done_path),
                    Undo::Restore(None) => Ok(()),
                };
            }
            staged.iter().for_each(|(tmp, _)| held.forget(tmp));
            return Err(e);
        }
        done.push((path, undo));
    }
    for (_, undo) in done {
        if let Undo::Restore(Some(keep)) = undo {
            let _ = std::fs::remove_file(keep);
        }
    }
    staged.iter().for_each(|(tmp, _)| held.forget(tmp));
    Ok(())
}

/// Refuses to replace `path` when it exists (through symbolic links) and is not a regular file: a rename would
/// put a plain file in the place of a device, a FIFO or a socket. Writing into one instead (`-o /dev/stdout`) is
/// not done either: a stream cannot be written all or none.
///
/// # Errors
/// [`Error::Output`] naming the path and what it is.
pub fn check_replaceable(path: &Path) -> Result<()> {
    let Ok(meta) = std::fs::metadata(path) else { return Ok(()) };
    if meta.is_file() {
        return Ok(());
    }
    if meta.is_dir() {
        return Err(Error::output_at(path, "is a folder; an output must be a file name"));
    }
    Err(Error::output_at(
        path,
        format!("is {}, not a regular file; jem writes only regular files and will not replace it", file_kind(&meta)),
    ))
}

/// What a file that is not a regular file or a folder is, in words.
pub(crate) fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    let _ = meta;
    "a special file"
}

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, flushed, then renamed.
///
/// # Errors
/// [`Error::Io`] naming `path` (the temporary file is removed on failure); [`Error::Output`] when `path` exists and
/// is not a regular file ([`check_replaceable`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    check_file_size_limit(path, bytes.len() as u64)?;
    write_atomic_with(path, |file| file.write_all(bytes).map_err(|e| Error::io(path, e)))
}

/// Refuses, before writing, a file larger than the file-size limit: the kernel would kill the process in the
/// middle of the write (SIGXFSZ), leaving the temporary file behind.
fn check_file_size_limit(path: &Path, bytes: u64) -> Result<()> {
    match crate::process::file_size_limit() {
        Some(limit) if bytes > limit => Err(Error::output_at(
            path,
            format!("needs {bytes} bytes but the file-size limit (ulimit -f) is {limit} bytes"),
        )),
        _ => Ok(()),
    }
}

/// Like [`write_atomic`], with a closure that writes into the temporary file.
///
/// # Errors
/// Whatever `write` returns, or [`Error::Io`] naming `path`.
pub fn write_atomic_with(path: &Path, write: impl FnOnce(&mut std::fs::File) -> Result<()>) -> Result<()> {
    check_replaceable(path)?;
    let tmp = stage(path, write)?;
    // Checked again at the rename, which a signal waits for (see write_all_or_none).
    let mut held = crate::cleanup::hold();
    let renamed = check_replaceable(path).and_then(|()| std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e)));
    if renamed.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    held.forget(&tmp);
    renamed
}

/// Writes `path`'s temporary file ([`temp_path`]) with `write` and flushes it to disk; returns its name, registered
/// with [`crate::cleanup`] until the caller renames it. On any error the temporary file is removed.
fn stage(path: &Path, write: impl FnOnce(&mut std::fs::File) -> Result<()>) -> Result<PathBuf> {
    let tmp = temp_path(path);
    // Registered before it exists: a signal removes it (after a signal, this waits until the process ends).
    crate::cleanup::hold().add_file(&tmp, None);
    let written = (|| {
        let mut file = std::fs::File::create(&tmp).map_err(|e| missing_folder(path).unwrap_or(Error::io(path, e)))?;
        write(&mut file)?;
        file.sync_all().map_err(|e| Error::io(path, e))
    })();
    match written {
        Ok(()) => Ok(tmp),
        Err(e) => {
            let mut held = crate::cleanup::hold();
            let _ = std::fs::remove_file(&tmp);
            held.forget(&tmp);
            Err(e)
        }
    }
}

/// `dir/.name.jem-tmp-<host>-<pid>-<nanoseconds>-<n>`: hidden, in the destination's folder (so the rename stays on
/// one file system), and unique per write — also between processes on different machines of a cluster that share
/// the folder (their process ids may coincide; the host, the clock and the counter keep them apart). The host and
/// pid let a later run remove what a killed one left ([`sweep_stale_temps`]).
pub(super) fn temp_path(path: &Path) -> PathBuf {
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let host = crate::process::host_name();
    path.with_file_name(format!(".{name}{TEMP_MARK}{host}-{}-{nanos}-{n}", std::process::id()))
}

/// What marks a temporary file's name ([`temp_path`]).
const TEMP_MARK: &str = ".jem-tmp-";

/// Removes the temporary files ([`temp_path`]) in `dir` that a run of this machine left when it was killed
/// (`kill -9` cannot be caught): those whose process is gone. Another machine's, and a live run's, are left alone;
/// without `/proc` nothing is removed.
#[cfg(feature = "toolkit")]
pub(crate) fn sweep_stale_temps(dir: &Path) {
    if !crate::process::proc_available() {
        return;
    }
    let mark = format!("{TEMP_MARK}{}-", crate::process::host_name());
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str().filter(|n| n.starts_with('.')) else { continue };
        let Some((_, rest)) = name.split_once(&mark) else { continue };
        let Some(pid) = rest.split('-').next().and_then(|p| p.parse::<u32>().ok()) else { continue };
        let gone = crate::process::pid_exists(pid) == Some(false);
        if gone && entry.file_type().is_ok_and(|t| t.is_file()) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}
