//! Input conditioning and the coarse prior (our addition, not in the paper): measure the pair, then adapt to it,
//! so that one configuration serves clean, noisy, dark and unevenly exposed pairs (issue 15).
//!
//! 1. **Photometric alignment** (`match_histograms`, off by default). The right view's channels are mapped onto
//!    the left view's by histogram specification (a monotonic lookup per channel). Measured worse than without
//!    once the rest is on (it hurts PianoL, whose views are lit differently on purpose).
//! 2. **Contrast** (`stretch`). A view whose robust range (the 0.5th to the 99.5th percentile of grey) is below
//!    [`TARGET_RANGE`] / `stretch_min_gain` is stretched by an affine map to span [`TARGET_RANGE`] grey levels,
//!    each view by its own range (one gain for both would push a darker right view below 0). A dark image gets
//!    the contrast the colour thresholds (σf, μ, the weighted median's and the planes' colour weights) assume,
//!    and its noise is then measured relative to its contrast: what matters for matching is the
//!    signal-to-noise ratio, not the absolute grey levels.
//! 3. **Noise** (`denoise_*`). The noise σn of each view is measured after the stretch ([`estimate_noise`]); a
//!    view noisier than `denoise_min_sigma` is smoothed by an edge-preserving bilateral filter (range scale
//!    `denoise_strength` × σn) **for the matching cost only**: Census bits of noisy near-flat windows flip at
//!    random, and no averaging of the cost afterwards recovers a stable code; the guidance (colour weights of the
//!    mean field, weighted median, planes) keeps the original edges. A clean camera measures 0.5–1.6 grey
//!    levels (texture counts a little as noise) and is not filtered: filtering it removes the fine texture
//!    Census relies on. JPEG compression flattens the flat regions (σn ≈ 0) but leaves block steps on the
//!    same image grid in both views; [`blockiness`] measures them, and a view's noise is taken as
//!    max(σn, blockiness·√π/2) (the mean step between two blocks with independent errors of σ is 2σ/√π).
//! 4. **Coarse prior** (`prior_*`, in [`crate::run`]): the whole pipeline first runs on the conditioned pair
//!    reduced 2× (noise halves, the range of labels too; a quarter of the plane segments, so they keep their size
//!    in the scene), and the full-resolution cost of label d at pixel i
//!    gets λᵢ·min(max(|d − d_coarse,i| − margin, 0), trunc), λᵢ = max(`prior_base` + `prior_per_sigma`·σn,
//!    `prior_flat` × the flatness of the pixel's cost, [`crate::cost::flatness`]: an untextured surface follows
//!    the coarse answer whatever the noise) × the coarse run's confidence at i (its max-marginal, with
//!    `prior_confidence`) × `prior_untrusted` where the coarse left-right check failed (the fill guessed there),
//!    × [`detail_factor`] where the image has detail the coarse level cannot hold. Beside a depth edge of the
//!    coarse answer (`prior_spread`) the distance is taken from the whole step, [low, high] of [`edge_range`],
//!    instead of d_coarse: the coarse level places an edge only to within its own pixels, and fattens near
//!    objects under noise. The coarse level removes the gross errors that fine-scale noise causes, the fine level
//!    keeps the precision; the prior also places each pixel well enough that three full-resolution iterations do
//!    the work of five. With `prior_levels` L
//!    the coarse run has a coarse prior of its own, L − 1 levels deep (default 3: the half-resolution run is
//!    guided by a quarter-resolution one, and that by an eighth-resolution one). With `prior_window` the full
//!    resolution searches only the labels the coarse run found, widened by two coarse labels (off by default: as
//!    accurate, and on MiddEval3's ranges hardly faster).
//! 5. **Vertical alignment** (`vertical_align`, in [`crate::run`] and the tiled run): with the coarse run's answer,
//!    the right view's residual vertical offset (imperfect rectification) is measured and, where it reaches
//!    `vertical_min_px`, removed from the guidance and the cost pair before the full-resolution cost
//!    ([`crate::rectify`]).
//!
//! Everything is measured on the pair itself; nothing depends on the dataset. The paper's configs turn all of
//! it off (`enabled = false`). Measurements: docs/tuning-log.md ("Robustness").

use std::borrow::Cow;

use rayon::prelude::*;

use crate::fastmath::exp_nonpositive;
use crate::image::{Plane, RgbImage, StereoPair, window_extreme};
use crate::params::ConditionParams;

/// The grey-level span the left view's 0.5–99.5 % range is stretched to (when it is smaller).
pub const TARGET_RANGE: f32 = 230.0;

/// The fraction of pixels, those of lowest gradient, on which [`estimate_noise`] measures.
const FLAT_FRACTION: f64 = 0.25;

/// What was measured on a pair, for diagnostics (`jem -v`) and the adaptive stages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairStats {
    /// The contrast gain applied to the left and the right view (1 = none).
    pub gain: [f32; 2],
    /// Noise σ of the left and right view after the stretch, in grey levels (mean of the channels).
    pub noise: [f32; 2],
    /// Noise σ of the grey images the cost sees (after denoising; the larger view's); measured only when the
    /// Census dead band needs it (`census_band` > 0), else 0.
    pub residual_grey_noise: f32,
    /// The Gaussian blur σ (px) given to the left and the right view of the cost pair so that their sharpness
    /// matches ([`sharpness`]; 0 = none).
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
}

/// A conditioned pair: what the guidance sees and, when it differs, what the matching cost sees.
pub struct Conditioned<'a> {
    /// Aligned and stretched (the input itself, not a copy, when neither was needed): the colour weights of the
    /// mean field, the weighted median and the planes use it.
    pub guide: Cow<'a, StereoPair>,
    /// The guide pair denoised, for the matching cost only; `None` when nothing was filtered.
    pub cost: Option<StereoPair>,
    /// What was measured.
    pub stats: PairStats,
}

impl Conditioned<'_> {
    /// The pair the matching cost is computed from.
    pub fn cost_pair(&self) -> &StereoPair {
        self.cost.as_ref().unwrap_or(&self.guide)
    }
}

/// Conditions a pair as the module doc says. Only the matching cost sees the denoised images: the guidance
/// keeps the original edges (denoising it too was measured worse, docs/tuning-log.md).
pub fn condition_pair<'a>(pair: &'a StereoPair, p: &ConditionParams) -> Conditioned<'a> {
    let mut guide = Cow::Borrowed(pair);
    if p.match_histograms {
        let right = match_histograms(&pair.right, &pair.left);
        guide.to_mut().right = right;
    }
    // Each view by its own range: a view darker than the other (exposure, gamma) is not pushed below 0 by the
    // other's gain, and the two end up with about the same contrast.
    let mut gain = [1.0f32; 2];
    if p.stretch {
        for (view, g) in gain.iter_mut().enumerate() {
            let img = if view == 0 { &guide.left } else { &guide.right };
            let (lo, hi) = percentiles(&img.to_grey().data, 0.005, 0.995);
            let range = (hi - lo).max(1.0);
            if TARGET_RANGE / range >= p.stretch_min_gain.max(1.0 + 1e-6) {
                *g = TARGET_RANGE / range;
                let (centre, gv) = (0.5 * (lo + hi), *g);
                let owned = guide.to_mut();
                let img = if view == 0 { &mut owned.left } else { &mut owned.right };
                for ch in &mut img.channels {
                    ch.iter_mut().for_each(|v| *v = ((*v - centre) * gv + 127.5).clamp(0.0, 255.0));
                }
            }
        }
    }
    // Compression artifacts count as noise of their measured size: JPEG flattens the flat regions the noise is
    // measured on (σn ≈ 0) while its block steps sit on the same image grid in both views and pull matches to
    // it. A step between two blocks with independent errors of σ has mean 2σ/√π, hence the factor.
    // The compression error is measured on the input (the stretch moves the quantisation steps off the integers)
    // and scaled by the view's gain.
    let view_noise = |img: &RgbImage, input: &RgbImage, gain: f32| {
        let grey = img.to_grey();
        let b = blockiness(&grey);
        let jpeg = if p.jpeg_noise {
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
    let [nl, nr] = match p.noise_ceiling {
        Some([cl, cr]) => [nl.min(cl), nr.min(cr)],
        None => [nl, nr],
    };
    let noise = [nl, nr];
    let (blocking, jpeg) = ([bl, br], [jl, jr]);
    // Below `denoise_min_sigma` (a clean camera, quantisation noise) a view is not filtered.
    let range = |n: f32| if n >= p.denoise_min_sigma { p.denoise_strength * n } else { 0.0 };
    let cost = (range(nl) > 0.0 || range(nr) > 0.0).then(|| StereoPair {
        left: bilateral(&guide.left, p.denoise_sigma_xy, range(nl)),
        right: bilateral(&guide.right, p.denoise_sigma_xy, range(nr)),
        ndisp: pair.ndisp,
    });
    let residual_grey_noise = if p.census_band > 0.0 {
        let c = cost.as_ref().unwrap_or(&guide);
        estimate_noise(&c.left.to_grey()).max(estimate_noise(&c.right.to_grey()))
    } else {
        0.0
    };
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
            *view = gaussian_blur(view, sigma);
            cost_blur[sharper] = sigma;
            cost = Some(pair);
        }
    }
    Conditioned { guide, cost, stats: PairStats { gain, noise, residual_grey_noise, cost_blur, blocking, jpeg } }
}

/// How sharp a grey image is, independently of its contrast: the mean |Laplacian| (4-neighbour) over the mean
/// |gradient| (central differences, both directions), interior pixels. Blur lowers the fine scale more than the
/// coarse one (MiddEval3's views agree to within 6 %; a view blurred by σ 1.5 px reads 2.5–3 times lower);
/// 0 for a flat image.
pub fn sharpness(grey: &Plane<f32>) -> f32 {
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

/// The Gaussian σ (px, in steps of 0.125 up to 3) whose blur brings `img`'s [`sharpness`] closest to `target`.
/// Sharpness falls as the blur grows, so a bisection finds the first step at or below `target` (six blurs instead
/// of 24: on a large image each is a pass over every pixel), and the closer of it and the step before wins.
fn matching_blur(grey: &Plane<f32>, target: f32) -> f32 {
    const STEPS: usize = 24;
    let sigma = |k: usize| k as f32 * 0.125;
    // Each step's sharpness once (a blur of the whole image each).
    let mut seen = [None; STEPS + 1];
    let mut at = |k: usize| {
        *seen[k].get_or_insert_with(|| {
            let blurred = gaussian_blur_plane(&grey.data, grey.width, grey.height, sigma(k));
            sharpness(&Plane::from_vec(grey.width, grey.height, blurred))
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

/// A separable Gaussian blur of every channel (σ px, radius ⌈3σ⌉, borders replicated; not quantised).
pub fn gaussian_blur(img: &RgbImage, sigma: f32) -> RgbImage {
    let (w, h) = img.dims();
    let mut out = img.clone();
    for ch in &mut out.channels {
        *ch = gaussian_blur_plane(ch, w, h, sigma);
    }
    out
}

fn gaussian_blur_plane(data: &[f32], w: usize, h: usize, sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 || data.is_empty() {
        return data.to_vec();
    }
    let r = (3.0 * sigma).ceil() as usize;
    let kernel: Vec<f32> =
        (0..=2 * r).map(|k| (-((k as f32 - r as f32).powi(2)) / (2.0 * sigma * sigma)).exp()).collect();
    let total: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / total).collect();
    let mut tmp = vec![0.0f32; w * h];
    tmp.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let src = &data[y * w..][..w];
        for (x, o) in row.iter_mut().enumerate() {
            *o = kernel.iter().enumerate().map(|(k, kv)| kv * src[(x + k).saturating_sub(r).min(w - 1)]).sum();
        }
    });
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (k, kv) in kernel.iter().enumerate() {
            let src = &tmp[(y + k).saturating_sub(r).min(h - 1) * w..][..w];
            row.iter_mut().zip(src).for_each(|(o, s)| *o += kv * s);
        }
    });
    out
}

/// How much of each pixel's neighbourhood a coarse level `factor` times smaller cannot hold, as a factor for the
/// coarse prior's weight: `1 / (1 + D / (k·D̄))`, where D is the 3 × 3 mean of |G − the mean of G over the
/// `factor` × `factor` block holding the pixel| and D̄ its mean over the image (so the factor does not depend on the
/// image's contrast). Thin structures and edges, where the coarse answer is least reliable, get a weaker prior; flat
/// regions keep it. All ones when `k` ≤ 0 or the image has no detail at all.
pub fn detail_factor(grey: &Plane<f32>, factor: usize, k: f32) -> Plane<f32> {
    let (w, h) = grey.dims();
    let f = factor.max(1);
    // The mean of each F × F block (clipped at the borders), once per block.
    let bw = w.div_ceil(f);
    let mut block_means = vec![0.0f32; bw * h.div_ceil(f)];
    block_means.par_chunks_mut(bw.max(1)).enumerate().for_each(|(by, means)| {
        let (y0, y1) = (by * f, (by * f + f).min(h));
        for (bx, m) in means.iter_mut().enumerate() {
            let (x0, x1) = (bx * f, (bx * f + f).min(w));
            let mut sum = 0.0f32;
            for yy in y0..y1 {
                sum += grey.row(yy)[x0..x1].iter().fold(0.0f32, |a, &g| a + g);
            }
            *m = sum / ((y1 - y0) * (x1 - x0)) as f32;
        }
    });
    let mut lost = Plane::new(w, h, 0.0f32);
    lost.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
        let (g, means) = (grey.row(y), &block_means[y / f * bw..]);
        for (x, v) in row.iter_mut().enumerate() {
            *v = g[x] - means[x / f];
        }
    });
    let mut out = crate::cost::local_mean_abs(&lost, 1);
    let scale = k * crate::cost::plane_mean(&out);
    if scale > 0.0 && scale.is_finite() {
        out.data.iter_mut().for_each(|d| *d = 1.0 / (1.0 + *d / scale));
    } else {
        out.data.fill(1.0);
    }
    out
}

/// The range of disparities a coarse prior accepts at each pixel: `(low, high)`, both the pixel's own value
/// except beside a depth edge, where the values within `radius` pixels (a square window) differ by more than
/// `min_jump`; there they are the window's smallest and largest. Non-finite values (no prior) are skipped, and
/// stay non-finite. `radius` 0 returns two copies.
pub fn edge_range(coarse: &Plane<f32>, radius: usize, min_jump: f32) -> (Plane<f32>, Plane<f32>) {
    let (w, h) = coarse.dims();
    if radius == 0 || w == 0 || h == 0 {
        return (coarse.clone(), coarse.clone());
    }
    let (lo, hi) = (
        window_extreme(coarse, radius, f32::INFINITY, f32::min),
        window_extreme(coarse, radius, f32::NEG_INFINITY, f32::max),
    );
    let mut low = coarse.clone();
    let mut high = coarse.clone();
    low.data.par_iter_mut().zip(&mut high.data).enumerate().for_each(|(i, (l, h))| {
        if l.is_finite() && hi.data[i] - lo.data[i] > min_jump {
            (*l, *h) = (lo.data[i], hi.data[i]);
        }
    });
    (low, high)
}

/// Block artifacts of JPEG-like compression: the mean absolute step between neighbours across the columns (and
/// rows) of an 8-pixel grid, at the grid's strongest phase, above the median step over the eight phases, less
/// three standard errors of that phase's mean (so a strong random texture, whose phases differ by chance, reads
/// as 0); 0 for an image without a block grid. Grey levels; the mean over both directions.
pub fn blockiness(grey: &Plane<f32>) -> f32 {
    let (w, h) = grey.dims();
    if w < 16 || h < 16 {
        return 0.0;
    }
    // Per phase: the sum of the steps, of their squares, and their number.
    let mut cols = [(0.0f64, 0.0f64, 0u64); 8];
    let mut rows = [(0.0f64, 0.0f64, 0u64); 8];
    let add = |acc: &mut (f64, f64, u64), step: f32| {
        let s = f64::from(step.abs());
        *acc = (acc.0 + s, acc.1 + s * s, acc.2 + 1);
    };
    for y in 0..h {
        let row = grey.row(y);
        for x in 0..w - 1 {
            add(&mut cols[x % 8], row[x + 1] - row[x]);
        }
        if y + 1 < h {
            for (a, b) in row.iter().zip(grey.row(y + 1)) {
                add(&mut rows[y % 8], b - a);
            }
        }
    }
    let excess = |phases: [(f64, f64, u64); 8]| {
        let stats: Vec<(f64, f64)> = phases
            .iter()
            .map(|&(sum, sq, n)| {
                let n = n.max(1) as f64;
                let mean = sum / n;
                (mean, ((sq / n - mean * mean).max(0.0) / n).sqrt())
            })
            .collect();
        let (max, std_err) = stats.iter().copied().fold((f64::MIN, 0.0), |a, b| if b.0 > a.0 { b } else { a });
        let mut means: Vec<f64> = stats.iter().map(|s| s.0).collect();
        means.sort_by(f64::total_cmp);
        (max - 0.5 * (means[3] + means[4]) - 3.0 * std_err).max(0.0)
    };
    (0.5 * (excess(cols) + excess(rows))) as f32
}

/// Blocks [`jpeg_noise`] looks at, at most (every k-th block beyond that).
const JPEG_MAX_BLOCKS: usize = 2048;

/// AC frequencies (8u + v, u + v = 3 or 4) that [`jpeg_noise`] looks at first: the standard tables at quality 90
/// or below quantise them with steps of 3 or more. Unless most of them (`JPEG_PROBES_NEEDED`) show such a step,
/// the image is taken as not JPEG-compressed: a regular synthetic pattern repeats a few exact coefficient values,
/// which can look quantised at some frequency, but not at most of these.
const JPEG_PROBES: [usize; 9] = [3, 10, 17, 24, 4, 11, 18, 25, 32];

/// See [`JPEG_PROBES`].
const JPEG_PROBES_NEEDED: usize = 6;

/// The compression error σ of a JPEG-decoded grey image, in grey levels (0 when it shows no JPEG quantisation).
///
/// JPEG quantises each 8 × 8 block's DCT coefficient (u, v) to a multiple of a step q(u, v), so the decoded
/// image's coefficients cluster at those multiples (up to the rounding to 8 bits). For each AC frequency, q is
/// the largest step (2 to 255, the range of baseline tables) at which the coefficients of magnitude above q/2 sit
/// at its multiples: the mean of cos(2πc/q) is above 0.6. The error of a coefficient is then modelled with a
/// Laplacian of the coefficient (scale b from the share p0 quantised to 0: P(|c| ≥ q/2) = exp(−q/2b)): inside
/// the dead zone it is the coefficient itself, E[c² | |c| < q/2]; elsewhere its position inside its step, the
/// variance of an exponential truncated to one step. The DCT is orthonormal, so the pixels' error variance is the
/// mean over the 64 coefficients. One-image noise estimates cannot see this error: compression removes exactly
/// the high frequencies they measure. Measured on MiddEval3 trainingQ compressed at quality 90 / 75 / 40, it
/// reads 1.6–3.1 / 2.7–4.8 / 3.6–6.5 where the true error is 1.3–2.5 / 2.1–4.1 / 3.2–6.4; uncompressed images,
/// noisy or not, read 0. Blocks on the grid from the image's origin (an image cropped after compression is not
/// seen).
pub fn jpeg_noise(grey: &Plane<f32>) -> f32 {
    let (w, h) = grey.dims();
    let (bw, bh) = (w / 8, h / 8);
    let blocks = bw * bh;
    if blocks < 64 {
        return 0.0;
    }
    let step = blocks.div_ceil(JPEG_MAX_BLOCKS);
    let basis = dct8_basis();
    let per_block: Vec<[f32; 64]> = (0..blocks)
        .step_by(step)
        .collect::<Vec<_>>()
        .par_iter()
        .map(|&b| {
            let (x0, y0) = ((b % bw) * 8, (b / bw) * 8);
            let mut px = [0.0f32; 64];
            for (y, row) in px.chunks_exact_mut(8).enumerate() {
                row.copy_from_slice(&grey.row(y0 + y)[x0..x0 + 8]);
            }
            dct8(&px, &basis)
        })
        .collect();
    // Frequency f's coefficients, by decreasing magnitude.
    let coefficients = |f: usize| {
        let mut v: Vec<f32> = per_block.iter().map(|c| c[f]).collect();
        v.sort_unstable_by(|a, b| b.abs().total_cmp(&a.abs()));
        v
    };
    let quantised = JPEG_PROBES.par_iter().filter(|&&f| quantisation_step(&coefficients(f)).is_some_and(|q| q >= 3));
    if quantised.count() < JPEG_PROBES_NEEDED {
        return 0.0;
    }
    // Per frequency in parallel, summed in frequency order (a parallel float sum would depend on the thread count).
    let per_frequency: Vec<f64> = (1..64)
        .into_par_iter()
        .map(|f| {
            let c = coefficients(f);
            let Some(q) = quantisation_step(&c) else { return 0.0 };
            let half = q as f32 / 2.0;
            let zero = 1.0 - c.partition_point(|v| v.abs() >= half) as f64 / c.len() as f64;
            coefficient_error_variance(f64::from(q), zero)
        })
        .collect();
    let variance: f64 = per_frequency.iter().sum();
    (variance / 64.0).sqrt() as f32
}

/// The step (2 to 255) of a frequency's quantisation, if its coefficients (by decreasing magnitude) show one
/// (see [`jpeg_noise`]).
fn quantisation_step(c: &[f32]) -> Option<u32> {
    let need = 20.max(c.len() / 500);
    let mut best = None;
    for q in 2..=255u32 {
        let half = q as f32 / 2.0;
        let n = c.partition_point(|v| v.abs() > half);
        if n < need {
            break;
        }
        let k = std::f32::consts::TAU / q as f32;
        let score: f64 = c[..n].iter().map(|&v| f64::from((k * v).cos())).sum::<f64>() / n as f64;
        if score > 0.6 {
            best = Some(q);
        }
    }
    best
}

/// The error variance of a coefficient quantised with step `q` of which the share `zero` went to 0, under a
/// Laplacian model (see [`jpeg_noise`]).
fn coefficient_error_variance(q: f64, zero: f64) -> f64 {
    // None in the dead zone (no scale to fit), or all of it (the coefficient is unknown): uniform over one step.
    if zero <= 0.0 || zero >= 1.0 {
        return q * q / 12.0;
    }
    let b = q / (2.0 * -(1.0 - zero).ln());
    // E[x²] of an exponential of scale b truncated to [0, a]: 2b² − (a² + 2ab) e^{−a/b} / (1 − e^{−a/b}).
    let truncated_second = |a: f64| {
        let e = (-a / b).exp();
        2.0 * b * b - (a * a + 2.0 * a * b) * e / (1.0 - e)
    };
    // Variance of an exponential of scale b truncated to one step of width q.
    let t = q / b;
    let in_step = b * b - q * q * (-t).exp() / (1.0 - (-t).exp()).powi(2);
    zero * truncated_second(q / 2.0) + (1.0 - zero) * in_step
}

/// The orthonormal 8-point DCT-II basis, `basis[k][n]`.
fn dct8_basis() -> [[f32; 8]; 8] {
    let mut m = [[0.0f32; 8]; 8];
    for (k, row) in m.iter_mut().enumerate() {
        let scale = if k == 0 { (1.0f64 / 8.0).sqrt() } else { (2.0f64 / 8.0).sqrt() };
        for (n, v) in row.iter_mut().enumerate() {
            *v = (scale * (std::f64::consts::PI * (2 * n + 1) as f64 * k as f64 / 16.0).cos()) as f32;
        }
    }
    m
}

/// The 2-D DCT of an 8 × 8 block (row-major), coefficient (u, v) at 8u + v.
fn dct8(px: &[f32; 64], basis: &[[f32; 8]; 8]) -> [f32; 64] {
    let mut rows = [0.0f32; 64];
    for y in 0..8 {
        for k in 0..8 {
            rows[y * 8 + k] = (0..8).map(|n| basis[k][n] * px[y * 8 + n]).sum();
        }
    }
    let mut out = [0.0f32; 64];
    for u in 0..8 {
        for v in 0..8 {
            out[u * 8 + v] = (0..8).map(|y| basis[u][y] * rows[y * 8 + v]).sum();
        }
    }
    out
}

/// The mean of the three channels' noise σ ([`estimate_noise`]).
pub fn channel_noise(img: &RgbImage) -> f32 {
    let (w, h) = img.dims();
    let sum: f32 = img.channels.par_iter().map(|c| noise_of(c, w, h)).sum();
    sum / 3.0
}

/// The values at fractions `a` and `b` of the sorted data (nearest rank), non-finite values left out.
fn percentiles(data: &[f32], a: f64, b: f64) -> (f32, f32) {
    let mut v: Vec<f32> = data.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (0.0, 0.0);
    }
    (crate::cost::rank_value(&mut v, a), crate::cost::rank_value(&mut v, b))
}

/// Noise σ of a grey image in grey levels, robust to texture: the 3 × 3 operator
/// `[1 −2 1; −2 4 −2; 1 −2 1]` (Immerkær, 1996) cancels planes and smooth ramps, leaving 6σ of white noise; its
/// absolute response is taken at the pixels whose Sobel gradient is in the lower half (flat regions), and the
/// median of those, divided by 6 × 0.6745 (the median absolute value of a unit normal), estimates σ.
pub fn estimate_noise(grey: &Plane<f32>) -> f32 {
    noise_of(&grey.data, grey.width, grey.height)
}

/// [`estimate_noise`] on a row-major `w` × `h` channel.
fn noise_of(data: &[f32], w: usize, h: usize) -> f32 {
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
    let median_grad = crate::cost::rank_value(&mut grad.clone(), FLAT_FRACTION);
    let mut flat: Vec<f32> = resp.iter().zip(&grad).filter(|(_, g)| **g <= median_grad).map(|(r, _)| *r).collect();
    crate::cost::rank_value(&mut flat, 0.5) / (6.0 * 0.6745)
}

/// Maps each channel of `src` onto the distribution of the same channel of `reference` (histogram
/// specification on 256 bins: each source level goes to the reference level of the same cumulative frequency,
/// taken at the middle of the source level's mass).
fn match_histograms(src: &RgbImage, reference: &RgbImage) -> RgbImage {
    let mut out = src.clone();
    for c in 0..3 {
        let hs = histogram(&src.channels[c]);
        let hr = histogram(&reference.channels[c]);
        let (ns, nr) = (src.len() as f64, reference.len() as f64);
        let mut cum_r = Vec::with_capacity(256);
        let mut acc = 0.0;
        for v in hr {
            acc += v as f64 / nr;
            cum_r.push(acc);
        }
        let mut lut = [0.0f32; 256];
        let mut acc = 0.0;
        for (level, &count) in hs.iter().enumerate() {
            let mid = acc + 0.5 * count as f64 / ns;
            acc += count as f64 / ns;
            // The reference level where the cumulative frequency reaches `mid`, interpolated within the bin.
            let k = cum_r.partition_point(|&c| c < mid).min(255);
            let below = if k == 0 { 0.0 } else { cum_r[k - 1] };
            let width = (cum_r[k] - below).max(1e-12);
            lut[level] = (k as f64 - 0.5 + ((mid - below) / width).clamp(0.0, 1.0)).clamp(0.0, 255.0) as f32;
        }
        out.channels[c].iter_mut().for_each(|v| *v = lut[v.round().clamp(0.0, 255.0) as usize]);
    }
    out
}

fn histogram(data: &[f32]) -> [u64; 256] {
    let mut h = [0u64; 256];
    for v in data {
        h[v.round().clamp(0.0, 255.0) as usize] += 1;
    }
    h
}

/// A bilateral filter on RGB (spatial σ `sigma_xy` pixels, radius ⌈2σ⌉; range σ `sigma_range` on the Euclidean
/// colour distance); the image unchanged if `sigma_range` ≤ 0.
fn bilateral(img: &RgbImage, sigma_xy: f32, sigma_range: f32) -> RgbImage {
    if sigma_range <= 0.0 || sigma_xy <= 0.0 {
        return img.clone();
    }
    let (w, h) = img.dims();
    let spatial = bilateral_taps(sigma_xy);
    let inv_range = 1.0 / (2.0 * sigma_range * sigma_range);
    let mut out = RgbImage::new(w, h);
    let [r_out, g_out, b_out] = &mut out.channels;
    let [r_in, g_in, b_in] = &img.channels;
    let rows = r_out.par_chunks_mut(w).zip(g_out.par_chunks_mut(w)).zip(b_out.par_chunks_mut(w)).enumerate();
    rows.for_each_init(
        || vec![0.0f32; 4 * w],
        |acc, (y, ((ro, go), bo))| {
            acc.fill(0.0);
            let (ar, rest) = acc.split_at_mut(w);
            let (ag, rest) = rest.split_at_mut(w);
            let (ab, total) = rest.split_at_mut(w);
            let centre = [&r_in[y * w..][..w], &g_in[y * w..][..w], &b_in[y * w..][..w]];
            // Tap by tap over the whole row (the taps in the same order for every pixel): contiguous, so the
            // loop vectorises.
            for &(dx, dy, ls) in &spatial {
                let yy = y as isize + dy;
                if yy < 0 || yy >= h as isize {
                    continue;
                }
                let (x0, x1) = ((-dx).max(0) as usize, (w as isize - dx.max(0)).max(0) as usize);
                if x0 >= x1 {
                    continue;
                }
                let off = yy as usize * w;
                let q0 = (x0 as isize + dx) as usize;
                let n = x1 - x0;
                bilateral_tap(
                    [&r_in[off + q0..][..n], &g_in[off + q0..][..n], &b_in[off + q0..][..n]],
                    [&centre[0][x0..x1], &centre[1][x0..x1], &centre[2][x0..x1]],
                    ls,
                    inv_range,
                    [&mut ar[x0..x1], &mut ag[x0..x1], &mut ab[x0..x1], &mut total[x0..x1]],
                );
            }
            for x in 0..w {
                (ro[x], go[x], bo[x]) = (ar[x] / total[x], ag[x] / total[x], ab[x] / total[x]);
            }
        },
    );
    out
}

/// The taps of [`bilateral`]'s window (radius ⌈2σ⌉), row by row: (dx, dy, the log of the spatial weight).
fn bilateral_taps(sigma_xy: f32) -> Vec<(isize, isize, f32)> {
    let r = (2.0 * sigma_xy).ceil() as isize;
    (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
        .map(|(dx, dy)| (dx, dy, -((dx * dx + dy * dy) as f32) / (2.0 * sigma_xy * sigma_xy)))
        .collect()
}

/// One tap of [`bilateral`] over a run of pixels: neighbours `q`, centres `c` (R, G, B), accumulated into the
/// weighted sums and the total weight. Compiled for AVX2 + FMA as well, picked at run time (same results: no
/// contraction of a·b + c).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn bilateral_tap(q: [&[f32]; 3], c: [&[f32]; 3], ls: f32, inv_range: f32, acc: [&mut [f32]; 4]) {
    let [ar, ag, ab, total] = acc;
    let n = total.len();
    let (qr, qg, qb) = (&q[0][..n], &q[1][..n], &q[2][..n]);
    let (cr, cg, cb) = (&c[0][..n], &c[1][..n], &c[2][..n]);
    let (ar, ag, ab) = (&mut ar[..n], &mut ag[..n], &mut ab[..n]);
    for i in 0..n {
        let d2 =
            (qr[i] - cr[i]) * (qr[i] - cr[i]) + (qg[i] - cg[i]) * (qg[i] - cg[i]) + (qb[i] - cb[i]) * (qb[i] - cb[i]);
        let wt = exp_nonpositive(ls - d2 * inv_range);
        total[i] += wt;
        ar[i] += wt * qr[i];
        ag[i] += wt * qg[i];
        ab[i] += wt * qb[i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The bilateral filter as written first: pixel by pixel, libm's exp (the reference for [`bilateral`]).
    fn bilateral_reference(img: &RgbImage, sigma_xy: f32, sigma_range: f32) -> RgbImage {
        if sigma_range <= 0.0 || sigma_xy <= 0.0 {
            return img.clone();
        }
        let (w, h) = img.dims();
        let spatial = bilateral_taps(sigma_xy);
        let inv_range = 1.0 / (2.0 * sigma_range * sigma_range);
        let mut out = RgbImage::new(w, h);
        let [r_out, g_out, b_out] = &mut out.channels;
        r_out.par_chunks_mut(w).zip(g_out.par_chunks_mut(w)).zip(b_out.par_chunks_mut(w)).enumerate().for_each(
            |(y, ((ro, go), bo))| {
                for x in 0..w {
                    let c = img.rgb(y * w + x);
                    let (mut acc, mut total) = ([0.0f32; 3], 0.0f32);
                    for &(dx, dy, ls) in &spatial {
                        let (xx, yy) = (x as isize + dx, y as isize + dy);
                        if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                            continue;
                        }
                        let q = img.rgb(yy as usize * w + xx as usize);
                        let d2 = (q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2) + (q[2] - c[2]).powi(2);
                        let wt = (ls - d2 * inv_range).exp();
                        total += wt;
                        acc.iter_mut().zip(q).for_each(|(a, v)| *a += wt * v);
                    }
                    (ro[x], go[x], bo[x]) = (acc[0] / total, acc[1] / total, acc[2] / total);
                }
            },
        );
        out
    }

    /// The row-vectorised bilateral filter (fast exp) matches the pixel-by-pixel reference (libm's exp) to within
    /// a thousandth of a grey level, borders included.
    #[test]
    fn bilateral_matches_the_reference() {
        let img = textured(97, 61, 6.0, 4);
        for (sxy, range) in [(3.0, 18.0), (1.5, 5.0), (3.0, 0.5)] {
            let (fast, slow) = (bilateral(&img, sxy, range), bilateral_reference(&img, sxy, range));
            for (a, b) in fast.channels.iter().flatten().zip(slow.channels.iter().flatten()) {
                assert!((a - b).abs() < 1e-3, "σxy {sxy}, range {range}: {a} vs {b}");
            }
        }
    }

    /// A textured image (a sum of ramps and a checker) with Gaussian noise of σ `sigma` per channel.
    fn textured(w: usize, h: usize, sigma: f64, seed: u64) -> RgbImage {
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

    /// A one-pixel line on a flat background: the 2 × 2 block average cannot hold it, so the prior is weakest on
    /// and beside it and untouched far from it; the factor ignores the image's contrast, and a flat image keeps
    /// the whole prior.
    #[test]
    fn detail_factor_weakens_the_prior_at_thin_structures_only() {
        let (w, h) = (24, 12);
        let line = |contrast: f32| Plane {
            width: w,
            height: h,
            data: (0..w * h).map(|i| if i % w == 11 { 100.0 + contrast } else { 100.0 }).collect(),
        };
        let f = detail_factor(&line(60.0), 2, 3.0);
        let at = |x: usize| f.data[6 * w + x];
        assert!(at(11) < 0.5 && at(10) < 0.8, "on the line {} beside it {}", at(11), at(10));
        assert_eq!(at(2), 1.0);
        assert_eq!(at(20), 1.0);
        let weaker = detail_factor(&line(6.0), 2, 3.0);
        assert!(f.data.iter().zip(&weaker.data).all(|(a, b)| (a - b).abs() < 1e-6), "contrast changed the factor");
        let flat = detail_factor(&line(0.0), 2, 3.0);
        assert!(flat.data.iter().all(|&v| v == 1.0));
        assert!(detail_factor(&line(60.0), 2, 0.0).data.iter().all(|&v| v == 1.0));
    }

    /// The estimator finds the noise it is given (within 10 %), and about the rounding noise (0.29) without.
    /// An image of 8 × 8 blocks with independent offsets has a block step at its grid and none elsewhere; a smooth
    /// ramp and a random texture have none; a shifted grid is found at its own phase.
    #[test]
    fn blockiness_sees_a_block_grid_only() {
        let (w, h) = (96, 64);
        let offsets = crate::test_util::rand_vec((w / 8) * (h / 8), 5);
        let blocks = |phase: usize| {
            let data = (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w + phase) / 8 % (w / 8), i / w / 8);
                    100.0 + 20.0 * offsets[y * (w / 8) + x] + 0.1 * (i % w) as f32
                })
                .collect();
            Plane::from_vec(w, h, data)
        };
        let b = blockiness(&blocks(0));
        assert!(b > 2.0, "block grid: {b}");
        assert!((blockiness(&blocks(3)) - b).abs() < 0.6 * b, "shifted grid: {}", blockiness(&blocks(3)));
        let ramp = Plane::from_vec(w, h, (0..w * h).map(|i| (i % w) as f32).collect());
        assert!(blockiness(&ramp) < 1e-3);
        let texture = Plane::from_vec(w, h, crate::test_util::rand_vec(w * h, 9).iter().map(|v| 255.0 * v).collect());
        assert!(blockiness(&texture) < 0.1 * b, "texture: {}", blockiness(&texture));
    }

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

    /// JPEG's compression error is read from the quantisation of the block DCT: of the order of the true error at
    /// two qualities, and 0 on an uncompressed image, with or without noise (the noise-free one is a regular
    /// pattern whose coefficients repeat a few exact values: it looks quantised at 3 of the 9 probe frequencies);
    /// the one-image estimate reads less than the true error after compression. (Where whole frequencies are
    /// quantised to 0, as at quality 50 on this image's sharp squares, their loss cannot be seen and the estimate
    /// is low: 4.4 against 7.6.)
    #[test]
    fn jpeg_noise_reads_the_compression_error() {
        use crate::degrade::{View, degrade};
        let clean = textured(256, 192, 0.0, 8);
        for quality in [90u8, 75] {
            let recipe = format!("jpeg:{quality}").parse().unwrap();
            let jpeg = degrade(&clean, &recipe, View::Left, 1).unwrap();
            let (a, b) = (clean.to_grey(), jpeg.to_grey());
            let err = (a.data.iter().zip(&b.data).map(|(x, y)| f64::from(x - y).powi(2)).sum::<f64>()
                / a.data.len() as f64)
                .sqrt() as f32;
            let est = jpeg_noise(&b);
            eprintln!(
                "quality {quality}: true error {err:.2}, jpeg_noise {est:.2}, one-image {:.2}",
                channel_noise(&jpeg)
            );
            assert!(err > 0.5, "quality {quality}: the compression should lose something ({err})");
            assert!(est >= 0.6 * err && est <= 2.0 * err, "quality {quality}: estimated {est}, true {err}");
            assert!(channel_noise(&jpeg) < err, "quality {quality}: the one-image estimate sees it");
        }
        assert_eq!(jpeg_noise(&clean.to_grey()), 0.0);
        assert_eq!(jpeg_noise(&textured(256, 192, 5.0, 9).to_grey()), 0.0);
    }

    /// A right view with another gain and gamma is mapped back onto the left view's levels.
    #[test]
    fn histogram_matching_undoes_a_tone_curve() {
        let left = textured(120, 80, 2.0, 5);
        let mut right = left.clone();
        for ch in &mut right.channels {
            ch.iter_mut().for_each(|v| *v = (255.0 * (0.6 * *v / 255.0).powf(1.4)).round());
        }
        let matched = match_histograms(&right, &left);
        let mean_abs = |a: &RgbImage| {
            a.channels[1].iter().zip(&left.channels[1]).map(|(p, q)| (p - q).abs()).sum::<f32>() / a.len() as f32
        };
        assert!(mean_abs(&right) > 30.0, "the tone curve changes the image");
        assert!(mean_abs(&matched) < 2.0, "matched: {}", mean_abs(&matched));
    }

    /// The prior's free range: widened to the whole step within `radius` of a coarse depth edge, on both sides;
    /// a slope whose window spans less than `min_jump` keeps the point; a pixel without a prior keeps none.
    #[test]
    fn edge_range_frees_the_step_only_beside_depth_edges() {
        let (w, h) = (20, 5);
        // A step from 10 to 30 at x = 10, a gentle slope (0.1 px per px) on top, and one pixel without a prior.
        let mut coarse = Plane::from_vec(
            w,
            h,
            (0..w * h).map(|i| 0.1 * (i % w) as f32 + if i % w >= 10 { 20.0 } else { 10.0 }).collect(),
        );
        coarse.data[2 * w + 3] = f32::INFINITY;
        let (low, high) = edge_range(&coarse, 2, 8.0);
        for y in 0..h {
            for x in 0..w {
                let (c, lo, hi) = (coarse.row(y)[x], low.row(y)[x], high.row(y)[x]);
                if !c.is_finite() {
                    assert!(!lo.is_finite() && !hi.is_finite(), "no prior at ({x}, {y})");
                } else if (8..12).contains(&x) {
                    assert_eq!(
                        (lo, hi),
                        (0.1 * (x.saturating_sub(2)) as f32 + 10.0, 0.1 * (x + 2) as f32 + 20.0),
                        "({x}, {y})"
                    );
                } else {
                    assert_eq!((lo, hi), (c, c), "away from the step, ({x}, {y})");
                }
            }
        }
        // Radius 0: two copies.
        let (low, high) = edge_range(&coarse, 0, 8.0);
        assert!(low.data.iter().zip(&coarse.data).all(|(a, b)| a == b || (!a.is_finite() && !b.is_finite())));
        assert!(high.data.iter().zip(&coarse.data).all(|(a, b)| a == b || (!a.is_finite() && !b.is_finite())));
    }

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
        let half = Plane::from_vec(96, 64, grey.data.iter().map(|v| 0.5 * v).collect());
        assert!((sharpness(&grey) - sharpness(&half)).abs() < 1e-4);
        let blurred = gaussian_blur(&img, 1.5);
        let target = sharpness(&blurred.to_grey());
        assert!(target < 0.7 * sharpness(&grey), "{target} vs {}", sharpness(&grey));
        // Blurring 0.7 px by σ gives √(0.7² + σ²); 1.5 more is about 1.66 in all, so σ ≈ 1.5 matches.
        let sigma = matching_blur(&img.to_grey(), target);
        assert!((1.25..=1.75).contains(&sigma), "matching blur {sigma}");
        // The default conditions such a pair (without the stretch, so the guidance is the input itself): the
        // sharper (left) view of the cost pair is blurred, the guidance keeps it sharp.
        let p = ConditionParams { stretch: false, ..ConditionParams::default() };
        let pair = StereoPair { left: img.clone(), right: blurred, ndisp: 8 };
        let c = condition_pair(&pair, &p);
        assert!(c.stats.cost_blur[0] > 1.0 && c.stats.cost_blur[1] == 0.0, "{:?}", c.stats.cost_blur);
        assert!(c.guide.left == img, "the guidance keeps the sharp view");
        assert!(c.cost_pair().left != img, "the cost sees the blurred one");
        // Two views alike are left alone.
        let same = StereoPair { left: img.clone(), right: img.clone(), ndisp: 8 };
        assert_eq!(condition_pair(&same, &p).stats.cost_blur, [0.0, 0.0]);
    }

    /// A dark pair is stretched (each view by its own range); a full-contrast pair is left alone; off is off.
    #[test]
    fn stretch_only_for_low_contrast() {
        // Full contrast: a ramp over the whole 8-bit range.
        let mut bright = RgbImage::new(64, 48);
        bright
            .channels
            .iter_mut()
            .for_each(|c| c.iter_mut().enumerate().for_each(|(i, v)| *v = (255 * (i % 64) / 63) as f32));
        let mut dark = textured(64, 48, 1.0, 7);
        dark.channels.iter_mut().for_each(|c| c.iter_mut().for_each(|v| *v = (*v * 0.2).round()));
        let p = ConditionParams { stretch: true, ..ConditionParams::off() };
        let pair = |img: &RgbImage| StereoPair { left: img.clone(), right: img.clone(), ndisp: 4 };
        let dark_pair = pair(&dark);
        let out = condition_pair(&dark_pair, &p);
        assert!(out.stats.gain[0] > 3.0 && out.stats.gain[0] == out.stats.gain[1], "gain {:?}", out.stats.gain);
        assert!(matches!(out.guide, Cow::Owned(_)));
        assert_eq!(out.guide.left, out.guide.right);
        assert!(out.cost.is_none(), "nothing denoised");
        let bright_pair = pair(&bright);
        let out = condition_pair(&bright_pair, &p);
        assert_eq!(out.stats.gain, [1.0, 1.0]);
        assert!(matches!(out.guide, Cow::Borrowed(_)), "a full-contrast pair is not copied");
        let out = condition_pair(&dark_pair, &ConditionParams::off());
        assert_eq!(out.guide.left, dark);
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
        let pair = StereoPair { left: coarse.clone(), right: coarse, ndisp: 4 };
        let reduced = sigma as f32 / f as f32;
        let own = condition_pair(&pair, &ConditionParams { stretch: false, ..ConditionParams::default() });
        assert!(own.stats.noise[0] > 3.0 * reduced, "the estimate at 1/{f}: {:?}", own.stats.noise);
        let p = ConditionParams { stretch: false, noise_ceiling: Some([reduced; 2]), ..ConditionParams::default() };
        assert_eq!(condition_pair(&pair, &p).stats.noise, [reduced; 2]);
        let high = ConditionParams { noise_ceiling: Some([100.0; 2]), ..p };
        assert_eq!(condition_pair(&pair, &high).stats.noise, own.stats.noise);
    }

    /// Denoising is gated by the measured noise and reaches the cost pair only.
    #[test]
    fn denoising_only_above_the_gate_and_only_for_the_cost() {
        let noisy = textured(96, 64, 6.0, 11);
        let clean = textured(96, 64, 0.0, 11);
        let p = ConditionParams { denoise_strength: 3.0, denoise_min_sigma: 1.5, ..ConditionParams::off() };
        let pair = StereoPair { left: noisy.clone(), right: noisy.clone(), ndisp: 4 };
        let out = condition_pair(&pair, &p);
        assert_eq!(out.guide.left, noisy, "the guidance keeps the original");
        let err = |a: &RgbImage| {
            a.channels[0].iter().zip(&clean.channels[0]).map(|(p, q)| (p - q).abs()).sum::<f32>() / a.len() as f32
        };
        let denoised = &out.cost.as_ref().expect("σ 6 is above the gate").left;
        assert!(err(denoised) < 0.6 * err(&noisy), "{} vs {}", err(denoised), err(&noisy));
        let clean_pair = StereoPair { left: clean.clone(), right: clean, ndisp: 4 };
        assert!(condition_pair(&clean_pair, &p).cost.is_none(), "a clean pair is below the gate");
    }
}
