//! The rows and ground truths a contact sheet finds in small trees of empty files (only their names and places
//! matter until a row is drawn).

use std::path::{Path, PathBuf};

use super::*;
use crate::dataset::{GT_FILE, MASK_FILE};

/// Creates empty files at `names` under `dir` (and the folders they need).
fn touch(dir: &Path, names: &[&str]) {
    for name in names {
        let path = dir.join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, b"").unwrap();
    }
}

#[test]
fn middlebury_rows_take_the_scene_truth_and_scale() {
    let dir = tempfile::tempdir().unwrap();
    let q = dir.path().join("trainingQ");
    touch(&q, &["A/im0.png", "A/disp0X.pfm", "A/disp0GT.pfm", "A/mask0nocc.png"]);
    touch(&q, &["B/im0.png", "B/disp0X.pfm", "B/disp0GT.pfm"]);
    touch(&q, &["C/im0.png", "C/disp0X.pfm"]);
    // No result of X: not a row.
    touch(&q, &["D/im0.png", "D/disp0GT.pfm"]);
    let rows = sheet_rows(dir.path(), "X", &SheetOptions::default()).unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names.len(), 3, "{names:?}");
    let truth = |scene: &str, mask: bool| TruthFiles {
        disparity: q.join(scene).join(GT_FILE),
        occlusion: mask.then(|| Occlusion::Mask(q.join(scene).join(MASK_FILE))),
    };
    assert_eq!(rows[0].truth, Some(truth("A", true)));
    assert_eq!(rows[1].truth, Some(truth("B", false)));
    assert_eq!(rows[2].truth, None);
    // The scale from the trainingQ folder where there is truth to score; 1 (unused) where there is none.
    assert_eq!(rows[0].rule, ErrorRule::Middlebury { scale: 4 });
    assert_eq!(rows[0].resolution.as_ref().map(|r| r.scale), Some(4));
    assert_eq!(rows[2].rule, ErrorRule::Middlebury { scale: 1 });
    assert_eq!(rows[0].left, q.join("A/im0.png"));
    assert_eq!(rows[0].result, q.join("A/disp0X.pfm"));
    assert_eq!(rows[0].calib, Some(q.join("A/calib.txt")));
    assert_eq!(rows[0].paths().len(), 5, "left, result, truth, mask, calib");
    // A given scale wins over the path's.
    let given = SheetOptions { scale: Some(2), ..SheetOptions::default() };
    let rows = sheet_rows(dir.path(), "X", &given).unwrap();
    assert_eq!((rows[0].rule, rows[0].resolution.is_none()), (ErrorRule::Middlebury { scale: 2 }, true));
}

#[test]
fn no_scene_with_a_result_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    touch(dir.path(), &["A/im0.png", "A/disp0GT.pfm"]);
    let e = sheet_rows(dir.path(), "X", &SheetOptions::default()).unwrap_err().to_string();
    assert!(e.contains("disp0X.pfm"), "{e}");
}

#[test]
fn gt_rule_recognises_each_layout() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // KITTI: the map of all pixels is the truth and the non-occluded map marks the occlusions, whichever is given.
    touch(d, &["k/disp_noc_0/000000_10.png", "k/disp_occ_0/000000_10.png", "k/disp_occ_0/000001_10.png"]);
    let (noc, occ) = (d.join("k/disp_noc_0/000000_10.png"), d.join("k/disp_occ_0/000000_10.png"));
    let both = TruthFiles { disparity: occ.clone(), occlusion: Some(Occlusion::NonOccludedMap(noc.clone())) };
    for given in [&noc, &occ] {
        let t = gt_rule(given, None, None).unwrap();
        assert_eq!((t.files, t.rule), (both.clone(), ErrorRule::KittiD1));
    }
    let alone = d.join("k/disp_occ_0/000001_10.png");
    assert_eq!(gt_rule(&alone, None, None).unwrap().files, TruthFiles { disparity: alone, occlusion: None });
    // ETH3D: a scene folder in a `*_gt` tree, its mask beside the map.
    touch(d, &["two_view_training_gt/s/disp0GT.pfm", "two_view_training_gt/s/mask0nocc.png"]);
    let gt = d.join("two_view_training_gt/s/disp0GT.pfm");
    let t = gt_rule(&gt, None, None).unwrap();
    assert_eq!(t.rule, ErrorRule::Eth3d);
    assert_eq!(t.files.occlusion, Some(Occlusion::Mask(d.join("two_view_training_gt/s/mask0nocc.png"))));
    // MiddEval3: the scale from the path, from `scale`, or an error naming --scale.
    touch(d, &["trainingH/s/disp0GT.pfm", "elsewhere/s/disp0GT.pfm"]);
    let t = gt_rule(&d.join("trainingH/s/disp0GT.pfm"), None, None).unwrap();
    assert_eq!((t.rule, t.files.occlusion), (ErrorRule::Middlebury { scale: 2 }, None));
    let unknown = d.join("elsewhere/s/disp0GT.pfm");
    assert!(gt_rule(&unknown, None, None).unwrap_err().to_string().contains("--scale"));
    assert_eq!(gt_rule(&unknown, None, Some(1)).unwrap().rule, ErrorRule::Middlebury { scale: 1 });
    // A layout given overrides the recognition.
    assert_eq!(gt_rule(&unknown, Some(Layout::Eth3d), None).unwrap().rule, ErrorRule::Eth3d);
}

#[test]
fn kitti_and_existing_truths_take_what_exists() {
    let dir = tempfile::tempdir().unwrap();
    let (all, nonocc): (PathBuf, PathBuf) = (dir.path().join("occ.png"), dir.path().join("noc.png"));
    assert_eq!(kitti_truth(all.clone(), nonocc.clone()), None);
    touch(dir.path(), &["noc.png"]);
    assert_eq!(
        kitti_truth(all.clone(), nonocc.clone()),
        Some(TruthFiles { disparity: nonocc.clone(), occlusion: None })
    );
    touch(dir.path(), &["occ.png"]);
    let both = kitti_truth(all.clone(), nonocc.clone()).unwrap();
    assert_eq!(both.paths(), [all.as_path(), nonocc.as_path()]);
    // A scene's truth: nothing without the map; the mask only when it exists.
    let scene = dir.path().join("s");
    assert_eq!(TruthFiles::existing(Truth::in_scene(&scene)), None);
    touch(&scene, &[GT_FILE]);
    assert_eq!(TruthFiles::existing(Truth::in_scene(&scene)).unwrap().occlusion, None);
    touch(&scene, &[MASK_FILE]);
    assert_eq!(
        TruthFiles::existing(Truth::in_scene(&scene)).unwrap().occlusion,
        Some(Occlusion::Mask(scene.join(MASK_FILE)))
    );
}
