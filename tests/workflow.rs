//! The research workflow — `jem batch`, `jem eval`, `jem viz` — run as a user would, on tiny scenes
//! built in temporary folders (plus the real MiddEval3 trainingQ scenes when they are present).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use jem::Plane;
use jem::eval::{MaskMode, PaperResults, evaluate_files};
use jem::internals::SplitMix64;
use serde_json::Value;

fn jem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_jem"))
}

fn run(cmd: &mut Command) -> Output {
    cmd.output().expect("cannot start jem")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A synthetic scene: random RGB texture, the right view shifted so every left pixel x matches right pixel x − d.
fn write_shift_scene(dir: &Path, width: u32, height: u32, d: u32, ndisp: usize, seed: u64) {
    std::fs::create_dir_all(dir).unwrap();
    let mut rng = SplitMix64::new(seed);
    let tex_w = width + d;
    let mut byte = || (rng.next_u64() >> 56) as u8;
    let tex: Vec<[u8; 3]> = (0..tex_w * height).map(|_| [byte(), byte(), byte()]).collect();
    let at = |x: u32, y: u32| image::Rgb(tex[(y * tex_w + x) as usize]);
    // Left x shows texture column x; right x' shows column x' + d, so right x − d shows what left x shows.
    image::RgbImage::from_fn(width, height, at).save(dir.join("im0.png")).unwrap();
    image::RgbImage::from_fn(width, height, |x, y| at(x + d, y)).save(dir.join("im1.png")).unwrap();
    std::fs::write(dir.join("calib.txt"), format!("width={width}\nheight={height}\nndisp={ndisp}\n")).unwrap();
}

/// A TOML config that needs no mean-field inference.
fn wta_config(dir: &Path) -> PathBuf {
    let p = dir.join("wta.toml");
    // Plain winner-take-all: no conditioning, no left-right check and no post-processing (the defaults run the
    // full pipeline; the i.i.d. random texture of these scenes would be measured as noise and denoised).
    std::fs::write(
        &p,
        "model = \"wta\"\n[condition]\nenabled = false\n[post]\nfill = false\n[post.lrc]\nmode = \"off\"\n\
         [post.wmedian]\nenabled = false\n[post.sps]\nenabled = false\n",
    )
    .unwrap();
    p
}

/// A scene with ground truth: `disp0GT.pfm`, `mask0nocc.png`, `calib.txt`, and optionally a result.
fn write_gt_scene(dir: &Path, gt: &Plane<f32>, mask: &[u8], ndisp: usize, result: Option<(&str, &Plane<f32>)>) {
    std::fs::create_dir_all(dir).unwrap();
    jem::io::pfm::write_pfm(&dir.join("disp0GT.pfm"), gt).unwrap();
    image::GrayImage::from_raw(gt.width() as u32, gt.height() as u32, mask.to_vec())
        .unwrap()
        .save(dir.join("mask0nocc.png"))
        .unwrap();
    std::fs::write(dir.join("calib.txt"), format!("ndisp={ndisp}\nvmin=0\nvmax={ndisp}\n")).unwrap();
    if let Some((alg, r)) = result {
        jem::io::pfm::write_pfm(&dir.join(format!("disp0{alg}.pfm")), r).unwrap();
    }
}

const INF: f32 = f32::INFINITY;

/// The 4×2 scene of the hand computation below.
fn hand_scene(dir: &Path) {
    //                    0    1      2    3    4     5     6     7
    let gt = Plane::from_vec(4, 2, vec![1.0, 2.0, 3.0, INF, 5.0, 6.0, 7.0, 8.0]).unwrap();
    let result = Plane::from_vec(4, 2, vec![1.0, 2.625, INF, 4.0, 11.0, -1.0, 7.25, 8.0]).unwrap();
    write_gt_scene(dir, &gt, &[255, 255, 255, 255, 255, 128, 0, 255], 10, Some(("X", &result)));
}

fn metric(v: &Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("{key} is not a number in {v}"))
}

fn assert_metrics(v: &Value, want: [f64; 8]) {
    let obj = v.as_object().expect("metrics object");
    let keys: Vec<&str> = obj.keys().map(String::as_str).collect();
    let mut expected = jem::eval::Metrics::NAMES.to_vec();
    expected.sort();
    let mut sorted = keys.clone();
    sorted.sort();
    assert_eq!(sorted, expected, "metric keys");
    for (k, w) in jem::eval::Metrics::NAMES.iter().zip(want) {
        let got = metric(v, k);
        assert!((got - w).abs() < 1e-9, "{k}: got {got}, want {w}");
    }
}

#[test]
fn eval_json_matches_hand_computed_metrics() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("MiddEval3/trainingQ");
    hand_scene(&root.join("Tiny"));

    // Nonocc, ×4 inferred from `trainingQ`: pixels 0, 1, 2, 4, 7 (3: GT inf, 5: occluded, 6: mask 0), n = 5.
    // Pixel 2 is invalid. Valid errors ×4: 0, 4·0.625 = 2.5, 4·|min(11, ndisp 10) − 5| = 20, 0.
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "X", "--format", "json"]));
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).expect("valid JSON");
    let top: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
    assert_eq!(top, ["alg", "layout", "mask", "mean", "scale", "scenes", "weighted"]); // serde_json sorts keys
    let text = stdout(&o);
    let at = |k: &str| text.find(&format!("\n  \"{k}\": ")).unwrap_or_else(|| panic!("{k} in {text}"));
    let order = ["alg", "layout", "mask", "scale", "scenes", "weighted", "mean"].map(at);
    assert!(order.windows(2).all(|w| w[0] < w[1]), "keys in the documented order: {text}");
    assert_eq!((v["alg"].as_str(), v["mask"].as_str(), v["scale"].as_u64()), (Some("X"), Some("nonocc"), Some(4)));
    assert_eq!(v["layout"].as_str(), Some("middlebury"));
    let want = [22.5 / 4.0, ((2.5f64.powi(2) + 400.0) / 4.0).sqrt(), 40.0, 40.0, 40.0, 20.0, 20.0, 60.0];
    assert_metrics(&v["scenes"]["Tiny"], want);
    assert_metrics(&v["weighted"], want);
    assert_metrics(&v["mean"], want);

    // All (mask > 0) adds pixel 5: −1 clips to 0, error 4·6 = 24. n = 6, 5 valid.
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "X", "--format", "json", "--mask", "all"]));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let p = |k: f64| 100.0 * k / 6.0;
    let rms = ((2.5f64.powi(2) + 400.0 + 576.0) / 5.0).sqrt();
    assert_metrics(&v["scenes"]["Tiny"], [46.5 / 5.0, rms, p(3.0), p(3.0), p(3.0), p(2.0), p(1.0), p(4.0)]);
    assert_eq!(v["mask"], "all");

    // --scale 1 overrides the path: errors 0, 0.625, 5, 0.
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "X", "--format", "json", "--scale", "1"]));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["scale"], 1);
    let rms = ((0.625f64.powi(2) + 25.0) / 4.0).sqrt();
    assert_metrics(&v["scenes"]["Tiny"], [5.625 / 4.0, rms, 40.0, 20.0, 20.0, 20.0, 20.0, 40.0]);

    // The other formats carry the same numbers.
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "X", "--format", "csv"]));
    let csv = stdout(&o);
    assert!(csv.starts_with("alg,mask,scale,scene,weight,avgerr,rms,bad0.5,bad1,bad2,bad4,invalid,totbad2,"), "{csv}");
    assert!(csv.contains("\nX,nonocc,4,Tiny,1,5.625,"), "{csv}");
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "X", "--format", "markdown"]));
    assert!(stdout(&o).contains("| Tiny | 1 | 5.62 |"), "{}", stdout(&o));
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "X"]));
    assert!(stdout(&o).lines().any(|l| l.starts_with("Tiny") && l.contains("5.62")), "{}", stdout(&o));
}

#[test]
fn eval_without_a_resolution_in_the_path_asks_for_scale() {
    let tmp = tempfile::tempdir().unwrap();
    hand_scene(&tmp.path().join("scenes/Tiny"));
    let o = run(jem().args(["eval", tmp.path().join("scenes").to_str().unwrap(), "--alg", "X"]));
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--scale"), "{}", stderr(&o));
    let o = run(jem().args(["eval", tmp.path().join("scenes").to_str().unwrap(), "--alg", "X", "--scale", "2"]));
    assert!(o.status.success(), "{}", stderr(&o));
}

/// A copy of MiddEval3 scenes in a folder named otherwise: the scenes' names and sizes tell the resolution (Teddy
/// at 450×375 is quarter resolution), so eval and viz need no --scale, say what they inferred on one line, and
/// -q silences it; a lone ground-truth file is told by its folder's name or its size.
#[test]
fn a_copied_middeval3_set_needs_no_scale() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("copy").join("Teddy");
    let (w, h) = (450, 375);
    let gt = Plane::new(w, h, 10.0f32);
    // Error 0.75 px at quarter resolution: 3 full-resolution px, bad-2 everywhere at ×4 (and at ×1 nowhere).
    let result = Plane::new(w, h, 10.75f32);
    write_gt_scene(&scene, &gt, &vec![255; w * h], 64, Some(("X", &result)));
    image::RgbImage::from_pixel(w as u32, h as u32, image::Rgb([9, 9, 9])).save(scene.join("im0.png")).unwrap();
    let copy = tmp.path().join("copy");
    let o = run(jem().arg("eval").arg(&copy).args(["--alg", "X", "--format", "json"]));
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["scale"], 4);
    assert!((metric(&v["scenes"]["Teddy"], "avgerr") - 3.0).abs() < 1e-6);
    let err = stderr(&o);
    let notes: Vec<&str> = err.lines().filter(|l| l.starts_with("note: ")).collect();
    assert_eq!(notes.len(), 1, "{err}");
    assert!(notes[0].contains("quarter resolution (errors ×4)") && notes[0].contains("--scale"), "{}", notes[0]);
    let o = run(jem().arg("eval").arg(&copy).args(["--alg", "X", "-q"]));
    assert!(o.status.success() && stderr(&o).is_empty(), "{}", stderr(&o));
    // viz: a contact sheet and a lone map with --gt, without --scale.
    let sheet = tmp.path().join("sheet.png");
    let o = run(jem().arg("viz").arg(&copy).args(["--alg", "X", "-o"]).arg(&sheet));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("note: ") && stderr(&o).contains("errors ×4"), "{}", stderr(&o));
    let lone = tmp.path().join("gt.pfm");
    jem::io::pfm::write_pfm(&lone, &gt).unwrap();
    let out = tmp.path().join("v.png");
    let o = run(jem().arg("viz").arg(scene.join("disp0X.pfm")).arg("--gt").arg(&lone).arg("-o").arg(&out));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("450×375 is the size of a MiddEval3 scene at quarter resolution"), "{}", stderr(&o));
    assert_eq!(png_dims_and_pixel(&out, w as u32 + 4, 0).1, [230, 30, 30], "bad at ×4");
    // A size no MiddEval3 scene has: --scale is asked for, and then used.
    jem::io::pfm::write_pfm(&lone, &Plane::new(w, h - 10, 10.0f32)).unwrap();
    let odd = tmp.path().join("odd.pfm");
    jem::io::pfm::write_pfm(&odd, &Plane::new(w, h - 10, 10.75f32)).unwrap();
    let o = run(jem().arg("viz").arg(&odd).arg("--gt").arg(&lone).arg("-o").arg(&out));
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).starts_with("error: ") && stderr(&o).contains("--scale"), "{}", stderr(&o));
    let o = run(jem().arg("viz").arg(&odd).arg("--gt").arg(&lone).args(["--scale", "1", "-o"]).arg(&out));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(png_dims_and_pixel(&out, w as u32 + 4, 0).1, [236; 3], "not bad at ×1: grey for 0.75 of 2 px");
}

/// Three 2×1 scenes with a constant error: PianoL 2 (weight 0.5), Teddy 4, Mystery 1 (unknown: weight 1).
fn weighted_scenes(root: &Path) {
    let gt = Plane::from_vec(2, 1, vec![1.0, 1.0]).unwrap();
    for (name, d) in [("PianoL", 1.5), ("Teddy", 2.0), ("Mystery", 1.25)] {
        let r = Plane::from_vec(2, 1, vec![d, d]).unwrap();
        write_gt_scene(&root.join(name), &gt, &[255, 255], 8, Some(("W", &r)));
        std::fs::write(root.join(name).join("timeW.txt"), format!("{}\n", d * 2.0)).unwrap();
    }
}

#[test]
fn eval_weighted_average_halves_the_five_scenes() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("trainingQ");
    weighted_scenes(&root);
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "W", "--format", "json"]));
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert!((metric(&v["weighted"], "avgerr") - (0.5 * 2.0 + 4.0 + 1.0) / 2.5).abs() < 1e-12);
    assert!((metric(&v["mean"], "avgerr") - 7.0 / 3.0).abs() < 1e-12);
    // Bad2: Teddy's error 4 > 2 → 100 %, the others 0 → weighted 100/2.5 = 40.
    assert!((metric(&v["weighted"], "bad2") - 40.0).abs() < 1e-12);
    let scenes: Vec<&str> = v["scenes"].as_object().unwrap().keys().map(String::as_str).collect();
    assert_eq!(scenes, ["Mystery", "PianoL", "Teddy"]);
    // Mean time per pair (3 + 4 + 2.5) / 3 in the table.
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "W"]));
    assert!(stdout(&o).contains("mean time per pair 3.167 s (over 3)"), "{}", stdout(&o));
}

#[test]
fn eval_reports_missing_and_corrupt_results_and_excludes_them() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("trainingQ");
    weighted_scenes(&root);
    std::fs::write(root.join("Teddy/disp0W.pfm"), b"Pf\n2 1\n-1\n\x00\x00").unwrap(); // short data
    std::fs::remove_file(root.join("Mystery/disp0W.pfm")).unwrap();
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "W", "--format", "json"]));
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    let scenes: Vec<&str> = v["scenes"].as_object().unwrap().keys().map(String::as_str).collect();
    assert_eq!(scenes, ["PianoL"]);
    let excluded = v["excluded"].as_object().unwrap();
    assert!(excluded["Teddy"].as_str().unwrap().contains("disp0W.pfm"), "{excluded:?}");
    assert!(excluded["Mystery"].as_str().unwrap().contains("no result file"), "{excluded:?}");
    assert_eq!(metric(&v["weighted"], "avgerr"), 2.0);
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "W"]));
    let out = stdout(&o);
    assert!(out.contains("1 of 3 scenes evaluated") && out.contains("Excluded from the averages:"), "{out}");
    // Every scene missing: still a report, no panic.
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "Nothing", "--format", "json"]));
    assert_eq!(o.status.code(), Some(2));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert!(v["weighted"].is_null() && v["excluded"].as_object().unwrap().len() == 3);
}

#[test]
fn eval_paper_column_from_file_or_jem_data() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("trainingQ");
    weighted_scenes(&root);
    let data = tmp.path().join("data");
    std::fs::create_dir_all(&data).unwrap();
    let tsv = data.join("paper-results.tsv");
    std::fs::write(&tsv, "# test\nscene\tweight\tP\tQ\nTeddy\t1.0\t3.0\t9\nPianoL\t0.5\t6.0\t9\n").unwrap();

    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "W", "--paper", "P", "--paper-file"]).arg(&tsv));
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.lines().any(|l| l.starts_with("Teddy") && l.contains("4.00") && l.contains("3.00")), "{out}");
    // The paper's weighted average with the file's weights: (3 + 0.5·6) / 1.5 = 4.
    assert!(out.lines().any(|l| l.starts_with("weighted") && l.contains("2.40") && l.contains("4.00")), "{out}");

    let o = run(jem()
        .args(["eval", root.to_str().unwrap(), "--alg", "W", "--paper", "P", "--format", "json"])
        .env("JEM_DATA", &data));
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["paper"]["column"], "P");
    assert_eq!(v["paper"]["scenes"]["Teddy"], 3.0);
    assert!((v["paper"]["weighted"].as_f64().unwrap() - 4.0).abs() < 1e-12);

    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "W", "--paper", "Nope"]).env("JEM_DATA", &data));
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("P, Q"), "{}", stderr(&o));
    let o = run(jem()
        .args(["eval", root.to_str().unwrap(), "--alg", "W", "--paper", "P"])
        .env("JEM_DATA", tmp.path().join("nowhere")));
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--paper") && stderr(&o).contains("nowhere"), "{}", stderr(&o));
    // Without --paper the file is never needed.
    let o = run(jem().args(["eval", root.to_str().unwrap(), "--alg", "W"]).env("JEM_DATA", tmp.path().join("nowhere")));
    assert!(o.status.success(), "{}", stderr(&o));
}

/// `$JEM_DATA`, else `../shared/middlebury` beside the crate.
fn data_dir() -> PathBuf {
    match std::env::var_os("JEM_DATA") {
        Some(d) if !d.is_empty() => PathBuf::from(d),
        _ => Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/middlebury"),
    }
}

#[test]
fn eval_ground_truth_against_itself_on_trainingq_is_zero() {
    let dir = data_dir().join("MiddEval3/trainingQ");
    if !dir.is_dir() {
        eprintln!("skipped: no MiddEval3 data at {} (set JEM_DATA)", dir.display());
        return;
    }
    let scenes = jem::eval::find_gt_scenes(&dir).unwrap();
    assert_eq!(scenes.len(), 15);
    for s in &scenes {
        let gt = s.join("disp0GT.pfm");
        let ndisp = jem::io::calib::read_ndisp(&s.join("calib.txt")).unwrap();
        for mode in [MaskMode::Nonocc, MaskMode::All] {
            let m = evaluate_files(&gt, &gt, Some(&s.join("mask0nocc.png")), ndisp, 4, mode).unwrap();
            assert!(m.pixels > 10_000, "{}: {} pixels", s.display(), m.pixels);
            assert_eq!(m.values(), [0.0; 9], "{} {mode:?}", s.display());
        }
    }
    // The paper's "Avg" rows come back from its per-scene numbers with the MiddEval3 weights (PianoL, Playroom, Playtable, Shelves, Vintage count half).
    let paper = PaperResults::load(&data_dir().join("paper-results.tsv")).unwrap();
    for (col, avg) in [("LCM", 7.32), ("FCM", 6.58), ("JEM_LRC", 6.34), ("JEM_SPS", 5.52), ("JEM_ALL", 5.33)] {
        let c = paper.column(col).unwrap();
        assert_eq!(c.scenes.len(), 15);
        // Our weight table, applied to the paper's per-scene numbers, gives the paper's average.
        let (mut sum, mut total) = (0.0, 0.0);
        for (scene, v) in &c.scenes {
            let w = jem::eval::scene_weight(scene);
            sum += w * v;
            total += w;
        }
        assert!((sum / total - avg).abs() <= 0.01, "{col}: {}", sum / total);
        assert!((c.weighted.unwrap() - avg).abs() <= 0.01, "{col}: {:?}", c.weighted);
    }
}

#[test]
fn batch_runs_good_scenes_and_reports_each_bad_one() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("data");
    write_shift_scene(&root.join("a/Good"), 64, 24, 5, 16, 1);
    write_shift_scene(&root.join("a/BadImage"), 64, 24, 5, 16, 2);
    std::fs::write(root.join("a/BadImage/im1.png"), b"\x89PNG\r\n\x1a\ngarbage").unwrap();
    write_shift_scene(&root.join("b/BadCalib"), 64, 24, 5, 16, 3);
    std::fs::write(root.join("b/BadCalib/calib.txt"), "ndisp=lots\n").unwrap();
    write_shift_scene(&root.join("b/Sizes"), 64, 24, 5, 16, 4);
    image::RgbImage::new(60, 24).save(root.join("b/Sizes/im1.png")).unwrap();
    std::fs::create_dir_all(root.join("c/NotAScene")).unwrap();
    let cfg = wta_config(tmp.path());

    let o = run(jem().arg("batch").arg(&root).args(["--alg", "T", "--config"]).arg(&cfg));
    assert_eq!(o.status.code(), Some(2), "{}\n{}", stdout(&o), stderr(&o));
    let (out, err) = (stdout(&o), stderr(&o));
    // Plain progress (stderr is not a terminal): one line per scene, in path order.
    let lines: Vec<&str> = err.lines().filter(|l| l.starts_with('[')).collect();
    assert_eq!(lines.len(), 4, "{err}");
    assert!(lines[0].starts_with("[1/4] BadImage: FAILED: ") && lines[0].contains("im1.png"), "{err}");
    assert!(lines[1].starts_with("[2/4] Good: 64x24, ndisp 16, "), "{err}");
    // The time left, once a scene has finished, from its pipeline time and the two scenes left.
    assert!(!lines[0].contains("ETA") && lines[1].ends_with(" s, ETA 0 s"), "{err}");
    assert!(lines[2].starts_with("[3/4] BadCalib: FAILED: ") && lines[2].contains("ndisp"), "{err}");
    assert!(lines[3].starts_with("[4/4] Sizes: FAILED: ") && lines[3].contains("60x24"), "{err}");
    // The summary table and the failures.
    assert!(out.lines().any(|l| l.starts_with("Good") && l.contains("64x24") && l.ends_with("ok")), "{out}");
    assert!(out.contains("4 scene(s): 1 done, 0 skipped, 3 failed"), "{out}");
    assert!(out.contains("failures:\n  BadImage ("), "{out}");

    // The good scene's result recovers the shift away from the borders; the time file holds one number.
    let good = root.join("a/Good");
    let disp = jem::io::pfm::read_pfm(&good.join("disp0T.pfm")).unwrap();
    assert_eq!(disp.dims(), (64, 24));
    for y in 4..20 {
        for x in 13..56 {
            assert_eq!(disp.at(x, y), 5.0, "({x}, {y})");
        }
    }
    let time = std::fs::read_to_string(good.join("timeT.txt")).unwrap();
    assert!(time.ends_with('\n') && time.trim().split('.').nth(1).map(str::len) == Some(6), "{time:?}");
    assert!(time.trim().parse::<f64>().unwrap() >= 0.0);
    for bad in ["a/BadImage", "b/BadCalib", "b/Sizes"] {
        assert!(!root.join(bad).join("disp0T.pfm").exists(), "{bad}");
    }
    // Nothing but the result, its time and its configuration was added (atomic writes leave no temporary files).
    let mut names: Vec<String> =
        std::fs::read_dir(&good).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(names, ["calib.txt", "configT.toml", "disp0T.pfm", "im0.png", "im1.png", "timeT.txt"]);

    // --quiet keeps the failures (stderr) and drops the rest.
    let o = run(jem().arg("batch").arg(&root).args(["--alg", "T", "-q", "--config"]).arg(&cfg));
    assert_eq!(o.status.code(), Some(2));
    assert!(stdout(&o).is_empty());
    assert_eq!(stderr(&o).lines().filter(|l| l.contains("FAILED")).count(), 3, "{}", stderr(&o));

    // With the good scene alone, two jobs: success.
    let o = run(jem().arg("batch").arg(&good).args(["--alg", "T2", "-j", "2", "-v", "--config"]).arg(&cfg));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).lines().next().unwrap().contains("cost"), "-v adds stage columns: {}", stdout(&o));
}

#[test]
fn batch_usage_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let o = run(jem().arg("batch").arg(tmp.path()).args(["--alg", "T"]));
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("no scene folder"), "{}", stderr(&o));
    let o = run(jem().arg("batch").arg(tmp.path()).args(["--alg", "../x"]));
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--alg"), "{}", stderr(&o));
    let o = run(jem().arg("batch").arg(tmp.path()).args(["--alg", "T", "--shard", "4/3"]));
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("I/N"), "{}", stderr(&o));
}

#[test]
fn batch_shards_cover_every_scene_exactly_once() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("set");
    let names = ["S0", "S1", "S2", "S3", "S4", "S5", "S6"];
    for (k, n) in names.iter().enumerate() {
        write_shift_scene(&root.join(n), 32, 12, 2, 4, k as u64);
    }
    let cfg = wta_config(tmp.path());
    for i in 1..=3 {
        let o = run(jem()
            .arg("batch")
            .arg(&root)
            .args(["--alg", &format!("P{i}"), "--shard", &format!("{i}/3"), "-q", "--config"])
            .arg(&cfg));
        assert!(o.status.success(), "{}", stderr(&o));
    }
    for (k, n) in names.iter().enumerate() {
        let owners: Vec<usize> = (1..=3).filter(|i| root.join(n).join(format!("disp0P{i}.pfm")).exists()).collect();
        assert_eq!(owners, [k % 3 + 1], "{n}");
    }
}

#[test]
fn batch_skip_existing_leaves_finished_scenes_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("set");
    write_shift_scene(&root.join("A"), 32, 12, 2, 4, 7);
    write_shift_scene(&root.join("B"), 32, 12, 2, 4, 8);
    // A finished result: a PFM of the scene's size (its values are not looked at).
    let finished = jem::io::pfm::encode_pfm(&jem::Plane::new(32, 12, 1.5f32));
    std::fs::write(root.join("A/disp0K.pfm"), &finished).unwrap();
    let cfg = wta_config(tmp.path());
    let o = run(jem().arg("batch").arg(&root).args(["--alg", "K", "--skip-existing", "--config"]).arg(&cfg));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("[1/2] A: skipped"), "{}", stderr(&o));
    assert!(stdout(&o).contains("2 scene(s): 1 done, 1 skipped, 0 failed"), "{}", stdout(&o));
    assert_eq!(std::fs::read(root.join("A/disp0K.pfm")).unwrap(), finished);
    assert!(!root.join("A/timeK.txt").exists());
    assert!(jem::io::pfm::read_pfm(&root.join("B/disp0K.pfm")).is_ok());
    // Without the flag, the scene is redone.
    let o = run(jem().arg("batch").arg(&root).args(["--alg", "K", "-q", "--config"]).arg(&cfg));
    assert!(o.status.success());
    assert_ne!(std::fs::read(root.join("A/disp0K.pfm")).unwrap(), finished);
}

/// Only a result that parses and has the scene's size counts as done; an empty, truncated,
/// foreign or wrongly sized file is redone (it was skipped before).
#[test]
fn skip_existing_needs_a_complete_result() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("set");
    let full = jem::io::pfm::encode_pfm(&jem::Plane::new(32, 12, 1.5f32));
    let cases: [(&str, Vec<u8>); 4] = [
        ("Empty", Vec::new()),
        ("Truncated", full[..full.len() / 2].to_vec()),
        ("Foreign", b"placeholder".to_vec()),
        ("WrongSize", jem::io::pfm::encode_pfm(&jem::Plane::new(31, 12, 1.5f32))),
    ];
    for (i, (name, bytes)) in cases.iter().enumerate() {
        write_shift_scene(&root.join(name), 32, 12, 2, 4, 20 + i as u64);
        std::fs::write(root.join(name).join("disp0K.pfm"), bytes).unwrap();
    }
    let cfg = wta_config(tmp.path());
    let o = run(jem().arg("batch").arg(&root).args(["--alg", "K", "--skip-existing", "--config"]).arg(&cfg));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("4 scene(s): 4 done, 0 skipped, 0 failed"), "{}", stdout(&o));
    for (name, _) in &cases {
        let d = jem::io::pfm::read_pfm(&root.join(name).join("disp0K.pfm")).unwrap();
        assert_eq!(d.dims(), (32, 12), "{name}");
    }
}

fn png_dims_and_pixel(path: &Path, x: u32, y: u32) -> ((u32, u32), [u8; 3]) {
    let img = image::open(path).unwrap().to_rgb8();
    (img.dimensions(), img.get_pixel(x, y).0)
}

#[test]
fn viz_single_map_error_map_and_contact_sheet() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("trainingQ/Tiny");
    hand_scene(&scene);
    let out = tmp.path().join("v.png");
    let o = run(jem().args(["viz"]).arg(scene.join("disp0X.pfm")).arg("-o").arg(&out));
    assert!(o.status.success(), "{}", stderr(&o));
    // Range 0..10 from calib.txt: pixel (2, 0) is invalid → black; (0, 0) = 1 → colormap(0.1).
    assert_eq!(png_dims_and_pixel(&out, 2, 0), ((4, 2), [0, 0, 0]));
    assert_eq!(png_dims_and_pixel(&out, 0, 0).1, jem::viz::colormap(0.1));
    // --vmin/--vmax win over calib.txt.
    let o =
        run(jem().args(["viz"]).arg(scene.join("disp0X.pfm")).args(["--vmin", "1", "--vmax", "2"]).arg("-o").arg(&out));
    assert!(o.status.success());
    assert_eq!(png_dims_and_pixel(&out, 0, 0).1, jem::viz::colormap(0.0));
    // With --gt: disparity | 4 px gap | error map. Scale 4 from trainingQ: pixel 1 (error 2.5) is bad (red),
    // pixel 0 exact (white), pixel 3 has no GT (dark grey).
    let o = run(jem()
        .args(["viz"])
        .arg(scene.join("disp0X.pfm"))
        .arg("--gt")
        .arg(scene.join("disp0GT.pfm"))
        .arg("-o")
        .arg(&out));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(png_dims_and_pixel(&out, 8, 0), ((12, 2), [255, 255, 255]));
    assert_eq!(png_dims_and_pixel(&out, 9, 0).1, [230, 30, 30]);
    assert_eq!(png_dims_and_pixel(&out, 11, 0).1, [48, 48, 48]);
    // A folder: one row per scene with im0.png and the result.
    let second = tmp.path().join("trainingQ/Other");
    hand_scene(&second);
    for s in [&scene, &second] {
        image::RgbImage::from_pixel(4, 2, image::Rgb([9, 9, 9])).save(s.join("im0.png")).unwrap();
    }
    let sheet = tmp.path().join("sheet.png");
    let o = run(jem().arg("viz").arg(tmp.path().join("trainingQ")).args(["--alg", "X", "-o"]).arg(&sheet));
    assert!(o.status.success(), "{}", stderr(&o));
    let two_rows = image::open(&sheet).unwrap().to_rgb8();
    let has = |img: &image::RgbImage, c: [u8; 3]| img.pixels().filter(|p| p.0 == c).count();
    // Both rows' left images, the labels and column titles (light text), the colour bar's two ends.
    assert_eq!(has(&two_rows, [9, 9, 9]), 2 * 4 * 2, "the two left panels, whole");
    assert!(has(&two_rows, [235, 235, 235]) > 200, "names and headers");
    assert!(
        has(&two_rows, jem::viz::colormap(0.0)) >= 14 && has(&two_rows, jem::viz::colormap(1.0)) >= 14,
        "a colour bar"
    );
    assert!(stderr(&o).contains("2 rows (Other, Tiny)"), "{}", stderr(&o));
    // A scene that cannot be drawn is left out with a warning; the others still make a sheet.
    std::fs::write(second.join("disp0X.pfm"), b"Pf\n9 9\n-1\n").unwrap();
    let o = run(jem().arg("viz").arg(tmp.path().join("trainingQ")).args(["--alg", "X", "-o"]).arg(&sheet));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("warning: ") && stderr(&o).contains("Other"), "{}", stderr(&o));
    let one_row = image::open(&sheet).unwrap().to_rgb8();
    assert_eq!(has(&one_row, [9, 9, 9]), 4 * 2, "one left panel");
    assert!(one_row.height() < two_rows.height());
    // Wrong uses are errors, not panics.
    let o = run(jem().arg("viz").arg(tmp.path().join("trainingQ")).arg("-o").arg(&sheet));
    assert_eq!(o.status.code(), Some(2));
    let o = run(jem().arg("viz").arg(scene.join("disp0X.pfm")).arg("-o").arg(tmp.path().join("v.jpg")));
    assert_eq!(o.status.code(), Some(2));
}

/// `post.sps.segments` above what the image holds (pixels / `post.sps.min_support`: 307 on a
/// 64 × 48 scene) gives one warning naming the key and the bound, in `jem` and in `jem batch`, and the map of the
/// bound (1a367fa: accepted silently up to 2^24; 50000 wrecked Teddy, avgErr 1.79 → 30.4). Under the bound
/// nothing is said and nothing changes.
#[test]
fn absurd_segment_counts_are_held_to_the_image_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("set").join("S");
    let jem_in = |args: &[&str]| run(jem().current_dir(dir.path()).args(args));
    let out = jem_in(&["synth", scene.to_str().unwrap(), "--width", "64", "--height", "48", "--ndisp", "16"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let pair = [scene.join("im0.png"), scene.join("im1.png")];
    let mut maps = Vec::new();
    for (segments, warned) in [("50000", true), ("307", false)] {
        let out_file = dir.path().join(format!("d{segments}.pfm"));
        let set = format!("post.sps.segments={segments}");
        let args = [pair[0].to_str().unwrap(), pair[1].to_str().unwrap(), "-o", out_file.to_str().unwrap()];
        let out = jem_in(&[&args[..], &["--set", &set]].concat());
        let err = stderr(&out);
        assert!(out.status.success(), "{err}");
        assert_eq!(err.contains("warning: post.sps.segments = 50000") && err.contains("using 307"), warned, "{err}");
        assert_eq!(err.lines().filter(|l| l.contains("warning")).count(), usize::from(warned), "one line: {err}");
        maps.push(std::fs::read(&out_file).unwrap());
    }
    assert_eq!(maps[0], maps[1], "the map of the bound");
    let set = dir.path().join("set");
    let out = jem_in(&["batch", set.to_str().unwrap(), "--alg", "A", "--set", "post.sps.segments=50000"]);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("S: warning: post.sps.segments = 50000") && err.contains("using 307"), "{err}");
    assert_eq!(std::fs::read(scene.join("disp0A.pfm")).unwrap(), maps[1], "batch holds it to the bound too");
}
