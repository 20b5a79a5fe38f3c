//! Rectification of a calibrated pair: a stereo calibration read from OpenCV's `FileStorage` files (YAML or XML,
//! as `cv2.stereoCalibrate` results are saved) or KITTI's `calib_cam_to_cam.txt`, the rectifying transforms of
//! OpenCV's `stereoRectify` (`alpha = 0`, zero disparity at infinity), the maps of `initUndistortRectifyMap` and a
//! bilinear `remap`: the views come out as OpenCV rectifies them, ready to match, with the Middlebury `calib.txt`
//! of the rectified pair (focal length, principal points, baseline) for depth.
//!
//! ```
//! # let dir = tempfile::tempdir()?;
//! # let path = dir.path().join("stereo.yml");
//! # std::fs::write(&path, "%YAML:1.0\n---\nK1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 100., 0., 31.5, 0., 100., 23.5, 0., 0., 1. ]\nD1: !!opencv-matrix\n   rows: 1\n   cols: 4\n   dt: d\n   data: [ 0., 0., 0., 0. ]\nK2: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 100., 0., 31.5, 0., 100., 23.5, 0., 0., 1. ]\nD2: !!opencv-matrix\n   rows: 1\n   cols: 4\n   dt: d\n   data: [ 0., 0., 0., 0. ]\nR: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]\nT: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: d\n   data: [ -0.1, 0., 0. ]\n")?;
//! let calibration = jem::rectify::StereoCalibration::load(&path)?;
//! let rectification = calibration.rectification((64, 48))?;
//! let (left, right) = (jem::RgbImage::new(64, 48), jem::RgbImage::new(64, 48));
//! let (left, right) = rectification.rectify_pair(&left, &right)?;
//! assert_eq!(left.dims(), (64, 48));
//! assert!((rectification.baseline() - 0.1).abs() < 1e-12);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod camera;
mod checks;
mod formats;
mod linalg;
mod maps;
mod stereo;
mod yml;

use std::path::{Path, PathBuf};

pub use camera::Intrinsics;
pub use stereo::RectifyingTransforms;

use crate::error::{Error, Result};
use crate::image::{Plane, RgbImage};
use formats::{Format, Node, Nodes};
use linalg::{Mat3, Vec3};

/// The largest calibration file read (a stereo calibration is a few kilobytes).
const MAX_CALIBRATION_BYTES: u64 = 1 << 20;

/// The memory rectifying a pair holds beyond its input, per pixel: one view's maps (two `f32`) and both
/// rectified views (three `f32` each).
pub const RECTIFY_BYTES_PER_PX: u64 = 8 + 2 * 12;

/// A calibrated stereo rig: both cameras' intrinsics, the right camera's pose in the left's frame, and, when the
/// file gives them, the rectifying transforms and the image size.
#[derive(Clone, Debug, PartialEq)]
pub struct StereoCalibration {
    /// The file it was read from (named in every message about it).
    pub path: PathBuf,
    /// The left and right cameras.
    pub cameras: [Intrinsics; 2],
    /// R: the rotation from the left camera's frame to the right's (X_right = R·X_left + T).
    pub rotation: [[f64; 3]; 3],
    /// T, in the calibration's unit (the baseline and the depth come out in it).
    pub translation: [f64; 3],
    /// The image size (width, height) the calibration is for, when the file states it.
    pub image_size: Option<(usize, usize)>,
    /// R1, R2, P1, P2 when the file holds them (a saved `stereoRectify` result): used as they are.
    pub given: Option<RectifyingTransforms>,
    /// The rectification the file's maker already applied (KITTI's `S_rect`, `P_rect`): views of that size are
    /// taken as rectified.
    pub prerectified: Option<Prerectified>,
}

/// Views a data set ships already rectified: their size and projections.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prerectified {
    /// The rectified views' size (width, height).
    pub size: (usize, usize),
    /// The left view's projection, 3 × 4.
    pub p1: [[f64; 4]; 3],
    /// The right view's projection, 3 × 4.
    pub p2: [[f64; 4]; 3],
}

/// Which view of the pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum View {
    /// The left (reference) view.
    Left,
    /// The right view.
    Right,
}

/// How a pair of a given size is rectified.
#[derive(Clone, Debug, PartialEq)]
pub struct Rectification {
    size: (usize, usize),
    cameras: [Intrinsics; 2],
    transforms: RectifyingTransforms,
}

impl StereoCalibration {
    /// Reads a calibration file: OpenCV `FileStorage` YAML or XML (K1/M1/cameraMatrix1, D1/distCoeffs1, the same
    /// for 2, R, T; `image_width`/`image_height` or a `[w, h]` size node; R1/R2/P1/P2 when present), or KITTI's
    /// `calib_cam_to_cam.txt` (cameras 02 and 03). The format is told from the content.
    ///
    /// # Errors
    /// [`Error::Io`] if it cannot be read, [`Error::Calib`] naming the file and every missing or malformed value.
    pub fn load(path: &Path) -> Result<StereoCalibration> {
        let bytes = crate::io::read_capped(path, MAX_CALIBRATION_BYTES, "calibration file")?;
        let text = String::from_utf8(bytes).map_err(|_| calib_error(path, "not a text file".into()))?;
        StereoCalibration::parse(&text, path)
    }

    /// Parses a calibration file's text (`path` names it in messages).
    ///
    /// # Errors
    /// As [`StereoCalibration::load`].
    pub fn parse(text: &str, path: &Path) -> Result<StereoCalibration> {
        let err = |msg: String| calib_error(path, msg);
        match formats::sniff(text) {
            Some(Format::OpenCvYaml) => from_opencv(&formats::parse_yaml(text).map_err(err)?, path),
            Some(Format::OpenCvXml) => from_opencv(&formats::parse_xml(text).map_err(err)?, path),
            Some(Format::Kitti) => from_kitti(&formats::parse_kitti(text).map_err(err)?, path),
            None => {
                Err(err("neither an OpenCV FileStorage file (YAML or XML) nor a KITTI calib_cam_to_cam.txt".into()))
            }
        }
    }

    /// The rectification of views of `size` (width, height): the file's R1/R2/P1/P2 when it has them, else
    /// OpenCV's `stereoRectify` with `alpha = 0`.
    ///
    /// # Errors
    /// [`Error::Calib`] when the file states another image size, the cameras share their centre, are one above the
    /// other, or the right camera is to the left of the left one, or the distortion leaves no valid view.
    pub fn rectification(&self, size: (usize, usize)) -> Result<Rectification> {
        let err = |msg: String| calib_error(&self.path, msg);
        if let Some(pre) = self.prerectified
            && pre.size == size
            && self.image_size != Some(size)
        {
            // Already rectified: each view's camera is its projection's, without distortion, and the maps are the
            // identity.
            let pinhole = |p: &[[f64; 4]; 3]| Intrinsics {
                matrix: [0, 1, 2].map(|i| [p[i][0], p[i][1], p[i][2]]),
                distortion: [0.0; 8],
            };
            let transforms =
                RectifyingTransforms { r1: linalg::IDENTITY, r2: linalg::IDENTITY, p1: pre.p1, p2: pre.p2 };
            return self.checked(Rectification { size, cameras: [pinhole(&pre.p1), pinhole(&pre.p2)], transforms });
        }
        if let Some(stated) = self.image_size
            && stated != size
        {
            return Err(err(format!(
                "the calibration is for {}x{} images, these are {}x{}",
                stated.0, stated.1, size.0, size.1
            )));
        }
        let transforms = match self.given {
            Some(t) => t,
            None => {
                stereo::stereo_rectify([&self.cameras[0], &self.cameras[1]], size, &self.rotation, &self.translation)
                    .ok_or_else(|| err("T is zero: the two cameras are at the same place".into()))?
            }
        };
        self.checked(Rectification { size, cameras: self.cameras, transforms })
    }

    /// `rect`, if its views are side by side, its focal length valid and its right camera to the right.
    fn checked(&self, rect: Rectification) -> Result<Rectification> {
        let err = |msg: String| calib_error(&self.path, msg);
        let transforms = &rect.transforms;
        let (p1, p2) = (&transforms.p1, &transforms.p2);
        if p2[1][3] != 0.0 && p2[1][3].abs() >= p2[0][3].abs() {
            return Err(err(
                "the cameras are one above the other (a vertical baseline): jem matches side-by-side views; turn the \
                 images by 90° first"
                    .into(),
            ));
        }
        let f = p1[0][0];
        let invertible = |r: &Mat3, p: &[[f64; 4]; 3]| {
            linalg::inverse(&linalg::mul(&[0, 1, 2].map(|i| [p[i][0], p[i][1], p[i][2]]), r)).is_some()
        };
        if !(invertible(&transforms.r1, p1) && invertible(&transforms.r2, p2)) {
            return Err(err("P1·R1 or P2·R2 is singular: no rectified view can be made from them".into()));
        }
        if !(f.is_finite() && f > 0.0 && p1[1][1].is_finite() && p1[1][1] > 0.0) {
            return Err(err(format!(
                "the lens distortion leaves no valid rectified view (focal length {f:.3}); check D1 and D2"
            )));
        }
        let baseline = rect.baseline();
        if baseline.is_nan() || baseline <= 0.0 {
            return Err(err(format!(
                "the right camera is {} to the left of the left one: give the views the other way round",
                -baseline
            )));
        }
        Ok(rect)
    }
}

impl Rectification {
    /// The size of both views, before and after.
    pub fn size(&self) -> (usize, usize) {
        self.size
    }

    /// The rotations and projections (OpenCV's R1, R2, P1, P2).
    pub fn transforms(&self) -> &RectifyingTransforms {
        &self.transforms
    }

    /// One line per rectified view that comes out mostly black (more than half of its pixels from outside the raw
    /// image: a lens model that cannot be right, such as `k1 = 1e30`); OpenCV rectifies such a calibration the same
    /// way, so it is said, not refused.
    pub fn warnings(&self) -> Vec<String> {
        let (t, [a, b]) = (&self.transforms, &self.cameras);
        let left3 = |p: &[[f64; 4]; 3]| -> Mat3 { [0, 1, 2].map(|i| [p[i][0], p[i][1], p[i][2]]) };
        checks::empty_views([a, b], [&t.r1, &t.r2], [&left3(&t.p1), &left3(&t.p2)], self.size)
    }

    /// A fingerprint of what the rectification does (the size, both cameras, the rotations and projections; FNV-1a
    /// of their bits): equal for two calibrations that rectify alike, different when a value changes.
    pub fn fingerprint(&self) -> u64 {
        let t = &self.transforms;
        let cameras = self.cameras.iter().flat_map(|c| c.matrix.iter().flatten().chain(&c.distortion));
        let rotations = t.r1.iter().chain(&t.r2).flatten();
        let projections = t.p1.iter().chain(&t.p2).flatten();
        let size = [self.size.0 as f64, self.size.1 as f64];
        cameras
            .chain(rotations)
            .chain(projections)
            .chain(&size)
            .fold(crate::rng::FNV_OFFSET, |h, v| crate::rng::fnv1a(h, &v.to_bits().to_le_bytes()))
    }

    /// The rectified views' focal length in pixels.
    pub fn focal_px(&self) -> f64 {
        self.transforms.p1[0][0]
    }

    /// The distance between the camera centres, in the calibration's unit.
    pub fn baseline(&self) -> f64 {
        (self.transforms.p1[0][3] - self.transforms.p2[0][3]) / self.transforms.p2[0][0]
    }

    /// The principal points (x, y) of the rectified left and right views.
    pub fn principal_points(&self) -> [(f64, f64); 2] {
        let (p1, p2) = (&self.transforms.p1, &self.transforms.p2);
        [(p1[0][2], p1[1][2]), (p2[0][2], p2[1][2])]
    }

    /// The x-difference of the principal points, right minus left (Middlebury's `doffs`; 0 with zero disparity at
    /// infinity).
    pub fn doffs(&self) -> f64 {
        let [l, r] = self.principal_points();
        r.0 - l.0
    }

    /// OpenCV's Q, the 4 × 4 matrix that takes (x, y, disparity, 1) to homogeneous 3-D points in the rectified
    /// left frame (OpenCV's disparity: x_left − x_right).
    pub fn q(&self) -> [[f64; 4]; 4] {
        let [(cx, cy), (cx2, _)] = self.principal_points();
        let tx = -self.baseline();
        [
            [1.0, 0.0, 0.0, -cx],
            [0.0, 1.0, 0.0, -cy],
            [0.0, 0.0, 0.0, self.focal_px()],
            [0.0, 0.0, -1.0 / tx, (cx - cx2) / tx],
        ]
    }

    /// The rectified left camera, for depth and point clouds ([`crate::geometry`]), keeping depths up to that of
    /// a one-pixel disparity.
    pub fn camera(&self) -> crate::geometry::Camera {
        let [(cx, cy), _] = self.principal_points();
        let (focal, baseline) = (self.focal_px(), self.baseline());
        crate::geometry::Camera { focal, cx, cy, baseline, doffs: self.doffs(), max_depth: focal * baseline }
    }

    /// The maps (x, y) of one view: for each rectified pixel, the position in the original image its colour
    /// comes from (`initUndistortRectifyMap` with `CV_32FC1` maps).
    pub fn maps(&self, view: View) -> (Plane<f32>, Plane<f32>) {
        let (camera, r, p) = match view {
            View::Left => (&self.cameras[0], &self.transforms.r1, &self.transforms.p1),
            View::Right => (&self.cameras[1], &self.transforms.r2, &self.transforms.p2),
        };
        let p3: Mat3 = [0, 1, 2].map(|i| [p[i][0], p[i][1], p[i][2]]);
        maps::undistort_rectify_maps(camera, r, &p3, self.size)
            .expect("a rectification's projection and rotation are invertible (checked when it was made)")
    }

    /// Rectifies one view: each channel resampled through the view's maps (bilinear, outside black), rounded to
    /// whole grey levels as an 8-bit image holds them.
    ///
    /// # Errors
    /// [`Error::Input`] when the image is not of the rectification's size.
    pub fn rectify_view(&self, image: &RgbImage, view: View) -> Result<RgbImage> {
        if image.dims() != self.size {
            let (w, h) = image.dims();
            return Err(Error::Input(format!(
                "the {} view is {w}x{h}, the rectification is for {}x{}",
                if view == View::Left { "left" } else { "right" },
                self.size.0,
                self.size.1
            )));
        }
        let (map_x, map_y) = self.maps(view);
        let (w, h) = self.size;
        let channels = [0, 1, 2].map(|c| {
            let mut out = crate::imgproc::sample::remap_bilinear(image.channel(c), w, h, map_x.data(), map_y.data());
            out.iter_mut().for_each(|v| *v = v.round().clamp(0.0, 255.0));
            out
        });
        RgbImage::from_channels(w, h, channels)
    }

    /// Rectifies both views ([`Rectification::rectify_view`]).
    ///
    /// # Errors
    /// As [`Rectification::rectify_view`].
    pub fn rectify_pair(&self, left: &RgbImage, right: &RgbImage) -> Result<(RgbImage, RgbImage)> {
        Ok((self.rectify_view(left, View::Left)?, self.rectify_view(right, View::Right)?))
    }

    /// The Middlebury `calib.txt` of the rectified pair: `cam0`, `cam1`, `doffs`, `baseline`, `width`, `height`
    /// (no `ndisp`: jem measures the range when a calib.txt has none).
    pub fn calib_txt(&self) -> String {
        let f = num(self.focal_px());
        let [(cx0, cy0), (cx1, cy1)] = self.principal_points().map(|(x, y)| (num(x), num(y)));
        format!(
            "cam0=[{f} 0 {cx0}; 0 {f} {cy0}; 0 0 1]\ncam1=[{f} 0 {cx1}; 0 {f} {cy1}; 0 0 1]\ndoffs={}\nbaseline={}\n\
             width={}\nheight={}\n",
            num(self.doffs()),
            num(self.baseline()),
            self.size.0,
            self.size.1
        )
    }
}

/// A number for calib.txt: 9 significant digits, no trailing zeros.
fn num(v: f64) -> String {
    let digits = (8 - v.abs().log10().floor().max(0.0) as i32).max(0) as usize;
    let s = format!("{v:.digits$}");
    let s = if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s };
    if s == "-0" { "0".into() } else { s }
}

fn calib_error(path: &Path, msg: String) -> Error {
    Error::Calib { path: path.to_path_buf(), msg }
}

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

fn from_opencv(nodes: &Nodes, path: &Path) -> Result<StereoCalibration> {
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
fn from_kitti(nodes: &Nodes, path: &Path) -> Result<StereoCalibration> {
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

#[cfg(test)]
mod tests;
