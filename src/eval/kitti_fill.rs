//! The KITTI development kit's fill of a result before scoring: every invalid pixel takes a background value, so
//! that a sparse result is scored on all pixels with ground truth, as KITTI's own evaluation does.

use crate::image::DisparityMap;

/// Fills the invalid (non-finite) pixels of a result the way the KITTI development kit does before it scores
/// one: along each row, a run of invalid pixels between two valid ones takes the smaller (farther) of their
/// disparities and runs touching a row's ends take the nearest valid value of the row — the paper's occlusion fill
/// ([`crate::post::fill::fill_occlusions_in_place`]) — then the rows above the first and below the last row with
/// a valid pixel copy that row (rows without one between two such rows stay invalid, as in the devkit). A map
/// with no valid pixel is left as it is.
pub fn interpolate_background(map: &mut DisparityMap) {
    let (w, h) = map.dims();
    crate::post::fill::fill_occlusions_in_place(map);
    // Rows are now either all valid or all invalid; the invalid ones copy the nearest valid row (above first,
    // as the devkit extrapolates upwards from the first valid pixel of each column, then downwards).
    let valid_rows: Vec<usize> = (0..h).filter(|&y| map.data[y * w].is_finite()).collect();
    let (Some(&top), Some(&bottom)) = (valid_rows.first(), valid_rows.last()) else { return };
    for y in (0..top).chain(bottom + 1..h) {
        let src = if y < top { top } else { bottom };
        map.data.copy_within(src * w..(src + 1) * w, y * w);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Plane;

    const INF: f32 = f32::INFINITY;

    #[test]
    fn background_interpolation_by_hand() {
        // Rows 0 and 3: gaps between valid pixels take the smaller neighbour, the ends the nearest value.
        // Rows 1 and 2 have no valid pixel and lie between valid rows: they stay invalid, as in the devkit.
        let rows: [[f32; 6]; 4] =
            [[INF, 5.0, INF, INF, 2.0, INF], [INF; 6], [INF; 6], [1.0, INF, 3.0, f32::NAN, 7.0, 8.0]];
        let mut m = Plane::from_parts(6, 4, rows.concat());
        interpolate_background(&mut m);
        assert_eq!(&m.data[..6], &[5.0, 5.0, 2.0, 2.0, 2.0, 2.0]);
        assert!(m.data[6..18].iter().all(|d| d.is_infinite()), "{:?}", &m.data[6..18]);
        assert_eq!(&m.data[18..], &[1.0, 1.0, 3.0, 3.0, 7.0, 8.0]);

        let mut m = Plane::from_parts(2, 3, vec![INF, INF, 4.0, INF, INF, INF]);
        interpolate_background(&mut m);
        assert_eq!(m.data, vec![4.0; 6]);
        let mut empty = Plane::from_parts(2, 1, vec![INF, INF]);
        interpolate_background(&mut empty);
        assert!(empty.data.iter().all(|d| d.is_infinite()));
    }
}
