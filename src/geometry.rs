//! From disparity to geometry: metric depth and a coloured point cloud (binary PLY), with the Middlebury
//! camera model of `calib.txt`.
//!
//! A left pixel (x, y) with disparity d lies at depth Z = f·B / (d + doffs) (f: focal length in pixels, B: the
//! baseline, doffs: the difference of the two principal points' x), and at X = (x − cx)·Z / f,
//! Y = (y − cy)·Z / f in the left camera's frame (x right, y down, z forward), in the baseline's units
//! (millimetres for Middlebury). A pixel without a valid disparity, or with d + doffs ≤ 0 (at or beyond
//! infinity), has no depth: `inf` in the depth map, no point in the cloud.

use std::path::Path;

use crate::error::{Error, Result};
use crate::image::{DisparityMap, Plane, RgbImage};
use crate::io::calib::Calib;

/// The left camera and the rig, as far as depth needs them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Focal length in pixels.
    pub focal: f64,
    /// Principal point, pixels.
    pub cx: f64,
    /// Principal point, pixels.
    pub cy: f64,
    /// Distance between the camera centres (its unit is the output's unit).
    pub baseline: f64,
    /// x-difference of the principal points, in pixels (0 for rectified pairs that share it).
    pub doffs: f64,
    /// Points farther than this have no depth (`inf` in the depth map, no point in the cloud); `f64::INFINITY`
    /// keeps every one. [`Camera::resolve`] defaults it to [`Camera::one_pixel_depth`].
    pub max_depth: f64,
}

/// Values given on the command line, each overriding `calib.txt`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraOverrides {
    /// Focal length in pixels.
    pub focal: Option<f64>,
    /// Principal point x.
    pub cx: Option<f64>,
    /// Principal point y.
    pub cy: Option<f64>,
    /// Baseline.
    pub baseline: Option<f64>,
    /// Principal point offset.
    pub doffs: Option<f64>,
    /// The farthest depth kept.
    pub max_depth: Option<f64>,
}

/// Whether a depth of `v` fits a 32-bit float (what depth maps and clouds hold): f·B, the depth of a one-pixel
/// disparity, beyond it would make every depth `inf` and the cloud empty.
pub fn fits_f32(v: f64) -> bool {
    v.is_finite() && v.abs() <= f64::from(f32::MAX)
}

impl CameraOverrides {
    /// The values given on the command line checked, each invalid one named by its flag, all in one message: a
    /// finite number, the focal length, the baseline and the maximum depth positive (an infinite maximum depth
    /// keeps every depth).
    ///
    /// # Errors
    /// [`Error::Argument`] naming every invalid flag and its value.
    pub fn check(&self) -> Result<()> {
        let values = [
            ("--focal", self.focal, true),
            ("--baseline", self.baseline, true),
            ("--cx", self.cx, false),
            ("--cy", self.cy, false),
            ("--doffs", self.doffs, false),
        ];
        let mut invalid: Vec<String> = values
            .iter()
            .filter_map(|&(flag, value, positive)| {
                let v = value?;
                let ok = v.is_finite() && (!positive || v > 0.0);
                (!ok).then(|| format!("{flag} {v} (expected a finite number{})", if positive { " > 0" } else { "" }))
            })
            .collect();
        if let Some(z) = self.max_depth
            && z.is_nan() | (z <= 0.0)
        {
            invalid.push(format!("--max-depth {z} (expected a depth > 0)"));
        }
        if invalid.is_empty() {
            return Ok(());
        }
        Err(Error::argument(format!("invalid {}", invalid.join(", "))))
    }
}

/// The 3 × 3 matrix of a `cam0=[f 0 cx; 0 f cy; 0 0 1]` value, row-major.
fn matrix(text: &str) -> Option<[f64; 9]> {
    let inner = text.trim().strip_prefix('[')?.strip_suffix(']')?;
    let values: Vec<f64> = inner
        .split([';', ' ', '\t', ','])
        .filter(|s| !s.is_empty())
        .map(str::parse)
        .collect::<std::result::Result<_, _>>()
        .ok()?;
    values.try_into().ok()
}

impl Camera {
    /// The camera from `calib` (`cam0`, `baseline`, `doffs`, read from `calib_path`; `None` when there is no such
    /// file) and `overrides`, which win. Depth needs the focal length and the baseline only; a point cloud also
    /// needs the principal point (`with_principal_point`; without it cx and cy are 0 and only the depth is
    /// meaningful). `doffs` defaults to 0.
    ///
    /// # Errors
    /// [`Error::Argument`] naming the flags of invalid values given on the command line
    /// ([`CameraOverrides::check`]); else one error naming every value missing or invalid at once, the file read
    /// (or that none was found at `calib_path`) and the flags that give them: [`Error::Calib`] when the file
    /// exists, [`Error::Argument`] when not; [`Error::Argument`] when f·B is beyond 32-bit floats ([`fits_f32`]).
    pub fn resolve(
        calib: Option<&Calib>,
        calib_path: &Path,
        overrides: &CameraOverrides,
        with_principal_point: bool,
    ) -> Result<Camera> {
        overrides.check()?;
        let cam0 = calib.and_then(|c| c.get("cam0")).and_then(matrix);
        let key = |k: &str| calib.and_then(|c| c.get(k)).and_then(|v| v.trim().parse::<f64>().ok());
        let mut missing: Vec<(&str, &str)> = Vec::new();
        let mut invalid: Vec<String> = Vec::new();
        let mut pick = |given: Option<f64>, from_calib: Option<f64>, what: &'static str, flag: &'static str| {
            let v = given.or(from_calib);
            match v {
                None => missing.push((what, flag)),
                Some(v) if !v.is_finite() => invalid.push(format!("{what} {v} (expected a finite number)")),
                Some(_) => {}
            }
            v.unwrap_or(0.0)
        };
        let focal = pick(overrides.focal, cam0.map(|m| m[0]), "focal length (cam0)", "--focal");
        let baseline = pick(overrides.baseline, key("baseline"), "baseline", "--baseline");
        let (cx, cy) = if with_principal_point {
            (
                pick(overrides.cx, cam0.map(|m| m[2]), "principal point x (cam0)", "--cx"),
                pick(overrides.cy, cam0.map(|m| m[5]), "principal point y (cam0)", "--cy"),
            )
        } else {
            (0.0, 0.0)
        };
        let doffs = overrides.doffs.or(key("doffs")).unwrap_or(0.0);
        if !doffs.is_finite() {
            invalid.push(format!("doffs {doffs} (expected a finite number)"));
        }
        for (name, v) in [("focal length", focal), ("baseline", baseline)] {
            if v.is_finite() && v <= 0.0 && !missing.iter().any(|(w, _)| w.starts_with(name)) {
                invalid.push(format!("{name} {v} (expected > 0)"));
            }
        }
        let purpose = if with_principal_point { "a point cloud" } else { "depth" };
        if !missing.is_empty() || !invalid.is_empty() {
            let mut parts = Vec::new();
            if !missing.is_empty() {
                let what: Vec<&str> = missing.iter().map(|(w, _)| *w).collect();
                let flags: Vec<&str> = missing.iter().map(|(_, f)| *f).collect();
                parts.push(format!("{purpose} needs the {} (give {})", what.join(", "), flags.join(", ")));
            }
            if !invalid.is_empty() {
                parts.push(format!("invalid {}", invalid.join(", ")));
            }
            let msg = parts.join("; ");
            return Err(match calib {
                Some(_) => Error::Calib { path: calib_path.to_path_buf(), msg: format!("{msg} (read from this file)") },
                None => Error::argument(format!("{msg}: no {} was found", calib_path.display())),
            });
        }
        let max_depth = overrides.max_depth.unwrap_or(focal * baseline);
        let camera = Camera { focal, cx, cy, baseline, doffs, max_depth };
        if !fits_f32(camera.focal * camera.baseline) {
            return Err(Error::argument(format!(
                "focal length {:?} times baseline {:?} is beyond 32-bit floats: no depth f·B / d could be written; \
                 check {}'s cam0 and baseline (or --focal, --baseline)",
                camera.focal,
                camera.baseline,
                calib_path.display()
            )));
        }
        Ok(camera)
    }

    /// The depth of a disparity of one pixel, f·B: the default farthest depth. Beyond it a disparity error of
    /// half a pixel (what matching leaves) more than doubles the depth, and the sky, whose disparity is about 0,
    /// would be put thousands of kilometres away.
    pub fn one_pixel_depth(&self) -> f64 {
        self.focal * self.baseline
    }

    /// Depth of disparity `d`, or `None` (invalid, at or beyond infinity, or beyond [`Camera::max_depth`]).
    pub fn depth(&self, d: f32) -> Option<f64> {
        let denom = f64::from(d) + self.doffs;
        (d.is_finite() && denom > 0.0).then(|| self.focal * self.baseline / denom).filter(|&z| z <= self.max_depth)
    }

    /// The point (X, Y, Z) of pixel (`x`, `y`) with disparity `d` as written (`f32`), or `None` when it has no depth
    /// or one of its coordinates is beyond `f32` (absurd but finite camera values): the depth map and the cloud
    /// both use it, so a pixel has a finite depth exactly when it has a point.
    pub fn point(&self, x: usize, y: usize, d: f32) -> Option<[f32; 3]> {
        let z = self.depth(d)?;
        let p = [(x as f64 - self.cx) * z / self.focal, (y as f64 - self.cy) * z / self.focal, z].map(|v| v as f32);
        p.iter().all(|v| v.is_finite()).then_some(p)
    }
}

/// The depth map of a disparity map (`inf` where there is none, as where the cloud has no point).
pub fn depth_map(disparity: &DisparityMap, camera: &Camera) -> Plane<f32> {
    let w = disparity.width;
    let data = disparity
        .data
        .iter()
        .enumerate()
        .map(|(i, &d)| camera.point(i % w, i / w, d).map_or(f32::INFINITY, |p| p[2]))
        .collect();
    Plane::from_parts(disparity.width, disparity.height, data)
}

/// The points of the pixels with a depth ([`Camera::point`]), in row-major pixel order, and their colours: what
/// [`encode_ply`] writes (and `jem --cloud`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// (X, Y, Z) in the left camera's frame, in the baseline's unit.
    pub points: Vec<[f32; 3]>,
    /// Each point's colour: its pixel in the image, rounded to 8 bits.
    pub colours: Vec<[u8; 3]>,
}

impl PointCloud {
    /// The cloud as a binary little-endian PLY: `x y z` (float) and `red green blue` (uchar).
    pub fn to_ply(&self) -> Vec<u8> {
        let mut out = ply_header(self.points.len());
        for (p, c) in self.points.iter().zip(&self.colours) {
            push_vertex(&mut out, p, c);
        }
        out
    }
}

/// A PLY's header for `points` vertices, in a buffer with room for them.
fn ply_header(points: usize) -> Vec<u8> {
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment jem: left camera frame, baseline units\n\
         element vertex {points}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\n\
         property uchar green\nproperty uchar blue\nend_header\n"
    );
    let mut out = Vec::with_capacity(header.len() + points * 15);
    out.extend_from_slice(header.as_bytes());
    out
}

/// One vertex of a PLY: the point's three floats and its colour.
fn push_vertex(out: &mut Vec<u8>, point: &[f32; 3], colour: &[u8; 3]) {
    for v in point {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(colour);
}

/// The colour of pixel `i` of `image`, rounded to 8 bits.
fn colour(image: &RgbImage, i: usize) -> [u8; 3] {
    image.rgb(i).map(|c| c.round().clamp(0.0, 255.0) as u8)
}

/// The point cloud of the pixels with a depth, coloured from `image`.
///
/// # Panics
/// If `image` and `disparity` differ in size.
pub fn point_cloud(disparity: &DisparityMap, image: &RgbImage, camera: &Camera) -> PointCloud {
    assert_eq!(disparity.dims(), image.dims(), "image and disparity map differ in size");
    let w = disparity.width;
    // Counted first, so that the vectors hold their points exactly (grown, they held up to twice as many).
    let n = disparity.data.iter().enumerate().filter(|&(i, &d)| camera.point(i % w, i / w, d).is_some()).count();
    let mut cloud = PointCloud { points: Vec::with_capacity(n), colours: Vec::with_capacity(n) };
    for (i, &d) in disparity.data.iter().enumerate() {
        if let Some(p) = camera.point(i % w, i / w, d) {
            cloud.points.push(p);
            cloud.colours.push(colour(image, i));
        }
    }
    cloud
}

/// A binary little-endian PLY of the pixels with a depth ([`point_cloud`], [`PointCloud::to_ply`]).
///
/// # Panics
/// If `image` and `disparity` differ in size.
pub fn encode_ply(disparity: &DisparityMap, image: &RgbImage, camera: &Camera) -> Vec<u8> {
    assert_eq!(disparity.dims(), image.dims(), "image and disparity map differ in size");
    // The bytes of `point_cloud(..).to_ply()`, written straight into a buffer of the file's size: the cloud's
    // growing vectors held up to twice their points beside the file (a downscaled run's peak at full size).
    let w = disparity.width;
    let points = || disparity.data.iter().enumerate().filter_map(|(i, &d)| Some((i, camera.point(i % w, i / w, d)?)));
    let mut out = ply_header(points().count());
    for (i, p) in points() {
        push_vertex(&mut out, &p, &colour(image, i));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera { focal: 500.0, cx: 2.0, cy: 1.0, baseline: 100.0, doffs: 5.0, max_depth: f64::INFINITY }
    }

    #[test]
    fn camera_from_calib_and_overrides() {
        let calib =
            Calib::parse("cam0=[1746.24 0 14.88; 0 1746.24 65.5; 0 0 1]\nbaseline=178.089\ndoffs=2.5\n").unwrap();
        let path = Path::new("scene/calib.txt");
        let c = Camera::resolve(Some(&calib), path, &CameraOverrides::default(), true).unwrap();
        assert_eq!((c.focal, c.cx, c.cy, c.baseline, c.doffs), (1746.24, 14.88, 65.5, 178.089, 2.5));
        let o = CameraOverrides { baseline: Some(50.0), ..Default::default() };
        assert_eq!(Camera::resolve(Some(&calib), path, &o, true).unwrap().baseline, 50.0);
        let no_baseline = Calib::parse("cam0=[1 0 0; 0 1 0; 0 0 1]\n").unwrap();
        let e = Camera::resolve(Some(&no_baseline), path, &CameraOverrides::default(), false).unwrap_err().to_string();
        assert_eq!(e, "scene/calib.txt: depth needs the baseline (give --baseline) (read from this file)");
        let bad = CameraOverrides { focal: Some(-1.0), baseline: Some(1.0), ..Default::default() };
        assert!(Camera::resolve(None, path, &bad, true).is_err());
    }

    /// A focal length times baseline that overflows is refused; absurd values whose products
    /// stay finite give no non-finite point, and `inf` depth exactly where there is no point.
    #[test]
    fn overflowing_geometry_writes_no_infinite_point() {
        let huge = CameraOverrides {
            focal: Some(1e300),
            cx: Some(0.0),
            cy: Some(0.0),
            baseline: Some(1e300),
            ..Default::default()
        };
        let e = Camera::resolve(None, Path::new("calib.txt"), &huge, true).unwrap_err().to_string();
        assert!(e.contains("beyond 32-bit floats") && e.contains("baseline"), "{e}");
        let c = Camera { focal: 1e30, cx: 1.0, cy: 0.5, baseline: 1e30, doffs: 0.0, max_depth: f64::INFINITY };
        let disp = Plane::from_parts(3, 2, vec![1.0, 2.0, 3.0, 1e32, 2e32, f32::INFINITY]);
        let depth = depth_map(&disp, &c);
        let ply = encode_ply(&disp, &RgbImage::new(3, 2), &c);
        let end = b"end_header\n";
        let at = ply.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let body = &ply[at..];
        let floats: Vec<f32> = body
            .chunks(15)
            .flat_map(|p| p[..12].chunks(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())))
            .collect();
        assert!(floats.iter().all(|v| v.is_finite()), "{floats:?}");
        let with_depth = depth.data.iter().filter(|z| z.is_finite()).count();
        assert_eq!((body.len() / 15, with_depth), (2, 2), "{:?}", depth.data);
    }

    /// Everything missing is named in one message, with the flags that give it and where calib.txt was looked
    /// for; depth does not ask for the principal point.
    #[test]
    fn every_missing_value_is_named_at_once_and_depth_needs_no_principal_point() {
        let path = Path::new("pair/calib.txt");
        let none = CameraOverrides::default();
        let e = Camera::resolve(None, path, &none, true).unwrap_err().to_string();
        assert_eq!(
            e,
            "a point cloud needs the focal length (cam0), baseline, principal point x (cam0), principal point y \
             (cam0) (give --focal, --baseline, --cx, --cy): no pair/calib.txt was found"
        );
        let e = Camera::resolve(None, path, &none, false).unwrap_err().to_string();
        assert_eq!(
            e,
            "depth needs the focal length (cam0), baseline (give --focal, --baseline): no pair/calib.txt was found"
        );
        let given = CameraOverrides { focal: Some(500.0), baseline: Some(0.1), ..Default::default() };
        let c = Camera::resolve(None, path, &given, false).unwrap();
        assert_eq!((c.focal, c.baseline, c.doffs), (500.0, 0.1, 0.0));
        let both_bad = CameraOverrides { focal: Some(0.0), baseline: Some(-2.0), ..Default::default() };
        let e = Camera::resolve(None, path, &both_bad, false).unwrap_err().to_string();
        assert_eq!(e, "invalid --focal 0 (expected a finite number > 0), --baseline -2 (expected a finite number > 0)");
    }

    /// By default a point is kept up to the depth of a one-pixel disparity (the sky, at about 0, is left out);
    /// `max_depth` sets the range.
    #[test]
    fn depth_stops_at_one_pixel_of_disparity_unless_told_otherwise() {
        let given = CameraOverrides { focal: Some(500.0), baseline: Some(0.2), ..Default::default() };
        let c = Camera::resolve(None, Path::new("calib.txt"), &given, false).unwrap();
        assert_eq!(c.max_depth, 100.0);
        let disp = Plane::from_parts(4, 1, vec![0.001, 0.5, 1.0, 10.0]);
        assert_eq!(depth_map(&disp, &c).data, vec![f32::INFINITY, f32::INFINITY, 100.0, 10.0]);
        let near = CameraOverrides { max_depth: Some(20.0), ..given };
        let c = Camera::resolve(None, Path::new("calib.txt"), &near, false).unwrap();
        assert_eq!(depth_map(&disp, &c).data, vec![f32::INFINITY, f32::INFINITY, f32::INFINITY, 10.0]);
        let bad = CameraOverrides { max_depth: Some(-1.0), ..given };
        assert!(
            Camera::resolve(None, Path::new("calib.txt"), &bad, false)
                .unwrap_err()
                .to_string()
                .contains("--max-depth -1 (expected a depth > 0)")
        );
    }

    /// A value given by a flag that cannot be used is blamed on the flag, not on the calib.txt read beside it
    /// (`--max-depth NaN` was "calib.txt: invalid maximum depth NaN (read from this file)"); a focal length times
    /// baseline beyond 32-bit floats, finite in 64 bits, is refused (every depth was `inf`, the cloud empty).
    #[test]
    fn flags_are_blamed_for_their_values_and_a_depth_beyond_f32_is_refused() {
        let calib = Calib::parse("cam0=[500 0 10; 0 500 8; 0 0 1]\nbaseline=100\n").unwrap();
        let path = Path::new("scene/calib.txt");
        for (overrides, flag) in [
            (CameraOverrides { max_depth: Some(f64::NAN), ..Default::default() }, "--max-depth NaN"),
            (CameraOverrides { focal: Some(f64::INFINITY), ..Default::default() }, "--focal inf"),
            (CameraOverrides { doffs: Some(f64::NAN), ..Default::default() }, "--doffs NaN"),
        ] {
            let e = Camera::resolve(Some(&calib), path, &overrides, true).unwrap_err().to_string();
            assert!(e.starts_with("invalid ") && e.contains(flag) && !e.contains("calib.txt"), "{e}");
        }
        let far = CameraOverrides { focal: Some(1e20), baseline: Some(1e20), ..Default::default() };
        let e = Camera::resolve(Some(&calib), path, &far, true).unwrap_err().to_string();
        assert!(e.contains("beyond 32-bit floats"), "{e}");
        let near = CameraOverrides { focal: Some(1e18), baseline: Some(1e20), ..Default::default() };
        assert!(Camera::resolve(Some(&calib), path, &near, true).is_ok());
    }

    /// Depth and points follow Z = f·B / (d + doffs), X = (x − cx)·Z / f, Y = (y − cy)·Z / f; invalid pixels and
    /// d + doffs ≤ 0 give neither.
    #[test]
    fn depth_and_points_follow_the_camera_model() {
        let c = camera();
        let disp = Plane::from_parts(4, 2, vec![45.0, f32::INFINITY, 95.0, -5.0, 20.0, 45.0, f32::NAN, 0.0]);
        let depth = depth_map(&disp, &c);
        assert_eq!(depth.data[0], 1000.0);
        assert_eq!(depth.data[2], 500.0);
        assert_eq!(depth.data[7], 10_000.0);
        for i in [1, 3, 6] {
            assert!(depth.data[i].is_infinite(), "pixel {i}");
        }
        let mut img = RgbImage::new(4, 2);
        img.channels[0][4] = 200.0;
        let ply = encode_ply(&disp, &img, &c);
        let end = b"end_header\n";
        let at = ply.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&ply[..at]).unwrap();
        assert!(header.contains("element vertex 5\n") && header.starts_with("ply\nformat binary_little_endian"));
        let body = &ply[at..];
        assert_eq!(body.len(), 5 * 15);
        let f = |k: usize, j: usize| f32::from_le_bytes(body[k * 15 + 4 * j..k * 15 + 4 * j + 4].try_into().unwrap());
        // Points in pixel order: 0, 2, 4, 5, 7. Pixel 4 = (0, 1), d 20: Z = 2000, X = −2·2000/500, Y = 0.
        assert_eq!((f(0, 0), f(0, 1), f(0, 2)), (-4.0, -2.0, 1000.0));
        assert_eq!((f(2, 0), f(2, 1), f(2, 2)), (-8.0, 0.0, 2000.0));
        assert_eq!(&body[2 * 15 + 12..2 * 15 + 15], &[200, 0, 0]);
        assert_eq!(ply, point_cloud(&disp, &img, &c).to_ply(), "the file is the cloud's PLY");
    }
}
