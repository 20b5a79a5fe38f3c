//! The rectifying rotations and projections of a calibrated pair, as OpenCV's `stereoRectify` computes them with
//! zero disparity at infinity (both views share the principal point) and its free scaling `alpha` (0: only valid
//! pixels in the rectified views; 1: every source pixel kept).
//!
//! The right camera's rotation R is halved between the views (each turns by −½ of its rotation vector), then one
//! more rotation turns the baseline onto the x axis; the new focal length is the mean of the vertical ones, the new
//! principal point centres the undistorted corners of both views; finally both are scaled about it: by s0, the
//! scale at which the inscribed rectangle of each undistorted view fills the image (`alpha = 0`), or by s1, the
//! scale at which the circumscribed rectangle of each fits inside it (`alpha = 1`), or by s0·(1 − alpha) + s1·alpha
//! between them, as OpenCV interpolates.

use super::camera::{Intrinsics, undistorted_rectangles};
use super::linalg::{Mat3, Vec3, cross, mul, mul_vec, norm, rotation_from_vector, transpose, vector_from_rotation};

/// The rectification of a pair: rotations and projection matrices as `stereoRectify` returns them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RectifyingTransforms {
    /// The left camera's rectifying rotation.
    pub r1: Mat3,
    /// The right camera's rectifying rotation.
    pub r2: Mat3,
    /// The left view's projection in the rectified frame, 3 × 4.
    pub p1: [[f64; 4]; 3],
    /// The right view's projection, 3 × 4: the (0, 3) entry is f·Tx (negative when the right camera is to the
    /// right).
    pub p2: [[f64; 4]; 3],
}

/// `stereoRectify(K1, D1, K2, D2, size, R, T, alpha, CALIB_ZERO_DISPARITY)` for `alpha` in 0..=1; `None` when the
/// cameras share their centre (T = 0).
pub(crate) fn stereo_rectify(
    cams: [&Intrinsics; 2],
    size: (usize, usize),
    rotation: &Mat3,
    translation: &Vec3,
    alpha: f64,
) -> Option<RectifyingTransforms> {
    let (nx, ny) = (size.0 as f64, size.1 as f64);
    let om = vector_from_rotation(rotation).map(|v| -0.5 * v);
    let r_r = rotation_from_vector(&om);
    let t = mul_vec(&r_r, translation);
    let idx = if t[0].abs() > t[1].abs() { 0 } else { 1 };
    let (c, nt) = (t[idx], norm(&t));
    if !(nt > 0.0 && nt.is_finite()) {
        return None;
    }
    let mut uu = [0.0; 3];
    uu[idx] = if c > 0.0 { 1.0 } else { -1.0 };
    let mut ww = cross(&t, &uu);
    let nw = norm(&ww);
    if nw > 0.0 {
        let scale = (c.abs() / nt).acos() / nw;
        ww = ww.map(|v| v * scale);
    }
    let w_r = rotation_from_vector(&ww);
    let r1 = mul(&w_r, &transpose(&r_r));
    let r2 = mul(&w_r, &r_r);
    let t = mul_vec(&r2, translation);

    // The focal length: the mean of the two cameras' focal lengths across the baseline's direction.
    let mut fc = (cams[0].matrix[idx ^ 1][idx ^ 1] + cams[1].matrix[idx ^ 1][idx ^ 1]) * 0.5;
    let mut cc = [[0.0; 2]; 2];
    for (k, cam) in cams.iter().enumerate() {
        let rot = if k == 0 { &r1 } else { &r2 };
        let mut sum = [0.0; 2];
        for (u, v) in [(0.0, 0.0), (nx - 1.0, 0.0), (0.0, ny - 1.0), (nx - 1.0, ny - 1.0)] {
            // OpenCV holds these corner points in single precision; so do we, to give its principal point.
            let (u, v) = (u as f32, v as f32);
            let (x, y) = cam.undistort(f64::from(u), f64::from(v), None);
            let (x, y) = (f64::from(x as f32), f64::from(y as f32));
            let p = mul_vec(rot, &[x, y, 1.0]);
            sum[0] += f64::from((fc * p[0] / p[2]) as f32);
            sum[1] += f64::from((fc * p[1] / p[2]) as f32);
        }
        cc[k] = [(nx - 1.0) / 2.0 - sum[0] / 4.0, (ny - 1.0) / 2.0 - sum[1] / 4.0];
    }
    // Zero disparity at infinity: one principal point for both views.
    let shared = [(cc[0][0] + cc[1][0]) * 0.5, (cc[0][1] + cc[1][1]) * 0.5];
    let projection = |f: f64, c: [f64; 2], tx: f64| -> [[f64; 4]; 3] {
        let mut p = [[f, 0.0, c[0], 0.0], [0.0, f, c[1], 0.0], [0.0, 0.0, 1.0, 0.0]];
        p[idx][3] = tx;
        p
    };
    let p1 = projection(fc, shared, 0.0);
    let p2 = projection(fc, shared, t[idx] * fc);
    let left3 = |p: &[[f64; 4]; 3]| -> Mat3 { [0, 1, 2].map(|i| [p[i][0], p[i][1], p[i][2]]) };
    let (inner1, outer1) = undistorted_rectangles(cams[0], &r1, &left3(&p1), size);
    let (inner2, outer2) = undistorted_rectangles(cams[1], &r2, &left3(&p2), size);

    // The scale about the principal point at which a rectangle's left, top, right and bottom edges reach the
    // image's: the largest of the four covers the image with it, the smallest fits it inside.
    let (cx, cy) = (shared[0], shared[1]);
    let reach = |r: &[f64; 4]| {
        [cx / (cx - r[0]), cy / (cy - r[1]), (nx - 1.0 - cx) / (r[2] - cx), (ny - 1.0 - cy) / (r[3] - cy)]
    };
    let largest = |r: &[f64; 4]| reach(r).into_iter().fold(f64::MIN, f64::max);
    let smallest = |r: &[f64; 4]| reach(r).into_iter().fold(f64::MAX, f64::min);
    // alpha = 0: each view's inscribed rectangle covers the whole image (only valid pixels are seen).
    let s0 = largest(&inner1).max(largest(&inner2));
    // alpha = 1: each view's circumscribed rectangle fits inside the image (no source pixel is lost).
    let s1 = smallest(&outer1).min(smallest(&outer2));
    // The default alpha = 0 takes s0 as it is, whatever s1 is (not finite for a lens model that folds over).
    let s = if alpha == 0.0 { s0 } else { s0 * (1.0 - alpha) + s1 * alpha };
    fc *= s;
    let p1 = projection(fc, shared, 0.0);
    let p2 = projection(fc, shared, t[idx] * fc);
    Some(RectifyingTransforms { r1, r2, p1, p2 })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(f: f64, cx: f64, cy: f64, k1: f64) -> Intrinsics {
        Intrinsics {
            matrix: [[f, 0.0, cx], [0.0, f * 1.01, cy], [0.0, 0.0, 1.0]],
            distortion: [k1, 0.02, 0.0005, -0.0004, 0.0, 0.0, 0.0, 0.0],
        }
    }

    #[test]
    fn the_rectified_frames_put_the_baseline_on_the_x_axis() {
        let (a, b) = (cam(700.0, 318.0, 242.0, -0.1), cam(710.0, 325.0, 236.0, -0.08));
        let rotation = rotation_from_vector(&[0.01, -0.03, 0.008]);
        let translation = [-120.0, 2.5, -1.5];
        let rect = stereo_rectify([&a, &b], (640, 480), &rotation, &translation, 0.0).unwrap();
        // The right camera's centre, in the left rectified frame, lies on the x axis.
        let centre = mul_vec(&transpose(&rotation), &translation.map(|v| -v));
        let in_rect = mul_vec(&rect.r1, &centre);
        assert!(in_rect[1].abs() < 1e-9 && in_rect[2].abs() < 1e-9 && in_rect[0] > 0.0, "{in_rect:?}");
        // The two rectified frames are parallel: R2 · R · R1ᵀ = I.
        let relative = mul(&mul(&rect.r2, &rotation), &transpose(&rect.r1));
        for (i, row) in relative.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12, "{relative:?}");
            }
        }
        assert_eq!(rect.p1[0][2], rect.p2[0][2]);
        assert_eq!(rect.p1[1][2], rect.p2[1][2]);
        assert!((rect.p2[0][3] / rect.p2[0][0] + norm(&translation)).abs() < 1e-9);
    }

    #[test]
    fn cameras_at_the_same_place_have_no_rectification() {
        let a = cam(700.0, 320.0, 240.0, 0.0);
        assert!(stereo_rectify([&a, &a], (640, 480), &super::super::linalg::IDENTITY, &[0.0; 3], 0.0).is_none());
    }
}
