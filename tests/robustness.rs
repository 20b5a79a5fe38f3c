//! Robustness on synthetic scenes with exact ground truth: scenes rendered by `jem::synth` or the
//! shipped example, degraded by `jem::degrade` (seeded), matched by the default pipeline and by the paper's
//! (`configs/jem-all.toml`: no input conditioning, no coarse prior). Each test fails without the adaptive front
//! end of `[condition]`.

mod common;

use common::Pair;
use common::repo;
use jem::degrade::{Recipe, View, degrade};
use jem::synth::{MASK_VISIBLE, SynthParams, SynthScene, render_scene};
use jem::{Params, RgbImage};

/// The paper's full pipeline, as shipped.
fn paper() -> Params {
    Params::load(Some(&repo().join("configs/jem-all.toml")), &[]).unwrap()
}

/// Mean absolute error over the visible pixels of `scene`, matching `pair`.
fn mean_error(params: &Params, pair: &Pair, scene: &SynthScene) -> f64 {
    mean_error_where(params, pair, scene, |_| true)
}

/// [`mean_error`] over the visible pixels i with `keep(i)` only.
fn mean_error_where(params: &Params, pair: &Pair, scene: &SynthScene, keep: impl Fn(usize) -> bool) -> f64 {
    mean_errors(params, pair, scene, keep).0
}

/// One run of `params` on `pair`, scored twice: the mean absolute error over the visible pixels i with `keep(i)`,
/// and over all visible pixels.
fn mean_errors(params: &Params, pair: &Pair, scene: &SynthScene, keep: impl Fn(usize) -> bool) -> (f64, f64) {
    let out = pair.run(params);
    let ((mut sum, mut n), (mut sum_all, mut n_all)) = ((0.0, 0usize), (0.0, 0usize));
    for (i, ((d, g), m)) in out.disparity.data().iter().zip(scene.gt.data()).zip(scene.mask.data()).enumerate() {
        if *m == MASK_VISIBLE {
            let e = f64::from((d - g).abs());
            (sum_all, n_all) = (sum_all + e, n_all + 1);
            if keep(i) {
                (sum, n) = (sum + e, n + 1);
            }
        }
    }
    (sum / n as f64, sum_all / n_all as f64)
}

/// `img` with its contrast cut to `contrast` around mid-grey (weak texture).
fn flatten(mut img: RgbImage, contrast: f32) -> RgbImage {
    (0..3).for_each(|c| img.channel_mut(c).iter_mut().for_each(|v| *v = (127.5 + contrast * (*v - 127.5)).round()));
    img
}

/// A rendered scene (360 × 240, 48 labels), its texture's contrast cut to `contrast` (1 = as rendered).
fn scene(seed: u64, contrast: f32) -> SynthScene {
    let s = render_scene(&SynthParams { width: 360, height: 240, ndisp: 48, seed }).unwrap();
    SynthScene { left: flatten(s.left, contrast), right: flatten(s.right, contrast), ..s }
}

/// The scene's pair with `recipe` applied to both views (`None`: clean).
fn degraded(scene: &SynthScene, recipe: Option<&str>, seed: u64) -> Pair {
    let apply = |img: &RgbImage, view| match recipe {
        Some(r) => degrade(img, &r.parse::<Recipe>().unwrap(), view, seed).unwrap(),
        None => img.clone(),
    };
    Pair::new(apply(&scene.left, View::Left), apply(&scene.right, View::Right), scene.ndisp)
}

/// (paper, default) mean errors on `scene` degraded by `recipe`, printed.
fn both(scene: &SynthScene, recipe: Option<&str>) -> (f64, f64) {
    let pair = degraded(scene, recipe, 7);
    let (p, d) = (mean_error(&paper(), &pair, scene), mean_error(&Params::default(), &pair, scene));
    eprintln!("{:<20} paper {p:.3}  default {d:.3}", recipe.unwrap_or("clean"));
    (p, d)
}

/// Sensor noise σ 8: the default pipeline measures it, denoises what the cost sees and leans on the coarse prior.
#[test]
fn noisy_pair_default_beats_the_paper_pipeline() {
    let s = scene(21, 0.3);
    let (_, clean) = both(&s, None);
    let (paper, default) = both(&s, Some("noise:8"));
    assert!(default < 0.7 * paper, "noise σ 8: paper {paper:.3}, default {default:.3}");
    // The bound was clean + 0.5 (0.707) until the sub-pixel refinement took the clean pair from 0.207 to 0.108 (it
    // cannot do as much under noise: σ 8 0.602 -> 0.617); the same bound, absolute.
    assert!(default < 0.707, "noise σ 8: default {default:.3}, clean {clean:.3}");
}

/// Low light (12 % of the light, shot and read noise): the contrast stretch makes the measured noise relative to
/// the image's range, so the prior and the denoiser are as strong as the signal-to-noise ratio asks.
#[test]
fn dark_pair_default_beats_the_paper_pipeline() {
    let s = scene(22, 0.5);
    let (paper, default) = both(&s, Some("lowlight:0.12:1.5"));
    assert!(default < 0.7 * paper, "low light: paper {paper:.3}, default {default:.3}");
}

/// The right view darker with another gamma: Census is invariant to it and the prior does not get in the way.
#[test]
fn exposure_mismatch_costs_little() {
    let s = scene(23, 1.0);
    let (_, clean) = both(&s, None);
    let (_, default) = both(&s, Some("exposure:0.6:1.4"));
    assert!(default < 1.2 * clean + 0.05, "exposure: default {default:.3}, clean {clean:.3}");
}

/// On weakly textured images with sensor noise (σ 6 grey levels) the full-resolution cost makes gross errors;
/// the coarse prior, whose weight follows the measured noise, removes them (the shipped example, its contrast
/// cut to 15 % around mid-grey).
#[test]
fn weak_texture_and_noise() {
    // `examples/synth` (its pair is committed; its ground truth and mask are rendered, as here).
    let shipped = render_scene(&SynthParams::default()).unwrap();
    let (left, right) = (flatten(shipped.left, 0.15), flatten(shipped.right, 0.15));
    let example = SynthScene { left, right, gt: shipped.gt, mask: shipped.mask, ndisp: 48, vmin: 0.0, vmax: 47.0 };
    let (paper, default) = both(&example, Some("noise:6"));
    assert!(paper > 2.0, "the noise should hurt the paper's pipeline: {paper:.3}");
    assert!(default < 0.3 * paper, "paper {paper:.3}, default {default:.3}");
}

/// JPEG compression (quality 40) of a weakly textured pair: the block artifacts sit on the same image grid in
/// both views and the measured sensor noise is 0 (JPEG flattens the flat regions); the default measures the
/// blocking as noise, so it denoises what the cost sees and leans on the coarse prior.
#[test]
fn jpeg_pair_default_beats_the_paper_pipeline() {
    let s = scene(24, 0.3);
    let (_, clean) = both(&s, None);
    let (paper, default) = both(&s, Some("jpeg:40"));
    assert!(default < 0.8 * paper, "jpeg: paper {paper:.3}, default {default:.3}");
    assert!(default < clean + 1.0, "jpeg: default {default:.3}, clean {clean:.3}");
}

/// A surface with no texture at all (the nearest object of a rendered scene, a slanted disc on 12 % of the image,
/// painted one flat colour in both views): its matching cost is flat inside, so only its outline and the
/// pairwise terms place it. Measured inside the disc: the paper's pipeline 6.82 px, the default 2.34 px (the coarse
/// prior sees the outline over a larger share of the disc; at its 1/8 level the disc is about 9 px across),
/// winner-take-all 34.7 px. Then the same pair as if noiseless (below).
#[test]
fn untextured_surface() {
    let s = render_scene(&SynthParams { width: 360, height: 240, ndisp: 48, seed: 25 }).unwrap();
    let (w, h) = s.gt.dims();
    let gmax = s.gt.data().iter().copied().fold(f32::MIN, f32::max);
    let gmin = s.gt.data().iter().copied().fold(f32::MAX, f32::min);
    // The nearest quarter of the disparity range: one object in this scene.
    let cut = gmax - 0.25 * (gmax - gmin);
    let region: Vec<bool> = s.gt.data().iter().map(|&g| g >= cut).collect();
    let (mut left, mut right) = (s.left.clone(), s.right.clone());
    let colour = [200.0f32, 60.0, 160.0];
    for y in 0..h {
        // The object's span in the right view's row: where its left pixels land.
        let (mut lo, mut hi) = (usize::MAX, 0usize);
        for x in (0..w).filter(|&x| region[y * w + x]) {
            let i = y * w + x;
            (0..3).for_each(|c| left.channel_mut(c)[i] = colour[c]);
            let xr = (x as f32 - s.gt.data()[i]).round();
            if xr >= 0.0 {
                lo = lo.min(xr as usize);
                hi = hi.max(xr as usize);
            }
        }
        for x in lo..=hi.min(w - 1) {
            (0..3).for_each(|c| right.channel_mut(c)[y * w + x] = colour[c]);
        }
    }
    let flat = SynthScene { left, right, ..s };
    let share = region.iter().filter(|r| **r).count() as f64 / region.len() as f64;
    assert!((0.05..0.3).contains(&share), "one object: {:.1} % of the image", 100.0 * share);
    let pair = degraded(&flat, None, 7);
    // Mean error inside the painted object (visible pixels).
    let inside = |params: &Params| mean_error_where(params, &pair, &flat, |i| region[i]);
    let (paper, default) = (inside(&paper()), inside(&Params::default()));
    eprintln!("untextured surface ({:.1} % of the image): paper {paper:.3}, default {default:.3}", 100.0 * share);
    assert!(paper > 3.0, "the flat surface should defeat the paper's pipeline: {paper:.3}");
    assert!(default < 0.5 * paper && default < 2.5, "paper {paper:.3}, default {default:.3}");

    // As if the pair were noiseless (this renderer's texture reads σn ≈ 2, so λ would be about 1 from the noise
    // alone): without the noise-scaled weight only the floor where the cost is flat (`condition.prior.flat`) lets
    // the coarse levels hold the disc. Measured: 12.61 px without the floor (no coarse prior at all), 1.93 with it.
    let mut noiseless = Params::default();
    noiseless.condition.prior.per_sigma = 0.0;
    let mut no_floor = noiseless.clone();
    no_floor.condition.prior.flat = 0.0;
    let (with, without) = (inside(&noiseless), inside(&no_floor));
    eprintln!("untextured surface, no noise-scaled prior: floor where the cost is flat {with:.3}, none {without:.3}");
    assert!(with < 0.3 * without && with < 2.5, "with the floor {with:.3}, without {without:.3}");
}

/// Thin structures under noise (σ 8): bars two pixels wide, 12 px of disparity in front of a textured background.
/// The coarse runs (at 1/2, 1/4 and 1/8) cannot hold them, and a prior as strong as the noise asks would forbid them;
/// the prior weakened at detail (`condition.prior.detail`) lets the full-resolution cost keep them.
#[test]
fn thin_structures_under_noise() {
    let (w, h, ndisp) = (240usize, 120usize, 32usize);
    let (d_bg, d_fg) = (6usize, 18usize);
    let mut rng = jem::internals::SplitMix64::new(31);
    // A smoothly shaded background (what a coarse level holds) and bright, textured bars (what it cannot).
    let bg: Vec<f32> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            100.0 + 40.0 * (x / 7.0).sin() * (y / 9.0).cos() + 20.0 * ((x + 2.0 * y) / 13.0).sin()
        })
        .collect();
    let fg: Vec<f32> = (0..w * h).map(|_| 200.0 + rng.below(50) as f32).collect();
    let bar = |x: usize| (30..220).contains(&x) && (x - 30) % 19 < 2;
    let (mut left, mut right) = (vec![0.0f32; w * h], vec![0.0f32; w * h]);
    let (mut gt, mut mask) = (vec![d_bg as f32; w * h], vec![MASK_VISIBLE; w * h]);
    for y in 0..h {
        // The background in world coordinates: left pixel x and right pixel x − d_bg see bg(x).
        for x in 0..w {
            left[y * w + x] = bg[y * w + x];
            right[y * w + x] = bg[y * w + (x + d_bg).min(w - 1)];
        }
        for x in (0..w).filter(|&x| bar(x)) {
            left[y * w + x] = fg[y * w + x];
            right[y * w + x - d_fg] = fg[y * w + x];
            gt[y * w + x] = d_fg as f32;
        }
        // Background pixels whose right-view point a bar covers are occluded.
        for x in (d_bg..w).filter(|&x| !bar(x)) {
            let xr = x - d_bg;
            if (0..w).any(|xb| bar(xb) && xb - d_fg == xr) {
                mask[y * w + x] = jem::synth::MASK_OCCLUDED;
            }
        }
    }
    let grey = |v: Vec<f32>| RgbImage::from_channels(w, h, [v.clone(), v.clone(), v]).unwrap();
    let scene = SynthScene {
        left: grey(left),
        right: grey(right),
        gt: jem::Plane::from_vec(w, h, gt).unwrap(),
        mask: jem::Plane::from_vec(w, h, mask).unwrap(),
        ndisp,
        vmin: 0.0,
        vmax: (ndisp - 1) as f32,
    };
    let pair = degraded(&scene, Some("noise:8"), 5);
    let on_bars = |params: &Params| mean_errors(params, &pair, &scene, |i| bar(i % w) && i / w > 4 && i / w < h - 4);
    let mut without = Params::default();
    without.condition.prior.detail = 0.0;
    let ((off, all_off), (on, all_on)) = (on_bars(&without), on_bars(&Params::default()));
    eprintln!(
        "thin bars under noise σ 8: prior.detail off {off:.3} px, default {on:.3} px (whole image {all_off:.3} / {all_on:.3})"
    );
    assert!(on < 0.7 * off, "default {on:.3}, without the detail factor {off:.3}");
    assert!(all_on < all_off, "whole image: default {all_on:.3}, without {all_off:.3}");
}

/// Depth edges under noise (σ 8): the coarse runs fatten the near objects by a coarse pixel or more, and a prior
/// that holds the full resolution to the coarse disparity keeps the fattening. With `prior.spread` the labels of
/// the whole step are free beside a coarse depth edge, so the full resolution places the edge. Six rendered
/// scenes; mean error within 8 px of a depth step (on the row): 1.454 px with the point prior, 0.991 px with the
/// spread (every scene better: 12 to 50 %); whole images 0.326 / 0.269.
#[test]
fn depth_edges_under_noise() {
    let mut point = Params::default();
    point.condition.prior.spread = 0;
    let (mut near, mut all) = ([0.0f64; 2], [0.0f64; 2]);
    for seed in 11..=16 {
        let s = scene(seed, 1.0);
        let w = s.gt.width();
        // Within 8 px (on the row) of a step of more than 4 px in the ground truth.
        let near_edge = |i: usize| {
            let (x, g) = (i % w, s.gt.data()[i]);
            (x.saturating_sub(8)..(x + 9).min(w)).any(|xx| (s.gt.data()[i - x + xx] - g).abs() > 4.0)
        };
        let pair = degraded(&s, Some("noise:8"), 5);
        for (k, params) in [&point, &Params::default()].into_iter().enumerate() {
            let (at_edges, whole) = mean_errors(params, &pair, &s, near_edge);
            near[k] += at_edges / 6.0;
            all[k] += whole / 6.0;
        }
    }
    eprintln!(
        "depth edges under noise σ 8: point prior {:.3} px, spread {:.3} px (whole images {:.3} / {:.3})",
        near[0], near[1], all[0], all[1]
    );
    assert!(near[1] < 0.8 * near[0], "near depth edges: spread {:.3}, point prior {:.3}", near[1], near[0]);
    assert!(all[1] < all[0], "whole images: spread {:.3}, point prior {:.3}", all[1], all[0]);
}

/// A rig whose rectification is off: the right view of six rendered scenes moved vertically by a known surface
/// (0.8 to 1.9 px: a shift, a roll and a bend), with light noise (σ 1). The default measures the offset's range to
/// within 0.15 px and removes it (mean error 0.47 px without, 0.22 px with, when written).
#[test]
fn vertical_misalignment_is_measured_and_removed() {
    use jem::internals::vertical::{VerticalOffset, resample_right};
    let mut off = Params::default();
    off.condition.vertical.enabled = false;
    let (mut errors, mut worst) = ([0.0f64; 2], 0.0f64);
    for seed in 11..=16 {
        let s = scene(seed, 1.0);
        let (w, h) = (s.gt.width(), s.gt.height());
        let mut truth = VerticalOffset::zero(w, h);
        truth.coef = [1.2, 0.8, 0.0, 0.0, 1.2];
        // The right view whose row y + v(x, y) shows what the left view's row y does.
        let mut inverse = truth;
        inverse.coef = truth.coef.map(|c| -c);
        let moved = SynthScene { right: resample_right(&s.right, &inverse), ..s.clone() };
        let pair = degraded(&moved, Some("noise:1"), 5);
        let out = pair.run(&Params::default());
        let measured = out.measured.and_then(|m| m.vertical).expect("the offset is measured");
        assert!(measured.corrected, "seed {seed}: not removed ({:?})", measured.range);
        let (lo, hi) = truth.range();
        worst = worst.max(f64::from((measured.range.0 - lo).abs()).max(f64::from((measured.range.1 - hi).abs())));
        for (k, params) in [&off, &Params::default()].into_iter().enumerate() {
            errors[k] += mean_error(params, &pair, &moved) / 6.0;
        }
    }
    eprintln!(
        "vertical misalignment: not removed {:.3} px, removed {:.3} px; range measured to within {worst:.3} px",
        errors[0], errors[1]
    );
    assert!(worst < 0.15, "the measured range is {worst:.3} px off");
    assert!(errors[1] < 0.8 * errors[0], "removed {:.3}, not removed {:.3}", errors[1], errors[0]);
}
