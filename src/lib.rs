//! # jem — stereo matching by joint energy minimization
//!
//! An implementation of Xue & Cai, "Stereo Matching by Joint Energy Minimization": a Census + gradient cost
//! volume, mean-field inference on an MRF that joins a fully connected Potts term (bilateral kernel, filtered
//! with a permutohedral lattice) and a 4-neighbour local term, then left-right check, occlusion fill, weighted
//! median and slanted-plane smoothing; with our adaptive front end (the pair's noise, contrast, sharpness and
//! vertical offset measured and allowed for, and a coarse-to-fine prior).
//!
//! ## Use
//!
//! A [`Matcher`] is built once from a configuration ([`Params`]: defaults, a shipped preset ([`Params::preset`]),
//! a TOML file, `key=value` overrides) and matches rectified pairs: decoded images ([`Matcher::match_pair`]) or
//! image files ([`Matcher::match_files`]). The images are [`RgbImage`]s (samples 0..=255, whatever the file's bit
//! depth); the result is an [`Output`], whose disparity map is a [`DisparityMap`] (`inf` where invalid). [`io`]
//! reads and writes images and disparity maps (PFM, EXR, 16-bit PNG), [`geometry`] turns disparities into depth and
//! point clouds.
//!
//! ```
//! use jem::{Matcher, NdispSource, Params};
//! # let dir = tempfile::tempdir()?;
//! # let scene = jem::synth::render_scene(&jem::synth::SynthParams { width: 96, height: 64, ndisp: 16, seed: 1 })?;
//! # jem::synth::write_scene(dir.path(), &scene)?;
//! # let (left_png, right_png) = (dir.path().join("im0.png"), dir.path().join("im1.png"));
//! // A configuration: the defaults with one value changed (as `jem --set meanfield.iterations=2`).
//! let params = Params::load(None, &["meanfield.iterations=2".to_string()])?;
//! let mut matcher = Matcher::new(params)?.with_ndisp(NdispSource::Given(16));
//! let (left, right) = jem::io::read_image_pair(&left_png, &right_png)?;
//! let out = matcher.match_pair(&left, &right)?;
//! println!("ndisp {}, {:.2} s", out.plan.ndisp, out.seconds);
//! jem::io::write_disparity(&dir.path().join("disp.pfm"), &out.disparity)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! The stereo library is [`Matcher`] and its types at the root, [`params`], [`io`], [`geometry`] and [`rectify`].
//! The benchmark toolkit around it is behind the `toolkit` feature (on with the default `cli`; a library user with
//! `default-features = false` compiles none of it): [`eval`] scores results against ground truth (MiddEval3, KITTI,
//! ETH3D), [`batch`] and [`dataset`] run whole data sets, [`viz`] draws colour maps, [`report`] writes an HTML page
//! of results, [`synth`] renders scenes with exact ground truth, [`degrade`] makes degraded copies of a data set,
//! [`sequence`] runs stereo sequences, and [`threads`] and [`cleanup`] serve the front ends.
//!
//! ## Inside
//!
//! The pipeline, in `src/pipeline/`: prepare (condition the pair) → coarse prior (the pipeline on the pair
//! reduced 2×) → fine pass (cost volume, inference on both views, left-right check, fill, weighted median,
//! slanted planes). Each stage is a free function in its own module (`cost`, `lattice`, `meanfield`, `post`:
//! the paper's; `condition`, `setup`, `scale`: ours), private to the crate; the benches reach them through
//! [`internals`], which is not part of the API.
#![deny(missing_docs)]
#![warn(unreachable_pub)]

#[cfg(feature = "toolkit")]
pub mod batch;
#[cfg(feature = "toolkit")]
pub mod cleanup;
#[cfg(not(feature = "toolkit"))]
mod cleanup;
mod condition;
mod cost;
#[cfg(feature = "toolkit")]
pub mod dataset;
#[cfg(feature = "toolkit")]
pub mod degrade;
mod diagnose;
mod error;
#[cfg(feature = "toolkit")]
pub mod eval;
mod fastmath;
pub mod geometry;
mod image;
mod imgproc;
pub mod io;
mod lattice;
mod matcher;
mod meanfield;
mod min_disp;
pub mod params;
mod pipeline;
mod post;
mod process;
pub mod rectify;
#[cfg(feature = "toolkit")]
pub mod report;
mod rng;
mod scale;
#[cfg(feature = "toolkit")]
pub mod sequence;
mod setup;
#[cfg(feature = "toolkit")]
pub mod synth;
#[cfg(feature = "toolkit")]
mod table;
mod temporal;
#[cfg(feature = "toolkit")]
pub mod threads;
#[cfg(feature = "toolkit")]
pub mod viz;

pub use diagnose::{PairCheck, Repetition};
pub use error::{Error, Result};
pub use image::{DisparityMap, Plane, RgbImage};
pub use matcher::{Exposure, FrameKind, Matcher, Output, Progress, Rectified, RunPlan, Tiles, default_memory_limit};
pub use params::{LrcMode, Model, Params};
pub use pipeline::{Measured, Timings, VerticalMeasured};
#[cfg(feature = "toolkit")]
pub use process::peak_rss_bytes;
pub use setup::NdispSource;
pub use setup::memory::MemoryBudget;

#[doc(hidden)]
pub mod internals;

#[cfg(test)]
mod test_util;
