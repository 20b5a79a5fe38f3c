//! Parameters of the sub-pixel refinement ([`crate::post::subpixel`]).

use serde::{Deserialize, Serialize};

use super::check_positive;
use crate::error::{Error, Result};

/// Sub-pixel refinement parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SubpixelParams {
    /// Run the refinement (the last stage: after the planes and the median at depth edges).
    pub enabled: bool,
    /// Radius of the matching window in pixels (window (2r+1)²).
    pub radius: usize,
    /// σ of the prior on the correction, in pixels: how far the planes' answer is expected to be from the true
    /// sub-pixel disparity. The image evidence of a window moves the answer by up to ½ px; the weaker that evidence
    /// against its own residual noise, the more the answer stays at the planes' value.
    pub prior_px: f32,
}

impl Default for SubpixelParams {
    fn default() -> Self {
        SubpixelParams { enabled: true, radius: 2, prior_px: 0.2 }
    }
}

impl SubpixelParams {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] naming the key.
    pub fn validate(&self) -> Result<()> {
        if self.radius == 0 || self.radius > 16 {
            return Err(Error::param("post.subpixel.radius", self.radius, "1 to 16"));
        }
        check_positive("post.subpixel.prior_px", self.prior_px)
    }
}
