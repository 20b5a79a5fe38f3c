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
    let mut t = Timings::default();
    let post = &params.post;
    let need_right = post.lrc.mode != LrcMode::Off;

    on_stage("cost volume");
    let cost_left = t.time("cost", || cost::build_cost_volume(&pair.left, &pair.right, pair.ndisp, &params.cost));
    let cost_right = need_right
        .then(|| t.time("cost right", || cost::derive_right_volume(&cost_left, cost::truncation_cost(&params.cost))));

    on_stage("inference (left)");
    let left = estimate_view(params, &pair.left, &cost_left, &mut t);
    drop(cost_left);
    let right = cost_right.map(|c| {
        on_stage("inference (right)");
        estimate_view(params, &pair.right, &c, &mut t)
    });

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
fn estimate_view(params: &Params, image: &RgbImage, cost: &CostVolume, t: &mut Timings) -> ViewEstimate {
    match params.model {
        Model::Wta => {
            let disparity = t.time("wta", || cost::winner_take_all(cost));
            let confidence = Plane::new(cost.width, cost.height, 1.0);
            ViewEstimate { disparity, confidence }
        }
        Model::Lcm | Model::Fcm | Model::Jem => {
            let weights =
                meanfield::PairwiseWeights { fcm: params.effective_fcm_weight(), lcm: params.effective_lcm_weight() };
            let mut mf = t.time("mf setup", || meanfield::MeanField::new(cost, image, &params.meanfield, weights));
            t.time("mf iterations", || (0..params.meanfield.iterations).for_each(|_| mf.step()));
            let q = mf.into_marginals();
            let (disparity, confidence) =
                t.time("decode", || meanfield::decode_marginals(&q, params.meanfield.subpixel));
            ViewEstimate { disparity, confidence }
        }
    }
}
