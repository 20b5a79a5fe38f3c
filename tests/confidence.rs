//! A confidence that ranks errors. The map is the same whatever the thread count, puts a region
//! that cannot be matched below the rest, and `jem eval` scores it (the sparsification AUC) when it is beside the
//! result, and only then.

mod common;

use std::path::Path;

use common::{repo, run_in, stderr};

fn example(name: &str) -> String {
    repo().join("examples").join("synth").join(name).to_string_lossy().into_owned()
}

#[test]
fn confidence_bytes_are_the_same_whatever_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = (example("im0.png"), example("im1.png"));
    for t in ["1", "2"] {
        let out = run_in(
            dir.path(),
            &["--threads", t, &l, &r, "-o", &format!("d{t}.pfm"), "--confidence", &format!("c{t}.pfm")],
        );
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let read = |name: &str| std::fs::read(dir.path().join(name)).unwrap();
    assert!(read("c1.pfm") == read("c2.pfm"), "the confidence differs between 1 and 2 threads");
    let c = jem::io::pfm::read_pfm(&dir.path().join("c1.pfm")).unwrap();
    assert!(c.data().iter().all(|v| (0.0..=1.0).contains(v)), "the confidence is in 0..1");
}

/// The example with a square of the left view replaced by noise the right view does not have: nothing there has a
/// match, so the square's pixels must rank below the rest.
#[test]
fn a_region_that_cannot_be_matched_ranks_below_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let square = |x: u32, y: u32| (120..200).contains(&x) && (80..160).contains(&y);
    let mut img = image::open(example("im0.png")).unwrap().to_rgb8();
    let mut state = 1u32;
    for (x, y, p) in img.enumerate_pixels_mut() {
        if square(x, y) {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let v = (state >> 24) as u8;
            *p = image::Rgb([v, v, v]);
        }
    }
    img.save(dir.path().join("im0.png")).unwrap();
    std::fs::copy(example("im1.png"), dir.path().join("im1.png")).unwrap();
    let out = run_in(dir.path(), &["im0.png", "im1.png", "-o", "d.pfm", "--ndisp", "48", "--confidence", "c.pfm"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let c = jem::io::pfm::read_pfm(&dir.path().join("c.pfm")).unwrap();
    let (w, _) = c.dims();
    let (mut inside, mut outside) = (Vec::new(), Vec::new());
    for (i, &v) in c.data().iter().enumerate() {
        let (x, y) = ((i % w) as u32, (i / w) as u32);
        // Away from the square's edge, where the pixels are clearly one or the other.
        if square(x, y) && square(x.saturating_sub(10), y.saturating_sub(10)) && square(x + 10, y + 10) {
            inside.push(v);
        } else if !square(x.saturating_sub(10), y)
            && !square(x + 10, y)
            && !square(x, y.saturating_sub(10))
            && !square(x, y + 10)
        {
            outside.push(v);
        }
    }
    let mean = |v: &[f32]| v.iter().map(|&x| f64::from(x)).sum::<f64>() / v.len() as f64;
    let (i, o) = (mean(&inside), mean(&outside));
    assert!(i < 0.5 * o, "mean confidence {i:.3} in the flat square, {o:.3} outside");
}

fn eval(dir: &Path, alg: &str, format: &str) -> String {
    let out = run_in(dir, &["eval", "set", "--alg", alg, "--scale", "1", "--format", format]);
    assert!(out.status.success(), "{}", stderr(&out));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn eval_prints_the_auc_when_a_confidence_map_is_beside_the_result_and_not_otherwise() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_in(dir.path(), &["synth", "set/scene", "--seed", "3"]);
    assert!(out.status.success(), "{}", stderr(&out));
    for args in [&["--alg", "PLAIN"][..], &["--alg", "CONF", "--confidence"]] {
        let out = run_in(dir.path(), &[&["batch", "set", "-q"], args].concat());
        assert!(out.status.success(), "{}", stderr(&out));
    }
    assert!(dir.path().join("set/scene/conf0CONF.pfm").is_file());
    assert!(!dir.path().join("set/scene/conf0PLAIN.pfm").exists());
    let (plain, conf) = (eval(dir.path(), "PLAIN", "table"), eval(dir.path(), "CONF", "table"));
    assert!(!plain.contains("AUC"), "{plain}");
    assert!(conf.contains("AUC opt"), "{conf}");
    let json: serde_json::Value = serde_json::from_str(&eval(dir.path(), "CONF", "json")).unwrap();
    let auc = json["scenes"]["scene"]["auc"].as_f64().unwrap();
    let optimum = json["sparsification"]["auc_optimum"].as_f64().unwrap();
    assert!(auc >= optimum && auc < 0.2, "{json}");
    let json: serde_json::Value = serde_json::from_str(&eval(dir.path(), "PLAIN", "json")).unwrap();
    assert!(json.get("sparsification").is_none() && json["scenes"]["scene"].get("auc").is_none(), "{json}");
}
