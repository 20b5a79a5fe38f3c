//! The pair prepared for matching: conditioned as `[condition]` says ([`crate::condition`]), with the cost
//! parameters and the coarse prior's weight that follow from what was measured.

use std::borrow::Cow;

use crate::condition;
use crate::condition::vertical::{self, VerticalOffset};
use crate::cost;
use crate::image::{Plane, StereoPair};
use crate::imgproc::noise::GREY_PAIR_NOISE_PER_SIGMA;
use crate::params::{self, Params};

use super::output::{Measured, PipelineOutput, Timings, VerticalMeasured};

/// A pair after [`condition::condition_pair`] (when `[condition]` is active), with what follows from its
/// measurements: the cost parameters (the Census dead band grows with JPEG's block steps, the support and the
/// gradient's ε with the noise) and the coarse prior's weight λ = `prior.per_sigma`·σn (0 when conditioning is off).
pub(crate) struct Prepared<'a> {
    conditioned: Option<condition::Conditioned<'a>>,
    /// The cost parameters for this pair.
    pub cost_params: params::CostParams,
    /// ḡ of the gradient normalisation, measured once on the conditioned left view (so that the tiles and the
    /// whole image share it; `None` when conditioning is off: each volume measures its own).
    pub grad_norm_mean: Option<f32>,
    /// λ of the coarse prior before the per-pixel factor.
    pub prior_weight: f32,
    /// The floor of λ where the cost is flat (`condition.prior.flat`; 0 when conditioning is off).
    pub prior_flat: f32,
    /// The right view's residual vertical offset, once [`Prepared::align_vertically`] has measured it.
    vertical: Option<VerticalMeasured>,
    /// The vertical offset removed from the right views ([`Prepared::apply_vertical_offset`]).
    offset: Option<VerticalOffset>,
}

impl<'a> Prepared<'a> {
    /// Conditions `pair` as `params.condition` says (stage `condition`), its measured noise at most
    /// `noise_ceiling` (a coarse level's: [`condition::condition_pair`]).
    pub(crate) fn of(
        params: &Params,
        pair: &'a StereoPair<'a>,
        noise_ceiling: Option<[f32; 2]>,
        t: &mut Timings,
    ) -> Self {
        let c = &params.condition;
        let mut cost_params = params.cost.clone();
        let (mut prior_weight, mut prior_flat, mut grad_norm_mean) = (0.0f32, 0.0f32, None);
        let conditioned =
            c.is_active().then(|| t.time("condition", || condition::condition_pair(pair, c, noise_ceiling)));
        if let Some(cond) = &conditioned {
            prior_weight = c.prior.per_sigma * cond.stats.sigma();
            prior_flat = c.prior.flat;
            // JPEG: steps no larger than the block grid's own are compression artefacts, not texture.
            cost_params.census_dead_band +=
                cond.stats.block_band(c) * cond.stats.blocking[0].max(cond.stats.blocking[1]);
            // Two pixels' grey noise in a Census comparison of the cost pair.
            cost_params.census_ternary +=
                c.noise.ternary_per_sigma * GREY_PAIR_NOISE_PER_SIGMA * cond.stats.cost_sigma();
            if cost_params.census_support > 0.0 {
                cost_params.census_support += c.noise.support_per_sigma * cond.stats.sigma();
            }
            if cost_params.grad_norm_radius > 0 {
                cost_params.grad_norm_eps += c.noise.grad_eps_per_sigma * cond.stats.sigma();
                let grey = cond.cost_pair().left.to_grey();
                grad_norm_mean = Some(cost::mean_local_contrast(&grey, cost_params.grad_norm_radius));
            }
        }
        Prepared { conditioned, cost_params, grad_norm_mean, prior_weight, prior_flat, vertical: None, offset: None }
    }

    /// Measures the right view's residual vertical offset against a coarse answer at this size
    /// ([`vertical::estimate`] on the cost pair, `grey_left` its left view in grey) and, where it reaches
    /// `condition.vertical.min_px`, moves the right views of the guidance and the cost pair onto the left view's
    /// rows (stage `vertical`). Nothing when conditioning or `vertical.enabled` is off.
    pub(crate) fn align_vertically(
        &mut self,
        c: &params::ConditionParams,
        grey_left: &Plane<f32>,
        coarse: &PipelineOutput,
        t: &mut Timings,
    ) {
        // (`conditioned` exists only when conditioning is enabled.)
        let Some(cond) = self.conditioned.as_mut().filter(|_| c.vertical.enabled) else { return };
        let offset = t.time("vertical", || {
            vertical::estimate(grey_left, &cond.cost_pair().right.to_grey(), &coarse.disparity, &coarse.consistent)
        });
        if let Some(v) = offset {
            self.apply_vertical_offset(c, v, t);
        }
    }

    /// Moves the right views of the guidance and the cost pair onto the left view's rows by the vertical offset
    /// `v` (measured on this pair, or on the previous frame of a sequence), where it reaches
    /// `condition.vertical.min_px` (stage `vertical`). Nothing when conditioning or `vertical.enabled` is off.
    pub(crate) fn apply_vertical_offset(&mut self, c: &params::ConditionParams, v: VerticalOffset, t: &mut Timings) {
        let Some(cond) = self.conditioned.as_mut().filter(|_| c.vertical.enabled) else { return };
        let corrected = v.max_abs() >= c.vertical.min_px;
        self.vertical = Some(VerticalMeasured { range: v.range(), corrected });
        if corrected {
            t.time("vertical", || {
                if let Some(cost) = &mut cond.cost {
                    cost.right = Cow::Owned(vertical::resample_right(&cost.right, &v));
                }
                let right = vertical::resample_right(&cond.guide.right, &v);
                match &mut cond.guide {
                    Cow::Owned(guide) => guide.right = Cow::Owned(right),
                    Cow::Borrowed(guide) => {
                        let left = Cow::Borrowed(guide.left.as_ref());
                        cond.guide = Cow::Owned(StereoPair { left, right: Cow::Owned(right), ndisp: guide.ndisp });
                    }
                }
            });
            self.offset = Some(v);
        }
    }

    /// The vertical offset removed from the right views, if one was.
    pub(crate) fn vertical_offset(&self) -> Option<VerticalOffset> {
        self.offset
    }

    /// What was measured and derived, for [`PipelineOutput::measured`] (`None` when conditioning is off).
    pub(crate) fn measured(&self) -> Option<Measured> {
        self.conditioned.as_ref().map(|cond| Measured {
            stats: cond.stats,
            prior_weight: self.prior_weight,
            prior_flat: self.prior_flat,
            census_support: self.cost_params.census_support,
            gradient: (self.cost_params.grad_norm_radius > 0)
                .then(|| self.grad_norm_mean.map(|m| (m, self.cost_params.grad_norm_eps)))
                .flatten(),
            vertical: self.vertical,
        })
    }

    /// The noisier view's measured σn ([`condition::PairStats::sigma`]; 0 when conditioning is off).
    pub(crate) fn noise(&self) -> f32 {
        self.conditioned.as_ref().map_or(0.0, |cond| cond.stats.sigma())
    }

    /// The noise ceiling of a level reduced `factor`× from this one (the `noise_ceiling` of
    /// [`condition::condition_pair`]): each view's measured σn / `factor`, what an F × F box average leaves of
    /// independent noise (`None` when conditioning is off).
    pub(crate) fn noise_ceiling(&self, factor: usize) -> Option<[f32; 2]> {
        self.conditioned.as_ref().map(|cond| cond.stats.noise.map(|v| v / factor as f32))
    }

    /// The block band that applied at this level ([`condition::PairStats::block_band`]; 0 when conditioning
    /// is off): a coarse level, reduced off the block grid, keeps it.
    pub(crate) fn block_band(&self, c: &params::ConditionParams) -> f32 {
        self.conditioned.as_ref().map_or(0.0, |cond| cond.stats.block_band(c))
    }

    /// The guidance pair (colour weights, post-processing) and the pair the matching cost sees; `pair` itself
    /// for both when conditioning is off.
    pub(crate) fn pairs<'b>(&'b self, pair: &'b StereoPair<'b>) -> (&'b StereoPair<'b>, &'b StereoPair<'b>) {
        match &self.conditioned {
            Some(cond) => (&*cond.guide, cond.cost_pair()),
            None => (pair, pair),
        }
    }
}
