//! `jem synth`: runs the binary in a temporary folder and checks the scene it writes.

use std::path::Path;
use std::process::Command;

const FILES: [&str; 5] = ["im0.png", "im1.png", "calib.txt", "disp0GT.pfm", "mask0nocc.png"];

fn synth(dir: &Path, extra: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_jem")).arg("synth").arg(dir).args(extra).output().expect("cannot run jem")
}

fn read_all(dir: &Path) -> Vec<Vec<u8>> {
    FILES.iter().map(|f| std::fs::read(dir.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"))).collect()
}

#[test]
fn synth_writes_a_middlebury_scene_deterministically() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b, c) = (tmp.path().join("a"), tmp.path().join("nested/b"), tmp.path().join("c"));
    let out = synth(&a, &["--seed", "5", "--width", "120", "--height", "64", "--ndisp", "24"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("120×64"));

    let gt = jem::io::pfm::read_pfm(&a.join("disp0GT.pfm")).unwrap();
    assert_eq!(gt.dims(), (120, 64));
    assert!(gt.data().iter().all(|d| d.is_finite() && (0.0..24.0).contains(d)));
    assert_eq!(jem::io::read_image(&a.join("im0.png")).unwrap().dims(), (120, 64));
    assert_eq!(jem::io::read_image(&a.join("im1.png")).unwrap().dims(), (120, 64));
    let mask = jem::io::read_grey8(&a.join("mask0nocc.png")).unwrap();
    assert_eq!(mask.dims(), (120, 64));
    assert!(mask.data().iter().all(|&m| m == 255 || m == 128));
    let calib = jem::io::calib::Calib::load(&a.join("calib.txt")).unwrap();
    assert_eq!(calib.ndisp().ok(), Some(24));
    assert_eq!(jem::io::calib::read_ndisp(&a.join("calib.txt")).unwrap(), 24);

    // Same seed: byte-identical, and nothing else (no temporary files) in the folder.
    let out = synth(&b, &["--seed", "5", "--width", "120", "--height", "64", "--ndisp", "24", "--quiet"]);
    assert!(out.status.success());
    assert!(out.stderr.is_empty(), "--quiet printed {:?}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(read_all(&a), read_all(&b));
    assert_eq!(std::fs::read_dir(&b).unwrap().count(), FILES.len());

    // Another seed: a different scene.
    assert!(synth(&c, &["--seed", "6", "--width", "120", "--height", "64", "--ndisp", "24"]).status.success());
    assert_ne!(read_all(&a)[0], read_all(&c)[0]);
}

#[test]
fn synth_defaults_and_bad_sizes() {
    let tmp = tempfile::tempdir().unwrap();
    let out = synth(tmp.path(), &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(jem::io::pfm::read_pfm(&tmp.path().join("disp0GT.pfm")).unwrap().dims(), (320, 240));
    assert_eq!(jem::io::calib::read_ndisp(&tmp.path().join("calib.txt")).unwrap(), 48);

    let bad = tmp.path().join("bad");
    let out = synth(&bad, &["--ndisp", "400"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("ndisp") && err.contains("400"), "{err}");
    assert!(!bad.exists(), "nothing is written for invalid parameters");
}

/// The committed example (the pair and its calib.txt; its ground truth and mask are not committed, the tests
/// render them) is what the current renderer produces. If this fails after a deliberate change to the renderer,
/// regenerate it: `cargo run --release -- synth NEW --seed 1` into a new folder, and copy its im0.png, im1.png and
/// calib.txt into examples/synth.
#[test]
fn committed_example_is_up_to_date() {
    let tmp = tempfile::tempdir().unwrap();
    assert!(synth(tmp.path(), &["--seed", "1", "--quiet"]).status.success());
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/synth");
    for f in ["im0.png", "im1.png", "calib.txt"] {
        let read = |dir: &Path| std::fs::read(dir.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(read(tmp.path()) == read(&example), "examples/synth/{f} is stale");
    }
}
