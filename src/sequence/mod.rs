//! Stereo sequences as data: a folder of rectified frame pairs in time order, with optional per-frame ground truth.
//!
//! # Layouts ([`Sequence::open`])
//! | layout | the folder holds | frames | calibration |
//! |---|---|---|---|
//! | folders | `left/` and `right/` | the images in each, paired by file stem, in sorted order | `calib.txt` (Middlebury keys) at the root, optional |
//! | KITTI raw | `image_02/data/` and `image_03/data/` (a `*_sync` drive folder) | as above | none read (KITTI keeps `calib_cam_to_cam.txt` one level up, without a search range) |
//!
//! Images are PNG, PPM/PGM/PNM, JPEG, BMP, TIFF or WebP (by extension, any case: every format `jem match` reads);
//! other files and hidden ones (`.name`) are not frames. A frame's stem (the file name without its extension)
//! names it, and its result (`OUTDIR/<stem>.pfm`).
//! The left and right folders must hold the same stems: unequal counts, a stem without a partner, or two images
//! of one stem in a folder are refused with one line naming the folder. Frames are in the byte order of their
//! stems, so stems should be zero-padded (`000009` before `000010`), as the benchmarks' are.
//!
//! Ground truth, optional, in the folders layout: `gt/<stem>.pfm` (the left view's disparity, `inf` = unknown),
//! and `mask/<stem>.png` (MiddEval3 `mask0nocc.png` values: 255 non-occluded, 128 occluded, 0 no ground truth).
//! A frame without them has none; [`crate::eval::sequence`] scores the frames that have them.
//!
//! # The search range
//! [`Sequence::ndisp_source`] is `jem match`'s rule applied to the sequence: `--ndisp`, else the `ndisp` of the
//! root's `calib.txt` (a stated range, measured instead when it is no real bound), else none (measured).
//! [`run()`] applies it to every frame alone, which keeps each frame's map identical to `jem match` on that pair;
//! [`RangeRule::FirstFrame`] instead measures once on the first frame and holds that range for the sequence (a
//! model that carries state between frames needs one range throughout).
//!
//! # Files of this module
//! `mod.rs` (recognising a sequence folder), `run.rs` (matching every frame alone into an output folder, resumable),
//! `write.rs` (writing a sequence folder all or none), `make.rs` (sequences made from one scene: fresh noise per
//! frame, a window sliding across the pair).

mod make;
mod run;
mod write;

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::setup::NdispSource;

pub use make::{FromScene, frame_seed, sequence_from_scene};
pub use run::{
    CONFIG_FILE, Event, FrameRun, RUN_FILE, RangeRule, RunOptions, RunSummary, TIMES_FILE, recorded_source, run,
};
pub(crate) use write::frame_stem;
pub use write::{ROOT_FILES, SequenceFrame, write_sequence};

/// The image extensions a frame may have (compared without case).
pub const IMAGE_EXTENSIONS: [&str; 10] = ["png", "ppm", "pgm", "pnm", "jpg", "jpeg", "bmp", "tif", "tiff", "webp"];

/// The folders of the folders layout: left and right views, ground truth, masks.
pub const FOLDERS: [&str; 4] = ["left", "right", "gt", "mask"];

/// KITTI raw's left and right colour camera folders.
const KITTI_RAW: [&str; 2] = ["image_02/data", "image_03/data"];

/// How a sequence folder is laid out (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SequenceLayout {
    /// `left/`, `right/`, optional `gt/`, `mask/` and `calib.txt`.
    Folders,
    /// KITTI raw: `image_02/data/`, `image_03/data/`.
    KittiRaw,
}

impl SequenceLayout {
    /// The name reports print.
    pub fn name(self) -> &'static str {
        match self {
            SequenceLayout::Folders => "left/ + right/",
            SequenceLayout::KittiRaw => "KITTI raw",
        }
    }
}

/// One frame: its stem and files.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame {
    /// The file stem shared by its images (`000042`).
    pub stem: String,
    /// Left image.
    pub left: PathBuf,
    /// Right image.
    pub right: PathBuf,
    /// `gt/<stem>.pfm`, when it exists.
    pub gt: Option<PathBuf>,
    /// `mask/<stem>.png`, when it exists.
    pub mask: Option<PathBuf>,
}

/// A recognised sequence folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Sequence {
    /// The folder.
    pub root: PathBuf,
    /// Its layout.
    pub layout: SequenceLayout,
    /// The frames in time (sorted stem) order; never empty.
    pub frames: Vec<Frame>,
    /// `calib.txt` at the root, when it exists (folders layout).
    pub calib: Option<PathBuf>,
}

impl Sequence {
    /// Whether `dir` looks like a sequence folder (both view folders of a layout exist); [`Sequence::open`] says
    /// what is wrong with one that does not open.
    pub fn recognise(dir: &Path) -> Option<SequenceLayout> {
        let both = |l: &str, r: &str| dir.join(l).is_dir() && dir.join(r).is_dir();
        if both(FOLDERS[0], FOLDERS[1]) {
            Some(SequenceLayout::Folders)
        } else if both(KITTI_RAW[0], KITTI_RAW[1]) {
            Some(SequenceLayout::KittiRaw)
        } else {
            None
        }
    }

    /// Reads the sequence folder `dir` (see the module doc).
    ///
    /// # Errors
    /// [`Error::Dataset`] naming the folder when it is no sequence, a view folder holds no frame, the views' frames
    /// do not pair, or a folder holds two images of one stem; [`Error::Io`] for an unreadable folder.
    pub fn open(dir: &Path) -> Result<Sequence> {
        let Some(layout) = Sequence::recognise(dir) else {
            return Err(Error::dataset_at(
                dir,
                "not a stereo sequence (expected left/ and right/ folders of frames, or KITTI raw's image_02/data \
                 and image_03/data)",
            ));
        };
        let (l, r) = match layout {
            SequenceLayout::Folders => (FOLDERS[0], FOLDERS[1]),
            SequenceLayout::KittiRaw => (KITTI_RAW[0], KITTI_RAW[1]),
        };
        let (left, right) = (list_images(&dir.join(l))?, list_images(&dir.join(r))?);
        if left.is_empty() {
            let formats = crate::io::png::IMAGE_FORMATS;
            return Err(Error::dataset_at(&dir.join(l), format!("no frames ({formats} images)")));
        }
        if left.len() != right.len() {
            return Err(Error::dataset_at(
                dir,
                format!("{l}/ holds {} frames but {r}/ holds {}; frames pair by name", left.len(), right.len()),
            ));
        }
        if let Some(((ls, lp), (rs, rp))) = left.iter().zip(&right).find(|((ls, _), (rs, _))| ls != rs) {
            let (missing, folder) = if ls < rs { (lp, r) } else { (rp, l) };
            let name = missing.file_name().unwrap_or_default().to_string_lossy();
            let stem = if ls < rs { ls } else { rs };
            return Err(Error::dataset_at(
                dir,
                format!("frame {name} has no partner named {stem}.* in {folder}/; frames pair by name"),
            ));
        }
        let in_folder = |folder: &str, stem: &str, ext: &str| {
            let p = dir.join(folder).join(format!("{stem}.{ext}"));
            (layout == SequenceLayout::Folders && p.is_file()).then_some(p)
        };
        let frames = left
            .into_iter()
            .zip(right)
            .map(|((stem, left), (_, right))| Frame {
                gt: in_folder(FOLDERS[2], &stem, "pfm"),
                mask: in_folder(FOLDERS[3], &stem, "png"),
                stem,
                left,
                right,
            })
            .collect();
        let calib =
            Some(dir.join(crate::dataset::CALIB_FILE)).filter(|c| layout == SequenceLayout::Folders && c.is_file());
        Ok(Sequence { root: dir.to_path_buf(), layout, frames, calib })
    }

    /// Where the range comes from, as `jem match` takes it: `given` (`--ndisp`, or a matcher's
    /// [`crate::Matcher::ndisp`]) unless it is [`NdispSource::Unknown`], else the `ndisp` of the root's `calib.txt`
    /// ([`NdispSource::Stated`]), else [`NdispSource::Unknown`] (also for a `calib.txt` that states no `ndisp`:
    /// geometry only).
    ///
    /// # Errors
    /// [`Error::Calib`] for a `calib.txt` whose `ndisp` is not a positive integer (when it is read).
    pub fn ndisp_source(&self, given: NdispSource) -> Result<NdispSource> {
        let (NdispSource::Unknown, Some(c)) = (given, &self.calib) else { return Ok(given) };
        let calib = crate::io::calib::Calib::load(c)?;
        Ok(NdispSource::resolve(None, calib.stated_ndisp()?))
    }

    /// Whether any frame has ground truth.
    pub fn has_ground_truth(&self) -> bool {
        self.frames.iter().any(|f| f.gt.is_some())
    }
}

/// Whether `path` has an image extension ([`IMAGE_EXTENSIONS`]).
fn is_image(path: &Path) -> bool {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    ext.is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.as_str()))
}

/// The images of `folder` as `(stem, path)`, sorted by stem.
///
/// # Errors
/// [`Error::Io`] for an unreadable folder, [`Error::Dataset`] for two images of one stem or a stem holding a control
/// character.
fn list_images(folder: &Path) -> Result<Vec<(String, PathBuf)>> {
    let entries = std::fs::read_dir(folder).map_err(|e| Error::io(folder, e))?;
    let mut frames: Vec<(String, PathBuf)> = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(folder, e))?;
        let path = entry.path();
        let hidden = entry.file_name().to_string_lossy().starts_with('.');
        if hidden || !is_image(&path) || !path.is_file() {
            continue;
        }
        let Some(stem) = path.file_stem().and_then(|s| s.to_str()).map(str::to_owned) else { continue };
        if stem.chars().any(char::is_control) {
            // A line break in a frame's name would split its line of times.txt (and of every report) in two.
            return Err(Error::dataset_at(
                folder,
                format!("frame {:?} has a control character (a line break?) in its name; rename the file", stem),
            ));
        }
        frames.push((stem, path));
    }
    frames.sort();
    if let Some(pair) = frames.windows(2).find(|p| p[0].0 == p[1].0) {
        let name = |p: &Path| p.file_name().unwrap_or_default().to_string_lossy().into_owned();
        return Err(Error::dataset_at(
            folder,
            format!("two images of frame {} ({} and {})", pair[0].0, name(&pair[0].1), name(&pair[1].1)),
        ));
    }
    Ok(frames)
}

#[cfg(test)]
mod tests;
