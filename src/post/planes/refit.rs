//! The plane step of slanted-plane smoothing (paper §4.3, after Yamaguchi et al. 2014): one Jacobi update of every
//! segment's plane by weighted least squares (its inlier data plus the hinge and coplanar couplings to its
//! neighbours' previous planes; occlusion boundaries do not couple), in parallel; then segments without enough
//! data borrow the plane of an adjacent segment (a deviation from the paper, so that the output is dense).

use rayon::prelude::*;

use super::boundary::{Adjacency, Boundary, BoundaryLabel};
use super::fit::{Moments, eval};
use super::stats::SegAcc;
use super::{Scene, SpsParams, support_needed};

/// One Jacobi step of the plane fits: inlier data plus hinge/coplanar couplings to the neighbours' old planes.
/// `None` for a segment with too little data and no coupling.
pub(super) fn refit_planes(
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

/// Gives every segment without a plane the plane of an adjacent segment, in rounds: the one that fits the
/// segment's (scarce) data best, or without data the one that is lowest on their common boundary (the background
/// side of an occlusion). If no segment has a plane, a fronto-parallel plane at the median of the data (0 without
/// data).
pub(super) fn borrow_missing(
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
    // Left without a plane only if no segment has one: the median pass is not made otherwise.
    let fallback = planes.iter().any(Option::is_none).then(|| [0.0, 0.0, median_of_data(scene)]);
    planes.iter().map(|pl| pl.or(fallback).unwrap_or_default()).collect()
}

/// The median of the disparities with data weight > 0 (the lower median; 0 without any).
fn median_of_data(scene: &Scene) -> f64 {
    let mut v: Vec<f32> = scene.disp.iter().zip(&scene.weight).filter(|(_, w)| **w > 0.0).map(|(d, _)| *d).collect();
    if v.is_empty() {
        return 0.0;
    }
    f64::from(crate::imgproc::stats::lower_median(&mut v))
}
