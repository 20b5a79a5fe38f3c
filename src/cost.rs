//! Matching cost volume: Census transform + truncated gradient difference (paper §2).
//!
//! `C_L(x, y, d) = a·min(H(census_L(x, y), census_R(x − d, y)), τc) + b·min(|gx_L(x, y) − gx_R(x − d, y)|, τg)`,
//! where `H` is the Hamming distance of the Census codes on the grey image (window `census_width ×
//! census_height`, bit set where the neighbour is darker than the centre, borders replicated) and `gx` is the
//! Sobel-x gradient of the grey image.
//!
//! **Census support** (our addition, `census_support` τ > 0): bit k is compared only where neighbour k is within
//! τ grey levels of its centre in both windows, and counts ½ elsewhere (the expected distance of a bit that says
//! nothing): `H = Σ_k [k in both supports]·[bits differ] + ½·[k outside]`. Neighbours across a strong edge,
//! usually another surface, otherwise pull the match to their disparity (foreground fattening). τ = 0 is the
//! paper's Census.
//!
//! **Gradient normalisation** (our addition, `grad_norm_radius` r > 0): each view's `gx` is multiplied by
//! `(ḡ + ε) / (s + ε)`, where `s` is the mean |gx| over the (2r + 1)² window around the pixel and ḡ the mean of `s`
//! over the left view (for a whole pair, measured once on the full-resolution left view, so tiles share it). A
//! gain between the views, or a gamma (a gain that varies with brightness), scales `gx` and `s` alike, so it
//! cancels where `s ≫ ε`; the raw term charges `(1 − gain)·|gx|` at the true disparity. ε (Sobel units) keeps flat
//! regions, where `s` is noise, from being amplified; the adaptive front end widens it with the measured noise.
//! r = 0 is the paper's raw gradient.
//!
//! Out of view (`x − d < 0`) the true match is not in the other image; those entries get the *truncation cost*
//! `a·τc + b·τg`, the largest value an in-view entry can take, so the inference never prefers a label that looks
//! outside the image. (They are not left at 0, which would attract every border pixel to impossible labels.)
//!
//! The right view's volume is derived from the left one without a second Census pass:
//! `C_R(x, d) = C_L(x + d, d)`, with the truncation cost where `x + d ≥ width`.
//!
//! Layout `[(y·w + x)·nd + d]` (see [`CostVolume`]). Both volumes are built row-parallel with no per-pixel
//! allocation; cost O(w·h·nd).
//!
//! The row kernel is compiled for AVX2 + FMA + POPCNT as well and picked at run time, with the same results; the
//! `force-baseline` feature leaves only the baseline version (see [`crate::fastmath`], "SIMD in jem").

use rayon::prelude::*;

use crate::image::{CostVolume, Plane, RgbImage};
use crate::imgproc::filter::{local_mean_abs, pad_replicate, sobel_x};
use crate::imgproc::stats::{plane_mean, rank_value};
use crate::params::CostParams;

/// [`census_transform_banded`] without a dead band: the binary Census, for the tests.
#[cfg(test)]
pub(crate) fn census_transform(grey: &Plane<f32>, win_w: usize, win_h: usize) -> Plane<u64> {
    census_transform_banded(grey, win_w, win_h, 0.0)
}

/// Census codes of a grey image with a dead band: one bit per window neighbour, set when the neighbour is darker
/// than the centre by more than `band` grey levels; the neighbours in row-major order (centre skipped) fill the bits
/// from the highest used one down to bit 0 (of n = width·height − 1 bits, the k-th neighbour is bit n − 1 − k).
/// Borders replicate the edge pixels.
///
/// The image is padded once with replicated borders, so the inner loop has no clamping and runs over a whole
/// row per window offset (vectorised across x).
///
/// # Panics
/// If the window is even-sized or has more than 65 pixels (validated in [`crate::Params::validate`]).
pub(crate) fn census_transform_banded(grey: &Plane<f32>, win_w: usize, win_h: usize, band: f32) -> Plane<u64> {
    window_codes(grey, win_w, win_h, |n, c| n < c - band)
}

/// Census support masks, in the bit order of [`census_transform_banded`]: bit k is set when neighbour k is within `tau`
/// grey levels of the centre. A neighbour across a strong edge (most often another surface) tells nothing about
/// the centre's disparity and pulls the match towards its own: the foreground fattening of window costs.
///
/// # Panics
/// As [`census_transform_banded`].
pub(crate) fn support_mask(grey: &Plane<f32>, win_w: usize, win_h: usize, tau: f32) -> Plane<u64> {
    window_codes(grey, win_w, win_h, |n, c| (n - c).abs() <= tau)
}

/// One bit per window neighbour, `bit(neighbour, centre)`, in the order of [`census_transform_banded`] (borders
/// replicated; the image padded once, so the inner loop runs clamp-free over a whole row per window offset).
fn window_codes(grey: &Plane<f32>, win_w: usize, win_h: usize, bit: impl Fn(f32, f32) -> bool + Sync) -> Plane<u64> {
    assert!(win_w % 2 == 1 && win_h % 2 == 1 && win_w * win_h <= 65, "invalid census window {win_w}x{win_h}");
    let (w, h) = grey.dims();
    let (rx, ry) = (win_w / 2, win_h / 2);
    let padded = pad_replicate(grey, rx, ry);
    let pw = w + 2 * rx;
    let mut out = Plane::new(w, h, 0u64);
    out.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, codes)| {
        let center = &padded[(y + ry) * pw + rx..][..w];
        for dy in 0..win_h {
            let nrow = &padded[(y + dy) * pw..][..pw];
            for dx in 0..win_w {
                if dx == rx && dy == ry {
                    continue;
                }
                let nbr = &nrow[dx..][..w];
                for ((code, &n), &c) in codes.iter_mut().zip(nbr).zip(center) {
                    *code = (*code << 1) | u64::from(bit(n, c));
                }
            }
        }
    });
    out
}

/// The mask of the low `n` bits (all the bits of an `n`-bit Census code).
fn census_bits_mask(n: usize) -> u64 {
    if n == 0 { 0 } else { u64::MAX >> (64 - n) }
}

/// The mean over the image of its local contrast (the mean |Sobel x| over the (2r + 1)² window around each
/// pixel): ḡ of the gradient normalisation.
pub(crate) fn mean_local_contrast(grey: &Plane<f32>, radius: usize) -> f32 {
    plane_mean(&local_mean_abs(&sobel_x(grey), radius))
}

/// Scales each gradient by (`mean` + ε) / (s + ε), `s` its local mean |∇x|.
fn normalise_gradient(g: &mut Plane<f32>, s: &Plane<f32>, mean: f32, eps: f32) {
    g.data.iter_mut().zip(&s.data).for_each(|(g, &s)| *g *= (mean + eps) / (s + eps));
}

/// The cost given to out-of-view entries: the largest in-view cost, `a·τc + b·τg`.
pub fn truncation_cost(p: &CostParams) -> f32 {
    p.census_weight * p.census_trunc + p.grad_weight * p.grad_trunc
}

/// Builds the left view's cost volume (labels 0..ndisp), ḡ of the gradient normalisation measured on `left`.
///
/// # Panics
/// If the images differ in size (checked by [`crate::image::StereoPair::new`]) or the Census window is invalid.
pub fn build_cost_volume(left: &RgbImage, right: &RgbImage, ndisp: usize, p: &CostParams) -> CostVolume {
    build_cost_volume_then(left, right, ndisp, p, None, Vec::new(), |_, _| ()).0
}

/// [`build_cost_volume`] in `storage` (reused whatever its size and contents), with ḡ of the gradient
/// normalisation given (`grad_norm_mean`: measured once for a whole pair, so that tiles and the whole image share
/// it; `None` measures it on `left`), and `then(y, row)` called on each row of the volume as soon as it is written
/// (in the same parallel task, while the row is still in cache); its results, row by row.
pub(crate) fn build_cost_volume_then<R: Send>(
    left: &RgbImage,
    right: &RgbImage,
    ndisp: usize,
    p: &CostParams,
    grad_norm_mean: Option<f32>,
    storage: Vec<f32>,
    then: impl Fn(usize, &mut [f32]) -> R + Sync,
) -> (CostVolume, Vec<R>) {
    let (w, h) = left.dims();
    let rows = CostRows::new(left, right, p, grad_norm_mean);
    // Every entry is written below, rows in parallel: a fresh allocation is zeroed by the OS (no fill pass), a
    // reused one keeps what it held until then.
    let data = crate::image::reuse_storage(storage, w * h * ndisp);
    let mut vol = CostVolume { width: w, height: h, ndisp, data };
    let after = vol
        .data
        .par_chunks_mut(w * ndisp)
        .enumerate()
        .map_init(
            || RowScratch::new(w),
            |scratch, (y, row)| {
                cost_row(&rows, y, ndisp, scratch, row);
                then(y, row)
            },
        )
        .collect();
    (vol, after)
}

/// What [`cost_row`] reads: both views' census codes, support masks and gradients, the weights and truncations
/// `[census_weight, census_trunc, grad_weight, grad_trunc]`, and the out-of-view cost.
struct CostRows {
    cen_l: Plane<u64>,
    cen_r: Plane<u64>,
    /// The ternary Census's second plane (`cost.census_ternary` > 0): the neighbours brighter than the centre by
    /// more than the threshold (the first plane then holds those darker by more than it).
    bright: Option<(Plane<u64>, Plane<u64>)>,
    /// The support masks (`None`: every bit is compared).
    mask_l: Option<Plane<u64>>,
    mask_r: Option<Plane<u64>>,
    gx_l: Plane<f32>,
    gx_r: Plane<f32>,
    weights: [f32; 4],
    out_of_view: f32,
    /// Bits per Census code.
    bits: u32,
}

impl CostRows {
    /// Both views' Census codes, support masks and (normalised) gradients, ḡ of the gradient normalisation given or
    /// measured on `left` (see [`build_cost_volume_then`]).
    ///
    /// # Panics
    /// If the images differ in size or the Census window is invalid.
    fn new(left: &RgbImage, right: &RgbImage, p: &CostParams, grad_norm_mean: Option<f32>) -> CostRows {
        assert_eq!(left.dims(), right.dims(), "left and right images differ in size");
        let (grey_l, grey_r) = (left.to_grey(), right.to_grey());
        // Census support (both views): a bit is compared only where its neighbour is within `census_support` of the
        // centre in both windows; a bit outside the support counts ½, the expected distance of a bit that says
        // nothing (a constant count of 1 would favour the labels whose two masks overlap least).
        let (cw, ch) = (p.census_width, p.census_height);
        // With the ternary Census the first plane holds the neighbours darker than the centre by more than the
        // threshold and a second one those brighter by more than it (the Census of the negated image).
        let band = p.census_dead_band + p.census_ternary;
        let census = |g: &Plane<f32>| {
            let mask = (p.census_support > 0.0).then(|| support_mask(g, cw, ch, p.census_support));
            (census_transform_banded(g, cw, ch, band), mask)
        };
        let ((cen_l, mask_l), (cen_r, mask_r)) = rayon::join(|| census(&grey_l), || census(&grey_r));
        let bright = (p.census_ternary > 0.0).then(|| {
            let brighter = |g: &Plane<f32>| {
                let negated = Plane::from_parts(g.width, g.height, g.data.iter().map(|v| -v).collect());
                census_transform_banded(&negated, cw, ch, band)
            };
            rayon::join(|| brighter(&grey_l), || brighter(&grey_r))
        });
        let (mut gx_l, mut gx_r) = (sobel_x(&grey_l), sobel_x(&grey_r));
        if p.grad_norm_radius > 0 {
            let r = p.grad_norm_radius;
            let (sl, sr) = rayon::join(|| local_mean_abs(&gx_l, r), || local_mean_abs(&gx_r, r));
            let mean = grad_norm_mean.unwrap_or_else(|| plane_mean(&sl));
            normalise_gradient(&mut gx_l, &sl, mean, p.grad_norm_eps);
            normalise_gradient(&mut gx_r, &sr, mean, p.grad_norm_eps);
        }
        CostRows {
            cen_l,
            cen_r,
            bright,
            mask_l,
            mask_r,
            gx_l,
            gx_r,
            weights: [p.census_weight, p.census_trunc, p.grad_weight, p.grad_trunc],
            out_of_view: truncation_cost(p),
            bits: (p.census_width * p.census_height - 1) as u32,
        }
    }
}

/// The costs of row `y` (all pixels, `ndisp` labels each) into `row`, the right view's row reversed into `scratch`.
/// The Hamming distance counts the bits inside both pixels' support.
/// Compiled for AVX2 + FMA + POPCNT as well, picked at run time (same results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma+popcnt")))]
fn cost_row(rows: &CostRows, y: usize, ndisp: usize, scratch: &mut RowScratch, row: &mut [f32]) {
    let CostRows { cen_l, cen_r, bright, mask_l, mask_r, gx_l, gx_r, weights: [a, tc, b, tg], out_of_view, bits } =
        rows;
    let (a, tc, b, tg, out_of_view, bits) = (*a, *tc, *b, *tg, *out_of_view, *bits);
    let (mask_l, mask_r) = (mask_l.as_ref(), mask_r.as_ref());
    let w = cen_l.width;
    let all = census_bits_mask(bits as usize);
    let RowScratch { cr_rev, gr_rev, mr_rev, br_rev } = scratch;
    // The right row reversed: label d of left pixel x reads right pixel x − d = w−1−k with
    // k = w−1−x+d, so consecutive labels are consecutive k and the label loop runs forwards.
    for (k, ((c, g), m)) in cr_rev.iter_mut().zip(gr_rev.iter_mut()).zip(mr_rev.iter_mut()).enumerate() {
        *c = cen_r.data[y * w + w - 1 - k];
        *g = gx_r.data[y * w + w - 1 - k];
        *m = mask_r.map_or(all, |mr| mr.data[y * w + w - 1 - k]);
    }
    if let Some((_, br)) = bright {
        for (k, c) in br_rev.iter_mut().enumerate() {
            *c = br.data[y * w + w - 1 - k];
        }
    }
    let (cl_row, gl_row, ml_row) = (cen_l.row(y), gx_l.row(y), mask_l.map(|m| m.row(y)));
    let bl_row = bright.as_ref().map(|(bl, _)| bl.row(y));
    for (x, costs) in row.chunks_exact_mut(ndisp).enumerate() {
        let (cl, gl, ml) = (cl_row[x], gl_row[x], ml_row.map_or(all, |m| m[x]));
        let in_view = ndisp.min(x + 1);
        let k0 = w - 1 - x;
        let cr = &cr_rev[k0..][..in_view];
        let gr = &gr_rev[k0..][..in_view];
        let mr = &mr_rev[k0..][..in_view];
        let (inside, outside) = costs.split_at_mut(in_view);
        // Through i32 (twice ≤ 192): AVX2 converts signed integers to floats in one instruction, unsigned ones
        // in several. The truncations as compares and selects, without `f32::min`'s NaN fix-up (the same
        // values: nothing here is NaN).
        let total = |twice: u32, gr: f32| {
            let ham = twice as i32 as f32 * 0.5;
            let grad = (gl - gr).abs();
            a * if ham < tc { ham } else { tc } + b * if grad < tg { grad } else { tg }
        };
        match bl_row {
            None => {
                for (((c, &cr), &gr), &mr) in inside.iter_mut().zip(cr).zip(gr).zip(mr) {
                    // Twice the distance: 2 per differing bit inside the support, 1 per bit outside it.
                    let m = ml & mr;
                    *c = total(2 * ((cl ^ cr) & m).count_ones() + bits - m.count_ones(), gr);
                }
            }
            Some(bl_row) => {
                let bl = bl_row[x];
                let br = &br_rev[k0..][..in_view];
                for ((((c, &cr), &gr), &mr), &br) in inside.iter_mut().zip(cr).zip(gr).zip(mr).zip(br) {
                    // Twice the distance: each of the two planes' differing bits inside the support, 1 per bit
                    // outside it (a neighbour darker in one view and brighter in the other differs in both).
                    let m = ml & mr;
                    *c = total(((cl ^ cr) & m).count_ones() + ((bl ^ br) & m).count_ones() + bits - m.count_ones(), gr);
                }
            }
        }
        outside.fill(out_of_view);
    }
}

/// The per-thread rows [`cost_row`] reverses the right view's codes, gradients, masks and (ternary) second plane
/// into.
struct RowScratch {
    cr_rev: Vec<u64>,
    gr_rev: Vec<f32>,
    mr_rev: Vec<u64>,
    br_rev: Vec<u64>,
}

impl RowScratch {
    /// Scratch for rows of `w` pixels.
    fn new(w: usize) -> RowScratch {
        RowScratch { cr_rev: vec![0; w], gr_rev: vec![0.0; w], mr_rev: vec![0; w], br_rev: vec![0; w] }
    }
}

/// Derives the right view's volume from the left one: `C_R(x, d) = C_L(x + d, d)`, and `out_of_view` where
/// `x + d ≥ width`.
pub fn derive_right_volume(left: &CostVolume, out_of_view: f32) -> CostVolume {
    derive_right_volume_in(left, out_of_view, Vec::new())
}

/// [`derive_right_volume`] written into `storage` (any contents; resized as needed), so that a caller can reuse
/// an allocation that is already paged in.
pub fn derive_right_volume_in(left: &CostVolume, out_of_view: f32, storage: Vec<f32>) -> CostVolume {
    derive_right_volume_then(left, out_of_view, storage, |_, _| ()).0
}

/// [`derive_right_volume_in`], with `then(y, row)` called on each row as soon as it is written (as in
/// [`build_cost_volume_then`]); its results, row by row.
pub(crate) fn derive_right_volume_then<R: Send>(
    left: &CostVolume,
    out_of_view: f32,
    mut storage: Vec<f32>,
    then: impl Fn(usize, &mut [f32]) -> R + Sync,
) -> (CostVolume, Vec<R>) {
    let (w, h, nd) = (left.width, left.height, left.ndisp);
    storage = crate::image::reuse_storage(storage, w * h * nd); // every entry is written below
    let after = storage
        .par_chunks_mut(w * nd)
        .enumerate()
        .map(|(y, row)| {
            let lrow = &left.data[y * w * nd..][..w * nd];
            for (x, costs) in row.chunks_exact_mut(nd).enumerate() {
                let in_view = nd.min(w - x);
                let (inside, outside) = costs.split_at_mut(in_view);
                for (d, c) in inside.iter_mut().enumerate() {
                    *c = lrow[(x + d) * nd + d];
                }
                outside.fill(out_of_view);
            }
            then(y, row)
        })
        .collect();
    (CostVolume { width: w, height: h, ndisp: nd, data: storage }, after)
}

/// [`winner_take_all`] of one row of a volume with `ndisp` labels.
pub(crate) fn row_argmins(row: &[f32], ndisp: usize) -> Vec<f32> {
    row.chunks_exact(ndisp.max(1)).map(|c| argmin(c) as f32).collect()
}

/// Winner-take-all: the label of least cost at every pixel (ties go to the smaller label), as `f32`.
pub(crate) fn winner_take_all(vol: &CostVolume) -> Plane<f32> {
    let mut out = Plane::new(vol.width, vol.height, 0.0f32);
    out.data.par_iter_mut().enumerate().for_each(|(i, d)| {
        *d = argmin(vol.pixel(i)) as f32;
    });
    out
}

/// How flat each pixel's cost is over the labels, in (0, 1]: `1 / (1 + s / s̄)`, s the pixel's spread (mean − min
/// over its labels) and s̄ the median spread of the image. 1 where every label costs the same (an untextured
/// surface, where the cost says nothing), ½ at the median pixel, towards 0 where one label stands out. Relative to
/// the image's own median, so it does not depend on the cost's scale. All ones when the median spread is 0.
pub(crate) fn flatness(vol: &CostVolume) -> Plane<f32> {
    let m = vol.ndisp.max(1);
    let mut out = Plane::new(vol.width, vol.height, 0.0f32);
    // Each pixel's minimum and sum over its labels, in label order: a serial chain per pixel, so eight pixels at a
    // time, one per lane, for eight independent chains (the same operations per pixel as one at a time).
    const PIXELS: usize = 8;
    out.data.par_chunks_mut(PIXELS * 64).zip(vol.data.par_chunks(PIXELS * 64 * m)).for_each(|(out, costs)| {
        for (out, c) in out.chunks_mut(PIXELS).zip(costs.chunks(PIXELS * m)) {
            if out.len() == PIXELS {
                let (mut lo, mut sum) = ([f32::INFINITY; PIXELS], [0.0f32; PIXELS]);
                for d in 0..m {
                    for l in 0..PIXELS {
                        let v = c[l * m + d];
                        lo[l] = lo[l].min(v);
                        sum[l] += v;
                    }
                }
                for l in 0..PIXELS {
                    out[l] = sum[l] / m as f32 - lo[l];
                }
            } else {
                for (o, c) in out.iter_mut().zip(c.chunks_exact(m)) {
                    let (min, sum) = c.iter().fold((f32::INFINITY, 0.0f32), |(lo, s), &v| (lo.min(v), s + v));
                    *o = sum / m as f32 - min;
                }
            }
        }
    });
    if out.data.is_empty() {
        return out;
    }
    let median = rank_value(&mut out.data.clone(), 0.5);
    if median > 0.0 && median.is_finite() {
        out.data.par_iter_mut().for_each(|s| *s = 1.0 / (1.0 + *s / median));
    } else {
        out.data.fill(1.0);
    }
    out
}

/// Index of the smallest value (the first one on ties). NaN never wins.
#[inline]
pub(crate) fn argmin(values: &[f32]) -> usize {
    // The minimum over eight lanes, then its first position: two passes that vectorise, where one pass with a
    // running index does not.
    let min = crate::fastmath::lane_min(values);
    if min == f32::INFINITY {
        return 0;
    }
    values.iter().position(|&v| v == min).unwrap_or(0)
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // index loops read best in reference implementations
mod tests {
    use super::*;

    /// The spread of eight pixels at a time (one per lane) against one pixel at a time, bit for bit, with a
    /// remainder of pixels and labels that are not multiples of eight.
    #[test]
    fn flatness_in_lanes_matches_one_pixel_at_a_time() {
        let (w, h, m) = (37, 29, 13);
        let data: Vec<f32> = crate::test_util::rand_vec(w * h * m, 11).iter().map(|v| v * 50.0).collect();
        let vol = CostVolume { width: w, height: h, ndisp: m, data };
        let spread: Vec<f32> = vol
            .data
            .chunks_exact(m)
            .map(|c| {
                let (min, sum) = c.iter().fold((f32::INFINITY, 0.0f32), |(lo, s), &v| (lo.min(v), s + v));
                sum / m as f32 - min
            })
            .collect();
        let median = rank_value(&mut spread.clone(), 0.5);
        let expected: Vec<f32> = spread.iter().map(|s| 1.0 / (1.0 + *s / median)).collect();
        let got = flatness(&vol);
        assert!(got.data.iter().zip(&expected).all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    #[test]
    fn flatness_is_one_where_every_label_costs_the_same() {
        // Four pixels, three labels: flat, a clear winner, the median's spread, twice it.
        let data = vec![5.0, 5.0, 5.0, 0.0, 9.0, 9.0, 1.0, 2.0, 3.0, 0.0, 2.0, 4.0];
        let vol = CostVolume { width: 4, height: 1, ndisp: 3, data };
        let f = flatness(&vol);
        // Spreads 0, 6, 1, 2; the median (the upper middle of four) is 2.
        let expected = [1.0, 1.0 / 4.0, 1.0 / 1.5, 0.5];
        for (got, want) in f.data.iter().zip(expected) {
            assert!((got - want).abs() < 1e-6, "{:?} against {expected:?}", f.data);
        }
        let flat = CostVolume { width: 2, height: 1, ndisp: 2, data: vec![1.0; 4] };
        assert_eq!(flatness(&flat).data, vec![1.0, 1.0], "no spread anywhere: all flat");
    }

    /// Deterministic pseudo-random texture, integer values 0..255.
    pub(crate) fn noise(w: usize, h: usize, seed: u64) -> Vec<f32> {
        let mut rng = crate::rng::SplitMix64::new(seed);
        (0..w * h).map(|_| (rng.next_u64() % 256) as f32).collect()
    }

    fn grey_image(w: usize, h: usize, v: Vec<f32>) -> RgbImage {
        RgbImage { width: w, height: h, channels: [v.clone(), v.clone(), v] }
    }

    /// A random texture and its right view shifted by a per-row disparity field `disp(x, y)`, sampled from the
    /// left so that right(x − d) = left(x).
    fn shifted_pair(w: usize, h: usize, disp: impl Fn(usize, usize) -> usize) -> (RgbImage, RgbImage) {
        let left = noise(w, h, 7);
        let mut right = noise(w, h, 99);
        for y in 0..h {
            for x in 0..w {
                let d = disp(x, y);
                if x >= d {
                    right[y * w + x - d] = left[y * w + x];
                }
            }
        }
        (grey_image(w, h, left), grey_image(w, h, right))
    }

    /// A reference cost, computed entry by entry from the definition in the module doc with plain loops and
    /// nothing shared with the fast path but the grey conversion ([`RgbImage::to_grey`], the input edge): pixel
    /// `x` of `this` view against pixel `x + step·d` of `other` (`step` = −1 for the left view, +1 for the
    /// right), the truncation cost out of view. The Hamming distance of the two Census codes is counted straight
    /// from the windows (offsets where "the neighbour is darker than the centre" differs between the two pixels),
    /// without packing codes into bits; borders are replicated by clamping every coordinate.
    struct NaiveCost {
        this: Plane<f32>,
        other: Plane<f32>,
        step: isize,
        p: CostParams,
        /// ḡ of the gradient normalisation (see [`NaiveCost::new`]).
        mean: f32,
    }

    impl NaiveCost {
        /// `this` against `other`; ḡ as given, else the mean local contrast of the left view (summed in f64,
        /// row-major).
        fn new(this: &Plane<f32>, other: &Plane<f32>, step: isize, p: &CostParams, mean: Option<f32>) -> NaiveCost {
            let left = if step < 0 { this } else { other };
            let r = p.grad_norm_radius as isize;
            let mean = mean.unwrap_or_else(|| {
                let (w, h) = (left.width as isize, left.height as isize);
                let sum: f64 = (0..h)
                    .flat_map(|y| (0..w).map(move |x| (x, y)))
                    .map(|(x, y)| f64::from(Self::local_contrast(left, x, y, r)))
                    .sum();
                (sum / (w * h) as f64) as f32
            });
            NaiveCost { this: this.clone(), other: other.clone(), step, p: p.clone(), mean }
        }

        /// The grey value at (x, y), coordinates clamped into the image (replicated borders).
        fn grey(g: &Plane<f32>, x: isize, y: isize) -> f32 {
            let x = x.clamp(0, g.width as isize - 1) as usize;
            let y = y.clamp(0, g.height as isize - 1) as usize;
            g.data[y * g.width + x]
        }

        /// Sobel x at (x, y): `[-1 0 1; -2 0 2; -1 0 1]`, grouped as (right − left) per row, rows summed top to
        /// bottom with the middle one doubled.
        fn sobel(g: &Plane<f32>, x: isize, y: isize) -> f32 {
            let diff = |yy: isize| Self::grey(g, x + 1, yy) - Self::grey(g, x - 1, yy);
            diff(y - 1) + 2.0 * diff(y) + diff(y + 1)
        }

        /// The mean |Sobel x| over the (2r + 1)² window at (x, y), window coordinates clamped: row sums over dx,
        /// added over dy, each from −r up, times 1/(2r + 1)².
        fn local_contrast(g: &Plane<f32>, x: isize, y: isize, r: isize) -> f32 {
            let mut acc = 0.0f32;
            for dy in -r..=r {
                let mut row = 0.0f32;
                for dx in -r..=r {
                    let xx = (x + dx).clamp(0, g.width as isize - 1);
                    let yy = (y + dy).clamp(0, g.height as isize - 1);
                    row += Self::sobel(g, xx, yy).abs();
                }
                acc += row;
            }
            acc * (1.0 / ((2 * r + 1) * (2 * r + 1)) as f32)
        }

        /// Sobel x, normalised when `grad_norm_radius` > 0: × (ḡ + ε) / (s + ε).
        fn gradient(&self, g: &Plane<f32>, x: isize, y: isize) -> f32 {
            let r = self.p.grad_norm_radius as isize;
            if r == 0 {
                return Self::sobel(g, x, y);
            }
            let eps = self.p.grad_norm_eps;
            Self::sobel(g, x, y) * ((self.mean + eps) / (Self::local_contrast(g, x, y, r) + eps))
        }

        fn cost(&self, x: usize, y: usize, d: usize) -> f32 {
            let CostParams {
                census_width,
                census_height,
                census_dead_band: dead_band,
                census_ternary: ternary,
                census_support: tau,
                census_weight: a,
                census_trunc: tc,
                grad_weight: b,
                grad_trunc: tg,
                ..
            } = self.p;
            let (x, y) = (x as isize, y as isize);
            let xo = x + self.step * d as isize;
            if xo < 0 || xo >= self.this.width as isize {
                return a * tc + b * tg;
            }
            let (rx, ry) = (census_width as isize / 2, census_height as isize / 2);
            let mut twice = 0u32;
            for dy in -ry..=ry {
                for dx in -rx..=rx {
                    if (dx, dy) == (0, 0) {
                        continue;
                    }
                    let (n_this, c_this) = (Self::grey(&self.this, x + dx, y + dy), Self::grey(&self.this, x, y));
                    let (n_other, c_other) = (Self::grey(&self.other, xo + dx, y + dy), Self::grey(&self.other, xo, y));
                    // Support: the neighbour counts when it is within τ of the centre in both windows (τ = 0: off).
                    let inside = tau == 0.0 || ((n_this - c_this).abs() <= tau && (n_other - c_other).abs() <= tau);
                    // The ternary Census: darker, brighter or neither (beyond the dead band and the threshold);
                    // the binary one: darker beyond the dead band, or not.
                    let band = dead_band + ternary;
                    let dark = (n_this < c_this - band) != (n_other < c_other - band);
                    let bright = (n_this > c_this + band) != (n_other > c_other + band);
                    let differ = if ternary > 0.0 { u32::from(dark) + u32::from(bright) } else { 2 * u32::from(dark) };
                    twice += if inside { differ } else { 1 };
                }
            }
            let grad = (self.gradient(&self.this, x, y) - self.gradient(&self.other, xo, y)).abs();
            a * (twice as f32 * 0.5).min(tc) + b * grad.min(tg)
        }

        /// The whole volume, layout `[(y·w + x)·nd + d]`.
        fn volume(&self, ndisp: usize) -> Vec<f32> {
            let (w, h) = self.this.dims();
            let mut out = Vec::with_capacity(w * h * ndisp);
            for y in 0..h {
                for x in 0..w {
                    out.extend((0..ndisp).map(|d| self.cost(x, y, d)));
                }
            }
            out
        }
    }

    /// A random pair: the right view is the left one shifted by 2 px with every third pixel replaced by noise, so
    /// costs range from small (near d = 2) to truncated. `levels` quantises the grey values (few levels: many
    /// equal neighbours, so ties in the Census comparison and flat gradients); with `grey` all channels are equal.
    fn random_pair(w: usize, h: usize, seed: u64, levels: u64, grey: bool) -> (RgbImage, RgbImage) {
        let quantise = |v: f32| (v as u64 * levels / 256 * (255 / (levels - 1))) as f32;
        let channel = |k: u64| noise(w, h, seed * 7 + k).into_iter().map(quantise).collect::<Vec<f32>>();
        let left_ch: [Vec<f32>; 3] = if grey {
            let v = channel(0);
            [v.clone(), v.clone(), v]
        } else {
            [channel(0), channel(1), channel(2)]
        };
        let fresh = noise(w, h, seed * 7 + 5);
        let right_ch = left_ch.clone().map(|c| {
            (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    if i % 3 == 0 { quantise(fresh[i]) } else { c[y * w + (x + 2).min(w - 1)] }
                })
                .collect()
        });
        (RgbImage { width: w, height: h, channels: left_ch }, RgbImage { width: w, height: h, channels: right_ch })
    }

    /// The fast cost volume ([`cost_row`] through [`build_cost_volume`], and [`derive_right_volume_in`] for the
    /// right view) equals the naive per-entry cost everywhere: every pixel including the borders and images
    /// narrower than the Census window, every label including out-of-view ones, ndisp from 1 to above the width.
    ///
    /// Tolerance: none, the comparison is bit for bit. The Census comparisons and Hamming counts are integer, and
    /// every float operation (the Sobel differences and sums, |Δ|, the truncations, the two products and their sum)
    /// is the same IEEE f32 operation on the same operands in the same order as in the fast path (Rust neither
    /// contracts `a·b + c` nor reorders float operations, in either SIMD version). The right view's gradient term
    /// is |gx_R(x) − gx_L(x + d)| here and |gx_L(x + d) − gx_R(x)| in the fast path: equal exactly, since IEEE
    /// subtraction is antisymmetric under round-to-nearest.
    #[test]
    fn cost_volume_matches_the_naive_definition() {
        let params = [
            (CostParams::default(), None),
            (
                CostParams {
                    census_width: 5,
                    census_height: 3,
                    census_dead_band: 3.0,
                    census_ternary: 0.0,
                    census_support: 0.0,
                    census_weight: 2.0,
                    census_trunc: 5.0,
                    grad_weight: 0.45,
                    grad_trunc: 12.5,
                    grad_norm_radius: 0,
                    grad_norm_eps: 4.0,
                },
                None,
            ),
            (
                CostParams {
                    census_width: 9,
                    census_height: 7,
                    census_dead_band: 0.5,
                    census_ternary: 2.5,
                    census_support: 90.0,
                    census_weight: 0.7,
                    census_trunc: 21.0,
                    grad_weight: 1.3,
                    grad_trunc: 90.0,
                    grad_norm_radius: 1,
                    grad_norm_eps: 2.5,
                },
                None,
            ),
            (
                CostParams {
                    census_width: 1,
                    census_height: 3,
                    census_dead_band: 0.0,
                    census_ternary: 1.0,
                    census_support: 85.0,
                    census_weight: 1.0,
                    census_trunc: 1.0,
                    grad_weight: 0.1,
                    grad_trunc: 30.0,
                    grad_norm_radius: 3,
                    grad_norm_eps: 40.0,
                },
                Some(17.5),
            ),
        ];
        let mut checked = 0;
        for (case, &(w, h)) in [(1, 1), (2, 3), (5, 4), (17, 9), (31, 6)].iter().enumerate() {
            for (levels, grey) in [(256, false), (4, true)] {
                let (left, right) = random_pair(w, h, case as u64 + levels, levels, grey);
                let (grey_l, grey_r) = (left.to_grey(), right.to_grey());
                for (p, mean) in &params {
                    let mut ndisps = vec![1, 3, w, w + 5];
                    ndisps.sort_unstable();
                    ndisps.dedup();
                    for ndisp in ndisps {
                        let what = format!("{w}x{h}, {levels} levels, ndisp {ndisp}, {p:?}, ḡ {mean:?}");
                        let vl = build_cost_volume_then(&left, &right, ndisp, p, *mean, Vec::new(), |_, _| ()).0;
                        let naive_l = NaiveCost::new(&grey_l, &grey_r, -1, p, *mean);
                        assert_same_volume(&vl, &naive_l.volume(ndisp), &format!("left view, {what}"));
                        // The pipeline reuses a stale allocation: start from NaN so an unwritten entry shows.
                        let vr = derive_right_volume_in(&vl, truncation_cost(p), vec![f32::NAN; w * h * ndisp]);
                        let naive_r = NaiveCost::new(&grey_r, &grey_l, 1, p, *mean);
                        assert_same_volume(&vr, &naive_r.volume(ndisp), &format!("right view, {what}"));
                        checked += 2 * w * h * ndisp;
                    }
                }
            }
        }
        assert!(checked > 50_000, "{checked}");
    }

    /// A flat surface with noise below the ternary threshold has the same codes in both views (distance 0 at
    /// the true disparity), where the binary Census's comparisons of near-equal pixels flip with the noise.
    #[test]
    fn ternary_census_ignores_noise_below_its_threshold() {
        let (w, h) = (24, 9);
        // Grey 100 with noise of at most ±0.4 grey levels, different in the two views; the right view is the
        // left one's surface moved by 2 px.
        let jitter = |seed| noise(w, h, seed).into_iter().map(|v| 100.0 + (v / 255.0 - 0.5) * 0.8).collect();
        let (left, right) = (grey_image(w, h, jitter(3)), grey_image(w, h, jitter(4)));
        let at_true_label = |p: &CostParams| {
            let vol = build_cost_volume(&left, &right, 3, p);
            (4..w - 4).map(|x| vol.pixel(4 * w + x)[2]).sum::<f32>()
        };
        let binary = CostParams { census_support: 0.0, grad_weight: 0.0, ..CostParams::default() };
        let ternary = CostParams { census_ternary: 1.0, ..binary.clone() };
        assert_eq!(at_true_label(&ternary), 0.0, "every comparison is within the threshold: all equal");
        assert!(at_true_label(&binary) > 100.0, "the binary Census's bits follow the noise");
    }

    /// Bit-for-bit equality of a volume with a reference, naming the first differing entry.
    fn assert_same_volume(vol: &CostVolume, reference: &[f32], what: &str) {
        assert_eq!(vol.data.len(), reference.len(), "{what}");
        let nd = vol.ndisp;
        for (i, (&got, &want)) in vol.data.iter().zip(reference).enumerate() {
            let (p, d) = (i / nd, i % nd);
            let (x, y) = (p % vol.width, p / vol.width);
            assert_eq!(got.to_bits(), want.to_bits(), "{what}: ({x}, {y}) label {d}: {got} vs naive {want}");
        }
    }

    #[test]
    fn census_bits_on_a_tiny_image() {
        // 3x3 window on a 3x3 image: centre 5, neighbours row-major 1 2 3 / 4 . 6 / 7 8 9.
        let grey = Plane::from_parts(3, 3, (1..=9).map(|v| v as f32).collect());
        let c = census_transform(&grey, 3, 3);
        assert_eq!(c.at(1, 1), 0b1111_0000);
        // Top-left corner, replicated borders: neighbours 1 1 1 / 1 . 2 / 4 4 5 around centre 1 → none darker.
        assert_eq!(c.at(0, 0), 0);
    }

    #[test]
    fn sobel_on_a_ramp() {
        let grey = Plane::from_parts(4, 3, (0..12).map(|i| (i % 4) as f32 * 10.0).collect());
        let g = sobel_x(&grey);
        assert_eq!(g.at(1, 1), 80.0);
        assert_eq!(g.at(0, 1), 40.0, "replicated border halves the central difference");
    }

    #[test]
    fn argmin_recovers_constant_shift_exactly() {
        let (w, h, nd) = (64, 24, 16);
        let (left, right) = shifted_pair(w, h, |_, _| 5);
        let vol = build_cost_volume(&left, &right, nd, &CostParams::default());
        let wta = winner_take_all(&vol);
        for y in 3..h - 3 {
            for x in nd + 3..w - 3 {
                assert_eq!(wta.at(x, y), 5.0, "at ({x}, {y})");
            }
        }
    }

    #[test]
    fn argmin_recovers_a_varying_field() {
        let (w, h, nd) = (96, 40, 20);
        // Three vertical bands with disparities 3, 11, 17; compare away from band edges and borders.
        let field = |x: usize, _y: usize| {
            if x < 32 {
                3
            } else if x < 64 {
                11
            } else {
                17
            }
        };
        let (left, right) = shifted_pair(w, h, field);
        let vol = build_cost_volume(&left, &right, nd, &CostParams::default());
        let wta = winner_take_all(&vol);
        let mut checked = 0;
        for y in 3..h - 3 {
            for x in 3..w - 3 {
                let near_edge = [32usize, 64].iter().any(|&e| x + 24 > e && x < e + 4);
                if near_edge || x < field(x, y) + 3 {
                    continue;
                }
                assert_eq!(wta.at(x, y), field(x, y) as f32, "at ({x}, {y})");
                checked += 1;
            }
        }
        assert!(checked > 1000);
    }

    #[test]
    fn out_of_view_entries_get_the_truncation_cost() {
        let (left, right) = shifted_pair(20, 6, |_, _| 2);
        let p = CostParams::default();
        let vol = build_cost_volume(&left, &right, 8, &p);
        assert_eq!(vol.pixel(3)[4..], [truncation_cost(&p); 4]);
        assert!(vol.pixel(3)[..4].iter().all(|&c| c < truncation_cost(&p) + 1e-3));
    }

    #[test]
    fn right_volume_is_the_left_volume_resampled() {
        let (left, right) = shifted_pair(40, 9, |x, _| x % 5);
        // ḡ of the gradient normalisation is the left view's unless given: given, so that the mirrored pair (whose
        // left view is this right view) uses the same.
        let p = CostParams::default();
        let build =
            |l: &RgbImage, r: &RgbImage| build_cost_volume_then(l, r, 12, &p, Some(60.0), Vec::new(), |_, _| ()).0;
        let vl = build(&left, &right);
        let vr = derive_right_volume(&vl, truncation_cost(&p));
        for y in 0..9 {
            for x in 0..40 {
                for d in 0..12 {
                    let expect = if x + d < 40 { vl.data[(y * 40 + x + d) * 12 + d] } else { truncation_cost(&p) };
                    assert_eq!(vr.data[(y * 40 + x) * 12 + d], expect);
                }
            }
        }
        // And it matches a right-view volume computed directly on the mirrored pair.
        let direct = build(&right.mirrored(), &left.mirrored());
        for y in 0..9 {
            for x in 0..40 {
                let xm = 39 - x;
                for d in 0..12.min(40 - x) {
                    let a = vr.data[(y * 40 + x) * 12 + d];
                    let b = direct.data[(y * 40 + xm) * 12 + d];
                    // Census codes are not mirror-symmetric bit-for-bit but Hamming distances are; Sobel flips sign
                    // on both sides, so |difference| is unchanged.
                    assert!((a - b).abs() < 1e-3, "({x},{y},{d}) {a} vs {b}");
                }
            }
        }
    }

    /// A bit is in a pixel's support where its neighbour is within `tau` of the centre (bit order as the Census).
    #[test]
    fn support_mask_marks_the_similar_neighbours() {
        let g = Plane::from_parts(3, 3, vec![0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0]);
        let m = support_mask(&g, 3, 3, 15.0);
        // Centre (1, 1) = 40: neighbours 0 10 20 30 | 50 60 70 80 (bits 7 … 0); within 15: 30 and 50.
        assert_eq!(m.data[4], 0b0001_1000);
        assert_eq!(support_mask(&g, 3, 3, 100.0).data[4], 0xff);
        // Masks of all ones are the plain Census.
        let (l, r) = shifted_pair(64, 16, |_, _| 5);
        let mut p = CostParams { census_support: 0.0, ..CostParams::default() };
        let plain = build_cost_volume(&l, &r, 16, &p);
        p.census_support = 1000.0;
        assert_eq!(plain.data, build_cost_volume(&l, &r, 16, &p).data);
    }

    /// Foreground fattening: a high-contrast foreground strip (disparity 12) over a faint background texture
    /// (disparity 4). Beside the strip's right edge the background is visible in both views, but the plain Census
    /// windows there are dominated by the strip's strong edges and pick its disparity; with the support only the
    /// background's own bits count.
    #[test]
    fn census_support_stops_foreground_fattening() {
        let (w, h, (f0, f1), (d_bg, d_fg)) = (160, 60, (60, 100), (4, 12));
        let bg = noise(w + 16, h, 3).into_iter().map(|v| 100.0 + v / 16.0).collect::<Vec<_>>();
        let fg = noise(w + 16, h, 4).into_iter().map(|v| if v < 128.0 { 30.0 } else { 220.0 }).collect::<Vec<_>>();
        // Layers in scene coordinates: the left view sees scene column x, the right view x + d at disparity d.
        let (mut left, mut right) = (vec![0.0; w * h], vec![0.0; w * h]);
        for y in 0..h {
            for x in 0..w {
                left[y * w + x] = if (f0..f1).contains(&x) { fg[y * (w + 16) + x] } else { bg[y * (w + 16) + x] };
                // Right pixel x shows the foreground where x + d_fg is inside the strip, else the background.
                right[y * w + x] = if (f0..f1).contains(&(x + d_fg)) {
                    fg[y * (w + 16) + x + d_fg]
                } else {
                    bg[y * (w + 16) + x + d_bg]
                };
            }
        }
        let (l, r) = (grey_image(w, h, left), grey_image(w, h, right));
        let fattened = |support: f32| {
            let p = CostParams { census_support: support, grad_weight: 0.0, ..CostParams::default() };
            let wta = winner_take_all(&build_cost_volume(&l, &r, 24, &p));
            // The three background columns right of the strip (their windows reach into it).
            (3..h - 3)
                .flat_map(|y| (f1..f1 + 3).map(move |x| (x, y)))
                .filter(|&(x, y)| (wta.data[y * w + x] - d_fg as f32).abs() <= 1.0)
                .count()
        };
        let (plain, supported) = (fattened(0.0), fattened(50.0));
        eprintln!("fattened pixels: plain Census {plain}, with support {supported} (of {})", 3 * (h - 6));
        assert!(plain >= 15, "the plain Census fattens here: {plain}");
        assert!(supported * 4 <= plain, "support {supported} vs plain {plain}");
    }

    /// A gain between the views (the right view at half the contrast, the exposure mismatch of two cameras)
    /// leaves the raw gradient term large at the true disparity; normalised by the local contrast it cancels
    /// wherever the contrast is well above ε. Gradient term only, untruncated; a random texture shifted by 3 px.
    #[test]
    fn normalised_gradient_cancels_a_gain_between_the_views() {
        let (w, h, d) = (48, 12, 3);
        let (left, right) = shifted_pair(w, h, |_, _| d);
        let mut dark = right.clone();
        dark.channels.iter_mut().for_each(|c| c.iter_mut().for_each(|v| *v *= 0.5));
        let gradient_only = |radius| CostParams {
            census_weight: 0.0,
            grad_trunc: 1e9,
            grad_norm_radius: radius,
            ..CostParams::default()
        };
        // Mean cost at the true label, over pixels whose windows (Sobel and normalisation) see only shifted content.
        let at_truth = |p: &CostParams, right: &RgbImage| {
            let vol = build_cost_volume(&left, right, 8, p);
            let (mut sum, mut n) = (0.0f64, 0);
            for y in 0..h {
                for x in d + 2 + p.grad_norm_radius..w - 2 - p.grad_norm_radius {
                    sum += f64::from(vol.pixel(y * w + x)[d]);
                    n += 1;
                }
            }
            sum / n as f64
        };
        let (raw, normalised) = (gradient_only(0), gradient_only(2));
        let (raw_same, raw_gain) = (at_truth(&raw, &right), at_truth(&raw, &dark));
        let (norm_same, norm_gain) = (at_truth(&normalised, &right), at_truth(&normalised, &dark));
        eprintln!(
            "true-label gradient cost: raw {raw_same:.2} -> {raw_gain:.2} with the gain, normalised {norm_same:.2} -> {norm_gain:.2}"
        );
        assert!(raw_same < 1e-3 && norm_same < 1e-3, "same views: {raw_same} {norm_same}");
        assert!(raw_gain > 20.0, "the raw term sees the gain: {raw_gain}");
        assert!(norm_gain < 0.05 * raw_gain, "normalised {norm_gain} vs raw {raw_gain}");
    }
}
