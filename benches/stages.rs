//! Per-stage benchmarks on a real quarter-resolution scene (Motorcycle, 741×497, ndisp 70) when the Middlebury
//! data is present (`$JEM_DATA`, default `../shared/middlebury`), else on the shipped synthetic example.
//!
//! `cargo bench --bench stages` runs them all; `cargo bench --bench stages -- lattice` one group.
//!
//! Each kernel reports its throughput: cells per second for the stages over the cost volume's N × M cells (pixels ×
//! labels; the lattice's per pixel × channel), pixels per second for the post-processing. The `machine` group
//! measures what the roofline of docs/RESULTS.md compares them with: the memory bandwidth of a large copy and the
//! rate of independent f32 multiply-adds on data in L1, as the kernels are compiled (AVX2, no FMA contraction).

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use jem::Params;
use jem::internals::lattice::{Lattice, LatticeScratch};
use jem::internals::meanfield::{MeanField, PairwiseWeights};
use jem::internals::{StereoPair, cost, post};

/// The benchmark scene: (name, pair).
fn scene() -> (String, StereoPair<'static>) {
    let data = std::env::var_os("JEM_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/middlebury"));
    let moto = data.join("MiddEval3/trainingQ/Motorcycle");
    let (dir, name) = if moto.is_dir() {
        (moto, "Motorcycle Q")
    } else {
        eprintln!("note: Middlebury data not found; benchmarking the synthetic example instead");
        (Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/synth"), "synth")
    };
    let (left, right) = jem::io::read_image_pair(&dir.join("im0.png"), &dir.join("im1.png")).expect("images");
    let ndisp = jem::io::calib::read_ndisp(&dir.join("calib.txt")).expect("calib.txt");
    let pair = StereoPair::new(left, right, ndisp).expect("valid pair");
    (format!("{name} {}x{} nd{}", pair.left().width(), pair.left().height(), ndisp), pair)
}

/// Memory bandwidth and arithmetic rate of this machine, for the roofline.
fn machine(c: &mut Criterion) {
    let mut g = c.benchmark_group("machine");
    g.sample_size(10);
    // A copy of 256 MiB (read 256, write 256: the write-allocate read of the destination comes on top), far above
    // any cache, in parallel as the kernels run.
    let len = 64 << 20;
    let src = vec![1.0f32; len];
    let mut dst = vec![0.0f32; len];
    g.throughput(Throughput::Bytes(2 * 4 * len as u64));
    g.bench_function("copy 256 MiB (bytes read + written)", |b| {
        b.iter(|| {
            use rayon::prelude::*;
            dst.par_chunks_mut(1 << 16).zip(src.par_chunks(1 << 16)).for_each(|(d, s)| d.copy_from_slice(s));
            black_box(&dst);
        })
    });
    // Multiply-adds on 4 KiB in L1, 16 independent chains per pass: the arithmetic peak the vectorised kernels
    // can reach (2 FLOPs per element per pass).
    let x = vec![0.999f32; 1024];
    let mut acc = vec![0.0f32; 1024];
    const PASSES: usize = 1000;
    g.throughput(Throughput::Elements((2 * x.len() * PASSES) as u64));
    g.bench_function("f32 multiply-add in L1, one thread (FLOPs)", |b| {
        b.iter(|| {
            for _ in 0..PASSES {
                multiply_add(&mut acc, &x);
            }
            black_box(&acc);
        })
    });
    g.finish();
}

/// `acc = acc · x + x`, compiled for AVX2 + FMA as the kernels are (without contraction: a multiply and an add).
#[multiversion::multiversion(targets("x86_64+avx2+fma"))]
fn multiply_add(acc: &mut [f32], x: &[f32]) {
    for (a, v) in acc.iter_mut().zip(x) {
        *a = *a * v + v;
    }
}

fn stages(c: &mut Criterion) {
    let (name, pair) = scene();
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/default.toml");
    let params = Params::load(Some(&config), &[]).expect("configs/default.toml");
    let mf = &params.meanfield;

    let (pixels, labels) = (pair.left().len() as u64, pair.ndisp() as u64);
    let mut g = c.benchmark_group("cost");
    g.throughput(Throughput::Elements(2 * pixels * labels));
    // As in the pipeline: the left volume in fresh memory, the right one in a spare buffer of the same size (the
    // left view's spent marginals there).
    let mut spare = vec![0.0f32; pair.left().len() * pair.ndisp()];
    g.bench_function(BenchmarkId::new("both views", &name), |b| {
        b.iter(|| {
            let left = cost::build_cost_volume(pair.left(), pair.right(), pair.ndisp(), &params.cost);
            let right =
                cost::derive_right_volume_in(&left, cost::truncation_cost(&params.cost), std::mem::take(&mut spare));
            black_box(&left);
            spare = right.into_data();
        })
    });
    g.finish();

    let mut g = c.benchmark_group("lattice");
    g.throughput(Throughput::Elements(pixels));
    g.bench_function(BenchmarkId::new("build", &name), |b| {
        b.iter(|| black_box(Lattice::build(pair.left(), mf.sigma_xy, mf.sigma_rgb)))
    });
    let lattice = Lattice::build(pair.left(), mf.sigma_xy, mf.sigma_rgb);
    let n = pair.left().len();
    for channels in [1, pair.ndisp()] {
        g.throughput(Throughput::Elements(pixels * channels as u64));
        let input: Vec<f32> = (0..n * channels).map(|i| (i % 97) as f32 / 97.0).collect();
        let mut output = vec![0.0; input.len()];
        let mut scratch = LatticeScratch::default();
        g.bench_function(BenchmarkId::new(format!("filter {channels} channels"), &name), |b| {
            b.iter(|| lattice.filter(black_box(&input), &mut output, channels, &mut scratch))
        });
        g.bench_function(BenchmarkId::new(format!("splat + blur {channels} channels"), &name), |b| {
            b.iter(|| black_box(lattice.splat_blur(black_box(&input), None, None, channels, &mut scratch).len()))
        });
    }
    g.finish();

    let cost_left = cost::build_cost_volume(pair.left(), pair.right(), pair.ndisp(), &params.cost);
    let mut g = c.benchmark_group("meanfield");
    g.sample_size(10).measurement_time(Duration::from_secs(8)).throughput(Throughput::Elements(pixels * labels));
    let weights = PairwiseWeights { fcm: params.effective_fcm_weight(), lcm: params.effective_lcm_weight() };
    g.bench_function(BenchmarkId::new("setup (lattice + init)", &name), |b| {
        b.iter(|| black_box(MeanField::new(&cost_left, pair.left(), mf, weights)))
    });
    let mut state = MeanField::new(&cost_left, pair.left(), mf, weights);
    g.bench_function(BenchmarkId::new("one JEM iteration", &name), |b| b.iter(|| state.step()));
    g.finish();

    // Post-processing on real inference output for both views.
    let mut g = c.benchmark_group("post");
    g.throughput(Throughput::Elements(pixels));
    let infer = |image: &jem::RgbImage, cost: &jem::internals::CostVolume| {
        jem::internals::meanfield::decode_marginals(
            &jem::internals::meanfield::infer_mean_field(cost, image, mf, weights),
            true,
        )
        .0
    };
    let dl = infer(pair.left(), &cost_left);
    let cost_right = cost::derive_right_volume(&cost_left, cost::truncation_cost(&params.cost));
    let dr = infer(pair.right(), &cost_right);
    drop((cost_left, cost_right));
    g.bench_function(BenchmarkId::new("lrc + fill", &name), |b| {
        b.iter(|| {
            let (mut d, mask) = post::lr_check::left_right_check(&dl, &dr, jem::LrcMode::Invalidate, 1.0);
            post::fill::fill_occlusions_in_place(&mut d);
            black_box((d, mask))
        })
    });
    let (mut filled, trusted) = post::lr_check::left_right_check(&dl, &dr, jem::LrcMode::Invalidate, 1.0);
    post::fill::fill_occlusions_in_place(&mut filled);
    let targets =
        jem::Plane::from_vec(trusted.width(), trusted.height(), trusted.data().iter().map(|ok| !ok).collect()).unwrap();
    let share = 100.0 * targets.data().iter().filter(|t| **t).count() as f64 / targets.data().len() as f64;
    let mut wm = params.post.wmedian.clone();
    wm.enabled = true;
    g.bench_function(BenchmarkId::new(format!("weighted median ({share:.1}% targets)"), &name), |b| {
        b.iter(|| black_box(post::wmedian::weighted_median(&filled, pair.left(), &targets, &wm)))
    });
    let median = post::wmedian::weighted_median(&filled, pair.left(), &targets, &wm);
    let mut sps = params.post.sps.clone();
    sps.enabled = true;
    g.sample_size(10);
    g.bench_function(BenchmarkId::new("slanted planes", &name), |b| {
        b.iter(|| black_box(post::planes::fit_slanted_planes(pair.left(), &median, &trusted, &sps)))
    });
    // The second median, after the planes: at depth edges and the rejected pixels, with its own window and weight.
    let planes = post::planes::fit_slanted_planes(pair.left(), &median, &trusted, &sps);
    let edges = post::wmedian::edge_targets(&planes, wm.edge_px, wm.edge_band, &trusted);
    let share = 100.0 * edges.data().iter().filter(|t| **t).count() as f64 / edges.data().len() as f64;
    let second = wm.second_run(0.0);
    g.sample_size(20);
    g.bench_function(BenchmarkId::new(format!("median at edges ({share:.1}% targets)"), &name), |b| {
        b.iter(|| black_box(post::wmedian::weighted_median(&planes, pair.left(), &edges, &second)))
    });
    // The sub-pixel refinement of the final map, on the views themselves (the pipeline passes the cost pair).
    let last = post::wmedian::weighted_median(&planes, pair.left(), &edges, &second);
    let refine = &params.post.subpixel;
    g.bench_function(BenchmarkId::new("sub-pixel refinement", &name), |b| {
        b.iter(|| black_box(post::subpixel::refine_subpixel(pair.left(), pair.right(), &last, 0, refine)))
    });
    g.finish();

    let mut g = c.benchmark_group("end-to-end");
    g.sample_size(10).measurement_time(Duration::from_secs(20)).throughput(Throughput::Elements(pixels));
    g.bench_function(BenchmarkId::new("default.toml", &name), |b| {
        b.iter(|| black_box(jem::internals::run(&params, &pair).expect("pipeline")))
    });
    // The tiled path of large pairs (jem::tile) on the same pair: a coarse level at 1/4 and 256-px cores, to
    // compare with the run in one piece.
    let plan =
        jem::internals::TilePlan { coarse_factor: 4, core_px: 256, tile_budget_bytes: u64::MAX, split_for_work: false };
    g.bench_function(BenchmarkId::new("default.toml in 256-px tiles", &name), |b| {
        b.iter(|| {
            black_box(
                jem::internals::run_tiled(&params, &pair, &plan, &jem::internals::RunOptions::quiet())
                    .expect("tiled pipeline"),
            )
        })
    });
    g.finish();
}

criterion_group!(benches, machine, stages);
criterion_main!(benches);
