//! What OpenCV and depth-camera users expect of `jem match`: a search range that starts above zero
//! (`--min-disp`, SGBM's `minDisparity`) and a 16-bit depth PNG in the baseline's unit.

mod common;

use common::{repo, run_in, stderr};

fn example(name: &str) -> String {
    repo().join("examples").join("synth").join(name).to_string_lossy().into_owned()
}

/// Matches the shipped example (vmin 3, vmax 42) into `out` with `extra` flags; returns stderr.
fn match_example(dir: &std::path::Path, out: &str, extra: &[&str]) -> String {
    let (l, r) = (example("im0.png"), example("im1.png"));
    let mut args = vec![&l[..], &r[..], "-o", out, "--set", "model=wta"];
    args.extend_from_slice(extra);
    let run = run_in(dir, &args);
    let err = stderr(&run);
    assert!(run.status.success(), "{err}");
    err
}

/// `--min-disp 8 --ndisp 40` searches 8..47: the first 8 columns are invalid, no answer is below 8, and the
/// answers agree with the search from 0 where the scene lies in both ranges (a map shifted by the offset would not).
#[test]
fn a_search_from_min_disp_finds_the_same_disparities() {
    let dir = tempfile::tempdir().unwrap();
    match_example(dir.path(), "full.pfm", &["--ndisp", "48"]);
    let err = match_example(dir.path(), "from8.pfm", &["--ndisp", "40", "--min-disp", "8"]);
    assert!(err.contains("ndisp 40 from 8"), "{err}");
    let read = |n: &str| jem::io::read_disparity(&dir.path().join(n)).unwrap();
    let (full, from8) = (read("full.pfm"), read("from8.pfm"));
    assert_eq!(full.dims(), from8.dims());
    let w = full.dims().0;
    let (mut both, mut agree) = (0, 0);
    for (i, (&a, &b)) in full.data().iter().zip(from8.data()).enumerate() {
        if i % w < 8 {
            assert!(b.is_infinite(), "column {} of the search from 8 holds {b}", i % w);
            continue;
        }
        assert!(!b.is_finite() || b >= 7.5, "{b} below the range");
        if a.is_finite() && b.is_finite() && a >= 10.0 {
            both += 1;
            agree += usize::from((a - b).abs() <= 1.0);
        }
    }
    assert!(both > 1000 && agree as f64 > 0.9 * both as f64, "{agree} of {both} agree");
}

/// `--min-disp calib` takes vmin from calib.txt beside LEFT (3 here) and keeps the top of its ndisp (48);
/// a minimum that leaves no columns is one error naming the flag, with nothing written.
#[test]
fn min_disp_from_calib_and_its_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let err = match_example(dir.path(), "d.pfm", &["--min-disp", "calib"]);
    assert!(err.contains("ndisp 45 from 3"), "{err}");
    let (l, r) = (example("im0.png"), example("im1.png"));
    let out = run_in(dir.path(), &[&l, &r, "-o", "e.pfm", "--ndisp", "16", "--min-disp", "319"]);
    let err = stderr(&out);
    assert!(!out.status.success() && err.contains("--min-disp") && err.trim_end().lines().count() == 1, "{err}");
    assert!(!dir.path().join("e.pfm").exists());
}

/// `--depth z.png` is the float depth rounded to whole units of the baseline (0 where there is none); depths
/// beyond 65535 are refused with nothing written, and `--max-depth` leaves them out.
#[test]
fn a_depth_png_is_the_depth_in_whole_baseline_units() {
    let dir = tempfile::tempdir().unwrap();
    // f·B = 320 × 100 = 32000: every depth fits.
    match_example(dir.path(), "d.pfm", &["--depth", "z.pfm"]);
    match_example(dir.path(), "e.pfm", &["--depth", "z.png"]);
    let z = jem::io::read_disparity(&dir.path().join("z.pfm")).unwrap();
    let png = image::open(dir.path().join("z.png")).unwrap();
    assert_eq!(png.color(), image::ColorType::L16);
    let png = png.to_luma16();
    let mut valid = 0;
    for (&f, p) in z.data().iter().zip(png.pixels()) {
        let expected = if f.is_finite() { f.round() as u16 } else { 0 };
        assert_eq!(p.0[0], expected, "depth {f}");
        valid += usize::from(expected > 0);
    }
    assert!(valid > z.data().len() / 2, "{valid} valid");
    // A baseline of 10000: depths up to 3.2e6, beyond the format.
    let (l, r) = (example("im0.png"), example("im1.png"));
    let far = [&l[..], &r[..], "-o", "f.pfm", "--depth", "f.png", "--baseline", "10000", "--set", "model=wta"];
    let out = run_in(dir.path(), &far);
    let err = stderr(&out);
    assert!(!out.status.success() && err.contains("f.png: depth") && err.contains("65535"), "{err}");
    assert!(!dir.path().join("f.png").exists() && !dir.path().join("f.pfm").exists());
    match_example(dir.path(), "g.pfm", &["--depth", "g.png", "--baseline", "10000", "--max-depth", "65535"]);
    assert!(dir.path().join("g.png").is_file());
    // Read back as the depth it holds (not as a disparity PNG's × 256), and drawn over the same depths as the PFM.
    let back = jem::io::read_depth(&dir.path().join("z.png")).unwrap();
    for (&f, &b) in z.data().iter().zip(back.data()) {
        assert!(if f.is_finite() { b == f.round() } else { b.is_infinite() }, "{f} read back as {b}");
    }
    let range = |depth: &str, out: &str| {
        let said = stderr(&run_in(dir.path(), &["viz", depth, "--depth", "-o", out]));
        let from = said.split(" from ").nth(1).and_then(|r| r.split(" (indigo)").next()).unwrap_or_default();
        from.replace(" (dark red)", "")
    };
    let (of_pfm, of_png) = (range("z.pfm", "zp.png"), range("z.png", "zz.png"));
    let ends = |r: &str| r.split(" to ").map(|v| v.parse::<f32>().unwrap()).collect::<Vec<_>>();
    assert_eq!(ends(&of_pfm).len(), 2, "{of_pfm}");
    for (a, b) in ends(&of_pfm).into_iter().zip(ends(&of_png)) {
        assert!((a - b).abs() <= 0.01 * a, "{of_pfm} against {of_png}");
    }
}
