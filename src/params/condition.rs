//! Parameters of input conditioning and the coarse prior ([`crate::condition`]), one sub-table per purpose:
//! `[condition.stretch]`, `[condition.denoise]`, `[condition.noise]` (how the measured noise widens the cost),
//! `[condition.prior]` and `[condition.vertical]`. A config that still uses a flat key of older versions is refused
//! with the key's new name; one that sets a removed experiment switch (`[condition.experimental]`) is refused with
//! where it can still be found.

use serde::{Deserialize, Serialize};

use super::check_nonneg;
use crate::error::{Error, Result};

/// Input conditioning and the coarse prior (`crate::condition`): measured on each pair, so one setting serves
/// clean, noisy and dark pairs (docs/tuning-log.md, "Robustness").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ConditionParams {
    /// The master switch: false turns every part off (the paper's configs use it).
    pub enabled: bool,
    /// When one view of the cost pair is sharper than the other by more than this factor
    /// (`crate::condition::sharpness`), it is blurred until they match (0 = never).
    pub sharpness_ratio: f32,
    /// `[condition.stretch]`: contrast of a low-contrast pair.
    pub stretch: StretchParams,
    /// `[condition.denoise]`: the bilateral denoiser of the images the cost sees.
    pub denoise: DenoiseParams,
    /// `[condition.noise]`: how the measured noise (JPEG's included) widens the cost's tolerances.
    pub noise: NoiseParams,
    /// `[condition.prior]`: the coarse prior.
    pub prior: PriorParams,
    /// `[condition.vertical]`: the right view's residual vertical offset.
    pub vertical: VerticalParams,
}

/// `[condition.stretch]`: the contrast stretch (`crate::condition`, "Contrast").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StretchParams {
    /// Stretch the contrast of a low-contrast pair.
    pub enabled: bool,
    /// The stretch is applied only when its gain would be at least this (a pair using most of the range is left
    /// as it is).
    pub min_gain: f32,
}

/// `[condition.denoise]`: the bilateral denoiser (`crate::condition`, "Noise"); the guidance keeps the original.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DenoiseParams {
    /// Bilateral range scale as a multiple of the measured noise σ; 0 = no denoising.
    pub strength: f32,
    /// Spatial σ of the denoising filter, in pixels.
    pub sigma_xy: f32,
    /// A view whose measured noise σ (grey levels) is below this is not denoised.
    pub min_sigma: f32,
}

/// `[condition.noise]`: what the measured noise σn changes in the cost (`condition::noise::estimate_noise`,
/// `crate::condition::jpeg_noise`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseParams {
    /// Count a JPEG-decoded view's compression error as noise (`crate::condition::jpeg_noise`); the coarse
    /// levels, whose images are reduced off the block grid, do not measure it.
    pub jpeg: bool,
    /// Census dead band as a multiple of the measured JPEG blocking (`crate::condition::blockiness`, the larger
    /// view's): a bit is set only where the neighbour is darker by more than the block grid's own steps; 0 = none.
    pub block_band: f32,
    /// Widens `cost.census_support` by this multiple of σn (when the support is on): under noise the bits of strong
    /// contrast are the ones noise does not flip.
    pub support_per_sigma: f32,
    /// Widens `cost.grad_norm_eps` by this multiple of σn (when the normalisation is on): the gradient term is
    /// normalised only where the local contrast stands well above the noise.
    pub grad_eps_per_sigma: f32,
    /// The ternary Census's threshold (`cost.census_ternary`) widened by this multiple of the noise of a grey-level
    /// difference (0.945·σn: two pixels' grey noise, 0.668·σn each); 0 = the binary Census.
    pub ternary_per_sigma: f32,
}

/// `[condition.prior]`: the coarse prior (`crate::pipeline`'s coarse chain): the pipeline first runs on the pair
/// reduced 2×, and the full-resolution cost of label d gets λ · min(max(|d − d_coarse| − `margin_px`, 0),
/// `trunc_px`) with λ = `per_sigma` × σn (scaled as below).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PriorParams {
    /// λ per grey level of measured noise σn; 0 = off (with `flat` 0 too).
    pub per_sigma: f32,
    /// Levels of coarse priors below the full resolution: 1 = the coarse run (at 1/2) has none of its own, 2 = it
    /// has one (at 1/4), and so on (1 to 4).
    pub levels: usize,
    /// Scale each pixel's prior weight by the coarse run's confidence (its max-marginal, 0..1).
    pub confidence: bool,
    /// Prior weight factor at pixels the coarse run's left-right check rejected.
    pub untrusted: f32,
    /// Weakens the prior where the image has detail the coarse run cannot hold: × 1 / (1 + D / (k·D̄)), D the
    /// local mean of what an F × F block average removes from the cost image (F the coarse factor), D̄ its image
    /// mean; this is k (0 = off).
    pub detail: f32,
    /// Where the full-resolution cost is flat the prior weighs at least this × 1 / (1 + s / s̄), s the pixel's
    /// cost spread over the labels (mean − min) and s̄ its image median (`crate::cost::flatness`): an untextured
    /// surface follows the coarse answer even in a clean pair, whose noise-scaled weight is near 0; 0 = off.
    pub flat: f32,
    /// Beside a depth edge of the coarse answer the prior accepts the whole step: where the coarse disparities
    /// within this many coarse pixels of a pixel differ by more than `trunc_px`, labels between their smallest
    /// and largest are free (the coarse level places an edge only to within its own pixels, and under noise its
    /// edges fatten); 0 = off.
    pub spread: usize,
    /// Labels within this distance of the coarse disparity (full-resolution px) are free.
    pub margin_px: f32,
    /// The penalty stops growing beyond this distance past the margin.
    pub trunc_px: f32,
}

/// `[condition.vertical]`: the right view's residual vertical offset (`crate::condition::vertical`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VerticalParams {
    /// Measure the offset against the coarse run's answer and remove it before the full-resolution cost (needs
    /// the coarse prior).
    pub enabled: bool,
    /// The offset is removed only where it reaches this many pixels somewhere in the image (below it the Census
    /// windows hardly differ, and a perfectly rectified pair stays as it is).
    pub min_px: f32,
}

/// The git tag of the last version with `[condition.experimental]` (switches measured and not kept: histogram
/// matching, a noise-tied Census band, a fixed prior weight, a recursive coarse prior, a label window at full
/// resolution); docs/tuning-log.md's measurements of them run there.
pub(crate) const EXPERIMENTS_TAG: &str = "experiments-last";

/// The flat `[condition]` keys of configs written before the sub-tables, and their names now (a config that uses
/// one is refused with the new name, rather than read differently).
const RENAMED: [(&str, &str); 20] = [
    ("stretch", "stretch.enabled"),
    ("stretch_min_gain", "stretch.min_gain"),
    ("denoise_strength", "denoise.strength"),
    ("denoise_sigma_xy", "denoise.sigma_xy"),
    ("denoise_min_sigma", "denoise.min_sigma"),
    ("jpeg_noise", "noise.jpeg"),
    ("block_band", "noise.block_band"),
    ("support_per_sigma", "noise.support_per_sigma"),
    ("grad_eps_per_sigma", "noise.grad_eps_per_sigma"),
    ("prior_per_sigma", "prior.per_sigma"),
    ("prior_levels", "prior.levels"),
    ("prior_confidence", "prior.confidence"),
    ("prior_untrusted", "prior.untrusted"),
    ("prior_detail", "prior.detail"),
    ("prior_flat", "prior.flat"),
    ("prior_spread", "prior.spread"),
    ("prior_margin_px", "prior.margin_px"),
    ("prior_trunc_px", "prior.trunc_px"),
    ("vertical_align", "vertical.enabled"),
    ("vertical_min_px", "vertical.min_px"),
];

/// The new name of a flat `[condition]` key that was moved into a sub-table (`None` for any other key). The
/// `stretch` key is ambiguous only as a value: a table is the new form, a boolean the old one.
pub(crate) fn renamed_key(key: &str, value: &toml::Value) -> Option<&'static str> {
    if key == "stretch" && value.is_table() {
        return None;
    }
    RENAMED.iter().find(|(old, _)| *old == key).map(|(_, new)| *new)
}

impl VerticalParams {
    /// The largest offset (px) the measurement trusts: the coarse disparities it rests on were found on rows that far
    /// apart, and its linearisation holds for about a pixel per iteration. `min_px` cannot exceed it.
    pub const MAX_OFFSET_PX: f32 = 4.0;
}

impl Default for StretchParams {
    /// Stretch only a view that uses less than 1/1.5 of the range.
    fn default() -> Self {
        StretchParams { enabled: true, min_gain: 1.5 }
    }
}

impl Default for DenoiseParams {
    /// Denoise (for the cost) only a view measured noisier than 2 grey levels, range 3·σn, spatial σ 3 px.
    fn default() -> Self {
        DenoiseParams { strength: 3.0, sigma_xy: 3.0, min_sigma: 2.0 }
    }
}

impl Default for NoiseParams {
    fn default() -> Self {
        NoiseParams {
            jpeg: true,
            block_band: 1.0,
            support_per_sigma: 2.5,
            grad_eps_per_sigma: 30.0,
            ternary_per_sigma: 0.5,
        }
    }
}

impl Default for PriorParams {
    /// Weight 0.5·σn scaled by the coarse confidence, halved where the coarse left-right check failed, from a
    /// half-resolution run that has such a prior of its own, and that one from a quarter-resolution run with one
    /// of its own (`levels` 3: docs/tuning-log.md "Coarse priors of their own", "A third coarse level").
    fn default() -> Self {
        PriorParams {
            per_sigma: 0.5,
            levels: 3,
            confidence: true,
            untrusted: 0.5,
            detail: 1.5,
            flat: 1.0,
            spread: 1,
            margin_px: 1.0,
            trunc_px: 8.0,
        }
    }
}

impl Default for VerticalParams {
    fn default() -> Self {
        VerticalParams { enabled: true, min_px: 0.1 }
    }
}

impl Default for ConditionParams {
    /// The default pipeline's conditioning (chosen in docs/tuning-log.md, "Robustness: the adaptive default"); see
    /// each sub-table's default.
    fn default() -> Self {
        ConditionParams {
            enabled: true,
            sharpness_ratio: 1.25,
            stretch: StretchParams::default(),
            denoise: DenoiseParams::default(),
            noise: NoiseParams::default(),
            prior: PriorParams::default(),
            vertical: VerticalParams::default(),
        }
    }
}

impl ConditionParams {
    /// Everything off: the pair goes to the cost as it is (the paper's configs: `enabled = false`).
    pub fn off() -> Self {
        let on = Self::default();
        ConditionParams {
            enabled: false,
            sharpness_ratio: 0.0,
            stretch: StretchParams { enabled: false, ..on.stretch },
            denoise: DenoiseParams { strength: 0.0, ..on.denoise },
            noise: NoiseParams {
                jpeg: false,
                block_band: 0.0,
                support_per_sigma: 0.0,
                grad_eps_per_sigma: 0.0,
                ternary_per_sigma: 0.0,
            },
            prior: PriorParams { per_sigma: 0.0, confidence: false, detail: 0.0, spread: 0, ..on.prior },
            vertical: VerticalParams { enabled: false, ..on.vertical },
        }
    }

    /// Whether any part is on (when none is, the pair goes to the cost unchanged).
    pub fn is_active(&self) -> bool {
        self.enabled
            && (self.stretch.enabled
                || self.denoise.strength > 0.0
                || self.noise.block_band > 0.0
                || self.noise.jpeg
                || self.prior.per_sigma > 0.0
                || self.prior.flat > 0.0)
    }

    /// Checks every value's range.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] naming the first offending key, its value and the valid range.
    pub fn validate(&self) -> Result<()> {
        let (d, n, p) = (&self.denoise, &self.noise, &self.prior);
        check_nonneg("condition.denoise.strength", d.strength)?;
        if !(d.sigma_xy.is_finite() && (0.0..=10.0).contains(&d.sigma_xy)) {
            return Err(Error::param("condition.denoise.sigma_xy", d.sigma_xy, "0 to 10"));
        }
        if !(self.stretch.min_gain.is_finite() && self.stretch.min_gain >= 1.0) {
            return Err(Error::param("condition.stretch.min_gain", self.stretch.min_gain, "at least 1"));
        }
        check_nonneg("condition.denoise.min_sigma", d.min_sigma)?;
        check_nonneg("condition.noise.block_band", n.block_band)?;
        check_nonneg("condition.noise.support_per_sigma", n.support_per_sigma)?;
        check_nonneg("condition.noise.grad_eps_per_sigma", n.grad_eps_per_sigma)?;
        check_nonneg("condition.noise.ternary_per_sigma", n.ternary_per_sigma)?;
        check_nonneg("condition.prior.per_sigma", p.per_sigma)?;
        check_nonneg("condition.prior.untrusted", p.untrusted)?;
        check_nonneg("condition.prior.detail", p.detail)?;
        check_nonneg("condition.prior.flat", p.flat)?;
        if !(1..=4).contains(&p.levels) {
            return Err(Error::param("condition.prior.levels", p.levels, "1 to 4"));
        }
        if p.spread > 8 {
            return Err(Error::param("condition.prior.spread", p.spread, "0 to 8"));
        }
        if !(self.sharpness_ratio == 0.0 || (self.sharpness_ratio.is_finite() && self.sharpness_ratio >= 1.0)) {
            return Err(Error::param("condition.sharpness_ratio", self.sharpness_ratio, "0 (off) or at least 1"));
        }
        let v = &self.vertical;
        if !(v.min_px.is_finite() && (0.0..=VerticalParams::MAX_OFFSET_PX).contains(&v.min_px)) {
            return Err(Error::param("condition.vertical.min_px", v.min_px, "0 to 4"));
        }
        check_nonneg("condition.prior.margin_px", p.margin_px)?;
        check_nonneg("condition.prior.trunc_px", p.trunc_px)
    }
}
