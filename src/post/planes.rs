//! Slanted-plane smoothing (paper §4.3, SPEC §4), after Yamaguchi, McAllester & Urtasun, "Efficient Joint
//! Segmentation, Occlusion Labeling, Stereo and Flow Estimation" (ECCV 2014) — the stereo part, on a semi-dense
//! disparity map. Written from the paper; no code was consulted.
//!
//! # Model
//! The image is cut into connected segments `S_k`, each with a plane `θ_k = (a, b, c)`, `d_k(x, y) = a·x + b·y + c`
//! (pixel centres at integer coordinates). Adjacent segments `k, l` share a boundary with a label `o_kl` ∈
//! {coplanar, hinge, occlusion with `k` in front, occlusion with `l` in front}. The energy is
//!
//! ```text
//! E = Σ_p [ |Lab_p − μ_s(p)|²                                         colour (CIE Lab, D65)
//!         + λ_pos · |p − ĉ_s(p)|² / step²                              position (segment centre, grid step)
//!         + λ_d · w_p · min((D_p − d_s(p)(p))², τ²) ]                   disparity, truncated at the inlier threshold
//!   + λ_bou · #{8-neighbour pairs p, q : s(p) ≠ s(q)}                  boundary length
//!   + Σ_{k~l} E_b(o_kl, θ_k, θ_l)                                       boundary labels
//!
//! E_b(coplanar)        = λ_s · mean_{p ∈ S_k ∪ S_l} (d_k(p) − d_l(p))²
//! E_b(hinge)           = λ_hinge + λ_s · mean_{m ∈ B_kl} (d_k(m) − d_l(m))²
//! E_b(occlusion, k>l)  = λ_occ + λ_imp · (fraction of m ∈ B_kl with d_k(m) < d_l(m))
//! ```
//!
//! `D_p` is the input disparity, `w_p` its data weight (1 for trusted pixels, `untrusted_weight` for finite
//! untrusted ones, 0 for `inf`), `B_kl` the midpoints between 4-adjacent pixel pairs across the boundary, and
//! `step` the initial grid step (√(pixels / segments)). Keys: λ_pos = `position_weight`, λ_d =
//! `disparity_weight`, τ = `inlier_thresh_px`, λ_bou = `boundary_weight`, λ_s = `smoothness_weight`,
//! λ_hinge = `hinge_penalty`, λ_occ = `occlusion_penalty`, λ_imp = `impossible_penalty`.
//!
//! # Algorithm (block coordinate descent, as in the paper)
//! 1. Segments start as a regular grid of about `segments` cells; each gets a plane by seeded RANSAC on its data
//!    pixels (`ransac_iterations` trials of 3 points, the score is the inlier weight, |residual| < τ), refined by
//!    least squares on the inliers.
//! 2. `iterations` times:
//!    - **Pixels**: one sweep over the boundary pixels. A pixel may move to the segment of a 4-neighbour when that
//!      lowers its energy (colour + position + disparity + boundary-length terms, segment means and planes held
//!      fixed) and when leaving keeps its old segment 4-connected (a local test on the 3×3 ring, which is exact
//!      for keeping connectivity; segments never vanish). The sweep runs in 9 phases of pixels with the same
//!      (x mod 3, y mod 3); pixels of one phase have disjoint 3×3 neighbourhoods, so each phase is a parallel
//!      Jacobi step and the result is independent of the thread count.
//!    - **Statistics**: segment colour means, centres, pixel moments, and the inlier data moments (|D_p − d_s(p)| < τ
//!      under the current plane: one step of iteratively reweighted least squares for the truncated quadratic).
//!    - **Boundary labels**: each boundary independently takes the label of least `E_b` (ties: coplanar, hinge,
//!      occlusion-first, occlusion-second).
//!    - **Planes**: every segment solves its weighted least-squares problem — the inlier data term plus, with the
//!      neighbours' planes held at their previous values, the hinge and coplanar terms (these couple neighbouring
//!      planes; occlusion boundaries do not). All segments update at once (Jacobi), in parallel. A segment whose
//!      plane explains less than half of its data weight (its pixels moved onto another surface) is refitted
//!      from scratch by RANSAC instead.
//! 3. Each pixel's output is its segment's plane, clamped to [0, max finite input + τ].
//!
//! Colour: sRGB (0..255, 8-bit values looked up in a table) → linear → XYZ (D65) → CIE L*a*b*, with L in 0..100;
//! the cube root is a bit-trick estimate refined by Newton steps (relative error < 1e-6, tested).
//!
//! The normal equations are solved in coordinates centred on the weighted centroid. The system is treated as
//! degenerate when |det| of the normal matrix is at most 1e-6 × the product of its diagonal (collinear points, a
//! single row or column, one point); a small ridge (0.25 px² × weight) on the slopes is then added, which keeps the
//! well-determined slope and sets the undetermined one to 0 (down to a fronto-parallel plane at the mean).
//!
//! A segment whose data weight is below `min_support`, or below `min_support_fraction` × its pixel count if that
//! is more, and which has no hinge/coplanar neighbour gets no plane of its own (RANSAC skips it too, and the
//! stale-plane test uses the same threshold); it borrows, in rounds, the plane of an adjacent segment: the one
//! that fits its few data points best, or without data the one that is *lowest* (smallest disparity) on their
//! common boundary — occluded regions belong to the background, the rule the occlusion fill uses too. If no
//! segment has a plane (no data at all), every segment is fronto-parallel at the median of the data, or 0 without
//! data. The output is therefore always finite.
//!
//! Defaults: `segments = 1500` (≈ 15 px cells at Q; Yamaguchi et al. use 1000 on KITTI's 0.47 Mpx),
//! `untrusted_weight = 0.3`, `disparity_weight = 100` and `inlier_thresh_px = 3`, tuned on trainingQ with the full
//! pipeline (docs/RESULTS.md); the other weights were set by reasoning about magnitudes (the position term reaches
//! λ_pos at one grid step) and checked on synthetic scenes, and the sweeps show them to matter little.
//! `untrusted_weight` lets filled pixels steer segments that have little trusted data; it has no effect when the
//! fill is off (untrusted pixels are `inf`). `min_support_fraction` (0 by default; 0.25 in `jem-sps.toml`, where
//! there is no fill) makes a segment with trusted data on too small a share of its pixels borrow a neighbour's
//! plane instead of stretching its own over the whole segment.
//!
//! # Deviations from the paper
//! - Stereo only: the flow and the motion terms are left out. As in the paper, the disparity term is the distance
//!   to a given semi-dense map (theirs from SGM, here the LRC-checked inference output).
//! - The impossible-occlusion penalty is proportional to the fraction of boundary points where the occluder is
//!   behind, instead of a hard penalty for any such point (more stable with noisy planes).
//! - Pixel moves ignore the change of the boundary-label energy `E_b` (its pixel set `B_kl` changes only
//!   slightly per pixel); `E_b` acts through the labels and the plane fits.
//! - One pixel sweep per outer iteration, and the plane update is Jacobi (all segments at once) rather than
//!   Gauss–Seidel, so it is parallel and order-independent.
//! - Segments that lack data borrow a neighbour's plane (see above) so that the output is dense; stale planes are
//!   re-initialised by RANSAC.
//! - Untrusted (filled) pixels may enter the data term with a small weight.
//! - The data a segment needs for a plane of its own can be a fraction of its size (`min_support_fraction`): a
//!   few consistent pixels in one corner of a segment otherwise set a plane that is extrapolated over the rest.
//!
//! # Complexity
//! Per iteration O(N) for the sweep and statistics (N pixels) plus O(K) for K segments; RANSAC is
//! O(ransac_iterations · N) once (and again for stale segments only). All sums run in fixed blocks of rows merged
//! in order, so results are bitwise identical for any thread count; randomness is a per-segment generator seeded
//! from `seed` and the segment id. Motorcycle Q (741×497) with the defaults: ≈ 0.2 s on 2 cores, ≈ 0.3 s of CPU.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::image::{DisparityMap, Plane, RgbImage};
use crate::params::{check_nonneg, check_positive};
use crate::rng::SplitMix64;

/// Slanted-plane smoothing parameters (see the module doc for the energy they weight).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SpsParams {
    /// Run the stage.
    pub enabled: bool,
    /// Target number of segments; the initial grid step is √(pixels / segments).
    pub segments: usize,
    /// Outer iterations (pixel sweep, labels, planes).
    pub iterations: usize,
    /// λ_pos: weight of the squared distance to the segment centre, in grid steps.
    pub position_weight: f32,
    /// λ_d: weight of the squared disparity-to-plane residual (px²).
    pub disparity_weight: f32,
    /// τ: residuals beyond this (px) are outliers, with the constant cost λ_d·τ², and are left out of the fit.
    pub inlier_thresh_px: f32,
    /// λ_bou: cost per 8-neighbour pair in different segments.
    pub boundary_weight: f32,
    /// λ_s: weight of the mean squared plane difference of hinge and coplanar boundaries.
    pub smoothness_weight: f32,
    /// Constant cost of a hinge boundary.
    pub hinge_penalty: f32,
    /// Constant cost of an occlusion boundary.
    pub occlusion_penalty: f32,
    /// Cost of an occlusion boundary whose occluder is behind along the whole boundary (scaled by the fraction).
    pub impossible_penalty: f32,
    /// Data weight of finite pixels that are not trusted (e.g. filled ones), 0 to 1; trusted pixels weigh 1.
    pub untrusted_weight: f32,
    /// A segment needs at least this much data weight to fit a plane without coupled neighbours.
    pub min_support: f32,
    /// ... and at least this fraction of its pixel count (0 to 1; 0 = only `min_support` applies). A fraction
    /// scales with the segment size, which an absolute count does not (cells are 64 px on ArtL Q at 1500
    /// segments, about 245 px on Motorcycle Q).
    pub min_support_fraction: f32,
    /// RANSAC trials per segment at initialisation.
    pub ransac_iterations: usize,
    /// Seed of the RANSAC sampling.
    pub seed: u64,
}

impl Default for SpsParams {
    fn default() -> Self {
        // segments, untrusted_weight, disparity_weight and inlier_thresh_px were tuned on trainingQ with the full pipeline (docs/RESULTS.md);
        // the rest were set by reasoning about magnitudes.
        SpsParams {
            enabled: true,
            segments: 1500,
            iterations: 10,
            position_weight: 300.0,
            disparity_weight: 100.0,
            inlier_thresh_px: 3.0,
            boundary_weight: 30.0,
            smoothness_weight: 400.0,
            hinge_penalty: 5.0,
            occlusion_penalty: 15.0,
            impossible_penalty: 30.0,
            untrusted_weight: 0.3,
            min_support: 10.0,
            min_support_fraction: 0.0,
            ransac_iterations: 64,
            seed: 1,
        }
    }
}

impl SpsParams {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`crate::Error::InvalidParam`] naming the key.
    pub fn validate(&self) -> Result<()> {
        if self.segments == 0 || self.segments > 1 << 24 {
            return Err(crate::Error::param("post.sps.segments", self.segments, "1 to 16777216"));
        }
        if self.iterations > 1000 {
            return Err(crate::Error::param("post.sps.iterations", self.iterations, "0 to 1000"));
        }
        if self.ransac_iterations == 0 || self.ransac_iterations > 100_000 {
            return Err(crate::Error::param("post.sps.ransac_iterations", self.ransac_iterations, "1 to 100000"));
        }
        check_nonneg("post.sps.position_weight", self.position_weight)?;
        check_nonneg("post.sps.disparity_weight", self.disparity_weight)?;
        check_positive("post.sps.inlier_thresh_px", self.inlier_thresh_px)?;
        check_nonneg("post.sps.boundary_weight", self.boundary_weight)?;
        check_nonneg("post.sps.smoothness_weight", self.smoothness_weight)?;
        check_nonneg("post.sps.hinge_penalty", self.hinge_penalty)?;
        check_nonneg("post.sps.occlusion_penalty", self.occlusion_penalty)?;
        check_nonneg("post.sps.impossible_penalty", self.impossible_penalty)?;
        check_nonneg("post.sps.min_support", self.min_support)?;
        if !(0.0..=1.0).contains(&self.min_support_fraction) {
            return Err(crate::Error::param("post.sps.min_support_fraction", self.min_support_fraction, "0 to 1"));
        }
        if !(0.0..=1.0).contains(&self.untrusted_weight) {
            return Err(crate::Error::param("post.sps.untrusted_weight", self.untrusted_weight, "0 to 1"));
        }
        Ok(())
    }
}

/// Fits slanted planes to superpixels and returns each pixel's disparity from its plane (see the module doc).
///
/// `trusted` marks the pixels whose disparity is reliable (the LRC-consistent ones); `inf` disparities are never
/// used. The output is dense and finite.
///
/// # Panics
/// If `image`, `disp` and `trusted` differ in size.
///
/// # Examples
/// ```
/// use jem::image::{Plane, RgbImage};
/// use jem::post::planes::{fit_slanted_planes, SpsParams};
/// // A plane d = 0.1·x + 2 with a hole at (3, 2).
/// let (w, h) = (8, 6);
/// let mut disp = Plane::from_vec(w, h, (0..w * h).map(|i| 0.1 * (i % w) as f32 + 2.0).collect());
/// disp.data[2 * w + 3] = f32::INFINITY;
/// let trusted = Plane::from_vec(w, h, disp.data.iter().map(|d| d.is_finite()).collect());
/// let out = fit_slanted_planes(&RgbImage::new(w, h), &disp, &trusted, &SpsParams { segments: 4, ..Default::default() });
/// assert!((out.at(3, 2) - 2.3).abs() < 1e-4);
/// ```
pub fn fit_slanted_planes(image: &RgbImage, disp: &DisparityMap, trusted: &Plane<bool>, p: &SpsParams) -> DisparityMap {
    assert_eq!(image.dims(), disp.dims(), "image and disparity map differ in size");
    assert_eq!(trusted.dims(), disp.dims(), "disparity map and trusted mask differ in size");
    let (w, h) = disp.dims();
    if w == 0 || h == 0 {
        return disp.clone();
    }
    let scene = Scene::new(image, disp, trusted, p);
    let (labels, planes) = segment_and_fit(&scene, p);
    render(&labels, &planes, w, scene.max_disp + p.inlier_thresh_px)
}

/// The alternation of the module doc: returns the final segment labels (row-major) and one plane per segment.
fn segment_and_fit(scene: &Scene, p: &SpsParams) -> (Vec<u32>, Vec<[f64; 3]>) {
    let (w, h) = (scene.width, scene.height);
    let step = ((w * h) as f64 / p.segments as f64).sqrt().max(1.0);
    let (mut labels, nseg) = grid_labels(w, h, step);
    let mut adj = Adjacency::new(nseg);

    // Initialisation: RANSAC planes on the grid cells.
    let acc = accumulate(scene, &labels, nseg, None);
    let bounds = adj.rebuild(&labels, w, h, None);
    let mut planes = ransac_planes(scene, &labels, nseg, p, |_| true);
    let mut planes_full = borrow_missing(&mut planes, &adj, &bounds, &acc, scene);
    let mut acc = accumulate(scene, &labels, nseg, Some(&planes_full));

    let pos_scale = f64::from(p.position_weight) / (step * step);
    for _ in 0..p.iterations {
        let models: Vec<SegModel> = acc.iter().zip(&planes_full).map(|(a, pl)| SegModel::new(a, *pl)).collect();
        sweep(scene, &mut labels, &models, pos_scale as f32, p);
        acc = accumulate(scene, &labels, nseg, Some(&planes_full));
        let mut bounds = adj.rebuild(&labels, w, h, Some(&planes_full));
        for b in &mut bounds {
            b.label = choose_label(b, &acc, &planes_full, p);
        }
        let mut planes = refit_planes(&acc, &adj, &bounds, &planes_full, p);
        // Segments whose plane no longer explains their data start again from RANSAC.
        let stale = |a: &SegAcc| a.is_stale(support_needed(p, a.geom.s1));
        if acc.iter().any(stale) {
            let fresh = ransac_planes(scene, &labels, nseg, p, |k| stale(&acc[k]));
            for ((pl, f), a) in planes.iter_mut().zip(fresh).zip(&acc) {
                if stale(a) {
                    *pl = f;
                }
            }
        }
        planes_full = borrow_missing(&mut planes, &adj, &bounds, &acc, scene);
    }
    (labels, planes_full)
}

/// Per-pixel inputs: Lab colour, disparity and data weight.
struct Scene<'a> {
    width: usize,
    height: usize,
    lab: [Vec<f32>; 3],
    disp: &'a [f32],
    weight: Vec<f32>,
    /// Largest finite input disparity (0 if none).
    max_disp: f32,
    /// τ, the inlier threshold.
    tau: f32,
}

impl<'a> Scene<'a> {
    fn new(image: &RgbImage, disp: &'a DisparityMap, trusted: &Plane<bool>, p: &SpsParams) -> Self {
        let weight = disp
            .data
            .iter()
            .zip(&trusted.data)
            .map(|(d, &t)| match (d.is_finite(), t) {
                (false, _) => 0.0,
                (true, true) => 1.0,
                (true, false) => p.untrusted_weight,
            })
            .collect();
        let max_disp = disp.data.iter().copied().filter(|d| d.is_finite()).fold(0.0f32, f32::max);
        Scene {
            width: disp.width,
            height: disp.height,
            lab: rgb_to_lab(image),
            disp: &disp.data,
            weight,
            max_disp,
            tau: p.inlier_thresh_px,
        }
    }
}

/// CIE L*a*b* (D65 white) of an sRGB image with samples in 0..=255: L in 0..100, a and b roughly ±100.
fn rgb_to_lab(image: &RgbImage) -> [Vec<f32>; 3] {
    fn srgb_to_linear(v: f32) -> f32 {
        let c = (v / 255.0).clamp(0.0, 1.0);
        if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
    }
    // 8-bit inputs (integers) are looked up; others (from 16-bit files) computed.
    let table: Vec<f32> = (0..256).map(|v| srgb_to_linear(v as f32)).collect();
    let linear =
        |v: f32| if (0.0..=255.0).contains(&v) && v == v.trunc() { table[v as usize] } else { srgb_to_linear(v) };
    fn f(t: f32) -> f32 {
        // (6/29)³ and the linear segment below it, from the CIE definition.
        const E: f32 = 216.0 / 24389.0;
        if t > E { cbrt_fast(t) } else { t * (841.0 / 108.0) + 4.0 / 29.0 }
    }
    let n = image.len();
    let mut lab = [vec![0.0f32; n], vec![0.0; n], vec![0.0; n]];
    let [l_out, a_out, b_out] = &mut lab;
    let [r, g, b] = &image.channels;
    (l_out, a_out, b_out, r, g, b).into_par_iter().with_min_len(4096).for_each(|(lo, ao, bo, &r, &g, &b)| {
        let (r, g, b) = (linear(r), linear(g), linear(b));
        // sRGB → XYZ (D65), divided by the white point (0.95047, 1, 1.08883).
        let x = (0.412_456_4 * r + 0.357_576_1 * g + 0.180_437_5 * b) / 0.950_47;
        let y = 0.212_672_9 * r + 0.715_152_2 * g + 0.072_175 * b;
        let z = (0.019_333_9 * r + 0.119_192 * g + 0.950_304_1 * b) / 1.088_83;
        let (fx, fy, fz) = (f(x), f(y), f(z));
        *lo = 116.0 * fy - 16.0;
        *ao = 500.0 * (fx - fy);
        *bo = 200.0 * (fy - fz);
    });
    lab
}

/// Cube root of t > 0 to within 1e-6 relative (tested): an exponent-bits estimate refined by three Newton steps.
/// Several times cheaper than libm's `cbrtf`, which dominated the colour conversion.
#[inline]
fn cbrt_fast(t: f32) -> f32 {
    // Dividing the biased exponent by 3: bits/3 + (2/3)·127·2²³ gives a first guess within ~6%.
    let mut y = f32::from_bits(t.to_bits() / 3 + 709_921_077);
    for _ in 0..3 {
        y -= (y * y * y - t) / (3.0 * y * y);
    }
    y
}

/// A regular grid of about `w·h / step²` cells, as even as possible. Returns (labels, number of segments).
fn grid_labels(w: usize, h: usize, step: f64) -> (Vec<u32>, usize) {
    let nx = ((w as f64 / step).round() as usize).clamp(1, w);
    let ny = ((h as f64 / step).round() as usize).clamp(1, h);
    let mut labels = vec![0u32; w * h];
    labels.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let cy = y * ny / h;
        for (x, l) in row.iter_mut().enumerate() {
            *l = (cy * nx + x * nx / w) as u32;
        }
    });
    (labels, nx * ny)
}

/// Weighted first and second moments of points (x, y) with targets t: the normal equations of a plane fit.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Moments {
    s1: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
    syy: f64,
    st: f64,
    sxt: f64,
    syt: f64,
}

impl Moments {
    #[inline]
    fn add(&mut self, wt: f64, x: f64, y: f64, t: f64) {
        let (wx, wy) = (wt * x, wt * y);
        self.s1 += wt;
        self.sx += wx;
        self.sy += wy;
        self.sxx += wx * x;
        self.sxy += wx * y;
        self.syy += wy * y;
        self.st += wt * t;
        self.sxt += wx * t;
        self.syt += wy * t;
    }

    fn merge(&mut self, o: &Moments) {
        self.merge_scaled(o, 1.0);
    }

    fn merge_scaled(&mut self, o: &Moments, k: f64) {
        self.s1 += k * o.s1;
        self.sx += k * o.sx;
        self.sy += k * o.sy;
        self.sxx += k * o.sxx;
        self.sxy += k * o.sxy;
        self.syy += k * o.syy;
        self.st += k * o.st;
        self.sxt += k * o.sxt;
        self.syt += k * o.syt;
    }

    /// The same points with the targets replaced by a plane's values (the coupling terms' "data").
    fn with_plane_targets(&self, pl: &[f64; 3]) -> Moments {
        let [a, b, c] = *pl;
        Moments {
            st: a * self.sx + b * self.sy + c * self.s1,
            sxt: a * self.sxx + b * self.sxy + c * self.sx,
            syt: a * self.sxy + b * self.syy + c * self.sy,
            ..*self
        }
    }

    /// Σ wt · (Δ · (x, y, 1))², the weighted squared difference of two planes over the points.
    fn quad_form(&self, dl: &[f64; 3]) -> f64 {
        let [a, b, c] = *dl;
        (a * a * self.sxx
            + 2.0 * a * b * self.sxy
            + b * b * self.syy
            + 2.0 * a * c * self.sx
            + 2.0 * b * c * self.sy
            + c * c * self.s1)
            .max(0.0)
    }

    /// Least-squares plane, `None` without weight or when degenerate and `ridge` is false (see the module doc).
    fn solve(&self, ridge: bool) -> Option<[f64; 3]> {
        if self.s1.is_nan() || self.s1 <= 0.0 {
            return None;
        }
        // Centre on the weighted centroid: the constant decouples from the slopes.
        let (mx, my) = (self.sx / self.s1, self.sy / self.s1);
        let mut sxx = self.sxx - self.sx * mx;
        let sxy = self.sxy - self.sx * my;
        let mut syy = self.syy - self.sy * my;
        let (sxt, syt) = (self.sxt - self.st * mx, self.syt - self.st * my);
        // det of the centred 3×3 normal matrix [[sxx, sxy, 0], [sxy, syy, 0], [0, 0, s1]].
        let det = self.s1 * (sxx * syy - sxy * sxy);
        let bound = self.s1 * sxx.max(0.0) * syy.max(0.0);
        // Written so that a NaN determinant also counts as degenerate.
        let well_posed = bound > 0.0 && det.abs() > 1e-6 * bound;
        if !well_posed {
            if !ridge {
                return None;
            }
            // Ridge on the slopes: 0.25 px² per unit weight, the spread of two adjacent rows.
            sxx = sxx.max(0.0) + 0.25 * self.s1;
            syy = syy.max(0.0) + 0.25 * self.s1;
        }
        let det2 = sxx * syy - sxy * sxy;
        let a = (sxt * syy - syt * sxy) / det2;
        let b = (syt * sxx - sxt * sxy) / det2;
        let c = self.st / self.s1 - a * mx - b * my;
        (a.is_finite() && b.is_finite() && c.is_finite()).then_some([a, b, c])
    }
}

#[inline]
fn eval(pl: &[f64; 3], x: f64, y: f64) -> f64 {
    pl[0] * x + pl[1] * y + pl[2]
}

/// Per-segment sums: pixel moments (targets unused), Lab sums, inlier data moments, all data moments and Σ w·d².
#[derive(Clone, Copy, Debug, Default)]
struct SegAcc {
    geom: Moments,
    lab: [f64; 3],
    data: Moments,
    all: Moments,
    sdd: f64,
}

impl SegAcc {
    fn centre(&self) -> [f64; 2] {
        let n = self.geom.s1.max(1.0);
        [self.geom.sx / n, self.geom.sy / n]
    }

    /// Σ w·(d − θ(p))² over all the segment's data.
    fn sq_residual(&self, pl: &[f64; 3]) -> f64 {
        let m = &self.all;
        let cross = pl[0] * m.sxt + pl[1] * m.syt + pl[2] * m.st;
        (self.sdd - 2.0 * cross + m.quad_form(pl)).max(0.0)
    }

    /// The plane explains less than half of the segment's data (its pixels changed surface): refit from scratch.
    fn is_stale(&self, min_support: f64) -> bool {
        self.all.s1 >= min_support && self.all.s1 > 0.0 && self.data.s1 < 0.5 * self.all.s1
    }
}

/// Rows per block of the statistics pass: blocks are summed independently and merged in order, so the sums do
/// not depend on the thread count.
const BLOCK_ROWS: usize = 32;

/// Segment statistics; data pixels count as inliers when within τ of their segment's plane (all of them when
/// `planes` is `None`).
fn accumulate(scene: &Scene, labels: &[u32], nseg: usize, planes: Option<&[[f64; 3]]>) -> Vec<SegAcc> {
    let (w, h) = (scene.width, scene.height);
    let tau = f64::from(scene.tau);
    let partial: Vec<Vec<SegAcc>> = (0..h.div_ceil(BLOCK_ROWS))
        .into_par_iter()
        .map(|blk| {
            let mut acc = vec![SegAcc::default(); nseg];
            for y in blk * BLOCK_ROWS..((blk + 1) * BLOCK_ROWS).min(h) {
                let yf = y as f64;
                for x in 0..w {
                    let i = y * w + x;
                    let s = labels[i] as usize;
                    let a = &mut acc[s];
                    let xf = x as f64;
                    a.geom.add(1.0, xf, yf, 0.0);
                    for c in 0..3 {
                        a.lab[c] += f64::from(scene.lab[c][i]);
                    }
                    let wt = scene.weight[i];
                    if wt > 0.0 {
                        let (wt, d) = (f64::from(wt), f64::from(scene.disp[i]));
                        a.all.add(wt, xf, yf, d);
                        a.sdd += wt * d * d;
                        if planes.is_none_or(|pl| (d - eval(&pl[s], xf, yf)).abs() < tau) {
                            a.data.add(wt, xf, yf, d);
                        }
                    }
                }
            }
            acc
        })
        .collect();
    let mut total = vec![SegAcc::default(); nseg];
    for part in &partial {
        for (t, a) in total.iter_mut().zip(part) {
            t.geom.merge(&a.geom);
            t.data.merge(&a.data);
            t.all.merge(&a.all);
            t.sdd += a.sdd;
            for c in 0..3 {
                t.lab[c] += a.lab[c];
            }
        }
    }
    total
}

/// Boundary label (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum BoundaryLabel {
    Coplanar,
    Hinge,
    /// The lower-numbered segment `a` is in front.
    OcclusionA,
    /// The higher-numbered segment `b` is in front.
    OcclusionB,
}

/// One boundary between segments `a < b`.
#[derive(Clone, Debug)]
struct Boundary {
    a: u32,
    b: u32,
    /// Midpoints of the 4-adjacent pixel pairs across the boundary (`s1` = their number).
    geom: Moments,
    /// Midpoints where `a`'s plane is below `b`'s (so `a` cannot be the occluder there), and vice versa.
    a_behind: f64,
    b_behind: f64,
    label: BoundaryLabel,
}

/// Segment adjacency: for each segment, its (neighbour, boundary index) pairs in order of first encounter.
struct Adjacency {
    lists: Vec<Vec<(u32, u32)>>,
}

impl Adjacency {
    fn new(nseg: usize) -> Self {
        Adjacency { lists: vec![Vec::new(); nseg] }
    }

    /// Rebuilds the adjacency from the labels (raster order, so deterministic) and returns the boundaries, all
    /// labelled occlusion-A until [`choose_label`] runs; with planes, it also counts the occlusion violations.
    fn rebuild(&mut self, labels: &[u32], w: usize, h: usize, planes: Option<&[[f64; 3]]>) -> Vec<Boundary> {
        for l in &mut self.lists {
            l.clear();
        }
        let mut bounds: Vec<Boundary> = Vec::new();
        let mut visit = |s: u32, t: u32, mx: f64, my: f64| {
            let (a, b) = if s < t { (s, t) } else { (t, s) };
            let found = self.lists[a as usize].iter().find(|(n, _)| *n == b).map(|&(_, k)| k as usize);
            let k = match found {
                Some(k) => k,
                None => {
                    let k = bounds.len();
                    self.lists[a as usize].push((b, k as u32));
                    self.lists[b as usize].push((a, k as u32));
                    bounds.push(Boundary {
                        a,
                        b,
                        geom: Moments::default(),
                        a_behind: 0.0,
                        b_behind: 0.0,
                        label: BoundaryLabel::OcclusionA,
                    });
                    k
                }
            };
            let bd = &mut bounds[k];
            bd.geom.add(1.0, mx, my, 0.0);
            if let Some(pl) = planes {
                let (da, db) = (eval(&pl[a as usize], mx, my), eval(&pl[b as usize], mx, my));
                if da < db {
                    bd.a_behind += 1.0;
                } else if db < da {
                    bd.b_behind += 1.0;
                }
            }
        };
        for y in 0..h {
            let row = &labels[y * w..][..w];
            for x in 0..w {
                let s = row[x];
                if x + 1 < w && row[x + 1] != s {
                    visit(s, row[x + 1], x as f64 + 0.5, y as f64);
                }
                if y + 1 < h && labels[(y + 1) * w + x] != s {
                    visit(s, labels[(y + 1) * w + x], x as f64, y as f64 + 0.5);
                }
            }
        }
        bounds
    }
}

/// The label of least boundary energy given the planes.
fn choose_label(b: &Boundary, acc: &[SegAcc], planes: &[[f64; 3]], p: &SpsParams) -> BoundaryLabel {
    let (pa, pb) = (&planes[b.a as usize], &planes[b.b as usize]);
    let dl = [pa[0] - pb[0], pa[1] - pb[1], pa[2] - pb[2]];
    let mut union = acc[b.a as usize].geom;
    union.merge(&acc[b.b as usize].geom);
    let ls = f64::from(p.smoothness_weight);
    let n_b = b.geom.s1.max(1.0);
    let candidates = [
        (BoundaryLabel::Coplanar, ls * union.quad_form(&dl) / union.s1.max(1.0)),
        (BoundaryLabel::Hinge, f64::from(p.hinge_penalty) + ls * b.geom.quad_form(&dl) / n_b),
        (
            BoundaryLabel::OcclusionA,
            f64::from(p.occlusion_penalty) + f64::from(p.impossible_penalty) * b.a_behind / n_b,
        ),
        (
            BoundaryLabel::OcclusionB,
            f64::from(p.occlusion_penalty) + f64::from(p.impossible_penalty) * b.b_behind / n_b,
        ),
    ];
    let mut best = candidates[0];
    for c in &candidates[1..] {
        if c.1 < best.1 {
            best = *c;
        }
    }
    best.0
}

/// One Jacobi step of the plane fits: inlier data plus hinge/coplanar couplings to the neighbours' old planes.
/// `None` for a segment with too little data and no coupling.
fn refit_planes(
    acc: &[SegAcc],
    adj: &Adjacency,
    bounds: &[Boundary],
    old: &[[f64; 3]],
    p: &SpsParams,
) -> Vec<Option<[f64; 3]>> {
    let (ld, ls) = (f64::from(p.disparity_weight), f64::from(p.smoothness_weight));
    (0..acc.len())
        .into_par_iter()
        .map(|k| {
            let mut sys = Moments::default();
            sys.merge_scaled(&acc[k].data, ld);
            let mut coupled = false;
            for &(j, bi) in &adj.lists[k] {
                let (j, b) = (j as usize, &bounds[bi as usize]);
                match b.label {
                    BoundaryLabel::Hinge => {
                        sys.merge_scaled(&b.geom.with_plane_targets(&old[j]), ls / b.geom.s1.max(1.0));
                        coupled = true;
                    }
                    BoundaryLabel::Coplanar => {
                        let mut union = acc[k].geom;
                        union.merge(&acc[j].geom);
                        sys.merge_scaled(&union.with_plane_targets(&old[j]), ls / union.s1.max(1.0));
                        coupled = true;
                    }
                    BoundaryLabel::OcclusionA | BoundaryLabel::OcclusionB => {}
                }
            }
            if !(coupled && ls > 0.0) && acc[k].data.s1 < support_needed(p, acc[k].geom.s1).max(f64::MIN_POSITIVE) {
                return None;
            }
            sys.solve(true)
        })
        .collect()
}

/// The data weight a segment of `pixels` pixels needs to fit a plane of its own: `min_support`, or
/// `min_support_fraction` of its pixels if that is more.
fn support_needed(p: &SpsParams, pixels: f64) -> f64 {
    f64::from(p.min_support).max(f64::from(p.min_support_fraction) * pixels)
}

/// Gives every segment without a plane the plane of an adjacent segment, in rounds: the one that fits the
/// segment's (scarce) data best, or without data the one that is lowest on their common boundary (the background
/// side of an occlusion). If no segment has a plane, a fronto-parallel plane at the median of the data (0 without
/// data).
fn borrow_missing(
    planes: &mut [Option<[f64; 3]>],
    adj: &Adjacency,
    bounds: &[Boundary],
    acc: &[SegAcc],
    scene: &Scene,
) -> Vec<[f64; 3]> {
    loop {
        let before = planes.to_vec();
        let mut changed = false;
        for (k, slot) in planes.iter_mut().enumerate().filter(|(_, s)| s.is_none()) {
            let has_data = acc[k].all.s1 > 0.0;
            let mut best: Option<([f64; 3], f64)> = None;
            for &(j, bi) in &adj.lists[k] {
                if let Some(pl) = before[j as usize] {
                    let g = &bounds[bi as usize].geom;
                    let v = if has_data { acc[k].sq_residual(&pl) } else { eval(&pl, g.sx / g.s1, g.sy / g.s1) };
                    if best.is_none_or(|(_, bv)| v < bv) {
                        best = Some((pl, v));
                    }
                }
            }
            if let Some((pl, _)) = best {
                *slot = Some(pl);
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    let fallback = [0.0, 0.0, median_of_data(scene)];
    planes.iter().map(|pl| pl.unwrap_or(fallback)).collect()
}

/// The median of the disparities with data weight > 0 (the lower median; 0 without any).
fn median_of_data(scene: &Scene) -> f64 {
    let mut v: Vec<f32> = scene.disp.iter().zip(&scene.weight).filter(|(_, w)| **w > 0.0).map(|(d, _)| *d).collect();
    if v.is_empty() {
        return 0.0;
    }
    let mid = (v.len() - 1) / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    f64::from(*m)
}

/// RANSAC plane per `selected` segment (see the module doc); `None` where the data weight is below
/// [`support_needed`] and for the others.
fn ransac_planes(
    scene: &Scene,
    labels: &[u32],
    nseg: usize,
    p: &SpsParams,
    selected: impl Fn(usize) -> bool + Sync,
) -> Vec<Option<[f64; 3]>> {
    // Data pixels grouped by segment (counting sort, raster order within a segment).
    let mut start = vec![0usize; nseg + 1];
    let mut pixels = vec![0usize; nseg];
    for (l, w) in labels.iter().zip(&scene.weight) {
        pixels[*l as usize] += 1;
        if *w > 0.0 {
            start[*l as usize + 1] += 1;
        }
    }
    for k in 0..nseg {
        start[k + 1] += start[k];
    }
    let mut fill = start.clone();
    let mut members = vec![0u32; start[nseg]];
    for (i, (l, w)) in labels.iter().zip(&scene.weight).enumerate() {
        if *w > 0.0 {
            members[fill[*l as usize]] = i as u32;
            fill[*l as usize] += 1;
        }
    }
    (0..nseg)
        .into_par_iter()
        .map_init(Points::default, |pts, k| {
            if !selected(k) {
                return None;
            }
            pts.load(scene, &members[start[k]..start[k + 1]]);
            let mut rng = SplitMix64::new(p.seed ^ (k as u64).wrapping_mul(0xd6e8_feb8_6659_fd93));
            ransac_segment(pts, p, support_needed(p, pixels[k] as f64), &mut rng)
        })
        .collect()
}

/// The data points of one segment, structure of arrays, coordinates relative to the first point (exact in f32).
#[derive(Default)]
struct Points {
    origin: [f64; 2],
    x: Vec<f32>,
    y: Vec<f32>,
    d: Vec<f32>,
    w: Vec<f32>,
}

impl Points {
    fn load(&mut self, scene: &Scene, members: &[u32]) {
        let w = scene.width;
        let first = members.first().map_or(0, |&i| i as usize);
        let (x0, y0) = (first % w, first / w);
        self.origin = [x0 as f64, y0 as f64];
        self.x.clear();
        self.y.clear();
        self.d.clear();
        self.w.clear();
        for &i in members {
            let i = i as usize;
            self.x.push((i % w) as f32 - x0 as f32);
            self.y.push((i / w) as f32 - y0 as f32);
            self.d.push(scene.disp[i]);
            self.w.push(scene.weight[i]);
        }
    }

    fn len(&self) -> usize {
        self.x.len()
    }

    /// Σ w over the points within `tau` of the plane (absolute coordinates), in eight lanes so it vectorises.
    fn inlier_weight(&self, pl: &[f64; 3], tau: f32) -> f32 {
        let (a, b) = (pl[0] as f32, pl[1] as f32);
        let c = (pl[2] + pl[0] * self.origin[0] + pl[1] * self.origin[1]) as f32;
        let mut lanes = [0.0f32; 8];
        let chunks = self.x.chunks_exact(8).zip(self.y.chunks_exact(8)).zip(self.d.chunks_exact(8));
        for (((x, y), d), w) in chunks.zip(self.w.chunks_exact(8)) {
            for l in 0..8 {
                let r = d[l] - (a * x[l] + b * y[l] + c);
                lanes[l] += if r.abs() < tau { w[l] } else { 0.0 };
            }
        }
        for k in self.len() / 8 * 8..self.len() {
            let r = self.d[k] - (a * self.x[k] + b * self.y[k] + c);
            lanes[0] += if r.abs() < tau { self.w[k] } else { 0.0 };
        }
        ((lanes[0] + lanes[1]) + (lanes[2] + lanes[3])) + ((lanes[4] + lanes[5]) + (lanes[6] + lanes[7]))
    }

    /// Moments of the points within `tau` of the plane (absolute coordinates).
    fn inlier_moments(&self, pl: &[f64; 3], tau: f64) -> Moments {
        let mut m = Moments::default();
        for k in 0..self.len() {
            let (x, y) = (f64::from(self.x[k]) + self.origin[0], f64::from(self.y[k]) + self.origin[1]);
            let d = f64::from(self.d[k]);
            if (d - eval(pl, x, y)).abs() < tau {
                m.add(f64::from(self.w[k]), x, y, d);
            }
        }
        m
    }
}

fn ransac_segment(pts: &Points, p: &SpsParams, min_weight: f64, rng: &mut SplitMix64) -> Option<[f64; 3]> {
    let total: f64 = pts.w.iter().map(|&w| f64::from(w)).sum();
    if pts.len() == 0 || total < min_weight {
        return None;
    }
    let n = pts.len();
    let mut best: Option<([f64; 3], f32)> = None;
    if n >= 3 {
        for _ in 0..p.ransac_iterations {
            let (i0, i1, i2) = (rng.below(n), rng.below(n), rng.below(n));
            if i0 == i1 || i1 == i2 || i0 == i2 {
                continue;
            }
            let mut m = Moments::default();
            for k in [i0, i1, i2] {
                let (x, y) = (f64::from(pts.x[k]) + pts.origin[0], f64::from(pts.y[k]) + pts.origin[1]);
                m.add(1.0, x, y, f64::from(pts.d[k]));
            }
            let Some(pl) = m.solve(false) else { continue };
            let score = pts.inlier_weight(&pl, p.inlier_thresh_px);
            if best.is_none_or(|(_, s)| score > s) {
                best = Some((pl, score));
            }
        }
    }
    let tau = f64::from(p.inlier_thresh_px);
    match best {
        // Two rounds of least squares on the inliers.
        Some((pl, _)) => {
            let pl = pts.inlier_moments(&pl, tau).solve(true).unwrap_or(pl);
            Some(pts.inlier_moments(&pl, tau).solve(true).unwrap_or(pl))
        }
        // Too few points or all samples degenerate: fronto-parallel at the median.
        None => {
            let mut v = pts.d.clone();
            let mid = (v.len() - 1) / 2;
            let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
            Some([0.0, 0.0, f64::from(*m)])
        }
    }
}

/// What a pixel move needs of a segment, in `f32` for the sweep.
#[derive(Clone, Copy, Debug)]
struct SegModel {
    lab: [f32; 3],
    centre: [f32; 2],
    plane: [f64; 3],
}

impl SegModel {
    fn new(a: &SegAcc, plane: [f64; 3]) -> Self {
        let n = a.geom.s1.max(1.0);
        let c = a.centre();
        SegModel {
            lab: [(a.lab[0] / n) as f32, (a.lab[1] / n) as f32, (a.lab[2] / n) as f32],
            centre: [c[0] as f32, c[1] as f32],
            plane,
        }
    }
}

/// One sweep over the boundary pixels in 9 parallel phases (see the module doc).
fn sweep(scene: &Scene, labels: &mut [u32], models: &[SegModel], pos_scale: f32, p: &SpsParams) {
    let (w, h) = (scene.width, scene.height);
    let lambda_d = p.disparity_weight;
    let tau2 = p.inlier_thresh_px * p.inlier_thresh_px;
    let lambda_bou = p.boundary_weight;
    for phase in 0..9 {
        let (px, py) = (phase % 3, phase / 3);
        let cur: &[u32] = labels;
        let changes: Vec<(usize, u32)> = (py..h)
            .into_par_iter()
            .step_by(3)
            .flat_map_iter(|y| {
                let mut out = Vec::new();
                for x in (px..w).step_by(3) {
                    let i = y * w + x;
                    let s = cur[i];
                    let mut cand = [u32::MAX; 4];
                    let mut nc = 0;
                    for n in [
                        (y > 0).then(|| i - w),
                        (x > 0).then(|| i - 1),
                        (x + 1 < w).then(|| i + 1),
                        (y + 1 < h).then(|| i + w),
                    ]
                    .into_iter()
                    .flatten()
                    {
                        let t = cur[n];
                        if t != s && !cand[..nc].contains(&t) {
                            cand[nc] = t;
                            nc += 1;
                        }
                    }
                    if nc == 0 || !can_leave(cur, w, h, x, y, s) {
                        continue;
                    }
                    let energy = |t: u32| -> f32 {
                        let m = &models[t as usize];
                        let mut e = 0.0;
                        for c in 0..3 {
                            let dc = scene.lab[c][i] - m.lab[c];
                            e += dc * dc;
                        }
                        let (dx, dy) = (x as f32 - m.centre[0], y as f32 - m.centre[1]);
                        e += pos_scale * (dx * dx + dy * dy);
                        let wt = scene.weight[i];
                        if wt > 0.0 {
                            let r = (f64::from(scene.disp[i]) - eval(&m.plane, x as f64, y as f64)) as f32;
                            e += lambda_d * wt * (r * r).min(tau2);
                        }
                        e + lambda_bou * (8 - same_label_neighbours(cur, w, h, x, y, t)) as f32
                    };
                    let mut best = (s, energy(s));
                    for &t in &cand[..nc] {
                        let e = energy(t);
                        if e < best.1 {
                            best = (t, e);
                        }
                    }
                    if best.0 != s {
                        out.push((i, best.0));
                    }
                }
                out
            })
            .collect();
        for (i, t) in changes {
            labels[i] = t;
        }
    }
}

/// Number of 8-neighbours of (x, y) labelled `t` (outside pixels count as different).
#[inline]
fn same_label_neighbours(labels: &[u32], w: usize, h: usize, x: usize, y: usize, t: u32) -> u32 {
    let mut n = 0;
    for yy in y.saturating_sub(1)..=(y + 1).min(h - 1) {
        for xx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
            if (xx != x || yy != y) && labels[yy * w + xx] == t {
                n += 1;
            }
        }
    }
    n
}

/// Whether pixel (x, y) can leave its segment `s` without disconnecting it: the pixels of `s` in its 3×3 ring
/// must form exactly one run (consecutive ring pixels are 4-adjacent) that touches a 4-neighbour. With no
/// 4-neighbour in `s` the pixel is the whole segment and stays.
fn can_leave(labels: &[u32], w: usize, h: usize, x: usize, y: usize, s: u32) -> bool {
    // Ring in circular order: N, NE, E, SE, S, SW, W, NW (even entries are the 4-neighbours).
    const RING: [(isize, isize); 8] = [(0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1)];
    let mut inside = [false; 8];
    for (k, (dx, dy)) in RING.iter().enumerate() {
        let (xx, yy) = (x as isize + dx, y as isize + dy);
        inside[k] = xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h && {
            labels[yy as usize * w + xx as usize] == s
        };
    }
    let mut runs_with_edge = 0;
    let mut any_start = false;
    for k in 0..8 {
        if inside[k] && !inside[(k + 7) % 8] {
            any_start = true;
            // Walk the run starting at k.
            let mut touches = false;
            let mut j = k;
            while inside[j % 8] && j < k + 8 {
                touches |= j % 2 == 0;
                j += 1;
            }
            runs_with_edge += usize::from(touches);
        }
    }
    if !any_start {
        // All eight inside (an interior pixel) or none: removable only in the first case.
        return inside[0];
    }
    runs_with_edge == 1
}

/// Each pixel's disparity from its segment's plane, clamped to [0, max].
fn render(labels: &[u32], planes: &[[f64; 3]], w: usize, max: f32) -> DisparityMap {
    let h = labels.len() / w;
    let mut out = Plane::new(w, h, 0.0f32);
    out.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, d) in row.iter_mut().enumerate() {
            let v = eval(&planes[labels[y * w + x] as usize], x as f64, y as f64) as f32;
            *d = if v.is_finite() { v.clamp(0.0, max) } else { 0.0 };
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_fit_on_exact_points_is_exact() {
        let truth = [0.37, -1.25, 42.5];
        let mut m = Moments::default();
        for (x, y) in [(3.0, 4.0), (10.0, 4.0), (5.0, 9.0), (700.0, 480.0), (12.0, 13.0)] {
            m.add(1.5, x, y, eval(&truth, x, y));
        }
        let pl = m.solve(false).unwrap();
        for k in 0..3 {
            assert!((pl[k] - truth[k]).abs() < 1e-9, "{pl:?} vs {truth:?}");
        }
        // Three points suffice.
        let mut m = Moments::default();
        for (x, y) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)] {
            m.add(1.0, x, y, eval(&truth, x, y));
        }
        let pl = m.solve(false).unwrap();
        assert!((pl[0] - 0.37).abs() < 1e-12 && (pl[1] + 1.25).abs() < 1e-12 && (pl[2] - 42.5).abs() < 1e-12);
    }

    #[test]
    fn degenerate_fits_fall_back() {
        // Collinear points (one row): strict solve refuses, ridge keeps the x slope and sets b = 0.
        let mut m = Moments::default();
        for x in 0..10 {
            m.add(1.0, f64::from(x), 5.0, 2.0 + 0.5 * f64::from(x));
        }
        assert_eq!(m.solve(false), None);
        let pl = m.solve(true).unwrap();
        // Exact data along the row: the ridge shrinks the slope by sxx/(sxx + 0.25·n) = 82.5/85.
        assert!((pl[0] - 0.5 * 82.5 / 85.0).abs() < 1e-12, "{pl:?}");
        assert_eq!(pl[1], 0.0);
        assert!((eval(&pl, 4.5, 5.0) - 4.25).abs() < 1e-12, "passes through the centroid");
        // A diagonal line: still degenerate (|det| = 0) although both diagonals of the matrix are non-zero.
        let mut m = Moments::default();
        for k in 0..6 {
            m.add(1.0, f64::from(k), f64::from(k), 1.0);
        }
        assert_eq!(m.solve(false), None);
        let pl = m.solve(true).unwrap();
        assert!(pl.iter().all(|v| v.is_finite()) && (eval(&pl, 2.5, 2.5) - 1.0).abs() < 1e-12);
        // A single point: fronto-parallel through it. No weight: nothing.
        let mut m = Moments::default();
        m.add(2.0, 7.0, 3.0, 9.0);
        assert_eq!(m.solve(true), Some([0.0, 0.0, 9.0]));
        assert_eq!(Moments::default().solve(true), None);
    }

    #[test]
    fn connectivity_test() {
        // 3×3 patches, centre pixel (1, 1) in segment 1.
        let check = |v: [u32; 9]| can_leave(&v, 3, 3, 1, 1, 1);
        // A bridge: 1s above and below, 0 on both sides → removing the centre splits the segment.
        assert!(!check([0, 1, 0, 0, 1, 0, 0, 1, 0]));
        // An end of a line: safe.
        assert!(check([0, 1, 0, 0, 1, 0, 0, 0, 0]));
        // An L corner with the diagonal inside: one run N-NE-E → safe.
        assert!(check([0, 1, 1, 0, 1, 1, 0, 0, 0]));
        // N and E without the NE diagonal: two runs → only connected through the centre.
        assert!(!check([0, 1, 0, 0, 1, 1, 0, 0, 0]));
        // Only a diagonal neighbour: the centre is a 4-connected singleton → it stays.
        assert!(!check([1, 0, 0, 0, 1, 0, 0, 0, 0]));
        // Everything in the segment.
        assert!(check([1; 9]));
        // At the image corner (0, 0) of a 2×2 image: neighbours E and S in the segment, SE too → one run.
        assert!(can_leave(&[1, 1, 1, 1], 2, 2, 0, 0, 1));
        assert!(!can_leave(&[1, 1, 1, 0], 2, 2, 0, 0, 1));
    }

    #[test]
    fn lab_of_known_colours() {
        let mut img = RgbImage::new(3, 1);
        for c in 0..3 {
            img.channels[c][1] = 255.0;
        }
        img.channels[0][2] = 255.0;
        let lab = rgb_to_lab(&img);
        // Black, white, pure red (L 53.24, a 80.09, b 67.20 in the usual tables).
        assert!(lab[0][0].abs() < 1e-4 && lab[1][0].abs() < 1e-4 && lab[2][0].abs() < 1e-4);
        assert!((lab[0][1] - 100.0).abs() < 1e-2 && lab[1][1].abs() < 1e-2 && lab[2][1].abs() < 1e-2);
        assert!(
            (lab[0][2] - 53.24).abs() < 0.02 && (lab[1][2] - 80.09).abs() < 0.05 && (lab[2][2] - 67.20).abs() < 0.05
        );
    }

    #[test]
    fn fast_cbrt_matches_std() {
        let mut worst = 0.0f64;
        let mut t = 216.0f32 / 24389.0;
        while t < 1.2 {
            worst = worst.max((f64::from(cbrt_fast(t)) - f64::from(t).cbrt()).abs() / f64::from(t).cbrt());
            t *= 1.0001;
        }
        assert!(worst < 1e-6, "worst relative error {worst}");
    }

    #[test]
    fn grid_is_even_and_complete() {
        let (labels, n) = grid_labels(10, 4, 2.0);
        assert_eq!(n, 10);
        assert_eq!(&labels[..10], &[0, 0, 1, 1, 2, 2, 3, 3, 4, 4]);
        assert_eq!(&labels[30..], &[5, 5, 6, 6, 7, 7, 8, 8, 9, 9]);
        let (labels, n) = grid_labels(1, 1, 50.0);
        assert_eq!((labels, n), (vec![0], 1));
    }

    /// Every label's pixels form one 4-connected component (flood fill from each label's first pixel).
    fn assert_connected(labels: &[u32], w: usize, h: usize) {
        let nseg = labels.iter().max().map_or(0, |m| *m as usize + 1);
        let mut seen = vec![false; labels.len()];
        let mut started = vec![false; nseg];
        for start in 0..labels.len() {
            if seen[start] {
                continue;
            }
            let l = labels[start];
            assert!(!started[l as usize], "segment {l} has a second component at pixel {start}");
            started[l as usize] = true;
            let mut stack = vec![start];
            seen[start] = true;
            while let Some(i) = stack.pop() {
                let (x, y) = (i % w, i / w);
                let nbrs = [
                    (x > 0).then(|| i - 1),
                    (x + 1 < w).then(|| i + 1),
                    (y > 0).then(|| i - w),
                    (y + 1 < h).then(|| i + w),
                ];
                for j in nbrs.into_iter().flatten() {
                    if !seen[j] && labels[j] == l {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
    }

    fn scene_of<'a>(img: &RgbImage, disp: &'a DisparityMap, trusted: &Plane<bool>, p: &SpsParams) -> Scene<'a> {
        Scene::new(img, disp, trusted, p)
    }

    #[test]
    fn segments_snap_to_a_colour_edge_and_stay_connected() {
        // 40×24, red left of x = 13, blue from x = 13 (not a grid line: cells are 8 px wide), constant disparity,
        // so only colour can move the boundaries.
        let (w, h) = (40, 24);
        let mut img = RgbImage::new(w, h);
        for i in 0..w * h {
            let c = if i % w < 13 { 0 } else { 2 };
            img.channels[c][i] = 200.0;
        }
        let disp = Plane::new(w, h, 4.0);
        let trusted = Plane::new(w, h, true);
        let p = SpsParams { segments: 15, ..SpsParams::default() };
        let (labels, planes) = segment_and_fit(&scene_of(&img, &disp, &trusted, &p), &p);
        assert_connected(&labels, w, h);
        // Every segment is one colour.
        for l in 0..planes.len() as u32 {
            let xs: Vec<usize> = (0..w * h).filter(|&i| labels[i] == l).map(|i| i % w).collect();
            assert!(xs.iter().all(|&x| x < 13) || xs.iter().all(|&x| x >= 13), "segment {l} straddles: {xs:?}");
        }
        assert!(planes.iter().all(|pl| (eval(pl, 20.0, 10.0) - 4.0).abs() < 1e-9));
    }

    #[test]
    fn segments_stay_connected_on_noise() {
        // Random colours and disparities: the moves are erratic, connectivity must hold anyway.
        let (w, h) = (37, 29);
        let mut img = RgbImage::new(w, h);
        let mut disp = Plane::new(w, h, 0.0);
        let mut rng = SplitMix64::new(3);
        for i in 0..w * h {
            for c in 0..3 {
                img.channels[c][i] = (rng.next_u64() % 256) as f32;
            }
            disp.data[i] = (rng.next_u64() % 1000) as f32 / 50.0;
        }
        let trusted = Plane::new(w, h, true);
        for segments in [4, 20, 80] {
            let p = SpsParams { segments, boundary_weight: 0.0, position_weight: 1.0, ..SpsParams::default() };
            let (labels, _) = segment_and_fit(&scene_of(&img, &disp, &trusted, &p), &p);
            assert_connected(&labels, w, h);
        }
    }

    /// Two 6×4 segments side by side (a: x < 3, b: x ≥ 3), 4-adjacent along x = 2.5; boundary midpoints at
    /// (2.5, y) for y = 0..4.
    fn two_segment_boundary(pa: [f64; 3], pb: [f64; 3]) -> BoundaryLabel {
        let (w, h) = (6, 4);
        let labels: Vec<u32> = (0..w * h).map(|i| u32::from(i % w >= 3)).collect();
        let planes = [pa, pb];
        let mut adj = Adjacency::new(2);
        let bounds = adj.rebuild(&labels, w, h, Some(&planes));
        assert_eq!(bounds.len(), 1);
        assert_eq!(bounds[0].geom.s1, 4.0);
        let mut acc = vec![SegAcc::default(); 2];
        for (i, &l) in labels.iter().enumerate() {
            acc[l as usize].geom.add(1.0, (i % w) as f64, (i / w) as f64, 0.0);
        }
        choose_label(&bounds[0], &acc, &planes, &SpsParams::default())
    }

    #[test]
    fn boundary_labels() {
        // Same plane: coplanar (cost 0).
        assert_eq!(two_segment_boundary([0.1, 0.0, 5.0], [0.1, 0.0, 5.0]), BoundaryLabel::Coplanar);
        // A crease meeting at x = 2.5: hinge (mean squared difference 0 on the boundary, not over the segments).
        assert_eq!(two_segment_boundary([0.5, 0.0, 0.0], [-0.5, 0.0, 2.5]), BoundaryLabel::Hinge);
        // A 5 px step, a in front: occlusion with a in front; b in front: occlusion with b in front.
        assert_eq!(two_segment_boundary([0.0, 0.0, 10.0], [0.0, 0.0, 5.0]), BoundaryLabel::OcclusionA);
        assert_eq!(two_segment_boundary([0.0, 0.0, 5.0], [0.0, 0.0, 10.0]), BoundaryLabel::OcclusionB);
        // Violation counts: planes crossing on the boundary at y = 1.5 → half the midpoints each way.
        let (w, h) = (6, 4);
        let labels: Vec<u32> = (0..w * h).map(|i| u32::from(i % w >= 3)).collect();
        let mut adj = Adjacency::new(2);
        let b = adj.rebuild(&labels, w, h, Some(&[[0.0, 1.0, 0.0], [0.0, 0.0, 1.5]]));
        assert_eq!((b[0].a_behind, b[0].b_behind), (2.0, 2.0));
        assert_eq!(adj.lists, vec![vec![(1, 0)], vec![(0, 0)]]);
    }

    #[test]
    fn validate_names_keys() {
        SpsParams::default().validate().unwrap();
        let e = SpsParams { segments: 0, ..Default::default() }.validate().unwrap_err();
        assert!(e.to_string().contains("post.sps.segments"), "{e}");
        let e = SpsParams { inlier_thresh_px: 0.0, ..Default::default() }.validate().unwrap_err();
        assert!(e.to_string().contains("post.sps.inlier_thresh_px"), "{e}");
        let e = SpsParams { untrusted_weight: 2.0, ..Default::default() }.validate().unwrap_err();
        assert!(e.to_string().contains("post.sps.untrusted_weight"), "{e}");
        let e = SpsParams { min_support_fraction: 1.5, ..Default::default() }.validate().unwrap_err();
        assert!(e.to_string().contains("post.sps.min_support_fraction"), "{e}");
        SpsParams { min_support_fraction: 1.0, ..Default::default() }.validate().unwrap();
    }
}
