//! Parameters of input conditioning and the coarse prior ([`crate::condition`]).

use serde::{Deserialize, Serialize};

use super::check_nonneg;
use crate::error::{Error, Result};

/// Input conditioning and the coarse prior ([`crate::condition`]): measured on each pair, so one setting serves
/// clean, noisy and dark pairs (docs/tuning-log.md, "Robustness").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ConditionParams {
    /// The master switch: false turns every part off (the paper's configs use it).
    pub enabled: bool,
    /// Stretch the contrast of a low-contrast pair.
    pub stretch: bool,
    /// The stretch is applied only when its gain would be at least this (a pair using most of the range is left
    /// as it is).
    pub stretch_min_gain: f32,
    /// Bilateral range scale as a multiple of the measured noise σ; 0 = no denoising.
    pub denoise_strength: f32,
    /// Spatial σ of the denoising filter, in pixels.
    pub denoise_sigma_xy: f32,
    /// A view whose measured noise σ (grey levels) is below this is not denoised.
    pub denoise_min_sigma: f32,
    /// Count a JPEG-decoded view's compression error as noise ([`crate::condition::jpeg_noise`]); the coarse
    /// levels, whose images are reduced off the block grid, do not measure it.
    pub jpeg_noise: bool,
    /// Census dead band as a multiple of the measured JPEG blocking ([`crate::condition::blockiness`], the larger
    /// view's): a bit is set only where the neighbour is darker by more than the block grid's own steps; 0 = none.
    pub block_band: f32,
    /// Widens `cost.census_support` by this multiple of the measured noise σn (when the support is on): under
    /// noise the bits of strong contrast are the ones noise does not flip.
    pub support_per_sigma: f32,
    /// Widens `cost.grad_norm_eps` by this multiple of the measured noise σn (when the normalisation is on): the
    /// gradient term is normalised only where the local contrast stands well above the noise.
    pub grad_eps_per_sigma: f32,
    /// Coarse prior: the pipeline first runs on the pair reduced 2×, and the full-resolution cost gets
    /// `prior_per_sigma` × σn × min(max(|d − d_coarse| − `prior_margin_px`, 0), `prior_trunc_px`); 0 = off.
    pub prior_per_sigma: f32,
    /// Levels of coarse priors below the full resolution: 1 = the coarse run (at 1/2) has none of its own, 2 = it
    /// has one (at 1/4), and so on (1 to 4).
    pub prior_levels: usize,
    /// Scale each pixel's prior weight by the coarse run's confidence (its max-marginal, 0..1).
    pub prior_confidence: bool,
    /// Prior weight factor at pixels the coarse run's left-right check rejected.
    pub prior_untrusted: f32,
    /// Weakens the prior where the image has detail the coarse run cannot hold: × 1 / (1 + D / (k·D̄)), D the
    /// local mean of what an F × F block average removes from the cost image (F the coarse factor), D̄ its image
    /// mean; this is k (0 = off).
    pub prior_detail: f32,
    /// Beside a depth edge of the coarse answer the prior accepts the whole step: where the coarse disparities
    /// within this many coarse pixels of a pixel differ by more than `prior_trunc_px`, labels between their
    /// smallest and largest are free (the coarse level places an edge only to within its own pixels, and under
    /// noise its edges fatten); 0 = off.
    pub prior_spread: usize,
    /// When one view of the cost pair is sharper than the other by more than this factor
    /// ([`crate::condition::sharpness`]), it is blurred until they match (0 = never).
    pub sharpness_ratio: f32,
    /// Measure the right view's residual vertical offset against the coarse run's answer and remove it
    /// ([`crate::rectify`]) before the full-resolution cost (needs the coarse prior).
    pub vertical_align: bool,
    /// The offset is removed only where it reaches this many pixels somewhere in the image (below it the
    /// Census windows hardly differ, and a perfectly rectified pair stays as it is).
    pub vertical_min_px: f32,
    /// Where the full-resolution cost is flat the prior weighs at least this × 1 / (1 + s / s̄), s the pixel's
    /// cost spread over the labels (mean − min) and s̄ its image median ([`crate::cost::flatness`]): an untextured
    /// surface follows the coarse answer even in a clean pair, whose noise-scaled weight is near 0; 0 = off.
    pub prior_flat: f32,
    /// Labels within this distance of the coarse disparity (full-resolution px) are free.
    pub prior_margin_px: f32,
    /// The penalty stops growing beyond this distance past the margin.
    pub prior_trunc_px: f32,
    /// Switches measured and not kept, off by default (`[condition.experimental]`).
    pub experimental: ExperimentalConditionParams,
}

/// `[condition.experimental]`: switches that were measured and not adopted, off by default and set by no shipped
/// config. They stay so that the measurements in docs/tuning-log.md can be repeated
/// (`--set condition.experimental.KEY=VALUE`); a switch that measurement keeps moves out of this table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExperimentalConditionParams {
    /// Map the right view's histogram onto the left's. Worse than without once the rest of the conditioning is on:
    /// it hurts PianoL, whose views are lit differently on purpose (docs/tuning-log.md, "Robustness").
    pub match_histograms: bool,
    /// Census dead band as a multiple of the grey noise σ measured after denoising; 0 = none. A band tied to the
    /// measured noise (1 to 3) changed nothing measurable (docs/tuning-log.md).
    pub census_band: f32,
    /// A fixed prior weight added to the noise-scaled one (`prior_per_sigma`); 0 = none. Tried for blur, which
    /// lowers the measured noise, and not kept (docs/tuning-log.md).
    pub prior_base: f32,
    /// The coarse run gets a coarse prior of its own (recursively) when the measured σn is at least this; 0 =
    /// never. Superseded by `condition.prior_levels`, which gives every pair its chain.
    pub prior_recurse_sigma: f32,
    /// Search only the labels the coarse run found (its smallest and largest disparity, widened by two coarse
    /// labels) at full resolution: as accurate, and on MiddEval3's ranges hardly faster (docs/tuning-log.md).
    pub prior_window: bool,
}

impl Default for ConditionParams {
    /// The default pipeline's conditioning (chosen in docs/tuning-log.md, "Robustness: the adaptive default"):
    /// stretch only a view that uses less than 1/1.5 of the range, denoise (for the cost) only a view measured
    /// noisier than 2 grey levels, and a coarse prior of weight 0.5·σn scaled by the coarse confidence, halved
    /// where the coarse left-right check failed, from a half-resolution run that has such a prior of its own, and
    /// that one from a quarter-resolution run with one of its own (`prior_levels` 3: docs/tuning-log.md "Coarse
    /// priors of their own", "A third coarse level").
    fn default() -> Self {
        ConditionParams {
            enabled: true,
            stretch: true,
            stretch_min_gain: 1.5,
            denoise_strength: 3.0,
            denoise_sigma_xy: 3.0,
            denoise_min_sigma: 2.0,
            jpeg_noise: true,
            block_band: 1.0,
            support_per_sigma: 2.5,
            grad_eps_per_sigma: 30.0,
            prior_per_sigma: 0.5,
            prior_levels: 3,
            prior_confidence: true,
            prior_untrusted: 0.5,
            prior_detail: 1.5,
            prior_flat: 1.0,
            prior_spread: 1,
            vertical_align: true,
            vertical_min_px: 0.1,
            sharpness_ratio: 1.25,
            prior_margin_px: 1.0,
            prior_trunc_px: 8.0,
            experimental: ExperimentalConditionParams::default(),
        }
    }
}

impl ConditionParams {
    /// Everything off: the pair goes to the cost as it is (the paper's configs: `enabled = false`).
    pub fn off() -> Self {
        ConditionParams {
            enabled: false,
            stretch: false,
            denoise_strength: 0.0,
            jpeg_noise: false,
            block_band: 0.0,
            support_per_sigma: 0.0,
            grad_eps_per_sigma: 0.0,
            prior_per_sigma: 0.0,
            prior_confidence: false,
            prior_detail: 0.0,
            prior_spread: 0,
            vertical_align: false,
            sharpness_ratio: 0.0,
            ..Self::default()
        }
    }

    /// Whether any part is on (when none is, the pair goes to the cost unchanged).
    pub fn is_active(&self) -> bool {
        self.enabled
            && (self.experimental.match_histograms
                || self.stretch
                || self.denoise_strength > 0.0
                || self.experimental.census_band > 0.0
                || self.block_band > 0.0
                || self.jpeg_noise
                || self.prior_per_sigma > 0.0
                || self.experimental.prior_base > 0.0
                || self.prior_flat > 0.0)
    }

    /// Checks every value's range.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] naming the first offending key, its value and the valid range.
    pub fn validate(&self) -> Result<()> {
        check_nonneg("condition.denoise_strength", self.denoise_strength)?;
        if !(self.denoise_sigma_xy.is_finite() && (0.0..=10.0).contains(&self.denoise_sigma_xy)) {
            return Err(Error::param("condition.denoise_sigma_xy", self.denoise_sigma_xy, "0 to 10"));
        }
        if !(self.stretch_min_gain.is_finite() && self.stretch_min_gain >= 1.0) {
            return Err(Error::param("condition.stretch_min_gain", self.stretch_min_gain, "at least 1"));
        }
        check_nonneg("condition.denoise_min_sigma", self.denoise_min_sigma)?;
        check_nonneg("condition.experimental.census_band", self.experimental.census_band)?;
        check_nonneg("condition.block_band", self.block_band)?;
        check_nonneg("condition.support_per_sigma", self.support_per_sigma)?;
        check_nonneg("condition.grad_eps_per_sigma", self.grad_eps_per_sigma)?;
        check_nonneg("condition.prior_per_sigma", self.prior_per_sigma)?;
        check_nonneg("condition.experimental.prior_base", self.experimental.prior_base)?;
        check_nonneg("condition.prior_untrusted", self.prior_untrusted)?;
        check_nonneg("condition.prior_detail", self.prior_detail)?;
        check_nonneg("condition.prior_flat", self.prior_flat)?;
        check_nonneg("condition.experimental.prior_recurse_sigma", self.experimental.prior_recurse_sigma)?;
        if !(1..=4).contains(&self.prior_levels) {
            return Err(Error::param("condition.prior_levels", self.prior_levels, "1 to 4"));
        }
        if self.prior_spread > 8 {
            return Err(Error::param("condition.prior_spread", self.prior_spread, "0 to 8"));
        }
        if !(self.sharpness_ratio == 0.0 || (self.sharpness_ratio.is_finite() && self.sharpness_ratio >= 1.0)) {
            return Err(Error::param("condition.sharpness_ratio", self.sharpness_ratio, "0 (off) or at least 1"));
        }
        if !(self.vertical_min_px.is_finite() && (0.0..=crate::rectify::MAX_OFFSET).contains(&self.vertical_min_px)) {
            return Err(Error::param("condition.vertical_min_px", self.vertical_min_px, "0 to 4"));
        }
        check_nonneg("condition.prior_margin_px", self.prior_margin_px)?;
        check_nonneg("condition.prior_trunc_px", self.prior_trunc_px)
    }
}
