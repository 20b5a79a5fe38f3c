//! Writing a sequence folder ([`write_sequence`]): frames made one at a time, the whole folder published at the
//! end or not at all.

use std::path::{Path, PathBuf};

use super::FOLDERS;
use crate::dataset::{CALIB_FILE, GT_FILE, LEFT_FILE, RIGHT_FILE};
use crate::error::{Error, Result};
use crate::image::{DisparityMap, Plane, RgbImage};

/// One frame to write: its views and, optionally, its ground truth and occlusion mask.
#[derive(Clone, Debug, PartialEq)]
pub struct SequenceFrame {
    /// Left view (8-bit values stored as `f32`).
    pub left: RgbImage,
    /// Right view.
    pub right: RgbImage,
    /// The left view's disparity (`gt/<stem>.pfm`).
    pub gt: Option<DisparityMap>,
    /// Its MiddEval3 mask (`mask/<stem>.png`: 255 non-occluded, 128 occluded, 0 no ground truth).
    pub mask: Option<Plane<u8>>,
}

/// The files a sequence may have at its root besides its folders: [`write_sequence`] writes no others.
pub const ROOT_FILES: [&str; 3] = [CALIB_FILE, "made.txt", "truth.txt"];

/// Names in a folder that say it holds a scene or a sequence already: [`write_sequence`] refuses such a folder.
const TAKEN: [&str; 10] =
    ["left", "right", "gt", "mask", CALIB_FILE, "made.txt", "truth.txt", LEFT_FILE, RIGHT_FILE, GT_FILE];

/// Writes a sequence of `count` frames into `out` (created if missing): `left/<stem>.png`, `right/<stem>.png`,
/// `gt/<stem>.pfm` and `mask/<stem>.png` when the frames have them, then each `(name, text)` that `files` returns
/// (called once all frames are made; the names among [`ROOT_FILES`]) at the root. Frame `k` is made by `frame(k)`
/// when it is written, so one frame is in memory at a time; its stem is `k` zero-padded to six digits.
///
/// Everything is written into a hidden temporary folder inside `out` and moved into place at the end: a failed
/// or interrupted run leaves no part of a sequence (a temporary folder a killed run left is removed by the next
/// run into `out`). Returns the stems written.
///
/// # Errors
/// [`Error::Output`] when `out` is a file or already holds a scene or a sequence (`left/`, `calib.txt`, `im0.png`,
/// …), [`Error::Dataset`] when the frames differ in what they carry; whatever `frame` returns; [`Error::Io`] /
/// [`Error::Image`] naming the file that could not be written.
///
/// # Panics
/// If `files` names a file outside [`ROOT_FILES`].
pub fn write_sequence(
    out: &Path,
    count: usize,
    frame: &mut dyn FnMut(usize) -> Result<SequenceFrame>,
    files: &mut dyn FnMut() -> Vec<(&'static str, String)>,
) -> Result<Vec<String>> {
    if out.exists() && !out.is_dir() {
        return Err(Error::output_at(out, "exists and is not a folder; give the name of a folder (a new one is made)"));
    }
    let taken = TAKEN.iter().find(|n| out.join(n).exists());
    if let Some(name) = taken {
        return Err(Error::output_at(
            out,
            format!("already holds a scene or a sequence ({name}); refusing to write into it"),
        ));
    }
    let created = !out.exists();
    crate::io::create_folder(out)?;
    let prefix = format!(".jem-tmp-{}-", crate::process::host_name());
    crate::degrade::sweep_stale(out, &prefix);
    let tmp = out.join(format!("{prefix}{}", std::process::id()));
    let result = (|| {
        let stems = write_frames(&tmp, count, frame)?;
        for (name, text) in files() {
            assert!(ROOT_FILES.contains(&name), "{name} is not a sequence's root file");
            crate::io::write_atomic(&tmp.join(name), text.as_bytes())?;
        }
        publish(&tmp, out)?;
        Ok(stems)
    })();
    let _ = std::fs::remove_dir_all(&tmp);
    if result.is_err() && created {
        let _ = std::fs::remove_dir(out);
    }
    result
}

/// The stem of frame `k`.
pub(crate) fn frame_stem(k: usize) -> String {
    format!("{k:06}")
}

/// Writes the frames into the folders of `tmp`.
fn write_frames(
    tmp: &Path,
    count: usize,
    frame: &mut dyn FnMut(usize) -> Result<SequenceFrame>,
) -> Result<Vec<String>> {
    let mut carries = None;
    let mut stems = Vec::with_capacity(count);
    for k in 0..count {
        let f = frame(k)?;
        let has = (f.gt.is_some(), f.mask.is_some());
        if *carries.get_or_insert(has) != has {
            return Err(Error::dataset(format!("frame {k} carries other ground truth than the first frame")));
        }
        if k == 0 {
            let folders = FOLDERS.iter().zip([true, true, has.0, has.1]).filter(|(_, on)| *on);
            for (folder, _) in folders {
                let dir = tmp.join(folder);
                std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
            }
        }
        let stem = frame_stem(k);
        let (w, h) = f.left.dims();
        for (folder, view) in [(FOLDERS[0], &f.left), (FOLDERS[1], &f.right)] {
            let path = tmp.join(folder).join(format!("{stem}.png"));
            crate::io::png::write_rgb8_png(&path, w, h, &crate::synth::interleave_rgb8(view))?;
        }
        if let Some(gt) = &f.gt {
            crate::io::pfm::write_pfm(&tmp.join(FOLDERS[2]).join(format!("{stem}.pfm")), gt)?;
        }
        if let Some(mask) = &f.mask {
            let path = tmp.join(FOLDERS[3]).join(format!("{stem}.png"));
            crate::io::write_atomic(&path, &crate::synth::encode_mask_png(&path, mask)?)?;
        }
        stems.push(stem);
    }
    Ok(stems)
}

/// Moves every entry of `tmp` into `out` (which holds none of their names): all of them, or, when a move fails,
/// none (the ones moved are moved back).
fn publish(tmp: &Path, out: &Path) -> Result<()> {
    let mut names: Vec<PathBuf> = std::fs::read_dir(tmp)
        .map_err(|e| Error::io(tmp, e))?
        .map(|e| e.map(|e| PathBuf::from(e.file_name())).map_err(|e| Error::io(tmp, e)))
        .collect::<Result<_>>()?;
    names.sort();
    for (i, name) in names.iter().enumerate() {
        let (from, to) = (tmp.join(name), out.join(name));
        let moved = if to.exists() {
            Err(std::io::Error::new(std::io::ErrorKind::AlreadyExists, "appeared while the sequence was written"))
        } else {
            std::fs::rename(&from, &to)
        };
        if let Err(e) = moved {
            for done in &names[..i] {
                let _ = std::fs::rename(out.join(done), tmp.join(done));
            }
            return Err(Error::io(&to, e));
        }
    }
    Ok(())
}
