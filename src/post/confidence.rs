//! The confidence of the final disparity map: for each pixel, the probability that its disparity is within 1 px
//! (at the resolution matched) of the truth, from measures the run already has. Made to rank the errors: kept most
//! confident first, the share of wrong pixels among the kept ones should rise as slowly as it can (the
//! sparsification curve of Hu & Mordohai, "A quantitative evaluation of confidence measures for stereo vision",
//! PAMI 2012; [`crate::eval::sparsification`] scores it).
//!
//! # The measures
//! Per pixel i, with d the left view's decoded disparity (before post-processing), f the final one:
//! - *agreement* sᵢ = Qᵢ · exp(−(e_lr + e_post + e_coarse) / [`AGREEMENT_SCALE_PX`]): the max-marginal Qᵢ times how
//!   well three independent answers agree with the pixel's: the right view (e_lr = |d − d_R(x − round d)|, the
//!   left-right check's difference), the post-processing (e_post = |f − d|: what the fill, median and planes
//!   changed) and the coarse run (e_coarse = |f − coarse|); each difference capped at [`CAP_PX`], an answer that
//!   is missing (out of view, invalid) counting as the cap and a check that did not run as agreement.
//! - *texture* tᵢ = ln(1 + the mean gradient magnitude of the grey guide over 5 × 5).
//! - *depth edge* eᵢ = ln(1 + the final map's range over 3 × 3, capped at 16 px).
//! - *rejection* uᵢ = the share of the 7 × 7 window that failed the left-right check, and the distance to the
//!   nearest pixel that failed it, ln(1 + px), capped at [`DISTANCE_CAP_PX`].
//! - *the cost curve* (the matching cost over the disparities, before the coarse prior is added; its three lowest
//!   local minima are kept per pixel while the volume is built, [`cost_minima_row`]): the peak ratio
//!   (c₁ − c₀)/(c₁ + c₀) of its two lowest minima (how distinct the best one is) and the margin of the minimum the
//!   final answer sits on over the lowest one elsewhere, same form, negative when the answer is not on the best
//!   ([`cost_margins`]). An answer that the propagation, the planes or the prior moved off what the cost prefers,
//!   where the cost prefers it clearly, is suspect; one on a repetition the cost cannot tell apart is too.
//! - *spread* = ln(1 + the final map's variance over 15 × 15).
//!
//! Errors come in regions (a wall matched to the wrong repetition, a textureless patch that slid), so the measures
//! enter as local means at a few scales (box means, borders replicated): ln of the mean agreement over 3 × 3,
//! 25 × 25 and 51 × 51 windows, the texture's 15 × 15 mean, the edge and its 7 × 7 mean, the rejection and its
//! 15 × 15 mean, the distance, the margin's and the peak ratio's 15 × 15 means, the spread.
//! A logistic model of those twelve values gives P(error > 1 px); the confidence is 1 − P, so a threshold on it
//! (`--min-confidence`) is a bound on the expected error rate of what is kept. The weights were fitted on MiddEval3
//! trainingQ and checked on the scenes each fold did not see (docs/tuning-log.md, "Confidence").
//!
//! An invalid pixel (`inf` in the final map) has confidence 0: it sorts last.
//!
//! # Cost
//! O(pixels): a dozen box means in O(1) per pixel each (running sums), one 3 × 3 min/max, a two-pass distance
//! transform (one thread), rows in parallel, each row summed by one thread in a fixed order (the map does not depend
//! on the thread count); the cost minima are one pass over each pixel's cost curve while it is in cache, and 24
//! bytes a pixel until the confidence is made.

use rayon::prelude::*;

use crate::fastmath::exp_nonpositive;
use crate::image::{DisparityMap, Plane, RgbImage};
use crate::imgproc::filter;

/// The disagreement that divides the agreement by e: half a pixel, so that an answer off by the 1 px the confidence
/// is about already counts as a clear disagreement (1 px and 2 px ranked worse on trainingQ).
pub(crate) const AGREEMENT_SCALE_PX: f32 = 0.5;

/// Differences beyond this are all the same disagreement (e^−16 is far below any agreement kept).
const CAP_PX: f32 = 8.0;

/// Added inside ln of a mean agreement so that a window of no agreement at all stays finite (about the agreement
/// of one pixel in 25 × 25 that agrees).
const LN_FLOOR: f32 = 1e-3;

/// Added to the sum of two costs in a ratio of them, so that two zero costs (a perfect match twice) give 0.
const RATIO_FLOOR: f32 = 1e-3;

/// The margin of an answer that sits on none of the cost curve's kept minima: about the margin of a pixel whose
/// answer the cost curve clearly places elsewhere.
const OFF_THE_MINIMA: f32 = -0.5;

/// Distances to the left-right rejections beyond this are all far (px; ln(1 + 64) ≈ 4.2).
const DISTANCE_CAP_PX: f32 = 64.0;

/// The logistic model's weights on the pooled measures, in the module doc's order: their log-odds of an error.
/// Fitted on trainingQ's 15 scenes by `scripts/fit-confidence.py` (docs/tuning-log.md, "Confidence"). Some pairs
/// of measures move together (the margin and the peak ratio, the rejection's two scales), so their weights are
/// read as pairs: a margin below the peak ratio (an answer off the cost's best minimum) raises the log-odds.
const WEIGHTS: [f32; 12] =
    [-0.1301, -0.2969, -0.4633, -0.1540, 0.3413, 0.3298, -2.0229, -7.5798, 8.3278, -0.4771, -0.2753, 1.7259];
/// The log-odds of an error where every measure is 0.
const BIAS: f32 = -5.7723;

/// What the confidence of a fine pass is made from.
pub(crate) struct ConfidenceInputs<'a> {
    /// The left view's max-marginal (1 for winner-take-all).
    pub max_marginal: &'a Plane<f32>,
    /// The left view's disparity as inference decoded it, before any post-processing.
    pub decoded: &'a DisparityMap,
    /// The right view's decoded disparity and the column of the right view where the left view's first column is
    /// (a tile's extension; 0 otherwise), when the left-right check ran.
    pub right: Option<(&'a DisparityMap, usize)>,
    /// The final disparity map.
    pub final_map: &'a DisparityMap,
    /// The pixels that passed the left-right check.
    pub consistent: &'a Plane<bool>,
    /// The coarse run's disparities at this resolution and the column where the left view's first column is (as
    /// for `right`), when there was one.
    pub coarse: Option<(&'a DisparityMap, usize)>,
    /// The guidance image of the left view.
    pub guide: &'a RgbImage,
    /// The lowest local minima of each pixel's matching cost, before the prior ([`cost_minima_row`]).
    pub minima: Option<&'a Plane<CostMinima>>,
}

/// How many of a cost curve's lowest local minima are kept per pixel.
pub(crate) const MINIMA: usize = 3;

/// A pixel's lowest local minima of the matching cost over the disparities, lowest first: [cost, disparity] each;
/// a curve with fewer minima repeats its last one.
pub(crate) type CostMinima = [[f32; 2]; MINIMA];

/// The [`CostMinima`] of each pixel of a cost volume's row (`data[x · ndisp + d]`). A local minimum is no higher than
/// its left neighbour and lower than its right one (the last of a flat bottom); the ends count against their one
/// neighbour. Ties: the lower disparity first.
///
/// Eight pixels at a time, one per lane ([`minima_in_lanes`]): one pixel's pass is a serial chain of selects, eight
/// are independent chains (about 8 ns per entry one pixel at a time: half of a Q pair's cost stage).
pub(crate) fn cost_minima_row(row: &[f32], ndisp: usize) -> Vec<CostMinima> {
    let m = ndisp.max(1);
    let mut out = Vec::with_capacity(row.len() / m);
    // A block of pixels with the labels outermost: `by_label[d · LANES + lane]`.
    let mut by_label = vec![0.0f32; LANES * m];
    let mut blocks = row.chunks_exact(LANES * m);
    for block in &mut blocks {
        for (lane, curve) in block.chunks_exact(m).enumerate() {
            for (d, &v) in curve.iter().enumerate() {
                by_label[d * LANES + lane] = v;
            }
        }
        out.extend(minima_in_lanes(&by_label));
    }
    out.extend(blocks.remainder().chunks_exact(m).map(curve_minima));
    out
}

/// Pixels per block of [`cost_minima_row`].
const LANES: usize = 8;

/// [`curve_minima`] of [`LANES`] curves at once, given with the labels outermost (`c[d · LANES + lane]`): the same
/// operations per curve. Compiled for AVX2 + FMA as well, picked at run time (same results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn minima_in_lanes(c: &[f32]) -> [CostMinima; LANES] {
    const INF: [f32; LANES] = [f32::INFINITY; LANES];
    let m = c.len() / LANES;
    // The kept values and disparities in arrays of their own, one lane per curve, so that the lanes vectorise.
    let ([mut v0, mut v1, mut v2], mut at) = ([INF; MINIMA], [[0.0f32; LANES]; MINIMA]);
    let mut prev = INF;
    for d in 0..m {
        let cur = &c[d * LANES..][..LANES];
        let next = if d + 1 < m { &c[(d + 1) * LANES..][..LANES] } else { &INF[..] };
        let [a0, a1, a2] = &mut at;
        for l in 0..LANES {
            let v = if cur[l] <= prev[l] && cur[l] < next[l] { cur[l] } else { f32::INFINITY };
            keep_lowest([&mut v0[l], &mut v1[l], &mut v2[l]], [&mut a0[l], &mut a1[l], &mut a2[l]], v, d as f32);
            prev[l] = cur[l];
        }
    }
    std::array::from_fn(|l| with_repeats([[v0[l], at[0][l]], [v1[l], at[1][l]], [v2[l], at[2][l]]]))
}

/// [`cost_minima_row`] of one pixel's curve: one pass, branch-free (a value that is no local minimum enters as
/// `inf`; the kept minima are updated by selects, which the compiler makes conditional moves: a cost curve's local
/// minima come at random, and a branch on them mispredicts).
fn curve_minima(c: &[f32]) -> CostMinima {
    let ([mut v0, mut v1, mut v2], [mut a0, mut a1, mut a2]) = ([f32::INFINITY; MINIMA], [0.0f32; MINIMA]);
    let mut prev = f32::INFINITY;
    let next = c.iter().skip(1).chain(std::iter::once(&f32::INFINITY));
    for (d, (&cur, &next)) in c.iter().zip(next).enumerate() {
        let v = if cur <= prev && cur < next { cur } else { f32::INFINITY };
        keep_lowest([&mut v0, &mut v1, &mut v2], [&mut a0, &mut a1, &mut a2], v, d as f32);
        prev = cur;
    }
    with_repeats([[v0, a0], [v1, a1], [v2, a2]])
}

/// Puts value `v` at disparity `at` among the kept `values` (lowest first) and their `disparities` if it is lower
/// than one of them, by selects (which the compiler makes conditional moves).
#[inline(always)]
fn keep_lowest(values: [&mut f32; MINIMA], disparities: [&mut f32; MINIMA], v: f32, at: f32) {
    let ([v0, v1, v2], [d0, d1, d2]) = (values, disparities);
    let (lt0, lt1, lt2) = (v < *v0, v < *v1, v < *v2);
    // Each slot, from the last: the slot above moves down into it when `v` is below that one, else `v` enters when
    // it is below this one.
    let slot = |below_above: bool, below_own: bool, above: (f32, f32), own: (f32, f32)| {
        if below_above {
            above
        } else if below_own {
            (v, at)
        } else {
            own
        }
    };
    (*v2, *d2) = slot(lt1, lt2, (*v1, *d1), (*v2, *d2));
    (*v1, *d1) = slot(lt0, lt1, (*v0, *d0), (*v1, *d1));
    (*v0, *d0) = slot(false, lt0, (*v0, *d0), (*v0, *d0));
}

/// `best` with each minimum that was not found (`inf`) replaced by the one before it.
fn with_repeats(mut best: CostMinima) -> CostMinima {
    for k in 1..MINIMA {
        if !best[k][0].is_finite() {
            best[k] = best[k - 1];
        }
    }
    best
}

/// The per-pixel measures before they are pooled.
struct Pixelwise {
    agreement: Plane<f32>,
    texture: Plane<f32>,
    edge: Plane<f32>,
    rejected: Plane<f32>,
    /// The cost curve's peak ratio and the margin of the answer's minimum ([`cost_margins`]).
    peak: Plane<f32>,
    margin: Plane<f32>,
}

/// The confidence of each pixel of the final map, 0..1 (see the module doc).
///
/// # Panics
/// If the maps differ in size.
pub(crate) fn confidence_map(inputs: &ConfidenceInputs<'_>) -> Plane<f32> {
    #[cfg(feature = "confidence-dump")]
    dump::write(inputs);
    let m = pixelwise(inputs);
    let mean = filter::box_mean_separable;
    let ln_mean = |r| {
        let mut p = mean(&m.agreement, r);
        p.data.iter_mut().for_each(|v| *v = (*v + LN_FLOOR).ln());
        p
    };
    // The log-odds summed one measure at a time, in the order of `WEIGHTS`, so that at most two pooled planes are
    // alive beside the per-pixel ones (a tile's memory).
    let (w, h) = inputs.final_map.dims();
    let mut logit = Plane::new(w, h, BIAS);
    let add = |logit: &mut Plane<f32>, values: &Plane<f32>, k: f32| {
        logit.data.par_chunks_mut(w.max(1)).zip(values.data.par_chunks(w.max(1))).for_each(|(l, v)| {
            l.iter_mut().zip(v).for_each(|(l, v)| *l += v * k);
        });
    };
    add(&mut logit, &ln_mean(1), WEIGHTS[0]);
    add(&mut logit, &ln_mean(12), WEIGHTS[1]);
    add(&mut logit, &ln_mean(25), WEIGHTS[2]);
    add(&mut logit, &mean(&m.texture, 7), WEIGHTS[3]);
    add(&mut logit, &m.edge, WEIGHTS[4]);
    add(&mut logit, &m.rejected, WEIGHTS[5]);
    add(&mut logit, &mean(&m.rejected, 7), WEIGHTS[6]);
    add(&mut logit, &mean(&m.margin, 7), WEIGHTS[7]);
    add(&mut logit, &mean(&m.peak, 7), WEIGHTS[8]);
    let mut near = distance_to_rejected(inputs.consistent, DISTANCE_CAP_PX);
    near.data.iter_mut().for_each(|d| *d = d.ln_1p());
    add(&mut logit, &near, WEIGHTS[9]);
    add(&mut logit, &local_spread(inputs.final_map, 7), WEIGHTS[10]);
    add(&mut logit, &mean(&m.edge, 3), WEIGHTS[11]);
    drop(m);
    logit.data.par_chunks_mut(w.max(1)).zip(inputs.final_map.data.par_chunks(w.max(1))).for_each(|(row, d)| {
        for (c, d) in row.iter_mut().zip(d) {
            let z = *c;
            // 1 / (1 + e^z), with the exponent never positive; an invalid pixel has none.
            let e = exp_nonpositive(-z.abs());
            *c = if !d.is_finite() {
                0.0
            } else if z > 0.0 {
                e / (1.0 + e)
            } else {
                1.0 / (1.0 + e)
            };
        }
    });
    logit
}

/// ln(1 + the variance of the final map's finite values over (2r + 1)² windows), an invalid pixel counting as 0.
fn local_spread(map: &DisparityMap, r: usize) -> Plane<f32> {
    let (w, h) = map.dims();
    let finite = |f: &f32| if f.is_finite() { *f } else { 0.0 };
    let values = Plane::from_parts(w, h, map.data.iter().map(finite).collect());
    let squares = Plane::from_parts(w, h, values.data.iter().map(|v| v * v).collect());
    let (mean, mut spread) = (filter::box_mean_separable(&values, r), filter::box_mean_separable(&squares, r));
    spread.data.iter_mut().zip(&mean.data).for_each(|(s, m)| *s = (*s - m * m).max(0.0).ln_1p());
    spread
}

/// The cost curve's evidence on the answer `f` from its lowest minima (before the prior): the peak ratio
/// (c₁ − c₀)/(c₁ + c₀) of the two lowest, and the margin (c_other − c_at)/(c_other + c_at) of the minimum the answer
/// sits on (within 1 px) over the lowest one elsewhere, −½ when it sits on none of them (the cost curve chose
/// otherwise). Both are free of the cost's scale.
fn cost_margins(minima: &CostMinima, f: f32) -> (f32, f32) {
    let ratio = |a: f32, b: f32| (a - b) / (a + b + RATIO_FLOOR);
    let [[c0, _], [c1, _], _] = *minima;
    let near = |k: usize| f.is_finite() && (f - minima[k][1]).abs() <= 1.0;
    let at = (0..MINIMA).find(|&k| near(k)).map(|k| minima[k][0]);
    let other = (0..MINIMA).find(|&k| !near(k)).map_or(minima[MINIMA - 1][0], |k| minima[k][0]);
    (ratio(c1, c0), at.map_or(OFF_THE_MINIMA, |at| ratio(other, at)))
}

/// Agreement, texture, depth edge and the left-right rejection around each pixel (see the module doc).
fn pixelwise(inputs: &ConfidenceInputs<'_>) -> Pixelwise {
    let ConfidenceInputs { max_marginal, decoded, right, final_map, consistent, coarse, guide, minima } = *inputs;
    let (w, h) = final_map.dims();
    assert_eq!(decoded.dims(), (w, h), "decoded and final maps differ in size");
    assert_eq!(max_marginal.dims(), (w, h), "max-marginal and final map differ in size");
    let diff = |a: f32, b: f32| if a.is_finite() && b.is_finite() { (a - b).abs().min(CAP_PX) } else { CAP_PX };
    let mut agreement = Plane::new(w, h, 0.0f32);
    agreement.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
        for (x, s) in row.iter_mut().enumerate() {
            let i = y * w + x;
            let (d, f) = (decoded.data[i], final_map.data[i]);
            let lr = right.map_or(0.0, |(right, from)| {
                let xr = (x + from) as f32 - d.round();
                if d.is_finite() && xr >= 0.0 && xr < right.width as f32 {
                    diff(d, right.row(y)[xr as usize])
                } else {
                    CAP_PX
                }
            });
            let coarse = coarse.map_or(0.0, |(c, from)| diff(f, c.row(y)[x + from]));
            let off = lr + diff(f, d) + coarse;
            *s = max_marginal.data[i].clamp(0.0, 1.0) * exp_nonpositive(-off / AGREEMENT_SCALE_PX);
        }
    });
    let texture = {
        let grey = guide.to_grey();
        let (gx, gy) = filter::central_differences(&grey);
        let magnitude = Plane::from_parts(w, h, gx.data.iter().zip(&gy.data).map(|(a, b)| a.hypot(*b)).collect());
        let mut texture = filter::box_mean_separable(&magnitude, 2);
        texture.data.iter_mut().for_each(|t| *t = t.ln_1p());
        texture
    };
    let edge = {
        let lo = filter::window_extreme(final_map, 1, f32::INFINITY, f32::min);
        let hi = filter::window_extreme(final_map, 1, f32::NEG_INFINITY, f32::max);
        let range =
            lo.data.iter().zip(&hi.data).map(|(lo, hi)| if lo <= hi { (hi - lo).min(16.0).ln_1p() } else { 0.0 });
        Plane::from_parts(w, h, range.collect())
    };
    let failed = Plane::from_parts(w, h, consistent.data.iter().map(|&ok| if ok { 0.0 } else { 1.0 }).collect());
    let rejected = filter::box_mean_separable(&failed, 3);
    let (peak, margin) = match minima {
        Some(minima) => {
            assert_eq!(minima.dims(), (w, h), "cost minima and final map differ in size");
            let pairs: Vec<(f32, f32)> =
                minima.data.par_iter().zip(&final_map.data).map(|(m, &f)| cost_margins(m, f)).collect();
            let (peak, margin) = pairs.into_iter().unzip();
            (Plane::from_parts(w, h, peak), Plane::from_parts(w, h, margin))
        }
        None => (Plane::new(w, h, 0.0), Plane::new(w, h, 0.0)),
    };
    Pixelwise { agreement, texture, edge, rejected, peak, margin }
}

/// The distance (px, 3-4 chamfer) from each pixel to the nearest one that failed the left-right check, capped at
/// `cap`; two raster passes, one thread.
pub(crate) fn distance_to_rejected(consistent: &Plane<bool>, cap: f32) -> Plane<f32> {
    let (w, h) = consistent.dims();
    let mut d: Vec<f32> = consistent.data.iter().map(|&ok| if ok { cap } else { 0.0 }).collect();
    let (side, diagonal) = (1.0f32, 4.0 / 3.0);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut v = d[i];
            if x > 0 {
                v = v.min(d[i - 1] + side);
            }
            if y > 0 {
                v = v.min(d[i - w] + side);
                if x > 0 {
                    v = v.min(d[i - w - 1] + diagonal);
                }
                if x + 1 < w {
                    v = v.min(d[i - w + 1] + diagonal);
                }
            }
            d[i] = v;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            let mut v = d[i];
            if x + 1 < w {
                v = v.min(d[i + 1] + side);
            }
            if y + 1 < h {
                v = v.min(d[i + w] + side);
                if x + 1 < w {
                    v = v.min(d[i + w + 1] + diagonal);
                }
                if x > 0 {
                    v = v.min(d[i + w - 1] + diagonal);
                }
            }
            d[i] = v;
        }
    }
    Plane::from_parts(w, h, d)
}

/// Writes the per-pixel inputs of the confidence to `$JEM_CONFIDENCE_DUMP/NNN.bin` (a fitting aid, the
/// `confidence-dump` feature; `scripts/fit-confidence.py` reads them).
#[cfg(feature = "confidence-dump")]
mod dump {
    use std::io::Write;
    use std::sync::atomic::{AtomicUsize, Ordering};

    use super::*;

    static COUNT: AtomicUsize = AtomicUsize::new(0);

    pub(super) fn write(inputs: &ConfidenceInputs<'_>) {
        let Some(dir) = std::env::var_os("JEM_CONFIDENCE_DUMP") else { return };
        let ConfidenceInputs { max_marginal, decoded, right, final_map, consistent, coarse, guide, minima } = *inputs;
        let (w, h) = final_map.dims();
        let n = w * h;
        let mut planes: Vec<(&str, Vec<f32>)> = Vec::new();
        planes.push(("max_marginal", max_marginal.data.clone()));
        planes.push(("decoded", decoded.data.clone()));
        planes.push(("final", final_map.data.clone()));
        let at_right = (0..n).map(|i| {
            let (x, y) = (i % w, i / w);
            right.map_or(f32::NAN, |(r, from)| {
                let d = decoded.data[i];
                let xr = (x + from) as f32 - d.round();
                if d.is_finite() && xr >= 0.0 && xr < r.width as f32 { r.row(y)[xr as usize] } else { f32::INFINITY }
            })
        });
        planes.push(("right", at_right.collect()));
        planes.push((
            "coarse",
            (0..n).map(|i| coarse.map_or(f32::NAN, |(c, from)| c.row(i / w)[i % w + from])).collect(),
        ));
        planes.push(("consistent", consistent.data.iter().map(|&b| f32::from(u8::from(b))).collect()));
        planes.push(("grey", guide.to_grey().data));
        planes.push(("dist_rejected", distance_to_rejected(consistent, 64.0).data));
        for (k, [cost, disp]) in [["c0", "d0"], ["c1", "d1"], ["c2", "d2"]].into_iter().enumerate() {
            for (j, name) in [(0, cost), (1, disp)] {
                planes.push((name, minima.map_or(vec![f32::NAN; n], |m| m.data.iter().map(|c| c[k][j]).collect())));
            }
        }
        let k = COUNT.fetch_add(1, Ordering::SeqCst);
        let path = std::path::Path::new(&dir).join(format!("{k:03}.bin"));
        let mut f = std::io::BufWriter::new(std::fs::File::create(path).expect("dump file"));
        let names: Vec<&str> = planes.iter().map(|p| p.0).collect();
        writeln!(f, "{w} {h} {}", names.join(" ")).expect("dump");
        for (_, v) in &planes {
            for x in v {
                f.write_all(&x.to_le_bytes()).expect("dump");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 16 × 8 map whose left half every check agrees with and whose right half the right view and the coarse
    /// answer contradict (and failed the left-right check): the left half ranks above the right one, and an
    /// invalid pixel ranks last.
    #[test]
    fn pixels_the_checks_contradict_rank_below_those_they_confirm() {
        let (w, h) = (16, 8);
        // Disparity 0 everywhere, so every pixel's match in the right view is the same column.
        let d = Plane::new(w, h, 0.0f32);
        let mut final_map = d.clone();
        final_map.data[w + 2] = f32::INFINITY;
        let right_half = |i: usize| i % w >= w / 2;
        let right = Plane::from_parts(w, h, (0..w * h).map(|i| if right_half(i) { 3.0 } else { 0.0 }).collect());
        let coarse = Plane::from_parts(w, h, (0..w * h).map(|i| if right_half(i) { 2.0 } else { 0.0 }).collect());
        let consistent = Plane::from_parts(w, h, (0..w * h).map(|i| !right_half(i)).collect());
        let guide = RgbImage::new(w, h);
        let c = confidence_map(&ConfidenceInputs {
            max_marginal: &Plane::new(w, h, 0.9),
            decoded: &d,
            right: Some((&right, 0)),
            final_map: &final_map,
            consistent: &consistent,
            coarse: Some((&coarse, 0)),
            guide: &guide,
            minima: None,
        });
        assert_eq!(c.data[w + 2], 0.0);
        let (mut lo_left, mut hi_right) = (f32::INFINITY, 0.0f32);
        for (i, &v) in c.data.iter().enumerate().filter(|&(i, _)| i != w + 2) {
            assert!((0.0..=1.0).contains(&v));
            if right_half(i) { hi_right = hi_right.max(v) } else { lo_left = lo_left.min(v) }
        }
        assert!(lo_left > hi_right, "left half from {lo_left}, right half up to {hi_right}");
    }

    /// The lowest local minima of a curve, lowest first, the last of a flat bottom; a curve with one minimum
    /// repeats it.
    #[test]
    fn cost_minima_are_the_lowest_local_minima_lowest_first() {
        let row = [
            5.0, 3.0, 4.0, 1.0, 1.0, 6.0, 2.0, 7.0, 0.5, /* second pixel */ 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0,
            8.0, 9.0,
        ];
        let m = cost_minima_row(&row, 9);
        assert_eq!(m[0], [[0.5, 8.0], [1.0, 4.0], [2.0, 6.0]]);
        assert_eq!(m[1], [[1.0, 0.0]; MINIMA]);
    }

    /// The blocks of eight pixels give what each pixel's own pass gives: random curves with many ties and flat
    /// bottoms, row widths that leave a remainder, one label and few.
    #[test]
    fn cost_minima_in_lanes_match_one_pixel_at_a_time() {
        let mut rng = crate::rng::SplitMix64::new(5);
        for (pixels, ndisp) in [(8, 1), (13, 2), (37, 5), (64, 9), (21, 70), (3, 4)] {
            let row: Vec<f32> = (0..pixels * ndisp).map(|_| (rng.next_u64() % 6) as f32).collect();
            let expected: Vec<CostMinima> = row.chunks_exact(ndisp).map(curve_minima).collect();
            assert_eq!(cost_minima_row(&row, ndisp), expected, "{pixels} pixels, {ndisp} labels");
        }
    }

    /// On the best minimum, the margin is the peak ratio; on the second, its opposite; on none, the fixed margin.
    #[test]
    fn the_margin_says_whether_the_answer_sits_on_the_best_minimum() {
        let minima = [[1.0, 10.0], [3.0, 20.0], [4.0, 30.0]];
        let peak = 2.0 / (4.0 + RATIO_FLOOR);
        assert_eq!(cost_margins(&minima, 10.5), (peak, peak));
        assert_eq!(cost_margins(&minima, 19.0), (peak, -peak));
        assert_eq!(cost_margins(&minima, 15.0), (peak, OFF_THE_MINIMA));
        assert_eq!(cost_margins(&minima, f32::INFINITY).1, OFF_THE_MINIMA);
    }

    /// The 3-4 chamfer distance to the one rejected pixel of a 5 × 3 map, and the cap where none is rejected.
    #[test]
    fn the_distance_to_the_rejections_is_the_chamfer_distance() {
        let mut consistent = Plane::new(5, 3, true);
        consistent.data[6] = false; // (1, 1)
        let d = distance_to_rejected(&consistent, 64.0);
        let k = 4.0 / 3.0;
        let want = [k, 1.0, k, 1.0 + k, 2.0 + k, 1.0, 0.0, 1.0, 2.0, 3.0, k, 1.0, k, 1.0 + k, 2.0 + k];
        for (got, want) in d.data.iter().zip(want) {
            assert!((got - want).abs() < 1e-6, "{:?}", d.data);
        }
        assert!(distance_to_rejected(&Plane::new(4, 2, true), 64.0).data.iter().all(|&v| v == 64.0));
    }
}
