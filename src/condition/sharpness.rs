//! Sharpness: one view sharper than the other (focus, a lens, motion) is blurred in the cost pair until the two
//! match ([`sharpness`], `condition.sharpness_ratio`).

use rayon::prelude::*;

use crate::image::Plane;
use crate::imgproc::filter::gaussian_blur_plane;

/// How sharp a grey image is, independently of its contrast: the mean |Laplacian| (4-neighbour) over the mean
/// |gradient| (central differences, both directions), interior pixels. Blur lowers the fine scale more than the
/// coarse one (MiddEval3's views agree to within 6 %; a view blurred by σ 1.5 px reads 2.5–3 times lower);
/// 0 for a flat image.
pub(crate) fn sharpness(grey: &Plane<f32>) -> f32 {
    let (w, h) = grey.dims();
    if w < 3 || h < 3 {
        return 0.0;
    }
    let (lap, grad) = (1..h - 1)
        .into_par_iter()
        .map(|y| {
            let (up, row, down) = (grey.row(y - 1), grey.row(y), grey.row(y + 1));
            let (mut l, mut g) = (0.0f64, 0.0f64);
            for x in 1..w - 1 {
                l += f64::from((4.0 * row[x] - row[x - 1] - row[x + 1] - up[x] - down[x]).abs());
                g += f64::from((row[x + 1] - row[x - 1]).abs() + (down[x] - up[x]).abs());
            }
            (l, g)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    if grad > 0.0 { (lap / grad) as f32 } else { 0.0 }
}

/// The steps of the blur [`matching_blur`] tries (σ, px).
const BLUR_STEP: f32 = 0.125;

/// How many steps [`matching_blur`] tries, the last one [`MAX_MATCHING_BLUR`].
const BLUR_STEPS: usize = 24;

/// The largest blur (σ, px) the front end gives the sharper view: 24 steps of 0.125, 3 px. A view blurrier than
/// the other by more is beyond what the front end matches (`diagnose` reports it).
pub(crate) const MAX_MATCHING_BLUR: f32 = BLUR_STEPS as f32 * BLUR_STEP;

/// The Gaussian σ (px, in steps of [`BLUR_STEP`] up to [`MAX_MATCHING_BLUR`]) whose blur brings `img`'s
/// [`sharpness`] closest to `target`. Sharpness falls as the blur grows, so a bisection finds the first step at or
/// below `target` (six blurs instead of 24: on a large image each is a pass over every pixel), and the closer of it
/// and the step before wins.
pub(super) fn matching_blur(grey: &Plane<f32>, target: f32) -> f32 {
    const STEPS: usize = BLUR_STEPS;
    let sigma = |k: usize| k as f32 * BLUR_STEP;
    // Each step's sharpness once (a blur of the whole image each).
    let mut seen = [None; STEPS + 1];
    let mut at = |k: usize| {
        *seen[k].get_or_insert_with(|| {
            let blurred = gaussian_blur_plane(&grey.data, grey.width, grey.height, sigma(k));
            sharpness(&Plane::from_parts(grey.width, grey.height, blurred))
        })
    };
    // The first k in 1..=STEPS with at(k) ≤ target (STEPS when there is none).
    let (mut lo, mut hi) = (1, STEPS);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if at(mid) <= target { hi = mid } else { lo = mid + 1 }
    }
    let mut gap = |k: usize| (at(k) - target).abs();
    if lo > 1 && gap(lo - 1) < gap(lo) { sigma(lo - 1) } else { sigma(lo) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::condition_pair;
    use crate::image::{RgbImage, StereoPair};
    use crate::imgproc::filter::gaussian_blur;
    use crate::params::{ConditionParams, StretchParams};

    /// Sharpness does not depend on contrast, falls with blur, and a view blurred by σ 1.5 px gets a matching
    /// blur of about that much in the other view.
    #[test]
    fn sharpness_is_contrast_free_and_matched_by_blur() {
        let mut img = RgbImage::new(96, 64);
        let mut seed = 1u64;
        for ch in &mut img.channels {
            for v in ch.iter_mut() {
                seed = crate::rng::mix64(seed);
                *v = 60.0 + (seed % 120) as f32;
            }
        }
        let img = gaussian_blur(&img, 0.7);
        let grey = img.to_grey();
        let half = Plane::from_parts(96, 64, grey.data.iter().map(|v| 0.5 * v).collect());
        assert!((sharpness(&grey) - sharpness(&half)).abs() < 1e-4);
        let blurred = gaussian_blur(&img, 1.5);
        let target = sharpness(&blurred.to_grey());
        assert!(target < 0.7 * sharpness(&grey), "{target} vs {}", sharpness(&grey));
        // Blurring 0.7 px by σ gives √(0.7² + σ²); 1.5 more is about 1.66 in all, so σ ≈ 1.5 matches.
        let sigma = matching_blur(&img.to_grey(), target);
        assert!((1.25..=1.75).contains(&sigma), "matching blur {sigma}");
        // The default conditions such a pair (without the stretch, so the guidance is the input itself): the
        // sharper (left) view of the cost pair is blurred, the guidance keeps it sharp.
        let p = ConditionParams {
            stretch: StretchParams { enabled: false, ..Default::default() },
            ..ConditionParams::default()
        };
        let pair = StereoPair::new(img.clone(), blurred, 8).unwrap();
        let c = condition_pair(&pair, &p, None);
        assert!(c.stats.cost_blur[0] > 1.0 && c.stats.cost_blur[1] == 0.0, "{:?}", c.stats.cost_blur);
        assert!(*c.guide.left == img, "the guidance keeps the sharp view");
        assert!(*c.cost_pair().left != img, "the cost sees the blurred one");
        // Two views alike are left alone.
        let same = StereoPair::new(img.clone(), img.clone(), 8).unwrap();
        assert_eq!(condition_pair(&same, &p, None).stats.cost_blur, [0.0, 0.0]);
    }
}
