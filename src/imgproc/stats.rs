//! Order statistics and means of planes, computed the same whatever the thread count.

use std::cmp::Ordering;

use crate::image::Plane;

/// Floats in IEEE 754's total order (`total_cmp`): every bit pattern has its own place, so the k-th smallest value is
/// one value whatever algorithm finds it (a sort, or a selection that leaves the rest in any order).
pub(crate) trait TotalOrder: Copy {
    /// `total_cmp` of the float type.
    fn total_order(&self, other: &Self) -> Ordering;
}

impl TotalOrder for f32 {
    fn total_order(&self, other: &Self) -> Ordering {
        self.total_cmp(other)
    }
}

impl TotalOrder for f64 {
    fn total_order(&self, other: &Self) -> Ordering {
        self.total_cmp(other)
    }
}

/// The `k`-th smallest value of `v` (0 = the least) in the total order, found by selection (`v` is reordered).
///
/// # Panics
/// If `k` is not below `v.len()`.
pub(crate) fn nth_smallest<T: TotalOrder>(v: &mut [T], k: usize) -> T {
    *v.select_nth_unstable_by(k, T::total_order).1
}

/// The lower median of `v` (of an even count, the smaller of the middle two), found by selection (`v` is
/// reordered).
///
/// # Panics
/// If `v` is empty.
pub(crate) fn lower_median<T: TotalOrder>(v: &mut [T]) -> T {
    let mid = (v.len() - 1) / 2;
    nth_smallest(v, mid)
}

/// The value at fraction `f` of `v` in sorted order (nearest rank), found by selection (`v` is reordered).
pub(crate) fn rank_value(v: &mut [f32], f: f64) -> f32 {
    let k = ((v.len() - 1) as f64 * f).round() as usize;
    nth_smallest(v, k)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_statistics_are_the_sorted_values() {
        let data: Vec<f32> = crate::test_util::rand_vec(37, 3).iter().map(|v| v * 10.0 - 5.0).collect();
        let mut sorted = data.clone();
        sorted.sort_unstable_by(f32::total_cmp);
        for k in [0, 1, 18, 35, 36] {
            assert_eq!(nth_smallest(&mut data.clone(), k), sorted[k]);
        }
        for f in [0.0, 0.02, 0.5, 0.98, 1.0] {
            assert_eq!(rank_value(&mut data.clone(), f), sorted[((sorted.len() - 1) as f64 * f).round() as usize]);
        }
        // Of an even count the lower of the middle two; rank 0.5 rounds up to the upper.
        let mut four = [4.0f64, 1.0, 3.0, 2.0];
        assert_eq!(lower_median(&mut four), 2.0);
        assert_eq!(lower_median(&mut [7.0f32]), 7.0);
        assert_eq!(rank_value(&mut [4.0, 1.0, 3.0, 2.0], 0.5), 3.0);
    }
}
