//! Input conditioning and the coarse prior (our addition, not in the paper): measure the pair, then adapt to it,
//! so that one configuration serves clean, noisy, dark and unevenly exposed pairs.
//!
//! 1. **Contrast** (`stretch.enabled`). A view whose robust range (the 0.5th to the 99.5th percentile of grey) is below
//!    [`contrast::TARGET_RANGE`] / `stretch.min_gain` is stretched by an affine map to span
//!    [`contrast::TARGET_RANGE`] grey levels, each view by its own range (one gain for both would push a darker
//!    right view below 0). A dark image gets the contrast the colour thresholds (σf, μ, the weighted median's and
//!    the planes' colour weights) assume, and its noise is then measured relative to its contrast: what matters for
//!    matching is the signal-to-noise ratio, not the absolute grey levels.
//! 2. **Noise** (`[condition.denoise]`). The noise σn of each view is measured after the stretch
//!    ([`noise::estimate_noise`]); a view noisier than `denoise.min_sigma` is smoothed by an edge-preserving bilateral
//!    filter (range scale `denoise.strength` × σn) **for the matching cost only**: Census bits of noisy near-flat
//!    windows flip at random, and no averaging of the cost afterwards recovers a stable code; the guidance (colour
//!    weights of the mean field, weighted median, planes) keeps the original edges. A clean camera measures 0.5–1.6
//!    grey levels (texture counts a little as noise) and is not filtered: filtering it removes the fine texture Census
//!    relies on. JPEG compression flattens the flat regions (σn ≈ 0) but leaves block steps on the same image grid in
//!    both views; [`blockiness`] measures them, and a view's noise is taken as max(σn, blockiness·√π/2) (the mean step
//!    between two blocks with independent errors of σ is 2σ/√π).
//! 3. **Coarse prior** (`prior_*`, in [`crate::pipeline`], prior.rs): the whole pipeline first runs on the
//!    conditioned pair reduced 2× (noise halves, the range of labels too; a quarter of the plane segments, so
//!    they keep their size in the scene), and the full-resolution cost of label d at pixel i
//!    gets λᵢ·min(max(|d − d_coarse,i| − margin, 0), trunc), λᵢ = max(`prior.per_sigma`·σn,
//!    `prior.flat` × the flatness of the pixel's cost, [`crate::cost::flatness`]: an untextured surface follows
//!    the coarse answer whatever the noise) × the coarse run's confidence at i (its max-marginal, with
//!    `prior.confidence`) × `prior.untrusted` where the coarse left-right check failed (the fill guessed there),
//!    × `detail_factor` (pipeline/prior.rs) where the image has detail the coarse level cannot hold. Beside a
//!    depth edge of the
//!    coarse answer (`prior.spread`) the distance is taken from the whole step, [low, high] of `edge_range`,
//!    instead of d_coarse: the coarse level places an edge only to within its own pixels, and fattens near
//!    objects under noise. The coarse level removes the gross errors that fine-scale noise causes, the fine level
//!    keeps the precision; the prior also places each pixel well enough that three full-resolution iterations do
//!    the work of five. With `prior.levels` L the coarse run has a coarse prior of its own, L − 1 levels deep (default
//!    3: the half-resolution run is guided by a quarter-resolution one, and that by an eighth-resolution one).
//! 4. **Vertical alignment** (`vertical.enabled`, in [`crate::pipeline::run`] and the tiled run): with the coarse run's
//!    answer, the right view's residual vertical offset (imperfect rectification) is measured and, where it reaches
//!    `vertical.min_px`, removed from the guidance and the cost pair before the full-resolution cost
//!    ([`crate::condition::vertical`]).
//!
//! Everything is measured on the pair itself; nothing depends on the dataset. The paper's configs turn all of
//! it off (`enabled = false`). Measurements: docs/tuning-log.md ("Robustness").

mod contrast;
mod denoise;
mod jpeg;
mod noise;
mod sharpness;
pub(crate) mod vertical;

use std::borrow::Cow;

use crate::image::{RgbImage, StereoPair};
use crate::params::ConditionParams;

use crate::imgproc::filter::gaussian_blur;
use contrast::stretch;
use denoise::bilateral;
pub(crate) use jpeg::{blockiness, jpeg_noise};
pub(crate) use noise::channel_noise;
use sharpness::matching_blur;
pub(crate) use sharpness::{MAX_MATCHING_BLUR, sharpness};

/// What was measured on a pair, for diagnostics (`jem -v`) and the adaptive stages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairStats {
    /// The contrast gain applied to the left and the right view (1 = none).
    pub gain: [f32; 2],
    /// Noise σ of the left and right view after the stretch, in grey levels (mean of the channels).
    pub noise: [f32; 2],
    /// Noise σ of the left and right view of the pair the matching cost sees: [`PairStats::noise`], or measured
    /// again on the views the denoiser or the sharpness matching filtered (at most `noise`).
    pub cost_noise: [f32; 2],
    /// The Gaussian blur σ (px) given to the left and the right view of the cost pair so that their sharpness
    /// matches ([`sharpness()`]; 0 = none).
    pub cost_blur: [f32; 2],
    /// Each view's JPEG blocking ([`blockiness`], grey levels; 0 = no block grid).
    pub blocking: [f32; 2],
    /// Each view's JPEG compression error ([`jpeg_noise`] × the view's gain; 0 = not JPEG-compressed or not
    /// measured).
    pub jpeg: [f32; 2],
}

impl PairStats {
    /// Whether either view was measured as JPEG-compressed.
    pub fn is_jpeg(&self) -> bool {
        self.jpeg.iter().any(|&j| j > 0.0)
    }

    /// The noisier view's σn: what the adaptive stages scale with.
    pub fn sigma(&self) -> f32 {
        self.noise[0].max(self.noise[1])
    }

    /// The noisier view's σn in the pair the matching cost sees ([`PairStats::cost_noise`]).
    pub fn cost_sigma(&self) -> f32 {
        self.cost_noise[0].max(self.cost_noise[1])
    }

    /// The Census band's multiple of the blocking for a pair measured so: `c.noise.block_band` where JPEG was detected,
    /// or where this level does not look for it (a coarse level, reduced off the block grid, gets the band of the
    /// level above); 0 otherwise.
    pub fn block_band(&self, c: &ConditionParams) -> f32 {
        if self.is_jpeg() || !c.noise.jpeg { c.noise.block_band } else { 0.0 }
    }
}

/// A conditioned pair: what the guidance sees and, when it differs, what the matching cost sees.
pub(crate) struct Conditioned<'a> {
    /// Aligned and stretched (the input itself, not a copy, when neither was needed): the colour weights of the
    /// mean field, the weighted median and the planes use it.
    pub guide: Cow<'a, StereoPair<'a>>,
    /// The guide pair denoised, for the matching cost only; `None` when nothing was filtered.
    pub cost: Option<StereoPair<'a>>,
    /// What was measured.
    pub stats: PairStats,
}

impl<'a> Conditioned<'a> {
    /// The pair the matching cost is computed from.
    pub(crate) fn cost_pair(&self) -> &StereoPair<'a> {
        self.cost.as_ref().unwrap_or(&self.guide)
    }
}

/// Conditions a pair as the module doc says. Only the matching cost sees the denoised images: the guidance
/// keeps the original edges (denoising it too was measured worse, docs/tuning-log.md).
///
/// `noise_ceiling` is run-time state, not a parameter: for a coarse level of the prior's chain (and a tiled run's
/// coarse level) the pipeline passes each view's noise σn at the level above divided by the reduction factor F
/// (`None` elsewhere). A box average of F × F pixels divides independent noise by F, while the one-image estimate
/// reads fine texture as noise where few flat pixels are left (1/8 of trainingQ: 0.7–1.2 grey levels on clean
/// pairs against 0.2–0.4 at 1/4), so a coarse level keeps the smaller of its own estimate and this.
pub(crate) fn condition_pair<'a>(
    pair: &'a StereoPair<'a>,
    p: &ConditionParams,
    noise_ceiling: Option<[f32; 2]>,
) -> Conditioned<'a> {
    let mut guide = Cow::Borrowed(pair);
    // Each view by its own range: a view darker than the other (exposure, gamma) is not pushed below 0 by the
    // other's gain, and the two end up with about the same contrast.
    let gain = if p.stretch.enabled { stretch(&mut guide, p.stretch.min_gain) } else { [1.0; 2] };
    // Compression artifacts count as noise of their measured size: JPEG flattens the flat regions the noise is
    // measured on (σn ≈ 0) while its block steps sit on the same image grid in both views and pull matches to
    // it. A step between two blocks with independent errors of σ has mean 2σ/√π, hence the factor.
    // The compression error is measured on the input (the stretch moves the quantisation steps off the integers)
    // and scaled by the view's gain.
    let view_noise = |img: &RgbImage, input: &RgbImage, gain: f32| {
        let grey = img.to_grey();
        let b = blockiness(&grey);
        let jpeg = if p.noise.jpeg {
            // An unstretched view is the input itself: its grey is the one just made.
            let input_grey = (!std::ptr::eq(img, input)).then(|| input.to_grey());
            gain * jpeg_noise(input_grey.as_ref().unwrap_or(&grey))
        } else {
            0.0
        };
        (channel_noise(img).max(b * std::f32::consts::PI.sqrt() / 2.0).max(jpeg), b, jpeg, grey)
    };
    let ((nl, bl, jl, grey_l), (nr, br, jr, grey_r)) =
        rayon::join(|| view_noise(&guide.left, &pair.left, gain[0]), || view_noise(&guide.right, &pair.right, gain[1]));
    // A coarse level of the prior's chain: at most the finer level's noise, reduced.
    let [nl, nr] = match noise_ceiling {
        Some([cl, cr]) => [nl.min(cl), nr.min(cr)],
        None => [nl, nr],
    };
    let noise = [nl, nr];
    let (blocking, jpeg) = ([bl, br], [jl, jr]);
    // Below `denoise.min_sigma` (a clean camera, quantisation noise) a view is not filtered.
    let range = |n: f32| if n >= p.denoise.min_sigma { p.denoise.strength * n } else { 0.0 };
    let cost = (range(nl) > 0.0 || range(nr) > 0.0).then(|| StereoPair {
        left: Cow::Owned(bilateral(&guide.left, p.denoise.sigma_xy, range(nl))),
        right: Cow::Owned(bilateral(&guide.right, p.denoise.sigma_xy, range(nr))),
        ndisp: pair.ndisp,
    });
    // One view sharper than the other (focus, a lens, motion): the Census codes of its fine texture have no
    // counterpart in the other view. The sharper view of the cost pair is blurred until the two match.
    let mut cost = cost;
    let mut cost_blur = [0.0f32; 2];
    if p.sharpness_ratio > 0.0 {
        // The guide's greys when the cost pair is the guide.
        let grey = match &cost {
            Some(c) => [c.left.to_grey(), c.right.to_grey()],
            None => [grey_l, grey_r],
        };
        let s = [sharpness(&grey[0]), sharpness(&grey[1])];
        let sharper = usize::from(s[1] > s[0]);
        if s[sharper] > p.sharpness_ratio * s[1 - sharper] {
            let sigma = matching_blur(&grey[sharper], s[1 - sharper]);
            let mut pair = cost.take().unwrap_or_else(|| guide.as_ref().clone());
            let view = if sharper == 0 { &mut pair.left } else { &mut pair.right };
            *view = Cow::Owned(gaussian_blur(view, sigma));
            cost_blur[sharper] = sigma;
            cost = Some(pair);
        }
    }
    // What the Census comparisons of the cost pair see of the noise (its ternary threshold follows it).
    let cost_noise = match &cost {
        Some(c) => {
            let (l, r) = rayon::join(|| channel_noise(&c.left), || channel_noise(&c.right));
            [l.min(nl), r.min(nr)]
        }
        None => noise,
    };
    Conditioned { guide, cost, stats: PairStats { gain, noise, cost_noise, cost_blur, blocking, jpeg } }
}

/// Test images shared by the conditioning stages' tests.
#[cfg(test)]
pub(crate) mod test_images {
    use crate::image::RgbImage;
    use crate::rng::SplitMix64;

    /// A textured image (a sum of ramps and a checker) with Gaussian noise of σ `sigma` per channel.
    pub(crate) fn textured(w: usize, h: usize, sigma: f64, seed: u64) -> RgbImage {
        let mut rng = SplitMix64::new(seed);
        let mut img = RgbImage::new(w, h);
        for i in 0..w * h {
            let (x, y) = (i % w, i / w);
            // Squares of 7 px: a grid of 8 would read as JPEG blocking (`blockiness`).
            let base = 60.0 + 0.4 * x as f64 + 0.3 * y as f64 + if (x / 7 + y / 7) % 2 == 0 { 40.0 } else { 0.0 };
            for c in 0..3 {
                let (u, v) = (rng.next_f64().max(1e-300), rng.next_f64());
                let n = (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos();
                img.channels[c][i] = (base + 10.0 * c as f64 + sigma * n).round().clamp(0.0, 255.0) as f32;
            }
        }
        img
    }
}
