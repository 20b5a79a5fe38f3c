//! The statistics step of slanted-plane smoothing (paper §4.3, after Yamaguchi et al. 2014): per segment, its
//! pixel moments (hence centre and size), Lab sums, the moments of all its data and of its inlier data (within τ
//! of its current plane: one step of iteratively reweighted least squares for the truncated quadratic), and
//! Σ w·d². Rows are summed in fixed blocks merged in order, so the sums are bitwise identical for any thread count.

use rayon::prelude::*;

use super::Scene;
use super::fit::{Moments, eval};

/// Per-segment sums: pixel moments (targets unused), Lab sums, inlier data moments, all data moments and Σ w·d².
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SegAcc {
    pub(super) geom: Moments,
    pub(super) lab: [f64; 3],
    pub(super) data: Moments,
    pub(super) all: Moments,
    pub(super) sdd: f64,
}

impl SegAcc {
    pub(super) fn centre(&self) -> [f64; 2] {
        let n = self.geom.s1.max(1.0);
        [self.geom.sx / n, self.geom.sy / n]
    }

    /// Σ w·(d − θ(p))² over all the segment's data.
    pub(super) fn sq_residual(&self, pl: &[f64; 3]) -> f64 {
        let m = &self.all;
        let cross = pl[0] * m.sxt + pl[1] * m.syt + pl[2] * m.st;
        (self.sdd - 2.0 * cross + m.quad_form(pl)).max(0.0)
    }

    /// The plane explains less than half of the segment's data (its pixels changed surface): refit from scratch.
    pub(super) fn is_stale(&self, min_support: f64) -> bool {
        self.all.s1 >= min_support && self.all.s1 > 0.0 && self.data.s1 < 0.5 * self.all.s1
    }
}

/// Rows per block of the statistics pass: blocks are summed independently and merged in order, so the sums do
/// not depend on the thread count.
const BLOCK_ROWS: usize = 32;

/// Segment statistics; data pixels count as inliers when within τ of their segment's plane (all of them when
/// `planes` is `None`).
pub(super) fn accumulate(scene: &Scene, labels: &[u32], nseg: usize, planes: Option<&[[f64; 3]]>) -> Vec<SegAcc> {
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
