//! Reading a stereo calibration's values: OpenCV `FileStorage` nodes (K1/M1/cameraMatrix1, D1, ..., R, T, and
//! R1/R2/P1/P2 when saved) and KITTI's `calib_cam_to_cam.txt` (cameras 02 and 03), every missing or malformed
//! value gathered into one message.

use std::path::Path;

use super::formats::{Node, Nodes};
use super::linalg::{self, Mat3, Vec3};
use super::{Intrinsics, Prerectified, RectifyingTransforms, StereoCalibration, calib_error, checks};
use crate::error::Result;

/// Looks up nodes by their accepted names and gathers everything missing, so one message lists it all.
struct Lookup<'a> {
    nodes: &'a Nodes,
    missing: Vec<String>,
    bad: Vec<String>,
}

impl<'a> Lookup<'a> {
    fn new(nodes: &'a Nodes) -> Self {
        Lookup { nodes, missing: Vec::new(), bad: Vec::new() }
    }

    fn find(&self, names: &[&str]) -> Option<(&'a str, &'a Node)> {
        names.iter().find_map(|n| self.nodes.get_key_value(*n).map(|(k, v)| (k.as_str(), v)))
    }

    /// A required node; recorded as missing (under all its names) when absent.
    fn required(&mut self, names: &[&str]) -> Option<(&'a str, &'a Node)> {
        let found = self.find(names);
        if found.is_none() {
            self.missing.push(names.join("/"));
        }
        found
    }

    fn mat3(&mut self, names: &[&str]) -> Option<Mat3> {
        let (name, node) = self.required(names)?;
        if node.data.len() != 9 {
            self.bad.push(format!("{name} has {} values (a 3×3 matrix has 9)", node.data.len()));
            return None;
        }
        Some([0, 1, 2].map(|i| [0, 1, 2].map(|j| node.data[3 * i + j])))
    }

    /// A required rotation matrix ([`checks::not_a_rotation`]).
    fn rotation(&mut self, names: &[&str]) -> Option<Mat3> {
        let m = self.mat3(names)?;
        self.checked(checks::not_a_rotation(self.find(names)?.0, &m), m)
    }

    /// A required translation ([`checks::not_a_translation`]).
    fn translation(&mut self, names: &[&str]) -> Option<Vec3> {
        let t = self.vec3(names)?;
        self.checked(checks::not_a_translation(self.find(names)?.0, &t), t)
    }

    /// `value`, or `None` with `why` recorded.
    fn checked<T>(&mut self, why: Option<String>, value: T) -> Option<T> {
        match why {
            Some(why) => {
                self.bad.push(why);
                None
            }
            None => Some(value),
        }
    }

    /// A projection whose values are finite, when the file has one.
    fn finite_proj(&mut self, names: &[&str]) -> Option<[[f64; 4]; 3]> {
        let p = self.proj(names)?;
        self.checked(checks::not_finite(self.find(names)?.0, p.as_flattened()), p)
    }

    fn vec3(&mut self, names: &[&str]) -> Option<Vec3> {
        let (name, node) = self.required(names)?;
        if node.data.len() != 3 {
            self.bad.push(format!("{name} has {} values (expected 3)", node.data.len()));
            return None;
        }
        Some([node.data[0], node.data[1], node.data[2]])
    }

    fn proj(&mut self, names: &[&str]) -> Option<[[f64; 4]; 3]> {
        let (name, node) = self.find(names)?;
        if node.data.len() != 12 {
            self.bad.push(format!("{name} has {} values (a 3×4 projection has 12)", node.data.len()));
            return None;
        }
        Some([0, 1, 2].map(|i| [0, 1, 2, 3].map(|j| node.data[4 * i + j])))
    }

    /// A camera: its matrix and distortion (4, 5, 8 coefficients; 12 or 14 when the thin-prism and tilt terms
    /// are zero, as this model has none).
    fn camera(&mut self, matrix: &[&str], distortion: &[&str]) -> Option<Intrinsics> {
        let k = self.mat3(matrix);
        let d = self.required(distortion);
        let (k, (dname, d)) = (k?, d?);
        let n = d.data.len();
        if ![4, 5, 8, 12, 14].contains(&n) || d.data.iter().skip(8).any(|&v| v != 0.0) {
            self.bad.push(format!(
                "{dname} has {n} coefficients{}: k1 k2 p1 p2 [k3 [k4 k5 k6]] are supported",
                if n > 8 { " with thin-prism or tilt terms" } else { "" }
            ));
            return None;
        }
        if !(k[0][0] > 0.0 && k[1][1] > 0.0 && k.iter().flatten().all(|v| v.is_finite())) {
            self.bad.push(format!("{} must have positive focal lengths", matrix[0]));
            return None;
        }
        if let Some(why) = checks::not_finite(dname, &d.data) {
            self.bad.push(why);
            return None;
        }
        let mut distortion = [0.0; 8];
        distortion[..n.min(8)].copy_from_slice(&d.data[..n.min(8)]);
        Some(Intrinsics { matrix: k, distortion })
    }

    fn finish(self, path: &Path, what: &str) -> Result<()> {
        let mut problems = Vec::new();
        if !self.missing.is_empty() {
            problems.push(format!("missing {}", self.missing.join(", ")));
        }
        problems.extend(self.bad);
        if problems.is_empty() {
            return Ok(());
        }
        Err(calib_error(path, format!("{} ({what})", problems.join("; "))))
    }
}

/// An image size from `image_width`/`image_height`, or a `[w, h]` node ([`checks::image_size`]); a stated size
/// that is no size is recorded in `look` and gives `None`.
fn stated_size(look: &mut Lookup<'_>, names: &[&str]) -> Option<(usize, usize)> {
    let scalar = |n: &str| look.nodes.get(n).and_then(|v| v.data.first().copied());
    let size = if let (Some(w), Some(h)) = (scalar("image_width"), scalar("image_height")) {
        checks::image_size("image_width/image_height", w, h)
    } else {
        let (name, node) = names.iter().find_map(|n| look.nodes.get_key_value(*n))?;
        if node.data.len() != 2 {
            look.bad.push(format!("{name} has {} values (an image size has 2: width, height)", node.data.len()));
            return None;
        }
        checks::image_size(name, node.data[0], node.data[1])
    };
    size.map_err(|why| look.bad.push(why)).ok()
}

pub(super) fn from_opencv(nodes: &Nodes, path: &Path) -> Result<StereoCalibration> {
    let mut look = Lookup::new(nodes);
    let left = look.camera(&["K1", "M1", "cameraMatrix1"], &["D1", "distCoeffs1"]);
    let right = look.camera(&["K2", "M2", "cameraMatrix2"], &["D2", "distCoeffs2"]);
    let rotation = match look.find(&["R"]) {
        Some((name, node)) if node.data.len() == 3 => {
            let v = [node.data[0], node.data[1], node.data[2]];
            look.checked(checks::not_finite(name, &v), linalg::rotation_from_vector(&v))
        }
        _ => look.rotation(&["R"]),
    };
    let translation = look.translation(&["T"]);
    let given = match (look.find(&["R1"]), look.find(&["R2"])) {
        (Some(_), Some(_)) => {
            let (r1, r2) = (look.rotation(&["R1"]), look.rotation(&["R2"]));
            let (p1, p2) = (look.finite_proj(&["P1"]), look.finite_proj(&["P2"]));
            match (r1, r2, p1, p2) {
                (Some(r1), Some(r2), Some(p1), Some(p2)) => Some(RectifyingTransforms { r1, r2, p1, p2 }),
                _ => None,
            }
        }
        _ => None,
    };
    let image_size = stated_size(&mut look, &["image_size", "imageSize", "size"]);
    look.finish(path, "an OpenCV stereo calibration has K1/M1, D1, K2/M2, D2, R and T")?;
    let (Some(left), Some(right), Some(rotation), Some(translation)) = (left, right, rotation, translation) else {
        unreachable!("every missing value was reported")
    };
    Ok(StereoCalibration {
        path: path.to_path_buf(),
        cameras: [left, right],
        rotation,
        translation,
        image_size,
        given,
        prerectified: None,
    })
}

/// KITTI's cameras 02 (left colour) and 03 (right colour). Raw images (of size S_02) are rectified from K, D, R, T
/// of both; images already rectified by KITTI (of size S_rect_02) are taken as they are, with P_rect_02 and
/// P_rect_03 as their projections.
pub(super) fn from_kitti(nodes: &Nodes, path: &Path) -> Result<StereoCalibration> {
    let mut look = Lookup::new(nodes);
    let left = look.camera(&["K_02"], &["D_02"]);
    let right = look.camera(&["K_03"], &["D_03"]);
    let (r02, r03) = (look.rotation(&["R_02"]), look.rotation(&["R_03"]));
    let (t02, t03) = (look.vec3(&["T_02"]), look.vec3(&["T_03"]));
    let (p02, p03) = (look.finite_proj(&["P_rect_02"]), look.finite_proj(&["P_rect_03"]));
    let (raw_size, rect_size) = (stated_size(&mut look, &["S_02"]), stated_size(&mut look, &["S_rect_02"]));
    look.finish(path, "KITTI's calib_cam_to_cam.txt has K_02, D_02, R_02, T_02 and the same for 03")?;
    let (Some(left), Some(right), Some(r02), Some(r03), Some(t02), Some(t03)) = (left, right, r02, r03, t02, t03)
    else {
        unreachable!("every missing value was reported")
    };
    // The pose of camera 03 in camera 02's frame, from both poses in camera 00's.
    let rotation = linalg::mul(&r03, &linalg::transpose(&r02));
    let rt = linalg::mul_vec(&rotation, &t02);
    let translation = [t03[0] - rt[0], t03[1] - rt[1], t03[2] - rt[2]];
    if let Some(why) = checks::not_a_translation("T_03 − R·T_02 (camera 03 seen from camera 02)", &translation) {
        return Err(calib_error(path, why));
    }
    let prerectified = match (p02, p03, rect_size) {
        (Some(p1), Some(p2), Some(size)) => Some(Prerectified { size, p1, p2 }),
        _ => None,
    };
    Ok(StereoCalibration {
        path: path.to_path_buf(),
        cameras: [left, right],
        rotation,
        translation,
        image_size: raw_size,
        given: None,
        prerectified,
    })
}
