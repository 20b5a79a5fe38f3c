//! Parameters of the weighted median ([`crate::post::wmedian`]).

use serde::{Deserialize, Serialize};

use super::check_positive;
use crate::error::{Error, Result};

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
    /// Also filter, after the planes, every pixel whose 3×3 neighbourhood spans more than this many pixels of
    /// disparity (a depth edge, where a window cost puts the foreground's disparity on the background's first
    /// pixels); 0 turns it off.
    pub edge_px: f32,
    /// The second run also filters the pixels within this many pixels of such an edge pixel (Chebyshev), and the
    /// pixels the left-right check rejected (whose values the planes extrapolated).
    pub edge_band: usize,
    /// Window radius of the second run in pixels: smaller than the first run's, which must reach across a whole
    /// occlusion.
    pub edge_radius: usize,
    /// Colour σ of the weights in the second run (RGB units) on noiseless views: sharper than the first run's, as
    /// the side of an edge a pixel belongs to is a question of its colour (the upsampling's edge rule uses the
    /// same σ). With the measured noise σn it widens to √(σ² + 3σn²): noise adds 6σn² to the expected squared
    /// distance of two pixels of one colour.
    pub edge_sigma_rgb: f32,
}

impl Default for WmedianParams {
    fn default() -> Self {
        WmedianParams {
            enabled: true,
            radius: 9,
            sigma_xy: 9.0,
            sigma_rgb: 20.0,
            edge_px: 2.0,
            edge_band: 1,
            edge_radius: 5,
            edge_sigma_rgb: 10.0,
        }
    }
}

impl WmedianParams {
    /// The filter's parameters in the second run, after the planes, on views with measured noise `noise` (σn, grey
    /// levels): `edge_radius`, and `edge_sigma_rgb` widened to √(σ² + 3σn²). Noise adds 6σn² to the expected squared
    /// RGB distance of two pixels of one colour; the σ² that keeps their weight is at least 3σn² more.
    pub fn second_run(&self, noise: f32) -> WmedianParams {
        let sigma_rgb = (self.edge_sigma_rgb.powi(2) + 3.0 * noise.powi(2)).sqrt();
        WmedianParams { radius: self.edge_radius, sigma_rgb, ..self.clone() }
    }

    /// Checks ranges.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] naming the key.
    pub fn validate(&self) -> Result<()> {
        if self.radius == 0 || self.radius > 64 {
            return Err(Error::param("post.wmedian.radius", self.radius, "1 to 64"));
        }
        check_positive("post.wmedian.sigma_xy", self.sigma_xy)?;
        check_positive("post.wmedian.sigma_rgb", self.sigma_rgb)?;
        if self.edge_radius == 0 || self.edge_radius > 64 {
            return Err(Error::param("post.wmedian.edge_radius", self.edge_radius, "1 to 64"));
        }
        if self.edge_band > 16 {
            return Err(Error::param("post.wmedian.edge_band", self.edge_band, "0 to 16"));
        }
        check_positive("post.wmedian.edge_sigma_rgb", self.edge_sigma_rgb)?;
        if !(self.edge_px >= 0.0 && self.edge_px.is_finite()) {
            return Err(Error::param("post.wmedian.edge_px", self.edge_px, "0 (off) or a positive number of pixels"));
        }
        Ok(())
    }
}
