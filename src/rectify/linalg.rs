//! The little linear algebra rectification needs: 3 × 3 matrices and 3-vectors in `f64`, Rodrigues' formula both
//! ways, and the nearest rotation to a matrix. Row-major `[[f64; 3]; 3]`; nothing here allocates.

/// A 3 × 3 matrix, row-major.
pub(crate) type Mat3 = [[f64; 3]; 3];
/// A 3-vector.
pub(crate) type Vec3 = [f64; 3];

/// The identity.
pub(crate) const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// `a · b`.
pub(crate) fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}

/// `a · v`.
pub(crate) fn mul_vec(a: &Mat3, v: &Vec3) -> Vec3 {
    [0, 1, 2].map(|i| a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
}

/// `aᵀ`.
pub(crate) fn transpose(a: &Mat3) -> Mat3 {
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| a[j][i]))
}

/// The determinant.
pub(crate) fn det(a: &Mat3) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// The inverse (adjugate over determinant), or `None` for a singular or non-finite matrix.
pub(crate) fn inverse(a: &Mat3) -> Option<Mat3> {
    let d = det(a);
    if !(d.is_finite() && d != 0.0) {
        return None;
    }
    let c = |i: usize, j: usize| {
        let (i1, i2, j1, j2) = ((i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3);
        a[i1][j1] * a[i2][j2] - a[i1][j2] * a[i2][j1]
    };
    // The inverse's (i, j) entry is the cofactor of (j, i) over the determinant.
    Some([0, 1, 2].map(|i| [0, 1, 2].map(|j| c(j, i) / d)))
}

/// The Euclidean norm.
pub(crate) fn norm(v: &Vec3) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// `a × b`.
pub(crate) fn cross(a: &Vec3, b: &Vec3) -> Vec3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// The rotation of angle |r| about r/|r| (Rodrigues' formula): R = cos θ·I + (1 − cos θ)·r̂r̂ᵀ + sin θ·[r̂]×.
pub(crate) fn rotation_from_vector(r: &Vec3) -> Mat3 {
    let theta = norm(r);
    if theta < f64::EPSILON {
        return IDENTITY;
    }
    let k = r.map(|v| v / theta);
    let (c, s) = (theta.cos(), theta.sin());
    let c1 = 1.0 - c;
    let cross = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| c * IDENTITY[i][j] + c1 * k[i] * k[j] + s * cross[i][j]))
}

/// The rotation vector of a rotation matrix (the inverse of [`rotation_from_vector`]), after replacing `m` by the
/// nearest rotation ([`nearest_rotation`]): a calibration file's matrix is a rotation only to its printed digits.
/// Angles near π take the axis from the diagonal, where the antisymmetric part vanishes.
pub(crate) fn vector_from_rotation(m: &Mat3) -> Vec3 {
    let r = nearest_rotation(m);
    let mut v = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]];
    let s = (0.25 * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])).sqrt();
    let c = ((r[0][0] + r[1][1] + r[2][2] - 1.0) * 0.5).clamp(-1.0, 1.0);
    let theta = c.acos();
    if s < 1e-5 {
        if c > 0.0 {
            return [0.0; 3];
        }
        let axis = |t: f64| ((t + 1.0) * 0.5).max(0.0).sqrt();
        v = [
            axis(r[0][0]),
            axis(r[1][1]) * if r[0][1] < 0.0 { -1.0 } else { 1.0 },
            axis(r[2][2]) * if r[0][2] < 0.0 { -1.0 } else { 1.0 },
        ];
        if v[0].abs() < v[1].abs() && v[0].abs() < v[2].abs() && (r[1][2] > 0.0) != (v[1] * v[2] > 0.0) {
            v[2] = -v[2];
        }
        let n = norm(&v);
        return v.map(|x| x * theta / n);
    }
    let scale = theta / (2.0 * s);
    v.map(|x| x * scale)
}

/// The orthogonal factor of the polar decomposition of `m` (U·Vᵀ of its SVD: the rotation nearest to it in the
/// Frobenius norm), by Newton's iteration X ← (X + X⁻ᵀ) / 2, which converges quadratically from any non-singular
/// matrix. A singular `m` is returned unchanged.
pub(crate) fn nearest_rotation(m: &Mat3) -> Mat3 {
    let mut x = *m;
    for _ in 0..50 {
        let Some(inv) = inverse(&x) else { return *m };
        let it = transpose(&inv);
        let next: Mat3 = [0, 1, 2].map(|i| [0, 1, 2].map(|j| 0.5 * (x[i][j] + it[i][j])));
        let change: f64 = (0..9).map(|k| (next[k / 3][k % 3] - x[k / 3][k % 3]).abs()).sum();
        x = next;
        if change < 1e-15 {
            break;
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Mat3, b: &Mat3, tol: f64) -> bool {
        (0..9).all(|k| (a[k / 3][k % 3] - b[k / 3][k % 3]).abs() <= tol)
    }

    #[test]
    fn rodrigues_round_trips_small_medium_and_near_half_turn_angles() {
        for r in [
            [0.01, -0.02, 0.005],
            [0.3, 0.2, -0.4],
            [0.0, 0.0, 1.5],
            [3.0, 0.5, -0.2],
            [0.0, std::f64::consts::PI, 0.0],
        ] {
            let m = rotation_from_vector(&r);
            assert!(close(&mul(&m, &transpose(&m)), &IDENTITY, 1e-12), "{r:?} not orthonormal");
            assert!((det(&m) - 1.0).abs() < 1e-12);
            let back = rotation_from_vector(&vector_from_rotation(&m));
            assert!(close(&back, &m, 1e-9), "{r:?}: {back:?} vs {m:?}");
        }
        assert_eq!(vector_from_rotation(&IDENTITY), [0.0; 3]);
    }

    #[test]
    fn a_rotation_about_z_turns_x_into_y() {
        let m = rotation_from_vector(&[0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        let v = mul_vec(&m, &[1.0, 0.0, 0.0]);
        assert!((v[0]).abs() < 1e-15 && (v[1] - 1.0).abs() < 1e-15 && v[2].abs() < 1e-15, "{v:?}");
    }

    #[test]
    fn the_nearest_rotation_of_a_rounded_rotation_is_orthonormal_and_close() {
        let m = rotation_from_vector(&[0.1, -0.05, 0.02]);
        let rounded = m.map(|row| row.map(|v| (v * 1e4).round() / 1e4));
        let r = nearest_rotation(&rounded);
        assert!(close(&mul(&r, &transpose(&r)), &IDENTITY, 1e-14));
        assert!(close(&r, &m, 1e-4));
    }

    #[test]
    fn inverse_times_matrix_is_identity_and_singular_is_none() {
        let a = [[700.0, 0.5, 320.0], [0.0, 690.0, 240.0], [0.0, 0.0, 1.0]];
        assert!(close(&mul(&a, &inverse(&a).unwrap()), &IDENTITY, 1e-12));
        assert!(inverse(&[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]).is_none());
        assert_eq!(cross(&[1.0, 0.0, 0.0], &[0.0, 1.0, 0.0]), [0.0, 0.0, 1.0]);
    }
}
