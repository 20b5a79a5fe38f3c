//! Denoising (module doc of [`crate::condition`], item 3): an edge-preserving bilateral filter, for the matching
//! cost only.

use rayon::prelude::*;

use crate::fastmath::exp_nonpositive;
use crate::image::RgbImage;

/// A bilateral filter on RGB (spatial σ `sigma_xy` pixels, radius ⌈2σ⌉; range σ `sigma_range` on the Euclidean
/// colour distance); the image unchanged if `sigma_range` ≤ 0.
pub(super) fn bilateral(img: &RgbImage, sigma_xy: f32, sigma_range: f32) -> RgbImage {
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
    use crate::condition::condition_pair;
    use crate::condition::test_images::textured;
    use crate::image::StereoPair;
    use crate::params::{ConditionParams, DenoiseParams};

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

    /// Denoising is gated by the measured noise and reaches the cost pair only.
    #[test]
    fn denoising_only_above_the_gate_and_only_for_the_cost() {
        let noisy = textured(96, 64, 6.0, 11);
        let clean = textured(96, 64, 0.0, 11);
        let p = {
            let off = ConditionParams::off();
            ConditionParams { denoise: DenoiseParams { strength: 3.0, min_sigma: 1.5, ..off.denoise }, ..off }
        };
        let pair = StereoPair::new(noisy.clone(), noisy.clone(), 4).unwrap();
        let out = condition_pair(&pair, &p, None);
        assert_eq!(*out.guide.left, noisy, "the guidance keeps the original");
        let err = |a: &RgbImage| {
            a.channels[0].iter().zip(&clean.channels[0]).map(|(p, q)| (p - q).abs()).sum::<f32>() / a.len() as f32
        };
        let denoised = &out.cost.as_ref().expect("σ 6 is above the gate").left;
        assert!(err(denoised) < 0.6 * err(&noisy), "{} vs {}", err(denoised), err(&noisy));
        let clean_pair = StereoPair::new(clean.clone(), clean, 4).unwrap();
        assert!(condition_pair(&clean_pair, &p, None).cost.is_none(), "a clean pair is below the gate");
    }
}
