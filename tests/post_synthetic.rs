//! Post-processing on synthetic scenes with known answers: slanted-plane smoothing recovers
//! piecewise-planar disparities from noisy, holed maps; degenerate inputs stay finite; outputs do not depend on the
//! thread count. One `#[ignore]`d test runs both stages on a Middlebury scene for timings.

mod common;

use jem::internals::SplitMix64;
use jem::internals::post::planes::fit_slanted_planes;
use jem::internals::post::wmedian::weighted_median;
use jem::params::{SpsParams, WmedianParams};
use jem::{DisparityMap, Plane, RgbImage};

/// A standard normal sample (Box–Muller, cosine branch).
fn gauss(rng: &mut SplitMix64) -> f64 {
    let (u, v) = (rng.next_f64().max(1e-300), rng.next_f64());
    (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
}

/// A piecewise-planar scene: its image, the true disparity, the region of each pixel, and a degraded map with
/// its trusted mask.
struct Synthetic {
    image: RgbImage,
    truth: Vec<f64>,
    region: Vec<u8>,
    disp: DisparityMap,
    trusted: Plane<bool>,
}

/// Four slanted planes: a background, a floor, a rectangle and a disc, each with its own colour and a texture.
/// The degraded map has Gaussian noise (σ = `noise` px), vertical invalid stripes, 10% random invalid pixels, and
/// 1% trusted gross outliers (uniform in 0..40 px).
fn synthetic(w: usize, h: usize, noise: f64, seed: u64) -> Synthetic {
    let colours: [[f32; 3]; 4] = [[90.0, 110.0, 160.0], [150.0, 120.0, 80.0], [200.0, 60.0, 60.0], [60.0, 170.0, 80.0]];
    synthetic_coloured(w, h, noise, seed, colours)
}

/// [`synthetic`] with the given region colours.
fn synthetic_coloured(w: usize, h: usize, noise: f64, seed: u64, colours: [[f32; 3]; 4]) -> Synthetic {
    let mut rng = SplitMix64::new(seed);
    let planes: [[f64; 3]; 4] = [[0.02, 0.01, 10.0], [0.0, 0.15, -3.0], [-0.05, 0.03, 30.0], [0.04, -0.02, 20.0]];
    let (wf, hf) = (w as f64, h as f64);
    let mut image = RgbImage::new(w, h);
    let (mut truth, mut region) = (vec![0.0; w * h], vec![0u8; w * h]);
    let mut disp = Plane::new(w, h, 0.0f32);
    let mut trusted = Plane::new(w, h, true);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let (xf, yf) = (x as f64, y as f64);
            let (dx, dy) = (xf - 0.7 * wf, yf - 0.35 * hf);
            let r = if dx * dx + dy * dy < (0.18 * hf).powi(2) {
                3
            } else if xf > 0.15 * wf && xf < 0.45 * wf && yf > 0.2 * hf && yf < 0.6 * hf {
                2
            } else if yf > 0.7 * hf {
                1
            } else {
                0
            };
            region[i] = r as u8;
            let pl = planes[r];
            truth[i] = pl[0] * xf + pl[1] * yf + pl[2];
            let tex = (rng.next_f64() as f32 - 0.5) * 30.0;
            for (c, base) in colours[r].into_iter().enumerate() {
                image.channel_mut(c)[i] = (base + tex).clamp(0.0, 255.0);
            }
            let stripe = x % 37 < 3;
            disp.data_mut()[i] = if stripe || rng.next_f64() < 0.1 {
                trusted.data_mut()[i] = false;
                f32::INFINITY
            } else if rng.next_f64() < 0.01 {
                (rng.next_f64() * 40.0) as f32
            } else {
                (truth[i] + noise * gauss(&mut rng)) as f32
            };
        }
    }
    Synthetic { image, truth, region, disp, trusted }
}

/// Pixels at least `margin` px (Chebyshev) from any other region.
fn interior(region: &[u8], w: usize, h: usize, margin: usize) -> Vec<bool> {
    let mut out = vec![true; w * h];
    for y in 0..h {
        for x in 0..w {
            let r = region[y * w + x];
            'scan: for yy in y.saturating_sub(margin)..=(y + margin).min(h - 1) {
                for xx in x.saturating_sub(margin)..=(x + margin).min(w - 1) {
                    if region[yy * w + xx] != r {
                        out[y * w + x] = false;
                        break 'scan;
                    }
                }
            }
        }
    }
    out
}

struct ErrorStats {
    mean_all: f64,
    mean_interior: f64,
    frac_interior_within: f64,
    max_interior: f64,
}

fn errors(s: &Synthetic, out: &DisparityMap, margin: usize, within: f64) -> ErrorStats {
    let (w, h) = out.dims();
    let inner = interior(&s.region, w, h, margin);
    let err: Vec<f64> = out.data().iter().zip(&s.truth).map(|(d, t)| (f64::from(*d) - t).abs()).collect();
    let n_in = inner.iter().filter(|b| **b).count() as f64;
    let inner_err = || err.iter().zip(&inner).filter(|(_, b)| **b).map(|(e, _)| *e);
    ErrorStats {
        mean_all: err.iter().sum::<f64>() / err.len() as f64,
        mean_interior: inner_err().sum::<f64>() / n_in,
        frac_interior_within: inner_err().filter(|e| *e < within).count() as f64 / n_in,
        max_interior: inner_err().fold(0.0, f64::max),
    }
}

fn sps(segments: usize) -> SpsParams {
    SpsParams { enabled: true, segments, ..SpsParams::default() }
}

/// The stated bound: with σ = 0.3 px noise, stripes and 10% holes and 1% gross outliers, the planes recover the
/// truth to a mean absolute error < 0.1 px over all pixels, and 99% of the pixels at least 3 px from a region border
/// are within 0.5 px (this seed: mean 0.025, interior mean 0.022, interior max 0.15).
#[test]
fn sps_recovers_piecewise_planar_scene() {
    let (w, h) = (200, 150);
    let s = synthetic(w, h, 0.3, 42);
    let out = fit_slanted_planes(&s.image, &s.disp, &s.trusted, &sps(150));
    assert!(out.data().iter().all(|d| d.is_finite()));
    let e = errors(&s, &out, 3, 0.5);
    eprintln!(
        "mean {:.4}, interior mean {:.4}, interior <0.5: {:.4}, interior max {:.3}",
        e.mean_all, e.mean_interior, e.frac_interior_within, e.max_interior
    );
    assert!(e.mean_all < 0.1, "mean abs error {}", e.mean_all);
    assert!(e.frac_interior_within > 0.99, "fraction within 0.5 px {}", e.frac_interior_within);
    assert!(e.max_interior < 0.5, "interior max error {} (seeds 1–15: at most 0.25)", e.max_interior);
}

/// All regions share one colour (texture only): the disparity term alone must move the segment borders onto the
/// depth edges. Bound: mean < 0.2 px, 99% of the pixels ≥ 3 px from a border within 0.5 px (this seed: mean 0.092,
/// 99.87%; seeds 1–11: mean ≤ 0.105, ≥ 99.76%). The misses are where the background and floor planes nearly
/// intersect (within τ of each other, so the data cannot separate them) and in invalid stripes along a border.
#[test]
fn sps_follows_depth_edges_without_colour_edges() {
    let (w, h) = (200, 150);
    let s = synthetic_coloured(w, h, 0.3, 42, [[120.0, 120.0, 120.0]; 4]);
    let out = fit_slanted_planes(&s.image, &s.disp, &s.trusted, &sps(150));
    let e = errors(&s, &out, 3, 0.5);
    eprintln!(
        "mean {:.4}, interior mean {:.4}, interior <0.5: {:.4}, interior max {:.3}",
        e.mean_all, e.mean_interior, e.frac_interior_within, e.max_interior
    );
    assert!(e.mean_all < 0.2, "mean abs error {}", e.mean_all);
    assert!(e.frac_interior_within > 0.99, "fraction within 0.5 px {}", e.frac_interior_within);
}

/// Without noise or outliers, the interior is exact up to float rounding.
#[test]
fn sps_is_exact_on_clean_planes() {
    let (w, h) = (120, 90);
    let mut s = synthetic(w, h, 0.0, 5);
    // Remove the gross outliers: every trusted pixel carries its true value.
    for (i, d) in s.disp.data_mut().iter_mut().enumerate() {
        if d.is_finite() {
            *d = s.truth[i] as f32;
        }
    }
    let out = fit_slanted_planes(&s.image, &s.disp, &s.trusted, &sps(80));
    let e = errors(&s, &out, 3, 1e-3);
    eprintln!("mean {:.5}, interior max {:.6}", e.mean_all, e.max_interior);
    assert!(e.max_interior < 1e-3, "interior max error {}", e.max_interior);
    assert!(e.mean_all < 0.05, "mean abs error {}", e.mean_all);
}

#[test]
fn sps_is_independent_of_thread_count() {
    let s = synthetic(96, 64, 0.3, 9);
    let run = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| fit_slanted_planes(&s.image, &s.disp, &s.trusted, &sps(40)))
    };
    let (a, b, c) = (run(1), run(2), run(3));
    assert!(a.data().iter().zip(b.data()).all(|(x, y)| x.to_bits() == y.to_bits()));
    assert!(a.data().iter().zip(c.data()).all(|(x, y)| x.to_bits() == y.to_bits()));
}

#[test]
fn sps_degenerate_inputs_stay_finite() {
    let p = sps(1000);
    let check = |w: usize, h: usize, disp: Vec<f32>, trusted: Vec<bool>| {
        let out = fit_slanted_planes(
            &RgbImage::new(w, h),
            &Plane::from_vec(w, h, disp).unwrap(),
            &Plane::from_vec(w, h, trusted).unwrap(),
            &p,
        );
        assert_eq!(out.dims(), (w, h));
        assert!(out.data().iter().all(|d| d.is_finite() && *d >= 0.0), "{w}x{h}: {:?}", out.data());
        out
    };
    // All invalid: 0 everywhere.
    let out = check(40, 30, vec![f32::INFINITY; 1200], vec![false; 1200]);
    assert!(out.data().iter().all(|d| *d == 0.0));
    // Finite but nothing trusted: with untrusted_weight 0 as if all invalid, with the default 0.1 the untrusted
    // values count.
    let no_untrusted = SpsParams { untrusted_weight: 0.0, ..p.clone() };
    let out =
        fit_slanted_planes(&RgbImage::new(20, 10), &Plane::new(20, 10, 7.0), &Plane::new(20, 10, false), &no_untrusted);
    assert!(out.data().iter().all(|d| *d == 0.0));
    let out = check(20, 10, vec![7.0; 200], vec![false; 200]);
    assert!(out.data().iter().all(|d| *d == 7.0));
    // Constant: reproduced exactly.
    let out = check(40, 30, vec![12.5; 1200], vec![true; 1200]);
    assert!(out.data().iter().all(|d| *d == 12.5), "{:?}", out.data().get(..8));
    // 1×1, 1×n, n×1, 2×2, with and without data; more segments than pixels.
    assert_eq!(check(1, 1, vec![3.0], vec![true]).data(), vec![3.0]);
    assert_eq!(check(1, 1, vec![f32::INFINITY], vec![false]).data(), vec![0.0]);
    check(1, 7, (0..7).map(|k| k as f32).collect(), vec![true; 7]);
    check(9, 1, (0..9).map(|k| 2.0 * k as f32).collect(), vec![true; 9]);
    check(2, 2, vec![1.0, f32::INFINITY, 3.0, 4.0], vec![true, false, true, true]);
    // A single valid pixel in a larger image: every segment borrows its plane.
    let mut d = vec![f32::INFINITY; 300];
    d[151] = 6.0;
    let t: Vec<bool> = d.iter().map(|v| v.is_finite()).collect();
    let p_low = SpsParams { min_support: 0.5, ..p.clone() };
    let out = fit_slanted_planes(
        &RgbImage::new(20, 15),
        &Plane::from_vec(20, 15, d).unwrap(),
        &Plane::from_vec(20, 15, t).unwrap(),
        &p_low,
    );
    assert!(out.data().iter().all(|v| *v == 6.0), "{:?}", out.data());
    // Empty.
    let out = fit_slanted_planes(&RgbImage::new(0, 0), &Plane::new(0, 0, 0.0), &Plane::new(0, 0, true), &p);
    assert!(out.data().is_empty());
}

/// The output stays in [0, max finite input + τ] even where planes extrapolate steeply.
#[test]
fn sps_output_is_clamped() {
    let (w, h) = (60, 40);
    // A steep ramp with only the first columns valid: extrapolated planes would overshoot.
    let disp: Vec<f32> = (0..w * h).map(|i| if i % w < 6 { 2.0 * (i % w) as f32 } else { f32::INFINITY }).collect();
    let trusted: Vec<bool> = disp.iter().map(|d| d.is_finite()).collect();
    let p = SpsParams { min_support: 1.0, ..sps(12) };
    let out = fit_slanted_planes(
        &RgbImage::new(w, h),
        &Plane::from_vec(w, h, disp).unwrap(),
        &Plane::from_vec(w, h, trusted).unwrap(),
        &p,
    );
    let max = 10.0 + p.inlier_thresh_px;
    assert!(
        out.data().iter().all(|d| (0.0..=max).contains(d)),
        "max {}",
        out.data().iter().fold(0.0f32, |a, b| a.max(*b))
    );
}

/// `min_support_fraction` scales the support a segment needs with its size: a cell with a small cluster of data
/// (16 px of 256, above `min_support` = 10 but below 30% of the cell) fits its own plane without it and borrows
/// its neighbour's with it.
#[test]
fn sparse_segments_borrow_with_min_support_fraction() {
    let (w, h) = (32, 16);
    // Two 16×16 cells: the left one fully trusted at d = 5, the right one only a 4×4 cluster at d = 9 in its
    // bottom-right corner, nothing else.
    let disp: Vec<f32> = (0..w * h)
        .map(|i| match (i % w, i / w) {
            (x, _) if x < 16 => 5.0,
            (x, y) if x >= 28 && y >= 12 => 9.0,
            _ => f32::INFINITY,
        })
        .collect();
    let trusted: Vec<bool> = disp.iter().map(|d| d.is_finite()).collect();
    let run = |fraction: f32| {
        let p = SpsParams { segments: 2, min_support: 10.0, min_support_fraction: fraction, ..SpsParams::default() };
        let (d, t) = (Plane::from_vec(w, h, disp.clone()).unwrap(), Plane::from_vec(w, h, trusted.clone()).unwrap());
        fit_slanted_planes(&RgbImage::new(w, h), &d, &t, &p)
    };
    // Far from the cluster, in the right cell.
    let (x, y) = (22, 3);
    let own = run(0.0);
    assert!((own.at(x, y) - 9.0).abs() < 1e-3, "absolute threshold: own plane, got {}", own.at(x, y));
    let borrowed = run(0.3);
    assert!((borrowed.at(x, y) - 5.0).abs() < 1e-3, "fraction 0.3: neighbour's plane, got {}", borrowed.at(x, y));
    // The left cell is the same either way.
    assert!((0..h).all(|y| (0..12).all(|x| own.at(x, y) == 5.0 && borrowed.at(x, y) == 5.0)));
}

/// Weighted median on the synthetic scene: filling the holes from same-coloured neighbours recovers the truth
/// to within the noise, far better than the row-wise fill near the region borders.
#[test]
fn wmedian_fills_holes_from_the_right_side() {
    let (w, h) = (120, 90);
    let s = synthetic(w, h, 0.0, 3);
    let mut filled = s.disp.clone();
    jem::internals::post::fill::fill_occlusions_in_place(&mut filled);
    let targets = Plane::from_vec(w, h, s.trusted.data().iter().map(|t| !t).collect()).unwrap();
    let p = WmedianParams { enabled: true, ..WmedianParams::default() };
    let out = weighted_median(&filled, &s.image, &targets, &p);
    let bad = |m: &DisparityMap| {
        targets
            .data()
            .iter()
            .zip(m.data())
            .zip(&s.truth)
            .filter(|((t, d), g)| **t && (f64::from(**d) - **g).abs() > 1.0)
            .count()
    };
    let (bad_fill, bad_wm) = (bad(&filled), bad(&out));
    eprintln!("targets with error > 1 px: fill {bad_fill}, weighted median {bad_wm}");
    assert!(bad_wm * 4 < bad_fill, "fill {bad_fill}, weighted median {bad_wm}");
    // Non-targets untouched.
    assert!(targets.data().iter().zip(out.data()).zip(filled.data()).all(|((t, a), b)| *t || a == b));
}

/// Real data, for timings and sanity (not tuning): WTA + LRC (invalidate) on Motorcycle Q (or `JEM_SCENE`), then
/// fill → weighted median → planes. Prints times and errors ×4 (full-resolution px) on the non-occluded pixels,
/// and checks that each post-processing step helps (Motorcycle: 32 % invalid after the check; fill 10.0, fill +
/// weighted median 6.6, the whole chain 2.8). `cargo test --release --test post_synthetic -- --ignored --nocapture`
#[test]
#[ignore = "timings on a real scene (a few seconds); run it with `cargo test --release -- --include-ignored`, as .ci/run does"]
fn motorcycle_timings() {
    use std::time::Instant;
    let scene = std::env::var("JEM_SCENE").unwrap_or_else(|_| "Motorcycle".into());
    let Some(data) = common::data_dir() else { return };
    let dir = data.join("MiddEval3/trainingQ").join(&scene);
    let left = jem::io::read_image(&dir.join("im0.png")).unwrap();
    let right = jem::io::read_image(&dir.join("im1.png")).unwrap();
    let ndisp = jem::io::calib::read_ndisp(&dir.join("calib.txt")).unwrap();
    let gt = jem::io::pfm::read_pfm(&dir.join("disp0GT.pfm")).unwrap();
    let mask = jem::io::read_grey8(&dir.join("mask0nocc.png")).unwrap();
    let pair = common::Pair::new(left, right, ndisp);
    // The pipeline's own post-processing off (it is on by default): `raw` keeps the holes of the check.
    let off: Vec<String> = [
        "model=wta",
        "post.lrc.mode=invalidate",
        "post.fill=false",
        "post.wmedian.enabled=false",
        "post.sps.enabled=false",
    ]
    .map(String::from)
    .to_vec();
    let params = jem::Params::load(None, &off).unwrap();
    let raw = pair.run(&params).disparity;
    let (w, h) = raw.dims();
    let trusted = Plane::from_vec(w, h, raw.data().iter().map(|d| d.is_finite()).collect()).unwrap();
    let targets = Plane::from_vec(w, h, trusted.data().iter().map(|t| !t).collect()).unwrap();
    let invalid = targets.data().iter().filter(|t| **t).count();
    let avg_err = |m: &DisparityMap| {
        let (mut sum, mut n, mut bad2) = (0.0f64, 0usize, 0usize);
        for i in 0..w * h {
            if mask.data()[i] == 255 && gt.data()[i].is_finite() && m.data()[i].is_finite() {
                let e = 4.0 * f64::from((m.data()[i].clamp(0.0, ndisp as f32) - gt.data()[i]).abs());
                sum += e;
                n += 1;
                bad2 += usize::from(e > 2.0);
            }
        }
        (sum / n as f64, 100.0 * bad2 as f64 / n as f64)
    };
    let mut filled = raw.clone();
    jem::internals::post::fill::fill_occlusions_in_place(&mut filled);
    let wm_params = WmedianParams { enabled: true, ..WmedianParams::default() };
    let sps_params = SpsParams { enabled: true, ..SpsParams::default() };
    // Best of 3 (the machine is shared): wall time with the default pool, then with one thread.
    let best_ms = |f: &dyn Fn()| {
        (0..3)
            .map(|_| {
                let t0 = Instant::now();
                f();
                t0.elapsed().as_secs_f64() * 1e3
            })
            .fold(f64::INFINITY, f64::min)
    };
    // CPU time of the calling thread (Linux schedstat: ns on the CPU), immune to other jobs on the machine.
    let cpu_ms = || {
        std::fs::read_to_string("/proc/thread-self/schedstat")
            .ok()
            .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse::<f64>().ok()))
            .map_or(f64::NAN, |ns| ns * 1e-6)
    };
    let best_cpu_ms = |f: &dyn Fn()| {
        (0..3)
            .map(|_| {
                let t0 = cpu_ms();
                f();
                cpu_ms() - t0
            })
            .fold(f64::INFINITY, f64::min)
    };
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let wm = weighted_median(&filled, &pair.left, &targets, &wm_params);
    let planes = fit_slanted_planes(&pair.left, &wm, &trusted, &sps_params);
    let t_wm = best_ms(&|| drop(weighted_median(&filled, &pair.left, &targets, &wm_params)));
    let t_wm1 = one.install(|| best_cpu_ms(&|| drop(weighted_median(&filled, &pair.left, &targets, &wm_params))));
    let t_sps = best_ms(&|| drop(fit_slanted_planes(&pair.left, &wm, &trusted, &sps_params)));
    let t_sps1 = one.install(|| best_cpu_ms(&|| drop(fit_slanted_planes(&pair.left, &wm, &trusted, &sps_params))));
    // The brief's reference load for the filter: ~15% targets (the invalid pixels of two rows in five).
    let targets15 = Plane::from_vec(w, h, (0..w * h).map(|i| targets.data()[i] && (i / w) % 5 < 2).collect()).unwrap();
    let n15 = targets15.data().iter().filter(|t| **t).count();
    let t_wm15 = best_ms(&|| drop(weighted_median(&filled, &pair.left, &targets15, &wm_params)));
    let t_wm15_1 = one.install(|| best_cpu_ms(&|| drop(weighted_median(&filled, &pair.left, &targets15, &wm_params))));
    let no_untrusted = SpsParams { untrusted_weight: 0.0, ..sps_params.clone() };
    let planes_no_untrusted = fit_slanted_planes(&pair.left, &wm, &trusted, &no_untrusted);
    let planes_fill = fit_slanted_planes(&pair.left, &filled, &trusted, &sps_params);
    let planes_raw = fit_slanted_planes(&pair.left, &raw, &trusted, &sps_params);
    eprintln!(
        "{scene} {w}x{h}, {:.1}% invalid after LRC, {} threads",
        100.0 * invalid as f64 / (w * h) as f64,
        rayon::current_num_threads()
    );
    eprintln!(
        "weighted median: {t_wm:.1} ms wall ({t_wm1:.1} ms CPU on 1 thread); planes: {t_sps:.1} ms wall ({t_sps1:.1} ms CPU on 1 thread)"
    );
    eprintln!(
        "weighted median, {:.1}% targets: {t_wm15:.1} ms wall ({t_wm15_1:.1} ms CPU on 1 thread)",
        100.0 * n15 as f64 / (w * h) as f64
    );
    for (name, m) in [
        ("fill", &filled),
        ("fill+wmedian", &wm),
        ("planes (no fill)", &planes_raw),
        ("fill+planes", &planes_fill),
        ("fill+wmedian+planes", &planes),
        ("… with untrusted_weight 0", &planes_no_untrusted),
    ] {
        let (avg, bad) = avg_err(m);
        eprintln!("{name:>24}: avgErr {avg:.3} (x4 px), bad2.0 {bad:.2}% (nonocc)");
    }
    let (fill, wmedian, chain) = (avg_err(&filled).0, avg_err(&wm).0, avg_err(&planes).0);
    assert!(wmedian < fill && chain < wmedian, "fill {fill:.3}, + weighted median {wmedian:.3}, + planes {chain:.3}");
    assert!(planes.data().iter().all(|d| d.is_finite()), "the planes leave no hole");
}

/// More segments than the image can hold (`SpsParams::max_segments`: pixels / min_support) are
/// held to that bound, so 2^24 segments give exactly the map of the bound and still recover the planes (1a367fa:
/// 2^24 segments on this 200 × 150 scene gave 1-px cells, none able to fit a plane alone; the map was wrecked).
#[test]
fn absurd_segment_counts_are_held_to_the_image() {
    let (w, h) = (200, 150);
    let s = synthetic(w, h, 0.3, 42);
    let bound = sps(1).max_segments(w * h);
    assert_eq!(bound, w * h / 10, "pixels / min_support (10)");
    assert_eq!(SpsParams { min_support: 0.0, ..sps(1) }.max_segments(w * h), w * h / 3, "3 points a plane");
    let at_bound = fit_slanted_planes(&s.image, &s.disp, &s.trusted, &sps(bound));
    let absurd = fit_slanted_planes(&s.image, &s.disp, &s.trusted, &sps(1 << 24));
    let differ = absurd.data().iter().zip(at_bound.data()).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
    assert_eq!(differ, 0, "held to the bound: {differ} of {} pixels differ", w * h);
    let e = errors(&s, &absurd, 3, 0.5);
    assert!(
        e.mean_all < 0.3 && e.frac_interior_within > 0.95,
        "mean {}, within {}",
        e.mean_all,
        e.frac_interior_within
    );
}
