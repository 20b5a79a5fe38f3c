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
}

impl Default for WorkingParams {
    fn default() -> Self {
        WorkingParams { auto: true, max_octaves: 3 }
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
        Ok(())
    }
}
