//! Scoring one disparity map against its ground truth with the rules of the MiddEval3 SDK's `evaldisp`:
//! [`evaluate`] on maps in memory, [`evaluate_files`] on files, [`evaluate_scene`] on a MiddEval3 scene folder.
//! Which pixels count, the clipping, the scale to full-resolution pixels, the eight metrics ([`Metrics`]) and
//! the deviations from `evaldisp` are written out in the [`eval`](crate::eval) module doc.
//!
//! Complexity: O(w·h) per scene, one pass, no allocation besides the loaded files.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::dataset::CALIB_FILE;
use crate::error::{Error, Result};
use crate::image::{DisparityMap, Plane};
use crate::io::calib::Calib;

/// The bad-pixel thresholds, in full-resolution pixels.
pub const BAD_THRESHOLDS_PX: [f64; 4] = [0.5, 1.0, 2.0, 4.0];

/// KITTI's D1 outlier: an error above this many pixels ...
pub const D1_THRESHOLD_PX: f64 = 3.0;
/// ... and above this fraction of the true disparity.
pub const D1_RELATIVE: f64 = 0.05;

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
    type Err = Error;
    fn from_str(s: &str) -> std::result::Result<Self, Error> {
        match s {
            "nonocc" => Ok(MaskMode::Nonocc),
            "all" => Ok(MaskMode::All),
            _ => Err(Error::argument(format!("unknown mask {s:?} (expected nonocc or all)"))),
        }
    }
}

/// The scores of one result (or an average of several). Percentages are 0–100; errors are in full-resolution
/// pixels. See the [`eval`](crate::eval) module doc for the exact definitions.
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
    /// KITTI's D1: % of pixels whose result is invalid or off by more than 3 px *and* more than 5 % of the
    /// true disparity.
    pub d1: f64,
    /// Number of pixels evaluated (masked and GT-valid); for an average, the total over its scenes.
    pub pixels: u64,
}

impl Metrics {
    /// Every metric's name, in the order of [`Metrics::values`] (also the JSON and CSV keys).
    pub const KEYS: [&'static str; 9] = ["avgerr", "rms", "bad0.5", "bad1", "bad2", "bad4", "invalid", "totbad2", "d1"];

    /// The metrics a MiddEval3 (and ETH3D) report shows: all but `d1`.
    pub const NAMES: [&'static str; 8] = ["avgerr", "rms", "bad0.5", "bad1", "bad2", "bad4", "invalid", "totbad2"];

    /// The metrics a KITTI report shows: D1 first; `totbad2` is left out because the result is interpolated
    /// before scoring (so `invalid` there is the share before interpolation).
    pub const KITTI_NAMES: [&'static str; 8] = ["d1", "avgerr", "rms", "bad0.5", "bad1", "bad2", "bad4", "invalid"];

    /// The metrics in the order of [`Metrics::KEYS`].
    pub fn values(&self) -> [f64; 9] {
        [self.avgerr, self.rms, self.bad0_5, self.bad1, self.bad2, self.bad4, self.invalid, self.totbad2, self.d1]
    }

    /// The metric named `key` (one of [`Metrics::KEYS`]); NaN for an unknown name.
    pub fn get(&self, key: &str) -> f64 {
        Metrics::KEYS.iter().position(|k| *k == key).map_or(f64::NAN, |i| self.values()[i])
    }

    /// Builds metrics from values in the order of [`Metrics::KEYS`].
    pub fn from_values(v: [f64; 9], pixels: u64) -> Self {
        Metrics {
            avgerr: v[0],
            rms: v[1],
            bad0_5: v[2],
            bad1: v[3],
            bad2: v[4],
            bad4: v[5],
            invalid: v[6],
            totbad2: v[7],
            d1: v[8],
            pixels,
        }
    }
}

/// Scores a disparity map against ground truth (see the [`eval`](crate::eval) module doc for the exact
/// semantics).
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
/// let gt = Plane::from_vec(2, 1, vec![3.0, f32::INFINITY])?;
/// let result = Plane::from_vec(2, 1, vec![3.5, 1.0])?;
/// let m = evaluate(&result, &gt, None, 16, 4, MaskMode::All);
/// assert_eq!((m.avgerr, m.bad1, m.pixels), (2.0, 100.0, 1));
/// # Ok::<(), jem::Error>(())
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
    let mut d1 = 0u64;
    let mut sum = 0.0f64;
    let mut sum_sq = 0.0f64;
    for (i, (&d, &g)) in result.data.iter().zip(&gt.data).enumerate() {
        if !g.is_finite() {
            continue;
        }
        if let Some(m) = mask
            && !mask_mode.selects(m.data[i])
        {
            continue;
        }
        n += 1;
        if !d.is_finite() {
            invalid += 1;
            continue;
        }
        let err = pixel_error(d, g, s, max_d);
        sum += err;
        sum_sq += err * err;
        for (count, &t) in bad.iter_mut().zip(&BAD_THRESHOLDS_PX) {
            *count += u64::from(err > t);
        }
        d1 += u64::from(err > D1_THRESHOLD_PX && err > D1_RELATIVE * s * f64::from(g).abs());
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
        d1: pct(d1 + invalid),
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
    Err(Error::bad_image_at(
        path,
        format!("{what} is {}x{} but {against} is {}x{}", dims.0, dims.1, expected.0, expected.1),
    ))
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
        return Err(Error::dataset_at(gt, format!("no pixel with ground truth under the {} mask", mask_mode.name())));
    }
    Ok(metrics)
}

/// Scores `disp0<alg>.pfm` in a MiddEval3 scene folder against its `disp0GT.pfm`, with `mask0nocc.png` (required
/// for [`MaskMode::Nonocc`]; for [`MaskMode::All`] it is used when present) and `ndisp` from `calib.txt`.
///
/// # Errors
/// As [`evaluate_files`], or a missing/malformed `calib.txt` or mask.
pub fn evaluate_scene(dir: &Path, alg: &str, scale: u32, mask_mode: MaskMode) -> Result<Metrics> {
    let (result, ndisp) = scene_result(dir, alg)?;
    let truth = crate::dataset::Truth::in_scene(dir);
    let mask = truth.mask.unwrap_or_default();
    let mask = match (mask.is_file(), mask_mode) {
        (true, _) => Some(mask),
        (false, MaskMode::All) => None,
        (false, MaskMode::Nonocc) => {
            return Err(Error::dataset(format!("no {} (needed for the nonocc mask)", mask.display())));
        }
    };
    evaluate_files(&result, &truth.disparity, mask.as_deref(), ndisp, scale, mask_mode)
}

/// The error of a valid result `d` against the truth `g` as MiddEval3 scores it: `d` clipped to `[0, max_d]`, the
/// difference in full-resolution pixels (× `scale`).
pub(crate) fn pixel_error(d: f32, g: f32, scale: f64, max_d: f64) -> f64 {
    scale * (f64::from(d).clamp(0.0, max_d) - f64::from(g)).abs()
}

/// A MiddEval3 scene folder's result `disp0<alg>.pfm` (an error when there is none) and `ndisp` from its
/// `calib.txt`.
///
/// # Errors
/// No result file; a missing or malformed `calib.txt` (naming it).
pub(crate) fn scene_result(dir: &Path, alg: &str) -> Result<(PathBuf, usize)> {
    let result = dir.join(format!("disp0{alg}.pfm"));
    if !result.is_file() {
        return Err(Error::dataset(format!("no result file {}", result.display())));
    }
    let calib_path = dir.join(CALIB_FILE);
    let ndisp = Calib::load(&calib_path)?.ndisp()?;
    Ok((result, ndisp))
}

#[cfg(test)]
mod tests {
    use super::*;

    const INF: f32 = f32::INFINITY;

    /// 8 pixels: GT, result and mask chosen so each rule of the `eval` module doc is exercised once.
    fn fixture() -> (DisparityMap, DisparityMap, Plane<u8>) {
        //                     0    1      2    3    4     5     6     7
        let gt = vec![1.0, 2.0, 3.0, INF, 5.0, 6.0, 7.0, 8.0];
        let result = vec![1.0, 2.625, INF, 4.0, 11.0, -1.0, 7.25, 8.0];
        let mask = vec![255, 255, 255, 255, 255, 128, 0, 255];
        (Plane::from_parts(4, 2, result), Plane::from_parts(4, 2, gt), Plane::from_parts(4, 2, mask))
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
        let gt = Plane::from_parts(5, 1, vec![0.0, 0.0, 0.0, 0.0, 8.0]);
        let r = Plane::from_parts(5, 1, vec![0.5, 1.0, 2.0, 4.0, 8.0]);
        let got = evaluate(&r, &gt, None, 8, 1, MaskMode::All);
        assert_close(&got, [7.5 / 5.0, (21.25f64 / 5.0).sqrt(), 60.0, 40.0, 20.0, 0.0, 0.0, 20.0], 5);
        let r = Plane::from_parts(5, 1, vec![0.0, 0.0, 0.0, 0.0, 9.0]);
        assert_eq!(evaluate(&r, &gt, None, 8, 1, MaskMode::All).avgerr, 0.0);
        // NaN and −inf are invalid too.
        let r = Plane::from_parts(5, 1, vec![f32::NAN, f32::NEG_INFINITY, 0.0, 0.0, 8.0]);
        let got = evaluate(&r, &gt, None, 8, 1, MaskMode::All);
        assert_close(&got, [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 40.0, 40.0], 5);
    }

    #[test]
    fn all_invalid_gives_nan_errors() {
        let gt = Plane::from_parts(2, 1, vec![1.0, 2.0]);
        let r = Plane::from_parts(2, 1, vec![INF, INF]);
        let m = evaluate(&r, &gt, None, 8, 4, MaskMode::All);
        assert!(m.avgerr.is_nan() && m.rms.is_nan());
        assert_eq!((m.invalid, m.totbad2, m.bad2), (100.0, 100.0, 0.0));
    }
}
