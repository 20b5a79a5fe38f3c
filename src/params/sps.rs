//! Parameters of slanted-plane smoothing ([`crate::post::planes`]).

use serde::{Deserialize, Serialize};

use super::{check_nonneg, check_positive};
use crate::error::{Error, Result};

/// Slanted-plane smoothing parameters (see [`crate::post::planes`] for the energy they weight).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SpsParams {
    /// Run the stage.
    pub enabled: bool,
    /// Target number of segments; the initial grid step is √(pixels / segments).
    pub segments: usize,
    /// The most pixels a segment covers on average (0 = no bound): an image with more than `segments` × this gets
    /// more segments ([`SpsParams::segments_for`]), so that the planes follow the detail a larger image holds.
    pub max_segment_px: f32,
    /// Outer iterations (pixel sweep, labels, planes).
    pub iterations: usize,
    /// λ_pos: weight of the squared distance to the segment centre, in grid steps.
    pub position_weight: f32,
    /// λ_d: weight of the squared disparity-to-plane residual (px²).
    pub disparity_weight: f32,
    /// τ: residuals beyond this (px) are outliers, with the constant cost λ_d·τ², and are left out of the fit.
    pub inlier_thresh_px: f32,
    /// λ_bou: cost per 8-neighbour pair in different segments.
    pub boundary_weight: f32,
    /// λ_s: weight of the mean squared plane difference of hinge and coplanar boundaries.
    pub smoothness_weight: f32,
    /// Constant cost of a hinge boundary.
    pub hinge_penalty: f32,
    /// Constant cost of an occlusion boundary.
    pub occlusion_penalty: f32,
    /// Cost of an occlusion boundary whose occluder is behind along the whole boundary (scaled by the fraction).
    pub impossible_penalty: f32,
    /// Data weight of finite pixels that are not trusted (e.g. filled ones), 0 to 1; trusted pixels weigh 1.
    pub untrusted_weight: f32,
    /// A segment needs at least this much data weight to fit a plane without coupled neighbours.
    pub min_support: f32,
    /// ... and at least this fraction of its pixel count (0 to 1; 0 = only `min_support` applies). A fraction
    /// scales with the segment size, which an absolute count does not (cells are 64 px on ArtL Q at 1500
    /// segments, about 245 px on Motorcycle Q).
    pub min_support_fraction: f32,
    /// RANSAC trials per segment at initialisation.
    pub ransac_iterations: usize,
    /// Seed of the RANSAC sampling.
    pub seed: u64,
}

impl Default for SpsParams {
    fn default() -> Self {
        // segments, untrusted_weight, disparity_weight and inlier_thresh_px were tuned on trainingQ with the full pipeline (docs/RESULTS.md);
        // the rest were set by reasoning about magnitudes.
        SpsParams {
            enabled: true,
            segments: 1500,
            max_segment_px: 250.0,
            iterations: 10,
            position_weight: 300.0,
            disparity_weight: 100.0,
            inlier_thresh_px: 3.0,
            boundary_weight: 30.0,
            smoothness_weight: 400.0,
            hinge_penalty: 5.0,
            occlusion_penalty: 15.0,
            impossible_penalty: 30.0,
            untrusted_weight: 0.3,
            min_support: 10.0,
            min_support_fraction: 0.0,
            ransac_iterations: 64,
            seed: 1,
        }
    }
}

/// The fewest data points a plane needs (three points fix one).
const MIN_PLANE_POINTS: f32 = 3.0;

impl SpsParams {
    /// The segments for an image of `pixels` pixels: `segments`, or more where each would cover more than
    /// `max_segment_px` pixels on average, and at most [`SpsParams::max_segments`].
    ///
    /// `segments` was tuned on MiddEval3 trainingQ (0.17 to 0.37 M pixels: 112 to 245 px a segment), where the bound
    /// changes nothing. A count per image lets the segments grow with a larger image, and the planes then smooth over
    /// the detail its extra pixels hold; bounded, the planes follow it (measured on MiddEval3 trainingH views and
    /// Middlebury 2005 at full size: docs/tuning-log.md, "The planes' segments bounded in size").
    pub fn segments_for(&self, pixels: usize) -> usize {
        let by_size = if self.max_segment_px > 0.0 {
            (pixels as f64 / f64::from(self.max_segment_px)).ceil() as usize
        } else {
            0
        };
        self.segments.max(by_size).min(self.max_segments(pixels))
    }

    /// The most segments an image of `pixels` pixels can hold (at least 1): the grid's cells must each be able to
    /// carry the data weight a plane of its own needs, `min_support` (at least 3 points). Above it no segment can
    /// fit a plane alone and the map is wrecked, so the planes use at most this many (RESULTS.md, "Bad input").
    pub fn max_segments(&self, pixels: usize) -> usize {
        let need = f64::from(self.min_support.max(MIN_PLANE_POINTS));
        ((pixels as f64 / need).floor() as usize).max(1)
    }

    /// Checks ranges.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] naming the key.
    pub fn validate(&self) -> Result<()> {
        if self.segments == 0 || self.segments > 1 << 24 {
            return Err(Error::param("post.sps.segments", self.segments, "1 to 16777216"));
        }
        if self.iterations > 1000 {
            return Err(Error::param("post.sps.iterations", self.iterations, "0 to 1000"));
        }
        if self.ransac_iterations == 0 || self.ransac_iterations > 100_000 {
            return Err(Error::param("post.sps.ransac_iterations", self.ransac_iterations, "1 to 100000"));
        }
        check_nonneg("post.sps.max_segment_px", self.max_segment_px)?;
        check_nonneg("post.sps.position_weight", self.position_weight)?;
        check_nonneg("post.sps.disparity_weight", self.disparity_weight)?;
        check_positive("post.sps.inlier_thresh_px", self.inlier_thresh_px)?;
        check_nonneg("post.sps.boundary_weight", self.boundary_weight)?;
        check_nonneg("post.sps.smoothness_weight", self.smoothness_weight)?;
        check_nonneg("post.sps.hinge_penalty", self.hinge_penalty)?;
        check_nonneg("post.sps.occlusion_penalty", self.occlusion_penalty)?;
        check_nonneg("post.sps.impossible_penalty", self.impossible_penalty)?;
        check_nonneg("post.sps.min_support", self.min_support)?;
        if !(0.0..=1.0).contains(&self.min_support_fraction) {
            return Err(Error::param("post.sps.min_support_fraction", self.min_support_fraction, "0 to 1"));
        }
        if !(0.0..=1.0).contains(&self.untrusted_weight) {
            return Err(Error::param("post.sps.untrusted_weight", self.untrusted_weight, "0 to 1"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_images_get_segments_of_bounded_size() {
        let p = SpsParams::default();
        // MiddEval3 trainingQ's sizes, Teddy to Motorcycle: the configured count.
        for (w, h) in [(450, 375), (741, 497)] {
            assert_eq!(p.segments_for(w * h), p.segments, "{w}×{h}");
        }
        // trainingH Motorcycle: one segment per 250 px.
        assert_eq!(p.segments_for(1482 * 994), (1482 * 994usize).div_ceil(250));
        // No bound: a count per image.
        let per_image = SpsParams { max_segment_px: 0.0, ..p.clone() };
        assert_eq!(per_image.segments_for(1482 * 994), p.segments);
        // Never more than the image can hold.
        let tiny = SpsParams { max_segment_px: 1.0, ..p.clone() };
        assert_eq!(tiny.segments_for(100 * 100), tiny.max_segments(100 * 100));
        assert!(SpsParams { max_segment_px: -1.0, ..p }.validate().is_err());
    }
}
