//! The working resolution: the pipeline works at 1/2ᵏ of the input when the input's k finest octaves hold no detail
//! of their own — only what an upsampling (a camera's digital zoom, a resized image, a defocused lens) and noise put
//! there. The views are then reduced (noise falls by 2ᵏ, the search range and the work by 2ᵏ and 8ᵏ) and the answer
//! is brought back edge-aware (`[upsample]`), as with `downscale`; matching at the full size would only match noise
//! at a scale the pipeline's windows were not made for (docs/RESULTS.md, "Native resolution and noise").
//!
//! Whether an octave holds detail: its *detail energy* E(I) — the mean squared difference between the image and the
//! image reduced 2× (2 × 2 box) and brought back (bilinear) — with the noise's share taken out, against the same at
//! half size:
//!
//! ```text
//! E(I) = mean (I − up(down(I)))² − c·σ²,    r = E(I) / E(I↓2)
//! ```
//!
//! (c = 209/256: white noise of σ keeps that share of its variance in the difference; the reduction leaves σ/2.)
//! Natural images hold detail in every octave, about as much in each per pixel (their spectra fall as 1/f²), and
//! read r ≈ 0.3–0.8; an image enlarged 2× holds in its top octave only what the interpolation leaks, r ≈ 0.15.
//! Measured: MiddEval3 trainingQ 0.50–0.72 (with noise σ 2: the same), the trainingH views of two scenes 0.40 and
//! 0.53, Middlebury 2005 at full size 0.43–0.52, the other benchmarks' pairs of docs/RESULTS.md 0.34–0.83 (KITTI
//! 0.40–0.54, FlyingThings3D renders 0.35–0.50); trainingQ enlarged 2× (bicubic, then noise σ 1.3) 0.13–0.16 and
//! 4× 0.15–0.19 in both of its top octaves. The boundary, 1/4, sits between the two families with a factor of 1.3
//! to each side.
//!
//! An octave is dropped only while the reduced view keeps `working.min_megapixels` (0.1 M): a soft image is soft
//! at any size, and below that the pipeline's windows and segments cover too much of the scene. Measured: trainingQ
//! blurred (Gaussian σ 1.2) reads r 0.15–0.17, as trainingQ enlarged 2×; the enlargement matched at half size
//! scores 3.24 (at its own 3.44), the blurred pairs matched at half size (0.04–0.09 M) 5.63 (at their own 4.97).

use rayon::prelude::*;

use crate::image::{Plane, RgbImage};
use crate::imgproc::noise::GREY_NOISE_PER_SIGMA;
use crate::params::Params;
use crate::scale;

/// r below this: the octave holds no detail of its own (see the module doc).
pub(crate) const DETAIL_RATIO: f64 = 0.25;

/// The share of white noise's variance left in `I − up(down(I))` (see the module doc): with bilinear weights 3/4,
/// 1/4 per axis over 2 × 2 block means, 1 − 2·(9/16)/4 + (100/256)/4.
const NOISE_SHARE: f64 = 209.0 / 256.0;

/// The grey image's detail energy E with white noise of `sigma` grey levels taken out (see the module doc), over
/// the pixels at least 2 from the border; `None` for an image under 6 × 6.
fn detail_energy(grey: &Plane<f32>, sigma: f32) -> Option<f64> {
    let (w, h) = grey.dims();
    if w < 6 || h < 6 {
        return None;
    }
    let back = scale::upsample_plane(&scale::downsample_plane(grey, 2), 2, w, h);
    let sum: f64 = (2..h - 2)
        .into_par_iter()
        .map(|y| {
            let (g, b) = (&grey.row(y)[2..w - 2], &back.row(y)[2..w - 2]);
            g.iter().zip(b).map(|(g, b)| f64::from(g - b).powi(2)).sum::<f64>()
        })
        .sum();
    Some(sum / ((w - 4) * (h - 4)) as f64 - NOISE_SHARE * f64::from(sigma).powi(2))
}

/// r from an octave's detail energy and the next one's (`None` when the next holds none beyond its noise).
fn ratio(fine: f64, coarse: Option<f64>) -> Option<f64> {
    Some(fine.max(0.0) / coarse.filter(|&e| e > 0.0)?)
}

/// The working resolution's reduction for a pair whose left view is `left` and whose search range is `ndisp`: 2ᵏ,
/// k the finest octaves of the left view that hold no detail of its own ([`empty_octaves`], at most
/// `working.max_octaves`, the reduced view at least `working.min_megapixels`), and no more than keeps the reduced
/// range below the reduced width. 1 (the input's own
/// resolution) when `working.auto` is off or `downscale` is set.
pub(crate) fn working_factor(left: &RgbImage, ndisp: usize, params: &Params) -> usize {
    if !params.working.auto || params.downscale != 1 {
        return 1;
    }
    let sigma = GREY_NOISE_PER_SIGMA * crate::condition::channel_noise(left);
    let min_pixels = (params.working.min_megapixels * 1e6) as usize;
    let octaves = empty_octaves(&left.to_grey(), sigma, params.working.max_octaves, min_pixels);
    (0..=octaves).rev().map(|k| 1usize << k).find(|&f| scale::factor_fits(left.width, ndisp, f)).unwrap_or(1)
}

/// How many times (0 to `max_octaves`) the grey image can be halved before its finest octave holds detail of its
/// own (the octaves above it carry only an upsampling's interpolation and noise) or the halved image would hold
/// fewer than `min_pixels`. `sigma` is the image's noise.
pub(crate) fn empty_octaves(grey: &Plane<f32>, sigma: f32, max_octaves: u32, min_pixels: usize) -> u32 {
    // Each octave's image and detail energy serve as the next octave's fine one: each is computed once.
    let mut image = std::borrow::Cow::Borrowed(grey);
    let mut sigma = sigma;
    let mut fine = detail_energy(&image, sigma);
    for k in 0..max_octaves {
        let halved = (image.width / 2) * (image.height / 2);
        let Some(fine_energy) = fine.filter(|_| halved >= min_pixels) else { return k };
        let coarse_image = scale::downsample_plane(&image, 2);
        let coarse = detail_energy(&coarse_image, sigma / 2.0);
        if !ratio(fine_energy, coarse).is_some_and(|r| r < DETAIL_RATIO) {
            return k;
        }
        (image, sigma, fine) = (std::borrow::Cow::Owned(coarse_image), sigma / 2.0, coarse);
    }
    max_octaves
}

#[cfg(test)]
mod tests {
    use super::*;

    /// r of the grey image's finest octave with white noise of `sigma` grey levels (see the module doc): 0 when the
    /// noise explains all of its detail energy; `None` when either image is too small or the reduced one holds no
    /// detail beyond its noise (nothing to compare with).
    fn detail_ratio(grey: &Plane<f32>, sigma: f32) -> Option<f64> {
        let fine = detail_energy(grey, sigma)?;
        ratio(fine, detail_energy(&scale::downsample_plane(grey, 2), sigma / 2.0))
    }

    /// The left view of a rendered scene (textures with detail at every scale, r 0.54), in grey.
    fn scene(seed: u64) -> Plane<f32> {
        let p = crate::synth::SynthParams { width: 160, height: 120, ndisp: 16, seed };
        crate::synth::render_scene(&p).unwrap().left.to_grey()
    }

    /// `p` enlarged `k` times by Catmull-Rom (bicubic) interpolation, separably, pixel centres aligned, borders
    /// replicated: what image editors and cameras' digital zoom use.
    fn upsampled(p: &Plane<f32>, k: usize) -> Plane<f32> {
        let cubic = |t: f32| {
            let t = t.abs();
            if t < 1.0 {
                1.5 * t * t * t - 2.5 * t * t + 1.0
            } else if t < 2.0 {
                -0.5 * t * t * t + 2.5 * t * t - 4.0 * t + 2.0
            } else {
                0.0
            }
        };
        let resample = |src: &[f32], n: usize| -> Vec<f32> {
            (0..n * k)
                .map(|i| {
                    let x = (i as f32 + 0.5) / k as f32 - 0.5;
                    let x0 = x.floor() as isize;
                    (x0 - 1..=x0 + 2).map(|j| src[j.clamp(0, n as isize - 1) as usize] * cubic(x - j as f32)).sum()
                })
                .collect()
        };
        let (w, h) = p.dims();
        let rows: Vec<Vec<f32>> = (0..h).map(|y| resample(p.row(y), w)).collect();
        let mut out = Plane::new(w * k, h * k, 0.0f32);
        for x in 0..w * k {
            let column: Vec<f32> = rows.iter().map(|r| r[x]).collect();
            for (y, v) in resample(&column, h).into_iter().enumerate() {
                out.data[y * w * k + x] = v;
            }
        }
        out
    }

    /// `p` with Gaussian-like noise of σ `sigma` (a sum of four uniforms), seeded.
    fn with_noise(p: &Plane<f32>, sigma: f32, seed: u64) -> Plane<f32> {
        let mut rng = crate::rng::SplitMix64::new(seed);
        let mut unit = || (0..4).map(|_| rng.next_f64() as f32 - 0.5).sum::<f32>() * 3f32.sqrt();
        Plane::from_parts(p.width, p.height, p.data.iter().map(|v| v + sigma * unit()).collect())
    }

    /// Measured: the scene r 0.54; enlarged 2× 0.127, 4× 0.124 in each of its top two octaves.
    #[test]
    fn an_enlarged_image_drops_its_octaves_and_a_detailed_one_keeps_them() {
        let base = scene(1);
        let r = detail_ratio(&base, 0.0).unwrap();
        assert!(r > 2.0 * DETAIL_RATIO, "the scene: r {r}");
        assert_eq!(empty_octaves(&base, 0.0, 3, 0), 0);
        assert_eq!(empty_octaves(&with_noise(&base, 3.0, 5), 3.0, 3, 0), 0, "noise does not hide its detail");
        let x2 = upsampled(&base, 2);
        let r2 = detail_ratio(&x2, 0.0).unwrap();
        assert!(r2 < 0.6 * DETAIL_RATIO, "2× enlarged: r {r2}");
        assert_eq!(empty_octaves(&x2, 0.0, 3, 0), 1);
        let x4 = with_noise(&upsampled(&base, 4), 3.0, 7);
        assert_eq!(empty_octaves(&x4, 3.0, 3, 0), 2);
        assert_eq!(empty_octaves(&x4, 3.0, 1, 0), 1, "held to max_octaves");
    }

    /// 640 × 480 enlarged 4×: halved twice it would hold 19 200 pixels, once 76 800.
    #[test]
    fn an_octave_is_dropped_only_while_the_reduced_image_keeps_its_smallest_size() {
        let x4 = upsampled(&scene(2), 4);
        assert_eq!(empty_octaves(&x4, 0.0, 3, 19_200), 2);
        assert_eq!(empty_octaves(&x4, 0.0, 3, 19_201), 1);
        assert_eq!(empty_octaves(&x4, 0.0, 3, 76_801), 0);
    }

    /// Noise added after the enlargement fills the top octave with energy, not with detail: measured with its σ the
    /// octave reads as empty; without it (σ 0) the noise would pass for detail.
    #[test]
    fn noise_in_an_enlarged_image_is_not_taken_for_detail() {
        let x2 = with_noise(&upsampled(&scene(2), 2), 3.0, 9);
        assert_eq!(empty_octaves(&x2, 3.0, 3, 0), 1);
        assert_eq!(empty_octaves(&x2, 0.0, 3, 0), 0, "the noise's share is what the correction takes out");
    }

    #[test]
    fn the_working_factor_keeps_the_range_below_the_width_and_follows_the_switches() {
        // A camera's noise: independent in each channel.
        let grey = upsampled(&scene(3), 4);
        let channel = |seed| with_noise(&grey, 3.0, seed).data;
        let img = RgbImage::from_channels(grey.width, grey.height, [channel(4), channel(5), channel(6)]).unwrap();
        let small = crate::params::WorkingParams { min_megapixels: 0.01, ..Params::default().working };
        let params = Params { working: small, ..Params::default() };
        assert_eq!(working_factor(&img, 16, &params), 4);
        // 640 columns and 638 labels: at 1/4, 160 labels on 160 columns; at 1/2, 319 on 320 still fit.
        assert_eq!(working_factor(&img, 638, &params), 2);
        assert_eq!(working_factor(&img, 16, &Params::default()), 1, "0.1 M: 320 × 240 is too small");
        let off = Params { working: crate::params::WorkingParams { auto: false, ..params.working }, ..params.clone() };
        assert_eq!(working_factor(&img, 16, &off), 1);
        assert_eq!(working_factor(&img, 16, &Params { downscale: 2, ..params }), 1, "downscale given: its own");
    }
}
