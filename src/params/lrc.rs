//! Parameters of the left-right check ([`crate::post::lr_check`]).

use serde::{Deserialize, Serialize};

use super::check_nonneg;
use crate::error::Result;

/// What the left-right check does with an inconsistent pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LrcMode {
    /// No check.
    Off,
    /// Replace it by the smaller of the two views' disparities (the two-step method's LRC; output stays dense).
    Correct,
    /// Mark it invalid (inf) for the later stages (occlusion fill, weighted median, planes).
    Invalidate,
}

/// Left-right consistency check (paper §4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LrcParams {
    /// What to do with inconsistent pixels.
    pub mode: LrcMode,
    /// A pixel is inconsistent when |d_L(x) − d_R(x − round d_L(x))| exceeds this, in pixels.
    pub thresh_px: f32,
}

impl Default for LrcParams {
    fn default() -> Self {
        LrcParams { mode: LrcMode::Invalidate, thresh_px: 1.0 }
    }
}

impl LrcParams {
    /// Checks every value's range.
    ///
    /// # Errors
    /// [`crate::Error::InvalidParam`] naming the first offending key, its value and the valid range.
    pub fn validate(&self) -> Result<()> {
        check_nonneg("post.lrc.thresh_px", self.thresh_px)
    }
}
