//! Rectification of a calibrated pair: a stereo calibration read from OpenCV's `FileStorage` files (YAML or XML,
//! as `cv2.stereoCalibrate` results are saved) or KITTI's `calib_cam_to_cam.txt`, the rectifying transforms of
//! OpenCV's `stereoRectify` (zero disparity at infinity; its free scaling `alpha`, 0 by default), the maps of
//! `initUndistortRectifyMap` and a bilinear `remap`: the views come out as OpenCV rectifies them, ready to match,
//! with the Middlebury `calib.txt` of the rectified pair (focal length, principal points, baseline) for depth, and
//! OpenCV's own description of it (`rectify.yml`: R1, R2, P1, P2, Q, the valid-pixel rectangles).
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
mod load;
mod maps;
mod stereo;
mod yml;

use std::path::{Path, PathBuf};

pub use camera::Intrinsics;
pub use stereo::RectifyingTransforms;

use crate::error::{Error, Result};
use crate::image::{Plane, RgbImage};
use formats::Format;
use linalg::Mat3;

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
    /// The calibration file it was made from (named by the warnings of a pair rectified with it).
    calibration: PathBuf,
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
            Some(Format::OpenCvYaml) => load::from_opencv(&formats::parse_yaml(text).map_err(err)?, path),
            Some(Format::OpenCvXml) => load::from_opencv(&formats::parse_xml(text).map_err(err)?, path),
            Some(Format::Kitti) => load::from_kitti(&formats::parse_kitti(text).map_err(err)?, path),
            None => {
                Err(err("neither an OpenCV FileStorage file (YAML or XML) nor a KITTI calib_cam_to_cam.txt".into()))
            }
        }
    }

    /// The rectification of views of `size` (width, height): the file's R1/R2/P1/P2 when it has them, else
    /// OpenCV's `stereoRectify` with `alpha = 0` ([`StereoCalibration::rectification_with_alpha`] with `None`).
    ///
    /// # Errors
    /// As [`StereoCalibration::rectification_with_alpha`].
    pub fn rectification(&self, size: (usize, usize)) -> Result<Rectification> {
        self.rectification_with_alpha(size, None)
    }

    /// The rectification of views of `size` (width, height) with OpenCV's free scaling `alpha` (`stereoRectify`'s):
    /// 0 keeps only valid pixels (the views are cropped to them), 1 keeps every pixel of the source views (black
    /// corners come in), values between interpolate the scale. `None`: the file's R1/R2/P1/P2 when it has them,
    /// else `alpha = 0`.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] for an `alpha` outside 0..=1; [`Error::Calib`] when `alpha` is given for a file that
    /// holds its own rectification (R1/R2/P1/P2, or views KITTI rectified), when the file states another image size,
    /// the cameras share their centre, are one above the other, or the right camera is to the left of the left one,
    /// or the distortion leaves no valid view.
    pub fn rectification_with_alpha(&self, size: (usize, usize), alpha: Option<f64>) -> Result<Rectification> {
        let err = |msg: String| calib_error(&self.path, msg);
        if let Some(a) = alpha
            && !(0.0..=1.0).contains(&a)
        {
            return Err(Error::param("alpha", a, "0..=1 (0: only valid pixels, 1: every source pixel)"));
        }
        let own = |what: &str| {
            err(format!("{what}: alpha applies only to a rectification jem computes from K1, D1, K2, D2, R and T"))
        };
        if let Some(pre) = self.prerectified
            && pre.size == size
            && self.image_size != Some(size)
        {
            if alpha.is_some() {
                return Err(own("these views are already rectified (the size of S_rect_02)"));
            }
            // Already rectified: each view's camera is its projection's, without distortion, and the maps are the
            // identity.
            let pinhole = |p: &[[f64; 4]; 3]| Intrinsics {
                matrix: [0, 1, 2].map(|i| [p[i][0], p[i][1], p[i][2]]),
                distortion: [0.0; 8],
            };
            let transforms =
                RectifyingTransforms { r1: linalg::IDENTITY, r2: linalg::IDENTITY, p1: pre.p1, p2: pre.p2 };
            let cameras = [pinhole(&pre.p1), pinhole(&pre.p2)];
            return self.checked(Rectification { size, cameras, transforms, calibration: self.path.clone() });
        }
        if let Some(stated) = self.image_size
            && stated != size
        {
            return Err(err(format!(
                "the calibration is for {}x{} images, these are {}x{}",
                stated.0, stated.1, size.0, size.1
            )));
        }
        let transforms = match (self.given, alpha) {
            (Some(_), Some(_)) => return Err(own("the file holds its own rectification (R1, R2, P1, P2)")),
            (Some(t), None) => t,
            (None, alpha) => {
                let cams = [&self.cameras[0], &self.cameras[1]];
                stereo::stereo_rectify(cams, size, &self.rotation, &self.translation, alpha.unwrap_or(0.0))
                    .ok_or_else(|| err("T is zero: the two cameras are at the same place".into()))?
            }
        };
        self.checked(Rectification { size, cameras: self.cameras, transforms, calibration: self.path.clone() })
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

    /// The calibration file it was made from ([`StereoCalibration::path`]).
    pub fn calibration_path(&self) -> &Path {
        &self.calibration
    }

    /// The rotations and projections (OpenCV's R1, R2, P1, P2).
    pub fn transforms(&self) -> &RectifyingTransforms {
        &self.transforms
    }

    /// The rectangle of valid pixels of each rectified view (left, right), as `stereoRectify` gives them
    /// (`validPixROI1`, `validPixROI2`): (x, y, width, height), within the image; from the inscribed rectangle of
    /// the view's undistorted outline, so with `alpha = 0` it is (nearly) the whole image and with `alpha = 1` the
    /// part that is not black. Empty (all zero) when no valid pixel is left.
    pub fn valid_rois(&self) -> [(usize, usize, usize, usize); 2] {
        let t = &self.transforms;
        let left3 = |p: &[[f64; 4]; 3]| -> Mat3 { [0, 1, 2].map(|i| [p[i][0], p[i][1], p[i][2]]) };
        [(&self.cameras[0], &t.r1, &t.p1), (&self.cameras[1], &t.r2, &t.p2)].map(|(camera, r, p)| {
            let (inner, _) = camera::undistorted_rectangles(camera, r, &left3(p), self.size);
            pixel_rectangle(inner, self.size)
        })
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
    /// [`Error::InputImage`] when the image is not of the rectification's size.
    pub fn rectify_view(&self, image: &RgbImage, view: View) -> Result<RgbImage> {
        if image.dims() != self.size {
            let (w, h) = image.dims();
            return Err(Error::bad_image(format!(
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

/// A rectangle (x0, y0, x1, y1) in rectified coordinates as OpenCV rounds a valid-pixel ROI, (⌈x0⌉, ⌈y0⌉,
/// ⌊x1 − x0⌋, ⌊y1 − y0⌋), intersected with the image of `size` (OpenCV's `Rect &`: all zero when they do not meet).
fn pixel_rectangle(r: [f64; 4], (width, height): (usize, usize)) -> (usize, usize, usize, usize) {
    if !r.iter().all(|v| v.is_finite()) {
        // A lens model that sends the outline nowhere: `max`/`min` below would pass a NaN over as the image edge.
        return (0, 0, 0, 0);
    }
    let (x, y) = (r[0].ceil(), r[1].ceil());
    let (right, bottom) = (x + (r[2] - r[0]).floor(), y + (r[3] - r[1]).floor());
    let (x0, y0) = (x.max(0.0), y.max(0.0));
    let (x1, y1) = (right.min(width as f64), bottom.min(height as f64));
    if !(x1 > x0 && y1 > y0) {
        return (0, 0, 0, 0);
    }
    (x0 as usize, y0 as usize, (x1 - x0) as usize, (y1 - y0) as usize)
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

#[cfg(test)]
mod tests;
