//! Accuracy regression on the Middlebury 2014 training scenes at quarter resolution.
//!
//! Each test runs a shipped config over all 15 trainingQ scenes in-process and scores it with MiddEval3's rules
//! (nonocc mask, errors ×4 in full-resolution pixels, weighted average with five scenes at half weight). It fails
//! when the weighted avgErr rises above the value achieved when the config was tuned plus a margin.
//!
//! Every test here runs the pipeline on real pairs, together about 6 to 7 minutes on 2 cores, so they are all
//! `#[ignore]`d: `cargo test --release` (the README's command) leaves them out, `.ci/run` runs them (`--
//! --include-ignored`), and so does `cargo test --release --test regression -- --include-ignored`.
//!
//! Margins: the pipeline is deterministic (byte-identical output for any thread count), so on one machine the
//! achieved value is reproduced exactly; the margin (0.05 px, under 1% of the values) only absorbs floating-point
//! differences between CPUs and compilers (e.g. `exp` and FMA contraction), while catching any real regression.

mod common;

use std::path::Path;

use common::Pair;
use jem::degrade::{View, degrade};
use jem::eval::{MaskMode, evaluate, scene_weight};
use jem::{DisparityMap, Params, RgbImage};

/// A trainingQ scene folder's pair (each view passed through `view`) and its scorer: the avgErr of a disparity map
/// under MiddEval3's rules (nonocc, errors ×4).
fn scene(dir: &Path, view: impl Fn(RgbImage, View) -> RgbImage) -> (Pair, impl Fn(&DisparityMap) -> f64) {
    let left = view(jem::io::read_image(&dir.join("im0.png")).unwrap(), View::Left);
    let right = view(jem::io::read_image(&dir.join("im1.png")).unwrap(), View::Right);
    let ndisp = jem::io::calib::read_ndisp(&dir.join("calib.txt")).unwrap();
    let gt = jem::io::pfm::read_pfm(&dir.join("disp0GT.pfm")).unwrap();
    let mask = jem::io::read_grey8(&dir.join("mask0nocc.png")).unwrap();
    let score = move |d: &DisparityMap| evaluate(d, &gt, Some(&mask), ndisp, 4, MaskMode::Nonocc).avgerr;
    (Pair::new(left, right, ndisp), score)
}

/// The mean avgErr of `off` and of the default on Adirondack, Motorcycle and Teddy, each view passed through
/// `view` (a mechanism's test on real pairs: the default with it, `off` without).
fn off_and_default(data: &Path, off: &Params, view: impl Fn(RgbImage, View) -> RgbImage) -> [f64; 2] {
    let mut errors = [0.0f64; 2];
    for name in ["Adirondack", "Motorcycle", "Teddy"] {
        let dir = data.join("MiddEval3/trainingQ").join(name);
        let (pair, score) = scene(&dir, &view);
        for (k, params) in [off, &Params::default()].into_iter().enumerate() {
            errors[k] += score(&pair.run(params).disparity) / 3.0;
        }
    }
    errors
}

/// Runs `config` on every trainingQ scene and returns (per-scene avgErr, weighted avgErr).
fn weighted_avgerr(data: &Path, config: &str) -> (Vec<(String, f64)>, f64) {
    let params = Params::load(Some(&common::repo().join("configs").join(config)), &[]).expect("config");
    let mut per_scene = Vec::new();
    let (mut sum, mut weights) = (0.0, 0.0);
    for dir in common::training_scenes(data) {
        let name = dir.file_name().unwrap().to_string_lossy().into_owned();
        let (pair, score) = scene(&dir, |image, _| image);
        let m = score(&pair.run(&params).disparity);
        let w = scene_weight(&name);
        sum += w * m;
        weights += w;
        per_scene.push((name, m));
    }
    assert_eq!(per_scene.len(), 15, "expected the 15 trainingQ scenes");
    (per_scene, sum / weights)
}

/// Runs `config` and fails if its weighted avgErr exceeds `achieved + margin`; returns it (`None` without data).
fn check(config: &str, achieved: f64, margin: f64) -> Option<f64> {
    let data = common::data_dir()?;
    let (per_scene, weighted) = weighted_avgerr(&data, config);
    for (name, e) in &per_scene {
        eprintln!("{config} {name:<12} {e:6.2}");
    }
    eprintln!("{config} weighted avgErr {weighted:.3} (achieved when tuned: {achieved})");
    assert!(weighted <= achieved + margin, "{config}: weighted avgErr {weighted:.3} > {achieved} + {margin}");
    Some(weighted)
}

/// The paper's Table 1: each model within its achieved value + margin, and the paper's ordering JEM < FCM < LCM.
#[test]
#[ignore = "slow: every trainingQ scene under each config (about 7 min on 2 cores); run it with `cargo test --release -- --include-ignored`, as .ci/run does"]
fn table1_configs_trainingq() {
    let Some(jem) = check("jem-lrc.toml", JEM_LRC_ACHIEVED, 0.05) else { return };
    let fcm = check("fcm-lrc.toml", FCM_LRC_ACHIEVED, 0.05).unwrap();
    let lcm = check("lcm-lrc.toml", LCM_LRC_ACHIEVED, 0.05).unwrap();
    assert!(jem < fcm && fcm < lcm, "Table 1 ordering: JEM {jem:.3}, FCM {fcm:.3}, LCM {lcm:.3}");
}

/// The paper's full pipeline (Table 3, last column) and the default (it, plus the adaptive front end),
/// which must stay better.
#[test]
#[ignore = "slow: every trainingQ scene under each config (about 7 min on 2 cores); run it with `cargo test --release -- --include-ignored`, as .ci/run does"]
fn full_pipeline_and_default_trainingq() {
    let Some(paper) = check("jem-all.toml", JEM_ALL_ACHIEVED, 0.05) else { return };
    let default = check("default.toml", DEFAULT_ACHIEVED, 0.05).unwrap();
    assert!(default < paper, "default {default:.3} should beat the paper's pipeline {paper:.3}");
}

/// The speed preset between the default and fast.toml (the local term only, 2 iterations, 4 prior levels).
#[test]
#[ignore = "slow: every trainingQ scene under each config (about 7 min on 2 cores); run it with `cargo test --release -- --include-ignored`, as .ci/run does"]
fn balanced_trainingq() {
    check("balanced.toml", BALANCED_ACHIEVED, 0.05);
}

#[test]
#[ignore = "slow: every trainingQ scene under each config (about 7 min on 2 cores); run it with `cargo test --release -- --include-ignored`, as .ci/run does"]
fn jem_sps_trainingq() {
    check("jem-sps.toml", JEM_SPS_ACHIEVED, 0.05);
}

// Each config's weighted avgErr on trainingQ as it stands (docs/RESULTS.md; how each got there: docs/tuning-log.md).
// A test allows 0.05 above it: room for a harmless change, not for a regression.
/// `configs/jem-lrc.toml` (the paper: 6.34).
const JEM_LRC_ACHIEVED: f64 = 6.279;
/// `configs/fcm-lrc.toml` (the paper: 6.58).
const FCM_LRC_ACHIEVED: f64 = 6.415;
/// `configs/lcm-lrc.toml` (the paper: 7.32).
const LCM_LRC_ACHIEVED: f64 = 6.581;
/// `configs/jem-all.toml`, the paper's full pipeline (the paper: 5.33).
const JEM_ALL_ACHIEVED: f64 = 4.938;
/// `configs/default.toml`, the built-in defaults (3.584 before the median at depth edges, 3.434 before the sub-pixel
/// refinement, 3.304 before the second median's rejected pixels, band, window and colour σ, 3.246 before the ternary
/// Census).
const DEFAULT_ACHIEVED: f64 = 3.234;
/// `configs/balanced.toml` (3.698 before the median at depth edges, 3.505 before the sub-pixel refinement, 3.405
/// before the second median's changes, 3.338 before the ternary Census).
const BALANCED_ACHIEVED: f64 = 3.318;
/// `configs/jem-sps.toml` (the paper: 5.52). The planes are the stage most sensitive to small perturbations: other
/// RANSAC seeds (`post.sps.seed` = 2, 3) give 5.164 and 5.146, inside the margin.
const JEM_SPS_ACHIEVED: f64 = 5.123;

/// One camera out of focus, on real pairs: the right view of three trainingQ scenes blurred (σ 1.5 px). The default
/// measures the views' sharpness and blurs the sharper one for the cost; without that the Census codes of the
/// left view's fine texture have no counterpart (all 15 scenes: 8.12 -> 6.16, docs/tuning-log.md).
#[test]
#[ignore = "slow: three trainingQ scenes, each twice (about 20 s on 2 cores, 55 s under load); run it with `cargo test --release -- --include-ignored`, as .ci/run does"]
fn one_view_out_of_focus_trainingq() {
    let Some(data) = common::data_dir() else { return };
    let mut off = Params::default();
    off.condition.sharpness_ratio = 0.0;
    let blur = "blur:1.5".parse().unwrap();
    let errors = off_and_default(&data, &off, |image, view| match view {
        View::Left => image,
        View::Right => degrade(&image, &blur, view, 1).unwrap(),
    });
    eprintln!("right view blurred σ 1.5: sharpness not matched {:.3}, matched {:.3}", errors[0], errors[1]);
    assert!(errors[1] < 0.85 * errors[0], "matched {:.3}, not matched {:.3}", errors[1], errors[0]);
}

/// JPEG at quality 90, what a camera or phone writes, on real pairs: both views of three trainingQ scenes. The
/// compression error (about 2 grey levels) is invisible to the one-image noise estimate; the default measures it
/// from the block DCT's quantisation and counts it as noise, and its Census ignores steps below the block grid's
/// (docs/tuning-log.md, "JPEG compression noise"). The prior's floor where the cost is flat does part of the same
/// work, and the median at depth edges undoes part of the same errors, so the gain is modest: these three scenes
/// 2.557 -> 2.445 when written, 2.390 -> 2.339 since that median (all 15: 4.63 -> 4.57, bad2 27.97 -> 26.97 %).
#[test]
#[ignore = "slow: three trainingQ scenes, each twice (about 20 s on 2 cores, 55 s under load); run it with `cargo test --release -- --include-ignored`, as .ci/run does"]
fn jpeg_compression_trainingq() {
    let Some(data) = common::data_dir() else { return };
    let mut off = Params::default();
    off.condition.noise.jpeg = false;
    off.condition.noise.block_band = 0.0;
    let recipe = "jpeg:90".parse().unwrap();
    let errors = off_and_default(&data, &off, |image, view| degrade(&image, &recipe, view, 1).unwrap());
    eprintln!("JPEG quality 90: compression not measured {:.3}, measured {:.3}", errors[0], errors[1]);
    assert!(errors[1] < 0.99 * errors[0], "measured {:.3}, not measured {:.3}", errors[1], errors[0]);
}
