//! Which data set a KITTI or ETH3D results folder holds ([`SOURCE_FILE`]), so that results are never mixed and
//! a moved or copied tree still evaluates.
//!
//! The file names the layout, the data set's folder relative to the results folder (both with links resolved),
//! and a fingerprint of the data set: its pair names and the byte sizes of their images (metadata only; KITTI's
//! training and testing frames share names but not sizes). A results folder holds a data set's results when the
//! layouts agree and either the recorded folder is the data set's folder, or the fingerprints agree (the data set
//! was moved or copied away from its results). Anything else is refused. A file of an older jem, with an
//! absolute `root` and no fingerprint, still matches its folder.

use std::path::{Component, Path, PathBuf};

use super::{Discovery, Pair, Purpose, SOURCE_FILE, discover};
use crate::error::{Error, Result};

/// The largest [`SOURCE_FILE`] read (it holds three short lines).
const MAX_SOURCE_BYTES: u64 = 64 << 10;

/// What a results folder's [`SOURCE_FILE`] says for `pair`'s data set, written from the results folder `dir`.
fn source_text(pair: &Pair, dir: &Path) -> String {
    let root = std::fs::canonicalize(&pair.root).unwrap_or_else(|_| pair.root.clone());
    let rel = std::fs::canonicalize(dir).map_or_else(|_| root.clone(), |d| relative_path(&d, &root));
    format!("layout {}\nroot {}\ndata {}\n", pair.layout.name(), rel.display(), fingerprint(pair))
}

/// The pairs of `pair`'s data set, and FNV-1a (64 bits) over their names and image sizes in bytes (0 for a
/// missing image), as `N pairs, fingerprint HEX`.
fn fingerprint(pair: &Pair) -> String {
    let how = Discovery { layout: Some(pair.layout), gt: None };
    let pairs = discover(std::slice::from_ref(&pair.root), Purpose::Run, &how).unwrap_or_default();
    let mut hash = crate::rng::FNV_OFFSET;
    let mut add = |bytes: &[u8]| hash = crate::rng::fnv1a(hash, bytes);
    for p in &pairs {
        add(p.name.as_bytes());
        for image in [&p.left, &p.right] {
            add(&[0]);
            add(&std::fs::metadata(image).map_or(0, |m| m.len()).to_le_bytes());
        }
        add(&[0xff]);
    }
    format!("{} pairs, fingerprint {hash:016x}", pairs.len())
}

/// `to` relative to `from` (both absolute, links resolved): `..` up to their common ancestor, then down.
fn relative_path(from: &Path, to: &Path) -> PathBuf {
    let (a, b): (Vec<Component>, Vec<Component>) = (from.components().collect(), to.components().collect());
    let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut rel: PathBuf = std::iter::repeat_n(Component::ParentDir, a.len() - common).collect();
    rel.extend(&b[common..]);
    if rel.as_os_str().is_empty() { PathBuf::from(".") } else { rel }
}

/// `path` with `.` and `name/..` removed lexically (for messages).
fn tidy(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir if matches!(out.components().next_back(), Some(Component::Normal(_))) => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// How a results folder's [`SOURCE_FILE`] matched a data set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Match {
    /// It names the data set's folder.
    Folder,
    /// It names another folder (or none that exists), but the fingerprints agree: the data set was moved or
    /// copied.
    Fingerprint,
}

/// Why a results folder's [`SOURCE_FILE`] does not match a data set.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Mismatch {
    /// It names another data set (its folder, tidied for messages), and whether that folder still exists.
    Other(String, bool),
    /// It is not a source file jem wrote: why.
    Malformed(String),
}

/// Whether the [`SOURCE_FILE`] text `have` of the results folder `dir` is `pair`'s data set (see the module doc),
/// and how it matched.
fn holds(have: &str, pair: &Pair, dir: &Path) -> std::result::Result<Match, Mismatch> {
    let field = |key: &str| have.lines().find_map(|l| l.strip_prefix(key).map(str::trim));
    let layout = match field("layout ") {
        None | Some("") => return Err(Mismatch::Malformed("no layout line".into())),
        Some(l) => l,
    };
    if layout.parse::<super::Layout>().is_err() {
        return Err(Mismatch::Malformed(format!("unknown layout {layout:?}")));
    }
    let named = match field("root ") {
        None | Some("") => return Err(Mismatch::Malformed("no root line".into())),
        Some(root) if Path::new(root).is_absolute() => PathBuf::from(root),
        Some(root) => std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf()).join(root),
    };
    let other = || Mismatch::Other(tidy(&named).display().to_string(), named.exists());
    if layout != pair.layout.name() {
        return Err(other());
    }
    if let Ok(root) = std::fs::canonicalize(&pair.root)
        && std::fs::canonicalize(&named).is_ok_and(|n| n == root)
    {
        return Ok(Match::Folder);
    }
    match field("data ") {
        Some(data) if data == fingerprint(pair) => Ok(Match::Fingerprint),
        _ => Err(other()),
    }
}

/// Checks that the results folders of `alg` for these pairs are free for them: no folder is claimed by two data
/// sets, none holds another data set's results (its [`SOURCE_FILE`] names another, see the module doc) or has a
/// source file that cannot be read, none lies inside a data set's folder, and no results of the data set wait in
/// the folder an older jem used (`RES/NAME/`, before each split had its own). With `claim`, creates the folders and
/// writes the missing source files, and rewrites (atomically) those that found their data set by its fingerprint
/// only, so that they name where it is now: after a move, the data set may grow (and its fingerprint change)
/// without its results being taken for another's.
///
/// # Errors
/// [`Error::Output`] naming the folder and the data sets, or the source file and what is wrong with it;
/// [`Error::Io`] if a folder or file cannot be made or a source file cannot be read.
pub fn check_results_dirs(pairs: &[Pair], alg: &str, results: Option<&Path>, claim: bool) -> Result<()> {
    let mut claimed: std::collections::BTreeMap<PathBuf, (&Pair, bool)> = Default::default();
    for pair in pairs {
        let Some(dir) = pair.results_dir(alg, results) else { continue };
        match claimed.get(&dir) {
            Some((other, _)) if other.root != pair.root => {
                return Err(Error::output_at(
                    &dir,
                    format!(
                        "the results of {} and of {} would share this folder (same frame names); run them one at a \
                     time with different --alg or --results",
                        other.root.display(),
                        pair.root.display()
                    ),
                ));
            }
            Some(_) => continue,
            None => {}
        }
        crate::io::check_folder_name(&dir)?;
        if let (Ok(d), Ok(r)) = (resolve_to_existing(&dir), std::fs::canonicalize(&pair.root))
            && d.starts_with(&r)
        {
            return Err(Error::output_at(
                &dir,
                format!(
                    "results would go inside the data set {} (never written to); choose another --results",
                    pair.root.display()
                ),
            ));
        }
        // Results of this data set where a jem before per-split folders put them (`RES/NAME/`): say where they
        // are, rather than report every result missing, or compute them all again beside them.
        if let Some(old) = dir.parent()
            && !dir.exists()
            && let Ok(have) = crate::io::read_capped(&old.join(SOURCE_FILE), MAX_SOURCE_BYTES, SOURCE_FILE)
            && holds(&String::from_utf8_lossy(&have), pair, old).is_ok()
        {
            return Err(Error::output_at(
                old,
                format!(
                    "holds results of {} written by an older jem, which put them there; move its {SOURCE_FILE} and \
                 result folders into {} (each split now has its own folder)",
                    pair.root.display(),
                    dir.display()
                ),
            ));
        }
        let source = dir.join(SOURCE_FILE);
        let moved = match crate::io::read_capped(&source, MAX_SOURCE_BYTES, SOURCE_FILE) {
            Err(Error::Io { source: e, .. }) if e.kind() == std::io::ErrorKind::NotFound => false,
            Err(e) => return Err(e),
            Ok(have) => match holds(&String::from_utf8_lossy(&have), pair, &dir) {
                Ok(how) => how == Match::Fingerprint,
                Err(Mismatch::Malformed(why)) => {
                    return Err(Error::output_at(
                        &source,
                        format!(
                            "unreadable ({why}), not a {SOURCE_FILE} jem wrote: it should name the data set whose \
                         results this folder holds; if they are {}'s, remove it and run again",
                            pair.root.display()
                        ),
                    ));
                }
                Err(Mismatch::Other(other, true)) => {
                    return Err(Error::output_at(
                        &dir,
                        format!(
                            "holds the results of {other}, not of {} (see {SOURCE_FILE}); choose another --alg or \
                         --results",
                            pair.root.display()
                        ),
                    ));
                }
                Err(Mismatch::Other(other, false)) => {
                    return Err(Error::output_at(
                        &dir,
                        format!(
                            "holds the results of {other}, which no longer exists, and the data sets differ (see \
                         {SOURCE_FILE}); if {} is that data set, moved and changed since, remove {} and run again; \
                         otherwise choose another --alg or --results",
                            pair.root.display(),
                            source.display()
                        ),
                    ));
                }
            },
        };
        claimed.insert(dir, (pair, moved));
    }
    // Everything checked: only now is anything made.
    for (dir, (pair, moved)) in claimed.iter().filter(|_| claim) {
        let source = dir.join(SOURCE_FILE);
        if *moved || !source.is_file() {
            crate::io::create_folder(dir)?;
            crate::io::write_atomic(&source, source_text(pair, dir).as_bytes())?;
        }
    }
    Ok(())
}

/// The canonical form of `path`, or of its nearest existing ancestor joined with the rest.
fn resolve_to_existing(path: &Path) -> std::io::Result<PathBuf> {
    let mut rest = Vec::new();
    let mut cur = path.to_path_buf();
    loop {
        if let Ok(c) = std::fs::canonicalize(&cur) {
            return Ok(rest.iter().rev().fold(c, |acc: PathBuf, part: &std::ffi::OsString| acc.join(part)));
        }
        match (cur.file_name().map(|n| n.to_os_string()), cur.parent()) {
            (Some(name), Some(parent)) => {
                rest.push(name);
                cur = if parent.as_os_str().is_empty() { PathBuf::from(".") } else { parent.to_path_buf() };
            }
            _ => return std::fs::canonicalize(path),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths() {
        let rel = |a: &str, b: &str| relative_path(Path::new(a), Path::new(b));
        assert_eq!(rel("/d/k/results/A/training", "/d/k/training"), Path::new("../../../training"));
        assert_eq!(rel("/r/A/training", "/d/k/training"), Path::new("../../../d/k/training"));
        assert_eq!(rel("/d", "/d"), Path::new("."));
        assert_eq!(tidy(Path::new("/r/A/x/../../../d/./k")), Path::new("/d/k"));
    }
}
