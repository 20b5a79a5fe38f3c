//! The temporal model through the public API: a `Matcher` that remembers frames, on synthetic sequences with exact
//! ground truth (`jem::synth` renders them in memory).

use jem::synth::{GainChange, MASK_VISIBLE, Motion, SequenceParams, SynthParams, render_frame};
use jem::{FrameKind, Matcher, NdispSource, Output, Params};

/// Frames of a synthetic sequence: the pairs and their ground truth with its mask.
fn frames(motion: Motion, noise: f64, n: usize) -> Vec<jem::synth::SynthScene> {
    frames_lit(motion, noise, n, GainChange::default())
}

/// [`frames`] under a changing exposure.
fn frames_lit(motion: Motion, noise: f64, n: usize, gain: GainChange) -> Vec<jem::synth::SynthScene> {
    frames_of(SynthParams { width: 200, height: 140, ndisp: 32, seed: 5 }, motion, noise, n, gain)
}

/// [`frames_lit`] of `scene`.
fn frames_of(
    scene: SynthParams,
    motion: Motion,
    noise: f64,
    n: usize,
    gain: GainChange,
) -> Vec<jem::synth::SynthScene> {
    let params = SequenceParams { scene, frames: n, motion, noise_sigma: noise, gain };
    (0..n).map(|k| render_frame(&params, k).unwrap().0).collect()
}

/// Matches every frame with one matcher (remembering frames or not).
fn run(scenes: &[jem::synth::SynthScene], temporal: bool) -> Vec<Output> {
    run_with(Params::default(), scenes, temporal)
}

/// [`run`] with `params`.
fn run_with(params: Params, scenes: &[jem::synth::SynthScene], temporal: bool) -> Vec<Output> {
    let matcher = Matcher::new(params).unwrap().with_ndisp(NdispSource::Given(32));
    let mut matcher = matcher.with_temporal(temporal);
    scenes.iter().map(|s| matcher.match_pair(&s.left, &s.right).unwrap()).collect()
}

/// Mean absolute error over the visible pixels.
fn error(out: &Output, s: &jem::synth::SynthScene) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for ((d, g), m) in out.disparity.data().iter().zip(s.gt.data()).zip(s.mask.data()) {
        if *m == MASK_VISIBLE && d.is_finite() {
            sum += f64::from((d - g).abs());
            n += 1;
        }
    }
    sum / n as f64
}

/// Mean |d_t − d_{t−1}| over the pixels visible in both frames (a still scene: the truth did not move).
fn flicker(a: &Output, b: &Output, s: &jem::synth::SynthScene) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for ((x, y), m) in a.disparity.data().iter().zip(b.disparity.data()).zip(s.mask.data()) {
        if *m == MASK_VISIBLE {
            sum += f64::from((x - y).abs());
            n += 1;
        }
    }
    sum / n as f64
}

#[test]
fn a_still_noisy_camera_settles_and_gains_accuracy() {
    let scenes = frames(Motion::Static, 8.0, 7);
    let (alone, remembered) = (run(&scenes, false), run(&scenes, true));
    let kinds: Vec<Option<FrameKind>> = remembered.iter().map(|o| o.frame).collect();
    assert_eq!(kinds[0], Some(FrameKind::First));
    assert!(kinds[1..].iter().all(|k| matches!(k, Some(FrameKind::Still { .. }))), "{kinds:?}");
    assert_eq!(kinds[6], Some(FrameKind::Still { frames: 7 }));
    assert!(alone.iter().all(|o| o.frame.is_none()));
    // The first frame is matched exactly as alone.
    assert_eq!(remembered[0].disparity, alone[0].disparity);
    let late = |outs: &[Output]| (3..7).map(|k| error(&outs[k], &scenes[k])).sum::<f64>() / 4.0;
    let changes = |outs: &[Output]| (4..7).map(|k| flicker(&outs[k], &outs[k - 1], &scenes[k])).sum::<f64>() / 3.0;
    let (err_alone, err_kept) = (late(&alone), late(&remembered));
    let (flicker_alone, flicker_kept) = (changes(&alone), changes(&remembered));
    eprintln!(
        "frames 4–7: error {err_alone:.3} alone, {err_kept:.3} remembered; flicker {flicker_alone:.3}, {flicker_kept:.3}"
    );
    assert!(err_kept < 0.9 * err_alone, "error {err_kept:.3} against {err_alone:.3}");
    assert!(flicker_kept < 0.5 * flicker_alone, "flicker {flicker_kept:.3} against {flicker_alone:.3}");
}

/// Frames 4–7's mean error and frames 5–7's mean flicker.
fn late_error_and_flicker(outs: &[Output], scenes: &[jem::synth::SynthScene]) -> (f64, f64) {
    let err = (3..7).map(|k| error(&outs[k], &scenes[k])).sum::<f64>() / 4.0;
    (err, (4..7).map(|k| flicker(&outs[k], &outs[k - 1], &scenes[k])).sum::<f64>() / 3.0)
}

#[test]
fn a_still_camera_under_a_changing_exposure_stays_still_and_settles() {
    // ±5 % gain each frame and a 10 % step at frame 3: every frame but the first still, the means never restart.
    let gain = GainChange { jitter: 0.05, step: 0.1, step_at: 3 };
    let scenes = frames_lit(Motion::Static, 6.0, 7, gain);
    let (alone, remembered) = (run(&scenes, false), run(&scenes, true));
    let kinds: Vec<Option<FrameKind>> = remembered.iter().map(|o| o.frame).collect();
    assert_eq!(kinds[6], Some(FrameKind::Still { frames: 7 }), "{kinds:?}");
    let step = remembered[3].exposure.expect("the step is compensated");
    assert!((step.gain - 1.1).abs() < 0.07, "{step:?}");
    let (err_alone, flicker_alone) = late_error_and_flicker(&alone, &scenes);
    let (err_kept, flicker_kept) = late_error_and_flicker(&remembered, &scenes);
    eprintln!(
        "gain: error {err_alone:.3} alone, {err_kept:.3} remembered; flicker {flicker_alone:.3}, {flicker_kept:.3}"
    );
    assert!(err_kept < 0.9 * err_alone, "error {err_kept:.3} against {err_alone:.3}");
    assert!(flicker_kept < 0.5 * flicker_alone, "flicker {flicker_kept:.3} against {flicker_alone:.3}");
}

#[test]
fn a_panning_camera_whose_exposure_steps_is_still_moving_with_the_step_compensated() {
    let scenes = frames_lit(Motion::Pan, 0.0, 3, GainChange { step: 0.1, step_at: 2, ..Default::default() });
    let remembered = run(&scenes, true);
    // The sideways motion has parallax: carried by its shift or by its 3D motion, it is a moving camera.
    assert!(
        matches!(remembered[2].frame, Some(FrameKind::Moving { .. } | FrameKind::Travelling { .. })),
        "{:?}",
        remembered[2].frame
    );
    let step = remembered[2].exposure.expect("the step is compensated");
    assert!((step.gain - 1.1).abs() < 0.02 && step.offset.abs() < 2.0, "{step:?}");
    assert_eq!(remembered[1].exposure, None, "no exposure change, nothing compensated");
}

#[test]
fn a_still_camera_with_a_moving_object_is_still_and_as_accurate_as_matching_alone() {
    // At `jem synth`'s size the object is a small part of the view: a still camera.
    let scene = SynthParams { width: 320, height: 240, ndisp: 32, seed: 1 };
    let scenes = frames_of(scene, Motion::Object, 2.0, 6, GainChange::default());
    let (alone, remembered) = (run(&scenes, false), run(&scenes, true));
    let kinds: Vec<_> = remembered.iter().map(|o| o.frame).collect();
    assert!(kinds[1..].iter().all(|k| matches!(k, Some(FrameKind::Still { .. }))), "{kinds:?}");
    let mean = |outs: &[Output]| (1..6).map(|k| error(&outs[k], &scenes[k])).sum::<f64>() / 5.0;
    let (err_alone, err_kept) = (mean(&alone), mean(&remembered));
    eprintln!("moving object: error {err_alone:.4} alone, {err_kept:.4} remembered");
    // The object and what it uncovers are released from the previous answer; the rest gains from the means.
    assert!(err_kept < 1.02 * err_alone, "error {err_kept:.4} against {err_alone:.4}");
}

#[test]
fn a_clean_still_camera_gives_the_same_answer_every_frame() {
    let scenes = frames(Motion::Static, 0.0, 4);
    let (alone, remembered) = (run(&scenes, false), run(&scenes, true));
    for (a, r) in alone.iter().zip(&remembered) {
        assert_eq!(a.disparity, r.disparity);
    }
}

#[test]
fn a_scene_cut_forgets_the_past_and_the_frame_after_it_is_matched_alone() {
    let scenes = frames(Motion::Cut, 0.0, 6);
    let (alone, remembered) = (run(&scenes, false), run(&scenes, true));
    let cut = remembered.iter().position(|o| o.frame == Some(FrameKind::Cut)).expect("a cut is found");
    assert!(remembered.iter().filter(|o| o.frame == Some(FrameKind::Cut)).count() == 1);
    assert_eq!(remembered[cut].disparity, alone[cut].disparity, "the frame after the cut");
}

#[test]
fn a_panning_camera_takes_the_previous_answer_and_stays_as_accurate() {
    let scenes = frames(Motion::Pan, 0.0, 5);
    let (alone, remembered) = (run(&scenes, false), run(&scenes, true));
    let moving = |o: &Output| matches!(o.frame, Some(FrameKind::Moving { .. } | FrameKind::Travelling { .. }));
    assert!(remembered[1..].iter().all(moving), "a moving camera is found");
    // The comparison with the previous frame is timed as the first stage of every frame that has one.
    let first_stage = |o: &Output| o.timings.stages.first().map(|(name, _)| *name);
    assert!(
        remembered[1..].iter().all(|o| first_stage(o) == Some("motion"))
            && first_stage(&remembered[0]) != Some("motion")
    );
    let mean = |outs: &[Output]| (1..5).map(|k| error(&outs[k], &scenes[k])).sum::<f64>() / 4.0;
    let (a, r) = (mean(&alone), mean(&remembered));
    assert!(r < 1.1 * a + 0.02, "panning: {r:.3} remembered against {a:.3} alone");
}

#[test]
fn a_remembered_sequence_is_the_same_whatever_the_thread_count() {
    // With an exposure that changes each frame: the fits are the same too.
    let scenes = frames_lit(Motion::Object, 4.0, 4, GainChange { jitter: 0.05, ..Default::default() });
    let with = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| run(&scenes, true))
    };
    let (one, two) = (with(1), with(2));
    for (a, b) in one.iter().zip(&two) {
        assert_eq!(a.disparity, b.disparity);
        assert_eq!(a.frame, b.frame);
        assert_eq!(a.exposure, b.exposure);
    }
    assert!(one.iter().any(|o| o.exposure.is_some()), "an exposure change was compensated");
}

#[test]
fn reset_starts_a_new_sequence() {
    let scenes = frames(Motion::Static, 6.0, 3);
    let mut matcher = Matcher::new(Params::default()).unwrap().with_ndisp(NdispSource::Given(32)).with_temporal(true);
    let first = matcher.match_pair(&scenes[0].left, &scenes[0].right).unwrap();
    let second = matcher.match_pair(&scenes[1].left, &scenes[1].right).unwrap();
    assert!(matches!(second.frame, Some(FrameKind::Still { frames: 2 })));
    matcher.reset();
    let again = matcher.match_pair(&scenes[0].left, &scenes[0].right).unwrap();
    assert_eq!((again.frame, &again.disparity), (Some(FrameKind::First), &first.disparity));
}

/// A camera driving forward: the scene expands from the focus of expansion, near things faster than far ones, and no
/// global shift explains it. The previous answer is carried by the camera's 3D motion (fitted to tracked points),
/// and the frames are at least as accurate as matched alone.
#[test]
fn a_camera_driving_forward_is_carried_by_its_motion() {
    let scenes = frames(Motion::Dolly, 0.0, 4);
    let (alone, remembered) = (run(&scenes, false), run(&scenes, true));
    let kinds: Vec<_> = remembered.iter().map(|o| o.frame).collect();
    assert!(kinds[1..].iter().all(|k| matches!(k, Some(FrameKind::Travelling { .. }))), "{kinds:?}");
    let mean = |outs: &[Output]| (1..4).map(|k| error(&outs[k], &scenes[k])).sum::<f64>() / 3.0;
    let (a, r) = (mean(&alone), mean(&remembered));
    eprintln!("dolly: {r:.4} remembered against {a:.4} alone");
    assert!(r <= 1.02 * a, "dolly: {r:.4} remembered against {a:.4} alone");
}

/// A moving frame takes its large allocations from those the frame before it left; a copy of the matcher starts
/// without them (they are scratch, not state), and the maps are the same either way, on a pan and on a drive.
#[test]
fn moving_frames_give_the_same_maps_with_or_without_the_previous_frames_buffers() {
    for motion in [Motion::Pan, Motion::Dolly] {
        let scenes = frames(motion, 0.0, 3);
        let kept = run(&scenes, true);
        let mut matcher =
            Matcher::new(Params::default()).unwrap().with_ndisp(NdispSource::Given(32)).with_temporal(true);
        for (s, k) in scenes.iter().zip(&kept) {
            matcher = matcher.clone();
            let out = matcher.match_pair(&s.left, &s.right).unwrap();
            assert_eq!((out.frame, &out.disparity), (k.frame, &k.disparity), "{motion:?}");
        }
        assert!(kept[1..].iter().all(|o| !matches!(o.frame, Some(FrameKind::First | FrameKind::Cut))));
    }
}

/// A driving camera's frames on an image large enough that inference groups its labels (here a reference size of a
/// quarter of the image's pixels: labels two at a time): the carried answer's label bands are grouped with the labels,
/// so the frame runs in the grouped run's memory, and it is at least as accurate as matched alone.
#[test]
fn a_large_travelling_frame_keeps_its_bands_on_grouped_labels() {
    let scenes = frames(Motion::Dolly, 0.0, 4);
    let mut params = Params::default();
    params.meanfield.reference_px = (200 * 140 / 4) as f32;
    let (alone, remembered) = (run_with(params.clone(), &scenes, false), run_with(params, &scenes, true));
    let ran = |o: &Output, stage: &str| o.timings.stages.iter().any(|(name, _)| *name == stage);
    for o in &remembered[1..] {
        assert!(matches!(o.frame, Some(FrameKind::Travelling { .. })), "{:?}", o.frame);
        assert!(ran(o, "group labels") && ran(o, "bands"), "{:?}", o.timings.stages);
    }
    let mean = |outs: &[Output]| (1..4).map(|k| error(&outs[k], &scenes[k])).sum::<f64>() / 3.0;
    let (a, r) = (mean(&alone), mean(&remembered));
    eprintln!("grouped dolly: {r:.4} remembered against {a:.4} alone");
    assert!(r <= 1.02 * a, "grouped dolly: {r:.4} remembered against {a:.4} alone");
}
