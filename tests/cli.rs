//! The `jem` binary end to end: outputs, formats, configs and clean failures on bad input.

mod common;

use std::path::Path;

use common::{files_in, repo, run_in, stderr};
use jem::io::pfm;

/// The example's exact disparity (`examples/synth` is `jem synth` with the default parameters and seed 1; its
/// ground truth is rendered here, not committed).
fn example_gt() -> jem::DisparityMap {
    jem::synth::render_scene(&jem::synth::SynthParams::default()).unwrap().gt
}

fn example(name: &str) -> String {
    repo().join("examples").join("synth").join(name).to_string_lossy().into_owned()
}

/// Asserts a clean failure: exit code 2, one `error:` line mentioning every `needle`, and no file left in `dir`.
fn assert_clean_failure(dir: &Path, args: &[&str], needles: &[&str]) {
    let before = files_in(dir);
    let out = run_in(dir, args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "args {args:?}: {err}");
    assert!(err.starts_with("error: ") && err.trim_end().lines().count() == 1, "not one error line: {err}");
    for n in needles {
        assert!(err.contains(n), "error for {args:?} does not mention {n:?}: {err}");
    }
    assert_eq!(files_in(dir), before, "args {args:?} left files behind");
}

/// Renders a scene with `jem synth ARGS` in `dir` (the output folder first, then the options).
fn synth_scene(dir: &Path, args: &[&str]) {
    let out = run_in(dir, &[&["synth"], args].concat());
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn readme_example_writes_a_valid_pfm() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_in(dir.path(), &[&example("im0.png"), &example("im1.png"), "-o", "disp.pfm"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let d = pfm::read_pfm(&dir.path().join("disp.pfm")).unwrap();
    assert_eq!(d.dims(), (320, 240));
    assert!(d.data().iter().all(|v| v.is_finite() && (0.0..48.0).contains(v)), "the default pipeline is dense");
    assert_eq!(files_in(dir.path()), ["disp.pfm"], "no temporary files left");
}

#[test]
fn output_formats_follow_the_extension() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    for name in ["d.pfm", "d.exr", "d.png"] {
        let out = run_in(dir.path(), &[&l, &r, "-o", name, "--set", "model=wta"]);
        assert!(out.status.success(), "{name}: {}", stderr(&out));
    }
    let a = jem::io::read_disparity(&dir.path().join("d.pfm")).unwrap();
    let b = jem::io::read_disparity(&dir.path().join("d.exr")).unwrap();
    let c = jem::io::read_disparity(&dir.path().join("d.png")).unwrap();
    assert_eq!(a, b);
    // 16-bit PNG: 1/256 px steps, and 0 means invalid, so a disparity of exactly 0 is stored as 1/256.
    assert!(a.data().iter().zip(c.data()).all(|(x, y)| (x - y).abs() <= 1.0 / 256.0), "PNG round trip");
}

#[test]
fn same_output_bytes_whatever_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    for (threads, name) in [("1", "t1.pfm"), ("2", "t2.pfm"), ("3", "t3.pfm"), ("2", "again.pfm")] {
        let out = run_in(dir.path(), &["--threads", threads, &l, &r, "-o", name]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let first = std::fs::read(dir.path().join("t1.pfm")).unwrap();
    for name in ["t2.pfm", "t3.pfm", "again.pfm"] {
        assert!(std::fs::read(dir.path().join(name)).unwrap() == first, "{name} differs from t1.pfm");
    }
}

/// The same on a noisy JPEG pair, where the compression is measured (`condition.noise.jpeg`: a parallel sum over the DCT
/// frequencies) and the views are denoised (the vectorised bilateral filter): `-v` reports the JPEG, and the
/// output is the same with 1, 2 and 3 threads.
#[test]
fn same_output_bytes_whatever_the_thread_count_jpeg() {
    let dir = tempfile::tempdir().unwrap();
    let src = repo().join("examples").to_string_lossy().into_owned();
    let out = run_in(dir.path(), &["degrade", &src, "dg", "--recipe", "noise:3+jpeg:75", "--seed", "1", "--quiet"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let (l, r) = ("dg/synth/im0.png", "dg/synth/im1.png");
    for (threads, name) in [("1", "t1.pfm"), ("2", "t2.pfm"), ("3", "t3.pfm")] {
        let out = run_in(dir.path(), &["--threads", threads, l, r, "-o", name, "-v"]);
        assert!(out.status.success(), "{}", stderr(&out));
        assert!(stderr(&out).contains("JPEG: compression error"), "{}", stderr(&out));
    }
    let first = std::fs::read(dir.path().join("t1.pfm")).unwrap();
    for name in ["t2.pfm", "t3.pfm"] {
        assert!(std::fs::read(dir.path().join(name)).unwrap() == first, "{name} differs from t1.pfm");
    }
}

#[test]
fn ndisp_comes_from_calib_or_flag() {
    let dir = tempfile::tempdir().unwrap();
    // Images copied away from their calib.txt: the range is measured on the pair (jem::range), and said so.
    for f in ["im0.png", "im1.png"] {
        std::fs::copy(example(f), dir.path().join(f)).unwrap();
    }
    let out = run_in(dir.path(), &["im0.png", "im1.png", "-o", "m.pfm", "--set", "model=wta"]);
    assert!(out.status.success() && stderr(&out).contains("measured on the pair"), "{}", stderr(&out));
    let out = run_in(dir.path(), &["im0.png", "im1.png", "-o", "d.pfm", "--ndisp", "32", "--set", "model=wta"]);
    assert!(out.status.success(), "{}", stderr(&out));
    std::fs::write(dir.path().join("calib.txt"), "width=320\nndisp=zero\n").unwrap();
    assert_clean_failure(dir.path(), &["im0.png", "im1.png", "-o", "e.pfm"], &["calib.txt", "ndisp"]);
}

/// The README's own-camera steps: the calib.txt `jem rectify` writes states the geometry and no range,
/// and `jem` on the rectified pair measures the range instead of refusing the file.
#[test]
fn a_rectified_pair_matches_with_the_calib_txt_rectify_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let yml = "%YAML:1.0\n---\nK1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 320., 0., 159.5, 0., \
               320., 119.5, 0., 0., 1. ]\nD1: !!opencv-matrix\n   rows: 1\n   cols: 4\n   dt: d\n   data: [ 0., 0., 0., 0. ]\n\
               K2: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 320., 0., 159.5, 0., 320., 119.5, 0., 0., \
               1. ]\nD2: !!opencv-matrix\n   rows: 1\n   cols: 4\n   dt: d\n   data: [ 0., 0., 0., 0. ]\nR: !!opencv-matrix\n\
               \x20  rows: 3\n   cols: 3\n   dt: d\n   data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]\nT: !!opencv-matrix\n\
               \x20  rows: 3\n   cols: 1\n   dt: d\n   data: [ -0.1, 0., 0. ]\n";
    std::fs::write(dir.path().join("stereo.yml"), yml).unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    let out = run_in(dir.path(), &["rectify", "stereo.yml", &l, &r, "-o", "rect"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let calib = std::fs::read_to_string(dir.path().join("rect/calib.txt")).unwrap();
    assert!(calib.contains("baseline=") && !calib.contains("ndisp"), "{calib}");
    let args = ["rect/im0.png", "rect/im1.png", "-o", "d.pfm", "--depth", "z.pfm", "--set", "model=wta"];
    let out = run_in(dir.path(), &args);
    assert!(out.status.success() && stderr(&out).contains("measured on the pair"), "{}", stderr(&out));
    assert!(dir.path().join("z.pfm").is_file());
}

#[test]
fn bad_input_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (l, r) = (example("im0.png"), example("im1.png"));
    // Missing file.
    assert_clean_failure(d, &[&l, "nope.png", "-o", "x.pfm", "--ndisp", "16"], &["nope.png"]);
    // Unequal sizes.
    image::RgbImage::new(100, 50).save(d.join("small.png")).unwrap();
    assert_clean_failure(d, &[&l, "small.png", "-o", "x.pfm", "--ndisp", "16"], &["320x240", "100x50"]);
    std::fs::remove_file(d.join("small.png")).unwrap();
    // Corrupt and truncated images.
    std::fs::write(d.join("bad.png"), b"\x89PNG\r\n\x1a\n garbage").unwrap();
    assert_clean_failure(d, &[&l, "bad.png", "-o", "x.pfm", "--ndisp", "16"], &["bad.png"]);
    let bytes = std::fs::read(&r).unwrap();
    std::fs::write(d.join("bad.png"), &bytes[..bytes.len() / 2]).unwrap();
    assert_clean_failure(d, &[&l, "bad.png", "-o", "x.pfm", "--ndisp", "16"], &["bad.png"]);
    std::fs::write(d.join("bad.png"), b"just text").unwrap();
    assert_clean_failure(d, &[&l, "bad.png", "-o", "x.pfm", "--ndisp", "16"], &["bad.png"]);
    std::fs::remove_file(d.join("bad.png")).unwrap();
    // Impossible ndisp.
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "--ndisp", "0"], &["ndisp"]);
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "--ndisp", "320"], &["ndisp", "320"]);
    let out = run_in(d, &[&l, &r, "-o", "x.pfm", "--ndisp", "-3"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(!d.join("x.pfm").exists());
    // Unknown output format.
    assert_clean_failure(d, &[&l, &r, "-o", "x.jpg", "--ndisp", "16"], &["x.jpg"]);
}

#[test]
fn bad_config_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (l, r) = (example("im0.png"), example("im1.png"));
    std::fs::write(d.join("typo.toml"), "[meanfield]\niteratons = 3\n").unwrap();
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "-c", "typo.toml"], &["typo.toml", "iteratons"]);
    std::fs::write(d.join("type.toml"), "[meanfield]\niterations = \"three\"\n").unwrap();
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "-c", "type.toml"], &["type.toml", "iterations"]);
    std::fs::write(d.join("range.toml"), "[meanfield]\nsigma_rgb = -1\n").unwrap();
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "-c", "range.toml"], &["meanfield.sigma_rgb", "-1", "> 0"]);
    std::fs::write(d.join("syntax.toml"), "[meanfield\n").unwrap();
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "-c", "syntax.toml"], &["syntax.toml"]);
    for f in ["typo.toml", "type.toml", "range.toml", "syntax.toml"] {
        std::fs::remove_file(d.join(f)).unwrap();
    }
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "-c", "missing.toml"], &["missing.toml"]);
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "--set", "model=deep"], &["model", "deep"]);
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "--set", "cost.census_width=8"], &["cost.census_width", "8"]);
}

#[test]
fn config_prints_the_effective_toml() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_in(dir.path(), &["config", "--set", "meanfield.iterations=9", "--set", "model=fcm"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8(out.stdout).unwrap();
    let params = jem::Params::from_toml_str(&text, Path::new("printed")).unwrap();
    assert_eq!(params.meanfield.iterations, 9);
    assert_eq!(params.model, jem::Model::Fcm);
    for cfg in std::fs::read_dir(repo().join("configs")).unwrap() {
        let cfg = cfg.unwrap().path();
        let out = run_in(dir.path(), &["config", "-c", cfg.to_str().unwrap()]);
        assert!(out.status.success(), "{}: {}", cfg.display(), stderr(&out));
    }
}

#[test]
fn tiny_images_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (w, h) in [(1u32, 1u32), (2, 1), (3, 2), (5, 40), (40, 3)] {
        image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 40) as u8, (y * 70) as u8, 9]))
            .save(d.join("a.png"))
            .unwrap();
        image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(y * 30) as u8, (x * 20) as u8, 1]))
            .save(d.join("b.png"))
            .unwrap();
        let out = run_in(d, &["a.png", "b.png", "-o", "o.pfm", "--ndisp", "1"]);
        let err = stderr(&out);
        if w == 1 {
            assert_eq!(out.status.code(), Some(2), "{w}x{h}: {err}");
            assert!(err.contains("at least 2 pixels wide"), "{err}");
        } else {
            assert!(out.status.success(), "{w}x{h}: {err}");
            let map = pfm::read_pfm(&d.join("o.pfm")).unwrap();
            assert_eq!(map.dims(), (w as usize, h as usize));
            assert!(map.data().iter().all(|v| !v.is_nan()));
        }
        assert!(!err.contains("panicked"), "{err}");
    }
}

#[test]
fn teddy_gives_a_450x375_pfm() {
    let Some(data) = common::data_dir() else { return };
    let teddy = data.join("MiddEval3/trainingQ/Teddy");
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (teddy.join("im0.png"), teddy.join("im1.png"));
    let out = run_in(dir.path(), &[l.to_str().unwrap(), r.to_str().unwrap(), "-o", "t.pfm"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let bytes = std::fs::read(dir.path().join("t.pfm")).unwrap();
    assert!(bytes.starts_with(b"Pf\n450 375\n-1\n"));
    assert_eq!(bytes.len(), 14 + 450 * 375 * 4);
}

#[test]
fn memory_guard_fails_fast_with_the_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    assert_clean_failure(dir.path(), &["--max-memory", "2M", &l, &r, "-o", "x.pfm"], &["needs about", "2.0 MiB"]);
    let out = run_in(dir.path(), &["--max-memory", "lots", &l, &r, "-o", "x.pfm"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("'lots' for '--max-memory"), "{}", stderr(&out));
    assert!(!dir.path().join("x.pfm").exists());
    let out = run_in(dir.path(), &["--max-memory", "4G", &l, &r, "-o", "x.pfm"]);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// A pair too large for the memory limit, but whose coarse level and smallest tile fit, runs in tiles
/// (jem::tile) instead of being refused, and is still matched.
#[test]
fn memory_limit_runs_in_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    // 320x240, ndisp 48: ~97 MB in one piece; 60 MB leaves room for a coarse level at 1/2 and 64-px tiles.
    let out = run_in(dir.path(), &["--max-memory", "60M", &l, &r, "-o", "t.pfm"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("running in tiles"), "{}", stderr(&out));
    let d = pfm::read_pfm(&dir.path().join("t.pfm")).unwrap();
    let gt = example_gt();
    let err: f64 =
        d.data().iter().zip(gt.data()).map(|(a, b)| f64::from((a - b).abs())).sum::<f64>() / gt.data().len() as f64;
    assert!(err < 1.0, "mean error {err:.3} px");
}

/// `-v` reports what the adaptive front end measured (noise, gains) and set from it; the paper's pipeline, with
/// `[condition]` off, has nothing to report; `jem batch -v` prints the same line per scene.
#[test]
fn verbose_prints_what_was_measured() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    let out = run_in(dir.path(), &[&l[..], &r, "-o", "m.pfm", "-v"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let line = stderr(&out).lines().find(|l| l.starts_with("measured: ")).map(str::to_string);
    let line = line.unwrap_or_else(|| panic!("no measured line in:\n{}", stderr(&out)));
    for part in ["noise σ ", "contrast gain ", "prior λ ", "Census support ", "gradient local contrast "] {
        assert!(line.contains(part), "{part:?} missing from {line:?}");
    }
    let paper = repo().join("configs/jem-all.toml");
    let out = run_in(dir.path(), &[&l[..], &r, "-o", "p.pfm", "-v", "-c", paper.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!stderr(&out).contains("measured: "), "{}", stderr(&out));

    // jem batch -v: the same line per scene after the table, with the scene's name.
    let scene = dir.path().join("scenes").join("Synth");
    std::fs::create_dir_all(&scene).unwrap();
    for f in ["im0.png", "im1.png", "calib.txt"] {
        std::fs::copy(example(f), scene.join(f)).unwrap();
    }
    let out = run_in(dir.path(), &["batch", "scenes", "--alg", "M", "-v"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(stdout.lines().any(|l| l == format!("Synth: {line}")), "no line 'Synth: {line}' in:\n{stdout}");
}

/// The memory a run plans for (the estimate in one piece; the budget when tiled) bounds its measured
/// peak (`-v` prints both; Linux's VmHWM).
#[test]
fn memory_plan_bounds_the_measured_peak() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    for extra in [&[][..], &["--max-memory", "60M"][..]] {
        let out = run_in(dir.path(), &[&[&l[..], &r, "-o", "m.pfm", "-v"][..], extra].concat());
        assert!(out.status.success(), "{}", stderr(&out));
        let Some((peak, planned)) = memory_line(&stderr(&out)) else {
            eprintln!("note: skipping: no peak memory reading on this system");
            return;
        };
        assert!(peak <= planned, "{extra:?}: peak {peak} MiB, planned {planned} MiB");
    }
}

/// At a high `--downscale` most of the run's memory is at the input's size (the pair, the maps brought back, the
/// pair's check, the files encoded for writing): counted, a run fits `--max-memory` or is refused with a word.
/// A 2000 × 1500 pair at `--downscale 8 --max-memory 130M` peaked at 152 MiB (planned 99); it is now refused, and
/// with room (and every output asked for) it stays within its plan.
#[test]
fn a_downscaled_run_stays_within_the_memory_limit() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (2000u32, 1500u32);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 56) as u8
    };
    let left = image::RgbImage::from_fn(w + 8, h, |_, _| image::Rgb([noise(), noise(), noise()]));
    let crop = |x0: u32| image::imageops::crop_imm(&left, x0, 0, w, h).to_image();
    crop(0).save(dir.path().join("l.png")).unwrap();
    crop(8).save(dir.path().join("r.png")).unwrap();
    let run = |limit: &str, extra: &[&str]| {
        let base = ["l.png", "r.png", "-o", "d.pfm", "--ndisp", "64", "--downscale", "8", "-v", "--max-memory", limit];
        run_in(dir.path(), &[&base[..], extra].concat())
    };
    let out = run("130M", &[]);
    let err = stderr(&out);
    match memory_line(&err) {
        _ if out.status.code() == Some(2) => assert!(err.contains("the memory limit is 130.0 MiB"), "{err}"),
        Some((peak, planned)) => assert!(peak <= 130.0 && peak <= planned, "peak {peak} MiB, planned {planned}: {err}"),
        None => eprintln!("note: no peak memory reading on this system"),
    }
    let all = ["--confidence", "c.pfm", "--min-confidence", "0.5", "--depth", "z.pfm", "--cloud", "p.ply"];
    let camera = ["--focal", "100", "--baseline", "1", "--cx", "1000", "--cy", "750", "--lr-mask", "m.png"];
    let out = run("400M", &[&all[..], &camera].concat());
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    if let Some((peak, planned)) = memory_line(&err) {
        assert!(peak <= planned && planned <= 400.0, "peak {peak} MiB, planned {planned} MiB");
    }
}

/// The `memory: peak X MiB (planned Y MiB)` line that `-v` prints: (X, Y), or `None` where the system gives no
/// peak reading.
fn memory_line(stderr: &str) -> Option<(f64, f64)> {
    let line = stderr.lines().find(|l| l.starts_with("memory: peak "))?;
    let mib =
        |after: &str| -> f64 { line.split(after).nth(1).unwrap().split_whitespace().next().unwrap().parse().unwrap() };
    Some((mib("peak "), mib("planned ")))
}

/// A large synthetic scene (1280×960, 160 labels: 3.3 GiB in one piece) under a 300 MB limit runs in
/// tiles, stays within the limit, and recovers its disparity: measured mean error 0.49 px, 0.65 % of the visible
/// pixels over 1 px (the same as in one piece). The bounds leave room for tuning and fail on a misplaced tile or
/// label window (errors of several px over whole tiles).
#[test]
fn large_synthetic_scene_runs_tiled_within_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let synth =
        run_in(dir.path(), &["synth", "s", "--width", "1280", "--height", "960", "--ndisp", "160", "--seed", "3"]);
    assert!(synth.status.success(), "{}", stderr(&synth));
    let out = run_in(dir.path(), &["s/im0.png", "s/im1.png", "-o", "d.pfm", "--max-memory", "300M", "-v"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stderr(&out);
    assert!(text.contains("running in tiles"), "{text}");
    if let Some((peak, _)) = memory_line(&text) {
        // `--max-memory 300M` is 300 MiB (binary units, as the CLI documents).
        assert!(peak <= 300.0, "peak {peak} MiB");
    }
    let d = pfm::read_pfm(&dir.path().join("d.pfm")).unwrap();
    let gt = pfm::read_pfm(&dir.path().join("s/disp0GT.pfm")).unwrap();
    let mask = jem::io::read_grey8(&dir.path().join("s/mask0nocc.png")).unwrap();
    let m = jem::eval::evaluate(&d, &gt, Some(&mask), 160, 1, jem::eval::MaskMode::Nonocc);
    assert_eq!(m.invalid, 0.0, "dense output");
    assert!(m.avgerr < 1.0 && m.bad1 < 2.0, "mean error {:.3} px, {:.2} % over 1 px", m.avgerr, m.bad1);
}

/// Killing a run (SIGTERM or SIGKILL) leaves neither the output nor a temporary file: the output is only ever
/// created by renaming a finished temporary file. The run is made long (many iterations) so the signal lands
/// while it computes. (jem handles no signal, so Ctrl-C's SIGINT ends it the same way; but a shell without job
/// control starts its background commands with SIGINT ignored, and a test run launched like that would never see
/// it: SIGTERM cannot be ignored that way.)
#[test]
fn interrupted_run_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    for signal in ["-TERM", "-KILL"] {
        let mut child = common::jem()
            .current_dir(dir.path())
            .args([&l, &r, "-o", "out.pfm", "--set", "meanfield.iterations=1000", "-q"])
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(400));
        let status = std::process::Command::new("kill").args([signal, &child.id().to_string()]).status().unwrap();
        assert!(status.success());
        let exit = child.wait().unwrap();
        assert!(!exit.success(), "the run finished before the signal; make it longer");
        assert!(files_in(dir.path()).is_empty(), "{signal}: left {:?}", files_in(dir.path()));
    }
}

/// NaN in a config is rejected; overflowing arithmetic (costs that reach inf) never puts NaN into the output.
#[test]
fn nan_and_inf_never_reach_the_output() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    for key in ["meanfield.unary_scale", "meanfield.fcm_weight", "cost.grad_weight", "post.sps.disparity_weight"] {
        assert_clean_failure(dir.path(), &[&l, &r, "-o", "x.pfm", "--set", &format!("{key}=nan")], &[key]);
        assert_clean_failure(dir.path(), &[&l, &r, "-o", "x.pfm", "--set", &format!("{key}=inf")], &[key]);
    }
    let out = run_in(
        dir.path(),
        &[&l, &r, "-o", "big.pfm", "--set", "cost.census_weight=3e38", "--set", "cost.grad_weight=3e38"],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let d = pfm::read_pfm(&dir.path().join("big.pfm")).unwrap();
    assert!(d.data().iter().all(|v| !v.is_nan()), "NaN in the output");
}

/// `--downscale N` runs at 1/N resolution and writes a full-size map; the same bytes whatever the thread
/// count; the flag wins over --config and --set; `jem batch` takes it too.
#[test]
fn downscale_flag_writes_a_full_size_map() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (l, r) = (example("im0.png"), example("im1.png"));
    for (threads, name) in [("1", "t1.pfm"), ("2", "t2.pfm")] {
        let out = run_in(d, &["--threads", threads, "-v", &l, &r, "-o", name, "--downscale", "2"]);
        let err = stderr(&out);
        assert!(out.status.success(), "{err}");
        assert!(err.contains("downsample") && err.contains("upsample"), "-v lists the resample stages: {err}");
    }
    let first = std::fs::read(d.join("t1.pfm")).unwrap();
    assert!(std::fs::read(d.join("t2.pfm")).unwrap() == first, "1 and 2 threads differ");
    let map = pfm::read_pfm(&d.join("t1.pfm")).unwrap();
    assert_eq!(map.dims(), (320, 240));
    assert!(map.data().iter().all(|v| v.is_finite() && (0.0..48.0).contains(v)), "dense and in range");
    let full = run_in(d, &["--threads", "1", &l, &r, "-o", "full.pfm"]);
    assert!(full.status.success(), "{}", stderr(&full));
    assert!(std::fs::read(d.join("full.pfm")).unwrap() != first, "--downscale 2 changes the result");

    // The flag wins over the config file and --set.
    std::fs::write(d.join("ds.toml"), "downscale = 4\n").unwrap();
    let out = run_in(d, &["config", "-c", "ds.toml", "--set", "downscale=3", "--downscale", "2"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(String::from_utf8(out.stdout).unwrap().contains("downscale = 2\n"));
    let out = run_in(d, &["config", "-c", "ds.toml"]);
    assert!(String::from_utf8(out.stdout).unwrap().contains("downscale = 4\n"));

    // jem batch: a copy of the example scene.
    let scene = d.join("scenes").join("Synth");
    std::fs::create_dir_all(&scene).unwrap();
    for f in ["im0.png", "im1.png", "calib.txt"] {
        std::fs::copy(example(f), scene.join(f)).unwrap();
    }
    let out = run_in(d, &["batch", "scenes", "--alg", "DS2", "--downscale", "2", "--threads", "1", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(std::fs::read(scene.join("disp0DS2.pfm")).unwrap() == first, "batch and match agree");
}

/// A bad `--downscale` (0, negative, not an integer), a bad `downscale` key, or a factor too large for
/// the pair is one error line, exit code 2, and no output file.
#[test]
fn bad_downscale_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (l, r) = (example("im0.png"), example("im1.png"));
    for bad in ["0", "-2", "two", "1.5", ""] {
        assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "--downscale", bad], &["--downscale", ">= 1"]);
        assert_clean_failure(d, &["batch", ".", "--alg", "X", "--downscale", bad], &["--downscale"]);
    }
    std::fs::write(d.join("zero.toml"), "downscale = 0\n").unwrap();
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "-c", "zero.toml"], &["downscale = 0", ">= 1"]);
    std::fs::write(d.join("neg.toml"), "downscale = -1\n").unwrap();
    assert_clean_failure(d, &[&l, &r, "-o", "x.pfm", "-c", "neg.toml"], &["neg.toml", "downscale"]);
    for f in ["zero.toml", "neg.toml"] {
        std::fs::remove_file(d.join(f)).unwrap();
    }
    // 320 px with ndisp 319: at 1/2 the search range (160) would not stay below the width (160).
    assert_clean_failure(
        d,
        &[&l, &r, "-o", "x.pfm", "--ndisp", "319", "--downscale", "2", "--set", "model=wta"],
        &["downscale = 2", "at most 1", "320x240"],
    );
}

/// The memory guard names the smallest `--downscale` that fits, and that factor then runs.
#[test]
fn memory_guard_suggests_a_downscale() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    // 320x240, ndisp 48: ~94 MiB at full size, ~32 MiB at 1/2 (each with the process's own 16 MiB); at 40 MiB
    // not even the smallest tile fits.
    assert_clean_failure(
        dir.path(),
        &["--max-memory", "40M", &l, &r, "-o", "x.pfm"],
        &["needs about", "40.0 MiB", "--downscale 2 ", "--max-memory"],
    );
    let out = run_in(dir.path(), &["--threads", "1", "--max-memory", "40M", &l, &r, "-o", "x.pfm", "--downscale", "2"]);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// Global flags may come before a subcommand as well as after it.
#[test]
fn global_flags_before_a_subcommand() {
    let dir = tempfile::tempdir().unwrap();
    for args in [&["-q", "config"][..], &["-v", "config"], &["config", "-q"]] {
        let out = run_in(dir.path(), args);
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
        assert!(String::from_utf8_lossy(&out.stdout).contains("model = \"jem\""), "{args:?} printed no config");
    }
    // A match with global flags first still works, and so does a bad one fail cleanly.
    let out = run_in(dir.path(), &["--threads", "2", &example("im0.png"), &example("im1.png"), "-o", "d.pfm"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_clean_failure(
        dir.path(),
        &["--threads", "1", "nothing.png", "nothing2.png", "-o", "x.pfm"],
        &["nothing.png"],
    );
}

/// `jem degrade` (the robustness suite's measuring stick): a whole tree, ground truth copied, images degraded, the same bytes
/// on a rerun; never into (or around) its input, never into a non-empty folder, nothing left on failure.
#[test]
fn degrade_copies_a_tree_and_never_writes_into_its_input() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src");
    std::fs::create_dir(&src).unwrap();
    for seed in ["1", "2"] {
        let out =
            run_in(dir.path(), &["synth", &format!("src/s{seed}"), "--seed", seed, "--width", "96", "--height", "64"]);
        assert!(out.status.success(), "{}", stderr(&out));
    }
    for (name, out_dir) in [("a", "deg/a"), ("b", "deg/b")] {
        let out = run_in(dir.path(), &["degrade", "src", out_dir, "--recipe", "blur:1+noise:5", "--seed", "9"]);
        assert!(out.status.success(), "{name}: {}", stderr(&out));
    }
    let a = dir.path().join("deg/a");
    assert_eq!(files_in(&a), ["degrade.txt", "s1", "s2"]);
    assert_eq!(files_in(&a.join("s1")), ["calib.txt", "disp0GT.pfm", "im0.png", "im1.png", "mask0nocc.png"]);
    for f in ["im0.png", "im1.png", "disp0GT.pfm", "calib.txt"] {
        let (x, y) =
            (std::fs::read(a.join("s2").join(f)).unwrap(), std::fs::read(dir.path().join("deg/b/s2").join(f)).unwrap());
        assert_eq!(x, y, "{f} differs between two runs with one seed");
        let original = std::fs::read(src.join("s2").join(f)).unwrap();
        assert_eq!(f.starts_with("im"), x != original, "{f}: images degraded, everything else copied");
    }
    let before = files_in(&src);
    assert_clean_failure(dir.path(), &["degrade", "src", "src/inner", "--recipe", "noise:2"], &["outside the input"]);
    assert_clean_failure(&src, &["degrade", "s1", "..", "--recipe", "noise:2"], &["not an empty folder"]);
    assert_clean_failure(dir.path(), &["degrade", "src", "deg/a", "--recipe", "noise:2"], &["not an empty folder"]);
    assert_eq!(files_in(&src), before);
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    assert_clean_failure(dir.path(), &["degrade", "empty", "deg/c", "--recipe", "noise:2"], &["no scene folder"]);
    assert!(!dir.path().join("deg/c").exists());
}

/// A disparity a 16-bit PNG cannot hold is an error that names a format that can, and nothing
/// is written (before: clipped at 255.996 without a word).
#[test]
fn png_output_refuses_disparities_it_cannot_hold() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["big", "--width", "1100", "--height", "64", "--ndisp", "540", "--seed", "4"]);
    let scene = dir.path().join("big");
    let args =
        ["big/im0.png", "big/im1.png", "-o", "big/d.png", "--set", "model=wta", "--set", "post.sps.enabled=false"];
    let before = files_in(&scene);
    let out = run_in(dir.path(), &args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("16-bit PNG") && err.contains(".pfm"), "{err}");
    assert_eq!(files_in(&scene), before, "no file written");
    let ok = run_in(dir.path(), &["big/im0.png", "big/im1.png", "-o", "big/d.pfm", "--set", "model=wta"]);
    assert!(ok.status.success(), "{}", stderr(&ok));
}

/// `--threads` beyond what can help is refused at once, with the range.
#[test]
fn threads_are_capped() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    for n in ["0", "100000", "99999999999"] {
        assert_clean_failure(dir.path(), &["--threads", n, &l, &r, "-o", "d.pfm"], &["--threads", "1 to"]);
    }
}

/// `--alg GT` (any case) would write `disp0GT.pfm` over the ground truth: refused by batch, and
/// the scene's files are untouched.
#[test]
fn alg_gt_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["data/Scene", "--width", "96", "--height", "64", "--ndisp", "16"]);
    let scene = dir.path().join("data/Scene");
    let gt = std::fs::read(scene.join("disp0GT.pfm")).unwrap();
    let before = files_in(&scene);
    for name in ["GT", "gt"] {
        let out = run_in(dir.path(), &["batch", "data", "--alg", name]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("--alg") && err.contains("ground truth"), "{err}");
    }
    assert_eq!(files_in(&scene), before);
    assert_eq!(std::fs::read(scene.join("disp0GT.pfm")).unwrap(), gt);
}

/// A PFM whose header has CRLF line ends is read correctly (it was scored as garbage), and one
/// with bytes after the data is refused by eval, naming the file.
#[test]
fn pfm_headers_are_parsed_exactly() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["trainingQ/Scene", "--width", "96", "--height", "64", "--ndisp", "16"]);
    let scene = dir.path().join("trainingQ/Scene");
    let gt = std::fs::read(scene.join("disp0GT.pfm")).unwrap();
    let header_len = b"Pf\n96 64\n-1\n".len();
    assert!(gt.starts_with(b"Pf\n96 64\n-1\n"));
    let mut crlf = b"Pf\r\n96 64\r\n-1\r\n".to_vec();
    crlf.extend_from_slice(&gt[header_len..]);
    std::fs::write(scene.join("disp0CRLF.pfm"), &crlf).unwrap();
    let out = run_in(dir.path(), &["eval", "trainingQ", "--alg", "CRLF", "--format", "csv"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let csv = String::from_utf8_lossy(&out.stdout).into_owned();
    let row = csv.lines().find(|l| l.contains(",Scene,")).expect("a row for the scene");
    assert_eq!(row.split(',').nth(5), Some("0"), "a perfect result scores avgErr 0: {row}");
    let mut long = gt.clone();
    long.extend_from_slice(&[0, 0, 0, 0]);
    std::fs::write(scene.join("disp0LONG.pfm"), &long).unwrap();
    let out = run_in(dir.path(), &["eval", "trainingQ", "--alg", "LONG"]);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("disp0LONG.pfm") && text.contains("data bytes"), "{text}");
}

/// `jem viz` refuses an empty or non-finite colour range and an 8-bit photo given as a
/// disparity map or as --gt (each gave a plausible picture and exit 0); nothing is written.
#[test]
fn viz_refuses_bad_ranges_and_photos() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().join("d.pfm");
    pfm::write_pfm(&d, &jem::Plane::new(8, 4, 2.0f32)).unwrap();
    let d = d.to_string_lossy().into_owned();
    for (lo, hi) in [("10", "0"), ("3", "3"), ("nan", "1"), ("0", "inf")] {
        assert_clean_failure(dir.path(), &["viz", &d, "--vmin", lo, "--vmax", hi, "-o", "v.png"], &["--v"]);
    }
    let photo = dir.path().join("photo.png");
    image::RgbImage::from_pixel(8, 4, image::Rgb([90, 120, 30])).save(&photo).unwrap();
    let photo = photo.to_string_lossy().into_owned();
    assert_clean_failure(dir.path(), &["viz", &photo, "-o", "v.png"], &["photo.png", "not a disparity map"]);
    assert_clean_failure(
        dir.path(),
        &["viz", &d, "--gt", &photo, "-o", "v.png"],
        &["photo.png", "not a disparity map"],
    );
    let ok = run_in(dir.path(), &["viz", &d, "--vmin", "0", "--vmax", "4", "-o", "v.png"]);
    assert!(ok.status.success(), "{}", stderr(&ok));
}

/// An output that is (or links to) an input of the same command, or another of its outputs,
/// is refused before any work; every file is left as it was.
#[test]
fn outputs_never_overwrite_inputs() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["trainingQ/S", "--width", "96", "--height", "64", "--ndisp", "16"]);
    let ok = run_in(dir.path(), &["trainingQ/S/im0.png", "trainingQ/S/im1.png", "-o", "trainingQ/S/disp0A.pfm"]);
    assert!(ok.status.success(), "{}", stderr(&ok));
    ok_png16(dir.path(), "trainingQ/S/disp0A.pfm", "d.png");
    std::os::unix::fs::symlink(dir.path().join("trainingQ/S/im1.png"), dir.path().join("alias.png")).unwrap();
    let cases: [&[&str]; 6] = [
        &["trainingQ/S/im0.png", "trainingQ/S/im1.png", "-o", "trainingQ/S/im0.png"],
        &["trainingQ/S/im0.png", "trainingQ/S/im1.png", "-o", "alias.png"],
        &["trainingQ/S/im0.png", "trainingQ/S/im1.png", "-o", "a.pfm", "--confidence", "./a.pfm"],
        &["viz", "d.png", "-o", "d.png"],
        &["viz", "trainingQ", "--alg", "A", "-o", "trainingQ/S/im0.png"],
        &["viz", "trainingQ/S/disp0A.pfm", "--gt", "trainingQ/S/disp0GT.pfm", "-o", "trainingQ/S/mask0nocc.png"],
    ];
    let snapshot = || {
        let mut all: Vec<(String, Vec<u8>)> = Vec::new();
        for d in [dir.path().to_path_buf(), dir.path().join("trainingQ/S")] {
            for e in std::fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_file() {
                    all.push((p.display().to_string(), std::fs::read(&p).unwrap()));
                }
            }
        }
        all.sort();
        all
    };
    let before = snapshot();
    for args in cases {
        let out = run_in(dir.path(), args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains("overwrite an input") || err.contains("two outputs"), "{args:?}: {err}");
    }
    assert_eq!(snapshot(), before, "no file changed");
}

/// Writes `src` (a PFM under `dir`) as a 16-bit disparity PNG `dst` with the library.
fn ok_png16(dir: &Path, src: &str, dst: &str) {
    let map = pfm::read_pfm(&dir.join(src)).unwrap();
    jem::io::write_disparity(&dir.join(dst), &map).unwrap();
}

/// When the confidence cannot be written, the disparity map is not written either.
#[test]
fn all_outputs_or_none() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    let args = [&l, &r, "-o", "d.pfm", "--confidence", "missing/c.pfm", "--set", "model=wta"];
    assert_clean_failure(dir.path(), &args, &["missing/c.pfm"]);
    assert!(!dir.path().join("d.pfm").exists());
}

/// Inputs are read with a size cap, and only from regular files (a config from /dev/zero
/// was read until the kernel killed the process); a calib.txt with a UTF-8 byte-order mark is read; a --set value
/// with a newline is refused (the part after it was dropped silently).
#[test]
fn capped_reads_bom_and_one_line_overrides() {
    let dir = tempfile::tempdir().unwrap();
    assert_clean_failure(dir.path(), &["config", "-c", "/dev/zero"], &["/dev/zero", "not a regular file"]);
    let (l, r) = (example("im0.png"), example("im1.png"));
    assert_clean_failure(dir.path(), &[&l, &r, "-o", "d.pfm", "--set", "model=wta\nfoo=1"], &["--set", "newline"]);
    synth_scene(dir.path(), &["S", "--width", "96", "--height", "64", "--ndisp", "16"]);
    let calib = dir.path().join("S/calib.txt");
    let mut text = "\u{feff}".as_bytes().to_vec();
    text.extend(std::fs::read(&calib).unwrap());
    std::fs::write(&calib, text).unwrap();
    let ok = run_in(dir.path(), &["S/im0.png", "S/im1.png", "-o", "d.pfm", "--set", "model=wta"]);
    assert!(ok.status.success(), "{}", stderr(&ok));
    std::os::unix::fs::symlink("/dev/zero", dir.path().join("zero.pfm")).unwrap();
    assert_clean_failure(dir.path(), &["viz", "zero.pfm", "-o", "v.png"], &["zero.pfm"]);
}

/// Slanted-plane smoothing extrapolates planes to segment corners; the output stays inside
/// the searched range 0..ndisp−1 (with a range too short for the shipped example, 16 or 24 labels, the map
/// reached 18.0 and 26.0).
#[test]
fn disparities_stay_in_the_search_range() {
    let dir = tempfile::tempdir().unwrap();
    for config in ["default.toml", "jem-sps.toml"] {
        let c = repo().join("configs").join(config).to_string_lossy().into_owned();
        for ndisp in [16, 24] {
            let n = ndisp.to_string();
            let args = [&example("im0.png"), &example("im1.png"), "-o", "d.pfm", "-c", &c, "--ndisp", &n];
            let out = run_in(dir.path(), &args);
            assert!(out.status.success(), "{}", stderr(&out));
            let d = pfm::read_pfm(&dir.path().join("d.pfm")).unwrap();
            let finite = d.data().iter().filter(|v| v.is_finite());
            let (lo, hi) = finite.fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
            assert!(lo >= 0.0 && hi <= (ndisp - 1) as f32, "{config}, ndisp {ndisp}: range {lo}..{hi}");
        }
    }
}

/// A PNG that is only a header claiming `w` × `h` RGB pixels (no image data).
fn png_header_only(w: u32, h: u32) -> Vec<u8> {
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
            }
        }
        !c
    }
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(13u32.to_be_bytes());
    png.extend(&ihdr);
    png.extend(crc32(&ihdr).to_be_bytes());
    // An empty IDAT: the decoder reads the header up to the first data chunk.
    png.extend(0u32.to_be_bytes());
    png.extend(b"IDAT");
    png.extend(crc32(b"IDAT").to_be_bytes());
    png
}

/// An image too large for the memory limit is refused from its header, before it is decoded
/// (the refusal gives the estimate, not a decoding error).
#[test]
fn memory_guard_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    let big = png_header_only(60_000, 40_000);
    std::fs::write(dir.path().join("l.png"), &big).unwrap();
    std::fs::write(dir.path().join("r.png"), &big).unwrap();
    let args = ["--max-memory", "1G", "l.png", "r.png", "--ndisp", "64", "-o", "d.pfm"];
    assert_clean_failure(dir.path(), &args, &["needs about"]);
    std::fs::create_dir_all(dir.path().join("set/S")).unwrap();
    for name in ["im0.png", "im1.png"] {
        std::fs::write(dir.path().join("set/S").join(name), &big).unwrap();
    }
    std::fs::write(dir.path().join("set/S/calib.txt"), "ndisp=64\n").unwrap();
    let out = run_in(dir.path(), &["--max-memory", "1G", "batch", "set", "--alg", "A"]);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("needs about"), "{text}");
}

/// Under a file-size limit (`ulimit -f`) too small for the output, the run fails with a
/// clear error before writing; it was killed by SIGXFSZ and left its hidden temporary file.
#[test]
fn file_size_limit_is_an_error_not_a_leftover() {
    let dir = tempfile::tempdir().unwrap();
    let bin = env!("CARGO_BIN_EXE_jem");
    let script = format!(
        "ulimit -f 16; exec '{bin}' '{}' '{}' -o d.pfm --set model=wta",
        example("im0.png"),
        example("im1.png")
    );
    let out = std::process::Command::new("sh").arg("-c").arg(&script).current_dir(dir.path()).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("d.pfm") && err.contains("file-size limit"), "{err}");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "nothing left behind");
}

/// `--depth` and `--cloud` on a synthetic scene whose calib.txt gives f = width, B = 100,
/// doffs = 0: the depth map is f·B/d of the written disparity map (where d ≥ 1 px, the default range), the PLY holds one point per valid pixel at
/// (x − cx)·Z/f, (y − cy)·Z/f, Z with the left image's colour; a missing baseline is an error naming --baseline.
#[test]
fn depth_and_point_cloud() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["S", "--width", "96", "--height", "64", "--ndisp", "16", "--seed", "3"]);
    let args = ["S/im0.png", "S/im1.png", "-o", "d.pfm", "--depth", "z.pfm", "--cloud", "c.ply", "--set", "model=wta"];
    let out = run_in(dir.path(), &args);
    assert!(out.status.success(), "{}", stderr(&out));
    let disp = pfm::read_pfm(&dir.path().join("d.pfm")).unwrap();
    let depth = pfm::read_pfm(&dir.path().join("z.pfm")).unwrap();
    let (f, b, cx, cy) = (96.0f64, 100.0f64, 47.5f64, 31.5f64);
    let mut valid = Vec::new();
    // Depth is kept up to f·B, the depth of a one-pixel disparity.
    for (i, (&d, &z)) in disp.data().iter().zip(depth.data()).enumerate() {
        if d.is_finite() && d >= 1.0 {
            assert!((f64::from(z) - f * b / f64::from(d)).abs() < 1e-3 * f64::from(z), "pixel {i}: d {d}, z {z}");
            valid.push((i, f64::from(z)));
        } else {
            assert!(z.is_infinite(), "pixel {i}: d {d}, z {z}");
        }
    }
    let ply = std::fs::read(dir.path().join("c.ply")).unwrap();
    let end = b"end_header\n";
    let at = ply.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = String::from_utf8_lossy(&ply[..at]).into_owned();
    assert!(header.contains(&format!("element vertex {}\n", valid.len())), "{header}");
    assert_eq!(ply.len() - at, valid.len() * 15);
    let left = jem::io::read_image(&dir.path().join("S/im0.png")).unwrap();
    for (k, &(i, z)) in valid.iter().enumerate().step_by(97) {
        let p = &ply[at + 15 * k..at + 15 * (k + 1)];
        let v = |j: usize| f64::from(f32::from_le_bytes(p[4 * j..4 * j + 4].try_into().unwrap()));
        let (x, y) = ((i % 96) as f64, (i / 96) as f64);
        assert!((v(0) - (x - cx) * z / f).abs() < 1e-3 * z && (v(1) - (y - cy) * z / f).abs() < 1e-3 * z);
        assert!((v(2) - z).abs() < 1e-3 * z);
        assert_eq!(&p[12..15], &left.rgb(i).map(|c| c as u8));
    }
    // Without a baseline: an error before any work, nothing written.
    std::fs::write(dir.path().join("S/calib.txt"), "cam0=[96 0 47.5; 0 96 31.5; 0 0 1]\nndisp=16\n").unwrap();
    let args = ["S/im0.png", "S/im1.png", "-o", "e.pfm", "--cloud", "e.ply"];
    assert_clean_failure(dir.path(), &args, &["--baseline"]);
    let ok = run_in(dir.path(), &["S/im0.png", "S/im1.png", "-o", "e.pfm", "--cloud", "e.ply", "--baseline", "100"]);
    assert!(ok.status.success(), "{}", stderr(&ok));
}

/// JPEG input (8-bit, the image crate's decoder), also a grey JPEG beside a colour PNG.
#[test]
fn jpeg_input() {
    let dir = tempfile::tempdir().unwrap();
    for (name, grey) in [("im0.jpg", false), ("im1.jpg", false), ("im1g.jpg", true)] {
        let src = image::open(example(if name.starts_with("im0") { "im0.png" } else { "im1.png" })).unwrap();
        let mut bytes = Vec::new();
        let encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 95);
        if grey {
            src.to_luma8().write_with_encoder(encoder).unwrap();
        } else {
            src.to_rgb8().write_with_encoder(encoder).unwrap();
        }
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    let gt = example_gt();
    for right in ["im1.jpg", "im1g.jpg"] {
        let out = run_in(dir.path(), &["im0.jpg", right, "--ndisp", "48", "-o", "d.pfm"]);
        assert!(out.status.success(), "{right}: {}", stderr(&out));
        let d = pfm::read_pfm(&dir.path().join("d.pfm")).unwrap();
        assert_eq!(d.dims(), gt.dims());
        let err =
            d.data().iter().zip(gt.data()).map(|(a, b)| f64::from((a - b).abs())).sum::<f64>() / d.data().len() as f64;
        assert!(err < 1.5, "{right}: mean error {err:.3} px");
    }
}

/// BMP, TIFF and WebP (lossless) views give the bytes the same pixels as PNG give; a format that is not read
/// (GIF) is one error line listing those that are.
#[test]
fn bmp_tiff_and_webp_inputs_match_png_and_other_formats_are_listed() {
    let dir = tempfile::tempdir().unwrap();
    for (i, ext) in [(0, "bmp"), (1, "tiff"), (0, "webp"), (1, "webp")] {
        let src = image::open(example(&format!("im{i}.png"))).unwrap();
        src.save(dir.path().join(format!("im{i}.{ext}"))).unwrap();
    }
    let wta = ["--ndisp", "48", "--set", "model=wta", "-o"];
    let result = |left: &str, right: &str| {
        let out = run_in(dir.path(), &[&[left, right][..], &wta, &["d.pfm"]].concat());
        assert!(out.status.success(), "{left} {right}: {}", stderr(&out));
        std::fs::read(dir.path().join("d.pfm")).unwrap()
    };
    let png = result(&example("im0.png"), &example("im1.png"));
    assert_eq!(result("im0.bmp", "im1.tiff"), png, "BMP and TIFF");
    assert_eq!(result("im0.webp", "im1.webp"), png, "WebP");
    std::fs::remove_file(dir.path().join("d.pfm")).unwrap();
    std::fs::write(dir.path().join("a.gif"), b"GIF89a\x01\x00\x01\x00\x00\x00\x00;").unwrap();
    assert_clean_failure(
        dir.path(),
        &["a.gif", "im1.tiff", "-o", "d.pfm"],
        &["a.gif", "GIF images are not read", "PNG, PPM/PGM/PNM, JPEG, BMP, TIFF, WebP"],
    );
}

/// A calib.txt whose ndisp is the image width (ETH3D style) is not trusted: the range is measured on
/// the pair, the run is as accurate as with the true range, and far fewer labels are searched.
#[test]
fn ndisp_equal_to_width_is_measured() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["S", "--width", "320", "--height", "240", "--ndisp", "64", "--seed", "5"]);
    let gt = pfm::read_pfm(&dir.path().join("S/disp0GT.pfm")).unwrap();
    let mean_err = |name: &str| {
        let d = pfm::read_pfm(&dir.path().join(name)).unwrap();
        d.data().iter().zip(gt.data()).map(|(a, b)| f64::from((a - b).abs().min(64.0))).sum::<f64>()
            / d.data().len() as f64
    };
    let out = run_in(dir.path(), &["S/im0.png", "S/im1.png", "-o", "true.pfm"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let calib = std::fs::read_to_string(dir.path().join("S/calib.txt")).unwrap().replace("ndisp=64", "ndisp=320");
    std::fs::write(dir.path().join("S/calib.txt"), calib).unwrap();
    let out = run_in(dir.path(), &["S/im0.png", "S/im1.png", "-o", "auto.pfm"]);
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    let n: usize = err.split("ndisp ").nth(1).and_then(|t| t.split(',').next()).and_then(|t| t.parse().ok()).unwrap();
    assert!(n <= 128 && err.contains("calib.txt says 320"), "{err}");
    let (t, a) = (mean_err("true.pfm"), mean_err("auto.pfm"));
    assert!(a <= t + 0.1, "mean error with the measured range {a:.3}, with the true one {t:.3}");
}

/// A range of nearly the image width (given with --ndisp) runs with the default config: the coarse prior is
/// skipped when its half-size run could not hold the range (it made the whole run fail).
#[test]
fn ndisp_near_the_width_runs_with_the_defaults() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["S", "--width", "96", "--height", "64", "--ndisp", "16"]);
    let out = run_in(dir.path(), &["S/im0.png", "S/im1.png", "-o", "d.pfm", "--ndisp", "95"]);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// `jem` with no range and `jem batch` with one that is no bound (a calib.txt with ndisp = the width,
/// as ETH3D writes) measure the range up to the same limit, [`jem::range::search_limit`] (before, `jem` stopped at
/// half the width). A random texture seen with a disparity of 60 px in a 96 px wide pair: both paths find a range
/// past half the width, agree on it, and write the same map.
#[test]
fn jem_and_batch_search_up_to_the_same_limit() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("shifted");
    std::fs::create_dir(&scene).unwrap();
    let (w, h, d) = (96, 48, 60);
    let mut rng = jem::internals::SplitMix64::new(38);
    let texture: Vec<u8> = (0..(w + d) * h).map(|_| (rng.next_u64() >> 56) as u8).collect();
    // Left pixel x shows texture column x, right pixel x texture column x + d: left x matches right x − d.
    for (f, from) in [("im0.png", 0), ("im1.png", d)] {
        let rgb: Vec<u8> = (0..w * h).flat_map(|i| [texture[(i / w) * (w + d) + i % w + from]; 3]).collect();
        jem::io::write_png_rgb8(&scene.join(f), w, h, &rgb).unwrap();
    }
    let wta = ["--set", "model=wta"];
    let out = run_in(&scene, &[&["im0.png", "im1.png", "-o", "match.pfm"][..], &wta].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let said = stderr(&out);
    let ndisp: usize =
        said.split("ndisp ").nth(1).and_then(|r| r.split(',').next()).and_then(|n| n.parse().ok()).unwrap();
    assert!(ndisp > d && ndisp <= w, "{said}");
    std::fs::write(scene.join("calib.txt"), format!("width={w}\nheight={h}\nndisp={w}\n")).unwrap();
    let out = run_in(dir.path(), &[&["batch", "shifted", "--alg", "T"][..], &wta].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let jem = std::fs::read(scene.join("match.pfm")).unwrap();
    assert!(jem == std::fs::read(scene.join("disp0T.pfm")).unwrap(), "jem and jem batch wrote different maps");
}

/// When the range is measured (no calib.txt, no `--ndisp`), the memory limit is checked from
/// both headers before either image is decoded, in `jem` and `jem batch`: the loading, the range measurement
/// (which then runs within the limit) and the run. 1ea02dd decoded first (here: a decoding error, as the files
/// are headers only; on real images, a 2872 × 1984 pair peaked at 1.17 GB under `--max-memory 20M`).
#[test]
fn memory_checked_before_decoding_when_the_range_is_measured() {
    let dir = tempfile::tempdir().unwrap();
    let big = png_header_only(2872, 1984);
    std::fs::write(dir.path().join("l.png"), &big).unwrap();
    std::fs::write(dir.path().join("r.png"), &big).unwrap();
    assert_clean_failure(dir.path(), &["--max-memory", "20M", "l.png", "r.png", "-o", "d.pfm"], &["needs about"]);
    std::fs::create_dir_all(dir.path().join("set/S")).unwrap();
    for name in ["im0.png", "im1.png"] {
        std::fs::write(dir.path().join("set/S").join(name), &big).unwrap();
    }
    // ndisp = the width is no real bound: the range is measured.
    std::fs::write(dir.path().join("set/S/calib.txt"), "ndisp=2872\n").unwrap();
    let out = run_in(dir.path(), &["--max-memory", "20M", "batch", "set", "--alg", "A"]);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), stderr(&out));
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("needs about"), "{text}");
}

/// Both headers are read before either image is decoded, so a right image of another size is
/// refused from its header (1ea02dd decoded it first: here a decoding error, as it is a header only); and with
/// no range (no calib.txt, no `--ndisp`), views of different sizes are the same one-line error (1ea02dd: a panic
/// in the cost volume, exit 101).
#[test]
fn right_header_read_before_decoding() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(example("im0.png"), dir.path().join("l.png")).unwrap();
    std::fs::write(dir.path().join("big.png"), png_header_only(8000, 6000)).unwrap();
    let mismatch = "left image is 320x240 but right image is 8000x6000";
    assert_clean_failure(dir.path(), &["l.png", "big.png", "--ndisp", "16", "-o", "d.pfm"], &[mismatch]);
    assert_clean_failure(dir.path(), &["l.png", "big.png", "-o", "d.pfm"], &[mismatch]);
    synth_scene(dir.path(), &["S", "--width", "64", "--height", "48", "--ndisp", "16"]);
    std::fs::copy(dir.path().join("S/im1.png"), dir.path().join("small.png")).unwrap();
    assert_clean_failure(dir.path(), &["l.png", "small.png", "-o", "d.pfm"], &["320x240", "64x48"]);
}

/// An output path that is an existing folder (`-o`, `--confidence`, `--depth`, `--cloud`) is
/// refused before any work, and nothing is written (1ea02dd ran the pair, renamed `d.pfm` into place, then failed
/// on the folder: exit 2 with `d.pfm` left). In batch, a time file that cannot be written (a folder in its
/// place) leaves no disparity map that a later `--skip-existing` would trust.
#[test]
fn an_output_that_is_a_folder_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["S", "--width", "64", "--height", "48", "--ndisp", "16"]);
    std::fs::create_dir(dir.path().join("k.pfm")).unwrap();
    std::fs::create_dir(dir.path().join("c.ply")).unwrap();
    let run = ["S/im0.png", "S/im1.png", "--set", "model=wta"];
    for extra in [&["--confidence", "k.pfm"][..], &["--depth", "k.pfm"], &["--cloud", "c.ply"]] {
        assert_clean_failure(dir.path(), &[&run[..], &["-o", "d.pfm"], extra].concat(), &[extra[1], "folder"]);
    }
    assert_clean_failure(dir.path(), &[&run[..], &["-o", "k.pfm"]].concat(), &["k.pfm", "folder"]);
    std::fs::create_dir(dir.path().join("S/timeA.txt")).unwrap();
    let out = run_in(dir.path(), &["batch", "S", "--alg", "A"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(!dir.path().join("S/disp0A.pfm").exists(), "a disparity map without its time file");
}

/// A closed stdout and stderr (`jem batch … 2>&1 | head -1`) do not stop the work: every scene
/// is written and the exit code is 0 (1ea02dd panicked on its second progress line, exit 101, after one scene).
#[test]
fn a_closed_pipe_does_not_stop_the_batch() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["S1", "S2", "S3"] {
        synth_scene(dir.path(), &[&format!("set/{name}"), "--width", "64", "--height", "48", "--ndisp", "16"]);
    }
    let mut child = common::jem()
        .current_dir(dir.path())
        .args(["batch", "set", "--alg", "A", "--set", "model=wta"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Both read ends closed at once: every line the batch prints goes to a closed pipe.
    drop(child.stdout.take());
    drop(child.stderr.take());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(0));
    for name in ["S1", "S2", "S3"] {
        assert!(dir.path().join("set").join(name).join("disp0A.pfm").is_file(), "{name} not written");
    }
}

/// Global flags before every subcommand, `degrade` included (1ea02dd: "the subcommand 'OUT'
/// cannot be used with --threads"): a degrade run, and each subcommand's help.
#[test]
fn global_flags_before_every_subcommand() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["src/S", "--width", "64", "--height", "48", "--ndisp", "16"]);
    let out = run_in(dir.path(), &["--threads", "1", "-q", "degrade", "src", "out", "--recipe", "noise:2"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.path().join("out/S/im0.png").is_file());
    for (sub, flags) in [
        ("match", &["--threads", "1", "--max-memory", "1G"][..]),
        ("batch", &["--threads", "1", "--max-memory=1G", "-q"]),
        ("sequence", &["--threads", "1", "--max-memory", "1G"]),
        ("synth", &["--threads", "1", "-v"]),
        ("degrade", &["--threads=1"]),
        ("eval", &["--threads", "1"]),
        ("config", &["-q"]),
        ("viz", &["-v"]),
    ] {
        let out = run_in(dir.path(), &[flags, &[sub, "--help"]].concat());
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success() && text.contains(&format!("Usage: jem {sub}")), "{sub}: {text}{}", stderr(&out));
    }
}

/// `--threads` and `--max-memory` are offered only where they mean something: `--threads` on the
/// commands that share work out (match, batch, sequence, synth, degrade, eval), `--max-memory` on those that run the
/// pipeline (match, batch, sequence); `config` and `viz` refuse both, before or after the subcommand, naming the flag. And `degrade
/// --recipe`'s short help lists every recipe.
#[test]
fn resource_flags_only_where_they_mean_something() {
    let dir = tempfile::tempdir().unwrap();
    for (sub, threads, memory) in [
        ("match", true, true),
        ("batch", true, true),
        ("sequence", true, true),
        ("synth", true, false),
        ("degrade", true, false),
        ("eval", true, false),
        ("config", false, false),
        ("viz", false, false),
    ] {
        let help = String::from_utf8_lossy(&run_in(dir.path(), &[sub, "--help"]).stdout).into_owned();
        assert_eq!(help.contains("--threads"), threads, "{sub} --help: {help}");
        assert_eq!(help.contains("--max-memory"), memory, "{sub} --help: {help}");
    }
    for args in
        [&["--threads", "1", "config"][..], &["config", "--threads", "1"], &["--max-memory", "1G", "viz", "d.pfm"]]
    {
        let out = run_in(dir.path(), args);
        let flag = args.iter().find(|a| a.starts_with("--")).unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(stderr(&out).contains(&format!("unexpected argument '{flag}'")), "{args:?}: {}", stderr(&out));
    }
    let help = String::from_utf8_lossy(&run_in(dir.path(), &["degrade", "-h"]).stdout).into_owned();
    let recipe = help.lines().find(|l| l.trim_start().starts_with("--recipe")).unwrap_or_default();
    for kind in ["noise:", "lowlight:", "exposure:", "blur:", "misalign:", "jpeg:"] {
        assert!(recipe.contains(kind), "degrade -h: --recipe omits {kind}: {recipe}");
    }
}

/// With no range given, a 1-pixel-wide pair is refused for its width, not with "invalid
/// ndisp = 2" (1ea02dd) for a range nobody gave; pairs 2 pixels wide and more run, their range measured.
#[test]
fn a_one_pixel_wide_pair_is_refused_for_its_width() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (w, h) in [(1u32, 1u32), (1, 5), (2, 1), (3, 2), (5, 40)] {
        for name in ["a.png", "b.png"] {
            image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 40) as u8, (y * 70) as u8, 9]))
                .save(d.join(name))
                .unwrap();
        }
        let out = run_in(d, &["a.png", "b.png", "-o", "o.pfm", "-q"]);
        let err = stderr(&out);
        if w == 1 {
            assert_clean_failure(
                d,
                &["a.png", "b.png", "-o", "o.pfm"],
                &["a.png", &format!("{w}x{h}"), "2 pixels wide"],
            );
            assert!(!err.contains("ndisp"), "{w}x{h}: {err}");
        } else {
            assert!(out.status.success(), "{w}x{h}: {err}");
        }
    }
}

/// `--max-memory 0.5` (half a byte) is refused with a clear error; 1ea02dd read it as a limit of
/// 0 bytes ("the memory limit is 0 B").
#[test]
fn a_max_memory_below_one_byte_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    for size in ["0.5", "0.9B"] {
        let out = run_in(dir.path(), &["--max-memory", size, "batch", "--help"]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{size}: {err}");
        assert!(err.contains("less than one byte") && err.contains("0.5G"), "{size}: {err}");
    }
    let out = run_in(dir.path(), &["--max-memory", "0.5G", "batch", "--help"]);
    assert!(out.status.success(), "{}", stderr(&out));
}

/// Absurd but finite camera values. A focal length times baseline beyond 32-bit floats is
/// refused before any work (1ea02dd: exit 0, a depth map of `inf` and a PLY of points at ±inf; with 1e30 × 1e30,
/// finite in 64 bits, later an all-`inf` depth map and an empty cloud); values whose product fits but put some
/// points beyond `f32` give no such point, and `inf` depth exactly where there is no point. A flag's own bad
/// value is blamed on the flag, not on the calib.txt beside the views.
#[test]
fn overflowing_geometry_writes_no_infinite_point() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["S", "--width", "64", "--height", "48", "--ndisp", "16"]);
    let run = ["S/im0.png", "S/im1.png", "-o", "d.pfm", "--depth", "z.pfm", "--cloud", "c.ply", "--set", "model=wta"];
    for huge in [["--focal", "1e30", "--baseline", "1e30"], ["--focal", "1e300", "--baseline", "1e300"]] {
        assert_clean_failure(dir.path(), &[&run[..], &huge].concat(), &["beyond 32-bit floats", "baseline"]);
    }
    let nan = ["--max-depth", "NaN"];
    assert_clean_failure(dir.path(), &[&run[..], &nan].concat(), &["invalid --max-depth NaN"]);
    let err = stderr(&run_in(dir.path(), &[&run[..], &nan].concat()));
    assert!(!err.contains("calib.txt"), "the flag's value is not calib.txt's: {err}");
    let out = run_in(dir.path(), &[&run[..], &["--focal", "1", "--baseline", "1e38"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let ply = std::fs::read(dir.path().join("c.ply")).unwrap();
    let end = b"end_header\n";
    let at = ply.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let points: Vec<[f32; 3]> =
        ply[at..].chunks(15).map(|p| [0, 4, 8].map(|k| f32::from_le_bytes(p[k..k + 4].try_into().unwrap()))).collect();
    assert!(points.iter().flatten().all(|v| v.is_finite()), "a non-finite point");
    let depth = pfm::read_pfm(&dir.path().join("z.pfm")).unwrap();
    assert_eq!(depth.data().iter().filter(|z| z.is_finite()).count(), points.len(), "depth and cloud disagree");
    assert!(!points.is_empty() && points.len() < 64 * 48, "{} points", points.len());
}

/// The image decoder's own allocation limit is `--max-memory` (checked from the headers
/// first), not its default of 512 MiB: a 20000 × 20000 header under `--max-memory 1T` reaches the decoder's
/// real complaint (the data is missing) instead of 1ea02dd's "Memory limit exceeded".
#[test]
fn the_decoder_limit_is_the_memory_limit() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("h.png"), png_header_only(20_000, 20_000)).unwrap();
    let args = ["--max-memory", "1T", "h.png", "h.png", "--ndisp", "16", "-o", "d.pfm"];
    assert_clean_failure(dir.path(), &args, &["h.png", "end of file"]);
    assert!(!stderr(&run_in(dir.path(), &args)).contains("Memory limit exceeded"));
}

/// A newline in a scene's folder name is shown escaped (`a\nb`), so it cannot break the batch
/// table or the progress lines (1ea02dd printed the name as it is: the row split over two lines).
#[test]
fn a_newline_in_a_scene_name_keeps_the_batch_table_whole() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["set/a\nb", "set/c"] {
        synth_scene(dir.path(), &[name, "--width", "64", "--height", "48", "--ndisp", "16"]);
    }
    let out = run_in(dir.path(), &["batch", "set", "--alg", "A", "--set", "model=wta"]);
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(table.lines().count(), 4, "header, two rows, the counts: {table}");
    assert!(table.lines().any(|l| l.starts_with("a\\nb ") && l.ends_with("ok")), "{table}");
    let progress = stderr(&out);
    assert!(progress.lines().all(|l| l.starts_with('[') || l.contains("pair(s)")), "{progress}");
}

/// The hidden temporary tree of a killed `jem degrade` (SIGTERM, SIGKILL) is removed by the next
/// run into the same folder when its process is gone; one whose process is alive is left alone (1ea02dd swept
/// nothing: the leftover stayed for good).
#[test]
fn degrade_sweeps_the_tree_of_a_killed_run() {
    let dir = tempfile::tempdir().unwrap();
    synth_scene(dir.path(), &["src/S", "--width", "64", "--height", "48", "--ndisp", "16"]);
    let host: String = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .unwrap_or_default()
        .trim()
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '.'))
        .collect();
    // A pid above Linux's largest (2^22) belongs to no process; this test's own pid is alive.
    let dead = dir.path().join(format!(".out.jem-tmp-{host}-4000000000"));
    let alive = dir.path().join(format!(".out.jem-tmp-{host}-{}", std::process::id()));
    for d in [&dead, &alive] {
        std::fs::create_dir_all(d.join("S")).unwrap();
        std::fs::write(d.join("S/im0.png"), b"partial").unwrap();
    }
    let out = run_in(dir.path(), &["degrade", "src", "out", "--recipe", "noise:2"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!dead.exists(), "the killed run's tree is left");
    assert!(alive.is_dir(), "a running process's tree was removed");
}
