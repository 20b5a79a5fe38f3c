//! Order statistics and means of planes, computed the same whatever the thread count.

use crate::image::Plane;

/// The value at fraction `f` of `v` in sorted order (nearest rank), found by selection (`v` is reordered).
pub(crate) fn rank_value(v: &mut [f32], f: f64) -> f32 {
    let k = ((v.len() - 1) as f64 * f).round() as usize;
    *v.select_nth_unstable_by(k, f32::total_cmp).1
}

/// The mean of a plane (summed in `f64`, row-major: the same value whatever the thread count).
pub(crate) fn plane_mean(p: &Plane<f32>) -> f32 {
    (p.data.iter().map(|&v| f64::from(v)).sum::<f64>() / p.data.len().max(1) as f64) as f32
}

/// The values at fractions `a` and `b` of the sorted data (nearest rank), non-finite values left out.
pub(crate) fn percentiles(data: &[f32], a: f64, b: f64) -> (f32, f32) {
    let mut v: Vec<f32> = data.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (0.0, 0.0);
    }
    (rank_value(&mut v, a), rank_value(&mut v, b))
}
