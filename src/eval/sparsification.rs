//! How well a confidence map ranks a result's errors: the area under the sparsification curve (Hu & Mordohai,
//! "A quantitative evaluation of confidence measures for stereo vision", PAMI 2012).
//!
//! Over the pixels [`evaluate`](super::evaluate) scores (finite ground truth, selected by the mask), sorted by
//! confidence, most confident first (ties: raster order; a NaN confidence counts as −∞), keep the first
//! ⌊n·k/20⌋ (at least 1) for k = 1..20 (densities 5 %, 10 %, …, 100 %) and take the share of *bad* pixels among
//! them: off by more than `bad_px` (at the result's resolution), or invalid (not finite). The AUC is the mean of the
//! 20 shares; its optimum is the same with the pixels sorted by their true error (bad ones last), and a random order
//! gives the bad share at 100 %, on average. Smaller is better.

use crate::image::{DisparityMap, Plane};

use super::MaskMode;

/// The densities the curve is sampled at: 5 %, 10 %, …, 100 %.
const DENSITIES: usize = 20;

/// The area under a confidence map's sparsification curve and its optimum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sparsification {
    /// The mean share of bad pixels among the most confident 5 %, 10 %, …, 100 %.
    pub auc: f64,
    /// The same for the pixels sorted by their true error: the best any confidence can do on this result.
    pub optimum: f64,
}

/// The sparsification AUC of `confidence` for `result` against `gt` (see the module doc); `None` when no pixel is
/// scored.
///
/// # Panics
/// If the maps (and the mask) differ in size.
///
/// # Examples
/// ```
/// use jem::{Plane, eval::{sparsification, MaskMode}};
/// let gt = Plane::from_vec(2, 1, vec![3.0, 3.0])?;
/// let result = Plane::from_vec(2, 1, vec![3.0, 9.0])?;
/// let right_way = Plane::from_vec(2, 1, vec![0.9, 0.1])?;
/// let s = sparsification(&right_way, &result, &gt, None, MaskMode::All, 1.0).unwrap();
/// assert_eq!((s.auc, s.optimum), (0.025, 0.025));
/// # Ok::<(), jem::Error>(())
/// ```
pub fn sparsification(
    confidence: &Plane<f32>,
    result: &DisparityMap,
    gt: &DisparityMap,
    mask: Option<&Plane<u8>>,
    mask_mode: MaskMode,
    bad_px: f32,
) -> Option<Sparsification> {
    assert_eq!(confidence.dims(), gt.dims(), "confidence and ground truth sizes differ");
    assert_eq!(result.dims(), gt.dims(), "result and ground truth sizes differ");
    if let Some(m) = mask {
        assert_eq!(m.dims(), gt.dims(), "mask and ground truth sizes differ");
    }
    let mut scored: Vec<(f32, bool)> = (0..gt.data.len())
        .filter(|&i| gt.data[i].is_finite() && mask.is_none_or(|m| mask_mode.selects(m.data[i])))
        .map(|i| {
            let d = result.data[i];
            let bad = !d.is_finite() || (d - gt.data[i]).abs() > bad_px;
            let c = confidence.data[i];
            (if c.is_nan() { f32::NEG_INFINITY } else { c }, bad)
        })
        .collect();
    if scored.is_empty() {
        return None;
    }
    // Stable: equal confidences keep their raster order.
    scored.sort_by(|a, b| b.0.total_cmp(&a.0));
    let n = scored.len();
    let mut bad_before = Vec::with_capacity(n + 1);
    bad_before.push(0usize);
    for &(_, bad) in &scored {
        bad_before.push(bad_before.last().copied().unwrap_or(0) + usize::from(bad));
    }
    let bad = bad_before[n];
    let kept = |k: usize| (n * k / DENSITIES).max(1);
    let mean = |share: &dyn Fn(usize) -> f64| (1..=DENSITIES).map(|k| share(kept(k))).sum::<f64>() / DENSITIES as f64;
    let auc = mean(&|m| bad_before[m] as f64 / m as f64);
    // Sorted by the true error, the first n − bad are good.
    let optimum = mean(&|m| m.saturating_sub(n - bad) as f64 / m as f64);
    Some(Sparsification { auc, optimum })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definition, literally: sort, cut at each density, count.
    fn brute_force(conf: &[f32], bad: &[bool]) -> f64 {
        let mut idx: Vec<usize> = (0..conf.len()).collect();
        idx.sort_by(|&a, &b| conf[b].partial_cmp(&conf[a]).unwrap().then(a.cmp(&b)));
        let n = conf.len() as f64;
        let mut sum = 0.0;
        for k in 1..=20 {
            let m = ((n * k as f64 / 20.0).floor() as usize).max(1);
            sum += idx[..m].iter().filter(|&&i| bad[i]).count() as f64 / m as f64;
        }
        sum / 20.0
    }

    #[test]
    fn the_auc_is_the_brute_force_definition() {
        let gt = Plane::from_parts(9, 1, vec![5.0, 5.0, 5.0, 5.0, f32::INFINITY, 5.0, 5.0, 5.0, 5.0]);
        let result = Plane::from_parts(9, 1, vec![5.0, 7.0, 5.5, f32::INFINITY, 0.0, 5.0, 9.0, 4.2, 5.0]);
        let conf = Plane::from_parts(9, 1, vec![0.5, 0.9, 0.5, 0.0, 1.0, 0.2, 0.7, 0.6, 0.5]);
        let s = sparsification(&conf, &result, &gt, None, MaskMode::All, 1.0).unwrap();
        // Pixel 4 has no ground truth; 1, 3 (invalid) and 6 are bad.
        let kept = [0, 1, 2, 3, 5, 6, 7, 8];
        let c: Vec<f32> = kept.iter().map(|&i| conf.data[i]).collect();
        let bad: Vec<bool> = kept.iter().map(|&i| [1, 3, 6].contains(&i)).collect();
        assert!((s.auc - brute_force(&c, &bad)).abs() < 1e-12, "{} vs {}", s.auc, brute_force(&c, &bad));
        let by_error: Vec<f32> = bad.iter().map(|&b| if b { 0.0 } else { 1.0 }).collect();
        assert!((s.optimum - brute_force(&by_error, &bad)).abs() < 1e-12);
        assert!(s.optimum < s.auc);
    }

    #[test]
    fn the_mask_selects_the_pixels_and_an_empty_selection_has_no_auc() {
        let gt = Plane::from_parts(2, 1, vec![1.0, 1.0]);
        let result = Plane::from_parts(2, 1, vec![1.0, 3.0]);
        let conf = Plane::from_parts(2, 1, vec![0.0, 1.0]);
        let mask = Plane::from_parts(2, 1, vec![255u8, 0]);
        let s = sparsification(&conf, &result, &gt, Some(&mask), MaskMode::Nonocc, 1.0).unwrap();
        assert_eq!((s.auc, s.optimum), (0.0, 0.0));
        let none = Plane::from_parts(2, 1, vec![0u8, 0]);
        assert_eq!(sparsification(&conf, &result, &gt, Some(&none), MaskMode::Nonocc, 1.0), None);
    }
}
