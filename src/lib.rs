//! # jem — stereo matching by joint energy minimization
//!
//! An implementation of Xue & Cai, "Stereo Matching by Joint Energy Minimization": a Census + gradient cost
//! volume, mean-field inference on an MRF that joins a fully connected Potts term (bilateral kernel, filtered
//! with a permutohedral lattice) and a 4-neighbour local term, then left-right check, occlusion fill, weighted
//! median and slanted-plane smoothing.
//!
//! The whole pipeline is one call, [`run`]; each stage is a free function in its own module:
//!
//! ```text
//! cost::build_cost_volume ─► meanfield::infer_mean_field (left and right views) ─► post::lr_check
//!   ─► post::fill ─► post::wmedian ─► post::planes
//! ```
//!
//! ```
//! use jem::{Params, StereoPair, image::RgbImage};
//! let (left, right) = (RgbImage::new(32, 16), RgbImage::new(32, 16));
//! let pair = StereoPair::new(left, right, 8).unwrap();
//! let mut params = Params::default();
//! params.model = jem::Model::Wta;
//! let out = jem::run(&params, &pair).unwrap();
//! assert_eq!(out.disparity.dims(), (32, 16));
//! ```
#![deny(missing_docs)]

pub mod batch;
pub mod cost;
pub mod error;
pub mod eval;
pub mod fastmath;
pub mod image;
pub mod io;
pub mod lattice;
pub mod meanfield;
pub mod params;
pub mod post;
pub mod synth;
pub mod viz;

use std::time::{Duration, Instant};

pub use error::{Error, Result};
pub use image::{CostVolume, DisparityMap, Plane, RgbImage, StereoPair};
pub use params::{LrcMode, Model, Params};

/// Wall-clock time spent in each stage, in pipeline order.
#[derive(Clone, Debug, Default)]
pub struct Timings {
    /// (stage name, duration) pairs.
    pub stages: Vec<(&'static str, Duration)>,
}

impl Timings {
    /// Runs `f`, recording its duration under `name`.
    pub fn time<T>(&mut self, name: &'static str, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        self.stages.push((name, start.elapsed()));
        out
    }

    /// Sum of all stages.
    pub fn total(&self) -> Duration {
        self.stages.iter().map(|(_, d)| *d).sum()
    }
}

/// What a run produces.
#[derive(Clone, Debug)]
pub struct Output {
    /// The left view's disparity map (`inf` = invalid, when post-processing leaves holes).
    pub disparity: DisparityMap,
    /// Per-pixel confidence of the left view before post-processing: the max-marginal (mean-field models) or
    /// 1 (WTA).
    pub confidence: Plane<f32>,
    /// Time per stage.
    pub timings: Timings,
}

/// Estimated peak memory of [`run`] in bytes for a `width × height` pair with `ndisp` labels.
///
/// N = pixels, M = labels. Alive at the peak: one cost volume (4NM), one view's marginals, next marginals and
/// fully connected message (12NM), the lattice's two vertex buffers (2·V·M·4 with V ≤ N vertices, ~0.4N on
/// natural images), the images and per-pixel lattice tables (~300 bytes per pixel).
pub fn estimate_memory_bytes(width: usize, height: usize, ndisp: usize, params: &Params) -> u64 {
    let (n, m) = (width as u64 * height as u64, ndisp as u64);
    let volume = 4 * n * m;
    let inference = match params.model {
        Model::Wta => 0,
        Model::Lcm => 2 * volume,
        Model::Fcm | Model::Jem => 3 * volume + 2 * volume,
    };
    let two_volumes = if params.post.lrc.mode == LrcMode::Off { volume } else { 2 * volume };
    (volume + inference).max(two_volumes) + 300 * n
}

/// Fails fast, before anything large is allocated, when a run would need more than `limit_bytes`.
///
/// # Errors
/// [`Error::OutOfMemory`] with the estimate, the limit and what to do about it.
pub fn check_memory(width: usize, height: usize, ndisp: usize, params: &Params, limit_bytes: u64) -> Result<()> {
    let needed = estimate_memory_bytes(width, height, ndisp, params);
    if needed <= limit_bytes {
        return Ok(());
    }
    Err(Error::OutOfMemory {
        needed,
        limit: limit_bytes,
        hint: format!(
            "{width}x{height} with ndisp {ndisp} is too large; use smaller images (e.g. half resolution) or a \
             smaller ndisp, or raise --max-memory if the machine has the memory"
        ),
    })
}

/// A default memory limit: 80% of the machine's physical memory (from `/proc/meminfo`), or 8 GiB where that
/// cannot be read.
pub fn default_memory_limit() -> u64 {
    let total_kib = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        s.lines().find(|l| l.starts_with("MemTotal:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
    });
    total_kib.map(|k| k * 1024 / 5 * 4).unwrap_or(8 << 30)
}

/// Disparity and confidence of one view.
struct ViewEstimate {
    disparity: DisparityMap,
    confidence: Plane<f32>,
}

/// Runs the whole pipeline on a pair.
///
/// # Errors
/// [`Error::InvalidParam`] if `params` does not validate.
pub fn run(params: &Params, pair: &StereoPair) -> Result<Output> {
    run_observed(params, pair, &|_| {})
}

/// Like [`run`], calling `on_stage(name)` as each stage starts (for progress display).
///
/// # Errors
/// [`Error::InvalidParam`] if `params` does not validate.
pub fn run_observed(params: &Params, pair: &StereoPair, on_stage: &dyn Fn(&str)) -> Result<Output> {
    params.validate()?;
    let mf = &params.meanfield;
    if params.effective_fcm_weight() > 0.0
        && !lattice::features_fit(pair.left.width, pair.left.height, mf.sigma_xy, mf.sigma_rgb)
    {
        return Err(Error::param(
            "meanfield.sigma_xy / meanfield.sigma_rgb",
            format!("{} / {}", mf.sigma_xy, mf.sigma_rgb),
            format!(
                "image size / sigma_xy and 255 / sigma_rgb at most {} (the image is {}x{})",
                lattice::MAX_FEATURE,
                pair.left.width,
                pair.left.height
            ),
        ));
    }
    let mut t = Timings::default();
    let post = &params.post;
    let need_right = post.lrc.mode != LrcMode::Off;

    on_stage("cost volume");
    let cost_left = t.time("cost", || cost::build_cost_volume(&pair.left, &pair.right, pair.ndisp, &params.cost));

    // Left inference first, then the right volume from the left one; the left volume is spent before the right
    // inference: at most one volume plus one view's inference buffers are alive at a time (three N × M buffers
    // in all, plus the lattice's).
    on_stage("inference (left)");
    let mut buffers = meanfield::Buffers::default();
    let left = estimate_view(params, &pair.left, &cost_left, &mut t, &mut buffers);
    let right = if need_right {
        // The right volume goes into the left view's spent marginals, and the left volume's storage becomes the
        // right view's marginals: no new allocation (nor page faults) for the right view.
        let spare = buffers.take_spare();
        let cost_right = t.time("cost right", || {
            cost::derive_right_volume_in(&cost_left, cost::truncation_cost(&params.cost), spare)
        });
        buffers.recycle(cost_left.data);
        on_stage("inference (right)");
        Some(estimate_view(params, &pair.right, &cost_right, &mut t, &mut buffers))
    } else {
        None
    };

    on_stage("post-processing");
    let mut disparity = left.disparity;
    let mut trusted = Plane::new(disparity.width, disparity.height, true);
    if let Some(right) = &right {
        let (checked, mask) = t.time("lrc", || {
            post::lr_check::left_right_check(&disparity, &right.disparity, post.lrc.mode, post.lrc.thresh_px)
        });
        disparity = checked;
        trusted = mask;
    }
    if post.fill {
        t.time("fill", || post::fill::fill_occlusions_in_place(&mut disparity));
    }
    if post.wmedian.enabled {
        let targets = Plane::from_vec(trusted.width, trusted.height, trusted.data.iter().map(|ok| !ok).collect());
        disparity =
            t.time("wmedian", || post::wmedian::weighted_median(&disparity, &pair.left, &targets, &post.wmedian));
    }
    if post.sps.enabled {
        disparity = t.time("sps", || post::planes::fit_slanted_planes(&pair.left, &disparity, &trusted, &post.sps));
    }
    Ok(Output { disparity, confidence: left.confidence, timings: t })
}

/// Inference for one view: WTA on the cost, or mean field with the view's own image.
/// `buffers` carries the large allocations from one view to the next.
fn estimate_view(
    params: &Params,
    image: &RgbImage,
    cost: &CostVolume,
    t: &mut Timings,
    buffers: &mut meanfield::Buffers,
) -> ViewEstimate {
    match params.model {
        Model::Wta => {
            let disparity = t.time("wta", || cost::winner_take_all(cost));
            let confidence = Plane::new(cost.width, cost.height, 1.0);
            ViewEstimate { disparity, confidence }
        }
        Model::Lcm | Model::Fcm | Model::Jem => {
            let weights =
                meanfield::PairwiseWeights { fcm: params.effective_fcm_weight(), lcm: params.effective_lcm_weight() };
            let reuse = std::mem::take(buffers);
            let mut mf = t.time("mf setup", || {
                meanfield::MeanField::with_buffers(cost, image, &params.meanfield, weights, reuse)
            });
            t.time("mf iterations", || (0..params.meanfield.iterations).for_each(|_| mf.step()));
            let (q, rest) = mf.into_marginals_and_buffers();
            let (disparity, confidence) =
                t.time("decode", || meanfield::decode_marginals(&q, params.meanfield.subpixel));
            *buffers = rest;
            buffers.recycle(q.data);
            ViewEstimate { disparity, confidence }
        }
    }
}

/// Helpers shared by the unit tests.
#[cfg(test)]
pub(crate) mod test_util {
    /// Seeded xorshift noise in 0..1: reproducible test inputs without a random-number crate.
    pub(crate) fn rand_vec(n: usize, seed: u64) -> Vec<f32> {
        let mut s = seed.max(1);
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_estimate_scales_with_pixels_and_labels() {
        let p = Params::default();
        // Vintage at quarter resolution: 720x480 (about), ndisp 190: well under 2 GB, over 1 GB.
        let vintage = estimate_memory_bytes(720, 480, 190, &p);
        assert!(vintage > 1 << 30 && vintage < 2 << 30, "{vintage}");
        assert_eq!(estimate_memory_bytes(200, 100, 10, &p) * 4, estimate_memory_bytes(400, 200, 10, &p));
        let wta = Params { model: Model::Wta, ..Params::default() };
        assert!(estimate_memory_bytes(720, 480, 190, &wta) < vintage / 2);
    }

    #[test]
    fn tiny_sigmas_are_an_error_not_a_panic() {
        let img = RgbImage::new(64, 8);
        let pair = StereoPair::new(img.clone(), img, 4).unwrap();
        let mut p = Params::default();
        p.meanfield.sigma_xy = 0.01;
        let e = run(&p, &pair).unwrap_err().to_string();
        assert!(e.contains("sigma_xy") && e.contains("64x8"), "{e}");
        p.meanfield.sigma_xy = 5.0;
        p.meanfield.sigma_rgb = 0.1;
        assert!(run(&p, &pair).is_err());
        p.meanfield.sigma_rgb = 55.0;
        assert!(run(&p, &pair).is_ok());
    }

    #[test]
    fn memory_guard_refuses_before_allocating() {
        let p = Params::default();
        // Full resolution 2880x1988 at ndisp 760 would need ~100 GB: refused at once with the numbers.
        let e = check_memory(2880, 1988, 760, &p, 24 << 30).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("needs about") && msg.contains("GiB") && msg.contains("2880x1988"), "{msg}");
        check_memory(450, 375, 64, &p, 24 << 30).unwrap();
    }
}
