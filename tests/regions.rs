//! The left-right mask (`jem match --lr-mask`, `jem batch --lr-mask`) and `jem eval --regions`.

mod common;

use common::{run_in, stderr};

/// The configuration that leaves the pixels the left-right check rejects invalid (`inf`): no fill, no weighted
/// median, no planes.
const NO_POST: [&str; 6] =
    ["--set", "post.fill=false", "--set", "post.wmedian.enabled=false", "--set", "post.sps.enabled=false"];

/// A synthetic scene (`jem synth`) in `dir/trainingF/Synth`: its folder name gives the scale 1.
fn scene(dir: &std::path::Path) -> std::path::PathBuf {
    let scene = dir.join("trainingF").join("Synth");
    let out = run_in(dir, &["synth", scene.to_str().unwrap(), "--width", "160", "--height", "120", "--ndisp", "24"]);
    assert!(out.status.success(), "{}", stderr(&out));
    scene
}

#[test]
fn the_lr_mask_is_where_the_unfilled_run_is_invalid() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let run = |extra: &[&str]| {
        let out = run_in(&s, &[&["match", "im0.png", "im1.png", "--threads", "1"], extra].concat());
        assert!(out.status.success(), "{extra:?}: {}", stderr(&out));
    };
    let read = |name: &str| std::fs::read(s.join(name)).unwrap();
    let rejected = |name: &str| -> Vec<bool> {
        let mask = jem::io::read_grey8(&s.join(name)).unwrap();
        assert!(mask.data().iter().all(|&v| v == 0 || v == jem::io::LR_REJECTED), "a binary mask");
        mask.data().iter().map(|&v| v == jem::io::LR_REJECTED).collect()
    };
    let invalid = |name: &str| -> Vec<bool> {
        jem::io::read_disparity(&s.join(name)).unwrap().data().iter().map(|d| !d.is_finite()).collect()
    };
    run(&["-o", "plain.pfm"]);
    run(&["-o", "flagged.pfm", "--lr-mask", "lr.png"]);
    // The disparity map is the same byte for byte with or without the mask.
    assert_eq!(read("plain.pfm"), read("flagged.pfm"), "--lr-mask changed the disparity map");
    // Without fill, weighted median and planes, the rejected pixels are exactly the invalid ones.
    run(&[&["-o", "raw.pfm", "--lr-mask", "lr_raw.png"][..], &NO_POST[..]].concat());
    let raw = rejected("lr_raw.png");
    assert_eq!(raw, invalid("raw.pfm"));
    let n = raw.iter().filter(|r| **r).count();
    assert!(n > 0 && n < raw.len() / 4, "some pixels, not most, are rejected: {n}");
    // The post-processing after the check does not change what the check rejects: without the coarse prior (which
    // runs the whole pipeline, post-processing included, on the reduced pair) the default run's mask is the raw
    // run's invalid pixels. With the prior the two runs' fine passes start from different priors.
    let no_prior = ["--set", "condition.enabled=false"];
    run(&[&["-o", "np.pfm", "--lr-mask", "np.png"][..], &no_prior[..]].concat());
    run(&[&["-o", "np_raw.pfm"][..], &no_prior[..], &NO_POST[..]].concat());
    assert_eq!(rejected("np.png"), invalid("np_raw.pfm"));
    // A mask is a PNG.
    let out = run_in(&s, &["match", "im0.png", "im1.png", "-o", "x.pfm", "--lr-mask", "lr.pfm"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains(".png"), "{}", stderr(&out));
}

#[test]
fn batch_writes_the_mask_and_eval_splits_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let s = scene(dir.path());
    let tree = dir.path().join("trainingF");
    let t = tree.to_str().unwrap();
    let out = run_in(dir.path(), &["batch", t, "--alg", "R", "--threads", "1", "--lr-mask", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(s.join("lrmask0R.png").is_file() && s.join("disp0R.pfm").is_file());
    let out = run_in(dir.path(), &["batch", t, "--alg", "P", "--threads", "1", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!s.join("lrmask0P.png").exists(), "no mask unless asked for");
    assert_eq!(std::fs::read(s.join("disp0R.pfm")).unwrap(), std::fs::read(s.join("disp0P.pfm")).unwrap());

    let out = run_in(dir.path(), &["eval", t, "--alg", "R", "--alg", "P", "--regions", "--format", "json", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for (k, with_mask) in [(0, true), (1, false)] {
        let report = &json[k];
        let avgerr = report["scenes"]["Synth"]["avgerr"].as_f64().unwrap();
        let split = &report["regions"]["scenes"]["Synth"];
        assert_eq!(split["lr_mask"].as_bool(), Some(with_mask));
        assert!((split["avgerr"].as_f64().unwrap() - avgerr).abs() < 1e-9);
        let sum = |key: &str, keys: &[&str]| keys.iter().map(|r| split[key][r].as_f64().unwrap_or(0.0)).sum::<f64>();
        let regions = jem::eval::REGION_KEYS;
        assert!((sum("error", &regions) - avgerr).abs() < 1e-9, "regions add up to avgErr: {split}");
        assert!((sum("by_size", &jem::eval::SIZE_KEYS) - avgerr).abs() < 1e-9, "sizes add up to avgErr: {split}");
        assert!((sum("pixels_pct", &regions) - 100.0).abs() < 1e-9);
        let gross = split["gross"]["total"].as_f64().unwrap();
        assert!(
            (sum("gross", &regions) - gross).abs() < 1e-9
                && (split["by_size"]["gt8"].as_f64().unwrap() - gross).abs() < 1e-9
        );
        assert_eq!(split["error"]["rejected"].is_null(), !with_mask);
        let weighted = &report["regions"]["weighted"];
        assert!((weighted["avgerr"].as_f64().unwrap() - report["weighted"]["avgerr"].as_f64().unwrap()).abs() < 1e-9);
    }
    // The text tables; the rejected column is "-" without the mask.
    let out = run_in(dir.path(), &["eval", t, "--alg", "P", "--regions", "-q"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("avgErr by region") && text.contains("by error size"), "{text}");
    assert!(text.contains("No lrmask0P.png"), "{text}");
    // CSV has no room for it.
    let out = run_in(dir.path(), &["eval", t, "--alg", "R", "--regions", "--format", "csv"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--regions"), "{}", stderr(&out));
}
