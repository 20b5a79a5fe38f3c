//! Parameters of the matching cost ([`crate::cost`]).

use serde::{Deserialize, Serialize};

use super::check_nonneg;
use crate::error::{Error, Result};

/// Matching cost: Census on the grey image plus truncated gradient difference (paper §2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CostParams {
    /// Census window width in pixels (odd).
    pub census_width: usize,
    /// Census window height in pixels (odd); width × height − 1 ≤ 64 bits.
    pub census_height: usize,
    /// Census dead band in grey levels: a bit is set only when the neighbour is darker than the centre by more
    /// than this (0 = the plain Census).
    pub census_dead_band: f32,
    /// Ternary Census threshold in grey levels: each neighbour is darker than the centre by more than this,
    /// brighter by more than this, or neither (two bit planes; a neighbour that is "neither" in one view and darker
    /// or brighter in the other counts ½, opposite signs 1). Comparisons of nearly equal pixels, which noise flips,
    /// then cost little. 0 = the binary Census; widened with the measured noise by `condition.noise.ternary_per_sigma`.
    pub census_ternary: f32,
    /// Census support in grey levels: a bit is compared only where its neighbour is within this of the centre in
    /// both views' windows, and counts ½ elsewhere (the neighbours of another surface, across a strong edge, say
    /// nothing about the centre's disparity and pull it to theirs); 0 = every bit is compared (the paper's Census).
    pub census_support: f32,
    /// Weight `a` of the Census Hamming distance.
    pub census_weight: f32,
    /// Truncation τc of the Hamming distance, in bits.
    pub census_trunc: f32,
    /// Weight `b` of the gradient term.
    pub grad_weight: f32,
    /// Truncation τg of |∇xL − ∇xR| (Sobel x on 0..255 grey).
    pub grad_trunc: f32,
    /// Local contrast normalisation of the gradient term: each view's Sobel x is scaled by (ḡ + ε) / (s + ε), s
    /// the mean |∇x| over the (2r + 1)² window around the pixel, ḡ the left view's mean s; this is r (0 = off, the
    /// paper's raw gradient). A gain or gamma difference between the views then cancels wherever the local
    /// contrast is well above ε.
    pub grad_norm_radius: usize,
    /// ε of the normalisation, in Sobel units (4 = the response to a one-grey-level step); widened with the
    /// measured noise by `condition.noise.grad_eps_per_sigma`.
    pub grad_norm_eps: f32,
}

impl Default for CostParams {
    fn default() -> Self {
        CostParams {
            census_width: 7,
            census_height: 7,
            census_dead_band: 0.0,
            census_ternary: 0.0,
            census_support: 40.0,
            census_weight: 1.0,
            census_trunc: 48.0,
            grad_weight: 0.3,
            grad_trunc: 60.0,
            grad_norm_radius: 2,
            grad_norm_eps: 4.0,
        }
    }
}

impl CostParams {
    /// Checks every value's range.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] naming the first offending key, its value and the valid range.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [("cost.census_width", self.census_width), ("cost.census_height", self.census_height)] {
            if v == 0 || v % 2 == 0 || v > 15 {
                return Err(Error::param(name, v, "an odd number from 1 to 15"));
            }
        }
        if self.census_width * self.census_height > 65 {
            return Err(Error::param(
                "cost.census_width × cost.census_height",
                self.census_width * self.census_height,
                "at most 65 (the Census code is 64 bits)",
            ));
        }
        check_nonneg("cost.census_dead_band", self.census_dead_band)?;
        check_nonneg("cost.census_ternary", self.census_ternary)?;

        check_nonneg("cost.census_support", self.census_support)?;
        check_nonneg("cost.census_weight", self.census_weight)?;
        check_nonneg("cost.census_trunc", self.census_trunc)?;
        check_nonneg("cost.grad_weight", self.grad_weight)?;
        check_nonneg("cost.grad_trunc", self.grad_trunc)?;
        if self.grad_norm_radius > 32 {
            return Err(Error::param("cost.grad_norm_radius", self.grad_norm_radius, "0 to 32 pixels"));
        }
        if !(self.grad_norm_eps > 0.0 && self.grad_norm_eps.is_finite()) {
            return Err(Error::param("cost.grad_norm_eps", self.grad_norm_eps, "> 0 (Sobel units)"));
        }
        if self.census_weight == 0.0 && self.grad_weight == 0.0 {
            return Err(Error::param("cost.census_weight", 0, "> 0 when cost.grad_weight is 0"));
        }
        Ok(())
    }
}
