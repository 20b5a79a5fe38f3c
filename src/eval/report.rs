//! One algorithm over a folder of scenes: [`find_gt_scenes`] finds the scene folders with ground truth,
//! [`scale_from_path`] their resolution and [`scene_weight`] their MiddEval3 weight; [`evaluate_dir`] scores them
//! in parallel with [`evaluate_scene`] into an [`AlgReport`], whose weighted and plain means are the "Averages"
//! of the [`eval`](crate::eval) module doc. Per-scene failures are recorded, not returned.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::metrics::{MaskMode, Metrics, evaluate_scene};
use crate::error::{Error, Result};

/// The MiddEval3 weight of a training scene: 0.5 for PianoL, Playroom, Playtable, Shelves and Vintage, 1 for
/// every other scene (including unknown ones).
pub fn scene_weight(name: &str) -> f64 {
    match name {
        "PianoL" | "Playroom" | "Playtable" | "Shelves" | "Vintage" => 0.5,
        _ => 1.0,
    }
}

/// The resolution scale implied by a path: the innermost component named `training`, `test` or `additional`
/// followed by `Q` (4), `H` (2) or `F` (1), as in MiddEval3's `trainingQ`. `None` if there is none.
pub fn scale_from_path(path: &Path) -> Option<u32> {
    path.components().rev().find_map(|c| {
        let name = c.as_os_str().to_str()?;
        let rest = ["training", "test", "additional"].iter().find_map(|p| name.strip_prefix(p))?;
        match rest {
            "Q" => Some(4),
            "H" => Some(2),
            "F" => Some(1),
            _ => None,
        }
    })
}

/// One scene's evaluation.
#[derive(Clone, Debug)]
pub struct SceneResult {
    /// Scene name (the folder name; the path relative to the evaluated folder when names repeat).
    pub name: String,
    /// Scene folder.
    pub dir: PathBuf,
    /// MiddEval3 weight ([`scene_weight`]).
    pub weight: f64,
    /// The scores, or why the scene could not be evaluated.
    pub metrics: std::result::Result<Metrics, String>,
    /// Run time from `time<alg>.txt`, when present and readable.
    pub seconds: Option<f64>,
}

/// One algorithm's evaluation over a folder of scenes.
#[derive(Clone, Debug)]
pub struct AlgReport {
    /// Algorithm name (`disp0<alg>.pfm`).
    pub alg: String,
    /// Which pixels were evaluated.
    pub mask: MaskMode,
    /// Factor to full-resolution pixels.
    pub scale: u32,
    /// Every scene with ground truth, sorted by path.
    pub scenes: Vec<SceneResult>,
}

impl AlgReport {
    /// The MiddEval3 weighted mean over the evaluated scenes (`None` if none was).
    pub fn weighted(&self) -> Option<Metrics> {
        self.average(|s| s.weight)
    }

    /// The plain mean over the evaluated scenes (`None` if none was).
    pub fn mean(&self) -> Option<Metrics> {
        self.average(|_| 1.0)
    }

    /// The scenes left out of the averages, with the reason.
    pub fn excluded(&self) -> impl Iterator<Item = (&str, &str)> {
        self.scenes.iter().filter_map(|s| s.metrics.as_ref().err().map(|e| (s.name.as_str(), e.as_str())))
    }

    /// Mean run time per pair over the evaluated scenes that have a time file, and how many had one.
    pub fn mean_seconds(&self) -> Option<(f64, usize)> {
        let times: Vec<f64> = self.scenes.iter().filter(|s| s.metrics.is_ok()).filter_map(|s| s.seconds).collect();
        (!times.is_empty()).then(|| (times.iter().sum::<f64>() / times.len() as f64, times.len()))
    }

    fn average(&self, weight: impl Fn(&SceneResult) -> f64) -> Option<Metrics> {
        let ok: Vec<(f64, &Metrics)> =
            self.scenes.iter().filter_map(|s| s.metrics.as_ref().ok().map(|m| (weight(s), m))).collect();
        let total: f64 = ok.iter().map(|(w, _)| w).sum();
        if ok.is_empty() || total <= 0.0 {
            return None;
        }
        let mut sums = [0.0f64; 8];
        for (w, m) in &ok {
            for (s, v) in sums.iter_mut().zip(m.values()) {
                *s += w * v;
            }
        }
        Some(Metrics::from_values(sums.map(|s| s / total), ok.iter().map(|(_, m)| m.pixels).sum()))
    }
}

/// Folders under `dir` (recursively, `dir` included) holding a `disp0GT.pfm`, sorted by path.
///
/// # Errors
/// [`Error::Io`] if `dir` cannot be read, [`Error::Input`] if it holds no such folder.
pub fn find_gt_scenes(dir: &Path) -> Result<Vec<PathBuf>> {
    let scenes = crate::batch::find_dirs_with(&[dir.to_path_buf()], &["disp0GT.pfm"])?;
    if scenes.is_empty() {
        return Err(Error::Input(format!("no scene folder with a disp0GT.pfm under {}", dir.display())));
    }
    Ok(scenes)
}

/// Evaluates `disp0<alg>.pfm` in every scene folder under `dir` that has ground truth (scenes in parallel).
///
/// `scale = None` infers the factor from each scene's path ([`scale_from_path`], after resolving `.`/symlinks).
///
/// # Errors
/// No scene with ground truth, an unreadable folder, or (with `scale = None`) a path that implies no resolution
/// or scenes at different resolutions. Per-scene problems are not errors: they are recorded in the report.
pub fn evaluate_dir(dir: &Path, alg: &str, mask_mode: MaskMode, scale: Option<u32>) -> Result<AlgReport> {
    let dirs = find_gt_scenes(dir)?;
    let scale = match scale {
        Some(s) => s,
        None => infer_common_scale(&dirs)?,
    };
    let names = scene_names(dir, &dirs);
    let scenes = dirs
        .par_iter()
        .zip(names)
        .map(|(d, name)| SceneResult {
            weight: scene_weight(&name),
            metrics: evaluate_scene(d, alg, scale, mask_mode).map_err(|e| error_chain(&e)),
            seconds: read_seconds(&d.join(format!("time{alg}.txt"))),
            name,
            dir: d.clone(),
        })
        .collect();
    Ok(AlgReport { alg: alg.to_string(), mask: mask_mode, scale, scenes })
}

/// The one scale all `dirs` imply.
fn infer_common_scale(dirs: &[PathBuf]) -> Result<u32> {
    let mut found: Option<(u32, &Path)> = None;
    for d in dirs {
        let resolved = std::fs::canonicalize(d).unwrap_or_else(|_| d.clone());
        let Some(s) = scale_from_path(&resolved) else {
            return Err(Error::Input(format!(
                "cannot tell the resolution of {} from its path (no trainingQ/H/F-like folder); pass --scale 1, 2 \
                 or 4",
                d.display()
            )));
        };
        match found {
            Some((f, other)) if f != s => {
                return Err(Error::Input(format!(
                    "{} and {} are at different resolutions; evaluate one folder at a time or pass --scale",
                    other.display(),
                    d.display()
                )));
            }
            _ => found = Some((s, d)),
        }
    }
    found.map(|(s, _)| s).ok_or_else(|| Error::Input("no scenes".into()))
}

/// Folder names, or paths relative to `root` where two folders share a name.
fn scene_names(root: &Path, dirs: &[PathBuf]) -> Vec<String> {
    let base: Vec<String> =
        dirs.iter().map(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()).collect();
    base.iter()
        .zip(dirs)
        .map(|(name, d)| {
            if name.is_empty() || base.iter().filter(|b| *b == name).count() > 1 {
                d.strip_prefix(root).unwrap_or(d).display().to_string()
            } else {
                name.clone()
            }
        })
        .collect()
}

/// The number in a `time<alg>.txt`, if the file exists and holds one finite non-negative number.
fn read_seconds(path: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(path).ok()?;
    text.trim().parse::<f64>().ok().filter(|t| t.is_finite() && *t >= 0.0)
}

/// The error and its sources on one line.
fn error_chain(e: &Error) -> String {
    let mut msg = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        let _ = write!(msg, ": {s}");
        source = s.source();
    }
    msg
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    #[test]
    fn scale_from_middeval_paths() {
        assert_eq!(scale_from_path(Path::new("/d/MiddEval3/trainingQ/Teddy")), Some(4));
        assert_eq!(scale_from_path(Path::new("MiddEval3/testH/Australia")), Some(2));
        assert_eq!(scale_from_path(Path::new("x/trainingF")), Some(1));
        assert_eq!(scale_from_path(Path::new("trainingQ/trainingH/Teddy")), Some(2));
        assert_eq!(scale_from_path(Path::new("/home/PDF/Teddy")), None);
        assert_eq!(scale_from_path(Path::new("trainingX/Teddy")), None);
    }

    /// A scene with made-up metrics (avgerr, rms = 2·avgerr, bad2 10, invalid 1) and run time `avgerr` s.
    pub(in crate::eval) fn scene(name: &str, avgerr: f64, ok: bool) -> SceneResult {
        let m = Metrics::from_values([avgerr, 2.0 * avgerr, 0.0, 0.0, 10.0, 0.0, 1.0, 11.0], 100);
        SceneResult {
            name: name.into(),
            dir: PathBuf::from(name),
            weight: scene_weight(name),
            metrics: if ok { Ok(m) } else { Err("no result".into()) },
            seconds: Some(avgerr),
        }
    }

    #[test]
    fn weighted_and_plain_means() {
        let r = AlgReport {
            alg: "X".into(),
            mask: MaskMode::Nonocc,
            scale: 4,
            scenes: vec![
                scene("PianoL", 2.0, true),
                scene("Teddy", 4.0, true),
                scene("New", 1.0, true),
                scene("Vintage", 50.0, false),
            ],
        };
        let w = r.weighted().unwrap();
        assert!((w.avgerr - (0.5 * 2.0 + 4.0 + 1.0) / 2.5).abs() < 1e-12);
        assert!((w.rms - 2.0 * 6.0 / 2.5).abs() < 1e-12);
        assert_eq!((w.bad2, w.pixels), (10.0, 300));
        assert!((r.mean().unwrap().avgerr - 7.0 / 3.0).abs() < 1e-12);
        assert_eq!(r.excluded().collect::<Vec<_>>(), vec![("Vintage", "no result")]);
        assert_eq!(r.mean_seconds(), Some((7.0 / 3.0, 3)));
    }
}
