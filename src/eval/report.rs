//! One algorithm over a data set: [`evaluate_dir`] finds the pairs with ground truth ([`crate::dataset::discover`]),
//! their resolution ([`super::scene_resolution`], MiddEval3) and weight ([`scene_weight`]), scores them in parallel
//! into an [`AlgReport`], whose weighted and plain means are the "Averages" of the [`eval`](crate::eval) module doc.
//! Per-scene failures are recorded, not returned. [`find_gt_scenes`] lists MiddEval3 scene folders with ground truth.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;

use super::metrics::{D1_THRESHOLD_PX, MaskMode, Metrics, check_size, evaluate, evaluate_files, evaluate_scene};
use super::resolution::{resolution_name, scene_resolution};
use super::sparsification::{Sparsification, sparsification};
use crate::dataset::{Discovery, Layout, Pair, Purpose};
use crate::error::{Error, Result};
use crate::image::Plane;

/// The MiddEval3 weight of a training scene: 0.5 for PianoL, Playroom, Playtable, Shelves and Vintage, 1 for
/// every other scene (including unknown ones).
pub fn scene_weight(name: &str) -> f64 {
    match name {
        "PianoL" | "Playroom" | "Playtable" | "Shelves" | "Vintage" => 0.5,
        _ => 1.0,
    }
}

/// One scene's evaluation.
#[derive(Clone, Debug)]
pub struct SceneResult {
    /// Scene name (the folder name, or the KITTI frame; the path relative to the evaluated folder when names
    /// repeat).
    pub name: String,
    /// Scene folder (a KITTI frame: its left image).
    pub dir: PathBuf,
    /// MiddEval3 weight ([`scene_weight`]); 1 for KITTI and ETH3D.
    pub weight: f64,
    /// The scores, or why the scene could not be evaluated.
    pub metrics: std::result::Result<Metrics, Arc<Error>>,
    /// Run time from `time<alg>.txt`, when present and readable.
    pub seconds: Option<f64>,
    /// How well the confidence map beside the result ranks its errors, when there is one (and it reads).
    pub sparsification: Option<Sparsification>,
    /// Left out for the data set's own files (its ground truth, mask or calib.txt is missing or unreadable), not
    /// for its result.
    pub truth_unusable: bool,
}

/// One algorithm's evaluation over a folder of scenes.
#[derive(Clone, Debug)]
pub struct AlgReport {
    /// Algorithm name (`disp0<alg>.pfm`).
    pub alg: String,
    /// The data set's layout.
    pub layout: Layout,
    /// Which pixels were evaluated.
    pub mask: MaskMode,
    /// Factor to full-resolution pixels.
    pub scale: u32,
    /// Every scene with ground truth, sorted by path.
    pub scenes: Vec<SceneResult>,
    /// How the MiddEval3 resolution was found, when the data told it rather than `--scale` or a folder's name: a
    /// line to show the user (`None` otherwise).
    pub scale_inferred: Option<String>,
    /// Runs that were writing these results while they were scored ([`crate::dataset::writers`]): the scores may
    /// change when they end.
    pub writers: Vec<String>,
}

impl AlgReport {
    /// The metrics the report shows, in order ([`Metrics::KITTI_NAMES`] for KITTI, else [`Metrics::NAMES`]).
    pub fn columns(&self) -> &'static [&'static str] {
        if self.layout.is_kitti() { &Metrics::KITTI_NAMES } else { &Metrics::NAMES }
    }

    /// The MiddEval3 weighted mean over the evaluated scenes (`None` if none was).
    pub fn weighted(&self) -> Option<Metrics> {
        self.average(|s| s.weight)
    }

    /// The plain mean over the evaluated scenes (`None` if none was).
    pub fn mean(&self) -> Option<Metrics> {
        self.average(|_| 1.0)
    }

    /// The mean sparsification AUC and optimum over the scenes that have one, and how many they are; `None`
    /// when none has a confidence map.
    pub fn mean_sparsification(&self) -> Option<(Sparsification, usize)> {
        let all: Vec<Sparsification> = self.scenes.iter().filter_map(|s| s.sparsification).collect();
        let n = all.len();
        (n > 0).then(|| {
            let mean = |f: fn(&Sparsification) -> f64| all.iter().map(f).sum::<f64>() / n as f64;
            (Sparsification { auc: mean(|s| s.auc), optimum: mean(|s| s.optimum) }, n)
        })
    }

    /// The scenes left out of the averages, with the reason ([`Error::chain`]).
    pub fn excluded(&self) -> impl Iterator<Item = (&str, String)> {
        self.scenes.iter().filter_map(|s| s.metrics.as_ref().err().map(|e| (s.name.as_str(), e.chain())))
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
        let mut sums = [0.0f64; 9];
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
/// [`Error::Io`] if `dir` cannot be read, [`Error::Dataset`] if it holds no such folder.
pub fn find_gt_scenes(dir: &Path) -> Result<Vec<PathBuf>> {
    let scenes = crate::dataset::walk::find_dirs_with(&[dir.to_path_buf()], &[crate::dataset::GT_FILE])?;
    if scenes.is_empty() {
        return Err(Error::dataset(format!("no scene folder with a disp0GT.pfm under {}", dir.display())));
    }
    Ok(scenes)
}

/// Where [`evaluate_dir`] finds what it scores, beyond the folder it is given.
#[derive(Clone, Debug, Default)]
pub struct Sources {
    /// Read every scene as this layout instead of recognising it (see [`crate::dataset::Discovery`]).
    pub layout: Option<Layout>,
    /// ETH3D's ground-truth tree (default: the sibling `<name>_gt/` of the image tree).
    pub gt: Option<PathBuf>,
    /// The results base for KITTI and ETH3D (default: `results/` beside the data set; see [`crate::dataset`]).
    pub results: Option<PathBuf>,
}

/// Evaluates `alg`'s results for every pair under `dir` that has ground truth (pairs in parallel): MiddEval3
/// scenes (`disp0<alg>.pfm` beside `disp0GT.pfm`), KITTI frames and ETH3D scenes (results and truth where
/// [`crate::dataset`] puts them). One layout per call.
///
/// `scale = None` infers the factor of MiddEval3 scenes from each scene's path (after resolving `.`/symlinks), else
/// from its name and image size ([`super::scene_resolution`]; [`AlgReport::scale_inferred`]
/// then says so); KITTI and ETH3D are scored in native pixels (1).
///
/// # Errors
/// No scene with ground truth, an unreadable folder, data sets of two layouts, a results folder that holds
/// another data set's results, or (MiddEval3, with `scale = None`) a scene whose resolution nothing tells, or
/// scenes at different resolutions. Per-scene problems are not errors: they are recorded in the report.
pub fn evaluate_dir(
    dir: &Path,
    alg: &str,
    mask_mode: MaskMode,
    scale: Option<u32>,
    src: &Sources,
) -> Result<AlgReport> {
    let how = Discovery { layout: src.layout, gt: src.gt.clone() };
    let pairs = crate::dataset::discover(&[dir.to_path_buf()], Purpose::Score, &how)?;
    let Some(layout) = pairs.first().map(|p| p.layout) else {
        return Err(Error::dataset(format!(
            "no scene with ground truth under {} (MiddEval3 disp0GT.pfm, KITTI disp_noc*/ or disp_occ*/, ETH3D *_gt/)",
            dir.display()
        )));
    };
    if let Some(other) = pairs.iter().find(|p| p.layout != layout) {
        return Err(Error::dataset(format!(
            "{} holds {} and {} data ({} and {}); evaluate one data set at a time",
            dir.display(),
            layout.name(),
            other.layout.name(),
            pairs[0].root.display(),
            other.root.display()
        )));
    }
    crate::dataset::check_results_dirs(&pairs, alg, src.results.as_deref(), false)?;
    let writers = crate::dataset::writers(&pairs, alg, src.results.as_deref());
    let locations: Vec<PathBuf> = pairs.iter().map(Pair::location).collect();
    let (scale, scale_inferred) = match (scale, layout) {
        (Some(s), _) => (s, None),
        (None, Layout::Middlebury) => infer_common_scale(dir, &locations)?,
        (None, _) => (1, None),
    };
    let names = scene_names(dir, &pairs, &locations);
    let scenes = pairs
        .par_iter()
        .zip(locations)
        .zip(names)
        .map(|((pair, dir), name)| {
            let files = pair.result_files(alg, src.results.as_deref());
            let metrics = check_truth(pair, mask_mode, src).and_then(|()| score_pair(pair, alg, scale, mask_mode, src));
            let sparsification = metrics.is_ok().then(|| score_confidence(pair, alg, mask_mode, src)).flatten();
            SceneResult {
                sparsification,
                weight: if layout == Layout::Middlebury { scene_weight(&name) } else { 1.0 },
                truth_unusable: metrics.as_ref().is_err_and(|e| !blames_result(e, &files.disparity)),
                metrics: metrics.map_err(Arc::new),
                seconds: read_seconds(&files.time),
                name,
                dir,
            }
        })
        .collect();
    Ok(AlgReport { alg: alg.to_string(), layout, mask: mask_mode, scale, scale_inferred, scenes, writers })
}

/// Checks that the files of the data set a pair's score needs are there: its ground truth, its mask (for
/// `nonocc`, where the layout has one) and, for MiddEval3, its calib.txt; checked before the result, so a scene
/// without them says so rather than that its result is missing.
fn check_truth(pair: &Pair, mask_mode: MaskMode, src: &Sources) -> Result<()> {
    let truth = pair.truth(mask_mode == MaskMode::All, src.gt.as_deref());
    if !truth.disparity.is_file() {
        return Err(Error::dataset(format!("no ground truth {}", truth.disparity.display())));
    }
    if let Some(mask) = truth.mask.filter(|m| mask_mode == MaskMode::Nonocc && !m.is_file()) {
        return Err(Error::dataset(format!("no {} (needed for the nonocc mask)", mask.display())));
    }
    if let Some(calib) = pair.calib.as_ref().filter(|c| pair.layout == Layout::Middlebury && !c.is_file()) {
        return Err(Error::dataset(format!("no {} (needed for the search range)", calib.display())));
    }
    Ok(())
}

/// Whether a scene's error is about its result (missing, unreadable, of another size) rather than the data set's
/// files.
fn blames_result(e: &Error, result: &Path) -> bool {
    match e {
        Error::Io { path, .. } | Error::Image { path, .. } | Error::Pfm { path, .. } | Error::Exr { path, .. } => {
            path == result
        }
        Error::Calib { .. } => false,
        // Messages of these name the file they concern first; a missing result is named after "no result file".
        Error::InputImage { .. }
        | Error::InputFile { .. }
        | Error::Config { .. }
        | Error::Dataset { .. }
        | Error::Locked { .. }
        | Error::Output { .. }
        | Error::Argument { .. } => {
            let msg = e.to_string();
            msg.starts_with("no result file") || msg.starts_with(&result.display().to_string())
        }
        _ => true,
    }
}

/// Scores one pair's result (see the [`eval`](crate::eval) module doc for each layout's rules).
fn score_pair(pair: &Pair, alg: &str, scale: u32, mask_mode: MaskMode, src: &Sources) -> Result<Metrics> {
    if pair.layout == Layout::Middlebury {
        return evaluate_scene(&pair.root, alg, scale, mask_mode);
    }
    let result = pair.result_files(alg, src.results.as_deref()).disparity;
    if !result.is_file() {
        return Err(Error::dataset(format!("no result file {}", result.display())));
    }
    let truth = pair.truth(mask_mode == MaskMode::All, src.gt.as_deref());
    // No clipping: neither benchmark clips a result to a search range.
    let unbounded = usize::MAX;
    if pair.layout == Layout::Eth3d {
        let mask = truth.mask.filter(|_| mask_mode == MaskMode::Nonocc);
        if let Some(m) = mask.as_ref().filter(|m| !m.is_file()) {
            return Err(Error::dataset(format!("no {} (needed for the nonocc mask)", m.display())));
        }
        return evaluate_files(&result, &truth.disparity, mask.as_deref(), unbounded, scale, mask_mode);
    }
    let gt = crate::io::read_disparity(&truth.disparity)?;
    let mut map = crate::io::read_disparity(&result)?;
    check_size(&result, "result", map.dims(), &format!("the ground truth {}", truth.disparity.display()), gt.dims())?;
    let known = gt.data.iter().filter(|g| g.is_finite()).count();
    let invalid_before = gt.data.iter().zip(&map.data).filter(|(g, d)| g.is_finite() && !d.is_finite()).count();
    super::interpolate_background(&mut map);
    let mut metrics = evaluate(&map, &gt, None, unbounded, scale, mask_mode);
    if metrics.pixels == 0 {
        return Err(Error::dataset_at(&truth.disparity, "no pixel with ground truth"));
    }
    metrics.invalid = 100.0 * invalid_before as f64 / known as f64;
    Ok(metrics)
}

/// The sparsification AUC of the confidence map beside `alg`'s result ([`Sparsification`]), when there is one: a
/// pixel is bad when it is invalid or off by more than 1 px at the resolution matched (KITTI: 3 px, its D1
/// threshold). A KITTI result is scored as written, before the development kit's fill.
fn score_confidence(pair: &Pair, alg: &str, mask_mode: MaskMode, src: &Sources) -> Option<Sparsification> {
    let files = pair.result_files(alg, src.results.as_deref());
    if !files.confidence.is_file() {
        return None;
    }
    let truth = pair.truth(mask_mode == MaskMode::All, src.gt.as_deref());
    let confidence = crate::io::read_disparity(&files.confidence).ok()?;
    let result = crate::io::read_disparity(&files.disparity).ok()?;
    let gt = crate::io::read_disparity(&truth.disparity).ok()?;
    let mask = match truth.mask.filter(|m| m.is_file() && !pair.layout.is_kitti()) {
        Some(m) => Some(crate::io::png::load_grey8(&m).ok()?),
        None => None,
    };
    let same = |p: &Plane<f32>| p.dims() == gt.dims();
    if !same(&confidence) || !same(&result) || mask.as_ref().is_some_and(|m| m.dims() != gt.dims()) {
        return None;
    }
    let bad_px = if pair.layout.is_kitti() { D1_THRESHOLD_PX as f32 } else { 1.0 };
    sparsification(&confidence, &result, &gt, mask.as_ref(), mask_mode, bad_px)
}

/// The one scale all scene folders `dirs` (under `root`) have ([`scene_resolution`]: their path, else their name
/// and image size), and a line saying so when it came from the sizes.
fn infer_common_scale(root: &Path, dirs: &[PathBuf]) -> Result<(u32, Option<String>)> {
    let mut found: Option<(u32, &Path)> = None;
    let mut from_sizes = 0;
    for d in dirs {
        let Some(res) = scene_resolution(d) else {
            return Err(Error::dataset(format!(
                "cannot tell the resolution of {}: no trainingQ/H/F-like folder in its path, and its name and \
                 image size are not a MiddEval3 scene's; pass --scale 1, 2 or 4",
                d.display()
            )));
        };
        from_sizes += usize::from(res.from_contents());
        match found {
            Some((f, other)) if f != res.scale => {
                return Err(Error::dataset(format!(
                    "{} and {} are at different resolutions; evaluate one folder at a time or pass --scale",
                    other.display(),
                    d.display()
                )));
            }
            _ => found = Some((res.scale, d)),
        }
    }
    let (scale, _) = found.ok_or_else(|| Error::dataset("no scenes"))?;
    let note = (from_sizes > 0).then(|| {
        let of = if from_sizes == dirs.len() { "its".to_string() } else { format!("{from_sizes} of its") };
        format!(
            "{}: {}, from the names and image sizes of {of} {} MiddEval3 scene(s) (--scale sets it)",
            root.display(),
            resolution_name(scale),
            dirs.len()
        )
    });
    Ok((scale, note))
}

/// Pair names, or the path of their location relative to `root` where two pairs share a name.
fn scene_names(root: &Path, pairs: &[Pair], locations: &[PathBuf]) -> Vec<String> {
    pairs
        .iter()
        .zip(locations)
        .map(|(p, loc)| {
            if p.name.is_empty() || pairs.iter().filter(|q| q.name == p.name).count() > 1 {
                loc.strip_prefix(root).unwrap_or(loc).display().to_string()
            } else {
                p.name.clone()
            }
        })
        .collect()
}

/// The number in a run-time file, if the file exists and holds one finite non-negative number (alone, or after
/// `runtime` as in ETH3D's files).
fn read_seconds(path: &Path) -> Option<f64> {
    let text = crate::io::read_small_text(path, 64 << 10)?;
    let text = text.trim();
    let number = text.strip_prefix("runtime").map_or(text, str::trim_start);
    number.parse::<f64>().ok().filter(|t| t.is_finite() && *t >= 0.0)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// A scene with made-up metrics (avgerr, rms = 2·avgerr, bad2 10, invalid 1) and run time `avgerr` s.
    pub(in crate::eval) fn scene(name: &str, avgerr: f64, ok: bool) -> SceneResult {
        let m = Metrics::from_values([avgerr, 2.0 * avgerr, 0.0, 0.0, 10.0, 0.0, 1.0, 11.0, 5.0], 100);
        SceneResult {
            name: name.into(),
            dir: PathBuf::from(name),
            weight: scene_weight(name),
            metrics: if ok { Ok(m) } else { Err(Arc::new(Error::dataset("no result"))) },
            seconds: Some(avgerr),
            sparsification: None,
            truth_unusable: false,
        }
    }

    #[test]
    fn weighted_and_plain_means() {
        let r = AlgReport {
            alg: "X".into(),
            layout: Layout::Middlebury,
            mask: MaskMode::Nonocc,
            scale: 4,
            scenes: vec![
                scene("PianoL", 2.0, true),
                scene("Teddy", 4.0, true),
                scene("New", 1.0, true),
                scene("Vintage", 50.0, false),
            ],
            scale_inferred: None,
            writers: Vec::new(),
        };
        let w = r.weighted().unwrap();
        assert!((w.avgerr - (0.5 * 2.0 + 4.0 + 1.0) / 2.5).abs() < 1e-12);
        assert!((w.rms - 2.0 * 6.0 / 2.5).abs() < 1e-12);
        assert_eq!((w.bad2, w.pixels), (10.0, 300));
        assert!((r.mean().unwrap().avgerr - 7.0 / 3.0).abs() < 1e-12);
        assert_eq!(r.excluded().collect::<Vec<_>>(), vec![("Vintage", "no result".to_string())]);
        assert_eq!(r.mean_seconds(), Some((7.0 / 3.0, 3)));
    }
}
