//! Your own camera from the command line: `jem rectify` and `jem match --rectify` with a stereo calibration, and
//! the camera values `--depth` and `--cloud` need, asked for all at once.

mod common;

use std::path::Path;

use common::{files_in, run_in, stderr};

/// An OpenCV FileStorage YAML of a rig of two pinhole cameras (no distortion, no rotation), the right one `b` to
/// the right, with the principal point at the centre of `w × h` images.
fn pinhole_rig_yaml(w: usize, h: usize, b: f64) -> String {
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let k = format!("[ 80., 0., {cx}, 0., 80., {cy}, 0., 0., 1. ]");
    let m = |name: &str, rows: usize, cols: usize, data: &str| {
        format!("{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: {data}\n")
    };
    format!(
        "%YAML:1.0\n---\n{}{}{}{}{}{}image_width: {w}\nimage_height: {h}\n",
        m("K1", 3, 3, &k),
        m("D1", 1, 5, "[ 0., 0., 0., 0., 0. ]"),
        m("K2", 3, 3, &k),
        m("D2", 1, 5, "[ 0., 0., 0., 0., 0. ]"),
        m("R", 3, 3, "[ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]"),
        m("T", 3, 1, &format!("[ {}, 0., 0. ]", -b)),
    )
}

fn synth_scene(dir: &Path, name: &str) {
    let out = run_in(dir, &["synth", name, "--width", "64", "--height", "48", "--ndisp", "16"]);
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn rectify_writes_the_pair_and_its_calib_txt() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    std::fs::write(dir.path().join("rig.yml"), pinhole_rig_yaml(64, 48, 0.25)).unwrap();
    let out = run_in(dir.path(), &["rectify", "rig.yml", "S/im0.png", "S/im1.png", "-o", "R"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(files_in(&dir.path().join("R")), ["calib.txt", "im0.png", "im1.png", "rectify.yml"]);
    // The rectification for OpenCV: an ideal rig keeps its cameras; Q's last row is 1 / baseline.
    let yml = std::fs::read_to_string(dir.path().join("R/rectify.yml")).unwrap();
    assert!(yml.starts_with("%YAML:1.0\n---\nimage_width: 64\nimage_height: 48\nR1: !!opencv-matrix\n"), "{yml}");
    assert!(
        yml.contains("P1: !!opencv-matrix\n   rows: 3\n   cols: 4\n   dt: d\n   data: [ 80.0, 0.0, 31.5, 0.0,"),
        "{yml}"
    );
    assert!(
        yml.contains("Q: !!opencv-matrix\n   rows: 4\n   cols: 4\n") && yml.contains("0.0, 0.0, 4.0, -0.0 ]"),
        "{yml}"
    );
    // An ideal rig: the rectified views are the views.
    for name in ["im0.png", "im1.png"] {
        let (a, b) = (
            jem::io::read_image(&dir.path().join("S").join(name)).unwrap(),
            jem::io::read_image(&dir.path().join("R").join(name)).unwrap(),
        );
        assert_eq!(a, b, "{name}");
    }
    let calib = std::fs::read_to_string(dir.path().join("R/calib.txt")).unwrap();
    assert_eq!(
        calib,
        "cam0=[80 0 31.5; 0 80 23.5; 0 0 1]\ncam1=[80 0 31.5; 0 80 23.5; 0 0 1]\ndoffs=0\nbaseline=0.25\nwidth=64\nheight=48\n"
    );
}

#[test]
fn match_with_rectify_writes_depth_from_the_rectified_camera() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    std::fs::write(dir.path().join("rig.yml"), pinhole_rig_yaml(64, 48, 0.25)).unwrap();
    let args =
        ["S/im0.png", "S/im1.png", "--rectify", "rig.yml", "-o", "d.pfm", "--depth", "z.pfm", "--set", "model=wta"];
    let out = run_in(dir.path(), &args);
    assert!(out.status.success(), "{}", stderr(&out));
    let d = jem::io::read_disparity(&dir.path().join("d.pfm")).unwrap();
    let z = jem::io::read_disparity(&dir.path().join("z.pfm")).unwrap();
    let (i, &di) = d.data().iter().enumerate().find(|(_, v)| v.is_finite() && **v > 1.0).unwrap();
    assert!((z.data()[i] - 80.0 * 0.25 / di).abs() < 1e-4, "depth {} for disparity {di}", z.data()[i]);
}

#[test]
fn a_bad_calibration_is_one_error_naming_the_file_and_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    let cases: [(&str, String, &str); 4] = [
        ("empty.yml", "%YAML:1.0\n---\n".into(), "missing K1/M1/cameraMatrix1, D1/distCoeffs1, K2/M2/cameraMatrix2"),
        ("other.yml", pinhole_rig_yaml(640, 480, 0.25), "the calibration is for 640x480 images, these are 64x48"),
        ("swapped.yml", pinhole_rig_yaml(64, 48, -0.25), "other way round"),
        ("notes.txt", "hello\n".into(), "neither an OpenCV FileStorage"),
    ];
    for (name, text, needle) in cases {
        std::fs::write(dir.path().join(name), text).unwrap();
        let before = files_in(dir.path());
        for args in [
            vec!["rectify", name, "S/im0.png", "S/im1.png", "-o", "R"],
            vec!["S/im0.png", "S/im1.png", "--rectify", name, "-o", "d.pfm"],
        ] {
            let out = run_in(dir.path(), &args);
            let err = stderr(&out);
            assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
            assert!(err.starts_with(&format!("error: {name}: ")) && err.contains(needle), "{args:?}: {err}");
            assert_eq!(err.trim_end().lines().count(), 1, "{err}");
            assert_eq!(files_in(dir.path()), before, "{args:?} left files");
        }
    }
}

#[test]
fn depth_asks_for_everything_missing_at_once_and_names_where_it_looked() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    std::fs::remove_file(dir.path().join("S/calib.txt")).unwrap();
    let base = ["S/im0.png", "S/im1.png", "-o", "d.pfm", "--ndisp", "16", "--set", "model=wta"];
    let out = run_in(dir.path(), &[&base[..], &["--depth", "z.pfm"]].concat());
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(
        err.trim_end(),
        "error: depth needs the focal length (cam0), baseline (give --focal, --baseline): no S/calib.txt was found"
    );
    // Depth needs the focal length and the baseline only.
    let out = run_in(dir.path(), &[&base[..], &["--depth", "z.pfm", "--focal", "100", "--baseline", "0.1"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    // A calib.txt without them is named as the file read.
    std::fs::write(dir.path().join("S/calib.txt"), "ndisp=16\n").unwrap();
    let out = run_in(dir.path(), &[&base[..], &["--cloud", "c.ply"]].concat());
    let err = stderr(&out);
    assert!(
        err.starts_with("error: S/calib.txt: a point cloud needs the focal length (cam0), baseline, principal point x")
            && err.contains("(give --focal, --baseline, --cx, --cy) (read from this file)"),
        "{err}"
    );
}

#[test]
fn min_confidence_writes_only_the_reliable_pixels() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    let base = ["S/im0.png", "S/im1.png", "--confidence", "k.pfm"];
    let all = run_in(dir.path(), &[&base[..], &["-o", "all.pfm"]].concat());
    assert!(all.status.success(), "{}", stderr(&all));
    let some = run_in(dir.path(), &["S/im0.png", "S/im1.png", "-o", "some.pfm", "--min-confidence", "0.9"]);
    assert!(some.status.success(), "{}", stderr(&some));
    let read = |n: &str| jem::io::read_disparity(&dir.path().join(n)).unwrap();
    let (all, some, confidence) = (read("all.pfm"), read("some.pfm"), read("k.pfm"));
    let mut dropped = 0;
    for ((&a, &s), &c) in all.data().iter().zip(some.data()).zip(confidence.data()) {
        if c < 0.9 {
            assert!(s.is_infinite());
            dropped += 1;
        } else {
            assert_eq!(a.to_bits(), s.to_bits());
        }
    }
    assert!(dropped > 0 && dropped < all.data().len(), "{dropped} pixels dropped");
    for bad in ["1.5", "-0.1", "nan"] {
        let out = run_in(dir.path(), &["S/im0.png", "S/im1.png", "-o", "x.pfm", "--min-confidence", bad]);
        assert_eq!(out.status.code(), Some(2), "{bad}");
        assert!(stderr(&out).contains("--min-confidence"), "{}", stderr(&out));
    }
    let out = run_in(dir.path(), &["S/im0.png", "S/im1.png", "-o", "x.pfm", "--max-depth", "10"]);
    assert!(stderr(&out).contains("--max-depth limits --depth and --cloud"), "{}", stderr(&out));
}

#[test]
fn viz_draws_a_depth_map_with_its_scale() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    let out = run_in(dir.path(), &["S/im0.png", "S/im1.png", "-o", "d.pfm", "--depth", "z.pfm", "--set", "model=wta"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = run_in(dir.path(), &["viz", "z.pfm", "--depth", "-o", "z.png"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("depth coloured by 1/Z"), "{}", stderr(&out));
    // The range's ends as a reader reads them: three significant digits, not a float's seven.
    let line = stderr(&out);
    let from = line.split(" from ").nth(1).and_then(|r| r.split(' ').next()).unwrap_or_default().to_string();
    assert!(from.parse::<f32>().is_ok() && from.trim_start_matches(['0', '.']).len() <= 4, "{line}");
    let picture = jem::io::read_image(&dir.path().join("z.png")).unwrap();
    // The picture and, under it, the scale bar.
    assert!(picture.width() == 64 && picture.height() > 48 + 20, "{:?}", picture.dims());
    let out = run_in(dir.path(), &["viz", "z.pfm", "--depth", "--vmin", "5", "--vmax", "2", "-o", "y.png"]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn swapped_views_warn_and_strict_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    let args = ["S/im1.png", "S/im0.png", "-o", "d.pfm", "--ndisp", "16", "--set", "model=wta"];
    let out = run_in(dir.path(), &args);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.lines().any(|l| l.starts_with("warning: the views look swapped")), "{err}");
    assert!(dir.path().join("d.pfm").is_file());
    let before = files_in(dir.path());
    let out = run_in(dir.path(), &["S/im1.png", "S/im0.png", "-o", "e.pfm", "--ndisp", "16", "--strict"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    let prefix = "error: the pair looks wrong (--strict: nothing written): the views look swapped";
    assert!(err.lines().any(|l| l.starts_with(prefix)), "{err}");
    assert_eq!(files_in(dir.path()), before);
    // The pair the right way round: no warning, and --strict writes it.
    let out = run_in(dir.path(), &["S/im0.png", "S/im1.png", "-o", "f.pfm", "--strict", "-v"]);
    let err = stderr(&out);
    // (A 64 × 48 image holds fewer slanted-plane segments than configured: that warning is about the settings.)
    assert!(out.status.success() && err.lines().all(|l| !l.starts_with("warning: the ")), "{err}");
    assert!(err.lines().any(|l| l.starts_with("checked: negative-disparity share")), "{err}");
}

/// No false alarm: the checks of every trainingQ pair give no warning; swapping each pair's views is caught every
/// time.
#[test]
fn no_trainingq_pair_is_said_to_be_wrong_and_every_swapped_one_is() {
    let Some(data) = common::data_dir() else { return };
    let params = jem::params::CostParams::default();
    for scene in common::training_scenes(&data) {
        let (l, r) = jem::io::read_image_pair(&scene.join("im0.png"), &scene.join("im1.png")).unwrap();
        let check = jem::internals::diagnose::check_pair(&l, &r, &params, None, None, u64::MAX);
        assert!(check.warnings().is_empty(), "{}: {check}: {:?}", scene.display(), check.warnings());
        let swapped = jem::internals::diagnose::check_pair(&r, &l, &params, None, None, u64::MAX);
        let said = swapped.warnings().iter().any(|w| w.starts_with("the views look swapped"));
        assert!(said, "{}: {swapped}", scene.display());
    }
}

/// The right view turned by `degrees` about the image centre (bilinear, the border pixels held).
fn rotated(view: &jem::RgbImage, degrees: f64) -> jem::RgbImage {
    let (w, h) = view.dims();
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let (sin, cos) = degrees.to_radians().sin_cos();
    let at = |c: &[f32], x: f64, y: f64| {
        let (x, y) = (x.clamp(0.0, w as f64 - 1.0), y.clamp(0.0, h as f64 - 1.0));
        let (x0, y0) = ((x.floor() as usize).min(w - 2), (y.floor() as usize).min(h - 2));
        let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let p = |xx: usize, yy: usize| c[yy * w + xx];
        let top = p(x0, y0) * (1.0 - fx) + p(x0 + 1, y0) * fx;
        let bottom = p(x0, y0 + 1) * (1.0 - fx) + p(x0 + 1, y0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    };
    let channel = |k: usize| {
        let c = view.channel(k);
        let pixel = |i: usize| {
            let (dx, dy) = ((i % w) as f64 - cx, (i / w) as f64 - cy);
            at(c, cx + cos * dx + sin * dy, cy - sin * dx + cos * dy)
        };
        (0..w * h).map(pixel).collect()
    };
    jem::RgbImage::from_channels(w, h, [0, 1, 2].map(channel)).unwrap()
}

/// No false alarm from the checks that read the answer (its true disparities here): every trainingQ pair under its
/// stated range has its answers well below the range's top and the same vertical offset across and down the
/// image; the right view turned by 1° (92 % bad on Adirondack, once unwarned) is said to be rotated every time.
#[test]
fn the_answer_checks_pass_every_trainingq_pair_and_catch_a_turned_right_view() {
    let Some(data) = common::data_dir() else { return };
    let params = jem::params::CostParams::default();
    for scene in common::training_scenes(&data) {
        let (l, r) = jem::io::read_image_pair(&scene.join("im0.png"), &scene.join("im1.png")).unwrap();
        let gt = jem::io::read_disparity(&scene.join("disp0GT.pfm")).unwrap();
        let calib = jem::io::calib::Calib::load(&scene.join("calib.txt")).unwrap();
        let ndisp = calib.stated_ndisp().unwrap().unwrap();
        let mut check = jem::internals::diagnose::check_pair(&l, &r, &params, None, None, u64::MAX);
        jem::internals::diagnose::check_answer(&mut check, &l, &r, &gt, Some([0, ndisp]), || Some(10 * ndisp));
        assert!(check.warnings().is_empty(), "{}: {check}: {:?}", scene.display(), check.warnings());
        let turned = rotated(&r, 1.0);
        let mut check = jem::internals::diagnose::check_pair(&l, &turned, &params, None, None, u64::MAX);
        jem::internals::diagnose::check_answer(&mut check, &l, &turned, &gt, Some([0, ndisp]), || None);
        let warnings = check.warnings();
        assert!(warnings.iter().any(|w| w.contains("rotated by about")), "{}: {check}: {warnings:?}", scene.display());
    }
}

/// `jem sequence --rectify CALIB` rectifies every frame as `jem match --rectify` rectifies a pair: frame by frame
/// the same bytes (a sequence must not rectify differently from the pair it is made of).
#[test]
fn sequence_with_rectify_is_jem_match_with_rectify_frame_by_frame() {
    let dir = tempfile::tempdir().unwrap();
    let synth =
        ["synth", "seq", "--frames", "2", "--motion", "pan", "--width", "64", "--height", "48", "--ndisp", "16"];
    let out = run_in(dir.path(), &synth);
    assert!(out.status.success(), "{}", stderr(&out));
    // The right camera a little higher as well: the rectification then moves both views.
    let rig = pinhole_rig_yaml(64, 48, 0.25).replace("[ -0.25, 0., 0. ]", "[ -0.25, 0.01, 0. ]");
    std::fs::write(dir.path().join("rig.yml"), rig).unwrap();
    let wta = ["--set", "model=wta"];
    let args = [&["sequence", "seq", "-o", "out", "--independent", "--rectify", "rig.yml"][..], &wta].concat();
    let out = run_in(dir.path(), &args);
    assert!(out.status.success(), "{}", stderr(&out));
    let plain = [&["sequence", "seq", "-o", "plain", "--independent"][..], &wta].concat();
    assert!(run_in(dir.path(), &plain).status.success());
    let read = |p: &str| std::fs::read(dir.path().join(p)).unwrap();
    for k in 0..2 {
        let (l, r) = (format!("seq/left/{k:06}.png"), format!("seq/right/{k:06}.png"));
        let args = [&[l.as_str(), &r, "--rectify", "rig.yml", "--ndisp", "16", "-o", "m.pfm"][..], &wta].concat();
        let out = run_in(dir.path(), &args);
        assert!(out.status.success(), "{}", stderr(&out));
        let got = read(&format!("out/{k:06}.pfm"));
        assert!(got == read("m.pfm"), "frame {k} differs from jem match --rectify");
        assert!(got != read(&format!("plain/{k:06}.pfm")), "frame {k} is not rectified");
    }
}

/// The same image given as both views matches at 0 everywhere and was "100 % valid" without a word: a warning
/// says it is the same image (and `--strict` writes nothing).
#[test]
fn the_same_image_twice_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    let out = run_in(dir.path(), &["S/im0.png", "S/im0.png", "-o", "d.pfm", "--ndisp", "16", "--set", "model=wta"]);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.lines().any(|l| l.starts_with("warning: the two views are the same image")), "{err}");
    let out = run_in(dir.path(), &["S/im0.png", "S/im0.png", "-o", "e.pfm", "--ndisp", "16", "--strict"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(!dir.path().join("e.pfm").exists());
}

/// Calibrations that cannot be right are refused with the key named, as `jem rectify` and `--rectify` read them:
/// a matrix that is no rotation (OpenCV turns any into the nearest rotation without a word), a reflection (it was
/// "a vertical baseline"), a given R1 that is no rotation, a size that is no size, a translation beyond floating
/// point (it was "T is zero"), a key given twice (jem took the last, OpenCV the first). One whose lens sends the
/// views outside the raw images (`k1 = 1e30`), which OpenCV rectifies into black views, is warned about.
#[test]
fn calibrations_that_cannot_be_right_are_refused_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    let rig = pinhole_rig_yaml(64, 48, 0.25);
    let identity = "[ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]";
    let with_r = |r: &str| rig.replace(identity, r);
    let given = |r1: &str| {
        let p = "[ 80., 0., 31.5, 0., 0., 80., 23.5, 0., 0., 0., 1., 0. ]";
        let p2 = "[ 80., 0., 31.5, -20., 0., 80., 23.5, 0., 0., 0., 1., 0. ]";
        let m = |name: &str, rows: usize, cols: usize, data: &str| {
            format!("{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: {data}\n")
        };
        format!("{rig}{}{}{}{}", m("R1", 3, 3, r1), m("R2", 3, 3, identity), m("P1", 3, 4, p), m("P2", 3, 4, p2))
    };
    let cases: Vec<(&str, String, &str)> = vec![
        ("counting.yml", with_r("[ 1., 2., 3., 4., 5., 6., 7., 8., 9. ]"), "R is not a rotation"),
        ("twice.yml", with_r("[ 2., 0., 0., 0., 2., 0., 0., 0., 2. ]"), "R is not a rotation"),
        ("mirror.yml", with_r("[ 1., 0., 0., 0., 1., 0., 0., 0., -1. ]"), "R is a reflection"),
        ("r1.yml", given("[ 3., 0., 0., 0., 3., 0., 0., 0., 3. ]"), "R1 is not a rotation"),
        ("width.yml", rig.replace("image_width: 64", "image_width: -5"), "image_width/image_height -5 × 48"),
        ("height.yml", rig.replace("image_height: 48", "image_height: 0"), "image_width/image_height 64 × 0"),
        ("far.yml", rig.replace("[ -0.25, 0., 0. ]", "[ -1e300, 0., 0. ]"), "T (-1e300, 0, 0) is too long"),
        (
            "dup.yml",
            format!("{rig}T: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: d\n   data: [ 1., 0., 0. ]\n"),
            "T is given twice",
        ),
    ];
    for (name, text, needle) in cases {
        std::fs::write(dir.path().join(name), text).unwrap();
        let before = files_in(dir.path());
        for args in [
            vec!["rectify", name, "S/im0.png", "S/im1.png", "-o", "R"],
            vec!["S/im0.png", "S/im1.png", "--rectify", name, "-o", "d.pfm"],
        ] {
            let out = run_in(dir.path(), &args);
            let err = stderr(&out);
            assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
            assert!(err.starts_with(&format!("error: {name}: ")) && err.contains(needle), "{args:?}: {err}");
            assert_eq!(err.trim_end().lines().count(), 1, "{err}");
            assert_eq!(files_in(dir.path()), before, "{args:?} left files");
        }
    }
    // The file's own R1, R2, P1, P2 (a saved stereoRectify result) with a lens no camera has.
    let wild = given(identity).replacen("[ 0., 0., 0., 0., 0. ]", "[ 1e30, 0., 0., 0., 0. ]", 1);
    std::fs::write(dir.path().join("wild.yml"), wild).unwrap();
    let out = run_in(dir.path(), &["rectify", "wild.yml", "S/im0.png", "S/im1.png", "-o", "W"]);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("warning: wild.yml: the rectified left view is") && err.contains("% black"), "{err}");
    let strict = ["S/im0.png", "S/im1.png", "--rectify", "wild.yml", "-o", "w.pfm", "--strict", "--set", "model=wta"];
    let out = run_in(dir.path(), &strict);
    assert_eq!(out.status.code(), Some(2), "--strict makes it an error: {}", stderr(&out));
}

/// `cv2.FileStorage` writes a 1-D numpy array (a distortion vector `np.array([...])`, a translation) as an
/// `opencv-nd-matrix`, in YAML and XML; they are read (it was "missing D1/distCoeffs1").
#[test]
fn opencv_one_dimensional_arrays_are_read() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    let rig = pinhole_rig_yaml(64, 48, 0.25);
    let nd = |name: &str, data: &str, n: usize| {
        format!("{name}: !!opencv-nd-matrix\n   sizes: [ {n} ]\n   dt: d\n   data: {data}\n")
    };
    let plain = |name: &str, rows: usize, cols: usize, data: &str| {
        format!("{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: {data}\n")
    };
    let yaml = rig
        .replace(&plain("D1", 1, 5, "[ 0., 0., 0., 0., 0. ]"), &nd("D1", "[ 0., 0.,\n       0., 0., 0. ]", 5))
        .replace(&plain("T", 3, 1, "[ -0.25, 0., 0. ]"), &nd("T", "[ -0.25, 0., 0. ]", 3))
        .replace("%YAML:1.0", "%YAML 1.2");
    assert!(yaml.contains("opencv-nd-matrix\n   sizes: [ 5 ]") && yaml.contains("sizes: [ 3 ]"), "{yaml}");
    std::fs::write(dir.path().join("nd.yml"), yaml).unwrap();
    let element = |name: &str, kind: &str, shape: &str, data: &str| {
        format!("<{name} type_id=\"{kind}\">\n  {shape}\n  <dt>d</dt>\n  <data>\n    {data}</data></{name}>\n")
    };
    let matrix = |name: &str, data: &str| element(name, "opencv-matrix", "<rows>3</rows>\n  <cols>3</cols>", data);
    let vector = |name: &str, n: usize, data: &str| {
        element(name, "opencv-nd-matrix", &format!("<sizes>\n    {n}</sizes>"), data)
    };
    let k = "80. 0. 31.5 0. 80. 23.5 0. 0. 1.";
    let xml = format!(
        "<?xml version=\"1.0\"?>\n<opencv_storage>\n{}{}{}{}{}{}</opencv_storage>\n",
        matrix("K1", k),
        vector("D1", 5, "0. 0. 0. 0. 0."),
        matrix("K2", k),
        vector("D2", 5, "0. 0. 0. 0. 0."),
        matrix("R", "1. 0. 0. 0. 1. 0. 0. 0. 1."),
        vector("T", 3, "-0.25 0. 0.")
    );
    std::fs::write(dir.path().join("nd.xml"), xml).unwrap();
    std::fs::write(dir.path().join("rig.yml"), &rig).unwrap();
    let out = run_in(dir.path(), &["rectify", "rig.yml", "S/im0.png", "S/im1.png", "-o", "A"]);
    assert!(out.status.success(), "{}", stderr(&out));
    for (calib, folder) in [("nd.yml", "B"), ("nd.xml", "C")] {
        let out = run_in(dir.path(), &["rectify", calib, "S/im0.png", "S/im1.png", "-o", folder]);
        assert!(out.status.success(), "{calib}: {}", stderr(&out));
        for f in ["im0.png", "im1.png", "calib.txt"] {
            let (a, b) = (dir.path().join("A").join(f), dir.path().join(folder).join(f));
            assert_eq!(std::fs::read(a).unwrap(), std::fs::read(b).unwrap(), "{calib}: {f}");
        }
    }
}

/// `jem rectify -o DIR` refuses a folder that holds a scene, as `jem synth` does: the new pair and calib.txt
/// would sit beside the old scene's ground truth and results. A folder that is a file says what to give.
#[test]
fn rectify_refuses_a_folder_that_holds_a_scene() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    synth_scene(dir.path(), "T");
    std::fs::write(dir.path().join("rig.yml"), pinhole_rig_yaml(64, 48, 0.25)).unwrap();
    let before = files_in(&dir.path().join("T"));
    let out = run_in(dir.path(), &["rectify", "rig.yml", "S/im0.png", "S/im1.png", "-o", "T"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("T: already holds a scene"), "{err}");
    assert_eq!(files_in(&dir.path().join("T")), before);
    std::fs::write(dir.path().join("afile"), b"x").unwrap();
    let out = run_in(dir.path(), &["rectify", "rig.yml", "S/im0.png", "S/im1.png", "-o", "afile"]);
    assert!(stderr(&out).contains("afile: exists and is not a folder; give -o"), "{}", stderr(&out));
}

/// Grey views come out of `jem rectify` as 8-bit grey PNGs, the same samples as the colour rectification of the
/// same views; a colour pair stays colour, and so does a pair with one grey view (its colour would be lost).
#[test]
fn a_grey_pair_stays_grey() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    std::fs::write(dir.path().join("rig.yml"), pinhole_rig_yaml(64, 48, 0.25)).unwrap();
    for name in ["im0", "im1"] {
        let rgb = image::open(dir.path().join(format!("S/{name}.png"))).unwrap();
        rgb.to_luma8().save(dir.path().join(format!("{name}-grey.png"))).unwrap();
        image::DynamicImage::ImageLuma8(rgb.to_luma8())
            .to_rgb8()
            .save(dir.path().join(format!("{name}-rgb.png")))
            .unwrap();
    }
    let colour = |folder: &str| image::open(dir.path().join(folder).join("im0.png")).unwrap().color();
    for (left, right, folder, expected) in [
        ("im0-grey.png", "im1-grey.png", "G", image::ColorType::L8),
        ("im0-rgb.png", "im1-rgb.png", "C", image::ColorType::Rgb8),
        ("im0-grey.png", "im1-rgb.png", "M", image::ColorType::Rgb8),
    ] {
        let out = run_in(dir.path(), &["rectify", "rig.yml", left, right, "-o", folder]);
        assert!(out.status.success(), "{}", stderr(&out));
        assert_eq!(colour(folder), expected, "{left} {right}");
    }
    for name in ["im0.png", "im1.png"] {
        let (grey, rgb) = (dir.path().join("G").join(name), dir.path().join("C").join(name));
        assert_eq!(jem::io::read_image(&grey).unwrap(), jem::io::read_image(&rgb).unwrap(), "{name}");
    }
}

/// `--alpha` is OpenCV's free scaling: 1 keeps every raw pixel (a smaller focal length, black corners and a valid
/// rectangle inside the view in rectify.yml); out of 0..1 it is refused and nothing is written.
#[test]
fn rectify_alpha_scales_the_views_and_states_the_valid_rectangle() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), "S");
    let barrel =
        pinhole_rig_yaml(64, 48, 0.25).replace("data: [ 0., 0., 0., 0., 0. ]", "data: [ -0.3, 0., 0., 0., 0. ]");
    std::fs::write(dir.path().join("rig.yml"), barrel).unwrap();
    let roi = |folder: &str| {
        let yml = std::fs::read_to_string(dir.path().join(folder).join("rectify.yml")).unwrap();
        let line = yml.lines().find(|l| l.starts_with("validPixROI1: [ ")).unwrap_or_else(|| panic!("{yml}"));
        let inner = line.trim_start_matches("validPixROI1: [ ").trim_end_matches(" ]");
        inner.split(", ").map(|v| v.parse::<usize>().unwrap()).collect::<Vec<_>>()
    };
    for (alpha, folder) in [("0", "A0"), ("1", "A1")] {
        let out = run_in(dir.path(), &["rectify", "rig.yml", "S/im0.png", "S/im1.png", "-o", folder, "--alpha", alpha]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let out = run_in(dir.path(), &["rectify", "rig.yml", "S/im0.png", "S/im1.png", "-o", "D"]);
    assert!(out.status.success(), "{}", stderr(&out));
    for f in ["im0.png", "im1.png", "calib.txt", "rectify.yml"] {
        let read = |folder: &str| std::fs::read(dir.path().join(folder).join(f)).unwrap();
        assert_eq!(read("A0"), read("D"), "--alpha 0 is the default: {f}");
    }
    let (cropped, kept) = (roi("A0"), roi("A1"));
    assert!(cropped[2] >= 62 && cropped[3] >= 46, "{cropped:?}");
    assert!(kept[0] > 0 && kept[1] > 0 && kept[2] < cropped[2] && kept[3] < cropped[3], "{kept:?} {cropped:?}");
    for bad in ["1.5", "-0.2"] {
        let out = run_in(dir.path(), &["rectify", "rig.yml", "S/im0.png", "S/im1.png", "-o", "X", "--alpha", bad]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("alpha") && err.contains("0..=1") && err.lines().count() == 1, "{err}");
        assert!(!dir.path().join("X").exists());
    }
}

/// No repetitive-texture false alarm: every trainingQ pair matched at its stated range (the default configuration,
/// with its confidence, as `jem match` runs) has no region of texture repeating within the range whose answers are
/// doubtful or a period off each other. The unit tests of `diagnose::repetitive` hold the cases that must warn.
#[test]
#[ignore = "slow: every trainingQ scene matched (about 1 min on 2 cores in release); run it with `cargo test --release -- --include-ignored`, as .ci/run does"]
fn no_trainingq_pair_is_said_to_be_matched_a_period_off() {
    let Some(data) = common::data_dir() else { return };
    for scene in common::training_scenes(&data) {
        let (l, r) = jem::io::read_image_pair(&scene.join("im0.png"), &scene.join("im1.png")).unwrap();
        let calib = jem::io::calib::Calib::load(&scene.join("calib.txt")).unwrap();
        let ndisp = calib.stated_ndisp().unwrap().unwrap();
        let mut matcher = jem::Matcher::new(jem::Params::default())
            .unwrap()
            .with_ndisp(jem::NdispSource::Given(ndisp))
            .with_confidence(true)
            .with_checks(true);
        let out = matcher.match_pair(&l, &r).unwrap();
        let said = out.warnings().into_iter().filter(|w| w.contains("period")).collect::<Vec<_>>();
        assert!(said.is_empty(), "{}: {}: {said:?}", scene.display(), out.checks.unwrap());
    }
}
