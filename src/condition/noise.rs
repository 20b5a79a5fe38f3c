//! Noise (module doc of [`crate::condition`], item 3): each view's noise σn measured on the image alone, robust
//! to texture ([`estimate_noise`]).

use rayon::prelude::*;

use crate::image::RgbImage;
use crate::imgproc::stats::rank_value;

/// The fraction of pixels, those of lowest gradient, on which [`estimate_noise`] measures.
const FLAT_FRACTION: f64 = 0.25;

/// The mean of the three channels' noise σ ([`estimate_noise`]).
pub(crate) fn channel_noise(img: &RgbImage) -> f32 {
    let (w, h) = img.dims();
    let sum: f32 = img.channels.par_iter().map(|c| estimate_noise(c, w, h)).sum();
    sum / 3.0
}

/// Noise σ of a row-major `w` × `h` grey channel in grey levels, robust to texture: the 3 × 3 operator
/// `[1 −2 1; −2 4 −2; 1 −2 1]` (Immerkær, 1996) cancels planes and smooth ramps, leaving 6σ of white noise; its
/// absolute response is taken at the pixels whose Sobel gradient is in the lower half (flat regions), and the
/// median of those, divided by 6 × 0.6745 (the median absolute value of a unit normal), estimates σ.
pub(crate) fn estimate_noise(data: &[f32], w: usize, h: usize) -> f32 {
    if w < 3 || h < 3 {
        return 0.0;
    }
    let row = |y: usize| &data[y * w..(y + 1) * w];
    // A clipped region (a saturated sky or highlight, crushed shadows) holds the image's extreme value exactly and
    // carries no noise: a window entirely at an extreme is left out, or an overexposed image would read as
    // noiseless. (Single pixels that noise pushed past an extreme stay: they are noise.)
    let (lo, hi) = data.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let plateau =
        |x: usize, rows: [&[f32]; 3], level: f32| rows.iter().all(|r| r[x - 1..=x + 1].iter().all(|&v| v == level));
    let mut resp = Vec::with_capacity((w - 2) * (h - 2));
    let mut grad = Vec::with_capacity((w - 2) * (h - 2));
    for y in 1..h - 1 {
        let (u, m, d) = (row(y - 1), row(y), row(y + 1));
        for x in 1..w - 1 {
            if plateau(x, [u, m, d], lo) || plateau(x, [u, m, d], hi) {
                continue;
            }
            let l = u[x - 1] - 2.0 * u[x] + u[x + 1] - 2.0 * (m[x - 1] - 2.0 * m[x] + m[x + 1])
                + (d[x - 1] - 2.0 * d[x] + d[x + 1]);
            let gx = (u[x + 1] - u[x - 1]) + 2.0 * (m[x + 1] - m[x - 1]) + (d[x + 1] - d[x - 1]);
            let gy = (d[x - 1] - u[x - 1]) + 2.0 * (d[x] - u[x]) + (d[x + 1] - u[x + 1]);
            resp.push(l.abs());
            grad.push(gx.abs() + gy.abs());
        }
    }
    if grad.is_empty() {
        return 0.0;
    }
    let median_grad = rank_value(&mut grad.clone(), FLAT_FRACTION);
    let mut flat: Vec<f32> = resp.iter().zip(&grad).filter(|(_, g)| **g <= median_grad).map(|(r, _)| *r).collect();
    rank_value(&mut flat, 0.5) / (6.0 * 0.6745)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::condition_pair;
    use crate::condition::test_images::textured;
    use crate::image::StereoPair;
    use crate::params::{ConditionParams, StretchParams};

    #[test]
    fn noise_estimate_matches_the_added_noise() {
        for sigma in [2.0, 5.0, 10.0] {
            let est = channel_noise(&textured(160, 120, sigma, 3));
            assert!((f64::from(est) / sigma - 1.0).abs() < 0.1, "σ {sigma}: estimated {est}");
        }
        assert!(channel_noise(&textured(160, 120, 0.0, 3)) < 0.6);
    }

    /// Overexposed: more than half of the image saturated (exactly 255), the rest noisy. The saturated plateau
    /// carries no noise and is left out; counted, it would be the flattest quarter and read as σ 0. Pixels that
    /// the noise alone pushes to an extreme still count.
    #[test]
    fn noise_estimate_ignores_clipped_regions() {
        let (w, h, sigma) = (160, 120, 4.0);
        let mut img = textured(w, h, sigma, 5);
        for ch in &mut img.channels {
            ch.iter_mut().enumerate().filter(|(i, _)| i % w < 100).for_each(|(_, v)| *v = 255.0);
        }
        let est = channel_noise(&img);
        assert!((f64::from(est) / sigma - 1.0).abs() < 0.15, "estimated {est}");
        // Crushed shadows likewise.
        let mut dark = textured(w, h, sigma, 6);
        for ch in &mut dark.channels {
            ch.iter_mut().enumerate().filter(|(i, _)| i / w < 70).for_each(|(_, v)| *v = 0.0);
        }
        let est = channel_noise(&dark);
        assert!((f64::from(est) / sigma - 1.0).abs() < 0.15, "estimated {est}");
    }

    /// A pair reduced 4× keeps its texture and loses its noise. Where the texture is as fine as the reduced
    /// pixels (here 4 × 4 blocks of random grey), one image cannot tell it from noise: the estimate reads it, far
    /// above the σ/4 the box average leaves. A coarse level of the prior's chain takes the finer level's σ reduced
    /// as its ceiling (`noise_ceiling`); a ceiling above the estimate changes nothing.
    #[test]
    fn a_coarse_level_keeps_the_finer_levels_noise_as_a_ceiling() {
        let (w, h, sigma, f) = (160, 120, 4.0, 4);
        let mut fine = textured(w, h, sigma, 13);
        let blocks = crate::test_util::rand_vec((w / f) * (h / f), 14);
        for ch in &mut fine.channels {
            ch.iter_mut()
                .enumerate()
                .for_each(|(i, v)| *v = (*v + 30.0 * blocks[(i / w / f) * (w / f) + i % w / f]).min(255.0));
        }
        let coarse = crate::scale::downsample_rgb(&fine, f);
        let pair = StereoPair::new(coarse.clone(), coarse, 4).unwrap();
        let reduced = sigma as f32 / f as f32;
        let own = condition_pair(
            &pair,
            &ConditionParams {
                stretch: StretchParams { enabled: false, ..Default::default() },
                ..ConditionParams::default()
            },
            None,
        );
        assert!(own.stats.noise[0] > 3.0 * reduced, "the estimate at 1/{f}: {:?}", own.stats.noise);
        let p = ConditionParams {
            stretch: StretchParams { enabled: false, ..Default::default() },
            ..ConditionParams::default()
        };
        assert_eq!(condition_pair(&pair, &p, Some([reduced; 2])).stats.noise, [reduced; 2]);
        assert_eq!(condition_pair(&pair, &p, Some([100.0; 2])).stats.noise, own.stats.noise);
    }
}
