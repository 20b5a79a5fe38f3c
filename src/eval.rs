//! Evaluation against ground truth with the semantics of the MiddEval3 SDK's `evaldisp` (SPEC §5).
//!
//! # What is counted
//! For every pixel whose ground truth is finite (an `inf` GT pixel is unknown and skipped) and that the mask
//! selects ([`MaskMode::Nonocc`]: `mask0nocc.png == 255`; [`MaskMode::All`]: `mask > 0`; no mask: every
//! GT-valid pixel), let `n` be the number of such pixels. A result pixel that is not finite (`+inf`, `-inf`,
//! NaN) is *invalid*; a finite one is clipped to `[0, ndisp]` (inclusive, at the result's resolution, as
//! `evaldisp` clips to its `maxdisp`) and its error is `err = s·|d − gt|`, with `s` the resolution scale
//! (4 for quarter, 2 for half, 1 for full resolution), so errors and thresholds are in full-resolution pixels.
//!
//! | metric     | definition                                                            |
//! |------------|-----------------------------------------------------------------------|
//! | `avgerr`   | Σ err / (n − invalid) — invalid pixels are left out                     |
//! | `rms`      | √(Σ err² / (n − invalid))                                               |
//! | `badT`     | 100 · #{valid pixels with err > T} / n, T ∈ {0.5, 1, 2, 4} (strict `>`) |
//! | `invalid`  | 100 · #{invalid pixels} / n                                            |
//! | `totbad2`  | `bad2 + invalid` = 100 · (#{err > 2} + #{invalid}) / n                 |
//!
//! So the bad percentages count bad *valid* pixels among *all* `n` masked GT-valid pixels, exactly as
//! `evaldisp` does (its `badpercent = 100·bad/n`, `totalbadpercent = 100·(bad + invalid)/n`, and since 2014
//! `avgErr = serr/(n − invalid)`). When `n − invalid = 0`, `avgerr` and `rms` are NaN (printed as `nan`,
//! `null` in JSON); a scene with `n = 0` is an error.
//!
//! # Deviations from `evaldisp`
//! - `evaldisp` upsamples a low-resolution result to the full-resolution GT; here the result and the GT have the
//!   same size (a Q result is scored against the Q ground truth) and the factor `s` restores full-res units.
//! - `evaldisp` treats only `+inf` as invalid; here every non-finite value is invalid (it would clip `-inf` to 0
//!   and let a NaN poison its sums). GT pixels that are NaN are skipped like `inf` ones.
//! - Sums are `f64` (not `f32`), accumulated in raster order, so results are deterministic.
//!
//! # Averages
//! [`AlgReport::weighted`] is the MiddEval3 weighted mean over the scenes that were evaluated: PianoL, Playroom,
//! Playtable, Shelves and Vintage weigh 0.5, every other scene 1 ([`scene_weight`]); [`AlgReport::mean`] is the
//! plain mean. Each metric is averaged separately. Scenes whose result is missing or unreadable are listed and
//! left out of both.
//!
//! Complexity: O(w·h) per scene, one pass, no allocation besides the loaded files.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::image::{DisparityMap, Plane};
use crate::io::calib::Calib;

/// The bad-pixel thresholds, in full-resolution pixels.
pub const BAD_THRESHOLDS_PX: [f64; 4] = [0.5, 1.0, 2.0, 4.0];

/// Which pixels of `mask0nocc.png` are evaluated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaskMode {
    /// Non-occluded pixels only: mask value 255.
    Nonocc,
    /// Every pixel with ground truth: mask value > 0 (255 non-occluded and 128 occluded).
    All,
}

impl MaskMode {
    /// `"nonocc"` or `"all"`.
    pub fn name(self) -> &'static str {
        match self {
            MaskMode::Nonocc => "nonocc",
            MaskMode::All => "all",
        }
    }

    /// Whether a pixel with this mask value is evaluated.
    #[inline]
    pub fn selects(self, mask_value: u8) -> bool {
        match self {
            MaskMode::Nonocc => mask_value == 255,
            MaskMode::All => mask_value > 0,
        }
    }
}

impl FromStr for MaskMode {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "nonocc" => Ok(MaskMode::Nonocc),
            "all" => Ok(MaskMode::All),
            _ => Err(format!("unknown mask {s:?} (expected nonocc or all)")),
        }
    }
}

/// The scores of one result (or an average of several). Percentages are 0–100; errors are in full-resolution
/// pixels. See the module doc for the exact definitions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metrics {
    /// Mean absolute error over the valid pixels.
    pub avgerr: f64,
    /// Root-mean-square error over the valid pixels.
    pub rms: f64,
    /// % of pixels with a valid disparity and err > 0.5.
    pub bad0_5: f64,
    /// % of pixels with a valid disparity and err > 1.
    pub bad1: f64,
    /// % of pixels with a valid disparity and err > 2.
    pub bad2: f64,
    /// % of pixels with a valid disparity and err > 4.
    pub bad4: f64,
    /// % of pixels whose result is invalid (not finite).
    pub invalid: f64,
    /// `bad2 + invalid`.
    pub totbad2: f64,
    /// Number of pixels evaluated (masked and GT-valid); for an average, the total over its scenes.
    pub pixels: u64,
}

impl Metrics {
    /// The metric names, in the order of [`Metrics::values`] (also the JSON and CSV keys).
    pub const NAMES: [&'static str; 8] = ["avgerr", "rms", "bad0.5", "bad1", "bad2", "bad4", "invalid", "totbad2"];

    /// The eight metrics in the order of [`Metrics::NAMES`].
    pub fn values(&self) -> [f64; 8] {
        [self.avgerr, self.rms, self.bad0_5, self.bad1, self.bad2, self.bad4, self.invalid, self.totbad2]
    }

    /// Builds metrics from values in the order of [`Metrics::NAMES`].
    pub fn from_values(v: [f64; 8], pixels: u64) -> Self {
        Metrics {
            avgerr: v[0],
            rms: v[1],
            bad0_5: v[2],
            bad1: v[3],
            bad2: v[4],
            bad4: v[5],
            invalid: v[6],
            totbad2: v[7],
            pixels,
        }
    }
}

/// Scores a disparity map against ground truth (see the module doc for the exact semantics).
///
/// `ndisp` is the search range of the result's resolution (valid disparities are clipped to `[0, ndisp]`) and
/// `scale` the factor to full-resolution pixels (4 for Q, 2 for H, 1 for F).
///
/// # Panics
/// If the result, the GT and the mask differ in size (check with [`evaluate_files`] first for user files).
///
/// # Examples
/// ```
/// use jem::{Plane, eval::{evaluate, MaskMode}};
/// let gt = Plane::from_vec(2, 1, vec![3.0, f32::INFINITY]);
/// let result = Plane::from_vec(2, 1, vec![3.5, 1.0]);
/// let m = evaluate(&result, &gt, None, 16, 4, MaskMode::All);
/// assert_eq!((m.avgerr, m.bad1, m.pixels), (2.0, 100.0, 1));
/// ```
pub fn evaluate(
    result: &DisparityMap,
    gt: &DisparityMap,
    mask: Option<&Plane<u8>>,
    ndisp: usize,
    scale: u32,
    mask_mode: MaskMode,
) -> Metrics {
    assert_eq!(result.dims(), gt.dims(), "result and ground truth sizes differ");
    if let Some(m) = mask {
        assert_eq!(m.dims(), gt.dims(), "mask and ground truth sizes differ");
    }
    let s = f64::from(scale);
    let max_d = ndisp as f64;
    let mut n = 0u64;
    let mut invalid = 0u64;
    let mut bad = [0u64; 4];
    let mut sum = 0.0f64;
    let mut sum_sq = 0.0f64;
    for (i, (&d, &g)) in result.data.iter().zip(&gt.data).enumerate() {
        if !g.is_finite() {
            continue;
        }
        if let Some(m) = mask {
            if !mask_mode.selects(m.data[i]) {
                continue;
            }
        }
        n += 1;
        if !d.is_finite() {
            invalid += 1;
            continue;
        }
        let err = s * (f64::from(d).clamp(0.0, max_d) - f64::from(g)).abs();
        sum += err;
        sum_sq += err * err;
        for (count, &t) in bad.iter_mut().zip(&BAD_THRESHOLDS_PX) {
            *count += u64::from(err > t);
        }
    }
    let pct = |k: u64| {
        if n == 0 { f64::NAN } else { 100.0 * k as f64 / n as f64 }
    };
    let valid = n - invalid;
    let (avgerr, rms) =
        if valid == 0 { (f64::NAN, f64::NAN) } else { (sum / valid as f64, (sum_sq / valid as f64).sqrt()) };
    Metrics {
        avgerr,
        rms,
        bad0_5: pct(bad[0]),
        bad1: pct(bad[1]),
        bad2: pct(bad[2]),
        bad4: pct(bad[3]),
        invalid: pct(invalid),
        totbad2: pct(bad[2] + invalid),
        pixels: n,
    }
}

/// Fails unless a map read from `path` has the size of the map it is compared with: "`path`: `what` is W×H but
/// `against` is W×H".
pub(crate) fn check_size(
    path: &Path,
    what: &str,
    dims: (usize, usize),
    against: &str,
    expected: (usize, usize),
) -> Result<()> {
    if dims == expected {
        return Ok(());
    }
    Err(Error::Input(format!(
        "{}: {what} is {}x{} but {against} is {}x{}",
        path.display(),
        dims.0,
        dims.1,
        expected.0,
        expected.1
    )))
}

/// Loads a result, the GT and an optional mask, checks their sizes and scores them with [`evaluate`].
///
/// # Errors
/// A missing or malformed file (naming it), unequal sizes, or no pixel to evaluate.
pub fn evaluate_files(
    result: &Path,
    gt: &Path,
    mask: Option<&Path>,
    ndisp: usize,
    scale: u32,
    mask_mode: MaskMode,
) -> Result<Metrics> {
    let gt_map = crate::io::read_disparity(gt)?;
    let result_map = crate::io::read_disparity(result)?;
    let truth = format!("the ground truth {}", gt.display());
    check_size(result, "result", result_map.dims(), &truth, gt_map.dims())?;
    let mask_plane = mask.map(crate::io::png::load_grey8).transpose()?;
    if let (Some(m), Some(path)) = (&mask_plane, mask) {
        check_size(path, "mask", m.dims(), "the ground truth", gt_map.dims())?;
    }
    let metrics = evaluate(&result_map, &gt_map, mask_plane.as_ref(), ndisp, scale, mask_mode);
    if metrics.pixels == 0 {
        return Err(Error::Input(format!(
            "{}: no pixel with ground truth under the {} mask",
            gt.display(),
            mask_mode.name()
        )));
    }
    Ok(metrics)
}

/// Scores `disp0<alg>.pfm` in a MiddEval3 scene folder against its `disp0GT.pfm`, with `mask0nocc.png` (required
/// for [`MaskMode::Nonocc`]; for [`MaskMode::All`] it is used when present) and `ndisp` from `calib.txt`.
///
/// # Errors
/// As [`evaluate_files`], or a missing/malformed `calib.txt` or mask.
pub fn evaluate_scene(dir: &Path, alg: &str, scale: u32, mask_mode: MaskMode) -> Result<Metrics> {
    let result = dir.join(format!("disp0{alg}.pfm"));
    if !result.is_file() {
        return Err(Error::Input(format!("no result file {}", result.display())));
    }
    let calib_path = dir.join("calib.txt");
    let ndisp = Calib::load(&calib_path)?.ndisp().map_err(|msg| Error::Calib { path: calib_path.clone(), msg })?;
    let mask = dir.join("mask0nocc.png");
    let mask = match (mask.is_file(), mask_mode) {
        (true, _) => Some(mask),
        (false, MaskMode::All) => None,
        (false, MaskMode::Nonocc) => {
            return Err(Error::Input(format!("no {} (needed for the nonocc mask)", mask.display())));
        }
    };
    evaluate_files(&result, &dir.join("disp0GT.pfm"), mask.as_deref(), ndisp, scale, mask_mode)
}

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

// ---------------------------------------------------------------------------------------------------------------
// The paper's numbers

/// The paper's per-scene numbers (`paper-results.tsv`: `#` comments, a header `scene weight COL...`, then one
/// tab-separated row per scene).
#[derive(Clone, Debug, PartialEq)]
pub struct PaperResults {
    columns: Vec<String>,
    rows: Vec<(String, f64, Vec<Option<f64>>)>,
}

/// One column of [`PaperResults`].
#[derive(Clone, Debug, PartialEq)]
pub struct PaperColumn {
    /// Column name, e.g. `JEM_ALL`.
    pub name: String,
    /// Scene → value.
    pub scenes: BTreeMap<String, f64>,
    /// Weighted mean of the column with the file's weights (the paper's "Avg").
    pub weighted: Option<f64>,
}

impl PaperResults {
    /// Parses the TSV text.
    ///
    /// # Errors
    /// A message naming the line for a missing header, a bad weight, or a row with the wrong number of fields.
    /// Empty fields and `-` are missing values.
    pub fn parse(text: &str) -> std::result::Result<Self, String> {
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
        let (_, header) = lines.next().ok_or("no header line")?;
        let head: Vec<&str> = header.split('\t').map(str::trim).collect();
        if head.len() < 3 || head[0] != "scene" || head[1] != "weight" {
            return Err("the header must be `scene<TAB>weight<TAB>COLUMN...`".into());
        }
        let columns: Vec<String> = head[2..].iter().map(|s| s.to_string()).collect();
        let mut rows = Vec::new();
        for (n, line) in lines {
            let f: Vec<&str> = line.split('\t').map(str::trim).collect();
            if f.len() != head.len() {
                return Err(format!("line {}: {} fields, the header has {}", n + 1, f.len(), head.len()));
            }
            let weight = f[1].parse::<f64>().map_err(|_| format!("line {}: bad weight {:?}", n + 1, f[1]))?;
            let values = f[2..].iter().map(|v| v.parse::<f64>().ok().filter(|v| v.is_finite())).collect();
            rows.push((f[0].to_string(), weight, values));
        }
        Ok(PaperResults { columns, rows })
    }

    /// Reads and parses a TSV file.
    ///
    /// # Errors
    /// [`Error::Io`] or [`Error::Input`] naming the path.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::parse(&text).map_err(|msg| Error::Input(format!("{}: {msg}", path.display())))
    }

    /// The column names.
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// One column by name.
    ///
    /// # Errors
    /// [`Error::Input`] listing the available columns.
    pub fn column(&self, name: &str) -> Result<PaperColumn> {
        let Some(k) = self.columns.iter().position(|c| c == name) else {
            return Err(Error::Input(format!("no paper column {name:?} (available: {})", self.columns.join(", "))));
        };
        let mut scenes = BTreeMap::new();
        let (mut sum, mut total) = (0.0, 0.0);
        for (scene, w, values) in &self.rows {
            if let Some(v) = values[k] {
                scenes.insert(scene.clone(), v);
                sum += w * v;
                total += w;
            }
        }
        Ok(PaperColumn { name: name.to_string(), scenes, weighted: (total > 0.0).then(|| sum / total) })
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Output formats

/// How [`render`] prints reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Aligned plain-text table, two decimals.
    Table,
    /// Comma-separated values, full precision, one row per (algorithm, scene) plus `weighted` and `mean` rows.
    Csv,
    /// One JSON object per algorithm (an array when several), full precision; NaN is `null`.
    Json,
    /// GitHub-flavoured Markdown tables, two decimals.
    Markdown,
}

impl FromStr for Format {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "table" => Ok(Format::Table),
            "csv" => Ok(Format::Csv),
            "json" => Ok(Format::Json),
            "markdown" | "md" => Ok(Format::Markdown),
            _ => Err(format!("unknown format {s:?} (expected table, csv, json or markdown)")),
        }
    }
}

/// Renders reports; `papers[i]` (if any) is printed beside `reports[i]`'s avgerr.
///
/// JSON: `{"alg", "mask", "scale", "scenes": {NAME: {metrics}}, "weighted": {metrics}|null, "mean": ...}` with
/// the keys of [`Metrics::NAMES`]; scenes that could not be evaluated are left out of `scenes`, and then an
/// `"excluded": {NAME: "reason"}` key is added; with a paper column, `"paper": {"column", "scenes", "weighted"}`.
///
/// # Panics
/// If `papers` is non-empty and not as long as `reports`.
pub fn render(reports: &[AlgReport], papers: &[Option<PaperColumn>], format: Format) -> String {
    assert!(papers.is_empty() || papers.len() == reports.len(), "one paper column per report");
    let paper: Vec<Option<&PaperColumn>> = (0..reports.len()).map(|i| papers.get(i).and_then(Option::as_ref)).collect();
    let paper = paper.as_slice();
    match format {
        Format::Json => render_json(reports, paper),
        Format::Csv => render_csv(reports, paper),
        Format::Table => render_text(reports, paper, false),
        Format::Markdown => render_text(reports, paper, true),
    }
}

fn json_str(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn json_num(v: f64) -> String {
    if v.is_finite() { format!("{v}") } else { "null".into() }
}

fn json_metrics(m: Option<&Metrics>) -> String {
    match m {
        None => "null".into(),
        Some(m) => {
            let fields: Vec<String> = Metrics::NAMES
                .iter()
                .zip(m.values())
                .map(|(k, v)| format!("{}: {}", json_str(k), json_num(v)))
                .collect();
            format!("{{{}}}", fields.join(", "))
        }
    }
}

fn render_json(reports: &[AlgReport], paper: &[Option<&PaperColumn>]) -> String {
    let objects: Vec<String> = reports
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let scenes: Vec<String> = r
                .scenes
                .iter()
                .filter_map(|s| {
                    s.metrics.as_ref().ok().map(|m| format!("    {}: {}", json_str(&s.name), json_metrics(Some(m))))
                })
                .collect();
            let mut o = format!(
                "{{\n  \"alg\": {},\n  \"mask\": {},\n  \"scale\": {},\n  \"scenes\": {{{}}},\n  \"weighted\": {},\n  \
                 \"mean\": {}",
                json_str(&r.alg),
                json_str(r.mask.name()),
                r.scale,
                if scenes.is_empty() { String::new() } else { format!("\n{}\n  ", scenes.join(",\n")) },
                json_metrics(r.weighted().as_ref()),
                json_metrics(r.mean().as_ref()),
            );
            let excluded: Vec<String> =
                r.excluded().map(|(n, e)| format!("{}: {}", json_str(n), json_str(e))).collect();
            if !excluded.is_empty() {
                let _ = write!(o, ",\n  \"excluded\": {{{}}}", excluded.join(", "));
            }
            if let Some(p) = paper[i] {
                let scenes: Vec<String> =
                    p.scenes.iter().map(|(k, v)| format!("{}: {}", json_str(k), json_num(*v))).collect();
                let _ = write!(
                    o,
                    ",\n  \"paper\": {{\"column\": {}, \"scenes\": {{{}}}, \"weighted\": {}}}",
                    json_str(&p.name),
                    scenes.join(", "),
                    p.weighted.map_or("null".into(), json_num)
                );
            }
            o.push_str("\n}");
            o
        })
        .collect();
    if objects.len() == 1 { format!("{}\n", objects[0]) } else { format!("[\n{}\n]\n", objects.join(",\n")) }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() }
}

fn csv_num(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v}"),
        Some(_) => "nan".into(),
        None => String::new(),
    }
}

fn render_csv(reports: &[AlgReport], paper: &[Option<&PaperColumn>]) -> String {
    let mut out = format!("alg,mask,scale,scene,weight,{},time_s,paper,error\n", Metrics::NAMES.join(","));
    for (i, r) in reports.iter().enumerate() {
        let p = paper[i];
        let prefix = format!("{},{},{}", csv_field(&r.alg), r.mask.name(), r.scale);
        let mut row =
            |scene: &str, weight: Option<f64>, m: Option<&Metrics>, t: Option<f64>, pv: Option<f64>, e: &str| {
                let values: Vec<String> = match m {
                    Some(m) => m.values().iter().map(|v| csv_num(Some(*v))).collect(),
                    None => vec![String::new(); 8],
                };
                let _ = writeln!(
                    out,
                    "{prefix},{},{},{},{},{},{}",
                    csv_field(scene),
                    csv_num(weight),
                    values.join(","),
                    csv_num(t),
                    csv_num(pv),
                    csv_field(e)
                );
            };
        for s in &r.scenes {
            let pv = p.and_then(|p| p.scenes.get(&s.name).copied());
            match &s.metrics {
                Ok(m) => row(&s.name, Some(s.weight), Some(m), s.seconds, pv, ""),
                Err(e) => row(&s.name, Some(s.weight), None, s.seconds, pv, e),
            }
        }
        let mean_t = r.mean_seconds().map(|(t, _)| t);
        row("weighted", None, r.weighted().as_ref(), None, p.and_then(|p| p.weighted), "");
        row("mean", None, r.mean().as_ref(), mean_t, None, "");
    }
    out
}

/// Two decimals, `nan` for NaN, `-` for nothing.
fn fixed(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v:.2}"),
        Some(_) => "nan".into(),
        None => "-".into(),
    }
}

/// A table as rows of cells; the first row is the header. `numeric[c]` right-aligns column c.
struct Grid {
    rows: Vec<Vec<String>>,
    numeric: Vec<bool>,
}

impl Grid {
    fn text(&self) -> String {
        let ncol = self.rows[0].len();
        let widths: Vec<usize> =
            (0..ncol).map(|c| self.rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0)).collect();
        let mut out = String::new();
        for r in &self.rows {
            let cells: Vec<String> = r
                .iter()
                .enumerate()
                .map(|(c, v)| {
                    if self.numeric[c] { format!("{v:>w$}", w = widths[c]) } else { format!("{v:<w$}", w = widths[c]) }
                })
                .collect();
            out.push_str(cells.join("  ").trim_end());
            out.push('\n');
        }
        out
    }

    fn markdown(&self) -> String {
        let mut out = String::new();
        let line =
            |r: &[String]| format!("| {} |\n", r.iter().map(|c| c.replace('|', "\\|")).collect::<Vec<_>>().join(" | "));
        out.push_str(&line(&self.rows[0]));
        let rule: Vec<String> = self.numeric.iter().map(|&n| if n { "---:".into() } else { "---".into() }).collect();
        out.push_str(&format!("|{}|\n", rule.join("|")));
        for r in &self.rows[1..] {
            out.push_str(&line(r));
        }
        out
    }

    fn render(&self, markdown: bool) -> String {
        if markdown { self.markdown() } else { self.text() }
    }
}

fn render_text(reports: &[AlgReport], paper: &[Option<&PaperColumn>], md: bool) -> String {
    let mut out = String::new();
    if reports.len() > 1 {
        out.push_str(&summary_grid(reports, paper).render(md));
        out.push('\n');
    }
    for (i, r) in reports.iter().enumerate() {
        let p = paper[i];
        let title = format!(
            "{} — mask {}, errors ×{} (full-resolution px){}",
            r.alg,
            r.mask.name(),
            r.scale,
            p.map(|p| format!(", paper column {}", p.name)).unwrap_or_default()
        );
        if md {
            let _ = writeln!(out, "#### {title}\n");
        } else {
            let _ = writeln!(out, "{title}");
        }
        let mut header: Vec<String> = vec!["scene".into(), "weight".into(), "avgErr".into()];
        if p.is_some() {
            header.push("paper".into());
        }
        header.extend(["rms", "bad0.5", "bad1", "bad2", "bad4", "invalid", "totbad2", "time s"].map(String::from));
        let ncol = header.len();
        let mut rows = vec![header];
        let mut push = |name: String, weight: String, m: Option<&Metrics>, pv: Option<f64>, t: Option<f64>| {
            let v = m.map(Metrics::values);
            let mut r = vec![name, weight, fixed(v.map(|v| v[0]))];
            if p.is_some() {
                r.push(fixed(pv));
            }
            r.extend((1..8).map(|k| fixed(v.map(|v| v[k]))));
            r.push(t.map_or("-".into(), |t| format!("{t:.3}")));
            rows.push(r);
        };
        for s in &r.scenes {
            let pv = p.and_then(|p| p.scenes.get(&s.name).copied());
            let name = if s.metrics.is_ok() { s.name.clone() } else { format!("{} (excluded)", s.name) };
            push(name, format!("{}", s.weight), s.metrics.as_ref().ok(), pv, s.seconds);
        }
        let strong = |s: &str| {
            if md { format!("**{s}**") } else { s.to_string() }
        };
        push(strong("weighted"), String::new(), r.weighted().as_ref(), p.and_then(|p| p.weighted), None);
        push("mean".into(), String::new(), r.mean().as_ref(), None, r.mean_seconds().map(|(t, _)| t));
        let mut numeric = vec![true; ncol];
        numeric[0] = false;
        out.push_str(&Grid { rows, numeric }.render(md));
        let evaluated = r.scenes.iter().filter(|s| s.metrics.is_ok()).count();
        let mut notes = vec![format!("{evaluated} of {} scenes evaluated", r.scenes.len())];
        if let Some((t, k)) = r.mean_seconds() {
            notes.push(format!("mean time per pair {t:.3} s (over {k})"));
        }
        if md {
            out.push('\n');
        }
        let _ = writeln!(out, "{}.", notes.join("; "));
        let excluded: Vec<(&str, &str)> = r.excluded().collect();
        if !excluded.is_empty() {
            let _ = writeln!(out, "Excluded from the averages:");
            for (n, e) in excluded {
                let _ = writeln!(out, "{}{n}: {e}", if md { "- " } else { "  " });
            }
        }
        out.push('\n');
    }
    out
}

/// One row per algorithm: weighted and mean avgErr (and the paper's), weighted bad2 and invalid, mean time.
fn summary_grid(reports: &[AlgReport], paper: &[Option<&PaperColumn>]) -> Grid {
    let has_paper = paper.iter().any(Option::is_some);
    let mut header: Vec<String> = vec!["alg".into(), "weighted avgErr".into()];
    if has_paper {
        header.extend(["paper".into(), "paper column".into()]);
    }
    header.extend(["mean avgErr", "weighted bad2", "weighted invalid", "scenes", "mean time s"].map(String::from));
    let mut rows = vec![header];
    for (i, r) in reports.iter().enumerate() {
        let w = r.weighted();
        let mut row = vec![r.alg.clone(), fixed(w.map(|m| m.avgerr))];
        if has_paper {
            let p = paper[i];
            row.push(fixed(p.and_then(|p| p.weighted)));
            row.push(p.map_or("-".into(), |p| p.name.clone()));
        }
        row.push(fixed(r.mean().map(|m| m.avgerr)));
        row.push(fixed(w.map(|m| m.bad2)));
        row.push(fixed(w.map(|m| m.invalid)));
        row.push(format!("{}/{}", r.scenes.iter().filter(|s| s.metrics.is_ok()).count(), r.scenes.len()));
        row.push(r.mean_seconds().map_or("-".into(), |(t, _)| format!("{t:.3}")));
        rows.push(row);
    }
    let ncol = rows[0].len();
    let numeric = (0..ncol).map(|c| !(c == 0 || (has_paper && c == 3))).collect();
    Grid { rows, numeric }
}

#[cfg(test)]
mod tests {
    use super::*;

    const INF: f32 = f32::INFINITY;

    /// 8 pixels: GT, result and mask chosen so each rule of the module doc is exercised once.
    fn fixture() -> (DisparityMap, DisparityMap, Plane<u8>) {
        //                     0    1      2    3    4     5     6     7
        let gt = vec![1.0, 2.0, 3.0, INF, 5.0, 6.0, 7.0, 8.0];
        let result = vec![1.0, 2.625, INF, 4.0, 11.0, -1.0, 7.25, 8.0];
        let mask = vec![255, 255, 255, 255, 255, 128, 0, 255];
        (Plane::from_vec(4, 2, result), Plane::from_vec(4, 2, gt), Plane::from_vec(4, 2, mask))
    }

    fn assert_close(m: &Metrics, want: [f64; 8], n: u64) {
        assert_eq!(m.pixels, n);
        for ((k, got), want) in Metrics::NAMES.iter().zip(m.values()).zip(want) {
            assert!((got - want).abs() < 1e-9, "{k}: got {got}, want {want}");
        }
    }

    #[test]
    fn nonocc_by_hand() {
        // Evaluated: 0, 1, 2, 4, 7 (3 has no GT, 5 is occluded, 6 has mask 0) → n = 5. Pixel 2 is invalid.
        // Errors of the valid ones: 0, 0.625, |min(11, 10) − 5| = 5 (clipped to ndisp = 10), 0.
        let (r, g, m) = fixture();
        let got = evaluate(&r, &g, Some(&m), 10, 1, MaskMode::Nonocc);
        let rms = ((0.625f64.powi(2) + 25.0) / 4.0).sqrt();
        assert_close(&got, [5.625 / 4.0, rms, 40.0, 20.0, 20.0, 20.0, 20.0, 40.0], 5);
    }

    #[test]
    fn all_mask_counts_occluded() {
        // Adds pixel 5 (mask 128): −1 clips to 0, error 6. n = 6, valid 5.
        let (r, g, m) = fixture();
        let got = evaluate(&r, &g, Some(&m), 10, 1, MaskMode::All);
        let rms = ((0.625f64.powi(2) + 25.0 + 36.0) / 5.0).sqrt();
        let p = |k: f64| 100.0 * k / 6.0;
        assert_close(&got, [11.625 / 5.0, rms, p(3.0), p(2.0), p(2.0), p(2.0), p(1.0), p(3.0)], 6);
    }

    #[test]
    fn scale_four_multiplies_errors_not_clipping() {
        // Errors ×4: 0, 2.5, 20, 0 → bad0.5 = bad1 = bad2 = 2/5, bad4 = 1/5.
        let (r, g, m) = fixture();
        let got = evaluate(&r, &g, Some(&m), 10, 4, MaskMode::Nonocc);
        let rms = ((2.5f64.powi(2) + 400.0) / 4.0).sqrt();
        assert_close(&got, [22.5 / 4.0, rms, 40.0, 40.0, 40.0, 20.0, 20.0, 60.0], 5);
    }

    #[test]
    fn no_mask_means_every_gt_pixel() {
        // n = 7 (all but pixel 3); pixel 6 adds error 0.25.
        let (r, g, _) = fixture();
        let got = evaluate(&r, &g, None, 10, 1, MaskMode::Nonocc);
        let p = |k: f64| 100.0 * k / 7.0;
        let rms = ((0.625f64.powi(2) + 25.0 + 36.0 + 0.0625) / 6.0).sqrt();
        assert_close(&got, [11.875 / 6.0, rms, p(3.0), p(2.0), p(2.0), p(2.0), p(1.0), p(3.0)], 7);
    }

    #[test]
    fn thresholds_are_strict_and_clip_is_inclusive() {
        // err exactly 0.5, 1, 2, 4 → never bad; d = ndisp exactly is not clipped.
        let gt = Plane::from_vec(5, 1, vec![0.0, 0.0, 0.0, 0.0, 8.0]);
        let r = Plane::from_vec(5, 1, vec![0.5, 1.0, 2.0, 4.0, 8.0]);
        let got = evaluate(&r, &gt, None, 8, 1, MaskMode::All);
        assert_close(&got, [7.5 / 5.0, (21.25f64 / 5.0).sqrt(), 60.0, 40.0, 20.0, 0.0, 0.0, 20.0], 5);
        let r = Plane::from_vec(5, 1, vec![0.0, 0.0, 0.0, 0.0, 9.0]);
        assert_eq!(evaluate(&r, &gt, None, 8, 1, MaskMode::All).avgerr, 0.0);
        // NaN and −inf are invalid too.
        let r = Plane::from_vec(5, 1, vec![f32::NAN, f32::NEG_INFINITY, 0.0, 0.0, 8.0]);
        let got = evaluate(&r, &gt, None, 8, 1, MaskMode::All);
        assert_close(&got, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 40.0, 40.0], 5);
    }

    #[test]
    fn all_invalid_gives_nan_errors() {
        let gt = Plane::from_vec(2, 1, vec![1.0, 2.0]);
        let r = Plane::from_vec(2, 1, vec![INF, INF]);
        let m = evaluate(&r, &gt, None, 8, 4, MaskMode::All);
        assert!(m.avgerr.is_nan() && m.rms.is_nan());
        assert_eq!((m.invalid, m.totbad2, m.bad2), (100.0, 100.0, 0.0));
    }

    #[test]
    fn scale_from_middeval_paths() {
        assert_eq!(scale_from_path(Path::new("/d/MiddEval3/trainingQ/Teddy")), Some(4));
        assert_eq!(scale_from_path(Path::new("MiddEval3/testH/Australia")), Some(2));
        assert_eq!(scale_from_path(Path::new("x/trainingF")), Some(1));
        assert_eq!(scale_from_path(Path::new("trainingQ/trainingH/Teddy")), Some(2));
        assert_eq!(scale_from_path(Path::new("/home/PDF/Teddy")), None);
        assert_eq!(scale_from_path(Path::new("trainingX/Teddy")), None);
    }

    fn scene(name: &str, avgerr: f64, ok: bool) -> SceneResult {
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

    #[test]
    fn paper_tsv_parses_and_averages() {
        let text = "# c\nscene\tweight\tA\tB\nTeddy\t1.0\t2.0\t-\nPianoL\t0.5\t5.0\t1.0\n";
        let p = PaperResults::parse(text).unwrap();
        assert_eq!(p.columns(), ["A", "B"]);
        let a = p.column("A").unwrap();
        assert_eq!(a.scenes.get("PianoL"), Some(&5.0));
        assert!((a.weighted.unwrap() - 4.5 / 1.5).abs() < 1e-12);
        assert_eq!(p.column("B").unwrap().scenes.len(), 1);
        assert!(p.column("C").unwrap_err().to_string().contains("A, B"));
        assert!(PaperResults::parse("scene\tweight\tA\nTeddy\t1\n").is_err());
        assert!(PaperResults::parse("scene\tA\n").is_err());
    }

    #[test]
    fn json_shape_and_nan() {
        let mut r = AlgReport {
            alg: "A\"B".into(),
            mask: MaskMode::All,
            scale: 2,
            scenes: vec![scene("Teddy", 1.5, true), scene("Pipes", 0.0, false)],
        };
        if let Ok(m) = &mut r.scenes[0].metrics {
            m.rms = f64::NAN;
        }
        let json = render(&[r], &[], Format::Json);
        assert!(json.starts_with("{\n  \"alg\": \"A\\\"B\",\n  \"mask\": \"all\",\n  \"scale\": 2,\n"), "{json}");
        assert!(json.contains("\"Teddy\": {\"avgerr\": 1.5, \"rms\": null, \"bad0.5\": 0, \"bad1\": 0, \"bad2\": 10,"));
        assert!(json.contains("\"excluded\": {\"Pipes\": \"no result\"}"));
        assert!(!json.contains("\"paper\""));
    }
}
