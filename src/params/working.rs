//! Parameters of the working resolution (`crate::setup::working`).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// `[working]`: the resolution the pipeline works at, chosen per pair.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WorkingParams {
    /// Work at 1/2ᵏ of the input when its k finest octaves hold no detail of their own (an upsampled or defocused
    /// image; measured on the left view), and bring the answer back edge-aware (`[upsample]`) as `downscale` does;
    /// only when `downscale` = 1. Off: always at the input's resolution.
    pub auto: bool,
    /// The most octaves dropped (the reduction is at most 2^max_octaves).
    pub max_octaves: u32,
    /// The smallest working image, in millions of pixels: an octave is dropped only while the reduced view keeps
    /// this many (smaller, the pipeline's windows and segments cover too much of the scene and its range too few
    /// labels; trainingQ, what it is tuned on, holds 0.17–0.37).
    pub min_megapixels: f64,
}

impl Default for WorkingParams {
    fn default() -> Self {
        WorkingParams { auto: true, max_octaves: 3, min_megapixels: 0.1 }
    }
}

impl WorkingParams {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] naming the key.
    pub fn validate(&self) -> Result<()> {
        if self.max_octaves > 6 {
            return Err(Error::param("working.max_octaves", self.max_octaves, "0 to 6"));
        }
        if !(0.0..=1000.0).contains(&self.min_megapixels) {
            return Err(Error::param("working.min_megapixels", self.min_megapixels, "0 to 1000"));
        }
        Ok(())
    }
}
