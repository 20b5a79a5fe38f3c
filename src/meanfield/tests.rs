//! Tests of the inference as a whole: recovery of synthetic disparities, the schedules against slow references,
//! the pyramid, annealing, and thread-count determinism. Unit tests of single parts sit in their own files.

#![allow(clippy::needless_range_loop)] // index loops read best in reference implementations

use super::energy::{MIN_RELATIVE_PROBABILITY, softmax_neg_in_place};
use super::*;
use crate::image::Plane;
use crate::params::{CostParams, MeanFieldParams, Normalization, Params, Schedule};
use crate::test_util::rand_vec;

fn tiny_image(w: usize, h: usize) -> RgbImage {
    let noise = rand_vec(w * h, 5);
    let mut img = RgbImage::new(w, h);
    for i in 0..w * h {
        let x = i % w;
        let base = if x < w / 2 { [180.0, 60.0, 50.0] } else { [40.0, 90.0, 200.0] };
        for c in 0..3 {
            img.channels[c][i] = base[c] + 25.0 * noise[i];
        }
    }
    img
}

/// The lattice message against Σ_{j≠i} k(i, j) Q_j(l) computed densely, for each normalisation.
/// Tolerance as for the lattice itself (its kernel is an approximation of the Gaussian; see
/// `lattice_matches_brute_force_gaussian`): relative L2 error below 12%.
#[test]
fn meanfield_fcm_message_matches_brute_force() {
    let (w, h, m) = (16, 12, 4);
    let img = tiny_image(w, h);
    let n = w * h;
    let cost =
        CostVolume { width: w, height: h, ndisp: m, data: rand_vec(n * m, 11).iter().map(|v| v * 10.0).collect() };
    for norm in [Normalization::None, Normalization::Pixel, Normalization::Symmetric] {
        let p = MeanFieldParams { normalization: norm, exclude_self: true, ..MeanFieldParams::default() };
        let mut mf = MeanField::new(&cost, &img, &p, PairwiseWeights { fcm: 1.0, lcm: 0.0 });
        let fast = mf.fcm_message();
        let q = mf.marginals().to_vec();
        let k = |i: usize, j: usize| {
            let (xi, yi, xj, yj) = ((i % w) as f32, (i / w) as f32, (j % w) as f32, (j / w) as f32);
            let (fi, fj) = (img.rgb(i), img.rgb(j));
            let dp = ((xi - xj).powi(2) + (yi - yj).powi(2)) / (2.0 * p.sigma_xy.powi(2));
            let df = fi.iter().zip(&fj).map(|(a, b)| (a - b).powi(2)).sum::<f32>() / (2.0 * p.sigma_rgb.powi(2));
            (-dp - df).exp()
        };
        let deg: Vec<f32> = (0..n).map(|i| (0..n).filter(|&j| j != i).map(|j| k(i, j)).sum()).collect();
        let (mut err2, mut ref2) = (0.0f64, 0.0f64);
        for i in 0..n {
            for l in 0..m {
                let reference: f32 = (0..n)
                    .filter(|&j| j != i)
                    .map(|j| {
                        let kij = k(i, j);
                        match norm {
                            Normalization::None => kij * q[j * m + l],
                            Normalization::Pixel => kij * q[j * m + l] / deg[i],
                            Normalization::Symmetric => kij * q[j * m + l] / (deg[i] * deg[j]).sqrt(),
                        }
                    })
                    .sum();
                err2 += f64::from(fast[i * m + l] - reference).powi(2);
                ref2 += f64::from(reference).powi(2);
            }
        }
        let rel = (err2 / ref2).sqrt();
        assert!(rel < 0.12, "{norm:?}: relative L2 error {rel}");
    }
}

/// Random texture, right view shifted by a three-band disparity field.
pub(super) fn banded_pair(w: usize, h: usize) -> (RgbImage, RgbImage, impl Fn(usize) -> usize) {
    let field = move |x: usize| {
        if x < w / 3 {
            4
        } else if x < 2 * w / 3 {
            9
        } else {
            14
        }
    };
    let tex_l = rand_vec(w * h * 3, 21);
    let tex_r = rand_vec(w * h * 3, 77);
    let mut left = RgbImage::new(w, h);
    let mut right = RgbImage::new(w, h);
    for c in 0..3 {
        for i in 0..w * h {
            left.channels[c][i] = 255.0 * tex_l[i * 3 + c];
            right.channels[c][i] = 255.0 * tex_r[i * 3 + c];
        }
    }
    for y in 0..h {
        for x in 0..w {
            let d = field(x);
            if x >= d {
                for c in 0..3 {
                    right.channels[c][y * w + x - d] = left.channels[c][y * w + x];
                }
            }
        }
    }
    (left, right, field)
}

/// Every model recovers a piecewise-constant disparity field on a textured pair: at least 97% of the pixels
/// away from the image border and from the band edges (where occlusions make the answer ambiguous) get the
/// exact label.
#[test]
fn meanfield_models_recover_synthetic_disparity() {
    let (w, h, nd) = (90, 40, 18);
    let (left, right, field) = banded_pair(w, h);
    let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
    for (name, weights, schedule) in [
        ("lcm", PairwiseWeights { fcm: 0.0, lcm: 1.0 }, Schedule::Jacobi),
        ("fcm", PairwiseWeights { fcm: 30.0, lcm: 0.0 }, Schedule::Jacobi),
        ("jem", PairwiseWeights { fcm: 30.0, lcm: 1.0 }, Schedule::Jacobi),
        ("lcm checkerboard", PairwiseWeights { fcm: 0.0, lcm: 1.0 }, Schedule::Checkerboard),
        ("jem checkerboard", PairwiseWeights { fcm: 30.0, lcm: 1.0 }, Schedule::Checkerboard),
        ("lcm pyramid", PairwiseWeights { fcm: 0.0, lcm: 1.0 }, Schedule::Checkerboard),
        ("jem pyramid", PairwiseWeights { fcm: 30.0, lcm: 1.0 }, Schedule::Checkerboard),
    ] {
        let pyramid_levels = if name.ends_with("pyramid") { 2 } else { 1 };
        let p = MeanFieldParams { iterations: 5, schedule, pyramid_levels, ..MeanFieldParams::default() };
        let q = infer_mean_field(&cost, &left, &p, weights);
        let (disp, conf) = decode_marginals(&q, false);
        let (mut good, mut total) = (0, 0);
        for y in 4..h - 4 {
            for x in 20..w - 4 {
                if [w / 3, 2 * w / 3].iter().any(|&e| x + 16 > e && x < e + 4) {
                    continue;
                }
                total += 1;
                good += usize::from(disp.at(x, y) == field(x) as f32);
            }
        }
        let frac = good as f64 / total as f64;
        assert!(frac >= 0.97, "{name}: {good}/{total} exact");
        assert!(conf.data.iter().all(|c| (0.0..=1.0 + 1e-6).contains(c)));
    }
}

/// The red-black schedule against a slow reference: update every even pixel from the old marginals, then
/// every odd pixel from the new even ones, one pixel at a time, with the local term only.
#[test]
fn meanfield_checkerboard_matches_sequential_reference() {
    let (w, h, nd) = (13, 7, 6);
    let (left, right, _) = banded_pair(w, h);
    let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
    let p = MeanFieldParams { iterations: 2, schedule: Schedule::Checkerboard, ..MeanFieldParams::default() };
    let weights = PairwiseWeights { fcm: 0.0, lcm: 1.5 };
    let fast = infer_mean_field(&cost, &left, &p, weights);
    let local = local_weights(&left, &p);
    let mut q: Vec<f32> = cost.data.iter().map(|c| c * p.unary_scale).collect();
    q.chunks_exact_mut(nd).for_each(softmax_neg_in_place);
    for _ in 0..p.iterations {
        for parity in [0, 1] {
            let old = q.clone();
            for y in 0..h {
                for x in (0..w).filter(|x| (x + y) % 2 == parity) {
                    let i = y * w + x;
                    let mut nbrs = Vec::new();
                    if x > 0 {
                        nbrs.push((i - 1, local.right.data[i - 1]));
                    }
                    if x + 1 < w {
                        nbrs.push((i + 1, local.right.data[i]));
                    }
                    if y > 0 {
                        nbrs.push((i - w, local.down.data[i - w]));
                    }
                    if y + 1 < h {
                        nbrs.push((i + w, local.down.data[i]));
                    }
                    let mut e: Vec<f32> = (0..nd).map(|d| p.unary_scale * cost.data[i * nd + d]).collect();
                    for d in 0..nd {
                        // Naive O(M²) local energy, without the label-independent constant.
                        let mut s = 0.0;
                        for l in 0..nd {
                            let phi = match d.abs_diff(l) {
                                0 => 0.0,
                                1 => p.beta,
                                _ => 1.0,
                            };
                            let pt: f32 = nbrs.iter().map(|&(j, wt)| wt * old[j * nd + l]).sum();
                            s += (phi - 1.0) * pt;
                        }
                        e[d] += weights.lcm * s;
                    }
                    softmax_neg_in_place(&mut e);
                    q[i * nd..][..nd].copy_from_slice(&e);
                }
            }
        }
    }
    for (a, b) in fast.data.iter().zip(&q) {
        assert!((a - b).abs() < 1e-5, "{a} vs {b}");
    }
}

/// The in-place red-black update (one sweep per band, and two plain sweeps without bands) against the
/// two-buffer, two-sweep one, bit for bit, for several heights and bandings, with both pairwise terms.
#[test]
fn meanfield_in_place_checkerboard_matches_two_sweeps() {
    for (w, h) in [(9, 3), (8, 4), (11, 7), (10, 13)] {
        let (left, right, _) = banded_pair(w, h);
        let nd = 5;
        let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
        let p = MeanFieldParams { schedule: Schedule::Checkerboard, ..MeanFieldParams::default() };
        let weights = PairwiseWeights { fcm: 8.0, lcm: 1.5 };
        let reference = {
            let mut mf = MeanField::new(&cost, &left, &p, weights);
            mf.next = vec![0.0; mf.q.len()];
            for _ in 0..3 {
                let (mut q, mut next) = (std::mem::take(&mut mf.q), std::mem::take(&mut mf.next));
                let mut scratch = std::mem::take(&mut mf.scratch);
                let vals = mf.full.as_ref().unwrap().splat_blur(&q, None, nd, &mut scratch);
                mf.checkerboard_two_pass(&mut q, &mut next, vals);
                (mf.q, mf.next, mf.scratch) = (q, next, scratch);
            }
            mf.q
        };
        for count in 0..=h / 3 {
            let bands: Vec<(usize, usize)> = (0..count).map(|k| (k * h / count, (k + 1) * h / count)).collect();
            let mut mf = MeanField::new(&cost, &left, &p, weights);
            let mut edges = vec![0.0; 2 * count * w * nd];
            for _ in 0..3 {
                let mut q = std::mem::take(&mut mf.q);
                let mut scratch = std::mem::take(&mut mf.scratch);
                let vals = mf.full.as_ref().unwrap().splat_blur(&q, None, nd, &mut scratch);
                mf.checkerboard_in_place(&mut q, vals, &bands, &mut edges);
                (mf.q, mf.scratch) = (q, scratch);
            }
            assert!(mf.q.iter().zip(&reference).all(|(a, b)| a.to_bits() == b.to_bits()), "{w}x{h}, bands {bands:?}");
        }
    }
    assert!(checkerboard_bands(2, 4).is_empty());
    assert_eq!(checkerboard_bands(7, 4), vec![(0, 3), (3, 7)]);
}

#[test]
fn meanfield_marginals_are_distributions() {
    let (w, h, nd) = (30, 10, 8);
    let (left, right, _) = banded_pair(w, h);
    let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
    let q = infer_mean_field(&cost, &left, &MeanFieldParams::default(), PairwiseWeights { fcm: 30.0, lcm: 1.0 });
    for i in 0..w * h {
        let s: f32 = q.pixel(i).iter().sum();
        assert!((s - 1.0).abs() < 1e-4 && q.pixel(i).iter().all(|v| v.is_finite() && *v >= 0.0));
    }
}

#[test]
fn meanfield_zero_iterations_is_softmax_of_the_unary() {
    let (w, h, nd) = (20, 6, 5);
    let (left, right, _) = banded_pair(w, h);
    let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
    let p = MeanFieldParams { iterations: 0, ..MeanFieldParams::default() };
    let q = infer_mean_field(&cost, &left, &p, PairwiseWeights { fcm: 30.0, lcm: 1.0 });
    let (disp, _) = decode_marginals(&q, false);
    assert_eq!(disp, crate::cost::winner_take_all(&cost));
}

#[test]
fn meanfield_run_is_identical_with_1_and_2_threads() {
    let (w, h) = (64, 30);
    let (left, right, _) = banded_pair(w, h);
    let pair = crate::image::StereoPair::new(left, right, 16).unwrap();
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| crate::pipeline::run(&Params::default(), &pair).unwrap().disparity)
    };
    let (a, b) = (run(1), run(2));
    assert!(a.data.iter().zip(&b.data).all(|(x, y)| x.to_bits() == y.to_bits()));
}

/// Every pixel of a 5 × 3 level takes the marginal of its 2 × 2 block in the 3 × 2 coarse level.
#[test]
fn meanfield_from_coarse_copies_each_block() {
    let (w, h, m) = (5, 3, 4);
    let cost = random_cost(w, h, m, 3, 10.0);
    let coarse = random_cost(3, 2, m, 9, 1.0);
    let p = MeanFieldParams::default();
    let mf = MeanField::from_coarse(&cost, &RgbImage::new(w, h), &p, LCM_ONLY, Buffers::default(), &coarse);
    for y in 0..h {
        for x in 0..w {
            let (i, parent) = (y * w + x, (y / 2) * 3 + x / 2);
            assert_eq!(&mf.marginals()[i * m..][..m], coarse.pixel(parent), "pixel ({x}, {y})");
        }
    }
}

/// One level is the plain inference, bit for bit (the pyramid only adds levels in front of it).
#[test]
fn meanfield_one_level_pyramid_is_plain_inference() {
    let (w, h, m) = (23, 17, 9);
    let cost = random_cost(w, h, m, 5, 20.0);
    let (image, _, _) = banded_pair(w, h);
    let p = MeanFieldParams { iterations: 4, unary_scale_start: 0.1, ..MeanFieldParams::default() };
    let weights = PairwiseWeights { fcm: 5.0, lcm: 1.0 };
    let mut mf = MeanField::new(&cost, &image, &p, weights);
    (0..p.iterations).for_each(|_| mf.step());
    let plain = mf.into_marginals();
    let (pyr, _) = infer_coarse_to_fine(&cost, &image, &p, weights, Buffers::default());
    assert!(plain.data.iter().zip(&pyr.data).all(|(a, b)| a.to_bits() == b.to_bits()));
}

/// What the pyramid is for: weak evidence under strong noise. Every pixel's cost is uniform noise in 0..6 plus
/// 1 for every label but the true one (5 of 8), so the true label wins the winner-take-all at few pixels;
/// the local term has to pool evidence over a large neighbourhood. The same number of iterations pools more
/// when it starts on a grid reduced 4 times (a 4 × 4 block mean already averages 16 pixels' noise).
#[test]
fn meanfield_pyramid_pools_weak_evidence() {
    let (w, h, m) = (64, 32, 8);
    let noise = rand_vec(w * h * m, 41);
    let data = noise.iter().enumerate().map(|(k, v)| 6.0 * v + if k % m == 5 { 0.0 } else { 1.0 }).collect();
    let cost = CostVolume { width: w, height: h, ndisp: m, data };
    let image = RgbImage::new(w, h);
    let exact = |disp: &Plane<f32>| disp.data.iter().filter(|&&d| d == 5.0).count() as f64 / (w * h) as f64;
    let wta = exact(&crate::cost::winner_take_all(&cost));
    let exact_after = |levels| {
        let p = MeanFieldParams {
            iterations: 4,
            pyramid_levels: levels,
            pyramid_iterations: 4,
            ..MeanFieldParams::default()
        };
        let q = infer_mean_field(&cost, &image, &p, PairwiseWeights { fcm: 0.0, lcm: 0.5 });
        exact(&decode_marginals(&q, false).0)
    };
    let (plain, pyramid) = (exact_after(1), exact_after(3));
    // Measured: WTA 0.29, plain 0.70, three levels 0.88.
    assert!(wta < 0.4, "the evidence is not weak: WTA already gets {wta:.2}");
    assert!(plain < 0.8 && pyramid > 0.85, "plain {plain:.3}, coarse to fine {pyramid:.3}");
}

/// Cold marginals (costs spread over 0..400 at unary scale 1) keep no subnormal float, neither in Q nor in the
/// fully connected message built from it (the lattice multiplies Q by weights below 1 many times), and the
/// floor costs nothing that matters: every probability removed was below 1e−20 of its pixel's maximum.
#[test]
fn meanfield_cold_marginals_hold_no_subnormal_floats() {
    let (w, h, m) = (40, 24, 30);
    let cost = random_cost(w, h, m, 17, 400.0);
    let (image, _, _) = banded_pair(w, h);
    let p = MeanFieldParams { unary_scale: 1.0, ..MeanFieldParams::default() };
    let mut mf = MeanField::new(&cost, &image, &p, PairwiseWeights { fcm: 30.0, lcm: 1.0 });
    let zeros_at_start = mf.marginals().iter().filter(|&&v| v == 0.0).count();
    assert!(zeros_at_start > 0, "the test needs labels below the floor");
    for q in mf.marginals().chunks_exact(m) {
        let max = q.iter().copied().fold(0.0f32, f32::max);
        assert!(q.iter().all(|&v| v == 0.0 || v >= max * MIN_RELATIVE_PROBABILITY * 0.99));
    }
    for _ in 0..3 {
        mf.step();
        assert!(mf.marginals().iter().all(|v| *v == 0.0 || v.is_normal()), "subnormal marginal");
    }
    assert!(mf.fcm_message().iter().all(|v| *v == 0.0 || v.is_normal()), "subnormal message");
}

const LCM_ONLY: PairwiseWeights = PairwiseWeights { fcm: 0.0, lcm: 1.0 };

/// Random label bands for a `w × h` view of `m` labels, a fifth of them all labels.
pub(super) fn random_bands(w: usize, h: usize, m: usize, seed: u64) -> LabelBands {
    let r = rand_vec(2 * w * h, seed);
    let centre = Plane::from_parts(w, h, (0..w * h).map(|i| (r[2 * i] * m as f32).floor()).collect());
    let best = Plane::from_parts(
        w,
        h,
        (0..w * h).map(|i| if i % 5 == 0 { f32::INFINITY } else { (r[2 * i + 1] * m as f32).floor() }).collect(),
    );
    // Reach 0, half width 1, joined with the own best label ± 0: from two labels to all of them.
    LabelBands::around((&centre, &centre), &best, m, 0, 1.0, 0)
}

/// Label bands of all labels are the dense run, bit for bit, with either schedule.
#[test]
fn meanfield_full_label_bands_are_the_dense_run() {
    let (w, h, m) = (21, 13, 9);
    let cost = random_cost(w, h, m, 21, 20.0);
    let (image, _, _) = banded_pair(w, h);
    let weights = PairwiseWeights { fcm: 6.0, lcm: 1.5 };
    for schedule in [Schedule::Checkerboard, Schedule::Jacobi] {
        let p = MeanFieldParams { schedule, ..MeanFieldParams::default() };
        let mut dense = MeanField::new(&cost, &image, &p, weights);
        let full = LabelBands::full(w, h, m);
        let mut banded = MeanField::in_label_bands(&cost, &image, &p, weights, Buffers::default(), full);
        for _ in 0..3 {
            dense.step();
            banded.step();
        }
        let same = dense.marginals().iter().zip(banded.marginals().iter()).all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same, "{schedule:?}");
    }
}

/// Inference in label bands is the dense inference with every label outside a pixel's band made impossible (a
/// cost so high that its probability is below the floor, so exactly 0): the same marginals up to the rounding of
/// the softmax's sums (over the band, not over all labels), and exactly 0 outside the bands. Reused buffers
/// holding other values do not leak into the bands' zeros.
#[test]
fn meanfield_label_bands_are_dense_inference_with_the_rest_forbidden() {
    let (w, h, m) = (24, 15, 12);
    let cost = random_cost(w, h, m, 22, 20.0);
    let (image, _, _) = banded_pair(w, h);
    let bands = random_bands(w, h, m, 23);
    let mut forbidden = cost.clone();
    for (i, costs) in forbidden.data.chunks_exact_mut(m).enumerate() {
        let (lo, hi) = bands.of(i);
        costs.iter_mut().enumerate().filter(|(d, _)| *d < lo || *d >= hi).for_each(|(_, c)| *c += 1e4);
    }
    let weights = PairwiseWeights { fcm: 6.0, lcm: 1.5 };
    for schedule in [Schedule::Checkerboard, Schedule::Jacobi] {
        let p = MeanFieldParams { schedule, ..MeanFieldParams::default() };
        let mut dense = MeanField::new(&forbidden, &image, &p, weights);
        let mut stale = Buffers::default();
        stale.recycle(vec![0.5; w * h * m]);
        stale.next = vec![0.25; if schedule == Schedule::Jacobi { w * h * m } else { 0 }];
        let mut banded = MeanField::in_label_bands(&cost, &image, &p, weights, stale, bands.clone());
        for _ in 0..3 {
            dense.step();
            banded.step();
        }
        for (i, (a, b)) in dense.marginals().chunks_exact(m).zip(banded.marginals().chunks_exact(m)).enumerate() {
            let (lo, hi) = bands.of(i);
            for d in 0..m {
                if d < lo || d >= hi {
                    assert!(a[d] == 0.0 && b[d] == 0.0, "{schedule:?}: pixel {i}, label {d} outside its band");
                } else {
                    assert!((a[d] - b[d]).abs() < 1e-5, "{schedule:?}: pixel {i}, label {d}: {} vs {}", a[d], b[d]);
                }
            }
        }
    }
}

/// A `w × h × m` cost volume of uniform random costs in `[0, scale)`.
pub(super) fn random_cost(w: usize, h: usize, m: usize, seed: u64, scale: f32) -> CostVolume {
    CostVolume { width: w, height: h, ndisp: m, data: rand_vec(w * h * m, seed).iter().map(|v| v * scale).collect() }
}

/// With annealing the initial marginals are the softmax of the starting scale, each iteration uses the next
/// scale of the schedule (checked against a Jacobi run built from scratch with that scale), and without it
/// the output is bit for bit the plain run's.
#[test]
fn meanfield_annealing_applies_the_schedule_per_iteration() {
    let (w, h, nd) = (24, 9, 7);
    let (left, right, _) = banded_pair(w, h);
    let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
    let weights = PairwiseWeights { fcm: 0.0, lcm: 1.5 };
    let plain = MeanFieldParams { iterations: 3, unary_scale: 0.2, schedule: Schedule::Jacobi, ..Default::default() };
    let annealed = MeanFieldParams { unary_scale_start: 0.05, ..plain.clone() };
    let schedule = UnarySchedule::new(&annealed);
    // Reference: one Jacobi step from the given marginals with a fixed scale.
    let jacobi_step = |q: &[f32], scale: f32| -> Vec<f32> {
        let p = MeanFieldParams { iterations: 1, unary_scale: scale, ..plain.clone() };
        let mut mf = MeanField::new(&cost, &left, &p, weights);
        mf.q.copy_from_slice(q);
        mf.step();
        mf.q
    };
    let mut mf = MeanField::new(&cost, &left, &annealed, weights);
    let mut reference: Vec<f32> = cost.data.iter().map(|c| c * 0.05).collect();
    reference.chunks_exact_mut(nd).for_each(softmax_neg_in_place);
    assert!(mf.marginals().iter().zip(&reference).all(|(a, b)| a.to_bits() == b.to_bits()));
    for t in 1..=3 {
        mf.step();
        reference = jacobi_step(&reference, schedule.at(t));
        assert!(mf.marginals().iter().zip(&reference).all(|(a, b)| a.to_bits() == b.to_bits()), "step {t}");
    }
    let off = MeanFieldParams { unary_scale_start: 0.0, ..annealed };
    let a = infer_mean_field(&cost, &left, &off, weights);
    let b = infer_mean_field(&cost, &left, &plain, weights);
    assert!(a.data.iter().zip(&b.data).all(|(x, y)| x.to_bits() == y.to_bits()));
}

/// Spare buffers: the smallest that holds the length asked for, else the largest (grown); at most `MAX_SPARE` kept.
#[test]
fn buffers_hand_out_the_best_fitting_spare() {
    let mut b = Buffers::default();
    for len in [10, 40, 20] {
        b.recycle(vec![0.0; len]);
    }
    assert_eq!(b.take(15).capacity(), 20, "the smallest that holds 15");
    assert_eq!(b.take(50).len(), 50, "none holds 50: the largest, grown");
    assert_eq!(b.take(5).capacity(), 10);
    assert_eq!(b.take(5).capacity(), 5, "none left: a fresh one");
    for len in 1..=super::MAX_SPARE + 2 {
        b.recycle(vec![0.0; len]);
    }
    assert_eq!(b.take(1).capacity(), 3, "the smallest were freed beyond MAX_SPARE");
}

/// Trimming keeps the largest spares that fit the total, and frees the rest and the lattice's buffers.
#[test]
fn buffers_trim_to_a_total() {
    let mut b = Buffers::default();
    for len in [10, 40, 20] {
        b.recycle(vec![0.0; len]);
    }
    b.next = vec![0.0; 8];
    b.trim(65);
    assert!(b.next.is_empty());
    let mut kept: Vec<usize> = b.spare.iter().map(Vec::capacity).collect();
    kept.sort_unstable();
    assert_eq!(kept, vec![20, 40], "40 and 20 fit 65, 10 more does not");
    b.trim(30);
    assert!(b.spare.is_empty(), "40 alone is over 30, and trimming keeps the largest first");
}

/// Settled pixels keep their marginals through later steps, with either schedule, in or out of label bands, while
/// the others still change; a confidence above 1 settles none and leaves the run bit for bit as it was; the result
/// is the same with 1 and 3 threads.
#[test]
fn meanfield_settled_pixels_keep_their_marginals() {
    let (w, h, nd) = (40, 17, 9);
    let (left, right, _) = banded_pair(w, h);
    let cost = crate::cost::build_cost_volume(&left, &right, nd, &CostParams::default());
    let weights = PairwiseWeights { fcm: 8.0, lcm: 1.5 };
    for schedule in [Schedule::Checkerboard, Schedule::Jacobi] {
        for banded in [false, true] {
            let p = MeanFieldParams { schedule, ..MeanFieldParams::default() };
            let make = || match banded {
                false => MeanField::new(&cost, &left, &p, weights),
                true => {
                    let bands = random_bands(w, h, nd, 7);
                    MeanField::in_label_bands(&cost, &left, &p, weights, Buffers::default(), bands)
                }
            };
            let run = |confidence: Option<f32>, threads: usize| {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                pool.install(|| {
                    let mut mf = make();
                    mf.step();
                    let settled = confidence.map_or(0, |c| mf.settle(c));
                    let before = mf.marginals().into_owned();
                    let flags = mf.settled.clone();
                    mf.step();
                    mf.step();
                    (before, flags, settled, mf.marginals().into_owned())
                })
            };
            let (_, _, none, plain) = run(None, 2);
            let (_, _, above_one, same) = run(Some(1.5), 2);
            assert_eq!((none, above_one), (0, 0));
            assert!(plain.iter().zip(&same).all(|(a, b)| a.to_bits() == b.to_bits()), "{schedule:?} {banded}");
            let (before, flags, settled, q) = run(Some(0.6), 2);
            assert!(settled > 0 && settled < w * h, "{schedule:?} {banded}: {settled} settled");
            for (i, &s) in flags.iter().enumerate() {
                let (a, b) = (&before[i * nd..][..nd], &q[i * nd..][..nd]);
                let top = a.iter().fold(0.0f32, |t, &v| t.max(v));
                assert_eq!(s, top >= 0.6, "pixel {i}");
                if s {
                    assert!(a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()), "settled pixel {i} moved");
                }
            }
            assert!(flags.iter().zip(q.chunks(nd)).zip(plain.chunks(nd)).any(|((&s, a), b)| !s && a != b));
            let (_, _, _, one_thread) = run(Some(0.6), 1);
            let (_, _, _, three) = run(Some(0.6), 3);
            assert!(one_thread.iter().zip(&three).all(|(a, b)| a.to_bits() == b.to_bits()));
            assert!(one_thread.iter().zip(&q).all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }
}
