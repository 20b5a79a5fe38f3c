//! Tests of sequence folders: recognising them, writing them, making them from a scene, running them.

use std::path::Path;

use super::*;
use crate::image::{Plane, RgbImage};

/// Writes a `w` × `h` PNG whose red channel is `value` everywhere.
fn png(path: &Path, w: usize, h: usize, value: u8) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let rgb: Vec<u8> = (0..w * h).flat_map(|_| [value, 0, 0]).collect();
    crate::io::png::write_rgb8_png(path, w, h, &rgb).unwrap();
}

/// A folder with `left/` and `right/` holding PNGs of these names.
fn folders(dir: &Path, left: &[&str], right: &[&str]) {
    for (folder, names) in [("left", left), ("right", right)] {
        for name in names {
            png(&dir.join(folder).join(name), 8, 4, 1);
        }
    }
}

fn open_err(dir: &Path) -> String {
    Sequence::open(dir).unwrap_err().to_string()
}

#[test]
fn sequence_frames_pair_by_sorted_name() {
    let dir = tempfile::tempdir().unwrap();
    let names = ["000010.png", "000002.ppm", "000001.JPG", "000003.png"];
    for (folder, names) in [("left", names), ("right", ["000003.png", "000001.jpg", "000010.png", "000002.png"])] {
        for name in names {
            // The format is sniffed from the content; the extension only says the file is an image.
            png(&dir.path().join(folder).join(name), 8, 4, 1);
        }
    }
    // Not frames: other extensions, hidden files, folders.
    std::fs::write(dir.path().join("left/notes.txt"), "x").unwrap();
    png(&dir.path().join("left/.000000.png"), 8, 4, 1);
    std::fs::create_dir(dir.path().join("right/000004.png")).unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.layout, SequenceLayout::Folders);
    let stems: Vec<&str> = seq.frames.iter().map(|f| f.stem.as_str()).collect();
    assert_eq!(stems, ["000001", "000002", "000003", "000010"]);
    assert_eq!(seq.frames[0].left, dir.path().join("left/000001.JPG"));
    assert_eq!(seq.frames[0].right, dir.path().join("right/000001.jpg"));
    assert_eq!(seq.frames[1].left, dir.path().join("left/000002.ppm"));
    assert_eq!(seq.frames[1].right, dir.path().join("right/000002.png"));
    assert!(seq.frames.iter().all(|f| f.gt.is_none() && f.mask.is_none()));
    assert_eq!(seq.calib, None);
    assert!(!seq.has_ground_truth());
}

#[test]
fn unequal_frame_counts_are_refused_naming_the_folder() {
    let dir = tempfile::tempdir().unwrap();
    folders(dir.path(), &["a.png", "b.png", "c.png"], &["a.png", "b.png"]);
    let e = open_err(dir.path());
    assert!(e.starts_with(&dir.path().display().to_string()), "{e}");
    assert!(e.contains("left/ holds 3 frames but right/ holds 2") && !e.contains('\n'), "{e}");
}

#[test]
fn a_frame_without_a_partner_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    folders(dir.path(), &["000001.png", "000002.png", "000003.png"], &["000001.png", "000003.png", "000004.png"]);
    let e = open_err(dir.path());
    assert!(e.contains("frame 000002.png has no partner named 000002.* in right/"), "{e}");
    let other = tempfile::tempdir().unwrap();
    folders(other.path(), &["000001.png", "000003.png"], &["000001.png", "000002.png"]);
    let e = open_err(other.path());
    assert!(e.contains("frame 000002.png has no partner named 000002.* in left/"), "{e}");
}

#[test]
fn two_images_of_one_stem_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    folders(dir.path(), &["000001.png", "000001.jpg"], &["000001.png", "000002.png"]);
    let e = open_err(dir.path());
    assert!(e.contains("left") && e.contains("two images of frame 000001 (000001.jpg and 000001.png)"), "{e}");
}

#[test]
fn an_empty_or_foreign_folder_is_no_sequence() {
    let dir = tempfile::tempdir().unwrap();
    assert!(open_err(dir.path()).contains("not a stereo sequence"));
    assert_eq!(Sequence::recognise(dir.path()), None);
    folders(dir.path(), &[], &[]);
    std::fs::create_dir_all(dir.path().join("left")).unwrap();
    std::fs::create_dir_all(dir.path().join("right")).unwrap();
    assert!(open_err(dir.path()).contains("no frames"), "{}", open_err(dir.path()));
}

#[test]
fn kitti_raw_drive_folders_are_recognised() {
    let dir = tempfile::tempdir().unwrap();
    let drive = dir.path().join("2011_09_26_drive_0001_sync");
    for k in 0..3 {
        for cam in ["image_02", "image_03"] {
            png(&drive.join(cam).join("data").join(format!("{k:010}.png")), 8, 4, 1);
        }
    }
    std::fs::write(dir.path().join("calib_cam_to_cam.txt"), "S_02: 1 2\n").unwrap();
    let seq = Sequence::open(&drive).unwrap();
    assert_eq!(seq.layout, SequenceLayout::KittiRaw);
    assert_eq!(seq.frames.len(), 3);
    assert_eq!(seq.frames[2].stem, "0000000002");
    assert_eq!(seq.frames[2].right, drive.join("image_03/data/0000000002.png"));
    assert_eq!((seq.calib.as_ref(), seq.ndisp_source(NdispSource::Unknown).unwrap()), (None, NdispSource::Unknown));
}

#[test]
fn ground_truth_and_masks_are_found_by_stem() {
    let dir = tempfile::tempdir().unwrap();
    folders(dir.path(), &["000001.png", "000002.png"], &["000001.png", "000002.png"]);
    std::fs::create_dir_all(dir.path().join("gt")).unwrap();
    crate::io::pfm::write_pfm(&dir.path().join("gt/000002.pfm"), &Plane::new(8, 4, 1.0)).unwrap();
    png(&dir.path().join("mask/000001.png"), 8, 4, 255);
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.frames[0].gt, None);
    assert_eq!(seq.frames[1].gt, Some(dir.path().join("gt/000002.pfm")));
    assert_eq!(seq.frames[0].mask, Some(dir.path().join("mask/000001.png")));
    assert_eq!(seq.frames[1].mask, None);
    assert!(seq.has_ground_truth());
}

#[test]
fn the_range_is_given_else_stated_by_calib_else_unknown() {
    let dir = tempfile::tempdir().unwrap();
    folders(dir.path(), &["1.png"], &["1.png"]);
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.ndisp_source(NdispSource::Unknown).unwrap(), NdispSource::Unknown);
    assert_eq!(seq.ndisp_source(NdispSource::Given(9)).unwrap(), NdispSource::Given(9));
    std::fs::write(dir.path().join("calib.txt"), "width=8\nndisp=5\n").unwrap();
    let seq = Sequence::open(dir.path()).unwrap();
    assert_eq!(seq.ndisp_source(NdispSource::Unknown).unwrap(), NdispSource::Stated(5));
    assert_eq!(seq.ndisp_source(NdispSource::Given(9)).unwrap(), NdispSource::Given(9));
    // A calib.txt of geometry only (as `jem rectify` writes one): the range is measured.
    std::fs::write(dir.path().join("calib.txt"), "width=8\n").unwrap();
    assert_eq!(Sequence::open(dir.path()).unwrap().ndisp_source(NdispSource::Unknown).unwrap(), NdispSource::Unknown);
    std::fs::write(dir.path().join("calib.txt"), "width=8\nndisp=zero\n").unwrap();
    let e = Sequence::open(dir.path()).unwrap().ndisp_source(NdispSource::Unknown).unwrap_err().to_string();
    assert!(e.contains("calib.txt") && e.contains("ndisp"), "{e}");
}

/// A frame of the given colour with ground truth and mask.
fn frame(value: f32) -> SequenceFrame {
    let mut left = RgbImage::new(6, 3);
    left.channels[0].fill(value);
    SequenceFrame { right: left.clone(), left, gt: Some(Plane::new(6, 3, value)), mask: Some(Plane::new(6, 3, 255)) }
}

#[test]
fn a_written_sequence_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("new/seq");
    let stems =
        write_sequence(&out, 3, &mut |k| Ok(frame(k as f32)), &mut || vec![("calib.txt", "ndisp=4\n".into())]).unwrap();
    assert_eq!(stems, ["000000", "000001", "000002"]);
    let seq = Sequence::open(&out).unwrap();
    assert_eq!(seq.frames.len(), 3);
    assert_eq!(seq.ndisp_source(NdispSource::Unknown).unwrap(), NdispSource::Stated(4));
    for (k, f) in seq.frames.iter().enumerate() {
        let expected = frame(k as f32);
        assert_eq!(crate::io::png::load_rgb(&f.left).unwrap(), expected.left);
        assert_eq!(crate::io::pfm::read_pfm(f.gt.as_ref().unwrap()).unwrap(), expected.gt.unwrap());
        assert_eq!(crate::io::png::load_grey8(f.mask.as_ref().unwrap()).unwrap(), expected.mask.unwrap());
    }
    let mut names: Vec<String> =
        std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(names, ["calib.txt", "gt", "left", "mask", "right"], "no temporary folder left");
}

#[test]
fn writing_refuses_a_folder_holding_a_scene_or_sequence() {
    for taken in ["left", "calib.txt", "im0.png", "made.txt"] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(taken);
        if taken == "left" { std::fs::create_dir(&path) } else { std::fs::write(&path, "x") }.unwrap();
        let e = write_sequence(dir.path(), 2, &mut |k| Ok(frame(k as f32)), &mut || vec![("made.txt", String::new())])
            .unwrap_err()
            .to_string();
        assert!(e.contains("already holds a scene or a sequence") && e.contains(taken), "{e}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "{taken}: something was written");
    }
    // Other files are no reason to refuse, and stay.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("README"), "x").unwrap();
    write_sequence(dir.path(), 2, &mut |k| Ok(frame(k as f32)), &mut Vec::new).unwrap();
    assert!(dir.path().join("README").is_file() && dir.path().join("left/000001.png").is_file());
}

#[test]
fn a_failed_write_leaves_no_part_of_a_sequence() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seq");
    let mut failing = |k: usize| if k < 2 { Ok(frame(k as f32)) } else { Err(crate::Error::dataset("frame 2 broke")) };
    let e = write_sequence(&out, 4, &mut failing, &mut Vec::new).unwrap_err().to_string();
    assert_eq!(e, "frame 2 broke");
    assert!(!out.exists(), "the folder it created is removed");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("keep.txt"), "x").unwrap();
    assert!(write_sequence(&out, 4, &mut failing, &mut Vec::new).is_err());
    let names: Vec<_> = std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names, ["keep.txt"], "an existing folder keeps only what it had");
    // Frames that carry ground truth only sometimes are refused.
    let mut mixed =
        |k: usize| Ok(SequenceFrame { gt: None, ..frame(k as f32) }).map(|f| if k == 0 { frame(0.0) } else { f });
    assert!(
        write_sequence(&dir.path().join("mixed"), 2, &mut mixed, &mut Vec::new)
            .unwrap_err()
            .to_string()
            .contains("frame 1")
    );
}

/// A synthetic scene written as a MiddEval3 scene folder.
fn synth_scene(dir: &Path) -> crate::synth::SynthScene {
    let scene =
        crate::synth::render_scene(&crate::synth::SynthParams { width: 96, height: 48, ndisp: 24, seed: 5 }).unwrap();
    crate::synth::write_scene(dir, &scene).unwrap();
    scene
}

#[test]
fn a_sliding_window_crops_the_ground_truth_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let scene = synth_scene(&dir.path().join("scene"));
    let how = FromScene { frames: 4, recipe: "none".parse().unwrap(), seed: 1, pan_px: 5 };
    let out = dir.path().join("pan");
    assert_eq!(sequence_from_scene(&dir.path().join("scene"), &out, &how).unwrap(), 4);
    let seq = Sequence::open(&out).unwrap();
    let window = 96 - 3 * 5;
    for (k, f) in seq.frames.iter().enumerate() {
        let gt = crate::io::pfm::read_pfm(f.gt.as_ref().unwrap()).unwrap();
        let mask = crate::io::png::load_grey8(f.mask.as_ref().unwrap()).unwrap();
        let left = crate::io::png::load_rgb(&f.left).unwrap();
        let right = crate::io::png::load_rgb(&f.right).unwrap();
        assert_eq!(gt.dims(), (window, 48));
        for y in 0..48 {
            for x in 0..window {
                let (i, j) = (y * window + x, y * 96 + x + 5 * k);
                assert_eq!(gt.data[i], scene.gt.data[j]);
                assert_eq!((left.rgb(i), right.rgb(i)), (scene.left.rgb(j), scene.right.rgb(j)));
                // The window's own left edge hides matches the scene's did not.
                let outside = (x as f32) < gt.data[i];
                let expected = if outside { crate::synth::MASK_OCCLUDED } else { scene.mask.data[j] };
                assert_eq!(mask.data[i], expected, "frame {k} ({x}, {y})");
            }
        }
    }
    let calib = crate::io::calib::Calib::load(&out.join("calib.txt")).unwrap();
    assert_eq!((calib.float("width"), calib.ndisp().ok()), (Some(window as f32), Some(24)));
    let too_far = FromScene { pan_px: 30, ..how };
    let e = sequence_from_scene(&dir.path().join("scene"), &dir.path().join("x"), &too_far).unwrap_err();
    assert!(e.to_string().contains("--pan") && !dir.path().join("x").exists(), "{e}");
}

#[test]
fn each_frame_gets_fresh_noise_and_a_rerun_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = synth_scene(&dir.path().join("scene"));
    let how = FromScene { frames: 3, recipe: "noise:6".parse().unwrap(), seed: 7, pan_px: 0 };
    for name in ["a", "b"] {
        sequence_from_scene(&dir.path().join("scene"), &dir.path().join(name), &how).unwrap();
    }
    let read = |name: &str, k: usize, view: &str| {
        std::fs::read(dir.path().join(name).join(view).join(format!("{k:06}.png"))).unwrap()
    };
    let load = |name: &str, k: usize, view: &str| {
        crate::io::png::load_rgb(&dir.path().join(name).join(view).join(format!("{k:06}.png"))).unwrap()
    };
    for k in 0..3 {
        assert_eq!(read("a", k, "left"), read("b", k, "left"));
        assert_ne!(load("a", k, "left"), load("a", k, "right"));
        let gt = crate::io::pfm::read_pfm(&dir.path().join(format!("a/gt/{k:06}.pfm"))).unwrap();
        assert_eq!(gt, scene.gt, "a static camera: the scene's ground truth every frame");
    }
    let (f0, f1) = (load("a", 0, "left"), load("a", 1, "left"));
    assert_ne!(f0, f1, "fresh noise each frame");
    // The noise is the recipe's: σ about 6 against the clean view.
    let diffs: Vec<f64> = f0.channels[1].iter().zip(&scene.left.channels[1]).map(|(a, b)| f64::from(a - b)).collect();
    let sigma = (diffs.iter().map(|d| d * d).sum::<f64>() / diffs.len() as f64).sqrt();
    assert!((5.0..7.0).contains(&sigma), "{sigma}");
}

/// A three-frame sequence of different synthetic scenes (with calib.txt), and fast parameters.
fn small_sequence(dir: &Path) -> (Sequence, crate::Params) {
    sequence_of(dir, 3)
}

/// [`small_sequence`] with `n` frames.
fn sequence_of(dir: &Path, n: usize) -> (Sequence, crate::Params) {
    let mut scenes = (1..=n as u64).map(|seed| {
        crate::synth::render_scene(&crate::synth::SynthParams { width: 80, height: 40, ndisp: 16, seed }).unwrap()
    });
    let seq = dir.join("seq");
    let mut frame = |_| {
        let s = scenes.next().unwrap();
        Ok(SequenceFrame { left: s.left, right: s.right, gt: Some(s.gt), mask: Some(s.mask) })
    };
    write_sequence(&seq, n, &mut frame, &mut || vec![("calib.txt", "ndisp=16\n".into())]).unwrap();
    let mut params = crate::Params { model: crate::Model::Wta, ..Default::default() };
    params.post.sps.enabled = false;
    (Sequence::open(&seq).unwrap(), params)
}

/// Frames written as PFM, the range settled on each.
const PER_FRAME: RunOptions = RunOptions { format: crate::io::DisparityFormat::Pfm, range: RangeRule::PerFrame };

/// Frames held to the first one's range.
const FIRST_FRAME: RunOptions = RunOptions { range: RangeRule::FirstFrame, ..PER_FRAME };

/// A matcher of `params` without a memory limit.
fn matcher(params: &crate::Params) -> crate::Matcher {
    crate::Matcher::new(params.clone()).unwrap().with_max_memory(u64::MAX)
}

#[test]
fn each_frame_is_the_map_jem_match_plans_and_runs() {
    let dir = tempfile::tempdir().unwrap();
    let (seq, params) = small_sequence(dir.path());
    let out = dir.path().join("out");
    let summary = run(&seq, &out, matcher(&params), &PER_FRAME, &|_| {}).unwrap();
    assert_eq!(summary.ran.len(), 3);
    for f in &seq.frames {
        let (l, r) = crate::io::png::load_rgb_pair(&f.left, &f.right).unwrap();
        let matcher = crate::matcher::Matcher::new(params.clone()).unwrap().with_max_memory(u64::MAX);
        let expected = matcher.with_ndisp(NdispSource::Stated(16)).match_pair(&l, &r).unwrap().disparity;
        let written = std::fs::read(out.join(format!("{}.pfm", f.stem))).unwrap();
        assert_eq!(written, crate::io::pfm::encode_pfm(&expected), "frame {}", f.stem);
    }
    let times = std::fs::read_to_string(out.join(TIMES_FILE)).unwrap();
    let stems: Vec<&str> = times.lines().map(|l| l.split(' ').next().unwrap()).collect();
    assert_eq!(stems, ["000000", "000001", "000002"]);
    assert!(times.lines().all(|l| l.split(' ').nth(1).unwrap().parse::<f64>().unwrap() >= 0.0), "{times}");
    assert_eq!(recorded_source(&out), Some(std::fs::canonicalize(&seq.root).unwrap()));
}

#[test]
fn a_rerun_skips_the_frames_written_and_runs_the_rest() {
    let dir = tempfile::tempdir().unwrap();
    let (seq, params) = small_sequence(dir.path());
    let out = dir.path().join("out");
    run(&seq, &out, matcher(&params), &PER_FRAME, &|_| {}).unwrap();
    let before = std::fs::read(out.join("000001.pfm")).unwrap();
    std::fs::remove_file(out.join("000001.pfm")).unwrap();
    std::fs::write(out.join("000002.pfm"), b"Pf\ntruncated").unwrap();
    let events = std::sync::Mutex::new(Vec::new());
    let summary = run(&seq, &out, matcher(&params), &PER_FRAME, &|e| {
        let line = match e {
            Event::Skipped { stem, .. } => format!("skip {stem}"),
            Event::Finished { run, .. } => format!("ran {}", run.stem),
            _ => return,
        };
        events.lock().unwrap().push(line);
    })
    .unwrap();
    assert_eq!(events.into_inner().unwrap(), ["skip 000000", "ran 000001", "ran 000002"]);
    assert_eq!(summary.skipped, ["000000"]);
    assert_eq!(std::fs::read(out.join("000001.pfm")).unwrap(), before, "the same map again");
    let times = std::fs::read_to_string(out.join(TIMES_FILE)).unwrap();
    assert_eq!(times.lines().map(|l| &l[..6]).collect::<Vec<_>>(), ["000000", "000001", "000002"]);
}

#[test]
fn a_temporal_rerun_replays_the_frames_before_the_missing_one_and_writes_the_same_map() {
    let dir = tempfile::tempdir().unwrap();
    let (seq, params) = small_sequence(dir.path());
    let out = dir.path().join("out");
    let temporal = || matcher(&params).with_temporal(true);
    let first = run(&seq, &out, temporal(), &FIRST_FRAME, &|_| {}).unwrap();
    assert!(first.ran.iter().all(|r| r.kind.is_some()), "every frame says how it was matched");
    let last = std::fs::read(out.join("000002.pfm")).unwrap();
    let kept = std::fs::read(out.join("000000.pfm")).unwrap();
    std::fs::remove_file(out.join("000002.pfm")).unwrap();
    let again = run(&seq, &out, temporal(), &FIRST_FRAME, &|_| {}).unwrap();
    assert_eq!(again.replayed, ["000000", "000001"], "the state is rebuilt from the frames before");
    assert!(again.skipped.is_empty());
    assert_eq!(again.ran.iter().map(|r| r.stem.as_str()).collect::<Vec<_>>(), ["000002"]);
    assert_eq!(std::fs::read(out.join("000002.pfm")).unwrap(), last, "the same map as the run without a stop");
    assert_eq!(std::fs::read(out.join("000000.pfm")).unwrap(), kept, "a replayed frame is not written again");
    // Everything written: nothing to rebuild, every frame skipped.
    let done = run(&seq, &out, temporal(), &FIRST_FRAME, &|_| {}).unwrap();
    assert_eq!((done.skipped.len(), done.replayed.len(), done.ran.len()), (3, 0, 0));
}

#[test]
fn a_temporal_rerun_reads_each_written_map_once() {
    let dir = tempfile::tempdir().unwrap();
    let (seq, params) = sequence_of(dir.path(), 8);
    let out = dir.path().join("out");
    let temporal = || matcher(&params).with_temporal(true);
    run(&seq, &out, temporal(), &FIRST_FRAME, &|_| {}).unwrap();
    let last = std::fs::read(out.join("000007.pfm")).unwrap();
    std::fs::remove_file(out.join("000007.pfm")).unwrap();
    run::MAPS_READ.with(|n| n.set(0));
    let again = run(&seq, &out, temporal(), &FIRST_FRAME, &|_| {}).unwrap();
    assert_eq!(again.replayed.len(), 7);
    // One look at each frame's map (the missing one included), not one per later frame for each frame.
    assert_eq!(run::MAPS_READ.with(|n| n.get()), 8);
    assert_eq!(std::fs::read(out.join("000007.pfm")).unwrap(), last, "the same map as the run without a stop");
}

#[test]
fn frames_in_bmp_tiff_and_webp_are_read_as_the_png() {
    let dir = tempfile::tempdir().unwrap();
    let (seq, params) = small_sequence(dir.path());
    let png_out = dir.path().join("png-out");
    run(&seq, &png_out, matcher(&params), &PER_FRAME, &|_| {}).unwrap();
    // The same frames in the other formats jem match reads, one format per frame.
    let other = dir.path().join("other");
    std::fs::create_dir_all(other.join("left")).unwrap();
    std::fs::create_dir_all(other.join("right")).unwrap();
    std::fs::copy(seq.root.join("calib.txt"), other.join("calib.txt")).unwrap();
    let exts = ["bmp", "TIFF", "webp"];
    for (f, ext) in seq.frames.iter().zip(exts) {
        for (src, folder) in [(&f.left, "left"), (&f.right, "right")] {
            let img = image::open(src).unwrap().to_rgb8();
            let format = image::ImageFormat::from_extension(ext.to_ascii_lowercase()).unwrap();
            img.save_with_format(other.join(folder).join(format!("{}.{ext}", f.stem)), format).unwrap();
        }
    }
    let converted = Sequence::open(&other).unwrap();
    let stems: Vec<&str> = converted.frames.iter().map(|f| f.stem.as_str()).collect();
    assert_eq!(stems, ["000000", "000001", "000002"]);
    let out = dir.path().join("other-out");
    assert_eq!(run(&converted, &out, matcher(&params), &PER_FRAME, &|_| {}).unwrap().ran.len(), 3);
    for f in &seq.frames {
        let name = format!("{}.pfm", f.stem);
        assert_eq!(std::fs::read(out.join(&name)).unwrap(), std::fs::read(png_out.join(&name)).unwrap(), "{name}");
    }
}

#[test]
fn an_output_folder_of_another_run_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (seq, params) = small_sequence(dir.path());
    let out = dir.path().join("out");
    run(&seq, &out, matcher(&params), &PER_FRAME, &|_| {}).unwrap();
    let mut other = params.clone();
    other.post.fill = !other.post.fill;
    let e = run(&seq, &out, matcher(&other), &PER_FRAME, &|_| {}).unwrap_err().to_string();
    assert!(e.contains("another run") && e.contains("configuration"), "{e}");
    let png = RunOptions { format: crate::io::DisparityFormat::Png16, ..PER_FRAME };
    assert!(run(&seq, &out, matcher(&params), &png, &|_| {}).unwrap_err().to_string().contains("format pfm"));
    // Frame results without a record are another program's.
    let foreign = dir.path().join("foreign");
    std::fs::create_dir(&foreign).unwrap();
    std::fs::write(foreign.join("000001.pfm"), "x").unwrap();
    assert!(run(&seq, &foreign, matcher(&params), &PER_FRAME, &|_| {}).unwrap_err().to_string().contains("without a"));
    for inside in [seq.root.clone(), seq.root.join("gt"), seq.root.join("left/new")] {
        let e = run(&seq, &inside, matcher(&params), &PER_FRAME, &|_| {}).unwrap_err().to_string();
        assert!(e.contains("must not be the sequence folder"), "{e}");
    }
}

#[test]
fn the_range_held_from_the_first_frame_is_given_to_every_frame() {
    let dir = tempfile::tempdir().unwrap();
    let (seq, params) = small_sequence(dir.path());
    std::fs::remove_file(seq.root.join("calib.txt")).unwrap();
    let seq = Sequence::open(&seq.root).unwrap();
    let summary = run(&seq, &dir.path().join("once"), matcher(&params), &FIRST_FRAME, &|_| {}).unwrap();
    let (n, measured) = summary.settled.unwrap();
    assert!(measured);
    assert!(summary.ran.iter().all(|r| r.ndisp == n && !r.ndisp_measured), "{:?}", summary.ran);
    let per_frame = run(&seq, &dir.path().join("each"), matcher(&params), &PER_FRAME, &|_| {}).unwrap();
    assert!(per_frame.ran.iter().all(|r| r.ndisp_measured));
    assert_eq!(per_frame.ran[0].ndisp, n, "the first frame is measured the same way");
}

/// With a smallest disparity, each frame is the map a matcher with that smallest disparity makes (the first
/// columns invalid), alone and through the temporal model; the folder's record holds it, so a rerun from another
/// smallest disparity is refused.
#[test]
fn a_sequence_searched_from_a_smallest_disparity_is_matched_as_jem_match_does() {
    let dir = tempfile::tempdir().unwrap();
    let (seq, params) = small_sequence(dir.path());
    let from = |d| matcher(&params).with_min_disp(d);
    let out = dir.path().join("out");
    run(&seq, &out, from(4), &PER_FRAME, &|_| {}).unwrap();
    for f in &seq.frames {
        let (l, r) = crate::io::png::load_rgb_pair(&f.left, &f.right).unwrap();
        let matcher = crate::matcher::Matcher::new(params.clone()).unwrap().with_max_memory(u64::MAX);
        let expected =
            matcher.with_ndisp(NdispSource::Stated(16)).with_min_disp(4).match_pair(&l, &r).unwrap().disparity;
        assert!((0..expected.height()).all(|y| expected.row(y)[..4].iter().all(|d| d.is_infinite())));
        let written = std::fs::read(out.join(format!("{}.pfm", f.stem))).unwrap();
        assert_eq!(written, crate::io::pfm::encode_pfm(&expected), "frame {}", f.stem);
    }
    let e = run(&seq, &out, from(2), &PER_FRAME, &|_| {}).unwrap_err().to_string();
    assert!(e.contains("another run"), "{e}");
    let temporal = from(4).with_temporal(true);
    let summary = run(&seq, &dir.path().join("temporal"), temporal, &FIRST_FRAME, &|_| {}).unwrap();
    assert_eq!(summary.ran.len(), 3);
    for f in &seq.frames {
        let map = crate::io::read_disparity(&dir.path().join("temporal").join(format!("{}.pfm", f.stem))).unwrap();
        let (w, h) = map.dims();
        assert_eq!((w, h), (80, 40));
        assert!((0..h).all(|y| map.row(y)[..4].iter().all(|d| d.is_infinite())), "frame {}", f.stem);
        assert!(map.data().iter().filter(|d| d.is_finite()).all(|&d| d >= 3.5), "frame {}", f.stem);
    }
}
