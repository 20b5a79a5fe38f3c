//! KITTI 2012/2015 and ETH3D trees as distributed, built in temp folders from synthetic scenes (`jem synth`):
//! `jem batch` and `jem eval` recognise each layout, write the benchmark's submission files outside the data set,
//! leave the data set untouched, and score with the benchmark's rules (D1 checked against a hand computation).

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::{run_in, stderr};
use jem::Plane;
use jem::io::pfm;

/// Renders a synthetic scene (MiddEval3 layout, 320×240, ndisp 48) into `dir`.
fn synth(dir: &Path, seed: u32) {
    std::fs::create_dir_all(dir.parent().unwrap()).unwrap();
    let out = run_in(dir.parent().unwrap(), &["synth", dir.to_str().unwrap(), "--seed", &seed.to_string()]);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                files.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    files
}

/// KITTI ground truth from a synthetic scene: non-occluded (mask 255) or all pixels with truth (mask > 0).
fn kitti_truth(scene: &Path, all: bool) -> Plane<f32> {
    let gt = pfm::read_pfm(&scene.join("disp0GT.pfm")).unwrap();
    let mask = jem::io::read_grey8(&scene.join("mask0nocc.png")).unwrap();
    let data = gt
        .data()
        .iter()
        .zip(mask.data())
        .map(|(&d, &m)| if (all && m > 0) || m == 255 { d } else { f32::INFINITY })
        .collect();
    Plane::from_vec(gt.width(), gt.height(), data).unwrap()
}

/// A KITTI 2015 training tree (`image_2/`, `image_3/`, `disp_noc_0/`, `disp_occ_0/`) with frames 000000_10 and
/// 000001_10 from synthetic scenes, plus an `_11` frame that must be ignored.
fn kitti2015(root: &Path, scenes: &[PathBuf]) -> PathBuf {
    let tree = root.join("kitti2015").join("training");
    for sub in ["image_2", "image_3", "disp_noc_0", "disp_occ_0"] {
        std::fs::create_dir_all(tree.join(sub)).unwrap();
    }
    for (k, scene) in scenes.iter().enumerate() {
        let frame = format!("{k:06}_10.png");
        std::fs::copy(scene.join("im0.png"), tree.join("image_2").join(&frame)).unwrap();
        std::fs::copy(scene.join("im1.png"), tree.join("image_3").join(&frame)).unwrap();
        jem::io::write_disparity(&tree.join("disp_noc_0").join(&frame), &kitti_truth(scene, false)).unwrap();
        jem::io::write_disparity(&tree.join("disp_occ_0").join(&frame), &kitti_truth(scene, true)).unwrap();
        let next = format!("{k:06}_11.png");
        std::fs::copy(scene.join("im0.png"), tree.join("image_2").join(&next)).unwrap();
        std::fs::copy(scene.join("im1.png"), tree.join("image_3").join(&next)).unwrap();
    }
    tree
}

/// D1 by hand: % of truth pixels with |d − gt| > 3 and > 5 % of gt (no invalid pixels in `result`).
fn d1_by_hand(result: &Plane<f32>, gt: &Plane<f32>) -> f64 {
    let (mut n, mut bad) = (0, 0);
    for (&d, &g) in result.data().iter().zip(gt.data()) {
        if g.is_finite() {
            n += 1;
            let e = (d - g).abs();
            bad += usize::from(e > 3.0 && e > 0.05 * g);
        }
    }
    100.0 * bad as f64 / n as f64
}

/// `scenes.SCENE.KEY` of a `jem eval --format json` report.
fn json_value(json: &str, scene: &str, key: &str) -> f64 {
    let v: serde_json::Value = serde_json::from_str(json).unwrap();
    v["scenes"][scene][key].as_f64().unwrap_or_else(|| panic!("no scenes.{scene}.{key} in {json}"))
}

#[test]
fn kitti2015_batch_and_eval() {
    let dir = tempfile::tempdir().unwrap();
    let scenes: Vec<PathBuf> = (1..=2).map(|s| dir.path().join(format!("s{s}"))).collect();
    for (k, s) in scenes.iter().enumerate() {
        synth(s, k as u32 + 1);
    }
    let tree = kitti2015(dir.path(), &scenes);
    let before = snapshot(&tree);
    let out = run_in(dir.path(), &["batch", tree.to_str().unwrap(), "--alg", "Jem"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let results = dir.path().join("kitti2015").join("results").join("Jem").join("training");
    assert!(stderr(&out).contains(&results.join("disp_0").display().to_string()), "{}", stderr(&out));
    assert_eq!(snapshot(&tree), before, "the data set is untouched");
    assert_eq!(common::files_in(&results.join("disp_0")), ["000000_10.png", "000001_10.png"], "only _10 frames");
    assert_eq!(common::files_in(&results.join("time")), ["000000_10.txt", "000001_10.txt"]);
    assert_eq!(common::files_in(&results.join("config")), ["000000_10.toml", "000001_10.toml"]);
    let d = jem::io::read_disparity(&results.join("disp_0").join("000000_10.png")).unwrap();
    assert_eq!(d.dims(), (320, 240));
    // KITTI's default range, 192, is at least half of this 320-pixel width, so it is measured on the pair
    // instead (the synthetic disparities stay below 48).
    let summary = String::from_utf8(out.stdout.clone()).unwrap();
    let row = summary.lines().find(|l| l.starts_with("000000_10")).unwrap_or_else(|| panic!("{summary}"));
    let ndisp: usize = row.split_whitespace().nth(2).unwrap().parse().unwrap();
    assert!((48..192).contains(&ndisp), "{row}");

    // Eval: D1 of the real result (the default pipeline is dense) against a hand computation.
    let out = run_in(dir.path(), &["eval", tree.to_str().unwrap(), "--alg", "Jem", "--format", "json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let json = String::from_utf8(out.stdout).unwrap();
    assert!(json.contains("\"layout\": \"kitti2015\""), "{json}");
    let gt = jem::io::read_disparity(&tree.join("disp_noc_0").join("000000_10.png")).unwrap();
    assert!(d.data().iter().all(|v| v.is_finite()));
    let want = d1_by_hand(&d, &gt);
    assert!((json_value(&json, "000000_10", "d1") - want).abs() < 1e-9, "{json} vs {want}");
    assert!(want < 10.0, "the synthetic scene is matched: D1 {want}");

    // A result made by hand: outliers where x % 4 == 0 (error 4 > 3 px and > 5 % of a disparity < 48), small
    // errors elsewhere, and the first column invalid (filled from its right neighbour, as KITTI's devkit does).
    let frame = results.join("disp_0").join("000001_10.png");
    let gt = jem::io::read_disparity(&tree.join("disp_occ_0").join("000001_10.png")).unwrap();
    let w = gt.width();
    let truth_or_zero: Vec<f32> = gt.data().iter().map(|g| if g.is_finite() { *g } else { 10.0 }).collect();
    let mut made: Vec<f32> = truth_or_zero
        .iter()
        .enumerate()
        .map(|(i, &g)| if (i % w).is_multiple_of(4) { g + 4.0 } else { g + 1.5 })
        .collect();
    let filled: Vec<f32> = (0..made.len()).map(|i| if i % w == 0 { made[i + 1] } else { made[i] }).collect();
    for i in (0..made.len()).step_by(w) {
        made[i] = f32::INFINITY;
    }
    jem::io::write_disparity(&frame, &Plane::from_vec(w, gt.height(), made).unwrap()).unwrap();
    let want = d1_by_hand(&Plane::from_vec(w, gt.height(), filled).unwrap(), &gt);
    let invalid = 100.0 * (0..gt.data().len()).filter(|i| i % w == 0 && gt.data()[*i].is_finite()).count() as f64
        / gt.data().iter().filter(|g| g.is_finite()).count() as f64;
    let out =
        run_in(dir.path(), &["eval", tree.to_str().unwrap(), "--alg", "Jem", "--mask", "all", "--format", "json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let json = String::from_utf8(out.stdout).unwrap();
    assert!((json_value(&json, "000001_10", "d1") - want).abs() < 1e-6, "{json} vs {want}");
    assert!((json_value(&json, "000001_10", "invalid") - invalid).abs() < 1e-9, "{json} vs {invalid}");
    assert!(want > 20.0 && want < 30.0, "about a quarter of the pixels are outliers: {want}");

    // The text table leads with D1.
    let out = run_in(dir.path(), &["eval", tree.to_str().unwrap(), "--alg", "Jem"]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("kitti2015") && text.lines().any(|l| l.starts_with("scene") && l.contains("D1")), "{text}");

    // A testing split, with the same frame names, gets its own results folder; the training results are kept.
    let testing = dir.path().join("kitti2015").join("testing");
    for sub in ["image_2", "image_3"] {
        std::fs::create_dir_all(testing.join(sub)).unwrap();
        std::fs::copy(tree.join(sub).join("000000_10.png"), testing.join(sub).join("000000_10.png")).unwrap();
    }
    let kept = snapshot(&results);
    let out = run_in(dir.path(), &["batch", testing.to_str().unwrap(), "--alg", "Jem"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(results.with_file_name("testing").join("disp_0/000000_10.png").is_file());
    assert_eq!(snapshot(&results), kept);
}

#[test]
fn kitti2012_grey_images() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("s");
    synth(&scene, 3);
    let tree = dir.path().join("data_stereo_flow").join("training");
    for sub in ["image_0", "image_1", "disp_noc", "disp_occ"] {
        std::fs::create_dir_all(tree.join(sub)).unwrap();
    }
    for (src, sub) in [("im0.png", "image_0"), ("im1.png", "image_1")] {
        image::open(scene.join(src)).unwrap().to_luma8().save(tree.join(sub).join("000005_10.png")).unwrap();
    }
    jem::io::write_disparity(&tree.join("disp_noc").join("000005_10.png"), &kitti_truth(&scene, false)).unwrap();
    jem::io::write_disparity(&tree.join("disp_occ").join("000005_10.png"), &kitti_truth(&scene, true)).unwrap();
    let out = run_in(dir.path(), &["batch", tree.to_str().unwrap(), "--alg", "G", "--ndisp", "48"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let result = dir.path().join("data_stereo_flow/results/G/training/disp_0/000005_10.png");
    assert!(result.is_file());
    let out = run_in(dir.path(), &["eval", tree.to_str().unwrap(), "--alg", "G", "--format", "csv"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let csv = String::from_utf8(out.stdout).unwrap();
    assert!(csv.starts_with("alg,mask,scale,scene,weight,d1,avgerr,"), "{csv}");
    let row = csv.lines().find(|l| l.contains(",000005_10,")).unwrap();
    let d1: f64 = row.split(',').nth(5).unwrap().parse().unwrap();
    assert!(d1 < 15.0, "grey KITTI 2012 frame matched: {row}");
}

#[test]
fn eth3d_batch_and_eval() {
    let dir = tempfile::tempdir().unwrap();
    let images = dir.path().join("two_view_training");
    let truth = dir.path().join("two_view_training_gt");
    for (name, seed) in [("forest_1s", 4), ("lakeside_1l", 5)] {
        let scene = images.join(name);
        synth(&scene, seed);
        // ETH3D's calib.txt states ndisp = the width; the ground truth lives in the parallel tree.
        let calib = std::fs::read_to_string(scene.join("calib.txt")).unwrap();
        let calib: String = calib
            .lines()
            .map(|l| if l.starts_with("ndisp=") { "ndisp=320\n".into() } else { format!("{l}\n") })
            .collect();
        std::fs::write(scene.join("calib.txt"), calib).unwrap();
        std::fs::create_dir_all(truth.join(name)).unwrap();
        for f in ["disp0GT.pfm", "mask0nocc.png"] {
            std::fs::rename(scene.join(f), truth.join(name).join(f)).unwrap();
        }
    }
    let before = (snapshot(&images), snapshot(&truth));
    let out = run_in(dir.path(), &["batch", "two_view_training", "--alg", "Jem"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!((snapshot(&images), snapshot(&truth)), before, "the data set is untouched");
    let results = dir.path().join("results/Jem/two_view_training/low_res_two_view");
    assert_eq!(common::files_in(&results), ["forest_1s.pfm", "forest_1s.txt", "lakeside_1l.pfm", "lakeside_1l.txt"]);
    let runtime = std::fs::read_to_string(results.join("forest_1s.txt")).unwrap();
    let seconds: f64 = runtime.strip_prefix("runtime ").unwrap().trim().parse().unwrap();
    assert!(seconds > 0.0 && seconds < 60.0, "{runtime}");

    // Eval finds the truth beside the images, from either tree, or given with --gt; native pixels.
    for args in [
        vec!["eval", "two_view_training", "--alg", "Jem", "--format", "json"],
        vec!["eval", "two_view_training_gt", "--alg", "Jem", "--format", "json"],
        vec!["eval", "two_view_training", "--gt", "two_view_training_gt", "--alg", "Jem", "--format", "json"],
    ] {
        let out = run_in(dir.path(), &args);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        let json = String::from_utf8(out.stdout).unwrap();
        assert!(json.contains("\"layout\": \"eth3d\"") && json.contains("\"scale\": 1"), "{json}");
        for scene in ["forest_1s", "lakeside_1l"] {
            let bad2 = json_value(&json, scene, "bad2");
            assert!(bad2 < 10.0, "{scene}: bad2 {bad2} (the measured range must hold the disparities)");
        }
    }
}

/// `scripts/slurm-batch.sh` as two tasks of a job array (the Slurm variables set by hand): each runs its shard,
/// together they cover the data set once, a rerun skips what is done, and one eval scores the merged results.
#[test]
fn slurm_array_tasks_cover_the_data_set() {
    let dir = tempfile::tempdir().unwrap();
    let tree = dir.path().join("MiddEval3").join("trainingQ");
    for seed in 1..=3 {
        synth(&tree.join(format!("Scene{seed}")), seed);
    }
    let script = common::repo().join("scripts").join("slurm-batch.sh");
    let task = |id: &str| {
        let out = std::process::Command::new("bash")
            .arg(&script)
            .args([tree.to_str().unwrap(), "--alg", "Slurm"])
            .env("JEM", env!("CARGO_BIN_EXE_jem"))
            .env("SLURM_ARRAY_TASK_ID", id)
            .env("SLURM_ARRAY_TASK_MIN", "1")
            .env("SLURM_ARRAY_TASK_MAX", "2")
            .env("SLURM_CPUS_PER_TASK", "1")
            .env("SLURM_MEM_PER_NODE", "2000")
            .current_dir(dir.path())
            .output()
            .unwrap();
        assert!(out.status.success(), "task {id}: {}", stderr(&out));
        (String::from_utf8(out.stdout.clone()).unwrap(), stderr(&out))
    };
    let (first, log) = task("1");
    assert!(log.contains("shard 1/2") && log.contains("--threads 1") && log.contains("--max-memory 1800M"), "{log}");
    let done = |scene: &str| tree.join(scene).join("disp0Slurm.pfm").is_file();
    // Shard 1 of 2 holds pairs 0 and 2 of the sorted list.
    assert!(done("Scene1") && !done("Scene2") && done("Scene3"), "{first}");
    task("2");
    assert!(done("Scene2"));
    let (again, _) = task("1");
    assert!(again.contains("2 skipped"), "a resubmitted task skips finished pairs: {again}");
    let out = run_in(dir.path(), &["eval", tree.to_str().unwrap(), "--alg", "Slurm"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8(out.stdout).unwrap().contains("3 of 3 scenes evaluated"));
}

/// A KITTI tree with only `disp_occ_0/` (as many published samples ship) is scored with
/// `--mask all`, which needs only that folder (1ea02dd: "no scene with ground truth"); the default mask lists the
/// frame as missing its `disp_noc_0/` truth.
#[test]
fn kitti_with_only_disp_occ_is_scored_with_mask_all() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_in(dir.path(), &["synth", "S", "--width", "64", "--height", "48", "--ndisp", "16"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let tree = dir.path().join("k").join("training");
    for sub in ["image_2", "image_3", "disp_occ_0"] {
        std::fs::create_dir_all(tree.join(sub)).unwrap();
    }
    std::fs::copy(dir.path().join("S/im0.png"), tree.join("image_2/000000_10.png")).unwrap();
    std::fs::copy(dir.path().join("S/im1.png"), tree.join("image_3/000000_10.png")).unwrap();
    let truth = kitti_truth(&dir.path().join("S"), true);
    jem::io::write_disparity(&tree.join("disp_occ_0/000000_10.png"), &truth).unwrap();
    let results = dir.path().join("k/results/A/training/disp_0");
    std::fs::create_dir_all(&results).unwrap();
    let result =
        Plane::from_vec(64, 48, truth.data().iter().map(|g| if g.is_finite() { *g } else { 1.0 }).collect()).unwrap();
    jem::io::write_disparity(&results.join("000000_10.png"), &result).unwrap();
    let tree_arg = tree.to_str().unwrap();
    let out = run_in(dir.path(), &["eval", tree_arg, "--alg", "A", "--mask", "all", "--format", "json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(json_value(&String::from_utf8(out.stdout).unwrap(), "000000_10", "d1"), 0.0);
    let out = run_in(dir.path(), &["eval", tree_arg, "--alg", "A"]);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("0 of 1 scenes evaluated") && text.contains("disp_noc_0"), "{text}");
}

/// A KITTI frame with a left image and ground truth but no right image is a failed scene in
/// batch (exit 2, named; the other frames still run) and missing in eval (1ea02dd: batch exited 0 without listing
/// it, and eval reported "1 of 1 evaluated" over the frames it kept).
#[test]
fn a_kitti_frame_without_its_right_image_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_in(dir.path(), &["synth", "S", "--width", "64", "--height", "48", "--ndisp", "16"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let tree = dir.path().join("k").join("training");
    for sub in ["image_2", "image_3", "disp_noc_0"] {
        std::fs::create_dir_all(tree.join(sub)).unwrap();
    }
    let truth = kitti_truth(&dir.path().join("S"), false);
    for frame in ["000000_10.png", "000001_10.png"] {
        std::fs::copy(dir.path().join("S/im0.png"), tree.join("image_2").join(frame)).unwrap();
        jem::io::write_disparity(&tree.join("disp_noc_0").join(frame), &truth).unwrap();
    }
    std::fs::copy(dir.path().join("S/im1.png"), tree.join("image_3/000000_10.png")).unwrap();
    let tree_arg = tree.to_str().unwrap();
    let out = run_in(dir.path(), &["batch", tree_arg, "--alg", "A", "--set", "model=wta"]);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("000001_10") && text.contains("image_3"), "{text}");
    assert!(dir.path().join("k/results/A/training/disp_0/000000_10.png").is_file(), "the other frame runs");
    let out = run_in(dir.path(), &["eval", tree_arg, "--alg", "A"]);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("1 of 2 scenes evaluated") && text.contains("000001_10"), "{text}");
}

/// ETH3D: a scene of an ETH3D tree with its left image, calib.txt and ground truth but no right
/// image is a failed scene in batch (exit 2, named; the other scene still runs) and missing in eval (1ea02dd: the
/// folder was not taken for a scene at all, so batch exited 0 without listing it and eval reported "1 of 1").
#[test]
fn an_eth3d_scene_without_its_right_image_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let images = dir.path().join("two_view_training");
    let truth = dir.path().join("two_view_training_gt");
    for name in ["forest_1s", "lakeside_1l"] {
        let scene = images.join(name);
        let out =
            run_in(dir.path(), &["synth", scene.to_str().unwrap(), "--width", "64", "--height", "48", "--ndisp", "16"]);
        assert!(out.status.success(), "{}", stderr(&out));
        std::fs::create_dir_all(truth.join(name)).unwrap();
        for f in ["disp0GT.pfm", "mask0nocc.png"] {
            std::fs::rename(scene.join(f), truth.join(name).join(f)).unwrap();
        }
    }
    std::fs::remove_file(images.join("lakeside_1l/im1.png")).unwrap();
    let out = run_in(dir.path(), &["batch", "two_view_training", "--alg", "A", "--set", "model=wta"]);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("1 failed") && text.contains("lakeside_1l") && text.contains("im1.png"), "{text}");
    let results = dir.path().join("results/A/two_view_training/low_res_two_view");
    assert_eq!(common::files_in(&results), ["forest_1s.pfm", "forest_1s.txt"]);
    let out = run_in(dir.path(), &["eval", "two_view_training", "--alg", "A"]);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("1 of 2 scenes evaluated") && text.contains("lakeside_1l"), "{text}");
}

/// A KITTI 2015 tree at `root/NAME/SPLIT` with frame 000000_10 from the synthetic scene `scene` (64 × 48).
fn kitti_split(dir: &Path, scene: &str, seed: u32, tree: &str) -> PathBuf {
    let s = dir.join(scene);
    if !s.is_dir() {
        let out = run_in(
            dir,
            &["synth", scene, "--width", "64", "--height", "48", "--ndisp", "16", "--seed", &seed.to_string()],
        );
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let tree = dir.join(tree);
    for sub in ["image_2", "image_3", "disp_noc_0"] {
        std::fs::create_dir_all(tree.join(sub)).unwrap();
    }
    std::fs::copy(s.join("im0.png"), tree.join("image_2/000000_10.png")).unwrap();
    std::fs::copy(s.join("im1.png"), tree.join("image_3/000000_10.png")).unwrap();
    jem::io::write_disparity(&tree.join("disp_noc_0/000000_10.png"), &kitti_truth(&s, false)).unwrap();
    tree
}

/// This machine's name as jem writes it into a lock.
fn host() -> String {
    let name = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
    name.trim().chars().filter(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '.')).collect()
}

/// The lock line of this process's PID namespace: a pid is checked only against a lock of the same namespace.
fn pidns() -> String {
    format!("pidns {}\n", std::fs::read_link("/proc/self/ns/pid").unwrap().display())
}

/// KITTI's training and testing splits share frame names; two batches started together, one per
/// split, each write their own results folder (`results/A/training/`, `results/A/testing/`, each with its
/// `source.txt`) and both succeed (1ea02dd: one `results/A/` for both; in 3 of 5 tries both exited 0 and one run's
/// results were lost). A results folder is locked while a batch writes it: a second live writer is refused with the
/// lock named, a stale lock (its process gone) is taken over with a note, another part of the same sharded run
/// is let in, and MiddEval3 scene folders are locked the same way.
#[test]
fn each_split_its_own_results_folder_and_a_lock() {
    let dir = tempfile::tempdir().unwrap();
    let training = kitti_split(dir.path(), "s1", 1, "k/training");
    let testing = kitti_split(dir.path(), "s2", 2, "k/testing");
    let batch = |tree: &Path, extra: &[&str]| {
        let mut cmd = common::jem();
        cmd.current_dir(dir.path()).args(["batch", tree.to_str().unwrap(), "--alg", "A", "--set", "model=wta"]);
        cmd.args(extra).stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped());
        cmd.spawn().unwrap()
    };
    let (a, b) = (batch(&training, &[]), batch(&testing, &[]));
    for (child, split) in [(a, "training"), (b, "testing")] {
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "{split}: {}", stderr(&out));
        let folder = dir.path().join("k/results/A").join(split);
        assert!(folder.join("disp_0/000000_10.png").is_file(), "{split}");
        let source = std::fs::read_to_string(folder.join("source.txt")).unwrap();
        assert!(source.contains(&format!("root ../../../{split}\n")), "{source}");
        assert_eq!(common::files_in(&folder), ["config", "disp_0", "source.txt", "time"], "no lock left behind");
    }
    let out = run_in(dir.path(), &["eval", "k/training", "--alg", "A"]);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert!(out.status.success() && text.contains("1 of 1 scenes evaluated"), "{text}");

    // A live writer (this test process) holds the lock: refused, naming the lock; the results are untouched.
    let folder = dir.path().join("k/results/A/training");
    let lock = folder.join(".jem-lock");
    let result = folder.join("disp_0/000000_10.png");
    let before = std::fs::read(&result).unwrap();
    std::fs::write(&lock, format!("pid {}\nhost {}\n", std::process::id(), host())).unwrap();
    let out = batch(&training, &["--set", "post.fill=false"]).wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("is writing these results") && stderr(&out).contains(".jem-lock"),
        "{}",
        stderr(&out)
    );
    assert_eq!(std::fs::read(&result).unwrap(), before);
    assert!(lock.is_file(), "another run's lock is left alone");
    // The same from another machine (which this one cannot check).
    std::fs::write(&lock, "pid 1\nhost another-host.example\n").unwrap();
    let out = batch(&training, &[]).wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    // Part 2 of 2 beside a live part 1 of 2 runs; an unsharded run beside it does not.
    std::fs::remove_file(&lock).unwrap();
    let part1 = folder.join(".jem-lock-1-of-2");
    std::fs::write(&part1, format!("pid {}\nhost {}\n", std::process::id(), host())).unwrap();
    let out = batch(&training, &["--shard", "2/2"]).wait_with_output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let out = batch(&training, &[]).wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    // A stale lock: its process is gone. Taken over with a note, and removed at the end.
    std::fs::remove_file(&part1).unwrap();
    let mut gone = std::process::Command::new("true").spawn().unwrap();
    let dead = gone.id();
    gone.wait().unwrap();
    std::fs::write(&lock, format!("pid {dead}\nhost {}\n{}", host(), pidns())).unwrap();
    let out = batch(&training, &[]).wait_with_output().unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains(&format!("took over the lock of pid {dead}")), "{}", stderr(&out));
    assert!(!lock.exists());

    // MiddEval3: the scene folder's lock for the algorithm.
    let scene = dir.path().join("mid").join("S");
    std::fs::create_dir_all(scene.parent().unwrap()).unwrap();
    let out = run_in(dir.path(), &["synth", "mid/S", "--width", "64", "--height", "48", "--ndisp", "16"]);
    assert!(out.status.success(), "{}", stderr(&out));
    std::fs::write(scene.join(".jem-lock-A"), format!("pid {}\nhost {}\n", std::process::id(), host())).unwrap();
    let out = run_in(dir.path(), &["batch", "mid", "--alg", "A", "--set", "model=wta"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(!scene.join("disp0A.pfm").exists());
    let out = run_in(dir.path(), &["batch", "mid", "--alg", "B", "--set", "model=wta"]);
    assert!(out.status.success(), "another algorithm's results are another lock: {}", stderr(&out));
}

/// `source.txt` records the data set relative to the results folder and by a fingerprint (pair
/// names and image sizes), so results still evaluate after the tree is moved (`mv`) or copied (`cp -r`), or the
/// data set moved away from a `--results` folder; another data set's results are still refused (1ea02dd: an
/// absolute path, so after `mv` eval refused "holds the results of …/k/training, not of …").
#[test]
fn results_move_and_copy_with_their_data_set() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    kitti_split(d, "s1", 1, "k/training");
    let out = run_in(d, &["batch", "k/training", "--alg", "A", "--set", "model=wta"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let evaluates = |tree: &str, extra: &[&str]| {
        let out = run_in(d, &[&["eval", tree, "--alg", "A"][..], extra].concat());
        let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
        (out.status.success() && text.contains("1 of 1 scenes evaluated"), text)
    };
    std::fs::rename(d.join("k"), d.join("moved")).unwrap();
    let (ok, text) = evaluates("moved/training", &[]);
    assert!(ok, "moved: {text}");
    let out = std::process::Command::new("cp").args(["-r", "moved", "copy"]).current_dir(d).output().unwrap();
    assert!(out.status.success());
    let (ok, text) = evaluates("copy/training", &[]);
    assert!(ok, "copied: {text}");

    // Results kept apart (--results R); then the data set alone moves: found by its fingerprint.
    let out = run_in(d, &["batch", "copy/training", "--alg", "A", "--results", "R", "--set", "model=wta"]);
    assert!(out.status.success(), "{}", stderr(&out));
    std::fs::create_dir_all(d.join("laptop")).unwrap();
    std::fs::rename(d.join("copy/training"), d.join("laptop/training")).unwrap();
    let (ok, text) = evaluates("laptop/training", &["--results", "R"]);
    assert!(ok, "data set moved away from its results: {text}");
    // Another data set under the same name (other images): refused.
    kitti_split(d, "s2", 2, "other/training");
    let (ok, text) = evaluates("other/training", &["--results", "R"]);
    assert!(!ok && text.contains("holds the results of"), "{text}");
    let out = run_in(d, &["batch", "other/training", "--alg", "A", "--results", "R", "--set", "model=wta"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
}

/// `jem eval` while a batch still holds the results' lock: it scores them as they
/// are and says so in a warning naming the folder and the run, for a KITTI results folder and a MiddEval3 scene; a
/// stale lock (its process gone) says nothing, and `-q` silences the warning.
#[test]
fn eval_warns_while_a_batch_holds_the_results() {
    let dir = tempfile::tempdir().unwrap();
    let training = kitti_split(dir.path(), "s1", 1, "k/training");
    let out = run_in(dir.path(), &["batch", training.to_str().unwrap(), "--alg", "A", "--set", "model=wta", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let scene = dir.path().join("trainingQ/S");
    synth(&scene, 3);
    let out = run_in(dir.path(), &["batch", "trainingQ", "--alg", "A", "--set", "model=wta", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let live = format!("pid {}\nhost {}\n", std::process::id(), host());
    let mut child = std::process::Command::new("true").spawn().unwrap();
    let dead = format!("pid {}\nhost {}\n{}", child.id(), host(), pidns());
    child.wait().unwrap();
    for (tree, lock) in
        [("k/training", dir.path().join("k/results/A/training/.jem-lock")), ("trainingQ", scene.join(".jem-lock-A"))]
    {
        let eval = |extra: &[&str]| {
            let out = run_in(dir.path(), &[&["eval", tree, "--alg", "A"], extra].concat());
            assert!(out.status.success(), "{tree}: {}", stderr(&out));
            stderr(&out)
        };
        assert!(!eval(&[]).contains("warning"), "{tree}: no lock, no warning");
        std::fs::write(&lock, &live).unwrap();
        let text = eval(&[]);
        let line = text.lines().find(|l| l.starts_with("warning:")).unwrap_or_else(|| panic!("{tree}: {text}"));
        assert!(
            line.contains(&format!("pid {}", std::process::id())) && line.contains("is writing these results"),
            "{line}"
        );
        assert!(!eval(&["-q"]).contains("warning"), "{tree}: -q silences it");
        std::fs::write(&lock, &dead).unwrap();
        assert!(!eval(&[]).contains("warning"), "{tree}: a stale lock says nothing");
        std::fs::remove_file(&lock).unwrap();
    }
}
