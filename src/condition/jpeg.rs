//! JPEG (module doc of [`crate::condition`], item 3): the block grid's steps ([`blockiness`]) and the compression
//! error read from the quantisation of the block DCT ([`jpeg_noise`]); both count as noise.

use rayon::prelude::*;

use crate::image::Plane;

/// Block artifacts of JPEG-like compression: the mean absolute step between neighbours across the columns (and
/// rows) of an 8-pixel grid, at the grid's strongest phase, above the median step over the eight phases, less
/// three standard errors of that phase's mean (so a strong random texture, whose phases differ by chance, reads
/// as 0); 0 for an image without a block grid. Grey levels; the mean over both directions.
pub(crate) fn blockiness(grey: &Plane<f32>) -> f32 {
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
pub(crate) fn jpeg_noise(grey: &Plane<f32>) -> f32 {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::channel_noise;
    use crate::condition::test_images::textured;

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
            Plane::from_parts(w, h, data)
        };
        let b = blockiness(&blocks(0));
        assert!(b > 2.0, "block grid: {b}");
        assert!((blockiness(&blocks(3)) - b).abs() < 0.6 * b, "shifted grid: {}", blockiness(&blocks(3)));
        let ramp = Plane::from_parts(w, h, (0..w * h).map(|i| (i % w) as f32).collect());
        assert!(blockiness(&ramp) < 1e-3);
        let texture = Plane::from_parts(w, h, crate::test_util::rand_vec(w * h, 9).iter().map(|v| 255.0 * v).collect());
        assert!(blockiness(&texture) < 0.1 * b, "texture: {}", blockiness(&texture));
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
}
