//! Parameters of mean-field inference ([`crate::meanfield`]).

use serde::{Deserialize, Serialize};

use super::{check_nonneg, check_positive, check_reference_px, side_growth};
use crate::error::{Error, Result};

/// Normalisation of the bilateral (fully connected) message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Normalization {
    /// Σ_j k(i,j) Q_j: the paper's equation as written.
    None,
    /// Divide by Σ_j k(i,j): a weighted mean of the neighbours' marginals.
    Pixel,
    /// D^{-1/2} K D^{-1/2}: symmetric, as in Krähenbühl's dense-CRF code.
    Symmetric,
}

/// Order of the mean-field updates within one iteration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Schedule {
    /// All pixels from the previous iterate at once (the paper's parallel update).
    Jacobi,
    /// Red-black: pixels with x + y even first, then the odd ones from the new even values (the local term
    /// then propagates two pixels per iteration and cannot oscillate between two checkerboard states). The
    /// fully connected message is computed once per iteration from the previous iterate in both schedules.
    Checkerboard,
}

/// Mean-field inference on the joint MRF (paper §3, Algorithm 1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MeanFieldParams {
    /// Number of mean-field iterations T.
    pub iterations: usize,
    /// Unary scale: ψ_u = unary_scale × cost (the cost is a log-probability up to this temperature).
    pub unary_scale: f32,
    /// Deterministic annealing of the unary temperature; 0 = off (every iteration uses `unary_scale`). When > 0,
    /// the initial marginals use this scale and iteration t = 1..T uses the geometric interpolation
    /// `unary_scale_start` × (`unary_scale` / `unary_scale_start`)^(t / T), so the last iteration uses
    /// `unary_scale` (start below `unary_scale` = start hot, end cold). See `crate::meanfield`.
    pub unary_scale_start: f32,
    /// With annealing: the number of iterations K over which the scale goes from `unary_scale_start` to
    /// `unary_scale` (t / K in place of t / T), the remaining T − K iterations staying at `unary_scale`;
    /// 0 = all T iterations. Must not exceed `iterations`.
    pub unary_anneal_iterations: usize,
    /// ω, the weight of the fully connected Potts term.
    pub fcm_weight: f32,
    /// ω̃, the weight of the locally connected term.
    pub lcm_weight: f32,
    /// Label-aware local coupling; 0 = off. When > 0, ω̃ is multiplied by M / `lcm_weight_ref_labels` for a scene
    /// with M labels, so the local term's gain around the uniform marginal, ~ω̃·Σλ·(3 − 2β) / M, is the same for
    /// every M (ω̃ is the weight at M = `lcm_weight_ref_labels`). See `crate::meanfield`.
    pub lcm_weight_ref_labels: usize,
    /// β, the local penalty for |d_i − d_j| = 1 (the penalty for > 1 is 1).
    pub beta: f32,
    /// σx of the bilateral kernel, in pixels.
    pub sigma_xy: f32,
    /// σf of the bilateral kernel, in RGB units (0..255).
    pub sigma_rgb: f32,
    /// Local edge weight thresholds μ1 < μ2 on Σ_rgb |I_i − I_j|.
    pub mu1: f32,
    /// See `mu1`.
    pub mu2: f32,
    /// Local edge weights λ1 (similar colours), λ2, λ3 (strong edge).
    pub lambda1: f32,
    /// See `lambda1`.
    pub lambda2: f32,
    /// See `lambda1`.
    pub lambda3: f32,
    /// Leave each pixel's own marginal out of its fully connected message (j ≠ i, as the paper writes).
    pub exclude_self: bool,
    /// Normalisation of the fully connected message.
    pub normalization: Normalization,
    /// Sub-pixel refinement: a parabola through the log-marginals around the argmax.
    pub subpixel: bool,
    /// Update order within an iteration.
    pub schedule: Schedule,
    /// Coarse-to-fine inference: the number of levels (1 = off). Level k runs on the image and cost volume
    /// reduced 2^k times (block means, the same labels); the coarsest level runs the configured `iterations`
    /// (and annealing) from the unary, every finer level starts from its parent's marginals and runs
    /// `pyramid_iterations` at `unary_scale`. See `crate::meanfield::infer_coarse_to_fine`.
    pub pyramid_levels: usize,
    /// Iterations at each level finer than the coarsest (with `pyramid_levels` > 1).
    pub pyramid_iterations: usize,
    /// The inference's labels are stated for an image of this many pixels: a larger one's fine pass infers on
    /// labels grouped `label_step` at a time and recovers the full labels from the cost
    /// ([`MeanFieldParams::for_image`]). 0: every label at every size.
    pub reference_px: f32,
    /// On grouped labels (an image above `reference_px`, `label_step` > 1) the `jem` model's inference at the full
    /// resolution runs its local term alone: the coarse prior, matched with both terms (its levels always have both),
    /// already gives each pixel the scene-wide context the fully connected term adds, and the finer level decides
    /// detail, which is local. No lattice is built at that size (docs/tuning-log.md, "The local term alone on
    /// grouped labels"). False: both terms at every size.
    pub grouped_local: bool,
    /// Labels grouped this many at a time for the inference: set by [`MeanFieldParams::for_image`]. Not a key (1 as
    /// configured).
    #[serde(skip)]
    pub label_step: usize,
}

impl Default for MeanFieldParams {
    fn default() -> Self {
        MeanFieldParams {
            iterations: 3,
            unary_scale: 0.5,
            unary_scale_start: 0.0,
            unary_anneal_iterations: 0,
            fcm_weight: 10.0,
            lcm_weight: 2.0,
            lcm_weight_ref_labels: 0,
            beta: 0.3,
            sigma_xy: 5.0,
            sigma_rgb: 55.0,
            mu1: 7.0,
            mu2: 15.0,
            lambda1: 3.5,
            lambda2: 3.0,
            lambda3: 1.0,
            exclude_self: true,
            normalization: Normalization::Symmetric,
            subpixel: true,
            schedule: Schedule::Checkerboard,
            pyramid_levels: 1,
            pyramid_iterations: 10,
            reference_px: 375_000.0,
            grouped_local: true,
            label_step: 1,
        }
    }
}

impl MeanFieldParams {
    /// The parameters for an image of `pixels` pixels: above `reference_px`, labels grouped k at a time, k =
    /// √(pixels / `reference_px`) rounded (the factor its side exceeds the reference by); below, every label.
    ///
    /// A disparity label is a pixel, so a larger image of the same scene has proportionally more of them, and the
    /// inference's work grows with pixels × labels. Which surface a pixel belongs to needs no finer labels than the
    /// reference size's; the larger image's finer disparity is recovered from the cost afterwards
    /// (`crate::pipeline`'s label step; measured on MiddEval3 trainingH views and Middlebury 2005 at full size:
    /// docs/tuning-log.md, "Inference on grouped labels").
    pub fn for_image(&self, pixels: usize) -> MeanFieldParams {
        let Some(k) = side_growth(self.reference_px, pixels) else { return self.clone() };
        MeanFieldParams { label_step: (k.round() as usize).clamp(1, 8), ..self.clone() }
    }

    /// The parameters of a coarse level (the prior's chain, a tiled run's coarse level): both terms of the model on
    /// grouped labels too, since a coarse level gives the finer one its scene-wide context (`grouped_local` is for
    /// the full resolution). The pipeline runs its coarse levels with these and the tile planner plans them so.
    pub fn for_coarse_level(&self) -> MeanFieldParams {
        MeanFieldParams { grouped_local: false, ..self.clone() }
    }

    /// Checks every value's range.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] naming the first offending key, its value and the valid range.
    pub fn validate(&self) -> Result<()> {
        if self.iterations > 1000 {
            return Err(Error::param("meanfield.iterations", self.iterations, "0 to 1000"));
        }
        check_positive("meanfield.unary_scale", self.unary_scale)?;
        if !(self.unary_scale_start.is_finite() && self.unary_scale_start >= 0.0) {
            return Err(Error::param(
                "meanfield.unary_scale_start",
                self.unary_scale_start,
                "0 (off) or a finite number > 0",
            ));
        }
        if self.unary_anneal_iterations > self.iterations {
            return Err(Error::param(
                "meanfield.unary_anneal_iterations",
                self.unary_anneal_iterations,
                format!("0 (all) to meanfield.iterations = {}", self.iterations),
            ));
        }
        if !(1..=6).contains(&self.pyramid_levels) {
            return Err(Error::param("meanfield.pyramid_levels", self.pyramid_levels, "1 (off) to 6"));
        }
        if self.pyramid_iterations > 1000 {
            return Err(Error::param("meanfield.pyramid_iterations", self.pyramid_iterations, "0 to 1000"));
        }
        check_nonneg("meanfield.fcm_weight", self.fcm_weight)?;
        check_nonneg("meanfield.lcm_weight", self.lcm_weight)?;
        if !(0.0..=1.0).contains(&self.beta) {
            return Err(Error::param("meanfield.beta", self.beta, "0 to 1"));
        }
        check_positive("meanfield.sigma_xy", self.sigma_xy)?;
        check_positive("meanfield.sigma_rgb", self.sigma_rgb)?;
        check_nonneg("meanfield.mu1", self.mu1)?;
        if !(self.mu2 >= self.mu1 && self.mu2.is_finite()) {
            return Err(Error::param("meanfield.mu2", self.mu2, format!(">= meanfield.mu1 = {}", self.mu1)));
        }
        check_nonneg("meanfield.lambda1", self.lambda1)?;
        check_nonneg("meanfield.lambda2", self.lambda2)?;
        check_nonneg("meanfield.lambda3", self.lambda3)?;
        check_reference_px("meanfield.reference_px", self.reference_px)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_labels_group_above_the_reference() {
        let p = MeanFieldParams::default();
        // MiddEval3 trainingQ's sizes, Teddy to Motorcycle: every label.
        for (w, h) in [(450, 375), (741, 497)] {
            assert_eq!(p.for_image(w * h), p, "{w}×{h}");
        }
        // The side grown by k: labels grouped round(k) at a time (1.34 → 1, 1.98 → 2), nothing else changed.
        assert_eq!(p.for_image(900 * 750).label_step, 1);
        let big = p.for_image(1482 * 994);
        assert_eq!(big.label_step, 2);
        assert_eq!(MeanFieldParams { label_step: 1, ..big }, p);
        assert_eq!(p.for_image(9 * 375_000).label_step, 3);
        assert_eq!(p.for_image(10_000 * 375_000).label_step, 8);
        // Off: every label at every size.
        let every = MeanFieldParams { reference_px: 0.0, ..p.clone() };
        assert_eq!(every.for_image(16 * 375_000), every);
        assert!(MeanFieldParams { reference_px: -1.0, ..p.clone() }.validate().is_err());
        assert!(MeanFieldParams { reference_px: f32::INFINITY, ..p }.validate().is_err());
    }
}
