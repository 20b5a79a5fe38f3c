//! Weighted median filter at the pixels that were invalid (paper §4.2, SPEC §4). (Being implemented.)

use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::image::{DisparityMap, Plane, RgbImage};

/// Weighted-median parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WmedianParams {
    /// Run the filter.
    pub enabled: bool,
    /// Window radius in pixels (window (2r+1)²).
    pub radius: usize,
    /// Spatial σ of the weights, in pixels.
    pub sigma_xy: f32,
    /// Colour σ of the weights, in RGB units (0..255).
    pub sigma_rgb: f32,
}

impl Default for WmedianParams {
    fn default() -> Self {
        WmedianParams { enabled: false, radius: 9, sigma_xy: 9.0, sigma_rgb: 20.0 }
    }
}

impl WmedianParams {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`crate::Error::InvalidParam`] naming the key.
    pub fn validate(&self) -> Result<()> {
        if self.radius == 0 || self.radius > 64 {
            return Err(crate::Error::param("post.wmedian.radius", self.radius, "1 to 64"));
        }
        crate::params::check_positive("post.wmedian.sigma_xy", self.sigma_xy)?;
        crate::params::check_positive("post.wmedian.sigma_rgb", self.sigma_rgb)
    }
}

/// Replaces the disparity at every `targets` pixel by the weighted median of the valid disparities in its window.
pub fn weighted_median(
    _disp: &DisparityMap,
    _image: &RgbImage,
    _targets: &Plane<bool>,
    _p: &WmedianParams,
) -> DisparityMap {
    todo!("weighted median: issue 5")
}
