//! The working resolution: the pipeline works at 1/2ᵏ of the input when the input's k finest octaves hold no detail
//! of their own — only what an upsampling (a camera's digital zoom, a resized image, a defocused lens) and noise put
//! there. The views are then reduced (noise falls by 2ᵏ, the search range and the work by 2ᵏ and 8ᵏ) and the answer
//! is brought back edge-aware (`[upsample]`), as with `downscale`; matching at the full size would only match noise
//! at a scale the pipeline's windows were not made for (docs/RESULTS.md, "Native resolution and noise").
//!
//! Whether an octave holds detail:
//! The measure is the ratio of the image's *scale* at full size to its scale reduced 2×, where the scale is the
//! root-mean-square Laplacian over the root-mean-square gradient, each with the noise's expected share taken out:
//!
//! ```text
//! s(I) = √((E[L²] − 20σ²) / (E[|∇I|²] − 4σ²)),    ρ = s(I) / s(I↓2)
//! ```
//!
//! (L the 4-neighbour Laplacian, whose response to white noise of σ has variance 20σ²; ∇ central differences, 2σ²
//! per axis; the 2 × 2 box reduction leaves σ/2.) A band-limited signal with its highest frequency f has
//! s ∝ f, so an image whose detail fills every octave — natural images are close to scale-invariant — reads ρ ≈ 1,
//! and one upsampled 2× from a sharp image reads ρ ≈ ½: its frequencies in pixels are half of what its size
//! allows. Measured: MiddEval3 trainingQ 0.81–0.93, its views with noise σ 2 0.80–0.91, the trainingH views of
//! two scenes 0.75–0.78, Middlebury 2005 at full size 0.76–0.85; trainingQ upsampled 2× (bicubic, noise σ 1.3)
//! 0.55–0.58, 4× 0.53–0.55 in both of its top octaves. The boundary is the geometric mean of the two, 1/√2.

use rayon::prelude::*;

use crate::image::{Plane, RgbImage};
use crate::params::Params;
use crate::scale;

/// The standard deviation of a grey pixel's noise per unit of per-channel noise σn: the grey weights'
/// √(0.299² + 0.587² + 0.114²), the channels' noise independent.
pub(crate) const GREY_NOISE_PER_SIGMA: f32 = 0.668;

/// ρ below this: the octave holds no detail of its own (see the module doc).
pub(crate) const DETAIL_RATIO: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// The image's scale s(I) with white noise of `sigma` grey levels taken out (see the module doc); `None` when the
/// image is too small or holds no gradient beyond its noise.
fn scale_of(grey: &Plane<f32>, sigma: f32) -> Option<f64> {
    let (w, h) = grey.dims();
    if w < 3 || h < 3 {
        return None;
    }
    let (lap, grad) = (1..h - 1)
        .into_par_iter()
        .map(|y| {
            let (up, row, down) = (grey.row(y - 1), grey.row(y), grey.row(y + 1));
            let (mut l, mut g) = (0.0f64, 0.0f64);
            for x in 1..w - 1 {
                let lx = f64::from(4.0 * row[x] - row[x - 1] - row[x + 1] - up[x] - down[x]);
                let (gx, gy) = (f64::from(row[x + 1] - row[x - 1]), f64::from(down[x] - up[x]));
                l += lx * lx;
                g += gx * gx + gy * gy;
            }
            (l, g)
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let n = ((w - 2) * (h - 2)) as f64;
    let var = f64::from(sigma) * f64::from(sigma);
    let (lap, grad) = (lap / n - 20.0 * var, grad / n - 4.0 * var);
    (lap > 0.0 && grad > 0.0).then(|| (lap / grad).sqrt())
}

/// ρ of the grey image's finest octave with white noise of `sigma` grey levels (see the module doc); `None` when
/// either scale cannot be measured.
pub(crate) fn detail_ratio(grey: &Plane<f32>, sigma: f32) -> Option<f32> {
    let (w, h) = grey.dims();
    let reduced = scale::downsample_plane(grey, 2);
    if reduced.width < 3 || reduced.height < 3 || w < 3 || h < 3 {
        return None;
    }
    Some((scale_of(grey, sigma)? / scale_of(&reduced, sigma / 2.0)?) as f32)
}

/// The working resolution's reduction for a pair whose left view is `left` and whose search range is `ndisp`: 2ᵏ,
/// k the finest octaves of the left view that hold no detail of its own ([`empty_octaves`], at most
/// `working.max_octaves`), and no more than keeps the reduced range below the reduced width. 1 (the input's own
/// resolution) when `working.auto` is off or `downscale` is set.
pub(crate) fn working_factor(left: &RgbImage, ndisp: usize, params: &Params) -> usize {
    if !params.working.auto || params.downscale != 1 {
        return 1;
    }
    let sigma = GREY_NOISE_PER_SIGMA * crate::condition::channel_noise(left);
    let octaves = empty_octaves(&left.to_grey(), sigma, params.working.max_octaves);
    (0..=octaves).rev().map(|k| 1usize << k).find(|&f| scale::factor_fits(left.width, ndisp, f)).unwrap_or(1)
}

/// How many times (0 to `max_octaves`) the grey image can be halved before its finest octave holds detail of its
/// own: the octaves above it carry only an upsampling's interpolation and noise. `sigma` is the image's noise.
pub(crate) fn empty_octaves(grey: &Plane<f32>, sigma: f32, max_octaves: u32) -> u32 {
    let mut image = grey.clone();
    let mut sigma = sigma;
    for k in 0..max_octaves {
        match detail_ratio(&image, sigma) {
            Some(r) if r < DETAIL_RATIO => {}
            _ => return k,
        }
        image = scale::downsample_plane(&image, 2);
        sigma /= 2.0;
    }
    max_octaves
}

#[cfg(test)]
mod tests {
    use super::*;

    /// White noise texture (every octave full) in 0..255.
    fn texture(w: usize, h: usize, seed: u64) -> Plane<f32> {
        let mut rng = crate::rng::SplitMix64::new(seed);
        Plane::from_parts(w, h, (0..w * h).map(|_| (rng.next_u64() % 256) as f32).collect())
    }

    /// `p` enlarged `k` times by bilinear interpolation (pixel centres aligned).
    fn upsampled(p: &Plane<f32>, k: usize) -> Plane<f32> {
        let (w, h) = (p.width * k, p.height * k);
        let at = |x: f32, y: f32| {
            let (x, y) = (x.clamp(0.0, (p.width - 1) as f32), y.clamp(0.0, (p.height - 1) as f32));
            let (x0, y0) = (x.floor() as usize, y.floor() as usize);
            let (x1, y1) = ((x0 + 1).min(p.width - 1), (y0 + 1).min(p.height - 1));
            let (fx, fy) = (x - x0 as f32, y - y0 as f32);
            let row = |y| p.at(x0, y) * (1.0 - fx) + p.at(x1, y) * fx;
            row(y0) * (1.0 - fy) + row(y1) * fy
        };
        let src = |i: usize| (i as f32 + 0.5) / k as f32 - 0.5;
        Plane::from_parts(w, h, (0..w * h).map(|i| at(src(i % w), src(i / w))).collect())
    }

    fn with_noise(p: &Plane<f32>, sigma: f32, seed: u64) -> Plane<f32> {
        let n = texture(p.width, p.height, seed);
        // Uniform noise of standard deviation sigma: (u − ½)·√12·σ.
        let data = p.data.iter().zip(&n.data).map(|(v, u)| v + (u / 255.0 - 0.5) * 12f32.sqrt() * sigma).collect();
        Plane::from_parts(p.width, p.height, data)
    }

    #[test]
    fn a_full_band_image_keeps_its_octaves_and_an_upsampled_one_drops_them() {
        let base = texture(96, 80, 1);
        let full = detail_ratio(&base, 0.0).unwrap();
        assert!(full > 0.9, "white noise texture: every octave full, ρ {full}");
        assert_eq!(empty_octaves(&base, 0.0, 3), 0);
        let x2 = upsampled(&base, 2);
        let r2 = detail_ratio(&x2, 0.0).unwrap();
        assert!(r2 < DETAIL_RATIO, "2× upsampled: ρ {r2}");
        assert_eq!(empty_octaves(&x2, 0.0, 3), 1);
        assert_eq!(empty_octaves(&upsampled(&base, 4), 0.0, 3), 2);
        assert_eq!(empty_octaves(&upsampled(&base, 4), 0.0, 1), 1, "held to max_octaves");
    }

    /// Noise added at the upsampled size fills the top octave with energy, not with detail: measured with its σ,
    /// the octave still reads as empty; without it (σ 0), noise would pass for detail.
    #[test]
    fn noise_in_an_upsampled_image_is_not_taken_for_detail() {
        // Faint texture (σ about 11 grey levels) and noise of σ 4.
        let faint = texture(96, 80, 2);
        let faint = Plane::from_parts(96, 80, faint.data.iter().map(|v| 100.0 + 0.15 * v).collect());
        let x2 = with_noise(&upsampled(&faint, 2), 4.0, 9);
        assert_eq!(empty_octaves(&x2, 4.0, 3), 1);
        assert_eq!(empty_octaves(&x2, 0.0, 3), 0, "the noise's share is what the correction takes out");
    }

    #[test]
    fn the_working_factor_keeps_the_range_below_the_width_and_follows_the_switches() {
        let grey = upsampled(&texture(64, 48, 3), 4);
        let img = RgbImage::from_channels(grey.width, grey.height, [grey.data.clone(), grey.data.clone(), grey.data])
            .unwrap();
        let params = Params::default();
        assert_eq!(working_factor(&img, 16, &params), 4);
        // 1/4 would leave 64 labels on 64 columns: 1/2 is the most.
        assert_eq!(working_factor(&img, 254, &params), 2);
        let off = Params { working: crate::params::WorkingParams { auto: false, ..params.working }, ..params.clone() };
        assert_eq!(working_factor(&img, 16, &off), 1);
        assert_eq!(working_factor(&img, 16, &Params { downscale: 2, ..params }), 1, "downscale given: its own");
    }
}
