//! Decoding the marginals (paper §3, after Algorithm 1): the disparity is argmax Q (the paper's WTA), with an
//! optional sub-pixel offset from a parabola through ln Q at d − 1, d, d + 1 (our addition), and the confidence
//! is max Q.

use rayon::prelude::*;

use super::Marginals;
use crate::fastmath::lane_max;
use crate::image::{DisparityMap, Plane};

/// Disparity (argmax Q, ties to the smaller label, with an optional sub-pixel parabola through ln Q) and
/// confidence (max Q) from marginals.
pub fn decode_marginals(q: &Marginals, subpixel: bool) -> (DisparityMap, Plane<f32>) {
    decode_with(q.width, q.height, subpixel, |i| (q.pixel(i), 0, q.ndisp))
}

/// [`decode_marginals`] for a `w × h` view whose pixel i holds the labels `lo..lo + q.len()` of `m` in
/// `labels(i) = (q, lo, m)`, the others 0: the same answer as its dense marginals give.
pub(super) fn decode_with<'q>(
    w: usize,
    h: usize,
    subpixel: bool,
    labels: impl Fn(usize) -> (&'q [f32], usize, usize) + Sync,
) -> (DisparityMap, Plane<f32>) {
    let mut disp = Plane::new(w, h, 0.0f32);
    let mut conf = Plane::new(w, h, 0.0f32);
    disp.data.par_iter_mut().zip(conf.data.par_iter_mut()).enumerate().with_min_len(1024).for_each(|(i, (d, c))| {
        let (qi, lo, m) = labels(i);
        // The first label holding the maximum (two vectorisable passes instead of a serial compare chain). The
        // maximum is positive (the marginal sums to 1), so no label outside the band holds it.
        let max = lane_max(qi);
        let k = qi.iter().position(|&v| v == max).unwrap_or(0);
        let best = lo + k;
        *c = qi[k];
        *d = best as f32;
        if subpixel && best > 0 && best + 1 < m {
            let below = k.checked_sub(1).map_or(0.0, |j| qi[j]);
            let above = qi.get(k + 1).copied().unwrap_or(0.0);
            *d += parabola_offset(below, qi[k], above);
        }
    });
    (disp, conf)
}

/// Vertex offset in [−0.5, 0.5] of the parabola through (−1, ln a), (0, ln b), (1, ln c), where b is the largest.
#[inline]
pub(crate) fn parabola_offset(a: f32, b: f32, c: f32) -> f32 {
    const FLOOR: f32 = 1e-30;
    let (la, lb, lc) = (a.max(FLOOR).ln(), b.max(FLOOR).ln(), c.max(FLOOR).ln());
    let curvature = la - 2.0 * lb + lc;
    if curvature < -1e-6 { (0.5 * (la - lc) / curvature).clamp(-0.5, 0.5) } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parabola_offset_finds_the_vertex() {
        // ln Q = −(x − 0.3)² sampled at −1, 0, 1.
        let f = |x: f32| (-(x - 0.3f32).powi(2)).exp();
        assert!((parabola_offset(f(-1.0), f(0.0), f(1.0)) - 0.3).abs() < 1e-4);
        assert_eq!(parabola_offset(0.2, 0.2, 0.2), 0.0, "flat: no offset");
        assert_eq!(parabola_offset(0.0, 1.0, 0.0), 0.0, "symmetric");
    }
}
