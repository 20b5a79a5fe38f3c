//! How the camera moved between two frames, seen in their left views: a global shift, what it leaves unexplained
//! (the cut test), and where the frames disagree locally (something moved there).

use rayon::prelude::*;

use crate::image::Plane;
use crate::imgproc::filter::{box_mean, box_reduce};
use crate::imgproc::noise::GREY_DIFFERENCE_PER_SIGMA;
use crate::pipeline::PipelineOutput;

/// The shift search covers ±this many pixels of the search image (the grey image reduced until it is at most
/// [`SEARCH_WIDTH`] wide): the range the search reaches, in pixels of that image.
const SEARCH_RADIUS: i64 = 16;
/// The widest image whose ±[`SEARCH_RADIUS`] the search covers.
const SEARCH_WIDTH: usize = 512;
/// The search runs on up to this many further halvings of the search image (the radius halved with each), and is
/// refined by ±[`REFINE_RADIUS`] on each finer level down to full size.
const PYRAMID_OCTAVES: u32 = 2;
/// The coarsest level keeps at least this many pixels in each direction.
const PYRAMID_MIN_SIDE: usize = 48;
/// The refinement's reach on each finer level around twice the coarser level's shift.
const REFINE_RADIUS: i64 = 2;
/// How many of the coarsest level's best distinct shifts are followed down to full size.
const HYPOTHESES: usize = 4;

/// The global shift between two frames: the current frame's pixel (x, y) shows what the previous frame showed
/// at (x + dx, y + dy), and the mean absolute grey difference left after that shift.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Shift {
    pub(crate) dx: i64,
    pub(crate) dy: i64,
    pub(crate) residual: f64,
}

/// The mean |a(x + dx, y + dy) − b(x, y)| over the pixels of every `step`-th row and column where both exist;
/// `None` when they overlap on less than half the image. Each row is summed on its own and the rows in order,
/// so the value does not depend on the thread count.
fn shifted_difference(a: &Plane<f32>, b: &Plane<f32>, dx: i64, dy: i64, step: usize) -> Option<f64> {
    let (w, h) = (a.width as i64, a.height as i64);
    let (x0, x1) = ((-dx).max(0), (w - dx).min(w));
    let (y0, y1) = ((-dy).max(0), (h - dy).min(h));
    if x1 <= x0 || y1 <= y0 || (x1 - x0) * (y1 - y0) * 2 < w * h {
        return None;
    }
    let (xa, xb, len) = ((x0 + dx) as usize, x0 as usize, (x1 - x0) as usize);
    let rows: Vec<(f64, usize)> = (y0..y1)
        .step_by(step)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|y| {
            let ra = &a.row((y + dy) as usize)[xa..xa + len];
            let rb = &b.row(y as usize)[xb..xb + len];
            if step == 1 {
                (row_difference(ra, rb), len)
            } else {
                let sum = ra.iter().step_by(step).zip(rb.iter().step_by(step)).map(|(p, q)| (p - q).abs()).sum::<f32>();
                (f64::from(sum), len.div_ceil(step))
            }
        })
        .collect();
    let (sum, n) = rows.iter().fold((0.0, 0), |(s, n), &(rs, rn)| (s + rs, n + rn));
    Some(sum / n.max(1) as f64)
}

/// Σ |a − b| over two rows of equal length, in eight running sums (a fixed order the compiler vectorises).
fn row_difference(a: &[f32], b: &[f32]) -> f64 {
    const LANES: usize = 8;
    let mut acc = [0.0f32; LANES];
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f32 = ca.remainder().iter().zip(cb.remainder()).map(|(p, q)| (p - q).abs()).sum();
    for (pa, pb) in ca.zip(cb) {
        for k in 0..LANES {
            acc[k] += (pa[k] - pb[k]).abs();
        }
    }
    acc.iter().map(|&v| f64::from(v)).sum::<f64>() + f64::from(tail)
}

/// Each candidate's difference (those that overlap enough), ordered from the least; ties go to the smaller shift,
/// then the first in the list.
fn ranked(candidates: Vec<(i64, i64)>, diff: impl Fn(i64, i64) -> Option<f64> + Sync) -> Vec<Shift> {
    let scored: Vec<Option<Shift>> =
        candidates.into_par_iter().map(|(dx, dy)| diff(dx, dy).map(|residual| Shift { dx, dy, residual })).collect();
    let mut scored: Vec<Shift> = scored.into_iter().flatten().collect();
    scored.sort_by(by_difference);
    scored
}

/// The order of shifts: the least difference first, then the smaller shift.
fn by_difference(a: &Shift, b: &Shift) -> std::cmp::Ordering {
    a.residual.total_cmp(&b.residual).then((a.dx.abs() + a.dy.abs()).cmp(&(b.dx.abs() + b.dy.abs())))
}

/// The candidate with the least difference (ties as [`ranked`]).
fn best(candidates: Vec<(i64, i64)>, diff: impl Fn(i64, i64) -> Option<f64> + Sync) -> Option<Shift> {
    ranked(candidates, diff).into_iter().next()
}

/// Up to `k` of the ranked shifts, each the best of those more than [`REFINE_RADIUS`] pixels from the ones before it.
fn distinct_best(ranked: Vec<Shift>, k: usize) -> Vec<Shift> {
    let mut kept: Vec<Shift> = Vec::with_capacity(k);
    for s in ranked {
        if kept.len() == k {
            break;
        }
        if kept.iter().all(|t| (t.dx - s.dx).abs().max((t.dy - s.dy).abs()) > REFINE_RADIUS) {
            kept.push(s);
        }
    }
    kept
}

/// The candidate shifts (dx, dy) within ±`r` of `(cx, cy)`.
fn around(cx: i64, cy: i64, r: i64) -> Vec<(i64, i64)> {
    (-r..=r).flat_map(|dy| (-r..=r).map(move |dx| (cx + dx, cy + dy))).collect()
}

/// The global integer shift between the previous and the current left view (grey), coarse to fine: the views
/// reduced to at most 512 pixels wide reach ±16 pixels there; the search itself runs on up to two more halvings
/// (±8, ±4 pixels; each level at least 48 pixels each way), and each finer level down to full size looks within
/// ±2 pixels of twice the coarser level's shift.
pub(crate) fn global_shift(prev: &Plane<f32>, cur: &Plane<f32>) -> Shift {
    let factor = prev.width.div_ceil(SEARCH_WIDTH).next_power_of_two();
    let mut octaves = factor.trailing_zeros();
    let mut radius = SEARCH_RADIUS;
    for _ in 0..PYRAMID_OCTAVES {
        let next = 2usize << octaves;
        if prev.width / next < PYRAMID_MIN_SIDE || prev.height / next < PYRAMID_MIN_SIDE {
            break;
        }
        octaves += 1;
        radius /= 2;
    }
    // The reduced levels, each from the finer one (box means of box means: the coarser box means up to rounding).
    let mut reduced: Vec<(Plane<f32>, Plane<f32>)> = Vec::with_capacity(octaves as usize);
    for _ in 0..octaves {
        let (p, c) = reduced.last().map_or((prev, cur), |(p, c)| (p, c));
        let next = (box_reduce(p, 2), box_reduce(c, 2));
        reduced.push(next);
    }
    let (coarse_prev, coarse_cur) = reduced.last().map_or((prev, cur), |(p, c)| (p, c));
    let coarse = ranked(around(0, 0, radius), |dx, dy| shifted_difference(coarse_prev, coarse_cur, dx, dy, 1));
    // A coarse level cannot tell a shift from a repetition of the scene's pattern that only fine texture tells
    // apart: its few best distinct shifts are each followed down, and the full size decides between them.
    let mut found = distinct_best(coarse, if octaves > 0 { HYPOTHESES } else { 1 });
    for level in (0..octaves as usize).rev() {
        let (p, c) = if level == 0 { (prev, cur) } else { (&reduced[level - 1].0, &reduced[level - 1].1) };
        found = found
            .iter()
            .filter_map(|s| {
                best(around(2 * s.dx, 2 * s.dy, REFINE_RADIUS), |dx, dy| shifted_difference(p, c, dx, dy, 1))
            })
            .collect();
    }
    let fallback = || Shift { dx: 0, dy: 0, residual: shifted_difference(prev, cur, 0, 0, 1).unwrap_or(f64::INFINITY) };
    found.into_iter().min_by(by_difference).unwrap_or_else(fallback)
}

/// The share of the image's own contrast that the shift leaves unexplained beyond what noise gives: (residual −
/// [`GREY_DIFFERENCE_PER_SIGMA`]·σn) / σ(grey). Two frames of one scene read about 0 (the frames' noise accounts for
/// the residual: the grey of independent per-channel noise σn differs between two frames by that much on average),
/// a new scene about 1 or more.
pub(crate) fn unexplained(shift: Shift, cur: &Plane<f32>, noise_sigma: f32) -> f64 {
    let n = cur.data.len().max(1) as f64;
    let mean = cur.data.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let var = cur.data.iter().map(|&v| (f64::from(v) - mean).powi(2)).sum::<f64>() / n;
    (shift.residual - GREY_DIFFERENCE_PER_SIGMA * f64::from(noise_sigma)) / var.sqrt().max(1e-6)
}

/// The previous frame's answer moved by `shift`: pixel (x, y) takes what (x + dx, y + dy) held; where that is
/// outside the frame there is no answer (`inf`, confidence 0, not consistent).
pub(crate) fn shift_answer(answer: &PipelineOutput, shift: Shift) -> PipelineOutput {
    let moved = |p: &Plane<f32>, fill: f32| p.shifted(shift.dx, shift.dy, fill);
    let consistent = answer.consistent.shifted(shift.dx, shift.dy, false);
    let mut out = carried(answer, moved(&answer.disparity, f32::INFINITY), consistent, moved);
    out.segmentation = answer.segmentation.as_ref().map(|s| s.shifted(shift.dx, shift.dy));
    out
}

/// The previous frame's answer carried into the current frame: its `disparity` and `consistent` as carried, its
/// confidence and max-marginal carried by `take` (0 where nothing lands), its vertical offset as it was.
pub(crate) fn carried(
    answer: &PipelineOutput,
    disparity: Plane<f32>,
    consistent: Plane<bool>,
    take: impl Fn(&Plane<f32>, f32) -> Plane<f32>,
) -> PipelineOutput {
    PipelineOutput {
        disparity,
        confidence: answer.confidence.as_ref().map(|c| take(c, 0.0)),
        max_marginal: take(&answer.max_marginal, 0.0),
        consistent,
        timings: Default::default(),
        measured: None,
        vertical_offset: answer.vertical_offset,
        segmentation: None,
    }
}

/// Where the frames disagree after the shift: the 5 × 5 mean absolute grey difference exceeds `limit` (and where
/// the previous frame does not reach).
pub(crate) fn disagreement(prev: &Plane<f32>, cur: &Plane<f32>, shift: Shift, limit: f32) -> Plane<bool> {
    disagreement_beyond(&prev.shifted(shift.dx, shift.dy, f32::INFINITY), cur, |_| limit)
}

/// Where the previous view, already moved into the current frame (`inf` where nothing lands), disagrees with the
/// current one: the 5 × 5 mean absolute grey difference exceeds `limit(i)` at pixel i, a pixel with nothing counting
/// as far off.
pub(crate) fn disagreement_beyond(moved: &Plane<f32>, cur: &Plane<f32>, limit: impl Fn(usize) -> f32) -> Plane<bool> {
    let diff = Plane::from_parts(
        cur.width,
        cur.height,
        moved.data.iter().zip(&cur.data).map(|(p, c)| if p.is_finite() { (p - c).abs() } else { 1e6 }).collect(),
    );
    let local = box_mean(&diff, 2);
    Plane::from_parts(cur.width, cur.height, local.data.iter().enumerate().map(|(i, &d)| d > limit(i)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::internals::SplitMix64;

    /// A textured grey image: smooth waves and fine noise, seeded.
    fn texture(w: usize, h: usize, seed: u64) -> Plane<f32> {
        let mut rng = SplitMix64::new(seed);
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                128.0 + 40.0 * (x * 0.21).sin() * (y * 0.17).cos() + 20.0 * (rng.next_f64() as f32 - 0.5)
            })
            .collect();
        Plane::from_parts(w, h, data)
    }

    /// The `w` × `h` window of `big` whose top-left pixel is (x0, y0): a camera's view of a larger scene.
    fn crop(big: &Plane<f32>, x0: usize, y0: usize, w: usize, h: usize) -> Plane<f32> {
        Plane::from_parts(w, h, (0..h).flat_map(|y| big.row(y0 + y)[x0..x0 + w].to_vec()).collect())
    }

    #[test]
    fn a_window_moved_across_an_image_is_found_exactly() {
        let big = texture(300, 200, 3);
        let (prev, cur) = (crop(&big, 20, 10, 240, 160), crop(&big, 27, 8, 240, 160));
        let s = global_shift(&prev, &cur);
        // The current frame's (x, y) is the big image's (x + 27, y + 8), the previous frame's (x + 7, y − 2).
        assert_eq!((s.dx, s.dy), (7, -2));
        assert!(s.residual < 1e-6, "{}", s.residual);
        assert!(unexplained(s, &cur, 0.0).abs() < 1e-6);
    }

    #[test]
    fn a_shift_near_the_reach_is_found_through_the_pyramid() {
        // 400 × 300 searches on two halvings (±4 px at a quarter size): a shift of (−15, 13) is found there and
        // refined down to the pixel.
        let big = texture(440, 340, 7);
        let (prev, cur) = (crop(&big, 30, 2, 400, 300), crop(&big, 15, 15, 400, 300));
        let s = global_shift(&prev, &cur);
        assert_eq!((s.dx, s.dy), (-15, 13));
        assert!(s.residual < 1e-6, "{}", s.residual);
    }

    #[test]
    fn another_scene_is_unexplained_and_the_same_one_is_not() {
        let (a, b) = (texture(200, 120, 1), texture(200, 120, 2));
        let same = global_shift(&a, &a);
        assert_eq!((same.dx, same.dy, same.residual), (0, 0, 0.0));
        let other = global_shift(&a, &b);
        assert!(unexplained(other, &b, 0.0) > 0.2, "{}", unexplained(other, &b, 0.0));
    }

    #[test]
    fn an_answer_moves_with_the_shift_and_is_unknown_where_it_leaves_the_frame() {
        let d = Plane::from_parts(3, 1, vec![1.0, 2.0, 3.0]);
        let answer = PipelineOutput {
            confidence: None,
            max_marginal: Plane::new(3, 1, 0.5),
            consistent: Plane::new(3, 1, true),
            disparity: d,
            timings: Default::default(),
            measured: None,
            vertical_offset: None,
            segmentation: None,
        };
        let moved = shift_answer(&answer, Shift { dx: 1, dy: 0, residual: 0.0 });
        assert_eq!(moved.disparity.data[..2], [2.0, 3.0]);
        assert!(moved.disparity.data[2].is_infinite());
        assert_eq!((moved.max_marginal.data[2], moved.consistent.data[2]), (0.0, false));
        assert!(moved.consistent.data[0]);
    }

    #[test]
    fn frames_disagree_only_where_something_changed() {
        let prev = texture(60, 40, 5);
        let mut cur = prev.clone();
        for y in 10..20 {
            for x in 30..40 {
                cur.data[y * 60 + x] += 80.0;
            }
        }
        let d = disagreement(&prev, &cur, Shift { dx: 0, dy: 0, residual: 0.0 }, 10.0);
        let at = |x: usize, y: usize| d.data[y * 60 + x];
        assert!((10..20).all(|y| (30..40).all(|x| at(x, y))), "the changed block");
        assert!(!at(27, 15) && !at(42, 15) && !at(35, 7) && !at(35, 22) && !at(5, 35), "3 px away and beyond");
    }
}
