//! What a calibration's values must be before any rectification is made of them, and what is said about a
//! rectification that can be made but shows nothing.
//!
//! Refused, with the key named: a matrix that is no rotation (R, R1, R2, KITTI's R_02 and R_03: RᵀR must be the
//! identity and det R = +1, within [`ROTATION_TOLERANCE`]; OpenCV turns any matrix into the rotation nearest to it
//! without a word, and a reflection into a mirrored view), an image size that is no size (`image_width: -5`,
//! `height: 0`), a translation of length zero or beyond floating point, and values that are not finite numbers.
//! Warned about ([`empty_views`]): a rectified view that comes out mostly black because the lens model sends its
//! pixels outside the raw image (`k1 = 1e30`), which OpenCV rectifies the same way.

use super::camera::Intrinsics;
use super::linalg::{Mat3, Vec3, det, inverse, mul, norm, transpose};

/// How far RᵀR may be from the identity, and det R from 1, entry by entry, for R to count as a rotation: the
/// printed digits of a calibration file (OpenCV prints 17 significant digits and KITTI 7, both within 1e-6; a
/// matrix typed with four decimals stays within 1e-3).
pub(crate) const ROTATION_TOLERANCE: f64 = 1e-3;

/// Why the matrix `name` is not a rotation; `None` when it is one (within [`ROTATION_TOLERANCE`]).
pub(crate) fn not_a_rotation(name: &str, m: &Mat3) -> Option<String> {
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Some(format!("{name} has a value that is not a finite number"));
    }
    let mtm = mul(&transpose(m), m);
    let off = (0..9).map(|k| (mtm[k / 3][k % 3] - f64::from(u8::from(k / 3 == k % 3))).abs()).fold(0.0, f64::max);
    if off > ROTATION_TOLERANCE {
        return Some(format!(
            "{name} is not a rotation (RᵀR differs from the identity by up to {}; a rotation's rows are \
             orthogonal unit vectors)",
            short(off)
        ));
    }
    let d = det(m);
    if (d - 1.0).abs() > ROTATION_TOLERANCE {
        return Some(format!(
            "{name} is a reflection, not a rotation (its determinant is {}): it would mirror the view; check its \
             signs",
            short(d)
        ));
    }
    None
}

/// Why the translation `name` cannot be a baseline: a value that is not finite, a length of zero (the cameras at
/// one place) or beyond floating point; `None` when it can.
pub(crate) fn not_a_translation(name: &str, t: &Vec3) -> Option<String> {
    let shown = format!("({}, {}, {})", value(t[0]), value(t[1]), value(t[2]));
    if t.iter().any(|v| !v.is_finite()) {
        return Some(format!("{name} {shown} has a value that is not a finite number"));
    }
    let length = norm(t);
    if length == 0.0 {
        return Some(format!("{name} is zero: the two cameras are at the same place"));
    }
    if !length.is_finite() {
        return Some(format!("{name} {shown} is too long: its length is beyond floating point; check its unit"));
    }
    None
}

/// Why the distortion coefficients `name` cannot be used: one is not a finite number.
pub(crate) fn not_finite(name: &str, values: &[f64]) -> Option<String> {
    values.iter().any(|v| !v.is_finite()).then(|| format!("{name} has a value that is not a finite number"))
}

/// An image size from a width and a height stated under `keys` (`image_width`/`image_height`, or one `[w, h]`
/// node): whole numbers of at least one pixel, else why not (naming the key).
pub(crate) fn image_size(keys: &str, w: f64, h: f64) -> Result<(usize, usize), String> {
    let ok = |v: f64| v >= 1.0 && v.fract() == 0.0 && v <= f64::from(u32::MAX);
    if ok(w) && ok(h) {
        return Ok((w as usize, h as usize));
    }
    Err(format!(
        "{keys} {} × {} is not an image size (expected whole numbers of pixels, at least 1)",
        value(w),
        value(h)
    ))
}

/// A value of the file in a message: a whole number as one (`-5`), any other as Rust writes it shortest (`0.5`,
/// `-1e300`, `NaN`).
fn value(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 { format!("{v}") } else { format!("{v:?}") }
}

/// A number in a message: three decimals, or three significant digits in scientific notation when it is large.
fn short(v: f64) -> String {
    if v.abs() < 1e4 { format!("{v:.3}") } else { format!("{v:.3e}") }
}

/// The share of a rectified view below which it counts as empty: alpha = 0 rectifies into the valid pixels only,
/// and a file's own R1/P1 with black borders still keeps most of the view.
const EMPTY_SHARE: f64 = 0.5;

/// Samples per side of the grid [`empty_views`] checks.
const GRID: usize = 64;

/// One line per view of a rectification of `size` whose pixels come from outside the raw image for more than half
/// of it (the view would be mostly black): `cameras[k]` seen through rotation `rotations[k]` and projection
/// `projections[k]`.
pub(crate) fn empty_views(
    cameras: [&Intrinsics; 2],
    rotations: [&Mat3; 2],
    projections: [&Mat3; 2],
    size: (usize, usize),
) -> Vec<String> {
    let (w, h) = (size.0 as f64, size.1 as f64);
    let mut lines = Vec::new();
    for (k, view) in ["left", "right"].iter().enumerate() {
        let Some(ir) = inverse(&mul(projections[k], rotations[k])) else { continue };
        let mut inside = 0usize;
        for gy in 0..GRID {
            for gx in 0..GRID {
                let x = (gx as f64 + 0.5) * w / GRID as f64 - 0.5;
                let y = (gy as f64 + 0.5) * h / GRID as f64 - 0.5;
                let (u, v) = super::maps::source_position(cameras[k], &ir, x, y);
                inside += usize::from((-0.5..w - 0.5).contains(&u) && (-0.5..h - 0.5).contains(&v));
            }
        }
        let share = inside as f64 / (GRID * GRID) as f64;
        if share < EMPTY_SHARE {
            lines.push(format!(
                "the rectified {view} view is {:.0} % black: the {view} camera's lens model (its distortion \
                 coefficients) or rectification sends its pixels outside the raw image; check the calibration",
                100.0 * (1.0 - share)
            ));
        }
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rectify::linalg::{IDENTITY, rotation_from_vector};

    #[test]
    fn rotations_pass_and_other_matrices_are_named() {
        assert_eq!(not_a_rotation("R", &rotation_from_vector(&[0.012, -0.031, 0.0075])), None);
        // Printed with four decimals: still a rotation.
        let r = rotation_from_vector(&[0.0, 0.0, 0.3]).map(|row| row.map(|v| (v * 1e4).round() / 1e4));
        assert_eq!(not_a_rotation("R", &r), None);
        let twice = IDENTITY.map(|row| row.map(|v| 2.0 * v));
        let counting = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]];
        for m in [twice, counting] {
            assert!(not_a_rotation("R1", &m).unwrap().starts_with("R1 is not a rotation"));
        }
        let mirror = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]];
        assert!(not_a_rotation("R", &mirror).unwrap().contains("reflection"));
        assert!(not_a_rotation("R", &[[f64::NAN; 3]; 3]).unwrap().contains("not a finite number"));
    }

    #[test]
    fn translations_sizes_and_coefficients_are_checked() {
        assert_eq!(not_a_translation("T", &[-0.12, 0.0035, -0.0021]), None);
        assert!(not_a_translation("T", &[0.0; 3]).unwrap().contains("T is zero"));
        assert!(not_a_translation("T", &[-1e300, 0.0, 0.0]).unwrap().contains("beyond floating point"));
        assert!(not_a_translation("T", &[f64::INFINITY, 0.0, 0.0]).unwrap().contains("not a finite number"));
        assert_eq!(image_size("S_02", 1392.0, 512.0), Ok((1392, 512)));
        for (w, h) in [(-5.0, 480.0), (640.0, 0.0), (640.5, 480.0), (f64::NAN, 480.0)] {
            assert!(image_size("image_width/image_height", w, h).unwrap_err().contains("image_width"));
        }
        assert!(not_finite("D1", &[0.1, f64::NAN]).is_some() && not_finite("D1", &[1e30]).is_none());
    }

    #[test]
    fn a_lens_that_sends_the_view_outside_the_image_is_said_to_be_empty() {
        let k = [[80.0, 0.0, 31.5], [0.0, 80.0, 23.5], [0.0, 0.0, 1.0]];
        let plain = Intrinsics { matrix: k, distortion: [0.0; 8] };
        let wild = Intrinsics { distortion: [1e30, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], ..plain };
        let views = |a: &Intrinsics, b: &Intrinsics| empty_views([a, b], [&IDENTITY, &IDENTITY], [&k, &k], (64, 48));
        assert!(views(&plain, &plain).is_empty());
        let lines = views(&plain, &wild);
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(lines[0].starts_with("the rectified right view is 100 % black"), "{lines:?}");
    }
}
