//! Evaluation against ground truth with the semantics of the MiddEval3 SDK's `evaldisp` (the Middlebury 2014 evaluation kit's scoring program), as listed below.
//!
//! # What is counted
//! For every pixel whose ground truth is finite (an `inf` GT pixel is unknown and skipped) and that the mask
//! selects ([`MaskMode::Nonocc`]: `mask0nocc.png == 255`; [`MaskMode::All`]: `mask > 0`; no mask: every
//! GT-valid pixel), let `n` be the number of such pixels. A result pixel that is not finite (`+inf`, `-inf`,
//! NaN) is *invalid*; a finite one is clipped to `[0, ndisp]` (inclusive, at the result's resolution, as
//! `evaldisp` clips to its `maxdisp`) and its error is `err = s·|d − gt|`, with `s` the resolution scale
//! (4 for quarter, 2 for half, 1 for full resolution), so errors and thresholds are in full-resolution pixels.
//!
//! | metric     | definition                                                            |
//! |------------|-----------------------------------------------------------------------|
//! | `avgerr`   | Σ err / (n − invalid) — invalid pixels are left out                     |
//! | `rms`      | √(Σ err² / (n − invalid))                                               |
//! | `badT`     | 100 · #{valid pixels with err > T} / n, T ∈ {0.5, 1, 2, 4} (strict `>`) |
//! | `invalid`  | 100 · #{invalid pixels} / n                                            |
//! | `totbad2`  | `bad2 + invalid` = 100 · (#{err > 2} + #{invalid}) / n                 |
//! | `d1`       | 100 · (#{err > 3 and err > 5 % of s·gt} + #{invalid}) / n (KITTI's D1)  |
//!
//! So the bad percentages count bad *valid* pixels among *all* `n` masked GT-valid pixels, exactly as
//! `evaldisp` does (its `badpercent = 100·bad/n`, `totalbadpercent = 100·(bad + invalid)/n`, and since 2014
//! `avgErr = serr/(n − invalid)`). When `n − invalid = 0`, `avgerr` and `rms` are NaN (printed as `nan`,
//! `null` in JSON); a scene with `n = 0` is an error.
//!
//! # Deviations from `evaldisp`
//! - `evaldisp` upsamples a low-resolution result to the full-resolution GT; here the result and the GT have the
//!   same size (a Q result is scored against the Q ground truth) and the factor `s` restores full-res units.
//! - `evaldisp` treats only `+inf` as invalid; here every non-finite value is invalid (it would clip `-inf` to 0
//!   and let a NaN poison its sums). GT pixels that are NaN are skipped like `inf` ones.
//! - Sums are `f64` (not `f32`), accumulated in raster order, so results are deterministic.
//!
//! # KITTI and ETH3D
//! The same rules with `s = 1` (native pixels) and no clipping, ground truth and results where the
//! [`dataset`](crate::dataset) layout puts them. ETH3D: `mask0nocc.png == 255` for `nonocc`, every GT pixel for
//! `all` (its mask does not mark "no ground truth"). KITTI, as its development kit: `nonocc` scores against
//! `disp_noc*`, `all` against `disp_occ*` (16-bit PNG, 0 = unknown); the result's invalid pixels are first
//! filled by [`interpolate_background`], so every error column counts
//! them with their filled value, and `invalid` reports the share that was invalid before the fill. The KITTI
//! table leads with `d1`; the MiddEval3 and ETH3D tables do not show it (the JSON and CSV of a KITTI report
//! have it).
//!
//! # Averages
//! [`AlgReport::weighted`] is the MiddEval3 weighted mean over the scenes that were evaluated: PianoL, Playroom,
//! Playtable, Shelves and Vintage weigh 0.5, every other scene 1 ([`scene_weight`]; KITTI and ETH3D scenes all
//! weigh 1); [`AlgReport::mean`] is the
//! plain mean. Each metric is averaged separately. Scenes whose result is missing or unreadable are listed and
//! left out of both.
//!
//! # Files
//! - `metrics.rs`: the rules above for one result: [`evaluate`] (maps in memory), [`evaluate_files`],
//!   [`evaluate_scene`] (a MiddEval3 scene folder).
//! - `report.rs`: one algorithm over a folder of scenes: [`evaluate_dir`] finds the scenes with ground truth,
//!   their resolution and weight, scores them in parallel and collects an [`AlgReport`] with its averages.
//! - `resolution.rs`: a MiddEval3 folder's resolution, from its path or from its scenes' names and sizes
//!   ([`scene_resolution`], [`file_resolution`]).
//! - `sparsification.rs`: how well a confidence map ranks the errors ([`sparsification()`], the AUC of Hu &
//!   Mordohai), scored when the result has one beside it (`conf0NAME.pfm`).
//! - `paper.rs`: the paper's numbers ([`PaperResults`], `paper-results.tsv`), printed beside ours.
//! - `format.rs`: [`render`] prints reports as a text or Markdown table, JSON or CSV.
//! - `regions.rs`: where the error is (`jem eval --regions`): a MiddEval3 result's avgErr split by region (rejected
//!   by the left-right check, near depth edges, textureless, near occlusions, the rest) and by error size
//!   ([`split_report`], [`split_scene`], [`split_by_region`]); `regions_format.rs` prints it ([`render_regions`],
//!   and a `"regions"` member in the JSON of [`render_with_regions`]).
//! - `sequence.rs`: a stereo sequence's results ([`sequence::evaluate_sequence`]): each frame as above, and the
//!   frame-to-frame figures (the change where the truth did not move, the error of the change where it did).

mod format;
mod kitti_fill;
mod metrics;
mod paper;
mod regions;
mod regions_format;
mod report;
mod resolution;
pub mod sequence;
mod sparsification;
mod text;

pub use format::{Format, render, render_with_regions};
pub use kitti_fill::interpolate_background;
pub(crate) use metrics::check_size;
pub use metrics::{
    BAD_THRESHOLDS_PX, D1_RELATIVE, D1_THRESHOLD_PX, MaskMode, Metrics, evaluate, evaluate_files, evaluate_scene,
};
pub use paper::{PaperColumn, PaperResults};
pub use regions::{
    EDGE_JUMP_PX, EDGE_RADIUS_PX, GROSS_PX, NOT_SCORED, OCCLUSION_RADIUS_PX, REGION_KEYS, RegionInputs, RegionReport,
    RegionSplit, SIZE_BOUNDS_PX, SIZE_KEYS, TEXTURE_RADIUS_PX, TEXTURELESS_SHARE, region_map, split_by_region,
    split_report, split_scene,
};
pub use regions_format::render_regions;
pub use report::{AlgReport, SceneResult, Sources, evaluate_dir, find_gt_scenes, scene_weight};
pub use resolution::{
    QUARTER_SIZES, Resolution, ScaleSource, file_resolution, resolution_name, scale_from_any_size, scale_from_path,
    scale_from_scene_size, scene_resolution,
};
pub use sparsification::{Sparsification, sparsification};
