//! The pipeline: what [`run`] does with a pair, in order.
//!
//! ```text
//! prepare (condition the pair; the cost parameters that follow)   prepared.rs
//!   ─► coarse prior (the pipeline on the pair reduced 2×)           prior.rs
//!   ─► fine pass: cost volume ─► inference, left and right views    fine.rs
//!        ─► left-right check ─► fill ─► weighted median ─► planes
//! ```
//!
//! Around it: `window.rs` (label windows: a tile's fine pass on the labels the coarse answer holds only), [`tile`]
//! (pairs too large for one cost volume: a coarse level, then tiles over label windows), `memory.rs` (the memory model
//! and guard: [`crate::setup::memory::estimate_memory_bytes`], [`crate::setup::memory::check_memory`]) and `output.rs`
//! (what a run returns: [`PipelineOutput`], [`Measured`], [`Timings`]).

mod fine;
mod label_step;
mod output;
mod prepared;
mod prior;
pub(crate) mod tile;
mod window;

use crate::error::{Error, Result};
use crate::image::{Plane, StereoPair};
use crate::params::Params;
use crate::{lattice, meanfield, scale};

pub(crate) use fine::FrameViews;
use fine::{FineInput, fine_pass};
pub use output::{Measured, PipelineOutput, Timings, VerticalMeasured};
use prepared::Prepared;
use prior::CoarseLevel;

/// What the caller of a run asks for beside the disparity map.
#[derive(Clone, Copy)]
pub struct RunOptions<'a> {
    /// Called with each stage's name as it starts (progress display).
    pub on_stage: &'a dyn Fn(&str),
    /// Whether to compute the confidence map ([`PipelineOutput::confidence`]): a few per cent of a run, spent only
    /// when asked for.
    pub confidence: bool,
}

impl RunOptions<'_> {
    /// No progress and no confidence map (a coarse level of the prior's chain).
    pub fn quiet() -> RunOptions<'static> {
        RunOptions { on_stage: &|_| {}, confidence: false }
    }
}

/// Runs the whole pipeline on a pair (at 1/`params.downscale` resolution if that is > 1; see `scale`), the
/// confidence map included.
///
/// # Errors
/// [`Error::InvalidParam`] if `params` does not validate, or the downscale factor is too large for the pair.
pub fn run(params: &Params, pair: &StereoPair) -> Result<PipelineOutput> {
    run_with(params, pair, &RunOptions { on_stage: &|_| {}, confidence: true })
}

/// Like [`run`], calling `on_stage(name)` as each stage starts (for progress display).
///
/// # Errors
/// As [`run`].
pub fn run_observed(params: &Params, pair: &StereoPair, on_stage: &dyn Fn(&str)) -> Result<PipelineOutput> {
    run_with(params, pair, &RunOptions { on_stage, confidence: true })
}

/// Runs the pipeline as `options` ask ([`RunOptions`]).
///
/// With `params.downscale` = N > 1: the pair is reduced by N (`scale::downsample_pair`, stage `downsample`),
/// the pipeline runs on it, and its disparity map (`scale::upsample_disparity_guided`, `[upsample]`) and confidence
/// (`scale::upsample_plane`) are brought back to the input size (stage `upsample`).
///
/// # Errors
/// As [`run`].
pub fn run_with(params: &Params, pair: &StereoPair, options: &RunOptions<'_>) -> Result<PipelineOutput> {
    run_level(params, pair, options, None)
}

/// [`run_with`] for a level whose measured noise is at most `noise_ceiling` (a coarse level: the `noise_ceiling`
/// of [`crate::condition::condition_pair`]; `None` for the full resolution).
fn run_level(
    params: &Params,
    pair: &StereoPair,
    options: &RunOptions<'_>,
    noise_ceiling: Option<[f32; 2]>,
) -> Result<PipelineOutput> {
    params.validate()?;
    let factor = params.downscale;
    if factor == 1 {
        return run_pipeline(params, pair, options, noise_ceiling, Timings::default());
    }
    let mut t = Timings::default();
    (options.on_stage)("downsample");
    let small = t.time("downsample", || scale::downsample_pair(pair, factor))?;
    let low = run_pipeline(params, &small, options, noise_ceiling, t)?;
    let mut t = low.timings;
    (options.on_stage)("upsample");
    let (w, h) = pair.left.dims();
    let up = &params.upsample;
    let (disparity, (mut confidence, max_marginal)) = t.time("upsample", || {
        rayon::join(
            || {
                let (low, guide) = (&low.disparity, &small.left);
                scale::upsample_disparity_guided(low, guide, &pair.left, factor, up.edge_px, up.sigma_rgb)
            },
            || {
                let up = |p| scale::upsample_plane(p, factor, w, h);
                (low.confidence.as_ref().map(up), up(&low.max_marginal))
            },
        )
    });
    drop(small);
    // An invalid pixel has no confidence, whatever its neighbours' at the reduced size.
    if let Some(confidence) = &mut confidence {
        let invalid = confidence.data.iter_mut().zip(&disparity.data).filter(|(_, d)| !d.is_finite());
        invalid.for_each(|(c, _)| *c = 0.0);
    }
    let consistent = scale::upsample_mask(&low.consistent, factor, w, h);
    Ok(PipelineOutput {
        disparity,
        confidence,
        max_marginal,
        consistent,
        timings: t,
        measured: low.measured,
        vertical_offset: None,
        segmentation: None,
    })
}

/// The pipeline at the pair's own resolution, appending its stage times to `t`: prepare, coarse prior, fine pass.
fn run_pipeline(
    params: &Params,
    pair: &StereoPair,
    options: &RunOptions<'_>,
    noise_ceiling: Option<[f32; 2]>,
    mut t: Timings,
) -> Result<PipelineOutput> {
    check_features_fit(params, pair)?;
    let mut input = Prepared::of(params, pair, noise_ceiling, &mut t);
    // Before the full-resolution volume exists, so the two runs' buffers are never alive together.
    let chain = CoarseLevel::chain();
    let prior = if chain.applies(pair, &input) {
        Some(chain.prior(params, pair, &mut input, options.on_stage, &mut t)?)
    } else {
        None
    };
    let buffers = &mut meanfield::Buffers::default();
    fine_at_full_resolution(params, pair, &input, prior.as_ref(), FromFrame::default(), (options, buffers), t)
}

/// What a frame of a sequence takes from the frame before it into the fine pass besides the prior (see
/// [`FineInput`]): how its views run, and the segmentation its planes start from.
#[derive(Clone, Copy, Default)]
struct FromFrame<'a> {
    views: Option<FrameViews>,
    segmentation: Option<&'a crate::post::planes::Segmentation>,
}

/// The fine pass on the prepared pair, with `prior` and what the frame before gives (`from`), as `options` ask, its
/// large allocations taken from `buffers` and given back there; appends its stage times to `t`. The output carries
/// what preparing the pair measured.
fn fine_at_full_resolution(
    params: &Params,
    pair: &StereoPair,
    input: &Prepared,
    prior: Option<&prior::Prior>,
    from: FromFrame<'_>,
    (options, buffers): (&RunOptions<'_>, &mut meanfield::Buffers),
    t: Timings,
) -> Result<PipelineOutput> {
    let (guide, cost_pair) = input.pairs(pair);
    let params = &params.for_image(pair.left.width * pair.left.height);
    let fine = FineInput {
        guide,
        cost_pair,
        cost_params: &input.cost_params,
        grad_norm_mean: input.grad_norm_mean,
        noise: input.noise(),
        prior,
        left_from: 0,
        views: from.views,
        confidence: options.confidence,
        segmentation: from.segmentation,
        // A whole image's prior in bands is a travelling frame's: its bands are grouped with the labels, if any.
        grouped_bands: prior.is_some_and(|p| p.in_bands),
    };
    let mut out = fine_pass(params, &fine, buffers, options.on_stage, t)?;
    out.measured = input.measured();
    out.vertical_offset = input.vertical_offset();
    Ok(out)
}

/// What a frame of a sequence takes from the frame before it in place of the coarse chain ([`run_with_prior`]).
pub(crate) struct FramePrior {
    /// The previous frame's answer, moved by the camera's motion (`inf` where it says nothing); the planes start
    /// from its segmentation, if it carries one.
    pub answer: PipelineOutput,
    /// Pixels where the frames disagree (something moved): no prior there.
    pub released: Option<Plane<bool>>,
    /// The vertical offset removed from the previous frame's right view, reused instead of measured again.
    pub vertical_offset: Option<crate::condition::vertical::VerticalOffset>,
    /// λ of the prior relative to the coarse prior's rule.
    pub weight_scale: f32,
    /// How the frame's views run (`None`: as configured).
    pub views: Option<FrameViews>,
    /// Inference keeps each pixel to a band of labels around the carried answer ([`prior::Prior::label_bands`]);
    /// a released pixel's band comes from its neighbours' answers, or is every label. On grouped labels (a large
    /// image) the bands are grouped with them.
    pub in_bands: bool,
}

/// The pipeline at the pair's own resolution with the previous frame's answer as the prior ([`FramePrior`]): the
/// coarse chain, and the vertical-offset measurement when the previous offset is given, are not run. The prior's
/// weight follows the coarse prior's rule (λ by the measured noise, its floor where the cost is flat, its factor by
/// the previous confidence and left-right check), scaled, and is released where the frames disagree. The large
/// allocations come from `buffers` and go back there (a sequence's frames reuse them).
///
/// # Errors
/// As [`run`].
pub(crate) fn run_with_prior(
    params: &Params,
    pair: &StereoPair,
    from: FramePrior,
    options: &RunOptions<'_>,
    buffers: &mut meanfield::Buffers,
) -> Result<PipelineOutput> {
    params.validate()?;
    check_features_fit(params, pair)?;
    let mut t = Timings::default();
    let mut input = Prepared::of(params, pair, None, &mut t);
    let c = &params.condition;
    match from.vertical_offset {
        Some(v) => input.apply_vertical_offset(c, v, &mut t),
        None => {
            let grey_left = input.pairs(pair).1.left.to_grey();
            input.align_vertically(c, &grey_left, &from.answer, &mut t);
        }
    }
    let weight = input.prior_weight * from.weight_scale;
    let mut answer = from.answer;
    let segmentation = answer.segmentation.take();
    let mut prior = prior::Prior::from_coarse(answer, weight, input.prior_flat, c.prior.untrusted);
    if let Some(released) = &from.released {
        prior.confidence.data.iter_mut().zip(&released.data).filter(|(_, r)| **r).for_each(|(f, _)| *f = 0.0);
        if from.in_bands {
            prior.disparity.data.iter_mut().zip(&released.data).filter(|(_, r)| **r).for_each(|(d, _)| {
                *d = f32::INFINITY;
            });
        }
    }
    prior.in_bands = from.in_bands;
    let frame = FromFrame { views: from.views, segmentation: segmentation.as_ref() };
    fine_at_full_resolution(params, pair, &input, Some(&prior), frame, (options, buffers), t)
}

/// The fully connected kernel's features must fit the lattice at this image size.
///
/// # Errors
/// [`Error::InvalidParam`] naming `meanfield.sigma_xy / meanfield.sigma_rgb` when they do not.
fn check_features_fit(params: &Params, pair: &StereoPair) -> Result<()> {
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
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::RgbImage;
    use crate::synth;

    /// A synthetic scene with exact ground truth run at half resolution: the upsampled disparity map is dense,
    /// full size, and within 1 full-resolution px of the truth on most visible pixels. (The scene must not be
    /// much smaller: `post.sps.segments` is a count per image, and 1500 segments on a 120×80 reduced image are
    /// 6 px each, which breaks the planes; at 160×120 they are 13 px.)
    #[test]
    fn downscale_two_recovers_a_synthetic_scene() {
        let scene = synth::render_scene(&synth::SynthParams { width: 320, height: 240, ndisp: 48, seed: 7 }).unwrap();
        let pair = StereoPair::new(scene.left.clone(), scene.right.clone(), scene.ndisp).unwrap();
        let p = Params { downscale: 2, ..Params::default() };
        let out = run(&p, &pair).unwrap();
        assert_eq!(out.disparity.dims(), (320, 240));
        assert_eq!(out.confidence.map(|c| c.dims()), Some((320, 240)));
        assert_eq!(out.consistent.dims(), (320, 240));
        let consistent = out.consistent.data.iter().filter(|ok| **ok).count();
        assert!(
            consistent > 320 * 240 * 3 / 4 && consistent < 320 * 240,
            "most, not all, pass the check: {consistent}"
        );
        let stages: Vec<&str> = out.timings.stages.iter().map(|(name, _)| *name).collect();
        assert_eq!((stages.first(), stages.last()), (Some(&"downsample"), Some(&"upsample")), "{stages:?}");
        assert!(out.disparity.data.iter().all(|d| d.is_finite() && (0.0..48.0).contains(d)), "dense, in range");
        let (mut n, mut bad, mut sum) = (0usize, 0usize, 0.0f64);
        for ((d, g), m) in out.disparity.data.iter().zip(&scene.gt.data).zip(&scene.mask.data) {
            if *m == synth::MASK_VISIBLE {
                let e = (d - g).abs() as f64;
                n += 1;
                sum += e;
                bad += (e > 1.0) as usize;
            }
        }
        let (mean, bad_pct) = (sum / n as f64, 100.0 * bad as f64 / n as f64);
        // Measured: mean 0.52 px, 2.3% over 1 px (without downscale: 0.23 px and 0.34%). The bounds, about twice
        // that, leave room for tuning changes but fail if the disparities were not scaled back (mean ~12 px) or
        // the maps misaligned by a block (most pixels over 1 px on the slanted surfaces).
        assert!(mean < 1.0 && bad_pct < 5.0, "mean {mean:.3} px, {bad_pct:.1}% over 1 px");
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
}
