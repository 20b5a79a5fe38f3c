//! The matcher against the pipeline it wraps, and what it does besides the match.

use std::path::PathBuf;

use super::*;
use crate::synth::{SynthParams, render_scene};

/// The matcher gives the pipeline's map, byte for byte, and says how it set the run up.
#[test]
fn a_matcher_runs_the_pipeline_on_a_borrowed_pair() {
    let scene = render_scene(&SynthParams { width: 96, height: 64, ndisp: 16, seed: 4 }).unwrap();
    let params = Params::default();
    let mut matcher = Matcher::new(params.clone()).unwrap().with_ndisp(NdispSource::Given(scene.ndisp));
    let out = matcher.match_pair(&scene.left, &scene.right).unwrap();
    let pair = crate::image::StereoPair::borrowed(&scene.left, &scene.right, scene.ndisp).unwrap();
    let direct = pipeline::run(&params, &pair).unwrap();
    assert_eq!(out.disparity.data, direct.disparity.data);
    assert_eq!((out.plan.ndisp, out.plan.ndisp_measured, out.plan.tiles), (scene.ndisp, false, None));
    assert!(out.plan.memory_bytes > 0 && out.seconds > 0.0);
}

#[test]
fn reliable_disparity_drops_the_pixels_below_the_confidence() {
    let scene = render_scene(&SynthParams { width: 64, height: 48, ndisp: 16, seed: 2 }).unwrap();
    let mut matcher = Matcher::new(Params::default()).unwrap().with_ndisp(NdispSource::Given(16));
    let out = matcher.match_pair(&scene.left, &scene.right).unwrap();
    let kept = out.reliable_disparity(0.95).unwrap();
    let confidence = out.confidence.as_ref().unwrap();
    for ((&d, &k), &c) in out.disparity.data.iter().zip(&kept.data).zip(&confidence.data) {
        assert!(if c < 0.95 { k.is_infinite() } else { k.to_bits() == d.to_bits() });
    }
    assert_eq!(out.reliable_disparity(0.0).unwrap().data, out.disparity.data);
    for outside in [-0.1, 1.5, f32::NAN] {
        let e = out.reliable_disparity(outside).unwrap_err().to_string();
        assert!(e.starts_with("invalid min_confidence") && e.contains("from 0 to 1"), "{e}");
    }
}

/// A matcher told not to compute the confidence map skips that stage and gives the same disparity map.
#[test]
fn the_confidence_is_computed_only_when_asked_for() {
    let scene = render_scene(&SynthParams { width: 64, height: 48, ndisp: 16, seed: 5 }).unwrap();
    let matcher = Matcher::new(Params::default()).unwrap().with_ndisp(NdispSource::Given(16));
    let with = matcher.clone().match_pair(&scene.left, &scene.right).unwrap();
    let without = matcher.with_confidence(false).match_pair(&scene.left, &scene.right).unwrap();
    assert!(with.confidence.is_some() && without.confidence.is_none());
    assert!(without.reliable_disparity(0.5).is_err() && without.confidence_map().is_err());
    let bits = |o: &Output| o.disparity.data.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&with), bits(&without));
    let stages = |o: &Output| o.timings.stages.iter().map(|(name, _)| *name).collect::<Vec<_>>();
    assert!(stages(&with).contains(&"confidence") && !stages(&without).contains(&"confidence"));
}

/// A small rig: equal pinhole cameras, the right one 0.1 to the right and turned by 1° about the vertical.
fn small_rig() -> crate::rectify::StereoCalibration {
    use crate::rectify::Intrinsics;
    let k =
        |cx: f64| Intrinsics { matrix: [[90.0, 0.0, cx], [0.0, 90.0, 32.0], [0.0, 0.0, 1.0]], distortion: [0.0; 8] };
    let (c, s) = (1f64.to_radians().cos(), 1f64.to_radians().sin());
    crate::rectify::StereoCalibration {
        path: PathBuf::from("rig.yml"),
        cameras: [k(48.0), k(47.0)],
        rotation: [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        translation: [-0.1, 0.0, 0.0],
        image_size: Some((96, 64)),
        given: None,
        prerectified: None,
    }
}

/// A matcher with a rectification matches the rectified pair, as rectifying first and matching after does,
/// and gives the rectified left view; its pair check's warnings doubt the calibration, not the rectifying.
#[test]
fn a_matcher_with_a_rectification_matches_the_rectified_pair() {
    let scene = render_scene(&SynthParams { width: 96, height: 64, ndisp: 16, seed: 3 }).unwrap();
    let rect = small_rig().rectification((96, 64)).unwrap();
    let plain = Matcher::new(Params::default()).unwrap().with_ndisp(NdispSource::Given(16));
    let (l, r) = rect.rectify_pair(&scene.left, &scene.right).unwrap();
    let expected = plain.clone().match_pair(&l, &r).unwrap();
    let mut rectifying = plain.with_rectification(rect).with_checks(true);
    let out = rectifying.match_pair(&scene.left, &scene.right).unwrap();
    let bits = |o: &Output| o.disparity.data.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&out), bits(&expected));
    let rectified = out.rectified.as_ref().unwrap();
    assert_eq!((&rectified.left.channels, rectified.calibration.as_path()), (&l.channels, Path::new("rig.yml")));
    assert_eq!(rectifying.search_range(&scene.left, &scene.right).unwrap(), (16, false));
    let mut offset = out.clone();
    let check = offset.checks.as_mut().unwrap();
    check.vertical_px = Some(check.vertical_limit_px + 5.0);
    let (plain_words, words) = (check.warnings().join(" "), offset.warnings().join(" "));
    assert!(plain_words.contains("rectify it with --rectify CALIB"), "{plain_words}");
    assert!(words.contains("after --rectify rig.yml") && !words.contains("rectify it with"), "{words}");
    let small = RgbImage::new(64, 48);
    assert!(rectifying.match_pair(&small, &small).unwrap_err().to_string().contains("rectification is for 96x64"));
}

/// A bound on the confidence gives the map of the reliable pixels, with the confidence computed though it
/// was not asked for, and the pair checked on the map before the bound.
#[test]
fn a_matcher_with_a_confidence_bound_keeps_the_reliable_pixels() {
    let scene = render_scene(&SynthParams { width: 64, height: 48, ndisp: 16, seed: 2 }).unwrap();
    let matcher = Matcher::new(Params::default()).unwrap().with_ndisp(NdispSource::Given(16)).with_checks(true);
    let full = matcher.clone().match_pair(&scene.left, &scene.right).unwrap();
    let mut bounded = matcher.with_confidence(false).with_min_confidence(0.95).unwrap();
    let out = bounded.match_pair(&scene.left, &scene.right).unwrap();
    assert_eq!(out.disparity.data, full.reliable_disparity(0.95).unwrap().data);
    assert!(out.disparity.data.iter().any(|d| d.is_infinite()) && out.confidence.is_some());
    assert_eq!(out.checks.map(|c| c.to_string()), full.checks.map(|c| c.to_string()));
    assert!(Matcher::new(Params::default()).unwrap().with_min_confidence(1.5).is_err());
}

#[test]
fn invalid_parameters_are_refused_when_the_matcher_is_built() {
    assert!(Matcher::new(Params { downscale: 0, ..Params::default() }).is_err());
}
