//! Slanted-plane smoothing after Yamaguchi, McAllester & Urtasun (ECCV 2014) (paper §4.3, SPEC §4).
//! (Being implemented.)

use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::image::{DisparityMap, Plane, RgbImage};

/// Slanted-plane smoothing parameters.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SpsParams {
    /// Run the stage.
    pub enabled: bool,
}

impl SpsParams {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`crate::Error::InvalidParam`] naming the key.
    pub fn validate(&self) -> Result<()> {
        Ok(())
    }
}

/// Fits slanted planes to superpixels and returns each pixel's disparity from its plane.
pub fn fit_slanted_planes(
    _image: &RgbImage,
    _disp: &DisparityMap,
    _trusted: &Plane<bool>,
    _p: &SpsParams,
) -> DisparityMap {
    todo!("slanted-plane smoothing: issue 5")
}
