//! The lock that keeps a second `jem batch` out of a results folder while one writes to it (two batches
//! into one folder overwrote each other's results, both exiting 0).
//!
//! A lock is a file created atomically (`create_new`, `O_EXCL`) in the folder, holding the writer's pid, host,
//! process start time and PID namespace, and its Slurm job when it runs in one; [`ResultsLock`] removes it when the
//! run ends, and a signal that stops the run removes it too ([`crate::cleanup`]). A lock whose process is gone
//! (this host and PID namespace, and no such pid, or the pid now another process: another start time) is stale,
//! as after `kill -9`: the next run takes it over and says so. A lock of another host or another PID namespace
//! (a container), one without a namespace (written by a jem before they were recorded, whose pid may be another
//! namespace's), or one that cannot be read counts as live: the error names the file to remove if no run is going
//! on. The one exception is a rerun of the same Slurm job's same shard (a requeued job: the same job id, a higher
//! restart count), which takes over its own earlier run's lock from any host: Slurm runs a job once at a time.
//!
//! A lock file is read without following a symbolic link or waiting on a FIFO; one that is not a regular file of
//! UTF-8 text is unreadable, and named as such.
//!
//! MiddEval3 results live in the scene folders: each scene a run writes gets its own lock, `.jem-lock-ALG` (a scene
//! whose lock cannot be read fails alone; the others run). A KITTI or ETH3D results folder gets `.jem-lock`, or
//! `.jem-lock-I-of-N` for part I of N of a sharded run (the parts of one job array write disjoint files into one
//! folder): a lock of another part of the same N does not conflict; any other live one does.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use super::runner::SlurmJob;
use super::{Layout, Pair};
use crate::error::{Error, Result};
use crate::process::{pid_namespace, process_start};

/// The locks a run holds; dropping it removes them (each only while it is still this run's).
#[derive(Debug)]
pub struct ResultsLock {
    files: Vec<PathBuf>,
    token: String,
    taken_over: Vec<String>,
    refused: Vec<(PathBuf, String)>,
}

impl ResultsLock {
    /// One line per stale lock this run took over (its file and the process that is gone).
    pub fn taken_over(&self) -> &[String] {
        &self.taken_over
    }

    /// The MiddEval3 scene folders whose lock could not be read, each with the error: those scenes must fail
    /// without running; the others are locked.
    pub fn refused(&self) -> &[(PathBuf, String)] {
        &self.refused
    }
}

impl Drop for ResultsLock {
    fn drop(&mut self) {
        let mut held = crate::cleanup::hold();
        for f in &self.files {
            if lock_holds(f, &self.token) {
                let _ = std::fs::remove_file(f);
            }
            held.forget(f);
        }
    }
}

/// Who holds a lock, as its file says.
struct Holder {
    pid: u32,
    host: String,
    start: Option<u64>,
    pidns: Option<String>,
    job: Option<SlurmJob>,
    shard: Option<String>,
}

impl Holder {
    fn parse(text: &str) -> Option<Holder> {
        let field = |key: &str| text.lines().find_map(|l| l.strip_prefix(key).map(|v| v.trim().to_string()));
        Some(Holder {
            pid: field("pid ")?.parse().ok()?,
            host: field("host ")?,
            start: field("start ").and_then(|s| s.parse().ok()),
            pidns: field("pidns "),
            job: SlurmJob::parse(field),
            shard: field("shard "),
        })
    }

    /// `Some(false)` if the process is gone for sure; `None` if this process cannot tell (another host, another
    /// or an unrecorded PID namespace, no `/proc`).
    fn alive(&self) -> Option<bool> {
        if self.host != crate::process::host_name() || !crate::process::proc_available() {
            return None;
        }
        match (&self.pidns, pid_namespace()) {
            (Some(theirs), Some(ours)) if *theirs == ours => {}
            _ => return None,
        }
        match process_start(&self.pid.to_string()) {
            None => Some(false),
            Some(now) => Some(self.start.is_none_or(|s| s == now)),
        }
    }

    /// Whether this process is a later run of the Slurm job and shard that wrote the lock (see the module doc).
    fn rerun_by(&self, ours: &Identity) -> bool {
        match (&self.job, &ours.job) {
            (Some(theirs), Some(job)) => {
                theirs.id == job.id && job.restart > theirs.restart && self.shard == ours.shard
            }
            _ => false,
        }
    }

    fn describe(&self) -> String {
        format!("pid {} on {}", self.pid, if self.host.is_empty() { "an unnamed host" } else { &self.host })
    }
}

/// This run, as its locks record it.
struct Identity {
    token: String,
    job: Option<SlurmJob>,
    shard: Option<String>,
}

impl Identity {
    fn new(shard: Option<(usize, usize)>) -> Identity {
        let job = SlurmJob::from_env();
        let shard = shard.map(|(i, n)| format!("{i}/{n}"));
        let mut token = format!("pid {}\nhost {}\n", std::process::id(), crate::process::host_name());
        if let Some(s) = process_start("self") {
            token.push_str(&format!("start {s}\n"));
        }
        if let Some(ns) = pid_namespace() {
            token.push_str(&format!("pidns {ns}\n"));
        }
        if let Some(job) = &job {
            token.push_str(&job.lines());
        }
        if let Some(shard) = &shard {
            token.push_str(&format!("shard {shard}\n"));
        }
        Identity { token, job, shard }
    }
}

/// A lock file, as read.
enum LockText {
    /// There is none (removed meanwhile).
    Gone,
    /// Its text.
    Text(String),
    /// It cannot be read, and why.
    Unreadable(String),
}

/// The largest lock file read (a lock holds a few short lines).
const MAX_LOCK_BYTES: u64 = 4096;

/// Reads a lock file without following a symbolic link or waiting on a FIFO (jem makes neither).
fn read_lock(file: &Path) -> LockText {
    let meta = match std::fs::symlink_metadata(file) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return LockText::Gone,
        Err(e) => return LockText::Unreadable(e.to_string()),
        Ok(meta) => meta,
    };
    if meta.file_type().is_symlink() {
        return LockText::Unreadable("it is a symbolic link".into());
    }
    if meta.is_dir() {
        return LockText::Unreadable("it is a folder".into());
    }
    if !meta.is_file() {
        return LockText::Unreadable(format!("it is {}, not a regular file", crate::io::file_kind(&meta)));
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        // Replaced by a FIFO or a link since it was looked at: fail instead of waiting or following.
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK | libc::O_NOFOLLOW);
    }
    let file_handle = match options.open(file) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return LockText::Gone,
        Err(e) => return LockText::Unreadable(e.to_string()),
        Ok(f) => f,
    };
    if !file_handle.metadata().is_ok_and(|m| m.is_file()) {
        return LockText::Unreadable("it is not a regular file".into());
    }
    let mut bytes = Vec::new();
    if let Err(e) = file_handle.take(MAX_LOCK_BYTES + 1).read_to_end(&mut bytes) {
        return LockText::Unreadable(e.to_string());
    }
    if bytes.len() as u64 > MAX_LOCK_BYTES {
        return LockText::Unreadable(format!("it is larger than {MAX_LOCK_BYTES} bytes"));
    }
    match String::from_utf8(bytes) {
        Ok(text) => LockText::Text(text),
        Err(_) => LockText::Unreadable("it is not UTF-8 text".into()),
    }
}

/// Whether the lock `file` holds exactly `token` (is still the run's that wrote it).
pub(crate) fn lock_holds(file: &Path, token: &str) -> bool {
    matches!(read_lock(file), LockText::Text(t) if t == token)
}

/// The error for a lock that cannot be read.
fn unreadable(file: &Path, why: &str) -> Error {
    let dir = file.parent().unwrap_or(Path::new("."));
    Error::locked_at(
        file,
        format!("this lock cannot be read ({why}); remove it if no jem run is writing into {}", dir.display()),
    )
}

/// Why a lock was not taken.
enum NotTaken {
    /// Its file could not be made.
    Io(Error),
    /// It exists and cannot be read.
    Unreadable(Error),
    /// Another run holds it, or may.
    Held(Error),
}

impl NotTaken {
    fn into_error(self) -> Error {
        match self {
            NotTaken::Io(e) | NotTaken::Unreadable(e) | NotTaken::Held(e) => e,
        }
    }
}

/// Locks the results of `alg` for these pairs against a second writer (see the module doc): the scene folders of
/// MiddEval3 pairs, the results folders of the others (created if missing). `shard` is `(I, N)` for part I of N.
///
/// # Errors
/// [`Error::Locked`] naming the folder, the lock file and the run holding it when another live run (or one this
/// machine cannot check) holds a conflicting lock, or naming a KITTI/ETH3D lock that cannot be read; [`Error::Io`]
/// if a folder or lock cannot be made. No lock is kept on error. A MiddEval3 scene whose lock cannot be read is
/// no error: it is listed in [`ResultsLock::refused`].
pub fn lock_results(
    pairs: &[Pair],
    alg: &str,
    results: Option<&Path>,
    shard: Option<(usize, usize)>,
) -> Result<ResultsLock> {
    let shard = shard.filter(|&(_, n)| n > 1);
    let me = Identity::new(shard);
    let mut lock =
        ResultsLock { files: Vec::new(), token: me.token.clone(), taken_over: Vec::new(), refused: Vec::new() };
    let mut dirs = std::collections::BTreeSet::new();
    for pair in pairs {
        let (dir, scene_lock) = lock_dir(pair, alg, results);
        let name = scene_lock.unwrap_or_else(|| match shard {
            Some((i, n)) => format!(".jem-lock-{i}-of-{n}"),
            None => ".jem-lock".to_string(),
        });
        if !dirs.insert(dir.clone()) {
            continue;
        }
        crate::io::create_folder(&dir)?;
        let file = dir.join(&name);
        match acquire(&file, &me, &mut lock) {
            Ok(()) => lock.files.push(file),
            // A scene folder no file can be made in: its results cannot be written either, and that scene fails
            // alone (as it did), instead of the whole run.
            Err(NotTaken::Io(_)) if pair.layout == Layout::Middlebury => continue,
            // A scene's lock that cannot be read: that scene fails, the others run.
            Err(NotTaken::Unreadable(e)) if pair.layout == Layout::Middlebury => {
                lock.refused.push((dir, e.to_string()));
                continue;
            }
            Err(e) => return Err(e.into_error()),
        }
        if pair.layout != Layout::Middlebury {
            check_other_parts(&dir, &name, shard)?;
        }
    }
    Ok(lock)
}

/// Locks a folder that one run writes as a whole (a sequence's output folder) against a second writer: its
/// `.jem-lock`, taken over when stale, as [`lock_results`] locks a results folder.
///
/// # Errors
/// [`Error::Locked`] naming the folder, the lock file and the run holding it when another live run (or one this
/// machine cannot check) holds it, or naming a lock that cannot be read; [`Error::Io`] if the lock cannot be made.
pub fn lock_folder(dir: &Path) -> Result<ResultsLock> {
    let me = Identity::new(None);
    let mut lock =
        ResultsLock { files: Vec::new(), token: me.token.clone(), taken_over: Vec::new(), refused: Vec::new() };
    let file = dir.join(".jem-lock");
    acquire(&file, &me, &mut lock).map_err(NotTaken::into_error)?;
    lock.files.push(file);
    Ok(lock)
}

/// The live runs holding a lock on the results of `alg` for these pairs, one line each (the folder and who holds
/// it), for `jem eval`, which reads results that a batch may still be writing. Stale locks are not listed; a lock
/// this machine cannot check (another host or PID namespace) or cannot read (named, as `jem batch` names it) is.
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
            let text = match read_lock(&dir.join(&name)) {
                LockText::Gone => continue,
                LockText::Unreadable(why) => {
                    found.push(format!(
                        "{}: a run may be writing these results: its lock {name} cannot be read ({why})",
                        dir.display()
                    ));
                    continue;
                }
                LockText::Text(text) => text,
            };
            let holder = Holder::parse(&text);
            if may_be_live(holder.as_ref(), None) {
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

/// Whether the holder of a lock may still be running: unless this machine can tell it is gone, or (`me`) this
/// run is a later run of the same Slurm job and shard.
fn may_be_live(holder: Option<&Holder>, me: Option<&Identity>) -> bool {
    match holder {
        None => true,
        Some(h) => match h.alive() {
            Some(alive) => alive,
            None => !me.is_some_and(|me| h.rerun_by(me)),
        },
    }
}

/// Who holds a lock, in words.
fn who(holder: Option<&Holder>) -> String {
    holder.map_or("a run whose lock cannot be read".to_string(), |h| format!("another jem run ({})", h.describe()))
}

/// The error for a live (or unknown) holder of `file`.
fn held(file: &Path, holder: Option<&Holder>) -> Error {
    let dir = file.parent().unwrap_or(Path::new("."));
    Error::locked_at(
        dir,
        format!(
            "{} is writing these results; wait for it to end, or remove {} if no such run is going on",
            who(holder),
            file.display()
        ),
    )
}

/// Creates the lock `file` holding `me.token`, taking over a stale one (a few tries, against a race with another
/// run taking it over at the same moment).
fn acquire(file: &Path, me: &Identity, lock: &mut ResultsLock) -> std::result::Result<(), NotTaken> {
    for _ in 0..4 {
        {
            // Registered before it exists, and made whole while a signal waits: a stopped run removes it.
            let mut held = crate::cleanup::hold();
            held.add_file(file, Some(&me.token));
            match std::fs::OpenOptions::new().write(true).create_new(true).open(file) {
                Ok(mut f) => {
                    return f.write_all(me.token.as_bytes()).map_err(|e| {
                        let _ = std::fs::remove_file(file);
                        held.forget(file);
                        NotTaken::Io(Error::io(file, e))
                    });
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => held.forget(file),
                Err(e) => {
                    held.forget(file);
                    return Err(NotTaken::Io(Error::io(file, e)));
                }
            }
        }
        let text = match read_lock(file) {
            LockText::Gone => continue, // removed meanwhile: try again
            LockText::Unreadable(why) => return Err(NotTaken::Unreadable(unreadable(file, &why))),
            LockText::Text(text) => text,
        };
        let holder = Holder::parse(&text);
        if may_be_live(holder.as_ref(), Some(me)) {
            return Err(NotTaken::Held(held(file, holder.as_ref())));
        }
        // Stale: move it aside (one run wins the rename), and check that what moved is the stale lock read
        // above, not a lock another run has just made in its place; that one is put back.
        let aside = file.with_file_name(format!(".jem-stale-{}", std::process::id()));
        if std::fs::rename(file, &aside).is_err() {
            continue;
        }
        let moved = match read_lock(&aside) {
            LockText::Text(t) => t,
            _ => String::new(),
        };
        if moved != text {
            let _ = std::fs::hard_link(&aside, file);
        } else if let Some(h) = holder {
            let why = match h.alive() {
                Some(_) => "which is no longer running".to_string(),
                None => format!("an earlier run of this Slurm job ({})", h.job.as_ref().map_or("", |j| &j.id)),
            };
            lock.taken_over.push(format!("{}: took over the lock of {}, {why}", file.display(), h.describe()));
        }
        let _ = std::fs::remove_file(&aside);
    }
    Err(NotTaken::Held(Error::locked_at(file, "could not take the lock (other runs are taking it at the same time)")))
}

/// Errors if `dir` holds a live lock of another run that conflicts with this one's `own` lock: any but another
/// part of the same number of parts; or one that cannot be read.
fn check_other_parts(dir: &Path, own: &str, shard: Option<(usize, usize)>) -> Result<()> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if name == own || !is_folder_lock(&name) {
            continue;
        }
        let other = shard_part(&name);
        let compatible = matches!((shard, other), (Some((i, n)), Some((j, m))) if n == m && i != j);
        if compatible {
            continue;
        }
        let text = match read_lock(&entry.path()) {
            LockText::Gone => continue,
            LockText::Unreadable(why) => return Err(unreadable(&entry.path(), &why)),
            LockText::Text(text) => text,
        };
        let holder = Holder::parse(&text);
        if may_be_live(holder.as_ref(), None) {
            return Err(held(&entry.path(), holder.as_ref()));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run outside Slurm, unsharded.
    fn me() -> Identity {
        Identity::new(None)
    }

    fn empty_lock(me: &Identity) -> ResultsLock {
        ResultsLock { files: Vec::new(), token: me.token.clone(), taken_over: Vec::new(), refused: Vec::new() }
    }

    /// The error of `acquire`, as text.
    fn refusal(file: &Path, me: &Identity) -> String {
        match acquire(file, me, &mut empty_lock(me)) {
            Ok(()) => panic!("{} was taken", file.display()),
            Err(e) => e.into_error().to_string(),
        }
    }

    #[test]
    fn live_locks_are_refused_stale_ones_taken_over_and_only_ours_removed() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join(".jem-lock");
        let host = crate::process::host_name();
        let ns = pid_namespace().expect("this test needs /proc/self/ns/pid");
        assert!(process_start("self").is_some(), "this test needs /proc");
        let me = me();

        // Live: this process, with and without its start time; another host; unreadable.
        let start = process_start("self").unwrap();
        for text in [
            format!("pid {}\nhost {host}\nstart {start}\npidns {ns}\n", std::process::id()),
            format!("pid {}\nhost {host}\npidns {ns}\n", std::process::id()),
            "pid 1\nhost another-host.example\n".to_string(),
            String::new(),
        ] {
            std::fs::write(&file, &text).unwrap();
            let e = refusal(&file, &me);
            assert!(e.contains("is writing these results") && e.contains(".jem-lock"), "{text:?}: {e}");
            assert_eq!(std::fs::read_to_string(&file).unwrap(), text, "left alone");
        }
        // Stale: a process that is gone, or this pid with another start time (a reused pid).
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        for text in [
            format!("pid {dead}\nhost {host}\npidns {ns}\n"),
            format!("pid {}\nhost {host}\nstart {}\npidns {ns}\n", std::process::id(), start + 1),
        ] {
            std::fs::write(&file, &text).unwrap();
            let mut lock = empty_lock(&me);
            assert!(acquire(&file, &me, &mut lock).is_ok());
            assert_eq!(lock.taken_over().len(), 1, "{text:?}");
            assert_eq!(std::fs::read_to_string(&file).unwrap(), lock.token);
            lock.files.push(file.clone());
            drop(lock);
            assert!(!file.exists(), "removed at the end");
        }
        // Dropping a lock that another run has replaced meanwhile leaves that one.
        let mut lock = empty_lock(&me);
        assert!(acquire(&file, &me, &mut lock).is_ok());
        lock.files.push(file.clone());
        std::fs::write(&file, "pid 1\nhost another-host.example\n").unwrap();
        drop(lock);
        assert!(file.exists());
        assert_eq!(names_in(dir.path()), [".jem-lock"], "no file left aside");
    }

    /// A pid is another process in another PID namespace: a lock of another namespace, or of none (a jem before
    /// namespaces were recorded), cannot be checked, and counts as live even when its pid is gone here.
    #[test]
    fn a_lock_of_another_pid_namespace_or_none_counts_as_live() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join(".jem-lock");
        let host = crate::process::host_name();
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        for text in [format!("pid {dead}\nhost {host}\npidns pid:[1]\n"), format!("pid {dead}\nhost {host}\n")] {
            std::fs::write(&file, &text).unwrap();
            let e = refusal(&file, &me());
            assert!(e.contains(&format!("pid {dead}")) && e.contains("is writing these results"), "{text:?}: {e}");
            assert_eq!(std::fs::read_to_string(&file).unwrap(), text);
        }
        assert!(me().token.contains(&format!("pidns {}\n", pid_namespace().unwrap())));
    }

    /// A requeued Slurm job (same job and shard, a higher restart count) takes over its earlier run's lock on
    /// another host; the same run count, another job or another shard is refused.
    #[test]
    fn a_rerun_of_the_same_slurm_job_takes_over_its_own_lock() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join(".jem-lock-2-of-4");
        let earlier = "pid 6302\nhost node-a\npidns pid:[4026531836]\nslurm-job 77_3\nslurm-restart 0\nshard 2/4\n";
        let run = |id: &str, restart: u32, shard: &str| {
            let mut me = Identity::new(None);
            me.job = Some(SlurmJob { id: id.into(), restart });
            me.shard = Some(shard.into());
            me.token = format!("pid {}\nhost here\nslurm-job {id}\n", std::process::id());
            me
        };
        for (id, restart, shard) in [("77_3", 0, "2/4"), ("78_3", 1, "2/4"), ("77_4", 1, "2/4"), ("77_3", 1, "3/4")] {
            std::fs::write(&file, earlier).unwrap();
            let e = refusal(&file, &run(id, restart, shard));
            assert!(e.contains("pid 6302 on node-a"), "{id} {restart} {shard}: {e}");
        }
        let me = run("77_3", 1, "2/4");
        let mut lock = empty_lock(&me);
        assert!(acquire(&file, &me, &mut lock).is_ok());
        assert_eq!(std::fs::read_to_string(&file).unwrap(), me.token);
        assert!(lock.taken_over()[0].contains("an earlier run of this Slurm job (77_3)"), "{:?}", lock.taken_over());
    }

    /// A lock that is a folder, a symbolic link (dangling or not), a FIFO, not UTF-8 or too long is named as
    /// unreadable at once (a FIFO is not waited on), by `batch`'s `acquire` and by `eval`'s `writers` alike.
    #[test]
    fn unreadable_locks_are_named_not_waited_on() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join(".jem-lock-A");
        let scene = Pair {
            layout: Layout::Middlebury,
            name: "S".into(),
            root: dir.path().to_path_buf(),
            left: dir.path().join("im0.png"),
            right: dir.path().join("im1.png"),
            calib: Some(dir.path().join("calib.txt")),
        };
        type Make<'a> = &'a dyn Fn(&Path);
        let make: [(&str, Make); 6] = [
            ("it is a folder", &|f| std::fs::create_dir(f).unwrap()),
            ("symbolic link", &|f| std::os::unix::fs::symlink("nowhere", f).unwrap()),
            ("symbolic link", &|f| std::os::unix::fs::symlink("/proc/self/stat", f).unwrap()),
            ("FIFO", &|f| assert!(std::process::Command::new("mkfifo").arg(f).status().unwrap().success())),
            ("not UTF-8", &|f| std::fs::write(f, b"pid 1\nhost \xff\n").unwrap()),
            ("larger than", &|f| std::fs::write(f, "pid 1\n".repeat(1000)).unwrap()),
        ];
        for (why, make) in make {
            make(&file);
            let e = refusal(&file, &me());
            assert!(e.contains(&*file.to_string_lossy()) && e.contains("cannot be read") && e.contains(why), "{e}");
            let listed = writers(std::slice::from_ref(&scene), "A", None);
            assert!(listed.len() == 1 && listed[0].contains(".jem-lock-A cannot be read") && listed[0].contains(why));
            // In a batch, that scene is refused; the run goes on.
            let lock = lock_results(std::slice::from_ref(&scene), "A", None, None).unwrap();
            assert!(lock.refused().len() == 1 && lock.refused()[0].1.contains(why), "{:?}", lock.refused());
            drop(lock);
            match std::fs::symlink_metadata(&file).unwrap().is_dir() {
                true => std::fs::remove_dir(&file).unwrap(),
                false => std::fs::remove_file(&file).unwrap(),
            }
        }
    }

    fn names_in(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        names.sort();
        names
    }
}
