//! Parameters of the weighted median ([`crate::post::wmedian`]).

use serde::{Deserialize, Serialize};

use super::{check_positive, check_reference_px, side_growth};
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
    /// The windows above (`radius`, `sigma_xy`, `edge_radius`) are stated for an image of this many pixels; a
    /// larger one gets them × √(pixels / `reference_px`), so that they cover the same part of the scene
    /// ([`WmedianParams::for_image`]). 0: the same in pixels at every size.
    pub reference_px: f32,
    /// The windows sample every `step`-th pixel in x and y from the target: set by [`WmedianParams::for_image`] to
    /// the factor the windows grew by (rounded), so that a grown window holds about as many samples as the stated
    /// one and costs about as much. Not a key (1 as configured).
    #[serde(skip)]
    pub step: usize,
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
            reference_px: 375_000.0,
            step: 1,
        }
    }
}

impl WmedianParams {
    /// The parameters for an image of `pixels` pixels: the windows grow with its side above `reference_px` (at
    /// most 64 px) and are sampled every `step` pixels; below it they stay as stated.
    ///
    /// They were tuned on MiddEval3 trainingQ (0.17 to 0.37 M pixels), where the first run's window must reach
    /// across an occlusion and the second's across the band a window cost smears at a depth edge. Both are parts
    /// of the scene, not numbers of pixels: on an image four times larger the same radius covers a quarter of it
    /// (measured on MiddEval3 trainingH views and Middlebury 2005 at full size: docs/tuning-log.md, "The median's
    /// windows follow the image").
    pub fn for_image(&self, pixels: usize) -> WmedianParams {
        let Some(k) = side_growth(self.reference_px, pixels) else { return self.clone() };
        let grow = |r: usize| ((r as f64 * k).round() as usize).min(64);
        WmedianParams {
            radius: grow(self.radius),
            sigma_xy: (f64::from(self.sigma_xy) * k) as f32,
            edge_radius: grow(self.edge_radius),
            step: (k.round() as usize).max(1),
            ..self.clone()
        }
    }

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
        check_reference_px("post.wmedian.reference_px", self.reference_px)?;
        if !(self.edge_px >= 0.0 && self.edge_px.is_finite()) {
            return Err(Error::param("post.wmedian.edge_px", self.edge_px, "0 (off) or a positive number of pixels"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_windows_follow_a_larger_image() {
        let p = WmedianParams::default();
        // MiddEval3 trainingQ's sizes, Teddy to Motorcycle: as stated.
        for (w, h) in [(450, 375), (741, 497)] {
            assert_eq!(p.for_image(w * h), p, "{w}×{h}");
        }
        // Four times the reference: twice the windows, the rest as stated.
        let big = p.for_image(4 * 375_000);
        assert_eq!((big.radius, big.edge_radius, big.sigma_xy), (2 * p.radius, 2 * p.edge_radius, 2.0 * p.sigma_xy));
        assert_eq!((big.sigma_rgb, big.edge_px, big.edge_band), (p.sigma_rgb, p.edge_px, p.edge_band));
        assert_eq!((p.step, big.step, big.second_run(0.0).step), (1, 2, 2));
        // At most the largest radius the parameters allow.
        assert_eq!(p.for_image(400 * 375_000).radius, 64);
        assert!(p.for_image(400 * 375_000).validate().is_ok());
        // Off: the same in pixels at every size.
        let fixed = WmedianParams { reference_px: 0.0, ..p.clone() };
        assert_eq!(fixed.for_image(4 * 375_000), fixed);
        assert!(WmedianParams { reference_px: -1.0, ..p.clone() }.validate().is_err());
        assert!(WmedianParams { reference_px: f32::NAN, ..p }.validate().is_err());
    }
}
