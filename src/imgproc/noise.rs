//! How independent per-channel noise of σ 1 carries into the grey ([`crate::image::RgbImage::to_grey`], BT.601
//! weights) and into differences of grey pixels: the factors the noise-aware thresholds scale the measured σn by.
//! Each is derived from the weights ([`GREY_WEIGHTS`]), to three digits; the test below holds them to that.

/// The grey's weights of red, green and blue (ITU-R BT.601 luma).
pub(crate) const GREY_WEIGHTS: [f32; 3] = [0.299, 0.587, 0.114];

/// σ of a grey pixel's noise: √(0.299² + 0.587² + 0.114²) = 0.66856, to three digits as it was tuned with (rounded
/// down; the thresholds built on it were measured with this value).
pub(crate) const GREY_NOISE_PER_SIGMA: f32 = 0.668;

/// σ of the difference of two grey pixels' independent noise (a Census comparison, two frames): √2 times
/// [`GREY_NOISE_PER_SIGMA`], 0.9455.
pub(crate) const GREY_PAIR_NOISE_PER_SIGMA: f32 = 0.945;

/// The mean |difference| of two grey pixels' independent noise: √(2/π) times [`GREY_PAIR_NOISE_PER_SIGMA`] (the
/// mean absolute value of a normal variable of σ 1), 0.7544.
pub(crate) const GREY_DIFFERENCE_PER_SIGMA: f64 = 0.754;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grey_noise_factors_follow_from_the_weights() {
        let grey = GREY_WEIGHTS.iter().map(|&w| f64::from(w).powi(2)).sum::<f64>().sqrt();
        let pair = std::f64::consts::SQRT_2 * grey;
        let difference = (2.0 / std::f64::consts::PI).sqrt() * pair;
        for (constant, derived) in [
            (f64::from(GREY_NOISE_PER_SIGMA), grey),
            (f64::from(GREY_PAIR_NOISE_PER_SIGMA), pair),
            (GREY_DIFFERENCE_PER_SIGMA, difference),
        ] {
            assert!((constant - derived).abs() < 1e-3, "{constant} for {derived}");
        }
    }
}
