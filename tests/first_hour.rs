//! The first hour: what a newcomer sees. Every command ends with one line on stderr saying what it did
//! and where (`-q` silences it); `jem viz` draws KITTI and ETH3D trees with each benchmark's own error rule.

mod common;

use std::path::Path;

use common::{run_in, stderr};

/// The last line a command printed on stderr (after checking it succeeded).
fn last_line(dir: &Path, args: &[&str]) -> String {
    let out = run_in(dir, args);
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    stderr(&out).lines().last().unwrap_or_default().to_string()
}

/// Each command's last line says what it did and where; with `-q` there is nothing on stderr
/// (and the files are written all the same).
#[test]
fn every_command_ends_with_what_it_did() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let small = ["--width", "96", "--height", "64", "--ndisp", "16"];
    let line = last_line(d, &[&["synth", "set/S"][..], &small].concat());
    assert!(line.starts_with("wrote set/S/") && line.contains("96×64"), "{line}");

    let line = last_line(d, &["set/S/im0.png", "set/S/im1.png", "-o", "d.pfm", "--cloud", "p.ply"]);
    let (head, tail) = line.split_once(" % valid, ndisp 16, ").unwrap_or_else(|| panic!("{line}"));
    assert!(head.starts_with("wrote d.pfm (96×64, ") && tail.contains(" s), point cloud p.ply ("), "{line}");
    let percent: f64 = head.rsplit(", ").next().unwrap().parse().unwrap_or_else(|_| panic!("{line}"));
    let map = jem::io::read_disparity(&d.join("d.pfm")).unwrap();
    let valid = 100.0 * map.data().iter().filter(|v| v.is_finite()).count() as f64 / map.data().len() as f64;
    assert!((percent - valid).abs() <= 0.5, "{line}: {valid} % valid");

    let line = last_line(d, &["batch", "set", "--alg", "T"]);
    let want = "1 pair(s): 1 written, 0 skipped, 0 failed; results: disp0T.pfm and timeT.txt in each MiddEval3 scene \
                folder (under set)";
    assert_eq!(line, want);
    let line = last_line(d, &["eval", "set", "--alg", "T", "--scale", "1"]);
    assert_eq!(line, "scored 1 of 1 scene(s) of T (middlebury, nonocc)");
    let line = last_line(d, &["viz", "d.pfm", "-o", "v.png"]);
    assert!(line.starts_with("wrote v.png (96×64): disparity coloured over "), "{line}");
    let line = last_line(d, &["viz", "set", "--alg", "T", "-o", "sheet.png", "--scale", "1"]);
    assert!(
        line.starts_with("wrote sheet.png (")
            && line.ends_with("1 rows (S); error maps: MiddEval3 bad-2 (error > 2 px)"),
        "{line}"
    );
    let line = last_line(d, &["config", "--set", "meanfield.iterations=2"]);
    assert_eq!(line, "printed the effective configuration: built-in defaults ← 1 --set");
    let line = last_line(d, &["degrade", "set", "noisy", "--recipe", "noise:2"]);
    assert_eq!(line, "wrote 1 scene(s) under noisy (noise:2, seed 1)");

    // A failed scene is counted in the last line (and the exit code is 2).
    std::fs::create_dir_all(d.join("bad/B")).unwrap();
    for f in ["im0.png", "im1.png", "calib.txt"] {
        std::fs::write(d.join("bad/B").join(f), b"not an image").unwrap();
    }
    let out = run_in(d, &["batch", "bad", "--alg", "T"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(err.lines().last().unwrap_or_default().contains("0 written, 0 skipped, 1 FAILED"), "{err}");

    // -q: nothing on stderr, the outputs all the same.
    for args in [
        &["-q", "synth", "q/S", "--width", "96", "--height", "64", "--ndisp", "16"][..],
        &["-q", "q/S/im0.png", "q/S/im1.png", "-o", "q.pfm"],
        &["batch", "q", "--alg", "T", "-q"],
        &["-q", "eval", "q", "--alg", "T", "--scale", "1"],
        &["-q", "viz", "q.pfm", "-o", "q.png"],
        &["-q", "viz", "q", "--alg", "T", "-o", "qsheet.png", "--scale", "1"],
        &["-q", "config"],
        &["-q", "degrade", "q", "qnoisy", "--recipe", "noise:2"],
    ] {
        let out = run_in(d, args);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        assert!(out.stderr.is_empty(), "{args:?} -q printed {:?}", stderr(&out));
    }
    for f in ["q/S/disp0GT.pfm", "q.pfm", "q/S/disp0T.pfm", "q.png", "qsheet.png", "qnoisy/S/im0.png"] {
        assert!(d.join(f).is_file(), "{f} missing after -q");
    }
}

const INF: f32 = f32::INFINITY;

/// Writes a disparity map in the format its extension names (16-bit PNG for KITTI, PFM).
fn write_map(path: &Path, w: usize, h: usize, data: Vec<f32>) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let bytes = jem::io::encode_disparity(path, &jem::Plane::from_vec(w, h, data).unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

/// Writes a flat grey 8-bit RGB image.
fn write_image(path: &Path, w: u32, h: u32) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::RgbImage::from_pixel(w, h, image::Rgb([9, 9, 9])).save(path).unwrap();
}

/// The colour at (x, y) of a PNG, and its size.
fn pixel(path: &Path, x: u32, y: u32) -> ((u32, u32), [u8; 3]) {
    let img = image::open(path).unwrap().to_rgb8();
    (img.dimensions(), img.get_pixel(x, y).0)
}

/// Where panel `k` (0 left image, 1 result, 2 error map) of a contact sheet's first row starts, for panels `w`
/// pixels wide: below the column titles (16 px) and the 8-px gap, right of the label column (15 characters of
/// 12 px, less the last gap, and 8 px), panels 4 px apart.
fn sheet_panel(k: u32, w: u32) -> (u32, u32) {
    (15 * 12 - 2 + 8 + k * (w + 4), 16 + 8)
}

/// An occluded pixel that is not bad, with error 0 (the module doc of jem::viz).
fn occluded_exact() -> [u8; 3] {
    [0.5f32 * 255.0, 0.55 * 255.0, 0.7 * 255.0].map(|v| v.round() as u8)
}

/// A KITTI tree's contact sheet and a single KITTI map's error map use D1 (error > 3 px and > 5 %
/// of the true disparity), not MiddEval3's 2 px: 4 px off a true 100 is fine, 4 px off a true 20 is bad. Pixels in
/// disp_occ_0 but not in disp_noc_0 are shaded as occluded. (Before: "no scene folder with im0.png and
/// disp0T.pfm", and a single map's error map used the 2 px rule.)
#[test]
fn viz_kitti_tree_with_d1() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let frame = "000000_10.png";
    for side in ["image_2", "image_3"] {
        write_image(&d.join("kitti/training").join(side).join(frame), 8, 2);
    }
    //                  0      1      2     3     4      5      6    7
    let all = vec![100.0, 100.0, 20.0, 20.0, 50.0, 50.0, INF, 60.0];
    let nonocc = vec![100.0, 100.0, 20.0, 20.0, INF, 50.0, INF, 60.0];
    let result = vec![104.0, 100.0, 24.0, 20.0, 50.0, INF, 9.0, 61.0];
    let second = |row: &[f32]| [row, row].concat();
    write_map(&d.join("kitti/training/disp_occ_0").join(frame), 8, 2, second(&all));
    write_map(&d.join("kitti/training/disp_noc_0").join(frame), 8, 2, second(&nonocc));
    write_map(&d.join("kitti/results/T/training/disp_0").join(frame), 8, 2, second(&result));
    let want = |(x0, y0): (u32, u32), sheet: &Path| {
        let grey = (255.0f32 - 50.0 * 4.0 / 5.0).round() as u8;
        let colours: Vec<[u8; 3]> = (0..8).map(|x| pixel(sheet, x0 + x, y0 + 1).1).collect();
        assert_eq!(colours[0], [grey; 3], "4 px off 100: within D1");
        assert_eq!(colours[1], [255; 3]);
        assert_eq!(colours[2], [230, 30, 30], "4 px off 20: a D1 outlier");
        assert_eq!(colours[4], occluded_exact(), "in disp_occ_0 only: occluded");
        assert_eq!(colours[5], [0, 0, 0], "invalid result");
        assert_eq!(colours[6], [48, 48, 48], "no ground truth");
    };
    let out = run_in(d, &["viz", "kitti/training", "--alg", "T", "-o", "sheet.png"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(err.contains("1 rows (000000_10); error maps: KITTI D1 (error > 3 px and > 5 % of the true"), "{err}");
    want(sheet_panel(2, 8), &d.join("sheet.png"));
    // One map against disp_noc_0 (its sibling disp_occ_0 is the truth of all pixels).
    let args =
        ["viz", "kitti/results/T/training/disp_0/000000_10.png", "--gt", "kitti/training/disp_noc_0/000000_10.png"];
    let out = run_in(d, &[&args[..], &["-o", "one.png"]].concat());
    assert!(out.status.success() && stderr(&out).contains("red: KITTI D1"), "{}", stderr(&out));
    want((12, 0), &d.join("one.png"));
    // A sheet of a tree without results says where it looked.
    let out = run_in(d, &["viz", "kitti/training", "--alg", "U", "-o", "none.png"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("no result of U") && stderr(&out).contains("results/U/training/disp_0"),
        "{}",
        stderr(&out)
    );
}

/// An ETH3D tree's contact sheet uses bad-1 (error > 1 px, native pixels; MiddEval3's rule would
/// let 1.5 px pass) with the ground truth of the `_gt` tree, and ETH3D's mask: anything but 255 is occluded.
#[test]
fn viz_eth3d_tree_with_bad1() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = d.join("two_view_training/S");
    write_image(&scene.join("im0.png"), 4, 1);
    write_image(&scene.join("im1.png"), 4, 1);
    std::fs::write(scene.join("calib.txt"), "ndisp=4\n").unwrap();
    write_map(&d.join("two_view_training_gt/S/disp0GT.pfm"), 4, 1, vec![10.0, 10.0, 10.0, 10.0]);
    image::GrayImage::from_raw(4, 1, vec![255, 255, 0, 255])
        .unwrap()
        .save(d.join("two_view_training_gt/S/mask0nocc.png"))
        .unwrap();
    write_map(&d.join("results/T/two_view_training/low_res_two_view/S.pfm"), 4, 1, vec![11.5, 10.5, 10.0, 10.0]);
    let out = run_in(d, &["viz", "two_view_training", "--alg", "T", "-o", "sheet.png"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("1 rows (S); error maps: ETH3D bad-1 (error > 1 px)"), "{}", stderr(&out));
    let sheet = d.join("sheet.png");
    let (x0, y0) = sheet_panel(2, 4);
    let colours: Vec<[u8; 3]> = (0..4).map(|x| pixel(&sheet, x0 + x, y0).1).collect();
    assert_eq!(colours, vec![[230, 30, 30], [230; 3], occluded_exact(), [255; 3]]);
    // One map: the rule follows from the ground truth's place in a *_gt tree.
    let args = [
        "viz",
        "results/T/two_view_training/low_res_two_view/S.pfm",
        "--gt",
        "two_view_training_gt/S/disp0GT.pfm",
        "-o",
        "o.png",
    ];
    let out = run_in(d, &args);
    assert!(out.status.success() && stderr(&out).contains("red: ETH3D bad-1"), "{}", stderr(&out));
    assert_eq!(pixel(&d.join("o.png"), 8, 0).1, [230, 30, 30]);
}

/// `viz --scale`: a MiddEval3 error map outside a trainingQ/H/F folder no longer takes 1
/// silently: the error asks for --scale, and --scale 4 makes 0.75 px (3 full-resolution px) bad.
#[test]
fn viz_scale_is_asked_for_when_the_path_does_not_tell() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_map(&d.join("S/disp0GT.pfm"), 2, 1, vec![10.0, 10.0]);
    write_map(&d.join("S/disp0T.pfm"), 2, 1, vec![10.75, 10.0]);
    write_image(&d.join("S/im0.png"), 2, 1);
    for args in [
        &["viz", "S/disp0T.pfm", "--gt", "S/disp0GT.pfm", "-o", "o.png"][..],
        &["viz", ".", "--alg", "T", "-o", "s.png"],
    ] {
        let out = run_in(d, args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = stderr(&out);
        assert!(err.contains("cannot tell the resolution of") && err.contains("pass --scale 1, 2 or 4"), "{err}");
        assert!(!d.join(args[args.len() - 1]).exists());
    }
    let out = run_in(d, &["viz", "S/disp0T.pfm", "--gt", "S/disp0GT.pfm", "-o", "o.png", "--scale", "4"]);
    assert!(out.status.success() && stderr(&out).contains("×4"), "{}", stderr(&out));
    assert_eq!(pixel(&d.join("o.png"), 6, 0).1, [230, 30, 30]);
    let out = run_in(d, &["viz", "S/disp0T.pfm", "--gt", "S/disp0GT.pfm", "-o", "o.png", "--scale", "1"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_ne!(pixel(&d.join("o.png"), 6, 0).1, [230, 30, 30]);
}

/// The library's example in docs/library.md is `examples/library.rs` as it is (which CI compiles), so the page
/// cannot drift from a program that builds; and it needs no file of jem's checkout, as a user's program has none.
#[test]
fn the_library_page_shows_the_compiled_example() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let read = |p: &str| std::fs::read_to_string(root.join(p)).unwrap_or_else(|e| panic!("{p}: {e}"));
    let (page, example) = (read("docs/library.md"), read("examples/library.rs"));
    assert!(page.contains(&format!("```rust\n{example}```\n")), "docs/library.md does not show examples/library.rs");
    assert!(example.contains("fn main()") && !example.contains("configs/"), "{example}");
}
