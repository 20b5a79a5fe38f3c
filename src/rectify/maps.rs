//! The undistort-and-rectify maps (OpenCV's `initUndistortRectifyMap` with `CV_32FC1` maps): for each pixel of a
//! rectified view, where in the original image its colour is. The rectified pixel goes back through the new
//! projection and the rectifying rotation to an ideal ray, and forward through the lens model to the original
//! pixel: no iteration, the distortion is only ever applied forward.

use rayon::prelude::*;

use super::camera::Intrinsics;
use super::linalg::{Mat3, inverse, mul};
use crate::image::Plane;

/// The maps (x, y) of one view: the original image's position of every rectified pixel, `width × height` each;
/// `None` when the projection times the rotation is singular.
pub(crate) fn undistort_rectify_maps(
    camera: &Intrinsics,
    rotation: &Mat3,
    projection: &Mat3,
    (width, height): (usize, usize),
) -> Option<(Plane<f32>, Plane<f32>)> {
    let ir = inverse(&mul(projection, rotation))?;
    let mut map_x = vec![0.0f32; width * height];
    let mut map_y = vec![0.0f32; width * height];
    map_x.par_chunks_mut(width.max(1)).zip(map_y.par_chunks_mut(width.max(1))).enumerate().for_each(
        |(i, (row_x, row_y))| {
            let y = i as f64;
            for (j, (mx, my)) in row_x.iter_mut().zip(row_y.iter_mut()).enumerate() {
                let (u, v) = source_position(camera, &ir, j as f64, y);
                (*mx, *my) = (u as f32, v as f32);
            }
        },
    );
    Some((Plane::from_parts(width, height, map_x), Plane::from_parts(width, height, map_y)))
}

/// The original image's position of rectified position (x, y), given the inverse `ir` of projection × rotation.
pub(crate) fn source_position(camera: &Intrinsics, ir: &Mat3, x: f64, y: f64) -> (f64, f64) {
    let ray = [0, 1, 2].map(|r| ir[r][0] * x + ir[r][1] * y + ir[r][2]);
    camera.distort(ray[0] / ray[2], ray[1] / ray[2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rectify::linalg::IDENTITY;

    #[test]
    fn without_distortion_or_rotation_the_maps_are_the_identity() {
        let k = [[500.0, 0.0, 3.5], [0.0, 500.0, 2.0], [0.0, 0.0, 1.0]];
        let cam = Intrinsics { matrix: k, distortion: [0.0; 8] };
        let (mx, my) = undistort_rectify_maps(&cam, &IDENTITY, &k, (8, 5)).unwrap();
        for y in 0..5 {
            for x in 0..8 {
                assert!((mx.at(x, y) - x as f32).abs() < 1e-5 && (my.at(x, y) - y as f32).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn a_new_principal_point_shifts_the_maps() {
        let k = [[500.0, 0.0, 3.0], [0.0, 500.0, 2.0], [0.0, 0.0, 1.0]];
        let new = [[500.0, 0.0, 5.0], [0.0, 500.0, 1.0], [0.0, 0.0, 1.0]];
        let cam = Intrinsics { matrix: k, distortion: [0.0; 8] };
        let (mx, my) = undistort_rectify_maps(&cam, &IDENTITY, &new, (8, 5)).unwrap();
        assert!((mx.at(5, 1) - 3.0).abs() < 1e-5 && (my.at(5, 1) - 2.0).abs() < 1e-5);
    }
}
