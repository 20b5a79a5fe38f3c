//! RANSAC planes: step 1 of slanted-plane smoothing (paper §4.3, after Yamaguchi et al. 2014) and the restart of
//! stale segments. Per segment, `ransac_iterations` trials of 3 data points drawn by a [`SplitMix64`] seeded from
//! `seed` and the segment id; the score is the data weight within τ of the plane; the best plane is refined by two
//! rounds of least squares on its inliers. A segment whose samples are all degenerate (or which has fewer than 3
//! points) gets a fronto-parallel plane at the median of its data. Segments are independent, so they run in
//! parallel and the result does not depend on the thread count.

use rayon::prelude::*;

use super::fit::{Moments, eval};
use super::{Scene, SpsParams, support_needed};
use crate::rng::SplitMix64;

/// RANSAC plane per `selected` segment (see the module doc); `None` where the data weight is below
/// [`support_needed`] and for the others.
pub(super) fn ransac_planes(
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

/// The RANSAC plane of one segment's points; `None` without points or with less data weight than `min_weight`.
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
            let median = crate::imgproc::stats::lower_median(&mut pts.d.clone());
            Some([0.0, 0.0, f64::from(median)])
        }
    }
}
