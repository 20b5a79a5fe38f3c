//! Sub-pixel refinement of the final map from the images (our addition; the paper stops at the planes).
//!
//! The mean-field answer is a label with a parabola through its log-marginals, and those marginals are peaked:
//! most decoded disparities sit within 0.1 px of a whole label (pixel locking). The planes average that out on
//! large surfaces but not on small or fronto-parallel ones, and on MiddEval3 trainingQ the pixels within 1 px of
//! the truth still carried about a quarter of the error. This stage looks at the images once more, at the
//! precision interpolation gives, and moves each pixel by at most half a pixel.
//!
//! # Model
//! Pixel p with the map's disparity D₀ takes the (2r + 1)² window of pixels q around it on its local plane,
//! D(q) = D + s · (q − p), where s is the map's slope at p (central differences; 0 across a step of more than
//! ½ px per px, a depth edge), and matches it against the right view at (q_x − D(q), q_y), linearly
//! interpolated. Both views are first normalised locally, N = (I − μ) / √(σ² + ε²) over
//! 5 × 5 pixels, so that a gain or offset between them cancels. With r = N_R − N_L at the
//! match and g = ∂N_R/∂x there, one Gauss–Newton step of least squares with a Gaussian prior N(D₀, s₀²) on D is
//!
//! ```text
//! D ← D + [Σ_q g r − λ (D − D₀)] / (Σ_q g² + λ),     λ = σ_r² / s₀²
//! ```
//!
//! where σ_r² is the window's residual variance after its own least-squares step (at least the 8-bit
//! quantisation's), so the prior weighs more where the images' evidence is noisy or absent, and s₀ is
//! `prior_px`. Two steps, each at most ¼ px, the total at most ½ px from D₀. Each
//! pixel depends on the images and D₀ alone, so the result does not depend on the thread count.
//!
//! Pixels whose windows lie inside the image are refined four at a time (`LANES`), each with the one-pixel path's
//! order of operations (a sample outside the right view adds +0 instead of being skipped, which leaves every
//! sum the same), so the results are bit-identical to the one-pixel path's; the independent sums give the
//! processor several additions to overlap instead of one chain.

use rayon::prelude::*;

use crate::image::{DisparityMap, Plane, RgbImage};
use crate::imgproc::filter::{box_mean_separable, central_differences};
use crate::params::SubpixelParams;

/// Radius of the local normalisation (px).
const NORM_RADIUS: usize = 2;

/// ε of the local normalisation (grey levels): below this contrast a window's differences are not amplified.
const NORM_EPS: f32 = 2.0;

/// Gauss–Newton steps.
const STEPS: usize = 2;

/// Largest single step (px).
const MAX_STEP: f32 = 0.25;

/// Largest total correction (px): the refinement is sub-pixel; which surface a pixel is on is decided before.
const MAX_SHIFT: f32 = 0.5;

/// A slope steeper than this (px of disparity per px) is a depth edge, not a surface: the window stays flat.
const MAX_SLOPE: f32 = 0.5;

/// Refines every finite disparity of `disp` (the left view's, columns from `left_from` of the right view's
/// frame: 0 but in a tile) against the views `left` and `right` (the pipeline passes the cost pair), as the
/// module doc says. Invalid (non-finite) pixels stay as they are.
///
/// # Panics
/// If `left` and `disp` differ in size or `right` is shorter than `left`.
///
/// # Example
/// ```
/// use jem::params::SubpixelParams;
/// use jem::internals::post::subpixel::refine_subpixel;
/// use jem::{Plane, RgbImage};
/// // A left view whose right view is it moved 3.3 px left; the map says 3.
/// let (w, h) = (40, 12);
/// let grey = |x: f32, _y: usize| 128.0 + 60.0 * (0.7 * x).sin() + 30.0 * (0.23 * x).cos();
/// let view = |shift: f32| {
///     let data: Vec<f32> = (0..w * h).map(|i| grey((i % w) as f32 + shift, i / w)).collect();
///     RgbImage::from_channels(w, h, [data.clone(), data.clone(), data]).unwrap()
/// };
/// let disp = Plane::new(w, h, 3.0f32);
/// let out = refine_subpixel(&view(0.0), &view(3.3), &disp, 0, &SubpixelParams::default());
/// assert!((out.at(20, 6) - 3.3).abs() < 0.05);
/// ```
pub fn refine_subpixel(
    left: &RgbImage,
    right: &RgbImage,
    disp: &DisparityMap,
    left_from: usize,
    p: &SubpixelParams,
) -> DisparityMap {
    assert_eq!(left.dims(), disp.dims(), "left view and disparity map differ in size");
    let (w, h) = disp.dims();
    let (wr, hr) = right.dims();
    assert!(hr == h && wr >= w + left_from, "right view smaller than the left view's frame");
    if w == 0 || h == 0 || wr < 2 {
        return disp.clone();
    }
    let left = Normalised::new(&left.to_grey());
    let right = Normalised::new(&right.to_grey());
    let (grad_r, _) = central_differences(&right.n);
    let right = Plane::from_parts(wr, h, right.n.data.iter().zip(&grad_r.data).map(|(&n, &g)| [n, g]).collect());
    let window = Window { left: &left, right: &right, left_from, radius: p.radius };
    let prior = 1.0 / (p.prior_px * p.prior_px);
    let mut out = disp.clone();
    out.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| refine_row(&window, disp, y, row, prior));
    out
}

/// Pixels of a row refined together where their windows lie inside the image, one per lane of the vector
/// registers; each lane keeps the single pixel's order of operations, so the result is the same.
const LANES: usize = 4;

/// Refines row `y` of `disp` into `row` (which holds it): blocks of [`LANES`] interior pixels by
/// [`Window::refine_lanes`], the pixels near the border one by one by [`Window::refine`]. Compiled for AVX2 +
/// FMA as well, picked at run time (same results: no multiply-add is contracted).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn refine_row(window: &Window, disp: &DisparityMap, y: usize, row: &mut [f32], prior: f32) {
    let (w, h) = disp.dims();
    let r = window.radius;
    let one = |x: usize, d: &mut f32| {
        if d.is_finite() {
            *d = window.refine(x, y, *d, slopes(disp, x, y), prior);
        }
    };
    let mut x = 0;
    if y >= r && y + r < h {
        while x < r.min(w) {
            one(x, &mut row[x]);
            x += 1;
        }
        while x + LANES + r <= w {
            let block = &mut row[x..x + LANES];
            let d0: [f32; LANES] = std::array::from_fn(|l| block[l]);
            let sl: [(f32, f32); LANES] = std::array::from_fn(|l| slopes(disp, x + l, y));
            let refined = window.refine_lanes(x, y, d0, sl, prior);
            for (out, (d, new)) in block.iter_mut().zip(d0.iter().zip(refined)) {
                if d.is_finite() {
                    *out = new;
                }
            }
            x += LANES;
        }
    }
    for (x, d) in row.iter_mut().enumerate().skip(x) {
        one(x, d);
    }
}

/// A grey view normalised locally (module doc), and 1 / (σ² + ε²) per pixel (the quantisation floor's scale).
struct Normalised {
    n: Plane<f32>,
    inv_var: Plane<f32>,
}

impl Normalised {
    fn new(grey: &Plane<f32>) -> Self {
        let (w, h) = grey.dims();
        let sq = Plane::from_parts(w, h, grey.data.iter().map(|v| v * v).collect());
        let (mean, mean_sq) = (box_mean_separable(grey, NORM_RADIUS), box_mean_separable(&sq, NORM_RADIUS));
        let inv_var: Vec<f32> = mean
            .data
            .iter()
            .zip(&mean_sq.data)
            .map(|(m, s)| 1.0 / ((s - m * m).max(0.0) + NORM_EPS * NORM_EPS))
            .collect();
        let n = grey.data.iter().zip(&mean.data).zip(&inv_var).map(|((v, m), iv)| (v - m) * iv.sqrt()).collect();
        Normalised { n: Plane::from_parts(w, h, n), inv_var: Plane::from_parts(w, h, inv_var) }
    }
}

/// The map's slope (px per px) along x and y at (x, y) by central differences; 0 where a neighbour is missing or
/// not finite, or the slope is steeper than [`MAX_SLOPE`].
fn slopes(disp: &DisparityMap, x: usize, y: usize) -> (f32, f32) {
    let (w, h) = disp.dims();
    let central = |a: Option<f32>, b: Option<f32>| match (a, b) {
        (Some(a), Some(b)) if a.is_finite() && b.is_finite() && (b - a).abs() <= 2.0 * MAX_SLOPE => (b - a) / 2.0,
        _ => 0.0,
    };
    let sx = central((x > 0).then(|| disp.at(x - 1, y)), (x + 1 < w).then(|| disp.at(x + 1, y)));
    let sy = central((y > 0).then(|| disp.at(x, y - 1)), (y + 1 < h).then(|| disp.at(x, y + 1)));
    (sx, sy)
}

/// What one pixel's refinement reads.
struct Window<'a> {
    left: &'a Normalised,
    /// The right view's normalised value and its horizontal central difference, side by side.
    right: &'a Plane<[f32; 2]>,
    left_from: usize,
    radius: usize,
}

impl Window<'_> {
    /// The refined disparities of the [`LANES`] pixels from (x, y) on, as [`Window::refine`] gives them one by one;
    /// their windows must lie inside the image (x ≥ r, x + LANES + r ≤ w, r ≤ y < h − r). Non-finite `d0` lanes give
    /// meaningless values.
    #[inline(always)]
    fn refine_lanes(&self, x: usize, y: usize, d0: [f32; LANES], sl: [(f32, f32); LANES], prior: f32) -> [f32; LANES] {
        let wr = self.right.width;
        let top = (wr - 1) as f32;
        let r = self.radius;
        let side = 2 * r + 1;
        let (sx, sy): ([f32; LANES], [f32; LANES]) = (sl.map(|s| s.0), sl.map(|s| s.1));
        let mut live = d0.map(f32::is_finite);
        let mut d = d0.map(|d| if d.is_finite() { d } else { 0.0 });
        let d_start = d;
        for _ in 0..STEPS {
            let mut sums = [Sums::default(); LANES];
            for j in 0..side {
                let qy = y + j - r;
                let cols = x - r..x + r + LANES;
                let (nl, iv, right) =
                    (&self.left.n.row(qy)[cols.clone()], &self.left.inv_var.row(qy)[cols], self.right.row(qy));
                // As in `refine`: the offsets from the centre are the same small integers for every lane.
                let dy = (j as i32 - r as i32) as f32;
                let at_x: [f32; LANES] = std::array::from_fn(|l| (x + l + self.left_from) as f32 - d[l] - sy[l] * dy);
                for k in 0..side {
                    let dx = (k as i32 - r as i32) as f32;
                    for (l, sum) in sums.iter_mut().enumerate() {
                        let xr = at_x[l] + (1.0 - sx[l]) * dx;
                        // Outside the right view a lane adds nothing (adding +0 leaves a sum as it is).
                        let inside = (0.0..=top).contains(&xr);
                        let (res, g) = match_at(right, xr.clamp(0.0, top), nl[l + k]);
                        sum.add(res, g, iv[l + k], inside);
                    }
                }
            }
            for l in 0..LANES {
                if live[l] {
                    match sums[l].step(d[l], d_start[l], prior) {
                        Some(next) => d[l] = next,
                        None => live[l] = false,
                    }
                }
            }
        }
        d
    }

    /// The refined disparity of (x, y) from `d0` on the local plane of slopes `(sx, sy)`; `prior` is 1 / s₀².
    fn refine(&self, x: usize, y: usize, d0: f32, (sx, sy): (f32, f32), prior: f32) -> f32 {
        let (w, h) = self.left.n.dims();
        let wr = self.right.width;
        let top = (wr - 1) as f32;
        let r = self.radius;
        let (rows, cols) = (y.saturating_sub(r)..(y + r + 1).min(h), x.saturating_sub(r)..(x + r + 1).min(w));
        // Offsets from the centre as small integers: their conversions to f32 are exact and cheap (a usize's is not).
        let (x_off, y_off) = (cols.start as i32 - x as i32, rows.start as i32 - y as i32);
        let mut d = d0;
        for _ in 0..STEPS {
            let mut sum = Sums::default();
            for (j, qy) in rows.clone().enumerate() {
                let (nl, iv, right) =
                    (&self.left.n.row(qy)[cols.clone()], &self.left.inv_var.row(qy)[cols.clone()], self.right.row(qy));
                // The match of (qx, qy) on the local plane: x_r = qx + left_from − (d + sx (qx − x) + sy (qy − y)).
                let at_x = (x + self.left_from) as f32 - d - sy * (y_off + j as i32) as f32;
                for (k, (&l, &v)) in nl.iter().zip(iv).enumerate() {
                    let xr = at_x + (1.0 - sx) * (x_off + k as i32) as f32;
                    if !(0.0..=top).contains(&xr) {
                        continue;
                    }
                    let (res, g) = match_at(right, xr, l);
                    sum.add(res, g, v, true);
                }
            }
            match sum.step(d, d0, prior) {
                Some(next) => d = next,
                None => break,
            }
        }
        d
    }
}

/// The residual N_R − `l` and the gradient ∂N_R/∂x of the right view's row `right` (value and central difference
/// per pixel) at `xr` in [0, width − 1], both interpolated linearly.
#[inline(always)]
fn match_at(right: &[[f32; 2]], xr: f32, l: f32) -> (f32, f32) {
    let x0 = (xr as u32 as usize).min(right.len() - 2);
    let f = xr - x0 as u32 as f32;
    let ([n0, g0], [n1, g1]) = (right[x0], right[x0 + 1]);
    // Central differences, interpolated: smoother under noise than the interpolant's own slope (which would make
    // each step exact on clean views; on trainingQ the two differ by 0.1 %, on its noise σ 8 copy the central
    // differences are 0.6 % better).
    (n0 + f * (n1 - n0) - l, g0 + f * (g1 - g0))
}

/// One Gauss–Newton step's sums over a window.
#[derive(Clone, Copy, Default)]
struct Sums {
    /// Σ g r.
    num: f32,
    /// Σ g².
    den: f32,
    /// Σ r².
    rr: f32,
    /// Σ 1 / (σ² + ε²) of the left view's samples.
    floor: f32,
    /// Samples.
    n: usize,
}

impl Sums {
    /// Adds one sample (residual, gradient, the left view's 1 / (σ² + ε²)) if `inside` the right view; otherwise
    /// adds +0 to each sum, which leaves it as it is.
    #[inline(always)]
    fn add(&mut self, res: f32, g: f32, floor: f32, inside: bool) {
        let keep = |v: f32| if inside { v } else { 0.0 };
        self.num += keep(g * res);
        self.den += keep(g * g);
        self.rr += keep(res * res);
        self.floor += keep(floor);
        self.n += usize::from(inside);
    }

    /// The disparity after this step from `d` (with D₀ = `d0`; `prior` is 1 / s₀²), or `None` where the window
    /// cannot tell (fewer than two samples, no finite step): the refinement stops there.
    #[inline(always)]
    fn step(self, d: f32, d0: f32, prior: f32) -> Option<f32> {
        let Sums { num, den, rr, floor, n } = self;
        if n < 2 {
            return None;
        }
        let fitted = if den > 0.0 { rr - num * num / den } else { rr };
        // Each view's 8-bit rounding has variance 1/12 grey level²; the difference's is twice that.
        let noise = (fitted.max(0.0) / (n - 1) as f32).max(floor / (6 * n) as f32);
        let lambda = noise * prior;
        let step = (num - lambda * (d - d0)) / (den + lambda);
        step.is_finite().then(|| (d + step.clamp(-MAX_STEP, MAX_STEP)).clamp(d0 - MAX_SHIFT, d0 + MAX_SHIFT))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn textured(w: usize, h: usize, shift: impl Fn(f32, usize) -> f32) -> (RgbImage, RgbImage) {
        let grey = |x: f32, y: f32| 128.0 + 50.0 * (0.6 * x + 0.3 * y).sin() + 40.0 * (0.31 * x - 0.47 * y).cos();
        let mut l = Vec::with_capacity(w * h);
        let mut r = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                l.push(grey(x as f32, y as f32));
                // The right view at column x shows the left view's point xl = x + d(xl).
                let mut xl = x as f32;
                for _ in 0..20 {
                    xl = x as f32 + shift(xl, y);
                }
                r.push(grey(xl, y as f32));
            }
        }
        let view = |v: Vec<f32>| RgbImage::from_channels(w, h, [v.clone(), v.clone(), v]).unwrap();
        (view(l), view(r))
    }

    /// Mean and largest |out − truth| away from the borders (6 px; 12 on the left, where the right view's match
    /// leaves the image).
    fn interior_errors(out: &DisparityMap, truth: impl Fn(usize, usize) -> f32) -> (f32, f32) {
        let (w, h) = out.dims();
        let (mut worst, mut sum, mut n) = (0.0f32, 0.0f32, 0);
        for y in 6..h - 6 {
            for x in 12..w - 6 {
                let e = (out.at(x, y) - truth(x, y)).abs();
                (worst, sum, n) = (worst.max(e), sum + e, n + 1);
            }
        }
        (sum / n as f32, worst)
    }

    #[test]
    fn a_whole_pixel_answer_moves_to_the_true_sub_pixel_disparity() {
        let (w, h) = (60, 30);
        for truth in [4.0f32, 4.2, 4.3, 3.75] {
            let (l, r) = textured(w, h, |_, _| truth);
            let disp = Plane::new(w, h, truth.round());
            let out = refine_subpixel(&l, &r, &disp, 0, &SubpixelParams::default());
            let (mean, worst) = interior_errors(&out, |_, _| truth);
            assert!(mean < 0.02 && worst < 0.08, "truth {truth}: mean error {mean} worst {worst}");
        }
    }

    #[test]
    fn a_slanted_surface_is_refined_on_its_plane() {
        let (w, h) = (80, 30);
        let plane = |x: f32, y: usize| 5.0 + 0.05 * x + 0.02 * y as f32;
        let (l, r) = textured(w, h, plane);
        // The answer a fifth of a pixel off everywhere, on the right slope.
        let disp = Plane::from_parts(w, h, (0..w * h).map(|i| plane((i % w) as f32, i / w) + 0.2).collect());
        let out = refine_subpixel(&l, &r, &disp, 0, &SubpixelParams::default());
        let (mean, worst) = interior_errors(&out, |x, y| plane(x as f32, y));
        assert!(mean < 0.02 && worst < 0.06, "mean error {mean} worst {worst}");
    }

    #[test]
    fn without_texture_the_answer_stays() {
        let (w, h) = (30, 20);
        let flat = RgbImage::from_channels(w, h, [vec![90.0; w * h], vec![90.0; w * h], vec![90.0; w * h]]).unwrap();
        let disp = Plane::from_parts(w, h, (0..w * h).map(|i| 2.0 + 0.01 * (i % 7) as f32).collect());
        let out = refine_subpixel(&flat, &flat, &disp, 0, &SubpixelParams::default());
        assert_eq!(out.data, disp.data);
    }

    #[test]
    fn the_correction_is_bounded_and_invalid_pixels_stay() {
        let (w, h) = (60, 30);
        let (l, r) = textured(w, h, |_, _| 6.0);
        // Two pixels off by far more than the refinement may move; one invalid.
        let mut disp = Plane::new(w, h, 6.0f32);
        disp.data[15 * w + 30] = 9.0;
        disp.data[15 * w + 40] = f32::INFINITY;
        let out = refine_subpixel(&l, &r, &disp, 0, &SubpixelParams::default());
        assert!((out.at(30, 15) - 9.0).abs() <= MAX_SHIFT + 1e-6);
        assert_eq!(out.at(40, 15), f32::INFINITY);
    }

    #[test]
    fn noisy_views_move_the_answer_less() {
        // The same quarter-pixel error, with and without noise: the prior holds the noisy answer nearer D₀.
        let (w, h) = (60, 30);
        let (l, r) = textured(w, h, |_, _| 4.25);
        let mut rng = crate::rng::SplitMix64::new(7);
        let mut noisy = |img: &RgbImage| {
            let c: Vec<f32> = img.to_grey().data.iter().map(|v| v + 40.0 * (rng.next_f64() as f32 - 0.5)).collect();
            RgbImage::from_channels(w, h, [c.clone(), c.clone(), c]).unwrap()
        };
        let (ln, rn) = (noisy(&l), noisy(&r));
        let disp = Plane::new(w, h, 4.0f32);
        let p = SubpixelParams::default();
        let mean_shift = |out: &DisparityMap| out.data.iter().map(|d| d - 4.0).sum::<f32>() / (w * h) as f32;
        let (clean, noisy) = (refine_subpixel(&l, &r, &disp, 0, &p), refine_subpixel(&ln, &rn, &disp, 0, &p));
        assert!(mean_shift(&clean) > 0.2, "clean: {}", mean_shift(&clean));
        assert!(mean_shift(&noisy) < mean_shift(&clean), "noisy {} clean {}", mean_shift(&noisy), mean_shift(&clean));
    }

    #[test]
    fn a_tile_reads_the_right_view_at_its_offset() {
        let (w, h) = (70, 24);
        let (l, r) = textured(w, h, |_, _| 5.3);
        let from = 12;
        let crop = l.columns_from(from);
        let disp = Plane::new(w - from, h, 5.0f32);
        let out = refine_subpixel(&crop, &r, &disp, from, &SubpixelParams::default());
        let whole = refine_subpixel(&l, &r, &Plane::new(w, h, 5.0f32), 0, &SubpixelParams::default());
        for y in 6..h - 6 {
            for x in 8..w - from - 6 {
                assert!((out.at(x, y) - 5.3).abs() < 0.1, "({x}, {y}) {}", out.at(x, y));
                assert!((out.at(x, y) - whole.at(x + from, y)).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn the_pixels_refined_in_lanes_are_those_refined_one_by_one() {
        // A scene whose matches leave the right view on the left (lanes outside it add nothing), slopes, steps of
        // a pixel and more (flat windows), invalid pixels, and textureless rows where the steps stop.
        let (w, h) = (67, 23);
        let (mut l, r) = textured(w, h, |x, y| 4.0 + 0.08 * x + if y % 7 == 3 { 6.0 } else { 0.0 });
        for c in &mut l.channels {
            c[(h - 4) * w..(h - 3) * w].fill(77.0);
        }
        let truth = |x: usize, y: usize| 4.0 + 0.08 * x as f32 + if y % 7 == 3 { 6.0 } else { 0.0 };
        let disp = Plane::from_parts(
            w,
            h,
            (0..w * h)
                .map(|i| match i % 29 {
                    0 => f32::INFINITY,
                    5 => f32::NAN,
                    k => truth(i % w, i / w) + 0.05 * (k % 9) as f32 - 0.2,
                })
                .collect(),
        );
        let p = SubpixelParams::default();
        let out = refine_subpixel(&l, &r, &disp, 0, &p);
        let (left, right) = (Normalised::new(&l.to_grey()), Normalised::new(&r.to_grey()));
        let (grad, _) = central_differences(&right.n);
        let right = Plane::from_parts(w, h, right.n.data.iter().zip(&grad.data).map(|(&n, &g)| [n, g]).collect());
        let window = Window { left: &left, right: &right, left_from: 0, radius: p.radius };
        let prior = 1.0 / (p.prior_px * p.prior_px);
        let mut moved = 0;
        for y in 0..h {
            for x in 0..w {
                let d = disp.at(x, y);
                let one = if d.is_finite() { window.refine(x, y, d, slopes(&disp, x, y), prior) } else { d };
                assert_eq!(out.at(x, y).to_bits(), one.to_bits(), "({x}, {y})");
                moved += usize::from(one != d);
            }
        }
        assert!(moved > w * h / 2, "{moved} pixels moved");
    }

    #[test]
    fn the_result_does_not_depend_on_the_thread_count() {
        let (w, h) = (90, 50);
        let (l, r) = textured(w, h, |x, _| 3.0 + 0.03 * x);
        let disp = Plane::from_parts(w, h, (0..w * h).map(|i| 3.0 + 0.03 * (i % w) as f32 + 0.2).collect());
        let p = SubpixelParams::default();
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| refine_subpixel(&l, &r, &disp, 0, &p))
        };
        let one = run(1);
        assert_eq!(
            one.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            run(3).data.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }
}
