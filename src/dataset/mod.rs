//! Benchmark folder layouts: where a data set keeps its pairs and ground truth, and where jem puts its results.
//!
//! `jem batch` and `jem eval` take any folder and find the data sets in it ([`discover`]); each stereo pair
//! becomes a [`Pair`] that knows its [`Layout`]. Four layouts, recognised by their folder names:
//!
//! | layout | a folder holding | pairs | ground truth | results of `--alg NAME` |
//! |---|---|---|---|---|
//! | MiddEval3 | `im0.png`, `im1.png`, `calib.txt` (one scene) | the scene | `disp0GT.pfm`, `mask0nocc.png` in the scene | `disp0NAME.pfm`, `timeNAME.txt` in the scene (the MiddEval3 submission layout) |
//! | KITTI 2015 | `image_2/`, `image_3/` | `image_2/NNNNNN_10.png` + `image_3/…` | `disp_noc_0/`, `disp_occ_0/` | `RES/NAME/SPLIT/disp_0/NNNNNN_10.png` |
//! | KITTI 2012 | `colored_0/`, `colored_1/` (or grey `image_0/`, `image_1/`) | `*_10.png` | `disp_noc/`, `disp_occ/` | as 2015 |
//! | ETH3D two-view | scene folders as MiddEval3, in a folder named `two_view_*` or with a sibling `<name>_gt/` | each scene | `<name>_gt/SCENE/disp0GT.pfm`, `mask0nocc.png` | `RES/NAME/SPLIT/low_res_two_view/SCENE.pfm` and `SCENE.txt` (`runtime <s>`) |
//!
//! `RES` is `--results DIR` when given, else the folder `results/` beside the data set's folder (for
//! `kitti/training/`, `kitti/results/`); `SPLIT` is the data set's folder name (`training`, `testing`), so a
//! training and a test split, which share frame names, never share a results folder. KITTI and ETH3D results are
//! in the benchmarks' submission forms (KITTI: 16-bit PNG, disparity × 256, 0 = invalid; its per-frame run times
//! go to `RES/NAME/SPLIT/time/FRAME.txt`), and are never written inside the data set's folder. A results folder
//! records which data set it holds ([`SOURCE_FILE`], relative to itself and by a fingerprint, so the two can
//! move); results of another data set under the same name are refused instead of mixed. While `jem batch` writes
//! results, a lock keeps a second writer out ([`lock_results`]).
//!
//! A MiddEval3 scene and an ETH3D scene look the same; the folder around it decides, or `--layout`.

mod kitti;
mod lock;
mod results;
mod runner;
pub mod walk;

use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::error::{Error, Result};

pub(crate) use lock::lock_holds;
pub use lock::{ResultsLock, lock_folder, lock_results, writers};
pub use results::check_results_dirs;

/// The search range of a KITTI frame when nothing else gives one (0..191, the usual choice for KITTI).
pub const KITTI_NDISP: usize = 192;

/// The file in a results folder that names the data set whose results it holds.
pub const SOURCE_FILE: &str = "source.txt";

/// A MiddEval3 scene's left view (ETH3D's two-view scenes name their files as MiddEval3's).
pub const LEFT_FILE: &str = "im0.png";

/// A MiddEval3 scene's right view.
pub const RIGHT_FILE: &str = "im1.png";

/// A MiddEval3 scene's calibration (`cam0`, `cam1`, `doffs`, `baseline`, `ndisp`, …).
pub const CALIB_FILE: &str = "calib.txt";

/// A MiddEval3 scene's ground truth of the left view.
pub const GT_FILE: &str = "disp0GT.pfm";

/// A MiddEval3 scene's mask of the left view (255 visible, 128 occluded, 0 no truth).
pub const MASK_FILE: &str = "mask0nocc.png";

/// The files that make a folder a MiddEval3 or ETH3D scene.
pub const SCENE_FILES: [&str; 3] = [LEFT_FILE, RIGHT_FILE, CALIB_FILE];

/// A benchmark's folder layout (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Layout {
    /// Middlebury 2014 (MiddEval3): one folder per scene.
    Middlebury,
    /// KITTI 2015 stereo: `image_2/`, `image_3/`, `disp_noc_0/`, `disp_occ_0/`.
    Kitti2015,
    /// KITTI 2012 stereo: `colored_0/`, `colored_1/` (or `image_0/`, `image_1/`), `disp_noc/`, `disp_occ/`.
    Kitti2012,
    /// ETH3D two-view: MiddEval3-like scene folders, ground truth in a parallel `*_gt` tree.
    Eth3d,
}

impl Layout {
    /// The name `--layout` takes and reports print.
    pub fn name(self) -> &'static str {
        match self {
            Layout::Middlebury => "middlebury",
            Layout::Kitti2015 => "kitti2015",
            Layout::Kitti2012 => "kitti2012",
            Layout::Eth3d => "eth3d",
        }
    }

    /// Whether this is one of the KITTI layouts.
    pub fn is_kitti(self) -> bool {
        matches!(self, Layout::Kitti2015 | Layout::Kitti2012)
    }
}

impl FromStr for Layout {
    type Err = Error;
    fn from_str(s: &str) -> std::result::Result<Self, Error> {
        match s {
            "middlebury" | "middeval3" => Ok(Layout::Middlebury),
            "kitti2015" => Ok(Layout::Kitti2015),
            "kitti2012" => Ok(Layout::Kitti2012),
            "eth3d" => Ok(Layout::Eth3d),
            _ => Err(Error::argument(format!(
                "unknown layout {s:?} (expected middlebury, kitti2015, kitti2012 or eth3d)"
            ))),
        }
    }
}

/// One stereo pair of a data set, with the paths of its inputs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Pair {
    /// The data set's layout.
    pub layout: Layout,
    /// The scene folder's name (MiddEval3, ETH3D) or the frame's file stem (KITTI: `000000_10`).
    pub name: String,
    /// The data set's folder: the folder holding `image_2/` (KITTI) or the scene folders (ETH3D); for MiddEval3
    /// the scene folder itself.
    pub root: PathBuf,
    /// Left image.
    pub left: PathBuf,
    /// Right image.
    pub right: PathBuf,
    /// `calib.txt` (MiddEval3, ETH3D); KITTI frames have none.
    pub calib: Option<PathBuf>,
}

/// Where a pair's ground truth is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Truth {
    /// The ground-truth disparity map (`.pfm`, or KITTI's 16-bit `.png`).
    pub disparity: PathBuf,
    /// The occlusion mask (MiddEval3, ETH3D: `mask0nocc.png`); KITTI has separate maps instead.
    pub mask: Option<PathBuf>,
}

impl Truth {
    /// The ground truth of a MiddEval3 (or ETH3D) scene folder: its [`GT_FILE`] and [`MASK_FILE`].
    pub fn in_scene(dir: &Path) -> Truth {
        Truth { disparity: dir.join(GT_FILE), mask: Some(dir.join(MASK_FILE)) }
    }
}

/// Where an algorithm's result for a pair goes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ResultFiles {
    /// The disparity map.
    pub disparity: PathBuf,
    /// The run time file.
    pub time: PathBuf,
    /// The confidence map, when one is written (`jem batch --confidence`; `jem eval` scores it when it is there):
    /// MiddEval3 `conf0NAME.pfm` beside the result, KITTI `conf_0/FRAME.pfm`, ETH3D `confidence/SCENE.pfm`.
    pub confidence: PathBuf,
    /// The configuration the run recorded beside the result (`jem batch`: every parameter, the command and jem's
    /// version, as TOML that `--config` reads back): MiddEval3 `configNAME.toml` in the scene folder, KITTI
    /// `config/FRAME.toml` and ETH3D `config/SCENE.toml` beside the submission folder (outside it).
    pub config: PathBuf,
}

impl Pair {
    /// Where the pair is shown in reports: its scene folder, or a KITTI frame's left image.
    pub fn location(&self) -> PathBuf {
        match self.layout {
            Layout::Middlebury => self.root.clone(),
            Layout::Eth3d => self.root.join(&self.name),
            Layout::Kitti2015 | Layout::Kitti2012 => self.left.clone(),
        }
    }

    /// The search range when neither `--ndisp` nor a calib.txt gives one (KITTI: [`KITTI_NDISP`]; `None`:
    /// measure it).
    pub fn default_ndisp(&self) -> Option<usize> {
        self.layout.is_kitti().then_some(KITTI_NDISP)
    }

    /// The results folder of `alg` for this pair's data set: `base/alg/SPLIT`, `base` = `results` or the folder
    /// `results/` beside the data set, `SPLIT` the data set's folder name (`training`, `testing`,
    /// `two_view_training`: each split its own folder); `None` for MiddEval3, whose results go into the
    /// scene folder.
    pub fn results_dir(&self, alg: &str, results: Option<&Path>) -> Option<PathBuf> {
        if self.layout == Layout::Middlebury {
            return None;
        }
        let base = match results {
            Some(r) => r.to_path_buf(),
            None => match self.root.parent() {
                Some(p) if !p.as_os_str().is_empty() => p.join("results"),
                _ => PathBuf::from("results"),
            },
        };
        Some(base.join(alg).join(self.split_name()))
    }

    /// The data set's folder name (of its resolved path when the given one has none, as `.`).
    fn split_name(&self) -> std::ffi::OsString {
        let name = |p: &Path| p.file_name().map(|n| n.to_os_string());
        name(&self.root)
            .or_else(|| std::fs::canonicalize(&self.root).ok().as_deref().and_then(name))
            .unwrap_or_else(|| "data".into())
    }

    /// The files `alg`'s result for this pair is written to (see the module doc).
    pub fn result_files(&self, alg: &str, results: Option<&Path>) -> ResultFiles {
        match self.results_dir(alg, results) {
            None => ResultFiles {
                disparity: self.root.join(format!("disp0{alg}.pfm")),
                time: self.root.join(format!("time{alg}.txt")),
                confidence: self.root.join(format!("conf0{alg}.pfm")),
                config: self.root.join(format!("config{alg}.toml")),
            },
            Some(dir) if self.layout == Layout::Eth3d => ResultFiles {
                disparity: dir.join("low_res_two_view").join(format!("{}.pfm", self.name)),
                time: dir.join("low_res_two_view").join(format!("{}.txt", self.name)),
                confidence: dir.join("confidence").join(format!("{}.pfm", self.name)),
                config: dir.join("config").join(format!("{}.toml", self.name)),
            },
            Some(dir) => ResultFiles {
                disparity: dir.join("disp_0").join(format!("{}.png", self.name)),
                time: dir.join("time").join(format!("{}.txt", self.name)),
                confidence: dir.join("conf_0").join(format!("{}.pfm", self.name)),
                config: dir.join("config").join(format!("{}.toml", self.name)),
            },
        }
    }

    /// Where `jem batch --lr-mask` writes where the left-right check rejected `alg`'s pixels
    /// ([`crate::io::encode_lr_mask`]): MiddEval3 `lrmask0<alg>.png` beside `disp0<alg>.pfm` (what `jem eval
    /// --regions` reads); KITTI `lrmask_0/FRAME.png` beside `disp_0/`, ETH3D `lrmask/SCENE.png` beside
    /// `low_res_two_view/` (outside the folders a benchmark takes as the submission).
    pub fn lr_mask_file(&self, alg: &str, results: Option<&Path>) -> PathBuf {
        match self.results_dir(alg, results) {
            None => self.root.join(format!("lrmask0{alg}.png")),
            Some(dir) if self.layout == Layout::Eth3d => dir.join("lrmask").join(format!("{}.png", self.name)),
            Some(dir) => dir.join("lrmask_0").join(format!("{}.png", self.name)),
        }
    }

    /// The text of the run-time file for `seconds` (ETH3D: `runtime <s>`, the benchmark's form; else the number).
    pub fn time_text(&self, seconds: f64) -> String {
        match self.layout {
            Layout::Eth3d => format!("runtime {seconds:.6}\n"),
            _ => format!("{seconds:.6}\n"),
        }
    }

    /// Where the ground truth of this pair is, for the non-occluded pixels (`all = false`) or all of them.
    /// ETH3D's truth is in the tree `gt` (default: the sibling `<root name>_gt/`).
    pub fn truth(&self, all: bool, gt: Option<&Path>) -> Truth {
        match self.layout {
            Layout::Middlebury => Truth::in_scene(&self.root),
            Layout::Eth3d => {
                let tree = gt.map_or_else(|| eth3d_gt_tree(&self.root), Path::to_path_buf);
                Truth::in_scene(&tree.join(&self.name))
            }
            Layout::Kitti2015 | Layout::Kitti2012 => {
                let (noc, occ) = kitti::truth_folders(self.layout);
                let folder = if all { occ } else { noc };
                Truth { disparity: self.root.join(folder).join(format!("{}.png", self.name)), mask: None }
            }
        }
    }
}

/// The sibling `<name>_gt` of an ETH3D image tree.
fn eth3d_gt_tree(root: &Path) -> PathBuf {
    let name = root.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    root.with_file_name(format!("{name}_gt"))
}

/// Whether the folder holding scene folders looks like an ETH3D tree: named `two_view_*`, or with a sibling
/// `<name>_gt/`.
fn is_eth3d_tree(dir: &Path) -> bool {
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    name.starts_with("two_view_") || (!name.is_empty() && eth3d_gt_tree(dir).is_dir())
}

/// What [`discover`] looks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Purpose {
    /// Pairs to run: a MiddEval3/ETH3D scene needs `im0.png`, `im1.png` and `calib.txt`; every KITTI frame.
    Run,
    /// Pairs to score: a MiddEval3 scene needs `disp0GT.pfm` (nothing else), an ETH3D scene its truth in the
    /// `_gt` tree, a KITTI frame its data set's truth folders.
    Score,
}

/// How [`discover`] reads a tree.
#[derive(Clone, Debug, Default)]
pub struct Discovery {
    /// Take every scene as this layout instead of recognising it (MiddEval3 and ETH3D scenes look alike; the
    /// KITTI layouts are always recognised, and `Some(kitti…)` keeps only those frames).
    pub layout: Option<Layout>,
    /// ETH3D's ground-truth tree (default: the sibling `<name>_gt/` of the image tree).
    pub gt: Option<PathBuf>,
}

/// Every pair under the roots (recursively, the roots included), sorted by data set and name, without
/// duplicates. A folder recognised as a data set or a scene is not searched further; hidden folders (`.name`)
/// are skipped; a folder reached twice (symbolic links) is read once.
///
/// # Errors
/// [`Error::Io`] if a root cannot be read, [`Error::Dataset`] if one is not
/// a folder. Unreadable sub-folders are skipped.
pub fn discover(roots: &[PathBuf], purpose: Purpose, how: &Discovery) -> Result<Vec<Pair>> {
    let mut found = Vec::new();
    walk::walk_folders(roots, &mut |dir| {
        if let Some(layout) = kitti::recognise(dir) {
            found.extend(kitti::frames(dir, layout, purpose));
            return true;
        }
        match scene(dir, purpose, how) {
            Some(pair) => {
                found.extend(pair);
                true
            }
            None => false,
        }
    })?;
    found.sort_by(|a, b| (&a.root, &a.name).cmp(&(&b.root, &b.name)));
    found.dedup();
    if let Some(forced) = how.layout {
        found.retain(|p| p.layout == forced);
    }
    Ok(found)
}

/// `Some(pair)` if `dir` is a scene folder for this purpose (`Some(None)`: a scene folder, but without what the
/// purpose needs, so not searched further and not listed); `None` if it is no scene folder.
fn scene(dir: &Path, purpose: Purpose, how: &Discovery) -> Option<Option<Pair>> {
    let has = |f: &str| dir.join(f).is_file();
    let inputs = SCENE_FILES.iter().all(|f| has(f));
    let truth_here = purpose == Purpose::Score && has(GT_FILE);
    let parent = dir.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let eth3d = || how.gt.is_some() || is_eth3d_tree(parent);
    // In an ETH3D tree a folder with any of the scene files is a scene, listed even when one is missing, so that
    // `jem batch` fails it naming the file and `jem eval` counts it as missing (it must not disappear).
    let partial_eth3d = || {
        SCENE_FILES.iter().any(|f| has(f))
            && match how.layout {
                Some(l) => l == Layout::Eth3d,
                None => eth3d(),
            }
    };
    if !(inputs || truth_here || partial_eth3d()) {
        return None;
    }
    let layout = match how.layout {
        Some(l @ (Layout::Middlebury | Layout::Eth3d)) => l,
        _ if eth3d() => Layout::Eth3d,
        _ => Layout::Middlebury,
    };
    let name = dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned());
    let mut pair = Pair {
        layout,
        name,
        root: dir.to_path_buf(),
        left: dir.join(LEFT_FILE),
        right: dir.join(RIGHT_FILE),
        calib: Some(dir.join(CALIB_FILE)),
    };
    if layout == Layout::Eth3d {
        pair.root = parent.to_path_buf();
    }
    let usable = match purpose {
        Purpose::Run => inputs || layout == Layout::Eth3d,
        Purpose::Score => pair.truth(false, how.gt.as_deref()).disparity.is_file(),
    };
    Some(usable.then_some(pair))
}

#[cfg(test)]
mod tests;
