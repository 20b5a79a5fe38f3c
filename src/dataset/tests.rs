use super::*;

/// Creates the (empty) files under `root`.
fn touch(root: &Path, files: &[&str]) {
    for f in files {
        let p = root.join(f);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, b"").unwrap();
    }
}

fn names(pairs: &[Pair]) -> Vec<(Layout, String)> {
    pairs.iter().map(|p| (p.layout, p.name.clone())).collect()
}

#[test]
fn recognises_each_layout() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    touch(
        root,
        &[
            "kitti15/training/image_2/000000_10.png",
            "kitti15/training/image_2/000000_11.png",
            "kitti15/training/image_3/000000_10.png",
            "kitti15/training/image_3/000000_11.png",
            "kitti15/training/image_2/000001_10.png", // no right view: listed, to fail loudly
            "kitti15/training/disp_noc_0/000000_10.png",
            "kitti12/training/colored_0/000007_10.png",
            "kitti12/training/colored_1/000007_10.png",
            "kitti12/grey/image_0/000003_10.png",
            "kitti12/grey/image_1/000003_10.png",
            "eth/two_view_training/delivery_area_1l/im0.png",
            "eth/two_view_training/delivery_area_1l/im1.png",
            "eth/two_view_training/delivery_area_1l/calib.txt",
            "eth/two_view_training_gt/delivery_area_1l/disp0GT.pfm",
            "eth/two_view_training/forest_1s/im0.png", // no right view: listed, to fail loudly
            "eth/two_view_training/forest_1s/calib.txt",
            "eth/two_view_training_gt/forest_1s/disp0GT.pfm",
            "mid/trainingQ/Lone/im0.png", // no right view, outside an ETH3D tree: no scene
            "mid/trainingQ/Teddy/im0.png",
            "mid/trainingQ/Teddy/im1.png",
            "mid/trainingQ/Teddy/calib.txt",
            "mid/trainingQ/Teddy/disp0GT.pfm",
        ],
    );
    let pairs = discover(&[root.to_path_buf()], Purpose::Run, &Discovery::default()).unwrap();
    assert_eq!(
        names(&pairs),
        [
            (Layout::Eth3d, "delivery_area_1l".into()),
            (Layout::Eth3d, "forest_1s".into()),
            (Layout::Kitti2012, "000003_10".into()),
            (Layout::Kitti2012, "000007_10".into()),
            (Layout::Kitti2015, "000000_10".into()),
            (Layout::Kitti2015, "000001_10".into()),
            (Layout::Middlebury, "Teddy".into()),
        ]
    );
    let kitti = &pairs[4];
    assert_eq!(kitti.root, root.join("kitti15/training"));
    assert_eq!(kitti.left, root.join("kitti15/training/image_2/000000_10.png"));
    assert_eq!(kitti.right, root.join("kitti15/training/image_3/000000_10.png"));
    assert_eq!((kitti.calib.as_ref(), kitti.default_ndisp()), (None, Some(KITTI_NDISP)));
    assert_eq!(pairs[2].left, root.join("kitti12/grey/image_0/000003_10.png"));
    assert_eq!(pairs[0].root, root.join("eth/two_view_training"));
    assert_eq!(pairs[0].default_ndisp(), None);

    // Scoring: only what has ground truth (the 2012 trees have no disp_noc/).
    let scored = discover(&[root.to_path_buf()], Purpose::Score, &Discovery::default()).unwrap();
    assert_eq!(
        names(&scored),
        [
            (Layout::Eth3d, "delivery_area_1l".into()),
            (Layout::Eth3d, "forest_1s".into()),
            (Layout::Kitti2015, "000000_10".into()),
            (Layout::Kitti2015, "000001_10".into()),
            (Layout::Middlebury, "Teddy".into())
        ]
    );

    // --layout: ETH3D scenes read as MiddEval3; a KITTI layout keeps only its frames.
    let forced = Discovery { layout: Some(Layout::Middlebury), gt: None };
    let mid = discover(&[root.join("eth")], Purpose::Run, &forced).unwrap();
    assert_eq!(names(&mid), [(Layout::Middlebury, "delivery_area_1l".into())]);
    let only = Discovery { layout: Some(Layout::Kitti2012), gt: None };
    assert_eq!(discover(&[root.to_path_buf()], Purpose::Run, &only).unwrap().len(), 2);
}

#[test]
fn results_and_truth_paths() {
    let kitti = Pair {
        layout: Layout::Kitti2015,
        name: "000042_10".into(),
        root: PathBuf::from("/d/kitti/training"),
        left: PathBuf::from("/d/kitti/training/image_2/000042_10.png"),
        right: PathBuf::from("/d/kitti/training/image_3/000042_10.png"),
        calib: None,
    };
    let files = kitti.result_files("Jem", None);
    assert_eq!(files.disparity, Path::new("/d/kitti/results/Jem/training/disp_0/000042_10.png"));
    assert_eq!(files.time, Path::new("/d/kitti/results/Jem/training/time/000042_10.txt"));
    assert_eq!(
        kitti.result_files("Jem", Some(Path::new("/out"))).disparity,
        Path::new("/out/Jem/training/disp_0/000042_10.png")
    );
    assert_eq!(kitti.truth(false, None).disparity, Path::new("/d/kitti/training/disp_noc_0/000042_10.png"));
    assert_eq!(kitti.truth(true, None).disparity, Path::new("/d/kitti/training/disp_occ_0/000042_10.png"));
    let k12 = Pair { layout: Layout::Kitti2012, ..kitti.clone() };
    assert_eq!(k12.truth(true, None).disparity, Path::new("/d/kitti/training/disp_occ/000042_10.png"));

    let eth = Pair {
        layout: Layout::Eth3d,
        name: "playground_1l".into(),
        root: PathBuf::from("/d/two_view_training"),
        left: PathBuf::from("/d/two_view_training/playground_1l/im0.png"),
        right: PathBuf::from("/d/two_view_training/playground_1l/im1.png"),
        calib: Some(PathBuf::from("/d/two_view_training/playground_1l/calib.txt")),
    };
    let files = eth.result_files("Jem", None);
    assert_eq!(files.disparity, Path::new("/d/results/Jem/two_view_training/low_res_two_view/playground_1l.pfm"));
    assert_eq!(files.time, Path::new("/d/results/Jem/two_view_training/low_res_two_view/playground_1l.txt"));
    assert_eq!(eth.time_text(1.5), "runtime 1.500000\n");
    let truth = eth.truth(false, None);
    assert_eq!(truth.disparity, Path::new("/d/two_view_training_gt/playground_1l/disp0GT.pfm"));
    assert_eq!(truth.mask.unwrap(), Path::new("/d/two_view_training_gt/playground_1l/mask0nocc.png"));
    assert_eq!(eth.truth(false, Some(Path::new("/g"))).disparity, Path::new("/g/playground_1l/disp0GT.pfm"));

    let mid = Pair { layout: Layout::Middlebury, root: PathBuf::from("/m/Teddy"), ..eth };
    assert_eq!(mid.result_files("Jem", None).disparity, Path::new("/m/Teddy/disp0Jem.pfm"));
    assert_eq!(mid.result_files("Jem", None).time, Path::new("/m/Teddy/timeJem.txt"));
    assert_eq!(mid.results_dir("Jem", None), None);
}

#[test]
fn a_results_folder_belongs_to_one_data_set() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    for split in ["training", "testing"] {
        touch(root, &[&format!("k/{split}/image_2/000000_10.png"), &format!("k/{split}/image_3/000000_10.png")]);
    }
    std::fs::write(root.join("k/testing/image_2/000000_10.png"), b"other").unwrap();
    let all = discover(&[root.join("k")], Purpose::Run, &Discovery::default()).unwrap();
    assert_eq!(all.len(), 2);
    // Each split its own folder: both at once are fine.
    check_results_dirs(&all, "A", None, true).unwrap();
    let source = std::fs::read_to_string(root.join("k/results/A/training").join(SOURCE_FILE)).unwrap();
    assert!(source.starts_with("layout kitti2015\nroot ../../../training\ndata 1 pairs, fingerprint "), "{source}");
    check_results_dirs(&all, "A", None, true).unwrap();

    // The same split name under one --results: the second data set is refused (another fingerprint).
    let training: Vec<Pair> = all.iter().filter(|p| p.root.ends_with("training")).cloned().collect();
    let other = root.join("o/training");
    touch(root, &["o/training/image_2/000000_10.png", "o/training/image_3/000000_10.png"]);
    std::fs::write(other.join("image_3/000000_10.png"), b"another right view").unwrap();
    let others = discover(&[other], Purpose::Run, &Discovery::default()).unwrap();
    let r = root.join("R");
    check_results_dirs(&training, "A", Some(&r), true).unwrap();
    let e = check_results_dirs(&others, "A", Some(&r), true).unwrap_err().to_string();
    assert!(e.contains("holds the results of") && e.contains("k/training"), "{e}");
    // Both in one call would share R/A/training.
    let both = [training.clone(), others].concat();
    let e = check_results_dirs(&both, "B", Some(&r), true).unwrap_err().to_string();
    assert!(e.contains("would share this folder"), "{e}");
    assert!(!r.join("B").exists(), "nothing made before the check passed");

    // Results where an older jem put them (R/C/, an absolute root, no fingerprint): the error says where they are.
    let old = r.join("C");
    std::fs::create_dir_all(&old).unwrap();
    let root_k = std::fs::canonicalize(root.join("k/training")).unwrap();
    std::fs::write(old.join(SOURCE_FILE), format!("layout kitti2015\nroot {}\n", root_k.display())).unwrap();
    let e = check_results_dirs(&training, "C", Some(&r), false).unwrap_err().to_string();
    assert!(e.contains("older jem") && e.contains("C/training"), "{e}");
    std::fs::create_dir_all(old.join("training")).unwrap();
    std::fs::rename(old.join(SOURCE_FILE), old.join("training").join(SOURCE_FILE)).unwrap();
    check_results_dirs(&training, "C", Some(&r), false).unwrap();

    // Results inside the data set are refused.
    let inside = root.join("k/training/out");
    let e = check_results_dirs(&training, "A", Some(&inside), true).unwrap_err().to_string();
    assert!(e.contains("inside the data set"), "{e}");
    assert!(!inside.exists());
}

#[test]
fn layout_names_round_trip() {
    for l in [Layout::Middlebury, Layout::Kitti2015, Layout::Kitti2012, Layout::Eth3d] {
        assert_eq!(l.name().parse::<Layout>().ok(), Some(l));
    }
    assert!("kitti".parse::<Layout>().is_err());
}
