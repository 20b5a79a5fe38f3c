//! **A region matched a period off on repetitive texture**: where the left view repeats itself along the row within
//! the search range (a chessboard, a fence, a tiled wall), a shift by one period matches about as well as the right
//! one, and a whole region can take the wrong repetition together. The check looks for blocks that are both:
//!
//! - *repetitive*: the block's normalised cross-correlation with itself moved along the row by L px, for L within
//!   the range's width (a wrong repetition must be one the search could reach), falls below [`LOBE`] (past the
//!   texture's own blur) and then comes back above [`PEAK`] at some lag: the period;
//! - and *suspect*: either doubtful, the answer's mean confidence over the block below ½ (the confidence is the
//!   probability that the answer is within 1 px, [`crate::post::confidence`]: more likely wrong than right); or a
//!   period off, the block in a part of the repetitive region whose answer differs from a touching part's by a
//!   whole number of periods ([`period_off`]): the same texture matched at two repetitions. A rig whose repetitive
//!   region is matched right has it confident and in one piece.
//!
//! The largest 4-connected set of such blocks, as a share of the image, past [`MIN_SHARE`], is a warning with its
//! period (the median of its blocks') and where it is.
//!
//! # Cost
//! At most [`MAX_WIDTH`] px wide (the view reduced by an integer factor): blocks × lags × block pixels, rows of
//! blocks in parallel, each block summed by one thread (the result does not depend on the thread count).

use rayon::prelude::*;

use crate::image::{DisparityMap, Plane, RgbImage};
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

/// Two blocks' answers within this (px at the reduced resolution) are the same answer.
const SAME_PX: f32 = 1.0;

/// The shortest period (px at the reduced resolution) a step between answers is compared with: a shorter one is
/// within [`SAME_PX`] of too many steps.
const MIN_PERIOD: usize = 4;

/// A repetitive, doubtful region larger than this share of the image is reported.
pub(super) const MIN_SHARE: f32 = 0.05;

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

/// A block of the reduced view (see [`repetitive_region`]): its period where its texture repeats itself, its
/// answer's median disparity (reduced px; `NaN` where none is valid) and whether its answer is doubtful.
#[derive(Clone, Copy)]
struct Block {
    period: Option<usize>,
    disparity: f32,
    doubtful: bool,
}

/// The largest region of repetitive texture (periods below `range_px`, the search range's width) whose answer
/// `disparity` is doubtful by `confidence` or a period off its neighbour's (see the module doc); `None` when there
/// is none.
///
/// # Panics
/// If the view, the answer and the confidence differ in size.
pub(super) fn repetitive_region(
    left: &RgbImage,
    disparity: &DisparityMap,
    confidence: &Plane<f32>,
    range_px: usize,
) -> Option<Repetition> {
    let (w, h) = left.dims();
    assert_eq!(confidence.dims(), (w, h), "view and confidence differ in size");
    assert_eq!(disparity.dims(), (w, h), "view and answer differ in size");
    let factor = w.div_ceil(MAX_WIDTH).max(1);
    let grey = downsample_rgb(left, factor).to_grey();
    let (bw, bh) = (grey.width() / BLOCK, grey.height() / BLOCK);
    let max_lag = (range_px / factor).min(grey.width() / 2);
    if bw == 0 || bh == 0 || max_lag < 2 {
        return None;
    }
    let side = BLOCK * factor;
    let blocks: Vec<Block> = (0..bh)
        .into_par_iter()
        .flat_map_iter(|by| {
            let grey = &grey;
            (0..bw).map(move |bx| {
                let cells =
                    (by * side..(by + 1) * side).flat_map(|y| (bx * side..(bx + 1) * side).map(move |x| y * w + x));
                let (mut c, mut d) = (0.0f32, Vec::with_capacity(side * side));
                for i in cells {
                    c += confidence.data()[i];
                    d.extend(Some(disparity.data()[i] / factor as f32).filter(|v| v.is_finite()));
                }
                let disparity = if d.is_empty() { f32::NAN } else { crate::imgproc::stats::rank_value(&mut d, 0.5) };
                let doubtful = c / ((side * side) as f32) < DOUBTFUL;
                Block { period: block_period(grey, bx * BLOCK, by * BLOCK, max_lag), disparity, doubtful }
            })
        })
        .collect();
    let off = period_off(&blocks, bw, bh);
    let suspect: Vec<bool> =
        blocks.iter().zip(&off).map(|(b, &off)| b.period.is_some() && (b.doubtful || off)).collect();
    let (labels, sizes) = components(bw, bh, |i| suspect[i], |_, _| true);
    let largest = (0..sizes.len()).max_by_key(|&k| (sizes[k], std::cmp::Reverse(k)))?;
    let region: Vec<usize> = (0..blocks.len()).filter(|&i| labels[i] == Some(largest)).collect();
    let mut found: Vec<f32> = region.iter().filter_map(|&i| blocks[i].period).map(|p| p as f32).collect();
    let period = crate::imgproc::stats::rank_value(&mut found, 0.5) * factor as f32;
    let (xs, ys) = (region.iter().map(|i| i % bw), region.iter().map(|i| i / bw));
    let bounds = [xs.clone().min()? * side, ys.clone().min()? * side, (xs.max()? + 1) * side, (ys.max()? + 1) * side];
    let share = (region.len() * side * side) as f32 / (w * h) as f32;
    let [x0, y0, x1, y1] = bounds;
    Some(Repetition { share, period_px: period, bounds: [x0.min(w), y0.min(h), x1.min(w), y1.min(h)] })
}

/// The blocks of repetitive texture that lie in a part of their region answered a whole number of periods off a
/// neighbouring part: the region's blocks split into parts of one answer (neighbours within [`SAME_PX`]); of two
/// touching parts whose answers differ by about k periods (k ≥ 1, within [`SAME_PX`] or a tenth of the period),
/// the smaller one is off (which one is wrong the answer cannot say; the smaller one is the likelier).
fn period_off(blocks: &[Block], bw: usize, bh: usize) -> Vec<bool> {
    let same = |a: f32, b: f32| (a - b).abs() <= SAME_PX;
    let repeating = |i: usize| blocks[i].period.is_some() && blocks[i].disparity.is_finite();
    let (labels, sizes) = components(bw, bh, repeating, |i, j| same(blocks[i].disparity, blocks[j].disparity));
    let mut off = vec![false; sizes.len()];
    for i in 0..blocks.len() {
        let (Some(a), Some(p)) = (labels[i], blocks[i].period.filter(|&p| p >= MIN_PERIOD)) else { continue };
        for j in [i + 1, i + bw].into_iter().filter(|&j| j < blocks.len() && (j != i + 1 || (i + 1) % bw != 0)) {
            let Some(b) = labels[j].filter(|&b| b != a) else { continue };
            let step = (blocks[i].disparity - blocks[j].disparity).abs();
            let k = (step / p as f32).round();
            if k >= 1.0 && (step - k * p as f32).abs() <= SAME_PX.max(0.1 * p as f32) {
                off[if sizes[a] < sizes[b] { a } else { b }] = true;
            }
        }
    }
    labels.iter().map(|l| l.is_some_and(|l| off[l])).collect()
}

/// The 4-connected components of the blocks `member` selects, two neighbours joined when `joined` says so: each
/// block's component (raster order of first blocks) and each component's size.
fn components(
    bw: usize,
    bh: usize,
    member: impl Fn(usize) -> bool,
    joined: impl Fn(usize, usize) -> bool,
) -> (Vec<Option<usize>>, Vec<usize>) {
    let mut labels = vec![None; bw * bh];
    let mut sizes = Vec::new();
    for start in 0..bw * bh {
        if labels[start].is_some() || !member(start) {
            continue;
        }
        let k = sizes.len();
        let (mut stack, mut size) = (vec![start], 0);
        labels[start] = Some(k);
        while let Some(i) = stack.pop() {
            size += 1;
            let (x, y) = (i % bw, i / bw);
            let near = [(x > 0).then(|| i - 1), (x + 1 < bw).then(|| i + 1), (y > 0).then(|| i - bw)];
            for j in near.into_iter().flatten().chain((y + 1 < bh).then(|| i + bw)) {
                if labels[j].is_none() && member(j) && joined(i, j) {
                    labels[j] = Some(k);
                    stack.push(j);
                }
            }
        }
        sizes.push(size);
    }
    (labels, sizes)
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

    /// An answer of 10 px everywhere but `step` px more in the stripes' right half (columns 128..192).
    fn answer(step: f32) -> DisparityMap {
        Plane::from_parts(
            256,
            192,
            (0..256 * 192).map(|i| if (128..192).contains(&(i % 256)) { 10.0 + step } else { 10.0 }).collect(),
        )
    }

    /// Stripes of period 12 within a range of 32 whose answers are doubtful: found, with their period, share and
    /// place.
    #[test]
    fn doubtful_stripes_within_the_range_are_found_with_their_period() {
        let r = repetitive_region(&striped(12), &answer(0.0), &confidence(256, 192, 0.2), 32).expect("a region");
        assert!((r.period_px - 12.0).abs() <= 1.0, "{r:?}");
        assert!(r.share > 0.4 && r.share < 0.55, "{r:?}");
        assert!(r.bounds[0] >= 48 && r.bounds[2] <= 208, "{r:?}");
    }

    /// The same stripes matched with confidence, or with a period beyond the range, or doubtful answers on
    /// texture that does not repeat: nothing.
    #[test]
    fn confident_stripes_long_periods_and_doubtful_random_texture_are_not() {
        assert_eq!(repetitive_region(&striped(12), &answer(0.0), &confidence(256, 192, 0.8), 32), None);
        assert_eq!(repetitive_region(&striped(40), &answer(0.0), &confidence(256, 192, 0.2), 32), None);
        let doubtful_everywhere = Plane::new(256, 192, 0.2);
        let r = repetitive_region(&striped(12), &answer(0.0), &doubtful_everywhere, 32).expect("the stripes");
        assert!(r.bounds[0] >= 48 && r.bounds[2] <= 208, "only the stripes: {r:?}");
    }

    /// Confident stripes answered at two disparities one or two periods apart: the smaller part is found; a step of
    /// half a period (a depth edge) is not.
    #[test]
    fn stripes_answered_a_period_apart_are_found() {
        let confident = confidence(256, 192, 0.9);
        for step in [12.0, 24.0] {
            let r = repetitive_region(&striped(12), &answer(step), &confident, 32).expect("a period off");
            assert!(r.bounds[0] >= 112 && r.bounds[2] <= 192 && r.share > 0.15, "{step}: {r:?}");
        }
        assert_eq!(repetitive_region(&striped(12), &answer(6.0), &confident, 32), None);
    }
}
