//! The superpixels of slanted-plane smoothing (paper §4.3, after Yamaguchi et al. 2014): the initial regular grid
//! (step 1) and the pixel step, one sweep over the boundary pixels. A pixel moves to the segment of a 4-neighbour
//! when that lowers its energy (colour, position, disparity and boundary-length terms, with the segments' means
//! and planes held fixed) and when leaving keeps its old segment 4-connected. The sweep runs in 9 phases of pixels
//! with the same (x mod 3, y mod 3), whose 3×3 neighbourhoods are disjoint, so each phase is a parallel Jacobi
//! step independent of the thread count.

use rayon::prelude::*;

use super::fit::eval;
use super::stats::SegAcc;
use super::{Scene, SpsParams};

/// A regular grid of about `w·h / step²` cells, as even as possible. Returns (labels, number of segments).
pub(super) fn grid_labels(w: usize, h: usize, step: f64) -> (Vec<u32>, usize) {
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

/// What a pixel move needs of a segment, in `f32` for the sweep.
#[derive(Clone, Copy, Debug)]
pub(super) struct SegModel {
    lab: [f32; 3],
    centre: [f32; 2],
    plane: [f64; 3],
}

impl SegModel {
    pub(super) fn new(a: &SegAcc, plane: [f64; 3]) -> Self {
        let n = a.geom.s1.max(1.0);
        let c = a.centre();
        SegModel {
            lab: [(a.lab[0] / n) as f32, (a.lab[1] / n) as f32, (a.lab[2] / n) as f32],
            centre: [c[0] as f32, c[1] as f32],
            plane,
        }
    }
}

/// One sweep over the boundary pixels in 9 parallel phases (see the module doc). Returns the number of pixels moved.
pub(super) fn sweep(scene: &Scene, labels: &mut [u32], models: &[SegModel], pos_scale: f32, p: &SpsParams) -> usize {
    let (w, h) = (scene.width, scene.height);
    let lambda_d = p.disparity_weight;
    let tau2 = p.inlier_thresh_px * p.inlier_thresh_px;
    let lambda_bou = p.boundary_weight;
    let mut moved = 0;
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
                    // Most pixels are inside their segment: all four neighbours in it, nothing to consider.
                    if y > 0 && x > 0 && x + 1 < w && y + 1 < h {
                        let same = |n: usize| cur[n] == s;
                        if same(i - w) && same(i - 1) && same(i + 1) && same(i + w) {
                            continue;
                        }
                    }
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
        moved += changes.len();
        for (i, t) in changes {
            labels[i] = t;
        }
    }
    moved
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

#[cfg(test)]
mod tests {
    use super::*;

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
    fn grid_is_even_and_complete() {
        let (labels, n) = grid_labels(10, 4, 2.0);
        assert_eq!(n, 10);
        assert_eq!(&labels[..10], &[0, 0, 1, 1, 2, 2, 3, 3, 4, 4]);
        assert_eq!(&labels[30..], &[5, 5, 6, 6, 7, 7, 8, 8, 9, 9]);
        let (labels, n) = grid_labels(1, 1, 50.0);
        assert_eq!((labels, n), (vec![0], 1));
    }
}
