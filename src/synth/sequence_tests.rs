//! Tests of synthetic sequences: each frame's ground truth against its own pair, and the motions against the
//! geometry they stand for.

use super::*;
use crate::synth::render_scene;

fn params(motion: Motion, frames: usize) -> SequenceParams {
    SequenceParams { scene: SynthParams::default(), frames, motion, noise_sigma: 0.0, gain: GainChange::default() }
}

fn frame(p: &SequenceParams, k: usize) -> SynthScene {
    render_frame(p, k).unwrap().0
}

/// Shares of the non-occluded pixels whose colour the right view has at `x − gt` within 12 grey levels: at the
/// nearest pixel, and interpolated linearly (the measure of the single scene's test of the same name).
fn shares_matching(s: &SynthScene) -> (f64, f64) {
    let w = s.gt.width;
    let (mut n, mut near_ok, mut lin_ok) = (0usize, 0usize, 0usize);
    let close = |p: [f32; 3], q: [f32; 3]| p.iter().zip(&q).all(|(a, b)| (a - b).abs() <= 12.0);
    for (i, (&d, &m)) in s.gt.data.iter().zip(&s.mask.data).enumerate() {
        if m != MASK_VISIBLE {
            continue;
        }
        let (x, y) = (i % w, i / w);
        let xr = x as f32 - d;
        assert!(xr >= 0.0, "visible pixel ({x}, {y}) matches outside the right image");
        n += 1;
        near_ok += usize::from(close(s.left.rgb(i), s.right.rgb(y * w + (xr.round() as usize).min(w - 1))));
        let (x0, t) = (xr.floor() as usize, xr.fract());
        let (p, q) = (s.right.rgb(y * w + x0), s.right.rgb(y * w + (x0 + 1).min(w - 1)));
        lin_ok += usize::from(close(s.left.rgb(i), [0, 1, 2].map(|c| p[c] + (q[c] - p[c]) * t)));
    }
    (near_ok as f64 / n as f64, lin_ok as f64 / n as f64)
}

/// Every motion's first and last frames: the ground truth maps the left colours onto the right view as well as
/// a single scene's does (its test: ≥ 90 % nearest, ≥ 97 % interpolated), within the range, dense.
#[test]
fn every_frame_s_ground_truth_maps_its_left_view_onto_its_right() {
    for motion in Motion::ALL {
        let p = params(motion, 8);
        for k in [0, 7] {
            let s = frame(&p, k);
            let (near, lin) = shares_matching(&s);
            eprintln!("{} frame {k}: nearest {near:.3}, linear {lin:.3}", motion.name());
            assert!(near > 0.90 && lin > 0.97, "{} frame {k}: nearest {near:.3}, linear {lin:.3}", motion.name());
            assert!(s.gt.data.iter().all(|&d| d.is_finite() && d >= 0.0 && d < p.scene.ndisp as f32));
            let occluded = s.mask.data.iter().filter(|&&m| m == MASK_OCCLUDED).count();
            assert!(occluded > s.gt.data.len() / 100, "{} frame {k}: occlusions are marked", motion.name());
        }
    }
}

/// The still camera's frame is the single scene's render through the general camera: the same ground truth (to
/// rounding) and, but for samples that land on the other side of a shape's edge by rounding, the same pixels.
#[test]
fn a_still_frame_is_the_single_scene() {
    let single = render_scene(&SynthParams::default()).unwrap();
    let s = frame(&params(Motion::Static, 2), 1);
    assert!(s.gt.data.iter().zip(&single.gt.data).all(|(a, b)| (a - b).abs() < 1e-4));
    let same_mask = s.mask.data.iter().zip(&single.mask.data).filter(|(a, b)| a == b).count();
    assert!(same_mask + 10 > s.mask.data.len(), "{} of {} mask pixels", same_mask, s.mask.data.len());
    for (a, b) in [(&s.left, &single.left), (&s.right, &single.right)] {
        let same = (0..a.len()).filter(|&i| a.rgb(i) == b.rgb(i)).count();
        assert!(same + a.len() / 1000 > a.len(), "{same} of {} pixels", a.len());
    }
}

/// A pan moves the left camera 0.1 baseline a frame: after ten frames it stands where the right camera started,
/// and sees exactly what that one saw.
#[test]
fn ten_frames_of_a_pan_bring_the_left_camera_to_the_first_right_camera() {
    let p = params(Motion::Pan, 11);
    let (first, last) = (frame(&p, 0), frame(&p, 10));
    assert_eq!(last.left, first.right);
    let (_, truth) = render_frame(&p, 10).unwrap();
    assert_eq!(truth.camera_x_baselines, 1.0);
    // Near objects move more than the background: the frame-to-frame change of the ground truth is not a shift.
    assert_ne!(first.gt, last.gt);
}

/// Forward motion: on the optical axis (the centre pixel of an odd-sized image) a point stays put and its
/// disparity grows as 1/d' = 1/d − F.
#[test]
fn a_dolly_grows_the_disparity_on_the_optical_axis_as_its_inverse_falls_by_f() {
    let mut p = params(Motion::Dolly, 5);
    p.scene.width = 161;
    p.scene.height = 121;
    let centre = 60 * 161 + 80;
    let d0 = f64::from(frame(&p, 0).gt.data[centre]);
    for k in 1..5 {
        let (s, truth) = render_frame(&p, k).unwrap();
        let expected = d0 / (1.0 - d0 * truth.forward);
        assert!(
            (f64::from(s.gt.data[centre]) - expected).abs() < 1e-3,
            "frame {k}: {} vs {expected}",
            s.gt.data[centre]
        );
        assert!(expected > d0);
    }
    let last = frame(&p, 4);
    assert!(last.vmax < p.scene.ndisp as f32 && last.vmax > 0.85 * p.scene.ndisp as f32, "grows into the range");
}

/// A moving object: the background and the other objects stay; the object's pixels, carried by its shift, keep
/// their disparity and colour.
#[test]
fn a_moving_object_carries_its_disparity_and_texture() {
    let p = params(Motion::Object, 6);
    let first = frame(&p, 0);
    // Frame 5's object has moved 10 px; pick the frame whose shift is closest to whole pixels for the check.
    let (moved, truth) = render_frame(&p, 5).unwrap();
    let [dx, dy] = truth.object_shift_px;
    assert!((dx.hypot(dy) - 10.0).abs() < 1e-9, "{dx} {dy}");
    let w = first.gt.width;
    let unchanged = first.gt.data.iter().zip(&moved.gt.data).filter(|(a, b)| a == b).count();
    assert!(unchanged > w * first.gt.height * 3 / 4 && unchanged < w * first.gt.height, "{unchanged}");
    // The frontmost object has the largest disparities: pixels of frame 0 with them reappear shifted in frame 5.
    let front = first.gt.data.iter().fold(0.0f32, |m, &d| m.max(d)) - 1.0;
    let (mut n, mut ok) = (0, 0);
    for (i, &d) in first.gt.data.iter().enumerate() {
        let (x, y) = ((i % w) as f64 + dx, (i / w) as f64 + dy);
        if d < front || !(0.0..w as f64 - 1.0).contains(&x) || !(0.0..first.gt.height as f64 - 1.0).contains(&y) {
            continue;
        }
        let j = y.round() as usize * w + x.round() as usize;
        n += 1;
        ok += usize::from((moved.gt.data[j] - d).abs() < 0.5);
    }
    assert!(n > 50 && ok * 10 > n * 9, "{ok} of {n} object pixels carried");
}

/// A cut: one scene before frame N/2, another from it on, each still.
#[test]
fn a_cut_switches_the_scene_half_way() {
    let p = params(Motion::Cut, 4);
    let f: Vec<SynthScene> = (0..4).map(|k| frame(&p, k)).collect();
    assert_eq!((&f[0].left, &f[0].gt), (&f[1].left, &f[1].gt));
    assert_eq!((&f[2].left, &f[2].gt), (&f[3].left, &f[3].gt));
    assert_ne!(f[1].left, f[2].left);
    assert_ne!(f[1].gt, f[2].gt);
    assert_eq!(render_frame(&p, 2).unwrap().1.scene, 1);
}

/// Noise is fresh per frame and view, seeded: the same call gives the same bytes at any thread count.
#[test]
fn noisy_frames_differ_from_each_other_but_not_between_runs() {
    let p = SequenceParams { noise_sigma: 5.0, ..params(Motion::Static, 3) };
    let a = frame(&p, 1);
    let b = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| frame(&p, 1));
    assert_eq!(a, b);
    let c = frame(&p, 2);
    assert_ne!(a.left, c.left);
    assert_eq!(a.gt, c.gt);
}

#[test]
fn a_written_sequence_opens_with_ground_truth_for_every_frame() {
    let dir = tempfile::tempdir().unwrap();
    let p =
        SequenceParams { scene: SynthParams { width: 96, height: 48, ndisp: 24, seed: 2 }, ..params(Motion::Pan, 3) };
    let stems = write_synth_sequence(dir.path(), &p).unwrap();
    assert_eq!(stems, ["000000", "000001", "000002"]);
    let seq = crate::sequence::Sequence::open(dir.path()).unwrap();
    assert!(seq.frames.iter().all(|f| f.gt.is_some() && f.mask.is_some()));
    let calib = crate::io::calib::Calib::load(&dir.path().join("calib.txt")).unwrap();
    let (vmin, vmax) = (calib.float("vmin").unwrap(), calib.float("vmax").unwrap());
    for f in &seq.frames {
        let gt = crate::io::pfm::read_pfm(f.gt.as_ref().unwrap()).unwrap();
        assert!(gt.data.iter().all(|&d| vmin <= d && d <= vmax));
    }
    let truth = std::fs::read_to_string(dir.path().join("truth.txt")).unwrap();
    assert_eq!(truth.lines().filter(|l| !l.starts_with('#')).count(), 3);
    assert!(truth.contains("000002 0.200000 0.000000000 0"), "{truth}");
    let e = write_synth_sequence(dir.path(), &p).unwrap_err().to_string();
    assert!(e.contains("already holds"), "{e}");
    assert!("spin".parse::<Motion>().unwrap_err().to_string().contains("static, pan, dolly, object or cut"));
    assert!(write_synth_sequence(&dir.path().join("x"), &params(Motion::Pan, 1)).is_err());
}

/// A gain multiplies both views of a frame alike (rounded, clipped at 255): a step from its frame on, a jitter
/// that differs between frames within its bounds; the ground truth stays.
#[test]
fn a_gain_changes_the_views_of_its_frames_and_not_the_truth() {
    let gain = GainChange { jitter: 0.05, step: 0.1, step_at: 2 };
    let (plain, lit) = (params(Motion::Static, 4), SequenceParams { gain, ..params(Motion::Static, 4) });
    let gains: Vec<f64> = (0..4).map(|k| render_frame(&lit, k).unwrap().1.gain).collect();
    assert!(gains[..2].iter().all(|g| (0.95..1.05).contains(g)), "{gains:?}");
    assert!(gains[2..].iter().all(|g| (1.045..1.155).contains(g)), "{gains:?}");
    assert!(gains[0] != gains[1] && gains[2] != gains[3], "{gains:?}");
    for k in [0, 3] {
        let (a, b) = (frame(&plain, k), frame(&lit, k));
        assert_eq!(a.gt, b.gt);
        for (va, vb) in [(&a.left, &b.left), (&a.right, &b.right)] {
            for (p, q) in va.channels.iter().flatten().zip(vb.channels.iter().flatten()) {
                assert_eq!(*q, (p * gains[k] as f32).round().min(255.0));
            }
        }
    }
    assert!(SequenceParams { gain: GainChange { jitter: 0.6, ..gain }, ..lit.clone() }.validate().is_err());
}
