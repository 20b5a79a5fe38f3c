//! Slanted-plane smoothing (paper §4.3), after Yamaguchi, McAllester & Urtasun, "Efficient Joint
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
//! A panning camera's next frame (our addition; `warm.rs`) starts from the segments and planes of the frame before,
//! moved by the pan, instead of step 1: the strip the pan brings into view and the pixels where the frames disagree
//! get grid cells (and RANSAC planes), the strip's small pieces join a neighbour, and step 2 stops once a sweep moves
//! fewer than `SETTLED_SHARE` of the pixels.
//!
//! Colours are compared in CIE L*a*b* (`lab.rs`); every plane is a weighted least-squares fit from moments, with a
//! small ridge when the points do not determine a plane (`fit.rs`).
//!
//! A segment whose data weight is below `min_support`, or below `min_support_fraction` × its pixel count if that
//! is more, and which has no hinge/coplanar neighbour gets no plane of its own (RANSAC skips it too, and the
//! stale-plane test uses the same threshold); it borrows, in rounds, the plane of an adjacent segment: the one
//! that fits its few data points best, or without data the one that is *lowest* (smallest disparity) on their
//! common boundary — occluded regions belong to the background, the rule the occlusion fill uses too. If no
//! segment has a plane (no data at all), every segment is fronto-parallel at the median of the data, or 0 without
//! data. The output is therefore always finite.
//!
//! Defaults: `segments = 1500` (≈ 15 px cells at Q; Yamaguchi et al. use 1000 on KITTI's 0.47 Mpx; a larger image
//! gets more, each at most `max_segment_px = 250` px on average: `SpsParams::segments_for`),
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
//!
//! # Data layout
//! Per-pixel arrays are row-major, index `y·w + x`: the segment labels (`u32`, 0..K), the three Lab channels,
//! the input disparity and the data weight (`f32`). Per-segment arrays are indexed by label: the planes
//! `[a, b, c]` (`f64`, pixel coordinates) and the statistics. Boundaries are numbered in raster order of first
//! encounter and each segment lists its (neighbour, boundary) pairs.
//!
//! # Code layout
//! - this file: the parameters, the entry [`fit_slanted_planes`], the alternation, the per-pixel inputs, and the
//!   output (step 3);
//! - `lab.rs`: sRGB → CIE L*a*b*;
//! - `fit.rs`: weighted least-squares planes from moments;
//! - `ransac.rs`: RANSAC planes (step 1, and stale segments);
//! - `segments.rs`: the initial grid and the pixel sweep;
//! - `stats.rs`: the per-segment statistics;
//! - `boundary.rs`: segment adjacency and boundary labels;
//! - `refit.rs`: the plane update and the borrowing of planes by segments without data;
//! - `warm.rs`: a segmentation carried from the frame before.

mod boundary;
mod fit;
mod lab;
mod ransac;
mod refit;
mod segments;
mod stats;
mod warm;

use rayon::prelude::*;

use self::boundary::{Adjacency, choose_label};
use self::fit::eval;
use self::lab::rgb_to_lab;
use self::ransac::ransac_planes;
use self::refit::{borrow_missing, refit_planes};
use self::segments::{SegModel, grid_labels, sweep};
use self::stats::{SegAcc, accumulate};
use crate::image::{DisparityMap, Plane, RgbImage};
use crate::params::SpsParams;
pub(crate) use warm::Segmentation;

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
/// use jem::internals::post::planes::fit_slanted_planes;
/// use jem::params::SpsParams;
/// use jem::{Plane, RgbImage};
/// // A plane d = 0.1·x + 2 with a hole at (3, 2).
/// let (w, h) = (8, 6);
/// let mut disp = Plane::from_vec(w, h, (0..w * h).map(|i| 0.1 * (i % w) as f32 + 2.0).collect()).unwrap();
/// disp.data_mut()[2 * w + 3] = f32::INFINITY;
/// let trusted = Plane::from_vec(w, h, disp.data().iter().map(|d| d.is_finite()).collect()).unwrap();
/// let out = fit_slanted_planes(&RgbImage::new(w, h), &disp, &trusted, &SpsParams { segments: 4, ..Default::default() });
/// assert!((out.at(3, 2) - 2.3).abs() < 1e-4);
/// ```
pub fn fit_slanted_planes(image: &RgbImage, disp: &DisparityMap, trusted: &Plane<bool>, p: &SpsParams) -> DisparityMap {
    fit_planes_from(image, disp, trusted, p, None).0
}

/// [`fit_slanted_planes`] started from a segmentation carried from the frame before (a panning camera's;
/// [`Segmentation::shifted`]) instead of a grid, when it is of this size: the alternation then runs until a sweep
/// moves fewer than [`SETTLED_SHARE`] of the pixels, at most `iterations` times (a segmentation that has splintered
/// into more than 1.5 × `segments` pieces starts from the grid instead). Returns the map and the segmentation it
/// ended with.
pub(crate) fn fit_planes_from(
    image: &RgbImage,
    disp: &DisparityMap,
    trusted: &Plane<bool>,
    p: &SpsParams,
    start: Option<&Segmentation>,
) -> (DisparityMap, Segmentation) {
    assert_eq!(image.dims(), disp.dims(), "image and disparity map differ in size");
    assert_eq!(trusted.dims(), disp.dims(), "disparity map and trusted mask differ in size");
    let (w, h) = disp.dims();
    if w == 0 || h == 0 {
        return (disp.clone(), Segmentation { labels: Plane::new(w, h, 0), planes: Vec::new() });
    }
    let scene = Scene::new(image, disp, trusted, p);
    let start = start.filter(|s| s.labels.dims() == (w, h));
    let (labels, planes) = segment_and_fit(&scene, p, start);
    let out = render(&labels, &planes, w, scene.max_disp + p.inlier_thresh_px);
    (out, Segmentation { labels: Plane::from_parts(w, h, labels), planes })
}

/// A carried segmentation has settled when a sweep moves fewer than this share of the pixels: about what the tenth
/// sweep from a grid still moves (0.7–1.6 % on trainingQ's sizes), so a carried start stops where a grid start would
/// (on a 3 px pan of Teddy, after one to three sweeps instead of ten).
pub(crate) const SETTLED_SHARE: f64 = 0.01;

/// The alternation of the module doc, from a grid or from a carried segmentation (`start`, of the scene's size):
/// returns the final segment labels (row-major) and one plane per segment.
fn segment_and_fit(scene: &Scene, p: &SpsParams, start: Option<&Segmentation>) -> (Vec<u32>, Vec<[f64; 3]>) {
    let (w, h) = (scene.width, scene.height);
    // A large image gets more segments (`segments_for`); more than the image can hold are absurd (see
    // `max_segments`; the caller warns about it).
    let segments = p.segments_for(w * h);
    let step = ((w * h) as f64 / segments as f64).sqrt().max(1.0);
    // A carried segmentation that has splintered (disocclusions and cut segments add pieces frame after frame)
    // past half as many segments again as configured starts from the grid.
    let carried = start.map(|start| warm::restart_from(start, step)).filter(|(_, pl)| pl.len() * 2 <= segments * 3);
    let warm = carried.is_some();
    let (mut labels, mut planes) = carried.unwrap_or_else(|| {
        let (labels, nseg) = grid_labels(w, h, step);
        (labels, vec![None; nseg])
    });
    let nseg = planes.len();
    let mut adj = Adjacency::new(nseg);

    // Initialisation: RANSAC planes on the segments without one (every grid cell of a first frame).
    let acc = accumulate(scene, &labels, nseg, None);
    let bounds = adj.rebuild(&labels, w, h, None);
    let fresh = ransac_planes(scene, &labels, nseg, p, |k| planes[k].is_none());
    planes.iter_mut().zip(fresh).filter(|(pl, _)| pl.is_none()).for_each(|(pl, f)| *pl = f);
    let mut planes_full = borrow_missing(&mut planes, &adj, &bounds, &acc, scene);
    let mut acc = accumulate(scene, &labels, nseg, Some(&planes_full));

    let pos_scale = f64::from(p.position_weight) / (step * step);
    for _ in 0..p.iterations {
        let models: Vec<SegModel> = acc.iter().zip(&planes_full).map(|(a, pl)| SegModel::new(a, *pl)).collect();
        let moved = sweep(scene, &mut labels, &models, pos_scale as f32, p);
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
        if warm && (moved as f64) < SETTLED_SHARE * (w * h) as f64 {
            break;
        }
    }
    (labels, planes_full)
}

/// The data weight a segment of `pixels` pixels needs to fit a plane of its own: `min_support`, or
/// `min_support_fraction` of its pixels if that is more.
fn support_needed(p: &SpsParams, pixels: f64) -> f64 {
    f64::from(p.min_support).max(f64::from(p.min_support_fraction) * pixels)
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
    use crate::rng::SplitMix64;

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
        let (labels, planes) = segment_and_fit(&scene_of(&img, &disp, &trusted, &p), &p, None);
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
            let (labels, _) = segment_and_fit(&scene_of(&img, &disp, &trusted, &p), &p, None);
            assert_connected(&labels, w, h);
        }
    }

    /// A panning camera: the segmentation of one frame, moved by the pan, starts the next frame; its map is as
    /// close to the truth as a grid start's, its segments are connected, and started from what it ended with, the
    /// same frame gives back the same map.
    #[test]
    fn a_carried_segmentation_starts_the_next_frame_of_a_pan() {
        let params = crate::synth::SynthParams { width: 206, height: 150, ndisp: 32, seed: 5 };
        let scene = crate::synth::render_scene(&params).unwrap();
        let (w, h, pan) = (200, 150, 3);
        let frame = |x0: usize| {
            let cols = |v: &[f32]| (0..w * h).map(|i| v[(i / w) * params.width + x0 + i % w]).collect::<Vec<f32>>();
            let mut img = RgbImage::new(w, h);
            for c in 0..3 {
                img.channels[c] = cols(&scene.left.channels[c]);
            }
            let truth = Plane::from_parts(w, h, cols(&scene.gt.data));
            // Every 5th pixel of the input is off by 4 px and untrusted.
            let disp =
                Plane::from_parts(w, h, (0..w * h).map(|i| truth.data[i] + 4.0 * f32::from(i % 5 == 0)).collect());
            let trusted = Plane::from_parts(w, h, (0..w * h).map(|i| i % 5 != 0).collect());
            (img, disp, trusted, truth)
        };
        let p = SpsParams { segments: 150, ..SpsParams::default() };
        let mean_error = |out: &DisparityMap, truth: &DisparityMap| {
            out.data.iter().zip(&truth.data).map(|(a, b)| f64::from((a - b).abs())).sum::<f64>() / (w * h) as f64
        };
        let (img, disp, trusted, _) = frame(0);
        let (_, first) = fit_planes_from(&img, &disp, &trusted, &p, None);
        let (img, disp, trusted, truth) = frame(pan);
        let carried = first.shifted(pan as i64, 0);
        let (labels, _) = warm::restart_from(&carried, 10.0);
        assert_connected(&labels, w, h);
        let (cold, _) = fit_planes_from(&img, &disp, &trusted, &p, None);
        let (warm, settled) = fit_planes_from(&img, &disp, &trusted, &p, Some(&carried));
        let (cold_err, warm_err) = (mean_error(&cold, &truth), mean_error(&warm, &truth));
        assert!(warm_err < 0.3 && warm_err <= cold_err + 0.05, "warm {warm_err:.3} px, cold {cold_err:.3} px");
        assert_connected(&settled.labels.data, w, h);
        let (again, same) = fit_planes_from(&img, &disp, &trusted, &p, Some(&settled));
        assert_eq!(same.labels.dims(), (w, h));
        assert!(mean_error(&again, &warm) < 0.05);
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
