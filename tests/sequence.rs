//! Stereo sequences end to end through the `jem` binary: `synth --frames`, `degrade --frames`, `sequence`, `eval`.

mod common;

use std::os::unix::fs::FileTypeExt;
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
fn a_still_camera_whose_exposure_steps_is_still_and_says_what_was_compensated() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["synth", "seq", "--frames", "3", "--width", "128", "--height", "80", "--ndisp", "24", "--noise", "4"];
    ok(dir.path(), &[&args[..], &["--exposure-step", "2:10"]].concat());
    let truth = std::fs::read_to_string(dir.path().join("seq/truth.txt")).unwrap();
    assert!(truth.contains("000001 0.000000 0.000000000 0 0.000 0.000 1.000000"), "{truth}");
    assert!(truth.contains("000002 0.000000 0.000000000 0 0.000 0.000 1.100000"), "{truth}");
    let err = ok(dir.path(), &["sequence", "seq", "-o", "out"]);
    assert!(err.contains("[2/3] 000001: ndisp 24, still camera, the mean of up to 2 frames, 0."), "{err}");
    assert!(err.contains("[3/3] 000002: ndisp 24, still camera, the mean of up to 3 frames, exposure ×1."), "{err}");
    fails(dir.path(), &[&args[..], &["--exposure-step", "2"]].concat(), &["FRAME:PERCENT"]);
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

/// A pinhole rig's OpenCV calibration for `w × h` views, baseline `b` (the views of `small_pan` are its rectified
/// pair: the rectification is the identity).
fn rig_yaml(w: usize, h: usize, b: f64) -> String {
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let m = |name: &str, rows: usize, cols: usize, data: &str| {
        format!("{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: {data}\n")
    };
    let k = format!("[ 80., 0., {cx}, 0., 80., {cy}, 0., 0., 1. ]");
    let d = "[ 0., 0., 0., 0., 0. ]";
    let r = "[ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]";
    format!(
        "%YAML:1.0\n---\n{}{}{}{}{}{}image_width: {w}\nimage_height: {h}\n",
        m("K1", 3, 3, &k),
        m("D1", 1, 5, d),
        m("K2", 3, 3, &k),
        m("D2", 1, 5, d),
        m("R", 3, 3, r),
        m("T", 3, 1, &format!("[ {}, 0., 0. ]", -b))
    )
}

/// The rectification is part of what a sequence folder records: a rerun without `--rectify` (or with another
/// calibration, also one changed in place under the same name) is another run, refused instead of mixing
/// rectified and raw frames; the same calibration resumes.
#[test]
fn a_sequence_folder_records_its_rectification() {
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    std::fs::write(dir.path().join("rig.yml"), rig_yaml(128, 80, 0.25)).unwrap();
    fn run<'a>(extra: &[&'a str]) -> Vec<&'a str> {
        [&["sequence", "seq", "-o", "out", "--set", "model=wta"][..], extra].concat()
    }
    ok(dir.path(), &run(&["--rectify", "rig.yml"]));
    std::fs::remove_file(dir.path().join("out/000002.pfm")).unwrap();
    fails(dir.path(), &run(&[]), &["out/sequence.txt", "another run", "rectified frames", "no --rectify"]);
    std::fs::write(dir.path().join("rig.yml"), rig_yaml(128, 80, 0.5)).unwrap();
    fails(dir.path(), &run(&["--rectify", "rig.yml"]), &["out/sequence.txt", "another rectification"]);
    assert!(!dir.path().join("out/000002.pfm").exists(), "nothing written by the refused runs");
    std::fs::write(dir.path().join("rig.yml"), rig_yaml(128, 80, 0.25)).unwrap();
    let err = ok(dir.path(), &run(&["--rectify", "rig.yml"]));
    assert!(err.contains("1 run, 2 already there"), "{err}");
    ok(dir.path(), &["sequence", "seq", "-o", "raw", "--set", "model=wta"]);
    std::fs::remove_file(dir.path().join("raw/000002.pfm")).unwrap();
    fails(
        dir.path(),
        &["sequence", "seq", "-o", "raw", "--set", "model=wta", "--rectify", "rig.yml"],
        &["unrectified"],
    );
}

/// A run that writes no frame (a range the frames cannot hold) leaves nothing: neither its record nor the folder
/// it made, so the corrected rerun is not taken for another run. Its error names the frame.
#[test]
fn a_failed_sequence_run_leaves_nothing_and_names_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    fails(dir.path(), &["sequence", "seq", "-o", "out", "--ndisp", "100000"], &["frame 000000", "ndisp = 100000"]);
    assert!(!dir.path().join("out").exists(), "{:?}", files_in(dir.path()));
    std::fs::create_dir(dir.path().join("kept")).unwrap();
    fails(dir.path(), &["sequence", "seq", "-o", "kept", "--ndisp", "100000"], &["frame 000000"]);
    assert!(files_in(&dir.path().join("kept")).is_empty(), "{:?}", files_in(&dir.path().join("kept")));
    ok(dir.path(), &["sequence", "seq", "-o", "out", "--ndisp", "24", "--set", "model=wta"]);
    // A frame that cannot be read is named, and the frames before it stay.
    std::fs::write(dir.path().join("seq/left/000002.png"), b"not a png").unwrap();
    std::fs::remove_file(dir.path().join("out/000002.pfm")).unwrap();
    let args = ["sequence", "seq", "-o", "out", "--ndisp", "24", "--set", "model=wta", "-q"];
    fails(dir.path(), &args, &["frame 000002", "seq/left/000002.png"]);
    assert!(dir.path().join("out/000001.pfm").is_file());
}

/// `-o` naming a file, not a folder (or a folder under a file), says what to give instead of the system's "File
/// exists" or "Not a directory"; so do the other commands that make a folder.
#[test]
fn a_sequence_output_that_is_a_file_is_refused_with_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    std::fs::write(dir.path().join("afile"), b"x").unwrap();
    fails(dir.path(), &["sequence", "seq", "-o", "afile"], &["afile", "not a folder", "give the name of a folder"]);
    fails(dir.path(), &["sequence", "seq", "-o", "afile/out"], &["afile: is a file", "afile/out cannot be made"]);
    assert_eq!(std::fs::read(dir.path().join("afile")).unwrap(), b"x");
    // The other commands that make a folder say the same, not the system's "File exists" or "Not a directory".
    for args in [
        &["synth", "afile"][..],
        &["synth", "afile/x"],
        &["synth", "afile", "--frames", "2"],
        &["degrade", "seq", "afile/x", "--recipe", "noise:4"],
    ] {
        let out = run_in(dir.path(), args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("afile") && !err.contains("File exists") && !err.contains("Not a directory"), "{err}");
        assert!(err.contains("not a folder") || err.contains("is a file"), "{args:?}: {err}");
    }
}

/// A frame whose name holds a line break would split its line of times.txt: refused, naming the folder.
#[test]
fn a_frame_name_with_a_line_break_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    for side in ["left", "right"] {
        let folder = dir.path().join("seq").join(side);
        std::fs::rename(folder.join("000001.png"), folder.join("0000\n01.png")).unwrap();
    }
    fails(dir.path(), &["sequence", "seq", "-o", "out", "--independent"], &["seq/left", "line break"]);
    assert!(!dir.path().join("out").exists());
}

/// A FIFO where an output of the folder goes (a frame's map, times.txt, sequence.txt) is refused at once, naming
/// it, instead of a read that waits for a writer forever; it is left as it is.
#[test]
fn a_fifo_in_a_sequence_folder_is_refused_not_waited_on() {
    use std::time::{Duration, Instant};
    let dir = tempfile::tempdir().unwrap();
    small_pan(dir.path());
    let args = ["sequence", "seq", "-o", "out", "--independent", "--set", "model=wta"];
    ok(dir.path(), &args);
    for name in ["000002.pfm", "times.txt", "sequence.txt"] {
        let saved = std::fs::read(dir.path().join("out").join(name)).unwrap();
        let path = dir.path().join("out").join(name);
        std::fs::remove_file(&path).unwrap();
        assert!(std::process::Command::new("mkfifo").arg(&path).status().unwrap().success());
        let mut child = common::jem()
            .current_dir(dir.path())
            .args(args)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while child.try_wait().unwrap().is_none() {
            if start.elapsed() > Duration::from_secs(60) {
                child.kill().unwrap();
                panic!("jem sequence waits on the FIFO {name}");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let out = child.wait_with_output().unwrap();
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains(name) && err.contains("FIFO"), "{err}");
        assert!(std::fs::symlink_metadata(&path).unwrap().file_type().is_fifo(), "{name} left as it was");
        std::fs::remove_file(&path).unwrap();
        std::fs::write(&path, saved).unwrap();
    }
}

/// A second run into a sequence folder while one writes to it is refused, naming the lock: two runs (one of them
/// `--independent`) both exited 0 and left a folder whose record and frames disagreed. The lock goes with the
/// run.
#[test]
fn a_sequence_folder_is_locked_while_a_run_writes_it() {
    use std::time::{Duration, Instant};
    let dir = tempfile::tempdir().unwrap();
    let args = ["synth", "seq", "--frames", "12", "--width", "480", "--height", "360", "--ndisp", "48", "-q"];
    ok(dir.path(), &args);
    let mut first = common::jem()
        .current_dir(dir.path())
        .args(["--threads", "1", "sequence", "seq", "-o", "out", "-q"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let lock = dir.path().join("out/.jem-lock");
    let start = Instant::now();
    while !lock.exists() {
        assert!(first.try_wait().unwrap().is_none(), "the first run ended before its lock was seen");
        assert!(start.elapsed() < Duration::from_secs(120), "no lock appeared");
        std::thread::sleep(Duration::from_millis(10));
    }
    fails(dir.path(), &["sequence", "seq", "-o", "out", "--independent"], &["out", "is writing", ".jem-lock"]);
    let status = first.wait().unwrap();
    assert!(status.success(), "the first run is not disturbed");
    assert!(!lock.exists(), "the lock goes with the run");
    let record = std::fs::read_to_string(dir.path().join("out/sequence.txt")).unwrap();
    assert!(record.contains("mode=temporal"), "{record}");
}
