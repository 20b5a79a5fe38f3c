//! Segment boundaries and their labels: the boundary-label step of slanted-plane smoothing (paper §4.3, after
//! Yamaguchi et al. 2014; the energies `E_b` are in the `post::planes` module doc). The adjacency of the segments is
//! rebuilt from the labels in raster order (boundaries are numbered by first encounter, so the result is
//! deterministic), with each boundary's midpoint moments and occlusion-violation counts; each boundary then takes
//! the label of least `E_b`: coplanar, hinge, or occlusion with either side in front.

use super::SpsParams;
use super::fit::{Moments, eval};
use super::stats::SegAcc;

/// Boundary label `o_kl` (its energies `E_b` are in the `post::planes` module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum BoundaryLabel {
    Coplanar,
    Hinge,
    /// The lower-numbered segment `a` is in front.
    OcclusionA,
    /// The higher-numbered segment `b` is in front.
    OcclusionB,
}

/// One boundary between segments `a < b`.
#[derive(Clone, Debug)]
pub(super) struct Boundary {
    pub(super) a: u32,
    pub(super) b: u32,
    /// Midpoints of the 4-adjacent pixel pairs across the boundary (`s1` = their number).
    pub(super) geom: Moments,
    /// Midpoints where `a`'s plane is below `b`'s (so `a` cannot be the occluder there), and vice versa.
    pub(super) a_behind: f64,
    pub(super) b_behind: f64,
    pub(super) label: BoundaryLabel,
}

/// Segment adjacency: for each segment, its (neighbour, boundary index) pairs in order of first encounter.
pub(super) struct Adjacency {
    pub(super) lists: Vec<Vec<(u32, u32)>>,
}

impl Adjacency {
    pub(super) fn new(nseg: usize) -> Self {
        Adjacency { lists: vec![Vec::new(); nseg] }
    }

    /// Rebuilds the adjacency from the labels (raster order, so deterministic) and returns the boundaries, all
    /// labelled occlusion-A until [`choose_label`] runs; with planes, it also counts the occlusion violations.
    pub(super) fn rebuild(&mut self, labels: &[u32], w: usize, h: usize, planes: Option<&[[f64; 3]]>) -> Vec<Boundary> {
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
pub(super) fn choose_label(b: &Boundary, acc: &[SegAcc], planes: &[[f64; 3]], p: &SpsParams) -> BoundaryLabel {
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
