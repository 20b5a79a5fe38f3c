//! Stereo sequences end to end through the `jem` binary: `synth --frames`, `degrade --frames`, `sequence`, `eval`.

mod common;

use std::path::Path;

use common::{files_in, run_in, stderr};

/// Runs `jem ARGS` in `dir` and asserts success; returns stderr.
fn ok(dir: &Path, args: &[&str]) -> String {
    let out = run_in(dir, args);
    assert!(out.status.success(), "jem {args:?}: {}", stderr(&out));
    stderr(&out)
}

/// Runs `jem ARGS` in `dir` and asserts a one-line error (exit 2) mentioning every needle.
fn fails(dir: &Path, args: &[&str], needles: &[&str]) {
    let out = run_in(dir, args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "jem {args:?}: {err}");
    assert!(err.starts_with("error: ") && err.trim_end().lines().count() == 1, "not one error line: {err}");
    for n in needles {
        assert!(err.contains(n), "jem {args:?}: {err:?} lacks {n:?}");
    }
}

/// A small three-frame pan rendered into `dir/seq`.
fn small_pan(dir: &Path) {
    let args =
        ["synth", "seq", "--frames", "3", "--motion", "pan", "--width", "128", "--height", "80", "--ndisp", "24"];
    ok(dir, &args);
}

#[test]
fn an_independent_sequence_is_jem_match_frame_by_frame() {
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    let err = ok(dir.path(), &["sequence", "seq", "-o", "out", "--independent"]);
    assert!(err.contains("[3/3] 000002: ndisp 24"), "{err}");
    let last = err.trim_end().lines().last().unwrap();
    assert!(last.starts_with("wrote 3 frames to out (128×80, ndisp 24 from calib.txt,"), "{last}");
    assert_eq!(
        files_in(&dir.path().join("out")),
        ["000000.pfm", "000001.pfm", "000002.pfm", "config.toml", "sequence.txt", "times.txt"]
    );
    ok(dir.path(), &["--threads", "1", "sequence", "seq", "-o", "one", "--independent"]);
    for k in 0..3 {
        let (l, r) = (format!("seq/left/{k:06}.png"), format!("seq/right/{k:06}.png"));
        ok(dir.path(), &[&l, &r, "-o", "match.pfm", "--ndisp", "24"]);
        let expected = std::fs::read(dir.path().join("match.pfm")).unwrap();
        for folder in ["out", "one"] {
            let got = std::fs::read(dir.path().join(folder).join(format!("{k:06}.pfm"))).unwrap();
            assert!(got == expected, "frame {k} in {folder}/ differs from jem match");
        }
    }
    let times = std::fs::read_to_string(dir.path().join("out/times.txt")).unwrap();
    assert_eq!(times.lines().count(), 3, "{times}");
}

#[test]
fn a_rerun_skips_the_frames_already_written_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    let fast = ["--set", "model=wta"];
    ok(dir.path(), &[&["sequence", "seq", "-o", "out", "--independent"][..], &fast].concat());
    std::fs::remove_file(dir.path().join("out/000002.pfm")).unwrap();
    let err = ok(dir.path(), &[&["sequence", "seq", "-o", "out", "--independent"][..], &fast].concat());
    assert!(err.contains("skipped 2 frame(s) already written (000000 … 000001)"), "{err}");
    assert!(err.contains("(1 run, 2 already there;"), "{err}");
    let err = ok(dir.path(), &[&["sequence", "seq", "-o", "out", "--independent"][..], &fast].concat());
    assert!(err.trim_end().ends_with("nothing to do: all 3 frames are in out already"), "{err}");
    fails(dir.path(), &["sequence", "seq", "-o", "out", "--independent"], &["out/sequence.txt", "another run"]);
}

#[test]
fn eval_scores_a_sequence_from_its_results_folder() {
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    ok(dir.path(), &["sequence", "seq", "-o", "out", "--independent", "--set", "model=wta"]);
    let out = run_in(dir.path(), &["eval", "out"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<&str> = text.lines().skip(2).collect();
    assert_eq!(rows.len(), 4, "{text}");
    assert!(rows[0].starts_with("000000") && rows[3].starts_with("mean"), "{text}");
    assert!(stderr(&out).contains("scored 3 of 3 frames"), "{}", stderr(&out));
    // The truth named with --gt, as the sequence or its gt/ folder, scores the same.
    for gt in ["seq", "seq/gt"] {
        let again = run_in(dir.path(), &["eval", "out", "--gt", gt]);
        assert_eq!(
            String::from_utf8_lossy(&again.stdout).lines().skip(1).collect::<Vec<_>>(),
            text.lines().skip(1).collect::<Vec<_>>()
        );
    }
    let json = run_in(dir.path(), &["eval", "out", "--format", "json"]);
    let v: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    assert_eq!(v["frames"].as_object().unwrap().len(), 3);
    assert!(v["flicker"].as_f64().unwrap() >= 0.0 && v["mean"]["avgerr"].as_f64().unwrap() > 0.0, "{v}");
    fails(dir.path(), &["eval", "out", "--alg", "X"], &["without --alg"]);
    fails(dir.path(), &["eval", "seq"], &["--alg NAME"]);
}

#[test]
fn a_temporal_sequence_says_how_each_frame_was_matched_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    let err = ok(dir.path(), &["sequence", "seq", "-o", "out"]);
    assert!(err.contains("[1/3] 000000: ndisp 24, first frame"), "{err}");
    assert!(err.contains("[2/3] 000001: ndisp 24, camera moved"), "{err}");
    let last = std::fs::read(dir.path().join("out/000002.pfm")).unwrap();
    std::fs::remove_file(dir.path().join("out/000002.pfm")).unwrap();
    let err = ok(dir.path(), &["sequence", "seq", "-o", "out"]);
    assert!(err.contains("matched again"), "the rerun says it rebuilt the state: {err}");
    let closing = err.trim_end().lines().last().unwrap();
    assert!(closing.starts_with("wrote 3 frames to out (1 run, 2 already there (2 matched again"), "{closing}");
    assert_eq!(std::fs::read(dir.path().join("out/000002.pfm")).unwrap(), last, "the same map as without the stop");
    // An independent run into the same folder is another run's results.
    fails(dir.path(), &["sequence", "seq", "-o", "out", "--independent"], &["out"]);
}

#[test]
fn sequences_that_do_not_pair_fail_with_one_line_naming_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    std::fs::rename(dir.path().join("seq/right/000001.png"), dir.path().join("seq/right/000009.png")).unwrap();
    fails(
        dir.path(),
        &["sequence", "seq", "-o", "out", "--independent"],
        &["seq", "000001.png has no partner", "right/"],
    );
    std::fs::remove_file(dir.path().join("seq/right/000009.png")).unwrap();
    fails(
        dir.path(),
        &["sequence", "seq", "-o", "out", "--independent"],
        &["seq", "left/ holds 3 frames but right/ holds 2"],
    );
    assert!(!dir.path().join("out").exists());
    fails(dir.path(), &["sequence", "seq", "-o", "out"], &["seq", "left/ holds 3 frames but right/ holds 2"]);
    fails(dir.path(), &["sequence", "nowhere", "-o", "out", "--independent"], &["nowhere", "not a stereo sequence"]);
}

#[test]
fn sequences_are_not_written_over_a_scene_or_sequence() {
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    let before = files_in(&dir.path().join("seq"));
    fails(dir.path(), &["synth", "seq", "--frames", "2"], &["seq", "already holds"]);
    ok(dir.path(), &["synth", "scene", "--width", "96", "--height", "48", "--ndisp", "16"]);
    fails(dir.path(), &["synth", "scene", "--frames", "2"], &["scene", "already holds"]);
    fails(dir.path(), &["degrade", "scene", "seq", "--recipe", "noise:4", "--frames", "2"], &["seq", "already holds"]);
    assert_eq!(files_in(&dir.path().join("seq")), before);
    let err = ok(dir.path(), &["degrade", "scene", "noisy", "--recipe", "noise:4", "--frames", "3", "--pan", "2"]);
    assert!(err.contains("wrote a sequence of 3 frames to noisy"), "{err}");
    assert_eq!(files_in(&dir.path().join("noisy")), ["calib.txt", "gt", "left", "made.txt", "mask", "right"]);
}
