//! Points tracked from the previous left view into the current one, for the ego-motion fit
//! ([`super::egomotion`]).
//!
//! One point per 16 × 16 cell of the previous view: the pixel whose 7 × 7 window has the largest smaller eigenvalue
//! of its gradient's structure tensor (Shi and Tomasi's "good feature"), kept where that stands above what the noise
//! alone gives and the previous answer has a disparity there that is not on a depth edge. Each is found in the
//! current view coarse to fine: on the views reduced 2^L× (L up to 3, while the reduced view is at least 120 pixels
//! wide) within ±6 pixels of where the global shift puts it, then within ±2 pixels at each finer level, by the least
//! sum of squared differences of the 7 × 7 windows with their means taken out; at full size a parabola through the
//! best position and its neighbours gives the sub-pixel position.

use rayon::prelude::*;

use crate::image::Plane;
use crate::imgproc::filter::{box_mean, box_reduce, central_differences};

#[cfg(test)]
use super::motion::Shift;

/// The side of the cells one point each is chosen in, in pixels.
const CELL: usize = 16;
/// The window's radius (7 × 7).
const RADIUS: isize = 3;
/// The search radius at the coarsest level, in its pixels.
const COARSE_SEARCH: isize = 6;
/// The search radius at each finer level around the coarser level's answer.
const FINE_SEARCH: isize = 2;
/// At most this many reductions.
const MAX_LEVELS: usize = 3;
/// The coarsest level is at least this wide.
const MIN_LEVEL_WIDTH: usize = 120;
/// A point is kept where its structure tensor's smaller eigenvalue (the mean squared central-difference gradient
/// over the window) exceeds this many times the noise's own (σ²/2 per direction for a grey noise σ), plus one grey
/// level² for quantisation.
const TEXTURE_PER_NOISE: f32 = 8.0;

/// A point of the previous frame (x, y, with disparity d there) and where it is in the current frame (tx, ty).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Track {
    pub(crate) x: f64,
    pub(crate) y: f64,
    pub(crate) d: f64,
    pub(crate) tx: f64,
    pub(crate) ty: f64,
}

/// The feature points of a previous view and the two views' pyramids, to track the points from a guess.
pub(crate) struct Tracker {
    prev: Vec<Plane<f32>>,
    cur: Vec<Plane<f32>>,
    /// The points (x, y) with their disparity.
    points: Vec<(usize, usize, f32)>,
}

impl Tracker {
    /// The points of `prev` (grey, under the current frame's exposure) to track into `cur`; `disparity` is the
    /// previous frame's answer, `noise` the grey noise σ.
    pub(crate) fn new(prev: &Plane<f32>, cur: &Plane<f32>, disparity: &Plane<f32>, noise: f32) -> Tracker {
        let levels = pyramid_levels(prev.width);
        let (found, (prev_levels, cur_levels)) = rayon::join(
            || features(prev, disparity, noise),
            || rayon::join(|| pyramid(prev, levels), || pyramid(cur, levels)),
        );
        let points = found.into_iter().map(|(x, y)| (x, y, disparity.data[y * prev.width + x])).collect();
        Tracker { prev: prev_levels, cur: cur_levels, points }
    }

    /// Every point found in the current view, searched from `guess(x, y, d)` (where it should be) coarse to fine:
    /// `Wide` from the coarsest level, `Near` from the half-size level only (a guess within a few pixels).
    pub(crate) fn follow(
        &self,
        guess: impl Fn(f64, f64, f64) -> Option<(f64, f64)> + Sync,
        reach: Reach,
    ) -> Vec<Track> {
        let (top, radius) = match reach {
            Reach::Wide => (self.prev.len() - 1, COARSE_SEARCH),
            Reach::Near => ((self.prev.len() - 1).min(1), FINE_SEARCH),
        };
        self.points
            .par_iter()
            .filter_map(|&(x, y, d)| {
                let (gx, gy) = guess(x as f64, y as f64, f64::from(d))?;
                let (tx, ty) = follow(&self.prev[..=top], &self.cur[..=top], x, y, (gx, gy), radius)?;
                Some(Track { x: x as f64, y: y as f64, d: f64::from(d), tx, ty })
            })
            .collect()
    }
}

/// How far from its guess a point is searched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Reach {
    /// From the coarsest level: ±6 of its pixels (±48 px at full size with three reductions).
    Wide,
    /// From the half-size level: ±2 of its pixels, then ±2 (±6 px).
    Near,
}

/// Tracks points of `prev` into `cur` from where the global shift puts them (see [`Tracker`]).
#[cfg(test)]
pub(crate) fn track(
    prev: &Plane<f32>,
    cur: &Plane<f32>,
    disparity: &Plane<f32>,
    shift: Shift,
    noise: f32,
) -> Vec<Track> {
    let (dx, dy) = (shift.dx as f64, shift.dy as f64);
    Tracker::new(prev, cur, disparity, noise).follow(|x, y, _| Some((x - dx, y - dy)), Reach::Wide)
}

/// The reductions whose coarsest view is still [`MIN_LEVEL_WIDTH`] wide, at most [`MAX_LEVELS`].
fn pyramid_levels(width: usize) -> usize {
    (0..MAX_LEVELS).take_while(|&l| width >> (l + 1) >= MIN_LEVEL_WIDTH).count()
}

/// The view and its reductions by 2, 4, … (box means), finest first.
fn pyramid(p: &Plane<f32>, levels: usize) -> Vec<Plane<f32>> {
    let mut out = vec![p.clone()];
    for _ in 0..levels {
        let next = box_reduce(out.last().expect("the finest level"), 2);
        out.push(next);
    }
    out
}

/// The feature points (x, y) of `grey`, one per cell at most, in raster order of the cells.
fn features(grey: &Plane<f32>, disparity: &Plane<f32>, noise: f32) -> Vec<(usize, usize)> {
    let (w, h) = grey.dims();
    let score = min_eigenvalue(grey);
    let floor = TEXTURE_PER_NOISE * 0.5 * noise * noise + 1.0;
    let margin = (RADIUS as usize + 1) << MAX_LEVELS;
    let usable = |x: usize, y: usize| {
        x >= margin && y >= margin && x + margin < w && y + margin < h && flat_disparity(disparity, x, y)
    };
    let mut out = Vec::new();
    for cy in (0..h).step_by(CELL) {
        for cx in (0..w).step_by(CELL) {
            let mut best: Option<(f32, usize, usize)> = None;
            for y in cy..(cy + CELL).min(h) {
                for x in cx..(cx + CELL).min(w) {
                    let s = score.data[y * w + x];
                    if s > floor && best.is_none_or(|(b, _, _)| s > b) && usable(x, y) {
                        best = Some((s, x, y));
                    }
                }
            }
            out.extend(best.map(|(_, x, y)| (x, y)));
        }
    }
    out
}

/// The disparity at (x, y) and its 8 neighbours is finite and spans at most 1 px (not a depth edge).
fn flat_disparity(d: &Plane<f32>, x: usize, y: usize) -> bool {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for yy in y - 1..=y + 1 {
        for &v in &d.row(yy)[x - 1..=x + 1] {
            if !v.is_finite() {
                return false;
            }
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    hi - lo <= 1.0
}

/// The smaller eigenvalue of each pixel's structure tensor over the 7 × 7 window (central differences, one-sided at
/// the borders).
fn min_eigenvalue(grey: &Plane<f32>) -> Plane<f32> {
    let (w, h) = grey.dims();
    let (gx, gy) = central_differences(grey);
    let products = |f: fn(f32, f32) -> f32| {
        Plane::from_parts(w, h, gx.data.iter().zip(&gy.data).map(|(&a, &b)| f(a, b)).collect())
    };
    let (gxx, gyy, gxy) = (products(|a, _| a * a), products(|_, b| b * b), products(|a, b| a * b));
    let (a, b, c) = (box_mean(&gxx, RADIUS as usize), box_mean(&gyy, RADIUS as usize), box_mean(&gxy, RADIUS as usize));
    let data = (0..w * h)
        .map(|i| {
            let (a, b, c) = (a.data[i], b.data[i], c.data[i]);
            0.5 * (a + b) - (0.25 * (a - b) * (a - b) + c * c).sqrt()
        })
        .collect();
    Plane::from_parts(w, h, data)
}

/// Where the point (x, y) of the previous view is in the current one, searched from `guess` coarse to fine over
/// the levels given (finest first), within ±`radius` at the coarsest and ±2 at the others; `None` where its
/// window leaves a level's view.
fn follow(
    prev: &[Plane<f32>],
    cur: &[Plane<f32>],
    x: usize,
    y: usize,
    guess: (f64, f64),
    radius: isize,
) -> Option<(f64, f64)> {
    let top = prev.len() - 1;
    let scale = (1i64 << top) as f64;
    let mut at = ((guess.0 / scale).round() as isize, (guess.1 / scale).round() as isize);
    for level in (0..=top).rev() {
        let (px, py) = ((x >> level) as isize, (y >> level) as isize);
        let radius = if level == top { radius } else { FINE_SEARCH };
        let (bx, by, _) = best_match(&prev[level], &cur[level], (px, py), at, radius)?;
        if level == 0 {
            let (sx, sy) = subpixel(&prev[0], &cur[0], (px, py), (bx, by));
            return Some((bx as f64 + sx, by as f64 + sy));
        }
        at = (2 * bx, 2 * by);
    }
    None
}

/// The position within ±`radius` of `guess` in `cur` whose window best matches `at`'s in `prev` (least
/// zero-mean SSD; ties to the first in raster order) and its SSD.
fn best_match(
    prev: &Plane<f32>,
    cur: &Plane<f32>,
    at: (isize, isize),
    guess: (isize, isize),
    radius: isize,
) -> Option<(isize, isize, f32)> {
    let template = window(prev, at)?;
    let mut best: Option<(isize, isize, f32)> = None;
    for dy in -radius..=radius {
        for dx in -radius..=radius {
            let (cx, cy) = (guess.0 + dx, guess.1 + dy);
            if let Some(ssd) = window(cur, (cx, cy)).map(|c| zero_mean_ssd(&template, &c))
                && best.is_none_or(|(_, _, b)| ssd < b)
            {
                best = Some((cx, cy, ssd));
            }
        }
    }
    best
}

/// The 7 × 7 window around `at`, mean removed; `None` where it leaves the view.
fn window(p: &Plane<f32>, at: (isize, isize)) -> Option<[f32; 49]> {
    let (w, h) = (p.width as isize, p.height as isize);
    if at.0 < RADIUS || at.1 < RADIUS || at.0 + RADIUS >= w || at.1 + RADIUS >= h {
        return None;
    }
    let mut out = [0.0f32; 49];
    for (k, v) in out.iter_mut().enumerate() {
        let (dx, dy) = ((k % 7) as isize - RADIUS, (k / 7) as isize - RADIUS);
        *v = p.data[((at.1 + dy) * w + at.0 + dx) as usize];
    }
    let mean = out.iter().sum::<f32>() / 49.0;
    out.iter_mut().for_each(|v| *v -= mean);
    Some(out)
}

fn zero_mean_ssd(a: &[f32; 49], b: &[f32; 49]) -> f32 {
    a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum()
}

/// The sub-pixel offset of the best integer match: a parabola through its SSD and its two neighbours', along x and
/// along y, each within ±½.
fn subpixel(prev: &Plane<f32>, cur: &Plane<f32>, at: (isize, isize), best: (isize, isize)) -> (f64, f64) {
    let Some(template) = window(prev, at) else { return (0.0, 0.0) };
    let ssd = |x: isize, y: isize| window(cur, (x, y)).map(|c| f64::from(zero_mean_ssd(&template, &c)));
    let vertex = |m: Option<f64>, c: Option<f64>, p: Option<f64>| match (m, c, p) {
        (Some(m), Some(c), Some(p)) if m + p - 2.0 * c > 1e-9 => (0.5 * (m - p) / (m + p - 2.0 * c)).clamp(-0.5, 0.5),
        _ => 0.0,
    };
    let (x, y) = best;
    let centre = ssd(x, y);
    (vertex(ssd(x - 1, y), centre, ssd(x + 1, y)), vertex(ssd(x, y - 1), centre, ssd(x, y + 1)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::internals::SplitMix64;

    /// A textured grey image: waves and smoothed random blobs, seeded.
    pub(crate) fn texture(w: usize, h: usize, seed: u64) -> Plane<f32> {
        let mut rng = SplitMix64::new(seed);
        let blobs = Plane::from_parts(w, h, (0..w * h).map(|_| 60.0 * (rng.next_f64() as f32 - 0.5)).collect());
        let blobs = box_mean(&blobs, 1);
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                128.0 + 30.0 * (x * 0.13).sin() * (y * 0.11).cos() + blobs.data[i]
            })
            .collect();
        Plane::from_parts(w, h, data)
    }

    /// `p` sampled at `map(x, y)` (bilinear, clamped to the image).
    pub(crate) fn resample(p: &Plane<f32>, map: impl Fn(f64, f64) -> (f64, f64)) -> Plane<f32> {
        let (w, h) = p.dims();
        let data = (0..w * h)
            .map(|i| {
                let (sx, sy) = map((i % w) as f64, (i / w) as f64);
                crate::imgproc::sample::sample_bilinear(&p.data, w, h, sx, sy) as f32
            })
            .collect();
        Plane::from_parts(w, h, data)
    }

    #[test]
    fn points_follow_a_zoom_to_a_fraction_of_a_pixel() {
        let (w, h) = (400, 240);
        let prev = texture(w, h, 7);
        // The current frame is the previous one enlarged 1.06× about (180, 110): its (x, y) shows the previous
        // (c + (x − c) / 1.06).
        let (cx, cy, s) = (180.0, 110.0, 1.06);
        let cur = resample(&prev, |x, y| (cx + (x - cx) / s, cy + (y - cy) / s));
        let disparity = Plane::new(w, h, 10.0f32);
        let tracks = track(&prev, &cur, &disparity, Shift { dx: 0, dy: 0, residual: 0.0 }, 0.0);
        assert!(tracks.len() > 150, "{} tracks", tracks.len());
        let errors: Vec<f64> = tracks
            .iter()
            .map(|t| ((t.tx - (cx + (t.x - cx) * s)).powi(2) + (t.ty - (cy + (t.y - cy) * s)).powi(2)).sqrt())
            .collect();
        let good = errors.iter().filter(|&&e| e < 0.3).count();
        assert!(good * 10 >= tracks.len() * 9, "{good} of {} within 0.3 px", tracks.len());
    }

    #[test]
    fn no_point_where_the_view_is_flat_or_the_answer_missing() {
        let (w, h) = (200, 120);
        let flat = Plane::new(w, h, 100.0f32);
        let d = Plane::new(w, h, 5.0f32);
        assert!(track(&flat, &flat, &d, Shift { dx: 0, dy: 0, residual: 0.0 }, 1.0).is_empty());
        let tex = texture(w, h, 3);
        let none = Plane::new(w, h, f32::INFINITY);
        assert!(track(&tex, &tex, &none, Shift { dx: 0, dy: 0, residual: 0.0 }, 1.0).is_empty());
        let same = track(&tex, &tex, &d, Shift { dx: 0, dy: 0, residual: 0.0 }, 1.0);
        // The parabola through an exact match's asymmetric neighbours is off by a little, never by a pixel.
        assert!(same.len() > 20, "{} tracks", same.len());
        assert!(same.iter().all(|t| (t.tx - t.x).abs() < 0.3 && (t.ty - t.y).abs() < 0.3 && t.d == 5.0), "{same:?}");
    }
}
