use super::*;
use crate::eval::SceneResult;

fn sheet_row(name: &str) -> SheetRow {
    let dir = PathBuf::from("set").join(name);
    SheetRow {
        name: name.into(),
        location: dir.clone(),
        left: dir.join("im0.png"),
        result: dir.join("disp0A.pfm"),
        truth: None,
        calib: None,
        rule: ErrorRule::Middlebury { scale: 4 },
        resolution: None,
        config: dir.join("configA.toml"),
    }
}

fn options(algs: &[&str]) -> ReportOptions {
    ReportOptions {
        algs: algs.iter().map(|a| a.to_string()).collect(),
        papers: Vec::new(),
        mask: MaskMode::Nonocc,
        scale: None,
        layout: None,
        gt: None,
        results: None,
        thumb_width: 160,
        command: "jem report".into(),
    }
}

#[test]
fn rows_join_each_algorithms_results_and_scores_by_scene() {
    let per_alg = vec![vec![sheet_row("Teddy"), sheet_row("ArtL")], vec![sheet_row("Teddy")]];
    let m = Metrics::from_values([1.5, 2.0, 0.0, 0.0, 7.0, 0.0, 1.0, 8.0, 0.0], 10);
    let scene = |name: &str, ok: bool| SceneResult {
        name: name.into(),
        dir: PathBuf::from("set").join(name),
        weight: crate::eval::scene_weight(name),
        metrics: if ok { Ok(m) } else { Err(std::sync::Arc::new(crate::Error::dataset("no result file"))) },
        seconds: Some(2.5),
        sparsification: None,
        truth_unusable: false,
    };
    let report = |scenes| AlgReport {
        alg: "X".into(),
        layout: Layout::Middlebury,
        mask: MaskMode::Nonocc,
        scale: 4,
        scale_inferred: None,
        scenes,
        writers: Vec::new(),
    };
    let evals = vec![
        Some(report(vec![scene("ArtL", true), scene("Teddy", true), scene("Vintage", true)])),
        Some(report(vec![scene("ArtL", false), scene("Teddy", true), scene("Vintage", false)])),
    ];
    let paper = PaperColumn { name: "JEM_ALL".into(), scenes: [("Teddy".to_string(), 4.25)].into(), weighted: None };
    let rows = join_rows(&["A".into(), "B".into()], &per_alg, &evals, &[None, Some(paper)]);
    let names: Vec<&str> = rows.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["ArtL", "Teddy", "Vintage"], "sorted by location; a scored scene without pictures kept");
    let teddy = &rows[1];
    assert!(teddy.cells.iter().all(|c| c.pictures.is_some() && c.metrics.as_ref().is_some_and(Result::is_ok)));
    assert_eq!((teddy.cells[0].paper, teddy.cells[1].paper), (None, Some(4.25)));
    assert!(rows[0].cells[1].pictures.is_none() && rows[0].cells[1].metrics.as_ref().is_some_and(Result::is_err));
    assert_eq!(rows[2].weight, Some(0.5));
    assert!(rows[2].cells.iter().all(|c| c.pictures.is_none()));
}

#[test]
fn picture_names_are_numbered_and_safe() {
    assert_eq!(file_stem(0, "Teddy"), "001-Teddy");
    assert_eq!(file_stem(11, "a b/c.d"), "012-a_b_c_d");
    assert_eq!(file_stem(2, &"x".repeat(80)).len(), 4 + 48);
}

#[test]
fn requests_are_checked_before_any_work() {
    let out = Path::new("r.html");
    assert_eq!(check_request(out, &options(&["A"])).unwrap(), PathBuf::from("r_files"));
    let e = |out: &str, opts: &ReportOptions| check_request(Path::new(out), opts).unwrap_err().to_string();
    assert!(e("r.png", &options(&["A"])).contains("HTML"));
    assert!(e("r.html", &options(&[])).contains("--alg"));
    assert!(e("r.html", &options(&["A", "A"])).contains("twice"));
    assert!(e("r.html", &options(&["GT"])).contains("GT"));
    let mut two = options(&["A", "B"]);
    two.papers = vec![None];
    assert!(e("r.html", &two).contains("one per --alg"));
    let mut tiny = options(&["A"]);
    tiny.thumb_width = 8;
    assert!(e("r.html", &tiny).contains("--thumb-width"));
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("r_files"), b"x").unwrap();
    let msg = check_request(&dir.path().join("r.html"), &options(&["A"])).unwrap_err().to_string();
    assert!(msg.contains("r_files") && msg.contains("not a folder"), "{msg}");
}

#[test]
fn each_layout_shows_its_benchmarks_scores() {
    let titles = |l| columns(l).iter().map(|c| c.title).collect::<Vec<_>>();
    assert_eq!(titles(Layout::Middlebury), ["avgErr", "bad-2", "invalid"]);
    assert_eq!(titles(Layout::Kitti2012), ["D1", "avgErr"]);
    assert_eq!(titles(Layout::Eth3d), ["bad-1", "avgErr"]);
    let m = Metrics::from_values([1.5, 2.0, 0.0, 3.0, 7.0, 0.0, 1.0, 8.0, 4.0], 10);
    let values = |l| columns(l).iter().map(|c| (c.value)(&m)).collect::<Vec<_>>();
    assert_eq!(values(Layout::Middlebury), [1.5, 8.0, 1.0]);
    assert_eq!(values(Layout::Kitti2015), [4.0, 1.5]);
    assert_eq!(values(Layout::Eth3d), [4.0, 1.5], "bad-1 counts the invalid pixels");
}

/// Rows that ran with one configuration share a fold; another configuration gets its own, naming its scenes;
/// a result without a record is in none, and an algorithm without any says it was not recorded.
#[test]
fn recorded_configurations_are_grouped_by_their_text() {
    let dir = tempfile::tempdir().unwrap();
    let row = |name: &str, config: Option<&str>| {
        let mut r = sheet_row(name);
        r.config = dir.path().join(format!("{name}.toml"));
        if let Some(text) = config {
            std::fs::write(&r.config, text).unwrap();
        }
        r
    };
    let rows = [row("S1", Some("a = 1\n")), row("S2", Some("a = 2\n")), row("S3", Some("a = 1\n")), row("S4", None)];
    let found = recorded_configs(&rows);
    let groups: Vec<(&str, Vec<&str>)> =
        found.iter().map(|r| (r.text.as_str(), r.scenes.iter().map(String::as_str).collect())).collect();
    assert_eq!(groups, [("a = 1\n", vec!["S1", "S3"]), ("a = 2\n", vec!["S2"])]);
    let html = html::configurations(&found, rows.len());
    assert!(html.contains("recorded beside 2 of 4 results: S1, S3") && html.contains("<pre>a = 2\n</pre>"), "{html}");
    let all = html::configurations(&found[..1], 2);
    assert!(all.contains("recorded beside all 2 results"), "{all}");
    assert!(html::configurations(&[], 4).starts_with("not recorded"));
}
