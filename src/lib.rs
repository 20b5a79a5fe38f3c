//! # jem — stereo matching by joint energy minimization
//!
//! An implementation of Xue & Cai, "Stereo Matching by Joint Energy Minimization": a Census + gradient cost
//! volume, mean-field inference on an MRF that joins a fully connected Potts term (bilateral kernel, filtered
//! with a permutohedral lattice) and a 4-neighbour local term, then left-right check, occlusion fill, weighted
//! median and slanted-plane smoothing.
//!
//! The whole pipeline is one call, [`run`] ([`pipeline`]: prepare → coarse prior → fine pass); each stage is a
//! free function in its own module:
//!
//! ```text
//! cost::build_cost_volume ─► meanfield::infer_mean_field (left and right views) ─► post::lr_check
//!   ─► post::fill ─► post::wmedian ─► post::planes
//! ```
//!
//! ## The crate map
//!
//! | modules | whose | what |
//! |---|---|---|
//! | [`cost`], [`lattice`], [`meanfield`], [`post`] | the paper | the stages (`meanfield`'s files mark our additions) |
//! | [`params`] | both | one file per stage: defaults, reasons, `validate()` |
//! | [`pipeline`] (with [`tile`]) | ours | the orchestrator: coarse prior, label windows, tiles, memory |
//! | [`condition`], [`rectify`] | ours | measuring and conditioning the pair; its vertical offset |
//! | [`range`], [`scale`], [`plan`] | ours | the search range when none is given; `--downscale`; setting up a match |
//! | [`io`], [`image`], [`dataset`], [`batch`], [`sequence`] | around | files, data types, data-set layouts, batch runs, stereo sequences |
//! | [`eval`], [`viz`], [`synth`], [`degrade`] | around | scoring, colour maps, synthetic and degraded pairs |
//! | [`geometry`], [`table`], [`fastmath`], [`error`] | around | depth and point clouds, shared helpers, errors |
//!
//! With `downscale = N > 1` ([`Params::downscale`]) the pipeline runs on the pair reduced by N
//! (`scale::downsample_pair`) and the result is brought back to the input size (`scale::upsample_disparity`).
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
pub mod condition;
pub mod cost;
pub mod dataset;
pub mod degrade;
pub mod error;
pub mod eval;
pub mod fastmath;
pub mod geometry;
pub mod image;
pub mod io;
pub mod lattice;
pub mod meanfield;
pub mod params;
pub mod pipeline;
pub mod plan;
pub mod post;
pub mod range;
pub mod rectify;
#[doc(hidden)]
pub mod rng;
pub mod scale;
pub mod sequence;
pub mod synth;
pub mod table;
pub mod viz;

pub use error::{Error, Result};
pub use image::{CostVolume, DisparityMap, Plane, RgbImage, StereoPair};
pub use params::{LrcMode, Model, Params};
pub use pipeline::tile;
pub use pipeline::{
    Measured, Output, PROCESS_BYTES, Timings, VerticalMeasured, check_memory, default_memory_limit,
    estimate_memory_bytes, run, run_observed,
};

/// Helpers shared by the unit tests.
#[cfg(test)]
pub(crate) mod test_util {
    /// Seeded uniform noise in 0..1 ([`crate::rng::SplitMix64`]): reproducible test inputs.
    pub(crate) fn rand_vec(n: usize, seed: u64) -> Vec<f32> {
        let mut rng = crate::rng::SplitMix64::new(seed);
        (0..n).map(|_| (rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32).collect()
    }
}
