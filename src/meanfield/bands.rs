//! Label bands (our addition, for tiles; [`crate::pipeline::tile`]): each pixel's marginal is kept to a contiguous run
//! of labels and is 0 outside it, so the update, the splat and the slice of an iteration cost the pixel's band, not the
//! view's whole label range, and only the bands are stored ([`super::packed`]). The blur still runs over every label
//! of a vertex (a vertex gathers pixels near and far: its pixels' bands span most labels).
//!
//! A band holds what the pixel can plausibly take: every answer of the coarse level within the fully connected
//! kernel's reach (3σx), widened by the labels over which the coarse prior still changes its penalty (its margin
//! plus its truncation: beyond that it is flat, and the data alone would have to pull a label there), and the
//! pixel's own best label by its cost alone (what the full resolution sees that the coarse level lost: thin
//! structures). [`LabelBands::around`] builds them; for the right view, around the coarse answer carried over to it
//! ([`warp_to_right_view`]) and the right pixel's own best label.

use rayon::prelude::*;

use crate::image::{DisparityMap, Plane};
use crate::imgproc::filter::window_extreme;

/// Per pixel, the labels `lo..hi` its marginal may hold (the rest are 0), for a `width × height` view of `ndisp`
/// labels.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelBands {
    /// The view's width.
    pub width: usize,
    /// The view's height.
    pub height: usize,
    /// The view's labels.
    pub ndisp: usize,
    /// `[lo, hi]` per pixel, raster order: `lo < hi ≤ ndisp`.
    bands: Vec<[u32; 2]>,
}

impl LabelBands {
    /// Every pixel's band is all `ndisp` labels.
    pub fn full(width: usize, height: usize, ndisp: usize) -> Self {
        LabelBands { width, height, ndisp, bands: vec![[0, ndisp as u32]; width * height] }
    }

    /// The bands around a coarse answer whose pixels allow the disparities `low..=high` (`inf`: no answer at
    /// that pixel) in the labels `0..ndisp`: at each pixel, the smallest `low` and largest `high` within `reach`
    /// pixels (a square), less and plus `half_width` labels, joined with `own_best` ± `own_half_width` (the
    /// pixel's own best label). A pixel with no coarse answer within reach gets all labels.
    ///
    /// # Panics
    /// If the maps differ in size, or `ndisp` is 0.
    pub fn around(
        (low, high): (&DisparityMap, &DisparityMap),
        own_best: &DisparityMap,
        ndisp: usize,
        reach: usize,
        half_width: f32,
        own_half_width: usize,
    ) -> Self {
        assert!(ndisp > 0, "label bands need labels");
        let (w, h) = (low.width, low.height);
        assert!(
            [(high.width, high.height), (own_best.width, own_best.height)].iter().all(|&s| s == (w, h)),
            "label bands: sizes differ"
        );
        let low = window_extreme(low, reach, f32::INFINITY, f32::min);
        let high = window_extreme(high, reach, f32::NEG_INFINITY, f32::max);
        let top = ndisp as f32;
        let bands = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let (dmin, dmax) = (low.data[i], high.data[i]);
                if !dmin.is_finite() {
                    return [0, ndisp as u32];
                }
                let mut lo = (dmin - half_width).floor().clamp(0.0, top - 1.0) as usize;
                let mut hi = ((dmax + half_width).ceil().clamp(0.0, top - 1.0) as usize + 1).max(lo + 1);
                let best = own_best.data[i];
                if best.is_finite() {
                    let best = best.round().clamp(0.0, top - 1.0) as usize;
                    lo = lo.min(best.saturating_sub(own_half_width));
                    hi = hi.max((best + own_half_width + 1).min(ndisp));
                }
                [lo as u32, hi as u32]
            })
            .collect();
        LabelBands { width: w, height: h, ndisp, bands }
    }

    /// The labels `(lo, hi)` of pixel `i`.
    #[inline(always)]
    pub fn of(&self, i: usize) -> (usize, usize) {
        let [lo, hi] = self.bands[i];
        (lo as usize, hi as usize)
    }

    /// The bands as `[lo, hi]` per pixel.
    pub fn as_slice(&self) -> &[[u32; 2]] {
        &self.bands
    }

    /// The mean band width in labels.
    pub fn mean_width(&self) -> f64 {
        let sum: u64 = self.bands.iter().map(|&[lo, hi]| u64::from(hi - lo)).sum();
        sum as f64 / self.bands.len().max(1) as f64
    }

    /// The same bands on labels grouped `step` at a time (group g: labels g·step … g·step + step − 1): each
    /// pixel's groups are those that hold any of its labels.
    pub fn grouped(&self, step: usize) -> Self {
        let step = step.max(1) as u32;
        let bands = self.bands.iter().map(|&[lo, hi]| [lo / step, hi.div_ceil(step)]).collect();
        LabelBands { width: self.width, height: self.height, ndisp: self.ndisp.div_ceil(step as usize), bands }
    }

    /// The bands of the columns `x0..` (for a view that starts there).
    pub fn columns_from(&self, x0: usize) -> Self {
        let w = self.width - x0;
        let bands = self.bands.chunks_exact(self.width).flat_map(|row| row[x0..].iter().copied()).collect();
        LabelBands { width: w, height: self.height, ndisp: self.ndisp, bands }
    }
}

/// The right view's side of a left view's allowed disparities `low..=high` (`inf`: none): left pixel x lands on
/// right pixel x − low (rounded; the right volume of [`crate::cost::derive_right_volume`] matches right pixel x at
/// label d with left pixel x + d), and a right pixel that several left pixels land on allows all their ranges; `inf`
/// where none lands (occluded in the left view).
pub(crate) fn warp_to_right_view(low: &DisparityMap, high: &DisparityMap) -> (DisparityMap, DisparityMap) {
    let (w, h) = (low.width, low.height);
    let mut right_low = Plane::new(w, h, f32::INFINITY);
    let mut right_high = Plane::new(w, h, f32::INFINITY);
    right_low.data.par_chunks_mut(w.max(1)).zip(right_high.data.par_chunks_mut(w.max(1))).enumerate().for_each(
        |(y, (rl, rh))| {
            for (x, (&lo, &hi)) in low.row(y).iter().zip(high.row(y)).enumerate() {
                let Some(xr) = (lo.is_finite() && hi.is_finite()).then(|| x as f32 - lo.round()) else { continue };
                if xr < 0.0 || xr >= w as f32 {
                    continue;
                }
                let xr = xr as usize;
                let first = !rh[xr].is_finite();
                rl[xr] = if first { lo } else { rl[xr].min(lo) };
                rh[xr] = if first { hi } else { rh[xr].max(hi) };
            }
        },
    );
    (right_low, right_high)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_hold_the_coarse_answers_within_reach_and_the_own_best() {
        let (w, h, m) = (12, 5, 40);
        let mut coarse = Plane::new(w, h, 10.0f32);
        coarse.data[2 * w + 8] = 20.0;
        coarse.data[0] = f32::INFINITY;
        let mut best = Plane::new(w, h, 10.0f32);
        best.data[4 * w] = 33.0;
        let bands = LabelBands::around((&coarse, &coarse), &best, m, 2, 3.0, 1);
        // Within 2 px of (8, 2): 10 − 3 ..= 20 + 3.
        assert_eq!(bands.of(2 * w + 6), (7, 24));
        assert_eq!(bands.of(4 * w + 10), (7, 24));
        // Out of its reach: 10 ± 3.
        assert_eq!(bands.of(2 * w + 5), (7, 14));
        // The own best label joins: 33 ± 1.
        assert_eq!(bands.of(4 * w), (7, 35));
        // Clipped to the labels.
        let wide = LabelBands::around((&coarse, &coarse), &best, m, 2, 30.0, 1);
        assert_eq!(wide.of(2 * w + 7), (0, 40));
        // No coarse answer within reach: all labels.
        let nothing = Plane::new(w, h, f32::INFINITY);
        let none = LabelBands::around((&nothing, &nothing), &best, m, 2, 3.0, 1);
        assert!((0..w * h).all(|i| none.of(i) == (0, m)));
        assert!((bands.mean_width() - 7.0).abs() < 5.0);
    }

    /// A grouped band holds every group that holds one of the pixel's labels, and no other.
    #[test]
    fn grouped_bands_hold_the_groups_of_their_labels() {
        let (w, m) = (5, 11);
        let coarse = Plane::from_parts(w, 1, vec![0.0, 3.0, 4.0, 7.0, 10.0]);
        let bands = LabelBands::around((&coarse, &coarse), &Plane::new(w, 1, f32::INFINITY), m, 0, 1.0, 0);
        for step in 1..=4 {
            let grouped = bands.grouped(step);
            assert_eq!((grouped.width, grouped.height, grouped.ndisp), (w, 1, m.div_ceil(step)));
            for i in 0..w {
                let (lo, hi) = bands.of(i);
                let (glo, ghi) = grouped.of(i);
                let holds = |g: usize| (g * step..(g + 1) * step).any(|d| (lo..hi).contains(&d));
                assert!((0..grouped.ndisp).all(|g| holds(g) == (glo..ghi).contains(&g)), "step {step}, pixel {i}");
            }
        }
    }

    /// Left pixels land on the right pixel x − d; where several land, the right pixel allows all their ranges.
    #[test]
    fn the_right_view_allows_what_lands_on_it() {
        let (w, h) = (8, 1);
        let low = Plane::from_parts(w, h, vec![0.0, 1.0, 1.0, f32::INFINITY, 3.0, 2.0, 4.0, 2.0]);
        let high = Plane::from_parts(w, h, vec![0.0, 1.0, 2.0, f32::INFINITY, 3.0, 2.0, 5.0, 2.0]);
        let (rl, rh) = warp_to_right_view(&low, &high);
        // x 0 → 0, 1 → 0, 2 → 1, 4 → 1, 5 → 3, 6 → 2, 7 → 5.
        let inf = f32::INFINITY;
        assert_eq!(rl.data, vec![0.0, 1.0, 4.0, 2.0, inf, 2.0, inf, inf]);
        assert_eq!(rh.data, vec![1.0, 3.0, 5.0, 2.0, inf, 2.0, inf, inf]);
        let (w, m) = (30, 12);
        let coarse = Plane::from_parts(w, 2, (0..w * 2).map(|i| ((i % w) % 7) as f32).collect());
        let bands = LabelBands::around((&coarse, &coarse), &Plane::new(w, 2, f32::INFINITY), m, 1, 1.0, 0);
        let cut = bands.columns_from(4);
        assert_eq!((cut.width, cut.of(w - 4 + 3)), (w - 4, bands.of(w + 7)));
    }
}
