//! One camera's intrinsics and lens distortion (OpenCV's radial-tangential model), and the two ways through it:
//! forward (an ideal normalised point to the pixel the lens puts it on) and back (a pixel to its ideal point, by
//! the same fixed-point iteration OpenCV's `undistortPoints` runs).
//!
//! The model: for an ideal normalised point (x, y), r² = x² + y²,
//! x_d = x·(1 + k1 r² + k2 r⁴ + k3 r⁶)/(1 + k4 r² + k5 r⁴ + k6 r⁶) + 2 p1 x y + p2 (r² + 2x²), y_d likewise with
//! p1 (r² + 2y²) + 2 p2 x y; the pixel is (fx x_d + cx, fy y_d + cy). Skew is not part of it (OpenCV's maps ignore
//! K's (0, 1) entry too).

use super::linalg::{Mat3, mul, mul_vec};

/// A camera matrix and its distortion coefficients `k1 k2 p1 p2 k3 k4 k5 k6` (absent ones are 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// The camera matrix K = [fx 0 cx; 0 fy cy; 0 0 1], row-major.
    pub matrix: [[f64; 3]; 3],
    /// `k1 k2 p1 p2 k3 k4 k5 k6`.
    pub distortion: [f64; 8],
}

/// How many times the back-projection iterates: OpenCV's `undistortPoints` default (a count, no tolerance), kept
/// so that the rectification it feeds comes out as OpenCV's does.
const UNDISTORT_ITERATIONS: usize = 5;

impl Intrinsics {
    /// The pixel where the lens images the ideal normalised point (x, y).
    pub(crate) fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3, k4, k5, k6] = self.distortion;
        let (x2, y2) = (x * x, y * y);
        let r2 = x2 + y2;
        let xy2 = 2.0 * x * y;
        let kr = (1.0 + ((k3 * r2 + k2) * r2 + k1) * r2) / (1.0 + ((k6 * r2 + k5) * r2 + k4) * r2);
        let k = &self.matrix;
        let u = k[0][0] * (x * kr + p1 * xy2 + p2 * (r2 + 2.0 * x2)) + k[0][2];
        let v = k[1][1] * (y * kr + p1 * (r2 + 2.0 * y2) + p2 * xy2) + k[1][2];
        (u, v)
    }

    /// The ideal normalised point of pixel (u, v): the distortion inverted by a fixed number of fixed-point steps
    /// (as OpenCV does; far from the centre of a strong lens it is not converged, and OpenCV's rectification is
    /// what it gives), then, when `then` is given, mapped through that 3 × 3 matrix (a rotation, or a projection
    /// times a rotation) and dehomogenised.
    pub(crate) fn undistort(&self, u: f64, v: f64, then: Option<&Mat3>) -> (f64, f64) {
        let [k1, k2, p1, p2, k3, k4, k5, k6] = self.distortion;
        let k = &self.matrix;
        let (x0, y0) = ((u - k[0][2]) / k[0][0], (v - k[1][2]) / k[1][1]);
        let (mut x, mut y) = (x0, y0);
        if self.distortion.iter().any(|&c| c != 0.0) {
            for _ in 0..UNDISTORT_ITERATIONS {
                let r2 = x * x + y * y;
                let icdist = (1.0 + ((k6 * r2 + k5) * r2 + k4) * r2) / (1.0 + ((k3 * r2 + k2) * r2 + k1) * r2);
                if icdist < 0.0 {
                    // The model folds over here: OpenCV gives up on the point and keeps it undistorted.
                    (x, y) = (x0, y0);
                    break;
                }
                let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
                let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
                (x, y) = ((x0 - dx) * icdist, (y0 - dy) * icdist);
            }
        }
        match then {
            None => (x, y),
            Some(m) => {
                let p = mul_vec(m, &[x, y, 1.0]);
                (p[0] / p[2], p[1] / p[2])
            }
        }
    }
}

/// The inscribed and circumscribed rectangles (x0, y0, x1, y1) of the image's outline after undistortion,
/// rotation by `r` and projection by `p` (its left 3 × 3), from a 9 × 9 grid of points over the image as OpenCV's
/// `getUndistortRectangles` samples it: the inner one holds only valid pixels, the outer one all of them.
pub(crate) fn undistorted_rectangles(
    camera: &Intrinsics,
    r: &Mat3,
    p: &Mat3,
    (width, height): (usize, usize),
) -> ([f64; 4], [f64; 4]) {
    const N: usize = 9;
    let pr = mul(p, r);
    let mut inner = [f64::from(-f32::MAX), f64::from(-f32::MAX), f64::from(f32::MAX), f64::from(f32::MAX)];
    let mut outer = [f64::from(f32::MAX), f64::from(f32::MAX), f64::from(-f32::MAX), f64::from(-f32::MAX)];
    for gy in 0..N {
        for gx in 0..N {
            let u = gx as f64 * (width as f64 - 1.0) / (N - 1) as f64;
            let v = gy as f64 * (height as f64 - 1.0) / (N - 1) as f64;
            let (x, y) = camera.undistort(u, v, Some(&pr));
            outer = [outer[0].min(x), outer[1].min(y), outer[2].max(x), outer[3].max(y)];
            if gx == 0 {
                inner[0] = inner[0].max(x);
            }
            if gx == N - 1 {
                inner[2] = inner[2].min(x);
            }
            if gy == 0 {
                inner[1] = inner[1].max(y);
            }
            if gy == N - 1 {
                inner[3] = inner[3].min(y);
            }
        }
    }
    (inner, outer)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lens() -> Intrinsics {
        Intrinsics {
            matrix: [[800.0, 0.0, 330.0], [0.0, 790.0, 235.0], [0.0, 0.0, 1.0]],
            distortion: [-0.12, 0.05, 0.001, -0.0008, -0.01, 0.0, 0.0, 0.0],
        }
    }

    #[test]
    fn undistorting_a_distorted_point_near_the_centre_gives_it_back() {
        let c = lens();
        for (x, y) in [(0.0, 0.0), (0.1, -0.05), (-0.2, 0.15)] {
            let (u, v) = c.distort(x, y);
            let (bx, by) = c.undistort(u, v, None);
            assert!((bx - x).abs() < 1e-6 && (by - y).abs() < 1e-6, "({x}, {y}) -> ({bx}, {by})");
        }
    }

    #[test]
    fn without_distortion_the_model_is_the_pinhole() {
        let c = Intrinsics { distortion: [0.0; 8], ..lens() };
        assert_eq!(c.distort(0.5, -0.25), (800.0 * 0.5 + 330.0, 790.0 * -0.25 + 235.0));
        assert_eq!(c.undistort(730.0, 235.0, None), (0.5, 0.0));
    }

    #[test]
    fn the_inner_rectangle_lies_inside_the_outer_one() {
        let k = lens().matrix;
        let (inner, outer) = undistorted_rectangles(&lens(), &super::super::linalg::IDENTITY, &k, (640, 480));
        assert!(outer[0] < inner[0] && outer[1] < inner[1] && inner[2] < outer[2] && inner[3] < outer[3]);
        // Barrel distortion (k1 < 0): the undistorted outline bulges beyond the image.
        assert!(outer[0] < 0.0 && outer[2] > 639.0, "{outer:?}");
    }
}
