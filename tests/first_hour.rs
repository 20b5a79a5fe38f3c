//! Issue 42, "the first hour": what a newcomer sees. Every command ends with one line on stderr saying what it did
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

/// Issue 42, item 3: each command's last line says what it did and where; with `-q` there is nothing on stderr
/// (and the files are written all the same).
#[test]
fn issue42_every_command_ends_with_what_it_did() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let small = ["--width", "96", "--height", "64", "--ndisp", "16"];
    let line = last_line(d, &[&["synth", "set/S"][..], &small].concat());
    assert!(line.starts_with("wrote set/S/") && line.contains("96x64"), "{line}");

    let line = last_line(d, &["set/S/im0.png", "set/S/im1.png", "-o", "d.pfm", "--cloud", "p.ply"]);
    let (head, tail) = line.split_once(" % valid, ndisp 16, ").unwrap_or_else(|| panic!("{line}"));
    assert!(head.starts_with("wrote d.pfm (96×64, ") && tail.contains(" s), point cloud p.ply ("), "{line}");
    let percent: f64 = head.rsplit(", ").next().unwrap().parse().unwrap_or_else(|_| panic!("{line}"));
    let map = jem::io::read_disparity(&d.join("d.pfm")).unwrap();
    let valid = 100.0 * map.data.iter().filter(|v| v.is_finite()).count() as f64 / map.data.len() as f64;
    assert!((percent - valid).abs() <= 0.5, "{line}: {valid} % valid");

    let line = last_line(d, &["batch", "set", "--alg", "T"]);
    let want = "1 pair(s): 1 written, 0 skipped, 0 failed; results: disp0T.pfm and timeT.txt in each MiddEval3 scene \
                folder (under set)";
    assert_eq!(line, want);
    let line = last_line(d, &["eval", "set", "--alg", "T", "--scale", "1"]);
    assert_eq!(line, "scored 1 of 1 scene(s) of T (middlebury, nonocc)");
    let line = last_line(d, &["viz", "d.pfm", "-o", "v.png"]);
    assert!(line.starts_with("wrote v.png (96×64): disparity coloured over "), "{line}");
    let line = last_line(d, &["viz", "set", "--alg", "T", "-o", "sheet.png"]);
    assert!(line.starts_with("wrote sheet.png (") && line.ends_with("1 rows (S)"), "{line}");
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
        &["-q", "viz", "q", "--alg", "T", "-o", "qsheet.png"],
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
