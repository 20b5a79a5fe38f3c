//! The rectification end to end: a rig made here (two cameras with lens distortion, the right one turned and
//! shifted), points of a scene projected through it, found again in the rectified views.

use super::linalg::{Vec3, inverse, mul, mul_vec, rotation_from_vector};
use super::*;

pub(super) fn rig() -> StereoCalibration {
    StereoCalibration {
        path: PathBuf::from("rig.yml"),
        cameras: [
            Intrinsics {
                matrix: [[702.0, 0.0, 318.5], [0.0, 698.0, 243.0], [0.0, 0.0, 1.0]],
                distortion: [-0.21, 0.09, 0.0012, -0.0007, -0.015, 0.0, 0.0, 0.0],
            },
            Intrinsics {
                matrix: [[690.0, 0.0, 326.0], [0.0, 693.5, 236.5], [0.0, 0.0, 1.0]],
                distortion: [-0.18, 0.06, -0.0009, 0.0011, 0.01, 0.0, 0.0, 0.0],
            },
        ],
        rotation: rotation_from_vector(&[0.012, -0.031, 0.0075]),
        translation: [-0.12, 0.0035, -0.0021],
        image_size: Some((640, 480)),
        given: None,
        prerectified: None,
    }
}

/// The rectified position whose map value is the raw pixel (u, v): Newton's method on the map function.
fn rectified_position(rect: &Rectification, view: View, (u, v): (f64, f64)) -> (f64, f64) {
    let (camera, r, p) = match view {
        View::Left => (&rect.cameras[0], &rect.transforms.r1, &rect.transforms.p1),
        View::Right => (&rect.cameras[1], &rect.transforms.r2, &rect.transforms.p2),
    };
    let p3: Mat3 = [0, 1, 2].map(|i| [p[i][0], p[i][1], p[i][2]]);
    let ir = inverse(&mul(&p3, r)).unwrap();
    let f = |x: f64, y: f64| maps::source_position(camera, &ir, x, y);
    let (mut x, mut y) = (u, v);
    for _ in 0..30 {
        let (fu, fv) = f(x, y);
        let h = 1e-4;
        let ((ax, ay), (bx, by)) = (f(x + h, y), f(x, y + h));
        let j = [[(ax - fu) / h, (bx - fu) / h], [(ay - fv) / h, (by - fv) / h]];
        let d = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        let (ru, rv) = (fu - u, fv - v);
        x -= (j[1][1] * ru - j[0][1] * rv) / d;
        y -= (-j[1][0] * ru + j[0][0] * rv) / d;
    }
    (x, y)
}

/// A corner of the scene seen by a camera at X_cam = rot·X + t: the raw pixel its lens puts it on.
fn raw_pixel(camera: &Intrinsics, rot: &Mat3, t: &Vec3, point: &Vec3) -> (f64, f64) {
    let p = mul_vec(rot, point);
    let p = [p[0] + t[0], p[1] + t[1], p[2] + t[2]];
    camera.distort(p[0] / p[2], p[1] / p[2])
}

#[test]
fn rectified_corners_lie_on_the_same_row_in_both_views() {
    let calib = rig();
    let rect = calib.rectification((640, 480)).unwrap();
    let mut worst: f64 = 0.0;
    let mut seen = 0;
    // The corners of a checkerboard on a slanted plane, 1.5 to 4 m away.
    for i in -6..=6 {
        for j in -4..=4 {
            let (x, y) = (f64::from(i) * 0.1, f64::from(j) * 0.1);
            let corner = [x, y, 2.0 + 0.3 * x + 0.2 * y];
            let left = raw_pixel(&calib.cameras[0], &linalg::IDENTITY, &[0.0; 3], &corner);
            let right = raw_pixel(&calib.cameras[1], &calib.rotation, &calib.translation, &corner);
            let inside = |(u, v): (f64, f64)| (0.0..639.0).contains(&u) && (0.0..479.0).contains(&v);
            if !(inside(left) && inside(right)) {
                continue;
            }
            let (xl, yl) = rectified_position(&rect, View::Left, left);
            let (xr, yr) = rectified_position(&rect, View::Right, right);
            worst = worst.max((yl - yr).abs());
            // The disparity is the depth's: f·B / Z in the rectified frame.
            let z = mul_vec(&rect.transforms.r1, &corner)[2];
            assert!((xl - xr - rect.focal_px() * rect.baseline() / z).abs() < 0.01, "{corner:?}");
            seen += 1;
        }
    }
    assert!(seen > 50, "only {seen} corners in view");
    assert!(worst < 0.05, "rectified rows differ by up to {worst} px");
}

#[test]
fn the_rectified_views_keep_only_valid_pixels() {
    // alpha = 0: every rectified pixel comes from inside both original images.
    let rect = rig().rectification((640, 480)).unwrap();
    for view in [View::Left, View::Right] {
        let (mx, my) = rect.maps(view);
        let inside = mx
            .data()
            .iter()
            .zip(my.data())
            .filter(|&(&x, &y)| (-0.5..639.5).contains(&x) && (-0.5..479.5).contains(&y));
        assert_eq!(inside.count(), 640 * 480, "{view:?}");
    }
}

#[test]
fn the_calib_txt_describes_the_rectified_camera() {
    let rect = rig().rectification((640, 480)).unwrap();
    let calib = crate::io::calib::Calib::parse(&rect.calib_txt()).unwrap();
    let camera =
        crate::geometry::Camera::resolve(Some(&calib), Path::new("calib.txt"), &Default::default(), true).unwrap();
    assert!((camera.focal - rect.focal_px()).abs() < 1e-5 && (camera.baseline - 0.12009).abs() < 1e-4);
    assert_eq!((calib.get("width"), calib.get("height"), calib.get("doffs")), (Some("640"), Some("480"), Some("0")));
}

#[test]
fn a_wrong_size_a_vertical_rig_and_a_right_camera_on_the_left_are_refused() {
    let e = rig().rectification((320, 240)).unwrap_err().to_string();
    assert!(e.contains("rig.yml") && e.contains("640x480") && e.contains("320x240"), "{e}");
    let vertical = StereoCalibration { translation: [0.001, -0.1, 0.0], ..rig() };
    assert!(vertical.rectification((640, 480)).unwrap_err().to_string().contains("one above the other"));
    let swapped = StereoCalibration { translation: [0.12, 0.0, 0.0], ..rig() };
    assert!(swapped.rectification((640, 480)).unwrap_err().to_string().contains("other way round"));
}

#[test]
fn kitti_views_of_the_rectified_size_are_taken_as_they_are() {
    let text = "calib_time: 09-Jan-2012 13:57:47\nS_02: 1.392000e+03 5.120000e+02\n\
        K_02: 9.597910e+02 0.000000e+00 6.960217e+02 0.000000e+00 9.569251e+02 2.241806e+02 0 0 1\n\
        D_02: -3.691481e-01 1.968681e-01 1.353473e-03 5.677587e-04 -6.770705e-02\n\
        R_02: 9.999758e-01 -5.267463e-03 -4.552439e-03 5.251945e-03 9.999804e-01 -3.413835e-03 4.570332e-03 \
        3.389843e-03 9.999838e-01\nT_02: 5.956621e-02 2.900141e-04 2.577209e-03\n\
        S_rect_02: 1.242000e+03 3.750000e+02\n\
        P_rect_02: 7.215377e+02 0 6.095593e+02 4.485728e+01 0 7.215377e+02 1.728540e+02 2.163791e-01 0 0 1 2.745884e-03\n\
        S_03: 1.392000e+03 5.120000e+02\n\
        K_03: 9.037596e+02 0.000000e+00 6.957519e+02 0.000000e+00 9.019653e+02 2.242509e+02 0 0 1\n\
        D_03: -3.639558e-01 1.788651e-01 6.029694e-04 -3.922424e-04 -5.382460e-02\n\
        R_03: 9.995599e-01 1.699522e-02 -2.431313e-02 -1.704422e-02 9.998531e-01 -1.809756e-03 2.427880e-02 \
        2.223358e-03 9.997028e-01\nT_03: -4.731050e-01 5.551470e-03 -5.250882e-03\n\
        P_rect_03: 7.215377e+02 0 6.095593e+02 -3.395242e+02 0 7.215377e+02 1.728540e+02 2.199936e+00 0 0 1 2.729905e-03\n";
    let calib = StereoCalibration::parse(text, Path::new("calib_cam_to_cam.txt")).unwrap();
    let rect = calib.rectification((1242, 375)).unwrap();
    assert!((rect.baseline() - 0.5327).abs() < 1e-3, "{}", rect.baseline());
    let (mx, my) = rect.maps(View::Right);
    assert!((mx.at(100, 50) - 100.0).abs() < 1e-3 && (my.at(100, 50) - 50.0).abs() < 1e-3);
    // The raw views are rectified from K, D, R, T: a baseline of about 0.53 m too.
    let raw = calib.rectification((1392, 512)).unwrap();
    assert!((raw.baseline() - 0.5327).abs() < 5e-3, "{}", raw.baseline());
}

#[test]
fn calibration_files_name_every_missing_value_at_once() {
    let e = StereoCalibration::parse("%YAML:1.0\n---\nimage_width: 640\n", Path::new("cam.yml")).unwrap_err();
    let msg = e.to_string();
    assert!(msg.starts_with("cam.yml: missing K1/M1/cameraMatrix1, D1/distCoeffs1, K2/M2/cameraMatrix2"), "{msg}");
    assert!(msg.contains(", R, T"), "{msg}");
    let e = StereoCalibration::parse("width=3\n", Path::new("calib.txt")).unwrap_err().to_string();
    assert!(e.contains("neither an OpenCV FileStorage"), "{e}");
}

/// The raw image's outline (a 9 × 9 grid's border), each point's rectified position in `view`.
fn rectified_outline(rect: &Rectification, view: View) -> Vec<(f64, f64)> {
    let steps = (0..=8).map(|k| f64::from(k) / 8.0);
    let border: Vec<(f64, f64)> = steps
        .clone()
        .flat_map(|t| [(t * 639.0, 0.0), (t * 639.0, 479.0), (0.0, t * 479.0), (639.0, t * 479.0)])
        .collect();
    border.into_iter().map(|p| rectified_position(rect, view, p)).collect()
}

#[test]
fn alpha_one_keeps_every_source_pixel_and_alpha_zero_only_valid_ones() {
    let calib = rig();
    let keep_all = calib.rectification_with_alpha((640, 480), Some(1.0)).unwrap();
    let crop = calib.rectification_with_alpha((640, 480), Some(0.0)).unwrap();
    assert_eq!(crop, calib.rectification((640, 480)).unwrap(), "alpha 0 is the default rectification");
    let inside = |&(x, y): &(f64, f64)| (-0.5..639.5).contains(&x) && (-0.5..479.5).contains(&y);
    for view in [View::Left, View::Right] {
        // alpha = 1: the whole raw outline lands in the rectified image; alpha = 0: parts of it lie outside.
        let outline = rectified_outline(&keep_all, view);
        assert!(outline.iter().all(inside), "{view:?}: {outline:?}");
        assert!(!rectified_outline(&crop, view).iter().all(inside), "{view:?}");
    }
    let half = calib.rectification_with_alpha((640, 480), Some(0.5)).unwrap();
    assert!(keep_all.focal_px() < half.focal_px() && half.focal_px() < crop.focal_px());
    // The valid pixels fill the cropped views, and only part of those that keep everything.
    for (c, k) in crop.valid_rois().into_iter().zip(keep_all.valid_rois()) {
        assert!(c.2 >= 636 && c.3 >= 476, "{c:?}");
        assert!(k.0 > 0 && k.1 > 0 && k.2 < 620 && k.3 < 460 && k.2 > 400 && k.3 > 300, "{k:?}");
    }
}

#[test]
fn an_alpha_out_of_range_or_for_a_given_rectification_is_refused() {
    for alpha in [-0.1, 1.5, f64::NAN] {
        let e = rig().rectification_with_alpha((640, 480), Some(alpha)).unwrap_err().to_string();
        assert!(e.contains("alpha") && e.contains("0..=1"), "{e}");
    }
    let mut saved = rig();
    saved.given = Some(*saved.rectification((640, 480)).unwrap().transforms());
    let e = saved.rectification_with_alpha((640, 480), Some(0.5)).unwrap_err().to_string();
    assert!(e.starts_with("rig.yml: the file holds its own rectification"), "{e}");
    assert!(saved.rectification_with_alpha((640, 480), None).is_ok());
}

#[test]
fn a_valid_rectangle_is_rounded_inwards_and_held_to_the_image_as_opencv_does() {
    // (⌈x0⌉, ⌈y0⌉, ⌊x1 − x0⌋, ⌊y1 − y0⌋), then cut to the image: x 1..640, y 0..470.
    assert_eq!(pixel_rectangle([0.2, -3.0, 639.9, 470.5], (640, 480)), (1, 0, 639, 470));
    assert_eq!(pixel_rectangle([10.0, 20.0, 30.5, 40.0], (640, 480)), (10, 20, 20, 20));
    assert_eq!(pixel_rectangle([700.0, 20.0, 800.0, 40.0], (640, 480)), (0, 0, 0, 0), "outside the image");
    assert_eq!(pixel_rectangle([f64::NAN, 0.0, 10.0, 10.0], (640, 480)), (0, 0, 0, 0), "no valid pixel left");
}
