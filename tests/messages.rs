//! What `jem` says when it is used wrongly or the input costs accuracy: the usage for a bare `jem`, a forgotten
//! `-o`, an output into a missing folder, and a note on JPEG-compressed views.

mod common;

use common::{files_in, repo, run_in, stderr};

fn example(name: &str) -> String {
    repo().join("examples").join("synth").join(name).to_string_lossy().into_owned()
}

/// A bare `jem` prints the usage and every command (clap alone named three "required arguments").
#[test]
fn a_bare_jem_prints_the_usage_and_the_commands() {
    let dir = tempfile::tempdir().unwrap();
    for args in [&[][..], &["-v"][..]] {
        let out = run_in(dir.path(), args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.starts_with("usage: jem LEFT RIGHT -o OUT"), "{err}");
        for command in ["match", "rectify", "sequence", "batch", "eval", "report", "viz", "config", "synth", "degrade"]
        {
            assert!(err.contains(&format!("\n  {command} ")), "{command} missing: {err}");
        }
        assert!(!err.contains("required arguments"), "{err}");
    }
}

/// `jem L R disp.pfm` suggests `-o disp.pfm` (clap alone called disp.pfm a subcommand), with nothing written.
#[test]
fn a_third_path_suggests_its_flag() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    for args in [vec![&l[..], &r[..], "disp.pfm"], vec!["match", &l[..], &r[..], "disp.pfm", "--ndisp", "16"]] {
        let out = run_in(dir.path(), &args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("did you mean -o disp.pfm?") && !err.contains("subcommand"), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    }
    assert!(files_in(dir.path()).is_empty());
}

/// `-o nodir/disp.pfm` names the missing folder, before matching (it read as a missing input after the run).
#[test]
fn an_output_into_a_missing_folder_names_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_in(dir.path(), &[&example("im0.png"), &example("im1.png"), "-o", "nodir/disp.pfm"]);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("nodir/disp.pfm: cannot write it: the folder nodir does not exist"), "{err}");
    assert!(files_in(dir.path()).is_empty());
}

/// JPEG-compressed views get a one-line note without `-v`; the same views saved losslessly do not.
#[test]
fn jpeg_compressed_views_get_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let src = repo().join("examples").to_string_lossy().into_owned();
    for (name, recipe) in [("jpeg", "jpeg:90"), ("clean", "none")] {
        let out = run_in(dir.path(), &["degrade", &src, name, "--recipe", recipe, "--quiet"]);
        assert!(out.status.success(), "{}", stderr(&out));
        let (l, r) = (format!("{name}/synth/im0.png"), format!("{name}/synth/im1.png"));
        let out = run_in(dir.path(), &[&l, &r, "-o", &format!("{name}.pfm"), "--set", "meanfield.iterations=1"]);
        let err = stderr(&out);
        assert!(out.status.success(), "{err}");
        let notes: Vec<&str> = err.lines().filter(|l| l.starts_with("note: the views are JPEG-compressed")).collect();
        assert_eq!(notes.len(), usize::from(name == "jpeg"), "{name}: {err}");
    }
}

/// A range the scene reaches beyond (`--ndisp 16` on the example, whose disparities reach 42) is one warning that
/// says which range fits, the map still written; with `--strict` nothing is written. The range calib.txt states is
/// no warning.
#[test]
fn a_range_that_clips_the_scene_says_which_one_fits() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    let out = run_in(dir.path(), &[&l, &r, "-o", "d.pfm", "--ndisp", "16"]);
    let err = stderr(&out);
    assert!(out.status.success() && dir.path().join("d.pfm").is_file(), "{err}");
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning:")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    assert!(warnings[0].contains("beyond the search range 0..15") && warnings[0].contains("would fit)"), "{err}");
    let out = run_in(dir.path(), &[&l, &r, "-o", "s.pfm", "--ndisp", "16", "--strict"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(!dir.path().join("s.pfm").exists());
    let out = run_in(dir.path(), &[&l, &r, "-o", "c.pfm"]);
    let err = stderr(&out);
    assert!(out.status.success() && !err.contains("warning"), "{err}");
}
