//! Residual vertical misalignment (our addition): measured on the pair and removed.
//!
//! A rectified pair should have its matches on the same row, but real calibrations leave a residual: MiddEval3's
//! "imperfect" pairs (Playtable against PlaytableP) and most pairs from users' own rigs have the right view's
//! match a fraction of a pixel, or a few pixels, above or below. The 7 × 7 Census then compares windows off by
//! that much, which costs most on horizontal edges and fine texture (on MiddEval3 trainingQ, Playtable's error
//! is 2.8 times PlaytableP's).
//!
//! [`estimate`] measures the offset with the coarse run's disparities: the left pixel (x, y) with disparity d sees
//! the right view at (x − d, y + v). Per block of [`BLOCK`] × [`BLOCK`] pixels, a Lucas–Kanade step solves for a
//! horizontal and a vertical displacement and a brightness offset (so a lighting or exposure difference between
//! the views does not read as a shift); blocks without two-dimensional structure are skipped. A smooth surface
//! [`VerticalOffset`] is fitted to the blocks' vertical displacements by iteratively reweighted least squares
//! (Tukey's biweight, so blocks on wrong coarse disparities or occlusions drop out), and the whole is iterated,
//! each time sampling the right view at the current estimate, from the whole-pixel shift that correlates best
//! (the steps converge from within about a pixel; a rig can be several pixels off). [`resample_right`] then
//! moves the right view by −v (cubic interpolation), and the pipeline continues on the aligned pair.

use rayon::prelude::*;

use crate::image::{DisparityMap, Plane, RgbImage};
use crate::imgproc::filter::central_differences;
use crate::imgproc::sample::{Bilinear, keys, sample_bilinear};
use crate::params::VerticalParams;

/// The side of the blocks that each give one measurement of the offset (px).
pub(crate) const BLOCK: usize = 8;

/// Terms of the offset surface: 1, x, y, x·y, y² (x, y normalised to about ±½).
const TERMS: usize = 5;

/// Outer iterations: the right view is sampled again at the current estimate each time.
const ITERATIONS: usize = 4;

/// Reweighting rounds of the robust fit per iteration.
const REWEIGHTS: usize = 5;

/// A block counts only where its structure tensor's smaller eigenvalue, per pixel, is at least this (grey
/// levels² per px²): the block must have gradients in both directions.
const MIN_STRUCTURE: f64 = 4.0;

/// An estimate larger than this anywhere (px) is not trusted ([`VerticalParams::MAX_OFFSET_PX`]).
const MAX_OFFSET: f32 = VerticalParams::MAX_OFFSET_PX;

/// The right view's vertical offset v(x, y) in pixels: the left pixel (x, y) at disparity d matches the right
/// view at (x − d, y + v(x, y)). A quadratic surface, v = c₀ + c₁x′ + c₂y′ + c₃x′y′ + c₄y′² with
/// x′ = (x − w/2)/w, y′ = (y − h/2)/h: the pattern small rotations of the cameras and a focal-length mismatch
/// leave (a roll tilts it along x, a focal-length mismatch along y, a pitch shifts it and bends it along y, a yaw
/// adds the x·y term).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerticalOffset {
    /// c₀ … c₄.
    pub coef: [f64; TERMS],
    width: usize,
    height: usize,
}

impl VerticalOffset {
    /// The zero offset for a `width × height` image.
    pub fn zero(width: usize, height: usize) -> Self {
        VerticalOffset { coef: [0.0; TERMS], width, height }
    }

    fn terms(width: usize, height: usize, x: f64, y: f64) -> [f64; TERMS] {
        let xn = (x - width as f64 / 2.0) / width as f64;
        let yn = (y - height as f64 / 2.0) / height as f64;
        [1.0, xn, yn, xn * yn, yn * yn]
    }

    /// v at pixel (x, y).
    pub fn at(&self, x: f64, y: f64) -> f64 {
        Self::terms(self.width, self.height, x, y).iter().zip(&self.coef).map(|(t, c)| t * c).sum()
    }

    /// The smallest and largest offset over the image (px).
    pub fn range(&self) -> (f32, f32) {
        let (w, h) = (self.width, self.height);
        // A quadratic in y (for fixed x) and linear in x: its extremes lie on the left or right edge, at the top,
        // the bottom or the vertex of the parabola.
        let mut ys = vec![0.0, (h.max(1) - 1) as f64];
        if self.coef[4] != 0.0 {
            for x in [0.0, (w.max(1) - 1) as f64] {
                let xn = (x - w as f64 / 2.0) / w as f64;
                let yn = -(self.coef[2] + self.coef[3] * xn) / (2.0 * self.coef[4]);
                let y = yn * h as f64 + h as f64 / 2.0;
                if (0.0..=(h.max(1) - 1) as f64).contains(&y) {
                    ys.push(y);
                }
            }
        }
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for x in [0.0, (w.max(1) - 1) as f64] {
            for &y in &ys {
                let v = self.at(x, y);
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        (lo as f32, hi as f32)
    }

    /// The largest |v| over the image.
    pub fn max_abs(&self) -> f32 {
        let (lo, hi) = self.range();
        lo.abs().max(hi.abs())
    }
}

/// Bilinear sample of `p` at (x, y), clamped to the image.
fn bilinear(p: &Plane<f32>, x: f64, y: f64) -> f64 {
    sample_bilinear(&p.data, p.width, p.height, x, y)
}

/// The right view's column that left pixel `i` (of a `w`-wide image) matches at its coarse disparity, where the
/// coarse left-right check passed there and the column lies at least `margin` px inside the image.
fn matched_column(disparity: &DisparityMap, trusted: &Plane<bool>, i: usize, w: usize, margin: usize) -> Option<f64> {
    let d = disparity.data[i];
    let xr = (i % w) as f64 - f64::from(d);
    (trusted.data[i] && d.is_finite() && xr >= margin as f64 && xr <= (w - 1 - margin) as f64).then_some(xr)
}

/// One block's measurement: the mean of its pixels' terms, the vertical displacement the Lucas–Kanade step
/// found (relative to the current estimate) and the block's structure per pixel (its weight).
struct BlockStep {
    terms: [f64; TERMS],
    dv: f64,
    structure: f64,
}

/// What the blocks' steps read: both views in grey with their central differences, and the coarse answer (its
/// disparities and the pixels that passed its left-right check).
struct Measurement<'a> {
    left: &'a Plane<f32>,
    lgrad: &'a (Plane<f32>, Plane<f32>),
    right: &'a Plane<f32>,
    rgrad: &'a (Plane<f32>, Plane<f32>),
    disparity: &'a DisparityMap,
    trusted: &'a Plane<bool>,
}

/// A block of the measurement: its top-left pixel, how many of its pixels are usable (passed the coarse check,
/// matched inside the image) and the mean of their fit terms. Neither depends on the current estimate.
struct Block {
    origin: (usize, usize),
    n: f64,
    terms: [f64; TERMS],
}

impl Block {
    /// The block with top-left (`bx`, `by`) of the `w × h` image.
    fn new(m: &Measurement<'_>, (bx, by): (usize, usize)) -> Block {
        let (w, h) = m.left.dims();
        let (mut n, mut terms) = (0.0f64, [0.0f64; TERMS]);
        for y in by..(by + BLOCK).min(h) {
            for x in bx..(bx + BLOCK).min(w) {
                if matched_column(m.disparity, m.trusted, y * w + x, w, 1).is_some() {
                    n += 1.0;
                    for (t, val) in terms.iter_mut().zip(VerticalOffset::terms(w, h, x as f64, y as f64)) {
                        *t += val;
                    }
                }
            }
        }
        terms.iter_mut().for_each(|t| *t /= n.max(1.0));
        Block { origin: (bx, by), n, terms }
    }
}

/// The Lucas–Kanade step of `block` at the current estimate `v`, or `None` where the block has too few usable
/// pixels or no two-dimensional structure.
fn block_step(m: &Measurement<'_>, v: &VerticalOffset, block: &Block) -> Option<BlockStep> {
    let Measurement { left, lgrad, right, rgrad, disparity, trusted } = *m;
    let (w, h) = left.dims();
    if block.n < (BLOCK * BLOCK / 2) as f64 {
        return None;
    }
    let (bx, by) = block.origin;
    let mut s = [0.0f64; 9]; // n, Σgx, Σgy, Σe, Σgx², Σgxgy, Σgy², Σgx·e, Σgy·e
    for y in by..(by + BLOCK).min(h) {
        for x in bx..(bx + BLOCK).min(w) {
            let i = y * w + x;
            // One pixel of room for the gradients' neighbours.
            let Some(xr) = matched_column(disparity, trusted, i, w, 1) else { continue };
            let at = Bilinear::new(w, h, xr, y as f64 + v.at(x as f64, y as f64));
            let e = at.sample(&right.data) - f64::from(left.data[i]);
            let gx = 0.5 * (at.sample(&rgrad.0.data) + f64::from(lgrad.0.data[i]));
            let gy = 0.5 * (at.sample(&rgrad.1.data) + f64::from(lgrad.1.data[i]));
            for (acc, val) in s.iter_mut().zip([1.0, gx, gy, e, gx * gx, gx * gy, gy * gy, gx * e, gy * e]) {
                *acc += val;
            }
        }
    }
    let n = s[0];
    // With a brightness offset per block as a third unknown, the normal equations of (du, dv) are those of the
    // centred sums.
    let [_, sx, sy, se, sxx, sxy, syy, sxe, sye] = s;
    let (sxx, sxy, syy) = (sxx - sx * sx / n, sxy - sx * sy / n, syy - sy * sy / n);
    let (sxe, sye) = (sxe - sx * se / n, sye - sy * se / n);
    let det = sxx * syy - sxy * sxy;
    let half_trace = 0.5 * (sxx + syy);
    let smaller = half_trace - (half_trace * half_trace - det).max(0.0).sqrt();
    if det <= 0.0 || smaller < MIN_STRUCTURE * n {
        return None;
    }
    // gx·du + gy·dv = −e in the least-squares sense.
    let dv = -(sxx * sye - sxy * sxe) / det;
    Some(BlockStep { terms: block.terms, dv, structure: (smaller / n).min(100.0) })
}

/// Solves the weighted least-squares fit of `targets` on `rows` (normal equations, Gaussian elimination with
/// partial pivoting); `None` when they are singular.
fn weighted_fit(rows: &[[f64; TERMS]], targets: &[f64], weights: &[f64]) -> Option<[f64; TERMS]> {
    let mut a = [[0.0f64; TERMS + 1]; TERMS];
    for ((r, &t), &wt) in rows.iter().zip(targets).zip(weights) {
        for i in 0..TERMS {
            for j in 0..TERMS {
                a[i][j] += wt * r[i] * r[j];
            }
            a[i][TERMS] += wt * r[i] * t;
        }
    }
    for col in 0..TERMS {
        let pivot = (col..TERMS).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, pivot);
        let pivot_row = a[col];
        for (r, row) in a.iter_mut().enumerate() {
            if r != col {
                let f = row[col] / pivot_row[col];
                row.iter_mut().zip(&pivot_row).skip(col).for_each(|(v, p)| *v -= f * p);
            }
        }
    }
    let mut out = [0.0; TERMS];
    for (i, o) in out.iter_mut().enumerate() {
        *o = a[i][TERMS] / a[i][i];
    }
    Some(out)
}

/// Measures the right view's vertical offset (see the module doc) from grey images of both views, the coarse
/// disparities at this size and the pixels whose coarse left-right check passed. `None` when too few blocks
/// carry a measurement (fewer than 20 per term), the fit is singular, or the estimate exceeds [`MAX_OFFSET`].
pub(crate) fn estimate(
    left: &Plane<f32>,
    right: &Plane<f32>,
    disparity: &DisparityMap,
    trusted: &Plane<bool>,
) -> Option<VerticalOffset> {
    let (w, h) = left.dims();
    if w < 3 * BLOCK || h < 3 * BLOCK {
        return None;
    }
    let (lgrad, rgrad) = rayon::join(|| central_differences(left), || central_differences(right));
    let measurement = Measurement { left, lgrad: &lgrad, right, rgrad: &rgrad, disparity, trusted };
    let blocks: Vec<Block> = (0..h / BLOCK)
        .flat_map(|j| (0..w / BLOCK).map(move |i| (i * BLOCK, j * BLOCK)))
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|origin| Block::new(&measurement, origin))
        .collect();
    let mut v = VerticalOffset::zero(w, h);
    // The Lucas–Kanade steps converge from within about a pixel: start from the best whole-pixel shift.
    v.coef[0] = f64::from(best_whole_shift(left, right, disparity, trusted));
    for _ in 0..ITERATIONS {
        let steps: Vec<BlockStep> = blocks.par_iter().filter_map(|b| block_step(&measurement, &v, b)).collect();
        if steps.len() < 20 * TERMS {
            return None;
        }
        let rows: Vec<[f64; TERMS]> = steps.iter().map(|s| s.terms).collect();
        let targets: Vec<f64> =
            steps.iter().map(|s| s.terms.iter().zip(&v.coef).map(|(t, c)| t * c).sum::<f64>() + s.dv).collect();
        let base: Vec<f64> = steps.iter().map(|s| s.structure).collect();
        let mut weights = base.clone();
        let mut coef = v.coef;
        for _ in 0..REWEIGHTS {
            coef = weighted_fit(&rows, &targets, &weights)?;
            let residuals: Vec<f64> = rows
                .iter()
                .zip(&targets)
                .map(|(r, t)| t - r.iter().zip(&coef).map(|(a, c)| a * c).sum::<f64>())
                .collect();
            let mut abs: Vec<f64> = residuals.iter().map(|r| r.abs()).collect();
            // Tukey's biweight at 3 robust standard deviations (1.4826 × the median absolute residual).
            let mid = abs.len() / 2;
            let median = crate::imgproc::stats::nth_smallest(&mut abs, mid);
            let cut = 3.0 * (1.4826 * median + 1e-3);
            weights = base
                .iter()
                .zip(&residuals)
                .map(|(b, r)| {
                    let u = r / cut;
                    if u.abs() < 1.0 { b * (1.0 - u * u).powi(2) } else { 0.0 }
                })
                .collect();
        }
        v.coef = coef;
        // (Also refuses a NaN.)
        if v.max_abs().partial_cmp(&MAX_OFFSET) != Some(std::cmp::Ordering::Less) {
            return None;
        }
    }
    Some(v)
}

/// The whole-pixel vertical shift, within ±[`MAX_OFFSET`], under which the right view sampled at the coarse
/// disparities correlates best with the left view: the normalised cross-correlation (insensitive to a gain and an
/// offset between the views) over every other pixel of every other row that passed the coarse left-right check.
/// Ties go to the smaller shift, so a pair without texture starts at 0.
fn best_whole_shift(left: &Plane<f32>, right: &Plane<f32>, disparity: &DisparityMap, trusted: &Plane<bool>) -> i32 {
    let (w, h) = left.dims();
    let reach = MAX_OFFSET as i32;
    let correlation = |dy: i32| -> f64 {
        // n, Σl, Σr, Σl², Σr², Σlr
        let mut s = [0.0f64; 6];
        for y in (0..h).step_by(2) {
            let yr = y as i32 + dy;
            if yr < 0 || yr >= h as i32 {
                continue;
            }
            for x in (0..w).step_by(2) {
                let i = y * w + x;
                let Some(xr) = matched_column(disparity, trusted, i, w, 0) else { continue };
                let (l, r) = (f64::from(left.data[i]), bilinear(right, xr, f64::from(yr)));
                for (acc, v) in s.iter_mut().zip([1.0, l, r, l * l, r * r, l * r]) {
                    *acc += v;
                }
            }
        }
        let [n, sl, sr, sll, srr, slr] = s;
        let (vl, vr) = (sll - sl * sl / n.max(1.0), srr - sr * sr / n.max(1.0));
        if n < 2.0 || vl <= 0.0 || vr <= 0.0 { f64::NEG_INFINITY } else { (slr - sl * sr / n) / (vl * vr).sqrt() }
    };
    let scores: Vec<(i32, f64)> =
        (-reach..=reach).collect::<Vec<_>>().into_par_iter().map(|dy| (dy, correlation(dy))).collect();
    scores
        .iter()
        .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.abs().cmp(&a.0.abs())))
        .map_or(0, |&(dy, c)| if c.is_finite() { dy } else { 0 })
}

/// The right view moved so that its matches lie on the left view's rows: out(x, y) = img(x, y + v(x, y)), cubic
/// interpolation along the column (borders replicated), clamped to 0..=255.
pub fn resample_right(img: &RgbImage, v: &VerticalOffset) -> RgbImage {
    let (w, h) = (img.width, img.height);
    let mut out = RgbImage::new(w, h);
    let [r, g, b] = &mut out.channels;
    let rows = r.par_chunks_mut(w.max(1)).zip(g.par_chunks_mut(w.max(1))).zip(b.par_chunks_mut(w.max(1)));
    rows.enumerate().for_each(|(y, ((r, g), b))| {
        let mut dst = [r, g, b];
        for x in 0..w {
            // The four taps and their weights, once for the three channels.
            let yy = y as f64 + v.at(x as f64, y as f64);
            let y0 = yy.floor();
            let f = yy - y0;
            let taps: [(usize, f64); 4] = std::array::from_fn(|t| {
                let k = t as i64 - 1;
                ((y0 as i64 + k).clamp(0, h as i64 - 1) as usize, keys(f - k as f64))
            });
            for (src, row) in img.channels.iter().zip(dst.iter_mut()) {
                let acc = taps.iter().fold(0.0, |acc, &(yi, wt)| acc + wt * f64::from(src[yi * w + x]));
                row[x] = acc.clamp(0.0, 255.0) as f32;
            }
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64 as Rng;

    /// A smooth random texture (sums of a few sinusoids in both directions plus fine noise, seeded).
    fn texture(w: usize, h: usize, seed: u64) -> RgbImage {
        let mut rng = Rng::new(seed);
        let waves: Vec<(f64, f64, f64, f64)> = (0..12)
            .map(|_| (rng.next_f64() * 0.9 + 0.05, rng.next_f64() * 0.9 + 0.05, rng.next_f64() * 6.3, 12.0))
            .collect();
        let mut img = RgbImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let v: f64 = waves.iter().map(|(fx, fy, ph, a)| a * (fx * x as f64 + fy * y as f64 + ph).sin()).sum();
                for ch in &mut img.channels {
                    ch[y * w + x] = (128.0f64 + v).clamp(0.0, 255.0) as f32;
                }
            }
        }
        img
    }

    #[test]
    fn cubic_resampling_is_exact_at_whole_pixels_and_moves_by_the_offset() {
        let img = texture(64, 48, 3);
        // Zero offset: the image itself.
        assert_eq!(resample_right(&img, &VerticalOffset::zero(64, 48)), img);
        // A whole-pixel offset moves the rows (away from the borders).
        let mut one = VerticalOffset::zero(64, 48);
        one.coef[0] = 1.0;
        let moved = resample_right(&img, &one);
        for y in 0..46 {
            for x in 0..64 {
                assert!((moved.channels[0][y * 64 + x] - img.channels[0][(y + 1) * 64 + x]).abs() < 1e-3);
            }
        }
    }

    #[test]
    fn range_covers_the_surface() {
        let v = VerticalOffset { coef: [0.1, 0.2, -0.3, 0.4, 0.8], width: 100, height: 80 };
        let (lo, hi) = v.range();
        for y in 0..80 {
            for x in 0..100 {
                let a = v.at(x as f64, y as f64) as f32;
                assert!(a >= lo - 1e-5 && a <= hi + 1e-5, "v({x}, {y}) = {a} outside {lo}..{hi}");
            }
        }
    }

    /// The right view of a textured plane at disparity 5, moved vertically by a known quadratic surface (up to
    /// 0.9 px): the estimate recovers it to within 0.05 px everywhere, and the aligned view matches the left.
    #[test]
    fn recovers_a_known_offset_surface() {
        let (w, h, d) = (160usize, 120usize, 5usize);
        let big = texture(w + d, h, 7);
        let crop = |off: usize| {
            let mut img = RgbImage::new(w, h);
            for (dst, src) in img.channels.iter_mut().zip(&big.channels) {
                for y in 0..h {
                    dst[y * w..][..w].copy_from_slice(&src[y * (w + d) + off..][..w]);
                }
            }
            img
        };
        let (left, right0) = (crop(0), crop(d));
        let truth = VerticalOffset { coef: [0.4, 0.3, -0.5, 0.6, 0.8], width: w, height: h };
        // The right view whose row y + v holds what the left's row y shows: resample by −v.
        let inverse = VerticalOffset { coef: truth.coef.map(|c| -c), ..truth };
        let right = resample_right(&right0, &inverse);
        let disparity = Plane::new(w, h, d as f32);
        let trusted = Plane::new(w, h, true);
        let est = estimate(&left.to_grey(), &right.to_grey(), &disparity, &trusted).expect("an estimate");
        for y in (8..h - 8).step_by(4) {
            for x in (8..w - 8).step_by(4) {
                let (a, b) = (est.at(x as f64, y as f64), truth.at(x as f64, y as f64));
                assert!((a - b).abs() < 0.05, "at ({x}, {y}): estimated {a:.3}, true {b:.3}");
            }
        }
        // A rig several pixels off: the whole-pixel search puts the Lucas–Kanade steps within reach.
        let far = VerticalOffset { coef: [2.6, 0.3, 0.0, 0.0, 0.0], width: w, height: h };
        let right_far = resample_right(&right0, &VerticalOffset { coef: far.coef.map(|c| -c), ..far });
        let est = estimate(&left.to_grey(), &right_far.to_grey(), &disparity, &trusted).expect("an estimate");
        let (a, b) = (est.at(80.0, 60.0), far.at(80.0, 60.0));
        assert!((a - b).abs() < 0.05, "a 2.6 px offset estimated as {a:.3}");
        // No offset: the estimate stays near zero.
        let flat = estimate(&left.to_grey(), &right0.to_grey(), &disparity, &trusted).expect("an estimate");
        assert!(flat.max_abs() < 0.02, "{:?}", flat.range());
    }

    #[test]
    fn no_estimate_without_structure() {
        let img = RgbImage::new(64, 64);
        let grey = img.to_grey();
        assert!(estimate(&grey, &grey, &Plane::new(64, 64, 0.0), &Plane::new(64, 64, true)).is_none());
    }
}
