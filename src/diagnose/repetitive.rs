//! **A region matched a period off on repetitive texture**: where the left view repeats itself along the row within
//! the search range (a chessboard, a fence, a tiled wall), a shift by one period matches about as well as the right
//! one, and a whole region can take the wrong repetition together. The check looks for blocks that are both:
//!
//! - *repetitive*: the block's normalised cross-correlation with itself moved along the row by L px, for L within
//!   the range's width (a wrong repetition must be one the search could reach), falls below [`LOBE`] (past the
//!   texture's own blur) and then comes back above [`PEAK`] at some lag: the period;
//! - *doubtful*: the answer's mean confidence over the block is below ½ (the confidence is the probability that the
//!   answer is within 1 px, [`crate::post::confidence`]): more likely wrong than right. A rig whose repetitive
//!   region is matched right has it confident (the coarse run, the right view and the fine pass agree).
//!
//! The largest 4-connected set of such blocks, as a share of the image, past [`MIN_SHARE`], is a warning with its
//! period (the median of its blocks') and where it is.
//!
//! # Cost
//! At most [`MAX_WIDTH`] px wide (the view reduced by an integer factor): blocks × lags × block pixels, rows of
//! blocks in parallel, each block summed by one thread (the result does not depend on the thread count).

use rayon::prelude::*;

use crate::image::{Plane, RgbImage};
use crate::scale::downsample_rgb;

/// Side of a block (px at the reduced resolution).
const BLOCK: usize = 16;

/// The view is reduced by the smallest integer factor that makes it at most this wide: a period of a few pixels
/// at the working resolution is still a few pixels there, and the lags stay few.
const MAX_WIDTH: usize = 512;

/// The correlation falls below this before a period is looked for (the texture's main lobe is over).
const LOBE: f32 = 0.5;

/// The correlation a shift must come back to for the block to repeat itself there: a match one period off
/// costs about what the right one does.
const PEAK: f32 = 0.7;

/// A block's grey-level standard deviation must exceed this (grey levels) to say anything (a flat block
/// correlates with itself by its noise).
const MIN_STD: f32 = 4.0;

/// The answer is doubtful where its mean confidence is below this: more likely wrong than right.
const DOUBTFUL: f32 = 0.5;

/// A repetitive, doubtful region larger than this share of the image is reported.
pub(super) const MIN_SHARE: f32 = 0.03;

/// The largest connected region of repetitive texture whose answer is doubtful.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Repetition {
    /// Its share of the image (0..1).
    pub share: f32,
    /// The period of its texture along the row (px; the median of its blocks').
    pub period_px: f32,
    /// Its bounding box: left, top, right, bottom (px, inclusive-exclusive).
    pub bounds: [usize; 4],
}

/// The block's period along the row within `max_lag` (px), when it repeats itself (see the module doc).
fn block_period(grey: &Plane<f32>, x0: usize, y0: usize, max_lag: usize) -> Option<usize> {
    let (w, h) = grey.dims();
    let (x1, y1) = ((x0 + BLOCK).min(w), (y0 + BLOCK).min(h));
    let n = ((x1 - x0) * (y1 - y0)) as f32;
    let stats = |dx: isize| {
        let (mut s, mut ss) = (0.0f32, 0.0f32);
        for y in y0..y1 {
            for &v in &grey.row(y)[(x0 as isize + dx) as usize..(x1 as isize + dx) as usize] {
                s += v;
                ss += v * v;
            }
        }
        let mean = s / n;
        (mean, (ss / n - mean * mean).max(0.0).sqrt())
    };
    let (mean, std) = stats(0);
    if std < MIN_STD {
        return None;
    }
    let ncc = |lag: usize| {
        // Moved right where the row allows it, else left.
        let dx = if x1 + lag <= w {
            lag as isize
        } else if x0 >= lag {
            -(lag as isize)
        } else {
            return None;
        };
        let (m2, s2) = stats(dx);
        if s2 < MIN_STD {
            return Some(0.0);
        }
        let mut sum = 0.0f32;
        for y in y0..y1 {
            let a = &grey.row(y)[x0..x1];
            let b = &grey.row(y)[(x0 as isize + dx) as usize..(x1 as isize + dx) as usize];
            sum += a.iter().zip(b).map(|(a, b)| (a - mean) * (b - m2)).sum::<f32>();
        }
        Some(sum / (n * std * s2))
    };
    let mut lag = 1;
    while lag <= max_lag && ncc(lag)? >= LOBE {
        lag += 1;
    }
    // The first lag back above the peak level, then on to the top of that peak, which must lie within the range
    // (a correlation still rising at the range's end peaks beyond it).
    let mut at = (lag + 1..=max_lag).find(|&l| ncc(l).is_some_and(|c| c >= PEAK))?;
    while at <= max_lag && ncc(at + 1) > ncc(at) {
        at += 1;
    }
    (at <= max_lag).then_some(at)
}

/// The largest region of repetitive texture (periods below `range_px`, the search range's width) whose answer is
/// doubtful by `confidence` (see the module doc); `None` when there is none.
///
/// # Panics
/// If the view and the confidence differ in size.
pub(super) fn repetitive_region(left: &RgbImage, confidence: &Plane<f32>, range_px: usize) -> Option<Repetition> {
    let (w, h) = left.dims();
    assert_eq!(confidence.dims(), (w, h), "view and confidence differ in size");
    let factor = w.div_ceil(MAX_WIDTH).max(1);
    let grey = downsample_rgb(left, factor).to_grey();
    let conf = crate::imgproc::filter::box_reduce(confidence, factor);
    let (rw, rh) = grey.dims();
    let (bw, bh) = (rw / BLOCK, rh / BLOCK);
    let max_lag = (range_px / factor).min(rw / 2);
    if bw == 0 || bh == 0 || max_lag < 2 {
        return None;
    }
    // Each block's period where it repeats itself and its answer is doubtful.
    let periods: Vec<Option<usize>> = (0..bh)
        .into_par_iter()
        .flat_map_iter(|by| {
            let (grey, conf) = (&grey, &conf);
            (0..bw).map(move |bx| {
                let (x0, y0) = (bx * BLOCK, by * BLOCK);
                let c: f32 = (y0..y0 + BLOCK).map(|y| conf.row(y)[x0..x0 + BLOCK].iter().sum::<f32>()).sum();
                if c / (BLOCK * BLOCK) as f32 >= DOUBTFUL {
                    return None;
                }
                block_period(grey, x0, y0, max_lag)
            })
        })
        .collect();
    let region = largest_component(&periods, bw, bh)?;
    let mut found: Vec<f32> = region.iter().filter_map(|&i| periods[i]).map(|p| p as f32).collect();
    let period = crate::imgproc::stats::rank_value(&mut found, 0.5) * factor as f32;
    let side = BLOCK * factor;
    let (xs, ys) = (region.iter().map(|i| i % bw), region.iter().map(|i| i / bw));
    let bounds = [xs.clone().min()? * side, ys.clone().min()? * side, (xs.max()? + 1) * side, (ys.max()? + 1) * side];
    let share = (region.len() * side * side) as f32 / (w * h) as f32;
    let [x0, y0, x1, y1] = bounds;
    Some(Repetition { share, period_px: period, bounds: [x0.min(w), y0.min(h), x1.min(w), y1.min(h)] })
}

/// The blocks of the largest 4-connected set of blocks that have a period (the first found on a tie, in raster
/// order).
fn largest_component(periods: &[Option<usize>], bw: usize, bh: usize) -> Option<Vec<usize>> {
    let mut seen = vec![false; periods.len()];
    let mut best: Option<Vec<usize>> = None;
    for start in 0..periods.len() {
        if seen[start] || periods[start].is_none() {
            continue;
        }
        let (mut stack, mut region) = (vec![start], Vec::new());
        seen[start] = true;
        while let Some(i) = stack.pop() {
            region.push(i);
            let (x, y) = (i % bw, i / bw);
            let near = [(x > 0).then(|| i - 1), (x + 1 < bw).then(|| i + 1), (y > 0).then(|| i - bw)];
            for j in near.into_iter().flatten().chain((y + 1 < bh).then(|| i + bw)) {
                if !seen[j] && periods[j].is_some() {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        if best.as_ref().is_none_or(|b| region.len() > b.len()) {
            best = Some(region);
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 256 × 192 view: vertical stripes of period `period` (a sine, grey 60..190) in the middle half of the
    /// columns, seeded noise-like texture elsewhere.
    fn striped(period: usize) -> RgbImage {
        let (w, h) = (256, 192);
        let noise = crate::test_util::rand_vec(w * h, 3);
        let grey: Vec<f32> = (0..w * h)
            .map(|i| {
                let x = i % w;
                if (64..192).contains(&x) {
                    125.0 + 65.0 * (std::f32::consts::TAU * x as f32 / period as f32).sin()
                } else {
                    255.0 * noise[i]
                }
            })
            .collect();
        RgbImage::from_channels(w, h, [grey.clone(), grey.clone(), grey]).unwrap()
    }

    fn confidence(w: usize, h: usize, inside: f32) -> Plane<f32> {
        Plane::from_parts(w, h, (0..w * h).map(|i| if (64..192).contains(&(i % w)) { inside } else { 0.9 }).collect())
    }

    /// Stripes of period 12 within a range of 32 whose answers are doubtful: found, with their period, share and
    /// place.
    #[test]
    fn doubtful_stripes_within_the_range_are_found_with_their_period() {
        let r = repetitive_region(&striped(12), &confidence(256, 192, 0.2), 32).expect("a repetitive region");
        assert!((r.period_px - 12.0).abs() <= 1.0, "{r:?}");
        assert!(r.share > 0.4 && r.share < 0.55, "{r:?}");
        assert!(r.bounds[0] >= 48 && r.bounds[2] <= 208, "{r:?}");
    }

    /// The same stripes matched with confidence, or with a period beyond the range, or doubtful answers on
    /// texture that does not repeat: nothing.
    #[test]
    fn confident_stripes_long_periods_and_doubtful_random_texture_are_not() {
        assert_eq!(repetitive_region(&striped(12), &confidence(256, 192, 0.8), 32), None);
        assert_eq!(repetitive_region(&striped(40), &confidence(256, 192, 0.2), 32), None);
        let doubtful_everywhere = Plane::new(256, 192, 0.2);
        let r = repetitive_region(&striped(12), &doubtful_everywhere, 32).expect("the stripes");
        assert!(r.bounds[0] >= 48 && r.bounds[2] <= 208, "only the stripes: {r:?}");
    }
}
