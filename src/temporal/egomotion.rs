//! The camera's motion in 3D between two frames (a car driving forward, a turn), seen through the previous frame's
//! disparities, and the previous answer carried into the new frame by it.
//!
//! # The model
//! In a rectified pair the pixel (x, y) with disparity d is the 3D point with homogeneous coordinates A·p, p = (x,
//! y, 1, d), A = [[1, 0, −cx, 0], [0, 1, −cy, 0], [0, 0, f, 0], [0, 0, 0, 1/B]] (f, cx, cy the rectified camera, B
//! the baseline). A rigid motion M of the camera takes it to M·A·p = A·H·p with H = A⁻¹·M·A, whose last row is (0,
//! 0, 0, 1). So in the new frame the point is at x' = h₁·p / w, y' = h₂·p / w with disparity d' = d / w, w = h₃·p:
//! three rows of H, a 3 × 4 projective camera looking at the previous frame's disparity space. Their scale is fixed
//! by the left 3 × 3 block, K·R·K⁻¹ with determinant 1. Nothing of the calibration is needed: the three rows are
//! fitted to points tracked between the left views ([`super::track`]) by the direct linear transform (each track
//! gives two linear equations; the coordinates normalised first, Hartley's rule), inside RANSAC (minimal samples of
//! six, a seeded stream: the same frames give the same motion), and refitted on the inliers.
//!
//! # Carrying the answer
//! Every pixel of the previous answer with a disparity is moved to (x', y') with d' and splatted into the pixels
//! within 0.75 px of it (a footprint 1.5 px wide, which closes the gaps an approaching surface opens), the nearer
//! (larger d') winning where two land on one pixel; the previous view's grey goes along for the disagreement test.
//! Pixels nothing lands on have no prior (disocclusions, the new border).

use rayon::prelude::*;

use crate::image::Plane;
use crate::imgproc::filter::box_mean;
use crate::imgproc::sample::sample_bilinear;
use crate::internals::SplitMix64;
use crate::pipeline::PipelineOutput;

use super::track::Track;

/// RANSAC's samples.
const RANSAC_ITERATIONS: usize = 400;
/// A track is an inlier when the motion puts it within a tolerance of where it was found: at least this many pixels,
/// more where the tracks' own precision is coarser ([`tolerance`]).
pub(crate) const INLIER_PX: f64 = 1.0;
/// The tolerance is this many times the median track's distance from where the motion puts it (a motion that
/// holds explains half the tracks within the median by definition, and most within twice it)...
const TOLERANCE_PER_MEDIAN: f64 = 2.0;
/// ... and at most this many pixels: past it the tracks do not follow one motion.
const MAX_INLIER_PX: f64 = 2.0;
/// The seed of RANSAC's stream.
const SEED: u64 = 0x6567_6f6d_6f74_696f;
/// A target pixel takes a moved point within this distance on both axes.
const FOOTPRINT_PX: f64 = 0.75;

/// The motion between two frames in the previous frame's disparity space (see the module doc): rows h₁, h₂, h₃,
/// scaled so that the left 3 × 3 block has determinant 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Motion {
    rows: [[f64; 4]; 3],
    /// The tracks it explains.
    pub(crate) inliers: usize,
    /// Within how many pixels it explains them: also the position error the disagreement test allows the carried
    /// view, since the carried disparity places a pixel to within about as much (on KITTI frames, where the
    /// tolerance is [`INLIER_PX`], 0.25 px released too much and 2 px too little; the tuning log's "Stereo video II").
    pub(crate) tolerance: f64,
}

impl Motion {
    /// Where the previous frame's (x, y) with disparity d is in the new frame: (x', y', d'); `None` behind the
    /// camera.
    pub(crate) fn apply(&self, x: f64, y: f64, d: f64) -> Option<(f64, f64, f64)> {
        let p = [x, y, 1.0, d];
        let dot = |r: &[f64; 4]| r.iter().zip(&p).map(|(a, b)| a * b).sum::<f64>();
        let w = dot(&self.rows[2]);
        (w > 1e-6).then(|| (dot(&self.rows[0]) / w, dot(&self.rows[1]) / w, d / w))
    }

    /// The inverse motion, from the new frame back to the previous one: H = [[M, t], [0, 1]] has the inverse
    /// [[M⁻¹, −M⁻¹·t], [0, 1]], of the same form (and its block's determinant is 1 too). `None` when M is singular.
    pub(crate) fn inverse(&self) -> Option<Motion> {
        let m = |i: usize, j: usize| self.rows[i][j];
        let det = det3(&self.rows);
        if !det.is_finite() || det.abs() < 1e-12 {
            return None;
        }
        let cof = |a: usize, b: usize| {
            let (r0, r1) = ((a + 1) % 3, (a + 2) % 3);
            let (c0, c1) = ((b + 1) % 3, (b + 2) % 3);
            m(r0, c0) * m(r1, c1) - m(r0, c1) * m(r1, c0)
        };
        let inv: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| cof(j, i) / det));
        let rows = std::array::from_fn(|i| {
            let t = -(0..3).map(|j| inv[i][j] * m(j, 3)).sum::<f64>();
            [inv[i][0], inv[i][1], inv[i][2], t]
        });
        Some(Motion { rows, ..*self })
    }

    /// How far from where it was found the motion puts a track, in pixels.
    fn error(&self, t: &Track) -> f64 {
        self.apply(t.x, t.y, t.d).map_or(f64::INFINITY, |(x, y, _)| (x - t.tx).hypot(y - t.ty))
    }
}

/// The motion that explains most `tracks` within `tolerance` pixels (RANSAC, then refitted on its inliers twice);
/// `None` with fewer than six tracks or no model that explains six.
pub(crate) fn fit(tracks: &[Track], tolerance: f64) -> Option<Motion> {
    if tracks.len() < 6 {
        return None;
    }
    // The samples drawn in turn from the seeded stream, their models scored in parallel; the first of the most
    // inliers in the stream's order wins, as in a sequential loop.
    let mut rng = SplitMix64::new(SEED);
    let samples: Vec<Vec<usize>> = (0..RANSAC_ITERATIONS).map(|_| distinct(&mut rng, tracks.len(), 6)).collect();
    let best = samples
        .par_iter()
        .filter_map(|sample| {
            let chosen: Vec<Track> = sample.iter().map(|&i| tracks[i]).collect();
            let model = solve(&chosen)?;
            Some(Motion { inliers: count_inliers(&model, tracks, tolerance), tolerance, ..model })
        })
        .reduce_with(|a, b| if b.inliers > a.inliers { b } else { a });
    let mut best = best.filter(|b| b.inliers >= 6)?;
    for _ in 0..2 {
        let inliers: Vec<Track> = tracks.iter().filter(|t| best.error(t) <= tolerance).copied().collect();
        match solve(&inliers) {
            Some(m) => {
                let m = Motion { inliers: count_inliers(&m, tracks, tolerance), tolerance, ..m };
                if m.inliers < best.inliers {
                    break;
                }
                best = m;
            }
            None => break,
        }
    }
    Some(best)
}

fn count_inliers(m: &Motion, tracks: &[Track], tolerance: f64) -> usize {
    tracks.iter().filter(|t| m.error(t) <= tolerance).count()
}

/// The tolerance the tracks' precision asks of a motion fitted to them: [`TOLERANCE_PER_MEDIAN`] times the median
/// track's distance from where `m` puts it, within [`INLIER_PX`] … [`MAX_INLIER_PX`]. The distances grow with what
/// blurs the views or the previous disparities (a larger image of the same scene, a softer lens, noise): on KITTI
/// frames the median is about 0.5 px, on the same frames enlarged 1.5 times about 0.8 px.
pub(crate) fn tolerance(m: &Motion, tracks: &[Track]) -> f64 {
    let mut errors: Vec<f64> = tracks.iter().map(|t| m.error(t)).collect();
    if errors.is_empty() {
        return INLIER_PX;
    }
    let mid = errors.len() / 2;
    let (_, median, _) = errors.select_nth_unstable_by(mid, f64::total_cmp);
    (TOLERANCE_PER_MEDIAN * *median).clamp(INLIER_PX, MAX_INLIER_PX)
}

/// `k` distinct indices below `n` (`n` ≥ `k`).
fn distinct(rng: &mut SplitMix64, n: usize, k: usize) -> Vec<usize> {
    let mut out = Vec::with_capacity(k);
    while out.len() < k {
        let i = rng.below(n);
        if !out.contains(&i) {
            out.push(i);
        }
    }
    out
}

/// The least-squares direct linear transform of `tracks` (at least six), normalised, with the scale fixed by the
/// determinant; `None` when degenerate.
fn solve(tracks: &[Track]) -> Option<Motion> {
    let n = tracks.len() as f64;
    let mean = |f: &dyn Fn(&Track) -> f64| tracks.iter().map(f).sum::<f64>() / n;
    let (mx, my, md) = (mean(&|t| t.x), mean(&|t| t.y), mean(&|t| t.d));
    let (mtx, mty) = (mean(&|t| t.tx), mean(&|t| t.ty));
    let spread = |f: &dyn Fn(&Track) -> f64| (mean(&|t| f(t).powi(2))).sqrt().max(1e-9);
    let s_src = std::f64::consts::SQRT_2 / spread(&|t| (t.x - mx).hypot(t.y - my));
    let s_d = 1.0 / spread(&|t| t.d - md);
    let s_dst = std::f64::consts::SQRT_2 / spread(&|t| (t.tx - mtx).hypot(t.ty - mty));
    // The normal equations of the stacked rows [X, 0, −u·X] and [0, X, −v·X].
    let mut ata = [[0.0f64; 12]; 12];
    for t in tracks {
        let x = [s_src * (t.x - mx), s_src * (t.y - my), 1.0, s_d * (t.d - md)];
        let (u, v) = (s_dst * (t.tx - mtx), s_dst * (t.ty - mty));
        let mut r1 = [0.0; 12];
        let mut r2 = [0.0; 12];
        for k in 0..4 {
            (r1[k], r1[8 + k]) = (x[k], -u * x[k]);
            (r2[4 + k], r2[8 + k]) = (x[k], -v * x[k]);
        }
        for row in [r1, r2] {
            for i in 0..12 {
                for j in 0..12 {
                    ata[i][j] += row[i] * row[j];
                }
            }
        }
    }
    let h = smallest_eigenvector(ata);
    // Undo the normalisations: P = T_dst⁻¹ · Pn · T_src.
    let pn = [[h[0], h[1], h[2], h[3]], [h[4], h[5], h[6], h[7]], [h[8], h[9], h[10], h[11]]];
    let t_src = [
        [s_src, 0.0, -s_src * mx, 0.0],
        [0.0, s_src, -s_src * my, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, -s_d * md, s_d],
    ];
    let t_dst_inv = [[1.0 / s_dst, 0.0, mtx], [0.0, 1.0 / s_dst, mty], [0.0, 0.0, 1.0]];
    let mut rows = [[0.0f64; 4]; 3];
    for (i, row) in rows.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| t_dst_inv[i][k] * (0..4).map(|l| pn[k][l] * t_src[l][j]).sum::<f64>()).sum();
        }
    }
    let det = det3(&rows);
    if !det.is_finite() || det.abs() < 1e-12 {
        return None;
    }
    let scale = det.cbrt();
    rows.iter_mut().flatten().for_each(|v| *v /= scale);
    Some(Motion { rows, inliers: 0, tolerance: INLIER_PX })
}

/// The determinant of the left 3 × 3 block.
fn det3(r: &[[f64; 4]; 3]) -> f64 {
    r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
        + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0])
}

/// The unit eigenvector of the symmetric `a`'s smallest eigenvalue (cyclic Jacobi rotations).
fn smallest_eigenvector(mut a: [[f64; 12]; 12]) -> [f64; 12] {
    const N: usize = 12;
    let mut v = [[0.0f64; N]; N];
    (0..N).for_each(|i| v[i][i] = 1.0);
    for _ in 0..60 {
        let off: f64 = (0..N)
            .flat_map(|i| (0..N).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j].powi(2))
            .sum();
        let diag: f64 = (0..N).map(|i| a[i][i].powi(2)).sum();
        if off <= 1e-30 * diag.max(1e-300) {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let (c, s) = (1.0 / (t * t + 1.0).sqrt(), t / (t * t + 1.0).sqrt());
                for row in a.iter_mut() {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (rp, rq) = (a[p], a[q]);
                a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
                a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    let k = (0..N).min_by(|&i, &j| a[i][i].total_cmp(&a[j][j])).expect("12 eigenvalues");
    std::array::from_fn(|i| v[i][k])
}

/// The previous answer and its left view (grey) carried into the new frame by `motion` (see the module doc):
/// the answer (`inf`, confidence 0, not consistent where nothing lands) and the grey (`inf` there).
pub(crate) fn carry(answer: &PipelineOutput, grey: &Plane<f32>, motion: &Motion) -> (PipelineOutput, Plane<f32>) {
    let (w, h) = answer.disparity.dims();
    let mut source = vec![usize::MAX; w * h];
    let mut depth = vec![f32::NEG_INFINITY; w * h];
    let mut moved = Plane::new(w, h, f32::INFINITY);
    // Where each pixel goes, in parallel; then splatted in raster order (the first of equal depths wins).
    let targets: Vec<Option<(f64, f64, f64)>> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let d = answer.disparity.data[i];
            if !d.is_finite() {
                return None;
            }
            let (tx, ty, td) = motion.apply((i % w) as f64, (i / w) as f64, f64::from(d))?;
            (tx.is_finite() && ty.is_finite() && td.is_finite() && td >= 0.0).then_some((tx, ty, td))
        })
        .collect();
    for y in 0..h {
        for x in 0..w {
            let Some((tx, ty, td)) = targets[y * w + x] else { continue };
            let span = |c: f64, n: usize| {
                let lo = ((c - FOOTPRINT_PX).ceil() as i64).max(0);
                let hi = ((c + FOOTPRINT_PX).floor() as i64).min(n as i64 - 1);
                (lo as usize)..(hi + 1).max(lo) as usize
            };
            for yy in span(ty, h) {
                for xx in span(tx, w) {
                    let i = yy * w + xx;
                    if (td as f32) > depth[i] {
                        depth[i] = td as f32;
                        source[i] = y * w + x;
                        moved.data[i] = td as f32;
                    }
                }
            }
        }
    }
    let take = |p: &Plane<f32>, fill: f32| {
        Plane::from_parts(w, h, source.iter().map(|&s| if s == usize::MAX { fill } else { p.data[s] }).collect())
    };
    let consistent =
        Plane::from_parts(w, h, source.iter().map(|&s| s != usize::MAX && answer.consistent.data[s]).collect());
    let out = super::motion::carried(answer, moved, consistent, take);
    let seen = sample_back(grey, &out.disparity, motion);
    (out, seen)
}

/// The previous view seen from the new frame: at each pixel with a carried disparity, the previous grey where the
/// inverse motion puts it (bilinear; `inf` outside the view or where nothing was carried).
fn sample_back(grey: &Plane<f32>, carried: &Plane<f32>, motion: &Motion) -> Plane<f32> {
    let (w, h) = carried.dims();
    let Some(back) = motion.inverse() else { return Plane::new(w, h, f32::INFINITY) };
    let data = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let d = carried.data[i];
            if !d.is_finite() {
                return f32::INFINITY;
            }
            match back.apply((i % w) as f64, (i / w) as f64, f64::from(d)) {
                Some((x, y, _)) if x >= 0.0 && y >= 0.0 && x <= (w - 1) as f64 && y <= (h - 1) as f64 => {
                    sample_bilinear(&grey.data, w, h, x, y) as f32
                }
                _ => f32::INFINITY,
            }
        })
        .collect();
    Plane::from_parts(w, h, data)
}

/// Where the previous view seen from the new frame disagrees with the current view (the 5 × 5 mean absolute
/// grey difference above `limit`, a pixel with nothing carried counting as far off), allowing beside the noise's
/// `limit` what a position off by `slack_px` (the motion's tolerance) changes at the current view's local gradient:
/// the motion places a point only to within its inliers' error.
pub(crate) fn disagreement(moved: &Plane<f32>, cur: &Plane<f32>, limit: f32, slack_px: f64) -> Plane<bool> {
    // |gx| + |gy| of central differences, halved at the borders as well (imgproc's `central_differences` is
    // one-sided there, which gives the border rows more slack and changes the maps the slack was chosen with).
    let (w, h) = cur.dims();
    let at = |x: usize, y: usize| cur.data[y * w + x];
    let gradient = Plane::from_parts(
        w,
        h,
        (0..w * h)
            .into_par_iter()
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let gx = at((x + 1).min(w - 1), y) - at(x.saturating_sub(1), y);
                let gy = at(x, (y + 1).min(h - 1)) - at(x, y.saturating_sub(1));
                0.5 * (gx.abs() + gy.abs())
            })
            .collect(),
    );
    let slack = box_mean(&gradient, 2);
    let slack_px = slack_px as f32;
    super::motion::disagreement_beyond(moved, cur, |i| limit + slack_px * slack.data[i])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// H = A⁻¹·M·A for a camera (f, cx, cy, B) moved by the rotation `yaw` (radians, about the vertical axis) and
    /// the translation t (metres; a point's coordinates in the new frame are R·X + t).
    fn true_motion(
        f: f64,
        cx: f64,
        cy: f64,
        b: f64,
        yaw: f64,
        t: [f64; 3],
    ) -> impl Fn(f64, f64, f64) -> (f64, f64, f64) {
        move |x, y, d| {
            let z = f * b / d;
            let (px, py) = ((x - cx) * z / f, (y - cy) * z / f);
            let (c, s) = (yaw.cos(), yaw.sin());
            let (qx, qy, qz) = (c * px + s * z + t[0], py + t[1], -s * px + c * z + t[2]);
            (f * qx / qz + cx, f * qy / qz + cy, f * b / qz)
        }
    }

    fn tracks_of(m: &impl Fn(f64, f64, f64) -> (f64, f64, f64), n: usize, seed: u64) -> Vec<Track> {
        let mut rng = SplitMix64::new(seed);
        (0..n)
            .map(|_| {
                let (x, y, d) = (rng.range(0.0, 1200.0), rng.range(0.0, 370.0), rng.range(2.0, 80.0));
                let (tx, ty, _) = m(x, y, d);
                Track { x, y, d, tx, ty }
            })
            .collect()
    }

    #[test]
    fn a_drive_forward_with_a_turn_is_recovered_with_the_new_disparities() {
        let m = true_motion(707.0, 601.9, 183.1, 0.54, 0.01, [0.02, -0.01, -1.2]);
        let mut tracks = tracks_of(&m, 300, 1);
        // A third of the tracks wrong (a moving car, mismatches).
        let mut rng = SplitMix64::new(2);
        for t in tracks.iter_mut().step_by(3) {
            (t.tx, t.ty) = (t.tx + rng.range(-30.0, 30.0), t.ty + rng.range(3.0, 20.0));
        }
        let fitted = fit(&tracks, INLIER_PX).expect("a motion");
        assert!(fitted.inliers >= 200 && fitted.inliers <= 201, "{} inliers", fitted.inliers);
        for (x, y, d) in [(100.0, 300.0, 60.0), (600.0, 180.0, 5.0), (1100.0, 50.0, 20.0)] {
            let (ex, ey, ed) = m(x, y, d);
            let (gx, gy, gd) = fitted.apply(x, y, d).expect("in front");
            assert!((ex - gx).abs() < 1e-3 && (ey - gy).abs() < 1e-3, "({x}, {y}, {d}): {gx} {gy} against {ex} {ey}");
            assert!((ed - gd).abs() < 1e-3, "({x}, {y}, {d}): d' {gd} against {ed}");
        }
    }

    #[test]
    fn too_few_or_inconsistent_tracks_give_no_motion() {
        let m = true_motion(700.0, 600.0, 180.0, 0.5, 0.0, [0.0, 0.0, -1.0]);
        assert!(fit(&tracks_of(&m, 5, 3), INLIER_PX).is_none());
        let mut rng = SplitMix64::new(4);
        let noise: Vec<Track> = (0..100)
            .map(|_| Track {
                x: rng.range(0.0, 1000.0),
                y: rng.range(0.0, 300.0),
                d: rng.range(1.0, 50.0),
                tx: rng.range(0.0, 1000.0),
                ty: rng.range(0.0, 300.0),
            })
            .collect();
        assert!(fit(&noise, INLIER_PX).is_none_or(|m| m.inliers < 15), "random tracks");
    }

    /// Tracks found to within a coarser precision (here each moved by up to ±s px on both axes) are judged within
    /// a wider tolerance, and with it the motion explains most of them again; exact tracks keep the least tolerance,
    /// and tracks that follow no motion do not widen it past the most.
    #[test]
    fn the_tolerance_follows_the_tracks_precision() {
        let m = true_motion(707.0, 601.9, 183.1, 0.54, 0.01, [0.02, -0.01, -1.2]);
        let exact = tracks_of(&m, 300, 1);
        let fitted = fit(&exact, INLIER_PX).expect("a motion");
        assert_eq!(tolerance(&fitted, &exact), INLIER_PX);
        for s in [0.8, 1.1] {
            let mut rng = SplitMix64::new(7);
            let mut blurred = exact.clone();
            for t in &mut blurred {
                (t.tx, t.ty) = (t.tx + rng.range(-s, s), t.ty + rng.range(-s, s));
            }
            let first = fit(&blurred, INLIER_PX).expect("a motion");
            let wider = tolerance(&first, &blurred);
            // The median distance of a point uniform in the square of side 2s is about 0.8 s (π a² = 2 s²).
            assert!(wider > INLIER_PX && (wider - 1.6 * s).abs() < 0.25 * s, "s {s}: tolerance {wider}");
            let again = fit(&blurred, wider).expect("a motion");
            assert!(
                again.inliers > first.inliers && again.inliers >= 270,
                "s {s}: {} then {}",
                first.inliers,
                again.inliers
            );
        }
        let mut rng = SplitMix64::new(8);
        let lost: Vec<Track> = exact
            .iter()
            .map(|t| Track { tx: t.tx + rng.range(-20.0, 20.0), ty: t.ty + rng.range(-20.0, 20.0), ..*t })
            .collect();
        assert_eq!(tolerance(&fitted, &lost), MAX_INLIER_PX);
    }

    #[test]
    fn the_nearer_surface_wins_and_gaps_are_left_without_an_answer() {
        let (w, h) = (8, 1);
        // A shift by +2 px of the far background (d 1) while the near pixel (d 3) moves by +3 px: x' = x + d.
        let motion = Motion {
            rows: [[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
            inliers: 0,
            tolerance: INLIER_PX,
        };
        let d = Plane::from_parts(w, h, vec![1.0, 1.0, 3.0, 1.0, 1.0, 1.0, f32::INFINITY, 1.0]);
        let answer = PipelineOutput {
            confidence: None,
            max_marginal: Plane::new(w, h, 0.5),
            consistent: Plane::new(w, h, true),
            disparity: d,
            timings: Default::default(),
            measured: None,
            vertical_offset: None,
            segmentation: None,
        };
        let grey = Plane::from_parts(w, h, (0..w).map(|x| x as f32 * 10.0).collect());
        let (out, moved_grey) = carry(&answer, &grey, &motion);
        // x 0 → 1, 1 → 2, 2 (near) → 5, 3 → 4, 4 → 5 (behind the near one), 5 → 6, 7 → 8 (outside).
        let want = [f32::INFINITY, 1.0, 1.0, f32::INFINITY, 1.0, 3.0, 1.0, f32::INFINITY];
        assert_eq!(out.disparity.data, want);
        // The grey seen back through the motion: pixel 5 holds the near pixel (from x 2).
        assert_eq!(moved_grey.data[5], 20.0, "the near pixel's grey");
        assert!(moved_grey.data[0].is_infinite() && moved_grey.data[3].is_infinite());
        assert!(!out.consistent.data[0] && out.consistent.data[1] && !out.consistent.data[3]);
    }
}
