//! Occlusion fill (paper §4.1): every invalid (`inf`) pixel takes the smaller of the nearest valid
//! disparities to its left and right on the same row; the background is the smaller disparity, and occlusions
//! are background. A row with no valid pixel is left as it is. O(w·h), row-parallel.

use rayon::prelude::*;

use crate::image::DisparityMap;

/// Fills invalid pixels in place (see the module doc).
pub fn fill_occlusions_in_place(disp: &mut DisparityMap) {
    let w = disp.width;
    disp.data.par_chunks_mut(w.max(1)).for_each(fill_row);
}

/// Fills one row: a left-to-right pass records the nearest valid value on the left, a right-to-left pass takes
/// the minimum with the nearest valid value on the right.
fn fill_row(row: &mut [f32]) {
    let mut left_valid = vec![f32::INFINITY; row.len()];
    let mut last = f32::INFINITY;
    for (v, lv) in row.iter().zip(left_valid.iter_mut()) {
        if v.is_finite() {
            last = *v;
        }
        *lv = last;
    }
    let mut right = f32::INFINITY;
    for (v, lv) in row.iter_mut().zip(left_valid).rev() {
        if v.is_finite() {
            right = *v;
        } else {
            *v = lv.min(right);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Plane;

    const INF: f32 = f32::INFINITY;

    #[test]
    fn fills_with_the_smaller_neighbour() {
        let mut d = Plane::from_parts(
            8,
            2,
            vec![
                INF, 5.0, INF, INF, 2.0, 7.0, INF, INF, //
                INF, INF, INF, INF, INF, INF, INF, INF,
            ],
        );
        fill_occlusions_in_place(&mut d);
        assert_eq!(d.row(0), &[5.0, 5.0, 2.0, 2.0, 2.0, 7.0, 7.0, 7.0]);
        assert!(d.row(1).iter().all(|v| v.is_infinite()), "an empty row stays invalid");
    }

    #[test]
    fn valid_pixels_are_untouched() {
        let mut d = Plane::from_parts(4, 1, vec![1.5, 0.25, 3.0, 9.0]);
        let before = d.clone();
        fill_occlusions_in_place(&mut d);
        assert_eq!(d, before);
    }
}
