//! Weighted least-squares planes `d = a·x + b·y + c` from accumulated moments (slanted-plane smoothing, paper
//! §4.3): every plane estimate (RANSAC refinement, the plane update with its coupling terms) is a [`Moments`] sum
//! solved here, and the boundary energies are quadratic forms of the same sums.
//!
//! The normal equations are solved in coordinates centred on the weighted centroid. The system is treated as
//! degenerate when |det| of the normal matrix is at most 1e-6 × the product of its diagonal (collinear points, a
//! single row or column, one point); a small ridge (0.25 px² × weight) on the slopes is then added, which keeps the
//! well-determined slope and sets the undetermined one to 0 (down to a fronto-parallel plane at the mean).

/// Weighted first and second moments of points (x, y) with targets t: the normal equations of a plane fit.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Moments {
    pub(super) s1: f64,
    pub(super) sx: f64,
    pub(super) sy: f64,
    pub(super) sxx: f64,
    pub(super) sxy: f64,
    pub(super) syy: f64,
    pub(super) st: f64,
    pub(super) sxt: f64,
    pub(super) syt: f64,
}

impl Moments {
    #[inline]
    pub(super) fn add(&mut self, wt: f64, x: f64, y: f64, t: f64) {
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

    pub(super) fn merge(&mut self, o: &Moments) {
        self.merge_scaled(o, 1.0);
    }

    pub(super) fn merge_scaled(&mut self, o: &Moments, k: f64) {
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
    pub(super) fn with_plane_targets(&self, pl: &[f64; 3]) -> Moments {
        let [a, b, c] = *pl;
        Moments {
            st: a * self.sx + b * self.sy + c * self.s1,
            sxt: a * self.sxx + b * self.sxy + c * self.sx,
            syt: a * self.sxy + b * self.syy + c * self.sy,
            ..*self
        }
    }

    /// Σ wt · (Δ · (x, y, 1))², the weighted squared difference of two planes over the points.
    pub(super) fn quad_form(&self, dl: &[f64; 3]) -> f64 {
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
    pub(super) fn solve(&self, ridge: bool) -> Option<[f64; 3]> {
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

/// The plane `pl = [a, b, c]` at (x, y): a·x + b·y + c.
#[inline]
pub(super) fn eval(pl: &[f64; 3], x: f64, y: f64) -> f64 {
    pl[0] * x + pl[1] * y + pl[2]
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
}
