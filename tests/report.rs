//! `jem report`: the page and its pictures, written all or none and self-contained, and the page in a real
//! browser (headless Chromium, when it is installed): it renders, every picture loads, a click on a header sorts
//! the rows.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use common::{files_in, jem, stderr};

/// Three synthetic scenes under `root/trainingQ/` with the results of two algorithms whose errors rank the
/// scenes differently: A is off by 0.1, 0.3, 0.2 px on S1, S2, S3 (avgErr ×4: 0.40, 1.20, 0.80), B by 0.3, 0.1,
/// 0.2; each with a run time.
fn scenes(root: &Path) -> PathBuf {
    let set = root.join("trainingQ");
    for (i, (a, b)) in [(0.1f32, 0.3f32), (0.3, 0.1), (0.2, 0.2)].into_iter().enumerate() {
        let dir = set.join(format!("S{}", i + 1));
        std::fs::create_dir_all(&dir).unwrap();
        let params = jem::synth::SynthParams { width: 64, height: 48, ndisp: 16, seed: i as u64 + 1 };
        let scene = jem::synth::render_scene(&params).unwrap();
        jem::synth::write_scene(&dir, &scene).unwrap();
        for (alg, off) in [("A", a), ("B", b)] {
            let data = scene.gt.data().iter().map(|g| g + off).collect();
            let result = jem::Plane::from_vec(64, 48, data).unwrap();
            jem::io::write_disparity(&dir.join(format!("disp0{alg}.pfm")), &result).unwrap();
            std::fs::write(dir.join(format!("time{alg}.txt")), format!("{}\n", 1.0 + off)).unwrap();
        }
    }
    set
}

/// Runs `jem report ARGS` in `dir`.
fn report(dir: &Path, args: &[&str]) -> std::process::Output {
    jem().current_dir(dir).arg("report").args(args).output().expect("cannot start jem")
}

/// Every `src="..."` and `href="..."` of a page.
fn links(page: &str) -> Vec<String> {
    let mut found = Vec::new();
    for attr in ["src=\"", "href=\""] {
        for (at, _) in page.match_indices(attr) {
            let rest = &page[at + attr.len()..];
            found.push(rest[..rest.find('"').unwrap()].to_string());
        }
    }
    found
}

#[test]
fn report_is_a_self_contained_page_with_its_pictures_beside_it() {
    let tmp = tempfile::tempdir().unwrap();
    scenes(tmp.path());
    let out = report(tmp.path(), &["trainingQ", "--alg", "A,B", "-o", "r.html"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("wrote r.html (3 rows, A, B) and 30 pictures in r_files/"), "{}", stderr(&out));
    let page = std::fs::read_to_string(tmp.path().join("r.html")).unwrap();
    // Nothing from a network, no script or style of its own files: it opens from the disk as it is.
    assert!(!page.contains("http://") && !page.contains("https://") && !page.contains("//cdn"), "{page}");
    assert!(!page.contains("<script src") && !page.contains("<link"), "{page}");
    let links = links(&page);
    assert_eq!(links.len(), 30, "15 thumbnails, each linking to its full size: {links:?}");
    for link in &links {
        assert!(link.starts_with("r_files/") && tmp.path().join(link).is_file(), "{link}");
    }
    assert_eq!(files_in(&tmp.path().join("r_files")).len(), 30);
    // The scores as jem eval computes them (×4 for trainingQ), the run times and the weighted means.
    for cell in ["data-v=\"0.4", "data-v=\"1.2", "data-v=\"0.8", "data-v=\"1.1", "data-v=\"1.3"] {
        assert!(page.contains(cell), "{cell}");
    }
    assert!(page.contains("weighted mean") && page.contains("jem report trainingQ --alg A,B -o r.html"));
    assert!(page.contains("not recorded") && page.contains(&format!("jem {}", env!("CARGO_PKG_VERSION"))));
    // The time column says its unit and ranks nothing: S1's 1.1 s of A against 1.3 s of B is not marked best
    // (runs timed under different loads), while A's avgErr there is.
    assert!(page.contains(">time (s)</th>") && page.contains("<td class=\"num\" data-v=\"1.1\">1.10</td>"), "{page}");
    assert!(!page.contains("<td class=\"num best\" data-v=\"1.1\">") && page.contains("num best"), "{page}");
    // The same command gives the same page and pictures.
    let read_all = || -> Vec<Vec<u8>> {
        let files = tmp.path().join("r_files");
        files_in(&files).iter().map(|f| std::fs::read(files.join(f)).unwrap()).collect()
    };
    let pictures = read_all();
    let again = report(tmp.path(), &["trainingQ", "--alg", "A,B", "-o", "r.html"]);
    assert!(again.status.success(), "{}", stderr(&again));
    assert!(std::fs::read_to_string(tmp.path().join("r.html")).unwrap() == page, "the page is byte-identical");
    assert!(read_all() == pictures, "the pictures are byte-identical");
    let quiet = report(tmp.path(), &["trainingQ", "--alg", "A,B", "-o", "r.html", "-q"]);
    assert!(quiet.status.success() && quiet.stderr.is_empty(), "{}", stderr(&quiet));
}

/// `jem batch` records beside each result the configuration it ran with (every parameter, the command and jem's
/// version, as TOML that `--config` reads back), and the report shows it; results without one say so.
#[test]
fn batch_records_its_configuration_and_the_report_shows_it() {
    let tmp = tempfile::tempdir().unwrap();
    let set = scenes(tmp.path());
    let run = |args: &[&str]| {
        let out = jem().current_dir(tmp.path()).args(args).output().expect("cannot start jem");
        assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    };
    run(&["batch", "trainingQ", "--alg", "J", "--set", "meanfield.iterations=1", "-q"]);
    let config = |scene: &str| std::fs::read_to_string(set.join(scene).join("configJ.toml")).unwrap();
    let text = config("S1");
    assert!(text.starts_with("# The configuration this result was made with"), "{text}");
    assert!(text.contains(&format!("# jem {}\n", env!("CARGO_PKG_VERSION"))), "{text}");
    assert!(text.contains("# command: jem batch trainingQ --alg J --set meanfield.iterations=1 -q\n"), "{text}");
    let params = jem::Params::load(Some(&set.join("S1").join("configJ.toml")), &[]).unwrap();
    assert_eq!(params.to_toml(), jem::Params::load(None, &["meanfield.iterations=1".into()]).unwrap().to_toml());
    assert_eq!(config("S2"), text, "one run, one configuration");
    assert!(files_in(&set.join("S1")).iter().all(|f| !f.starts_with('.')), "no temporary file left");

    let out = report(tmp.path(), &["trainingQ", "--alg", "J,A", "-o", "r.html"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let page = std::fs::read_to_string(tmp.path().join("r.html")).unwrap();
    let (j, a) = (page.find("<dt>configuration of J</dt>").unwrap(), page.find("<dt>configuration of A</dt>").unwrap());
    let (of_j, of_a) = (&page[j..a], &page[a..page[a..].find("</dd>").unwrap() + a]);
    assert!(of_j.contains("recorded beside all 3 results") && of_j.contains("# command: jem batch"), "{of_j}");
    assert!(of_j.contains("iterations = 1"), "{of_j}");
    assert!(of_a.contains("not recorded"), "{of_a}");
}

#[test]
fn report_is_written_all_or_none_and_refuses_bad_requests_in_one_line() {
    let tmp = tempfile::tempdir().unwrap();
    scenes(tmp.path());
    let refused = |args: &[&str], needles: &[&str]| {
        let before = files_in(tmp.path());
        let out = report(tmp.path(), args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.starts_with("error: ") && err.trim_end().lines().count() == 1, "{args:?}: {err}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: {err}");
        }
        assert_eq!(files_in(tmp.path()), before, "{args:?} left files behind");
    };
    refused(&["trainingQ", "--alg", "A", "-o", "r.png"], &["r.png", "HTML"]);
    refused(&["trainingQ", "--alg", "C", "-o", "r.html"], &["disp0C.pfm"]);
    refused(&["trainingQ", "--alg", "A,GT", "-o", "r.html"], &["GT"]);
    refused(&["trainingQ", "--alg", "A", "-o", "nowhere/r.html"], &["nowhere", "does not exist"]);
    refused(&["trainingQ", "--alg", "A,B", "--paper", "-,-,-", "-o", "r.html"], &["3 --paper columns for 2 --alg"]);
    std::fs::write(tmp.path().join("f_files"), b"mine").unwrap();
    refused(&["trainingQ", "--alg", "A", "-o", "f.html"], &["f_files", "not a folder"]);
    // A picture that cannot be put in place (its name is taken by a folder): no page, no picture, and the
    // folder the report made is removed again; an existing page is left as it was.
    let files = tmp.path().join("r_files");
    std::fs::create_dir_all(files.join("002-S2-left.png")).unwrap();
    std::fs::write(tmp.path().join("r.html"), b"old").unwrap();
    let out = report(tmp.path(), &["trainingQ", "--alg", "A", "-o", "r.html"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("002-S2-left.png"), "{}", stderr(&out));
    assert_eq!(std::fs::read(tmp.path().join("r.html")).unwrap(), b"old");
    assert_eq!(files_in(&files), ["002-S2-left.png"], "nothing else written, no temporary file left");
}

/// A KITTI 2015 tree of two frames with results of two algorithms where `jem batch` puts them: the rows are the
/// frames, each with both algorithms' pictures and D1 and avgErr (the scores of KITTI, after its devkit's fill).
#[test]
fn report_of_a_kitti_tree_shows_d1_per_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let tree = tmp.path().join("kitti").join("training");
    for sub in ["image_2", "image_3", "disp_noc_0", "disp_occ_0"] {
        std::fs::create_dir_all(tree.join(sub)).unwrap();
    }
    for k in 0..2 {
        let params = jem::synth::SynthParams { width: 64, height: 48, ndisp: 16, seed: k + 1 };
        let scene = jem::synth::render_scene(&params).unwrap();
        let frame = format!("{k:06}_10.png");
        for (view, img) in [("image_2", &scene.left), ("image_3", &scene.right)] {
            let rgb: Vec<u8> = (0..img.width() * img.height())
                .flat_map(|i| [0, 1, 2].map(|c| img.channel(c)[i].round() as u8))
                .collect();
            jem::io::write_png_rgb8(&tree.join(view).join(&frame), 64, 48, &rgb).unwrap();
        }
        for truth in ["disp_noc_0", "disp_occ_0"] {
            jem::io::write_disparity(&tree.join(truth).join(&frame), &scene.gt).unwrap();
        }
        for (alg, off) in [("A", 0.5f32), ("B", 4.0 + k as f32)] {
            let results = tmp.path().join("kitti").join("results").join(alg).join("training");
            std::fs::create_dir_all(results.join("disp_0")).unwrap();
            let data = scene.gt.data().iter().map(|g| g + off).collect();
            let result = jem::Plane::from_vec(64, 48, data).unwrap();
            jem::io::write_disparity(&results.join("disp_0").join(&frame), &result).unwrap();
        }
    }
    let out = report(tmp.path(), &["kitti/training", "--alg", "A,B", "-o", "k.html"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let page = std::fs::read_to_string(tmp.path().join("k.html")).unwrap();
    assert!(page.contains("KITTI 2015 · 2 rows") && page.contains(">D1</th>"), "the header and D1 columns");
    assert!(page.contains("data-v=\"000000_10\"") && page.contains("data-v=\"000001_10\""), "one row per frame");
    assert_eq!(links(&page).len(), 2 * 5 * 2, "each frame: its left image and two pictures per algorithm");
    // A's error (0.5 px) is never an outlier, B's (4 and 5 px, above 5 % of disparities below 16) always is.
    assert!(page.contains("<td class=\"num best\" data-v=\"0\">0.0</td>"), "A's D1 of 0 % is the row's best");
    assert!(page.contains("data-v=\"100\">100.0</td>"), "B's D1 of 100 %");
}

/// The harness page: loads the report in a frame, checks that every picture has loaded, clicks A's avgErr header
/// twice, and writes what it found into its own DOM, which `--dump-dom` prints.
const HARNESS: &str = r#"<!DOCTYPE html>
<html><body><pre id="verdict">no verdict: the report did not load</pre>
<iframe id="report" src="r.html" style="width:1400px;height:900px"></iframe>
<script>
var frame = document.getElementById("report");
frame.addEventListener("load", function () {
  var out = [];
  try {
    var doc = frame.contentDocument, images = doc.images, broken = [];
    for (var i = 0; i < images.length; i++) {
      if (!(images[i].complete && images[i].naturalWidth > 0)) broken.push(images[i].getAttribute("src"));
    }
    out.push("images " + images.length + " broken " + broken.length + " " + broken.join(" "));
    var body = doc.querySelector("table.results").tBodies[0];
    var order = function () {
      return Array.prototype.map.call(body.rows, function (r) { return r.cells[0].getAttribute("data-v"); }).join(",");
    };
    out.push("initial " + order());
    var header = Array.prototype.filter.call(doc.querySelectorAll("th[data-col]"), function (th) {
      return th.textContent.indexOf("avgErr") === 0;
    })[0];
    header.click();
    out.push("ascending " + order());
    header.click();
    out.push("descending " + order());
  } catch (e) {
    out.push("error " + e);
  }
  document.getElementById("verdict").textContent = out.join("\n");
});
</script></body></html>
"#;

/// The Chromium binary: `$JEM_CHROMIUM`, else `chromium` or `chromium-browser` on the PATH.
fn chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("JEM_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).flat_map(|d| ["chromium", "chromium-browser"].map(|n| d.join(n))).find(|p| p.is_file())
}

/// Runs Chromium on `page` with a bound on its time; returns the DOM it dumps.
fn dump_dom(browser: &Path, page: &Path, profile: &Path) -> String {
    let mut child = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--allow-file-access-from-files",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--virtual-time-budget=10000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg("--dump-dom")
        .arg(format!("file://{}", page.display()))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("cannot start chromium");
    let deadline = Instant::now() + Duration::from_secs(90);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("chromium did not finish within 90 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn report_renders_loads_every_picture_and_sorts_in_a_browser() {
    let Some(browser) = chromium() else {
        if std::env::var_os("JEM_REQUIRE_BROWSER").is_some_and(|v| v == "1") {
            panic!("chromium not found (JEM_CHROMIUM or PATH) but JEM_REQUIRE_BROWSER=1");
        }
        eprintln!("note: skipping the browser test: chromium not found (install it, or set JEM_CHROMIUM)");
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    scenes(tmp.path());
    let out = report(tmp.path(), &["trainingQ", "--alg", "A,B", "-o", "r.html", "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let harness = tmp.path().join("harness.html");
    std::fs::write(&harness, HARNESS).unwrap();
    let dom = dump_dom(&browser, &harness.canonicalize().unwrap(), &tmp.path().join("profile"));
    let verdict = dom
        .split("<pre id=\"verdict\">")
        .nth(1)
        .and_then(|v| v.split("</pre>").next())
        .unwrap_or_else(|| panic!("no verdict in the DOM: {dom}"));
    let lines: Vec<&str> = verdict.lines().map(str::trim_end).collect();
    // 3 rows: a left image and two pictures of each of two algorithms.
    assert_eq!(lines.first(), Some(&"images 15 broken 0"), "{verdict}");
    assert_eq!(&lines[1..], ["initial S1,S2,S3", "ascending S1,S3,S2", "descending S2,S3,S1"], "{verdict}");
}

/// `kill -9` of a report leaves the hidden temporary files of the pictures it had staged (a signal that cannot be
/// caught); the next report into the same place removes them, since their process is gone.
#[test]
fn a_rerun_removes_what_a_killed_report_left() {
    let tmp = tempfile::tempdir().unwrap();
    let set = tmp.path().join("trainingQ");
    for i in 0..6 {
        let dir = set.join(format!("S{i:02}"));
        std::fs::create_dir_all(&dir).unwrap();
        let params = jem::synth::SynthParams { width: 480, height: 360, ndisp: 32, seed: i + 1 };
        let scene = jem::synth::render_scene(&params).unwrap();
        jem::synth::write_scene(&dir, &scene).unwrap();
        jem::io::write_disparity(&dir.join("disp0A.pfm"), &scene.gt).unwrap();
    }
    let temps = |dir: &Path| -> Vec<String> {
        let mut found: Vec<String> = files_in(dir).into_iter().filter(|n| n.contains(".jem-tmp")).collect();
        if dir.join("r_files").is_dir() {
            found.extend(files_in(&dir.join("r_files")).into_iter().filter(|n| n.contains(".jem-tmp")));
        }
        found
    };
    let mut child = jem()
        .current_dir(tmp.path())
        .args(["--threads", "1", "report", "trainingQ", "--alg", "A", "-o", "r.html"])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while temps(tmp.path()).len() < 2 {
        if child.try_wait().unwrap().is_some() || start.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            eprintln!("note: skipping: the report ended before it could be killed mid-way");
            return;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(Command::new("kill").args(["-KILL", &child.id().to_string()]).status().unwrap().success());
    child.wait().unwrap();
    let left = temps(tmp.path());
    assert!(!left.is_empty(), "kill -9 leaves its temporary files");
    let out = report(tmp.path(), &["trainingQ", "--alg", "A", "-o", "r.html"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(temps(tmp.path()), Vec::<String>::new(), "left by the killed run: {left:?}");
    assert!(tmp.path().join("r.html").is_file());
}
