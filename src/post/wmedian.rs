//! Weighted median filter at the pixels that were invalid (paper §4.2).
//!
//! The paper applies the filter after occlusion filling, and only to the pixels the left-right check rejected
//! (Mozerov & van de Weijer apply it everywhere, which is slower and blurs good pixels). Ours: the default runs it
//! once more after the planes at [`depth_edges`] (`post.wmedian.edge_px`), where a window cost puts the foreground's
//! disparity on the background's first pixels and the two views agree on it, and at the rejected pixels the planes
//! extrapolated ([`edge_targets`]), with a smaller window and sharper colour weights (docs/tuning-log.md, "Accuracy
//! III: the median at depth edges" and "Accuracy III: the second median").
//!
//! Each target pixel `i` takes the weighted median of the *finite* disparities `d_j` in its (2r+1)² window (the window
//! is clipped at the image border; the pixel itself is included when finite), with bilateral weights
//!
//! ```text
//! w_ij = exp(−|x_i − x_j|² / 2σ_xy² − |I_i − I_j|² / 2σ_rgb²)        (I = RGB, 0..255)
//! ```
//!
//! **Exact** weighted median, with this tie rule: the result is the *lower* weighted median, the smallest
//! window value `v` with `Σ_{d_j ≤ v} w_j ≥ ½ Σ_j w_j` (weights summed in `f64`). Values are never quantised.
//! Per target pixel, O(n) for the n ≤ (2r+1)² window values, so the stage is O(T·r²) for T targets:
//! 1. gather the finite values and their exponents (branch-free when a window row has no `inf`);
//! 2. compute the weights and test the previous result on the row as a guess (m is the lower weighted median iff
//!    Σ_{v<m} w < ½ΣW ≤ Σ_{v≤m} w) — neighbouring targets mostly share their median (in the first run; after the
//!    planes the values vary continuously and the guess rarely holds, so a row stops testing it while it fails
//!    (`GuessRate`));
//! 3. otherwise count the weights into 128 equal-width value bins (ordered, since the bin index is monotone in the
//!    value), find the bin holding the median — summing and clearing only the bins that hold weight, a window
//!    of 121 values touches few of them — and run a weighted quickselect (three-way partition, median-of-three
//!    pivot) on that bin's values only, gathered by a branch-free compaction.
//!
//! The weights use `crate::fastmath::exp_nonpositive` (relative error < 5e-7 against `f32::exp`, tested) so the loop
//! vectorises; the reductions (min, max, sums) run in independent lanes combined in a fixed order, so that they
//! are not one serial dependency chain. The weights are thus defined up to that rounding; the median of the
//! weights as computed is exact.
//!
//! The filter reads only the input map (every output depends on input values only, not on other outputs), so the
//! result does not depend on the processing order or the thread count. Rows run in parallel with rayon.
//!
//! Numerics: the weights of one window are computed as `exp(e_min − e_j)` with `e_j` the exponent above and
//! `e_min` the window's smallest one. The median is invariant to a common scale of the weights, and this keeps the
//! largest weight at 1, so a window never has an all-zero total even for tiny sigmas.
//!
//! A target pixel whose window holds no finite disparity keeps its input value (possibly `inf`). Pixels that are
//! not targets are copied unchanged.
//!
//! The row kernel is compiled for AVX2 + FMA as well and picked at run time, with the same results; the
//! `force-baseline` feature leaves only the baseline version (see `crate::fastmath`, "SIMD in jem").

use std::borrow::Cow;

use rayon::prelude::*;

use crate::fastmath::{exp_nonpositive, lane_max, lane_min};
use crate::image::{DisparityMap, Plane, RgbImage};
use crate::imgproc::filter::window_extreme;
use crate::params::WmedianParams;

/// Replaces the disparity at every `targets` pixel by the weighted median of the valid disparities in its window
/// (see the module doc for the weights and the tie rule).
///
/// # Panics
/// If `disp`, `image` and `targets` differ in size.
///
/// # Examples
/// ```
/// use jem::internals::post::wmedian::weighted_median;
/// use jem::params::WmedianParams;
/// use jem::{Plane, RgbImage};
/// let disp = Plane::from_vec(3, 1, vec![2.0, 9.0, 2.0]).unwrap();
/// let targets = Plane::from_vec(3, 1, vec![false, true, false]).unwrap();
/// let out = weighted_median(&disp, &RgbImage::new(3, 1), &targets, &WmedianParams::default());
/// assert_eq!(out.data(), [2.0, 2.0, 2.0]);
/// ```
pub fn weighted_median(
    disp: &DisparityMap,
    image: &RgbImage,
    targets: &Plane<bool>,
    p: &WmedianParams,
) -> DisparityMap {
    assert_eq!(disp.dims(), image.dims(), "disparity map and image differ in size");
    assert_eq!(disp.dims(), targets.dims(), "disparity map and target mask differ in size");
    let (w, h) = disp.dims();
    let mut out = disp.clone();
    if w == 0 || h == 0 {
        return out;
    }
    let r = p.radius;
    let side = 2 * r + 1;
    // Spatial exponents |Δxy|²/2σ², indexed [(dy + r) * side + dx + r].
    let inv_xy = 1.0 / (2.0 * p.sigma_xy * p.sigma_xy);
    let spatial: Vec<f32> = (0..side * side)
        .map(|k| {
            let (dx, dy) = ((k % side) as f32 - r as f32, (k / side) as f32 - r as f32);
            (dx * dx + dy * dy) * inv_xy
        })
        .collect();
    let inv_rgb = 1.0 / (2.0 * p.sigma_rgb * p.sigma_rgb);

    let grid = SampleGrid::new(disp, image, spatial, r, p.step.max(1));
    let ctx = RowContext { targets, image, grid: &grid, inv_rgb };
    out.data
        .par_chunks_mut(w)
        .enumerate()
        .for_each_init(|| Scratch::new(side * side), |scratch, (y, row)| filter_row(&ctx, scratch, y, row));
    out
}

/// The window's samples laid out so that each window row's are contiguous: every `step`-th pixel from the target,
/// so with a step above 1 the map and the image are split by column phase (`x mod step`), each phase a plane of
/// its own columns, and the spatial exponents kept for the sampled offsets only. With step 1 it borrows the inputs.
/// The samples, their order and their exponents are those of the full window read every `step`-th pixel.
struct SampleGrid<'a> {
    step: usize,
    /// The sampled offsets per side of the centre: the most whole steps within the radius.
    reach: usize,
    /// Per column phase: its width and its [disparity, red, green, blue] planes, rows of that width.
    phases: Vec<(usize, [Cow<'a, [f32]>; 4])>,
    /// Spatial exponents of the sampled offsets, indexed [(dy/step + reach) · (2·reach + 1) + dx/step + reach].
    spatial: Vec<f32>,
}

impl<'a> SampleGrid<'a> {
    fn new(disp: &'a DisparityMap, image: &'a RgbImage, spatial: Vec<f32>, r: usize, step: usize) -> Self {
        let (w, [red, green, blue]) = (disp.width, &image.channels);
        let planes = [&disp.data, red, green, blue];
        if step == 1 {
            let phase = planes.map(|p| Cow::Borrowed(p.as_slice()));
            return SampleGrid { step, reach: r, phases: vec![(w, phase)], spatial };
        }
        let phases = (0..step.min(w))
            .map(|p| {
                let split = |plane: &Vec<f32>| -> Cow<'a, [f32]> {
                    Cow::Owned(plane.chunks_exact(w).flat_map(|row| row[p..].iter().step_by(step)).copied().collect())
                };
                ((w - p).div_ceil(step), planes.map(split))
            })
            .collect();
        let (reach, side) = (r / step, 2 * r + 1);
        let offset = |k: usize| r + step * k - step * reach;
        let spatial = (0..(2 * reach + 1).pow(2))
            .map(|k| spatial[offset(k / (2 * reach + 1)) * side + offset(k % (2 * reach + 1))])
            .collect();
        SampleGrid { step, reach, phases, spatial }
    }
}

/// What [`filter_row`] reads.
struct RowContext<'a> {
    /// The pixels to filter (the map's and the image's size).
    targets: &'a Plane<bool>,
    image: &'a RgbImage,
    grid: &'a SampleGrid<'a>,
    /// 1/2σ_rgb².
    inv_rgb: f32,
}

/// The weighted median at the target pixels of row `y` into `row` (which holds the input there). Compiled for
/// AVX2 + FMA as well, picked at run time (same results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn filter_row<'c>(ctx: &RowContext<'c>, scratch: &mut Scratch, y: usize, row: &mut [f32]) {
    let RowContext { targets, image, grid, inv_rgb } = *ctx;
    let (w, h) = targets.dims();
    let (step, reach) = (grid.step, grid.reach);
    let side = 2 * reach + 1;
    let [red, green, blue] = &image.channels;
    let trow = targets.row(y);
    // The window's first and last sample from `c` along an axis of `n` pixels: a multiple of `step` away.
    let span = |c: usize, n: usize| (c - step * reach.min(c / step), c + step * reach.min((n - 1 - c) / step));
    let (y0, y1) = span(y, h);
    // The previous result on this row: a good guess for the next median (see `Scratch::median`).
    let mut last: Option<f32> = None;
    let mut guesses = GuessRate::default();
    for (x, (d_out, _)) in row.iter_mut().zip(trow).enumerate().filter(|(_, (_, t))| **t) {
        let (x0, x1) = span(x, w);
        let i = y * w + x;
        let (ci_r, ci_g, ci_b) = (red[i], green[i], blue[i]);
        // The samples' columns in the target's phase plane, and the first one's spatial column.
        let (pw, [dp, rp, gp, bp]) = &grid.phases[x % step];
        let (k0, k1) = (x0 / step, x1 / step);
        let sx = k0 + reach - x / step;
        scratch.vals.clear();
        scratch.wts.clear();
        for yy in (y0..=y1).step_by(step) {
            let base = yy * pw;
            let seg = |plane: &'c [f32]| &plane[base + k0..=base + k1];
            let (dseg, rseg, gseg, bseg) = (seg(dp), seg(rp), seg(gp), seg(bp));
            let sseg = &grid.spatial[(yy + step * reach - y) / step * side + sx..][..dseg.len()];
            let exponent = |(((s, r), g), b): (((&f32, &f32), &f32), &f32)| {
                let (dr, dg, db) = (r - ci_r, g - ci_g, b - ci_b);
                s + (dr * dr + dg * dg + db * db) * inv_rgb
            };
            let terms = sseg.iter().zip(rseg).zip(gseg).zip(bseg);
            if dseg.iter().all(|d| d.is_finite()) {
                // The usual case after the occlusion fill: a branch-free loop that vectorises (written through a
                // slice: `extend` over this iterator is a push loop that does not).
                scratch.vals.extend_from_slice(dseg);
                let start = scratch.wts.len();
                scratch.wts.resize(start + dseg.len(), 0.0);
                scratch.wts[start..].iter_mut().zip(terms).for_each(|(o, t)| *o = exponent(t));
            } else {
                for (&d, t) in dseg.iter().zip(terms) {
                    if d.is_finite() {
                        scratch.vals.push(d);
                        scratch.wts.push(exponent(t));
                    }
                }
            }
        }
        if scratch.vals.is_empty() {
            continue; // no valid neighbour: keep the input value
        }
        let (v_min, v_max) = (lane_min(&scratch.vals), lane_max(&scratch.vals));
        let e_min = lane_min(&scratch.wts);
        let guess = guesses.worth_trying().then(|| last.or(Some(*d_out).filter(|d| d.is_finite()))).flatten();
        let (median, by_guess) = scratch.median(e_min, v_min, v_max, guess);
        guesses.record(guess.is_some(), by_guess);
        *d_out = median;
        last = Some(median);
    }
}

/// Whether the previous result on a row is worth testing as the next target's median: it costs a pass over the
/// window and pays only when it holds. In the first run most of a row's targets share their median (40–45 % of the
/// guesses hold on trainingQ); after the planes the values vary continuously (about 7 % hold). So the guess is
/// tried while at least one in [`GuessRate::MIN_SHARE`] of a row's tries has held, and at every
/// [`GuessRate::PROBE`]-th target otherwise. The result is the same whether it is tried or not.
#[derive(Default)]
struct GuessRate {
    tries: u32,
    hits: u32,
    /// Targets since the last try.
    since: u32,
}

impl GuessRate {
    /// Tries are counted before the rate is trusted.
    const WARM_UP: u32 = 8;
    /// A guess that holds less often than once in this many tries is not worth its pass.
    const MIN_SHARE: u32 = 5;
    /// Without tries, one in this many targets tries again.
    const PROBE: u32 = 8;

    fn worth_trying(&self) -> bool {
        self.tries < Self::WARM_UP || self.hits * Self::MIN_SHARE >= self.tries || self.since + 1 >= Self::PROBE
    }

    fn record(&mut self, tried: bool, held: bool) {
        if tried {
            self.tries += 1;
            self.hits += u32::from(held);
            self.since = 0;
        } else {
            self.since += 1;
        }
    }
}

/// Number of value bins [`Scratch::median`] uses to narrow the search.
const BINS: usize = 128;
const _: () =
    assert!(BINS <= 256 && BINS.is_multiple_of(64), "bin indices are stored as u8, the set of bins in u64 words");

/// A set of bin indices below [`BINS`], one bit each, listed in increasing order.
#[derive(Clone, Copy, Default)]
struct Occupancy([u64; BINS / 64]);

impl Occupancy {
    /// The set of these indices.
    fn of(indices: &[u8]) -> Self {
        let mut words = [0u64; BINS / 64];
        for &b in indices {
            for (i, word) in words.iter_mut().enumerate() {
                *word |= u64::from(usize::from(b) / 64 == i) << (b % 64);
            }
        }
        Occupancy(words)
    }

    /// The members in increasing order.
    fn iter(self) -> impl Iterator<Item = usize> {
        self.0.into_iter().enumerate().flat_map(|(i, mut word)| {
            std::iter::from_fn(move || {
                (word != 0).then(|| {
                    let bit = word.trailing_zeros() as usize;
                    word &= word - 1;
                    64 * i + bit
                })
            })
        })
    }
}

/// Per-thread buffers of the filter: the window's finite values and their weights (structure of arrays, so the
/// weight and sum loops vectorise).
struct Scratch {
    /// Disparities of the window's finite pixels.
    vals: Vec<f32>,
    /// Their exponents on entry to [`Scratch::median`], their weights after.
    wts: Vec<f32>,
    /// Weight per value bin, four lanes per bin: `bins[4 * bin + lane]`.
    bins: Vec<f64>,
    /// The bins that hold weight; all others are zero.
    occupied: Occupancy,
    /// The bin of each value (an index below [`BINS`]).
    bin_of: Vec<u8>,
    /// The (value, weight) pairs of the bin that holds the median (first), and scratch space after them.
    in_bin: Vec<(f32, f32)>,
}

impl Scratch {
    fn new(capacity: usize) -> Self {
        Scratch {
            vals: Vec::with_capacity(capacity),
            wts: Vec::with_capacity(capacity),
            bins: vec![0.0; 4 * BINS],
            occupied: Occupancy::default(),
            bin_of: Vec::with_capacity(capacity),
            in_bin: Vec::with_capacity(capacity),
        }
    }

    /// The lower weighted median of the window. On entry `wts` holds the exponents e_j; they become the weights
    /// exp(e_min − e_j) (at most 1). Requires a non-empty window with values in [`v_min`, `v_max`] and `e_min` the
    /// smallest exponent.
    ///
    /// First a `guess` m is checked in the pass that computes the weights: m is the lower weighted median exactly
    /// when Σ_{v<m} w < half ≤ Σ_{v≤m} w. Neighbouring target pixels mostly share their median, so the previous
    /// result on the row usually passes.
    ///
    /// Otherwise the values are counted into [`BINS`] bins of equal width over [v_min, v_max] — the bin index is a
    /// monotone function of the value, so the bins are ordered — the bin where the cumulative weight reaches half
    /// is found, and only its items go through the quickselect, with the weight below it subtracted from the
    /// target. Same result as [`weighted_lower_median`] on all items, in fewer operations. The bins are kept in
    /// four interleaved lanes (item k adds to lane k mod 4) so that runs of equal values do not serialise on one
    /// accumulator; lanes are always summed in the same order.
    #[inline(always)]
    fn median(&mut self, e_min: f32, v_min: f32, v_max: f32, guess: Option<f32>) -> (f32, bool) {
        for e in self.wts.iter_mut() {
            *e = exp_nonpositive(e_min - *e);
        }
        if v_min >= v_max {
            return (v_min, false);
        }
        if let Some(m) = guess {
            // Four lanes per sum, so the f64 additions do not form one long dependency chain.
            let (mut total, mut below, mut upto) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
            let (vc, wc) = (self.vals.chunks_exact(4), self.wts.chunks_exact(4));
            let (vr, wr) = (vc.remainder(), wc.remainder());
            for (v4, w4) in vc.zip(wc) {
                for l in 0..4 {
                    let wt = f64::from(w4[l]);
                    total[l] += wt;
                    below[l] += if v4[l] < m { wt } else { 0.0 };
                    upto[l] += if v4[l] <= m { wt } else { 0.0 };
                }
            }
            for (l, (&v, &wt)) in vr.iter().zip(wr).enumerate() {
                let wt = f64::from(wt);
                total[l] += wt;
                below[l] += if v < m { wt } else { 0.0 };
                upto[l] += if v <= m { wt } else { 0.0 };
            }
            let sum = |a: [f64; 4]| (a[0] + a[1]) + (a[2] + a[3]);
            let half = 0.5 * sum(total);
            if sum(below) < half && sum(upto) >= half {
                return (m, true);
            }
        }
        // The bin index, clamped in f32 so that the loop vectorises (same index as truncating, then clamping).
        let scale = BINS as f32 / (v_max - v_min);
        let last = (BINS - 1) as f32;
        self.bin_of.resize(self.vals.len(), 0);
        for (b, &v) in self.bin_of.iter_mut().zip(&self.vals) {
            *b = ((v - v_min) * scale).min(last) as u8;
        }
        // Only the bins the last window used hold weight: clear those.
        for b in self.occupied.iter() {
            self.bins[4 * b..4 * b + 4].fill(0.0);
        }
        self.occupied = Occupancy::of(&self.bin_of);
        for (k, (&b, &wt)) in self.bin_of.iter().zip(&self.wts).enumerate() {
            self.bins[usize::from(b) * 4 + (k & 3)] += f64::from(wt);
        }
        // The sums run over the occupied bins only, in bin order: adding an empty bin's +0 changes no sum, and an
        // empty bin is never where the cumulative weight first reaches half (it reached it at an earlier bin).
        let bin_weight = |b: usize| {
            let lanes = &self.bins[4 * b..4 * b + 4];
            (lanes[0] + lanes[1]) + (lanes[2] + lanes[3])
        };
        let total: f64 = self.occupied.iter().map(bin_weight).sum();
        let half = 0.5 * total;
        let mut below = 0.0f64;
        let mut k = BINS - 1;
        for b in self.occupied.iter() {
            let bw = bin_weight(b);
            if below + bw >= half {
                k = b;
                break;
            }
            below += bw;
        }
        // The bin's items, in their window order, by a branch-free compaction: each item is written to the next
        // free place, which advances only when the item is in the bin.
        let k = k as u8;
        self.in_bin.resize(self.vals.len(), (0.0, 0.0));
        let mut len = 0;
        for ((&v, &wt), &b) in self.vals.iter().zip(&self.wts).zip(&self.bin_of) {
            self.in_bin[len] = (v, wt);
            len += usize::from(b == k);
        }
        if len == 0 {
            // Only reachable through rounding when the last bins are empty: take the largest value.
            return (v_max, false);
        }
        (weighted_lower_median(&mut self.in_bin[..len], (half - below).max(f64::MIN_POSITIVE)), false)
    }
}

/// The smallest value `v` in `items` (value, weight) with Σ_{value ≤ v} weight ≥ `half`, by weighted quickselect.
/// Reorders `items`.
///
/// Requires a non-empty slice, weights ≥ 0 and 0 < `half` ≤ the total weight. If rounding makes `half` exceed what
/// is left, the largest value is returned.
fn weighted_lower_median(items: &mut [(f32, f32)], half: f64) -> f32 {
    debug_assert!(!items.is_empty() && half > 0.0);
    let mut target = half;
    let (mut lo, mut hi) = (0, items.len());
    loop {
        let part = &mut items[lo..hi];
        let n = part.len();
        if n == 1 {
            return part[0].0;
        }
        let pivot = median_of_three(part[0].0, part[n / 2].0, part[n - 1].0);
        // Three-way partition: [0, lt) < pivot, [lt, gt) == pivot, [gt, n) > pivot.
        let (mut lt, mut k, mut gt) = (0, 0, n);
        let (mut w_less, mut w_equal) = (0.0f64, 0.0f64);
        while k < gt {
            let v = part[k].0;
            if v < pivot {
                w_less += f64::from(part[k].1);
                part.swap(lt, k);
                lt += 1;
                k += 1;
            } else if v > pivot {
                gt -= 1;
                part.swap(k, gt);
            } else {
                w_equal += f64::from(part[k].1);
                k += 1;
            }
        }
        if w_less >= target {
            hi = lo + lt;
        } else if w_less + w_equal >= target || gt == n {
            return pivot;
        } else {
            target -= w_less + w_equal;
            lo += gt;
        }
    }
}

#[inline]
fn median_of_three(a: f32, b: f32, c: f32) -> f32 {
    a.max(b).min(a.min(b).max(c))
}

/// The pixels whose 3×3 neighbourhood (clipped at the border; `inf` ignored) spans more than `jump` pixels of
/// disparity: the two sides of a depth edge. A slanted surface changes by less than a pixel per pixel, so the
/// threshold is the same at every resolution.
pub fn depth_edges(disp: &DisparityMap, jump: f32) -> Plane<bool> {
    let lo = window_extreme(disp, 1, f32::INFINITY, f32::min);
    let hi = window_extreme(disp, 1, f32::NEG_INFINITY, f32::max);
    // No finite value in the window: lo = inf, hi = −inf, no edge.
    Plane::from_parts(disp.width, disp.height, lo.data.iter().zip(&hi.data).map(|(lo, hi)| hi - lo > jump).collect())
}

/// The targets of the second run after the planes (`post.wmedian.edge_px` and the keys after it): the
/// [`depth_edges`] of `disp` at `jump` and the pixels not `trusted` (the left-right check rejected them, and the
/// planes extrapolated their values), both widened by `band` px (Chebyshev).
pub fn edge_targets(disp: &DisparityMap, jump: f32, band: usize, trusted: &Plane<bool>) -> Plane<bool> {
    assert_eq!(disp.dims(), trusted.dims(), "disparity map and trusted mask differ in size");
    let (w, h) = disp.dims();
    let seeds: Vec<bool> = depth_edges(disp, jump).data.iter().zip(&trusted.data).map(|(&e, &ok)| e || !ok).collect();
    if band == 0 {
        return Plane::from_parts(w, h, seeds);
    }
    let marks = Plane::from_parts(w, h, seeds.iter().map(|&s| f32::from(u8::from(s))).collect());
    Plane::from_parts(w, h, window_extreme(&marks, band, 0.0, f32::max).data.iter().map(|&m| m > 0.5).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    const INF: f32 = f32::INFINITY;

    /// Sort-based reference: the smallest value whose cumulative weight reaches half the total.
    fn reference_median(items: &[(f32, f32)]) -> f32 {
        let mut v = items.to_vec();
        v.sort_by(|a, b| a.0.total_cmp(&b.0));
        let total: f64 = v.iter().map(|it| f64::from(it.1)).sum();
        let mut cum = 0.0;
        for (i, it) in v.iter().enumerate() {
            cum += f64::from(it.1);
            // Sum equal values as one group, as the quickselect does.
            if (i + 1 == v.len() || v[i + 1].0 != it.0) && cum >= 0.5 * total {
                return it.0;
            }
        }
        v[v.len() - 1].0
    }

    /// Seeded test data: [`crate::rng::SplitMix64`] with uniform `f32` draws in 0..1.
    struct Rng(crate::rng::SplitMix64);
    impl Rng {
        fn new(seed: u64) -> Self {
            Rng(crate::rng::SplitMix64::new(seed))
        }
        fn next_f32(&mut self) -> f32 {
            (self.0.next_u64() >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// Reference filter: the same weights, computed naively, then the sort-based median.
    fn reference_filter(disp: &DisparityMap, image: &RgbImage, targets: &Plane<bool>, p: &WmedianParams) -> Vec<f32> {
        let (w, h) = disp.dims();
        let (r, step) = (p.radius as isize, p.step.max(1) as isize);
        let mut out = disp.data.clone();
        for y in 0..h as isize {
            for x in 0..w as isize {
                let i = (y as usize) * w + x as usize;
                if !targets.data[i] {
                    continue;
                }
                let mut items = Vec::new();
                // Offsets that are multiples of the step, at most the radius, inside the image.
                let on_grid = |o: isize, c: isize, n: isize| o % step == 0 && (0..n).contains(&(c + o));
                for yy in (-r..=r).filter(|&o| on_grid(o, y, h as isize)).map(|o| y + o) {
                    for xx in (-r..=r).filter(|&o| on_grid(o, x, w as isize)).map(|o| x + o) {
                        let j = (yy as usize) * w + xx as usize;
                        if disp.data[j].is_finite() {
                            let dxy = ((xx - x).pow(2) + (yy - y).pow(2)) as f64;
                            let (a, b) = (image.rgb(i), image.rgb(j));
                            let dc: f64 = (0..3).map(|c| f64::from(a[c] - b[c]).powi(2)).sum();
                            let e = dxy / (2.0 * f64::from(p.sigma_xy).powi(2))
                                + dc / (2.0 * f64::from(p.sigma_rgb).powi(2));
                            items.push((disp.data[j], (-e).exp() as f32));
                        }
                    }
                }
                if !items.is_empty() {
                    out[i] = reference_median(&items);
                }
            }
        }
        out
    }

    #[test]
    fn quickselect_matches_sorting() {
        let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15);
        for n in 1..60 {
            for _ in 0..20 {
                // Few distinct values so ties are common; some zero weights.
                let items: Vec<(f32, f32)> = (0..n)
                    .map(|_| {
                        let v = (rng.next_f32() * 8.0).floor() * 0.5;
                        let w = if rng.next_f32() < 0.1 { 0.0 } else { rng.next_f32() + 0.01 };
                        (v, w)
                    })
                    .collect();
                let total: f64 = items.iter().map(|it| f64::from(it.1)).sum();
                if total == 0.0 {
                    continue;
                }
                let expected = reference_median(&items);
                let mut work = items.clone();
                assert_eq!(weighted_lower_median(&mut work, 0.5 * total), expected, "{items:?}");
                let (m, used) = binned_median(&items);
                assert_eq!(m, reference_median(&used), "{items:?}");
            }
        }
    }

    /// [`binned_median_in`] on one scratch per thread that earlier windows used (as on a row: the bins they filled
    /// must not leak into this one).
    fn binned_median(items: &[(f32, f32)]) -> (f32, Vec<(f32, f32)>) {
        thread_local! {
            static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::new(0));
        }
        SCRATCH.with_borrow_mut(|s| binned_median_in(s, items))
    }

    /// [`Scratch::median`] with no guess on (value, weight) pairs, passed in as exponents −ln w. Returns the median
    /// and the (value, weight) pairs it actually used (exp(ln w) need not give w back exactly), for the reference.
    fn binned_median_in(s: &mut Scratch, items: &[(f32, f32)]) -> (f32, Vec<(f32, f32)>) {
        s.vals.clear();
        s.wts.clear();
        s.vals.extend(items.iter().map(|it| it.0));
        s.wts.extend(items.iter().map(|&(_, w)| if w > 0.0 { -w.ln() } else { 1e3 }));
        let e_min = s.wts.iter().copied().fold(f32::INFINITY, f32::min);
        let v_min = items.iter().map(|it| it.0).fold(f32::INFINITY, f32::min);
        let v_max = items.iter().map(|it| it.0).fold(f32::NEG_INFINITY, f32::max);
        let (m, by_guess) = s.median(e_min, v_min, v_max, None);
        assert!(!by_guess, "no guess, none used");
        (m, s.vals.iter().copied().zip(s.wts.iter().copied()).collect())
    }

    #[test]
    fn binned_median_matches_sorting() {
        let mut rng = Rng::new(0x1234_5678_9abc_def1);
        for n in [1, 2, 3, 10, 100, 361, 1000] {
            for trial in 0..50 {
                // Continuous values (most bins hold a few), clustered values (one bin holds most), and outliers
                // that stretch the range (everything else falls into one bin).
                let items: Vec<(f32, f32)> = (0..n)
                    .map(|k| {
                        let v = match trial % 3 {
                            0 => rng.next_f32() * 64.0,
                            1 => 20.0 + (rng.next_f32() * 4.0).floor() * 0.25,
                            _ if k == 0 => 1e6,
                            _ => rng.next_f32(),
                        };
                        (v, rng.next_f32() * rng.next_f32())
                    })
                    .collect();
                if items.iter().all(|it| it.1 == 0.0) {
                    continue;
                }
                let (m, used) = binned_median(&items);
                assert_eq!(m, reference_median(&used), "n {n} trial {trial}");
            }
        }
        // The tie rule survives the binning.
        assert_eq!(binned_median(&[(4.0, 1.0), (1.0, 1.0), (4.0, 1.0), (1.0, 1.0)]).0, 1.0);
        assert_eq!(binned_median(&[(4.0, 1.0), (1.0, 1.0), (4.0, 1.0), (1.0, 0.5)]).0, 4.0);
        assert_eq!(binned_median(&[(2.0, 1.0)]).0, 2.0);
    }

    #[test]
    fn occupancy_lists_each_bin_once_in_order() {
        let set = Occupancy::of(&[127, 3, 64, 3, 0, 63, 65]);
        assert_eq!(set.iter().collect::<Vec<_>>(), [0, 3, 63, 64, 65, 127]);
        assert_eq!(Occupancy::of(&[]).iter().count(), 0);
        let all: Vec<u8> = (0..BINS as u8).rev().collect();
        assert!(Occupancy::of(&all).iter().eq(0..BINS));
    }

    #[test]
    fn guess_is_accepted_only_when_it_is_the_median() {
        let mut rng = Rng::new(77);
        for trial in 0..500 {
            let n = 1 + trial % 40;
            let items: Vec<(f32, f32)> =
                (0..n).map(|_| ((rng.next_f32() * 6.0).floor(), rng.next_f32() + 0.01)).collect();
            let (expected, used) = binned_median(&items);
            assert_eq!(expected, reference_median(&used));
            // Every value in the window, and one outside it, as a guess: the answer never changes.
            for guess in items.iter().map(|it| it.0).chain([100.0]) {
                let mut s = Scratch::new(n);
                s.vals.extend(items.iter().map(|it| it.0));
                s.wts.extend(items.iter().map(|&(_, w)| -w.ln()));
                let e_min = s.wts.iter().copied().fold(f32::INFINITY, f32::min);
                let v_min = s.vals.iter().copied().fold(f32::INFINITY, f32::min);
                let v_max = s.vals.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                let (m, by_guess) = s.median(e_min, v_min, v_max, Some(guess));
                assert_eq!(m, expected, "guess {guess} in {items:?}");
                // A guess is taken only when it is the median; the answer is the same either way.
                assert!(!by_guess || guess == expected, "guess {guess} taken in {items:?}");
                if v_min < v_max && guess == expected {
                    assert!(by_guess, "the median {guess} as a guess is taken in {items:?}");
                }
            }
        }
    }

    #[test]
    fn tie_rule_takes_the_lower_value() {
        // Equal weights, two values: exactly half the weight on each side → the lower one.
        let mut items = vec![(4.0, 1.0), (1.0, 1.0), (4.0, 1.0), (1.0, 1.0)];
        assert_eq!(weighted_lower_median(&mut items, 2.0), 1.0);
        // One more unit of weight on 4 moves it.
        let mut items = vec![(4.0, 1.5), (1.0, 1.0), (4.0, 1.0), (1.0, 1.0)];
        assert_eq!(weighted_lower_median(&mut items, 2.25), 4.0);
    }

    /// 5×5, left two columns red at disparity 1, right three blue at disparity 5 (the column x = 2 is blue).
    fn step_scene() -> (DisparityMap, RgbImage) {
        let mut disp = Plane::new(5, 5, 5.0);
        let mut img = RgbImage::new(5, 5);
        for y in 0..5 {
            for x in 0..5 {
                let i = y * 5 + x;
                if x < 2 {
                    disp.data[i] = 1.0;
                    img.channels[0][i] = 200.0;
                } else {
                    img.channels[2][i] = 200.0;
                }
            }
        }
        (disp, img)
    }

    #[test]
    fn colour_picks_the_side_of_the_edge() {
        let (mut disp, mut img) = step_scene();
        // Pixel (2, 2) is red (it belongs to the left surface) but carries a wrong disparity 5; pixel (1, 2) is
        // blue with a wrong disparity 1. Colour weights must pull each to its own colour's side, even though the
        // spatial majority of the 5×5 window (15 of 25 pixels are at disparity 5) says otherwise for (2, 2).
        img.channels[0][12] = 200.0;
        img.channels[2][12] = 0.0;
        img.channels[0][11] = 0.0;
        img.channels[2][11] = 200.0;
        disp.data[12] = 5.0;
        disp.data[11] = 1.0;
        let mut targets = Plane::new(5, 5, false);
        targets.data[12] = true;
        targets.data[11] = true;
        let p = WmedianParams {
            enabled: true,
            radius: 2,
            sigma_xy: 9.0,
            sigma_rgb: 20.0,
            edge_px: 0.0,
            ..Default::default()
        };
        let out = weighted_median(&disp, &img, &targets, &p);
        let mut expected = disp.data.clone();
        expected[12] = 1.0;
        expected[11] = 5.0;
        assert_eq!(out.data, expected);
        // With colour made irrelevant (huge σ_rgb) the spatial majority wins at both.
        // At (1, 2) the clipped window spans x = 0..=3: ten pixels at 1 (x = 0, 1) and ten at 5 (x = 2, 3), and
        // the ones at 1 are closer, so 1 wins there.
        let p = WmedianParams { sigma_rgb: 1e6, ..p };
        let out = weighted_median(&disp, &img, &targets, &p);
        expected[12] = 5.0;
        expected[11] = 1.0;
        assert_eq!(out.data, expected);
    }

    #[test]
    fn non_targets_are_untouched_and_inf_is_ignored() {
        let (mut disp, img) = step_scene();
        // Make the whole blue side invalid except the corner (4, 0), at 7.
        for y in 0..5 {
            for x in 2..5 {
                disp.data[y * 5 + x] = INF;
            }
        }
        disp.data[4] = 7.0; // (4, 0)
        let mut targets = Plane::new(5, 5, false);
        targets.data[12] = true; // (2, 2): inf itself, blue; its 3×3 window has only the red 1.0 column finite
        targets.data[13] = true; // (3, 2): window radius 1 has only inf → stays inf
        let p = WmedianParams {
            enabled: true,
            radius: 1,
            sigma_xy: 9.0,
            sigma_rgb: 20.0,
            edge_px: 0.0,
            ..Default::default()
        };
        let out = weighted_median(&disp, &img, &targets, &p);
        let expected = &disp.data;
        assert_eq!(out.data[..12], expected[..12]);
        assert_eq!(out.data[12], 1.0);
        assert!(out.data[13].is_infinite());
        assert_eq!(out.data[14..], expected[14..]);
        // Radius 4: (3, 2) now sees the blue 7.0 at (4, 0) (same colour, weight ~1) and the red 1.0 pixels
        // (colour distance 200√2 → weight e^-100): the blue pixel's weight outweighs all red ones.
        let p = WmedianParams { radius: 4, ..p };
        let out = weighted_median(&disp, &img, &targets, &p);
        assert_eq!(out.data[13], 7.0);
        assert_eq!(out.data[12], 7.0);
        for (i, (a, b)) in out.data.iter().zip(&disp.data).enumerate() {
            if i != 12 && i != 13 {
                assert_eq!(a.to_bits(), b.to_bits(), "non-target pixel {i} changed");
            }
        }
    }

    fn random_scene(w: usize, h: usize, seed: u64) -> (DisparityMap, RgbImage, Plane<bool>) {
        let mut rng = Rng::new(seed);
        let mut disp = Plane::new(w, h, 0.0);
        let mut img = RgbImage::new(w, h);
        let mut targets = Plane::new(w, h, false);
        for i in 0..w * h {
            let u = rng.next_f32();
            disp.data[i] = if u < 0.1 { INF } else { (rng.next_f32() * 40.0).floor() * 0.25 };
            for c in 0..3 {
                img.channels[c][i] = (rng.next_f32() * 255.0).floor();
            }
            targets.data[i] = rng.next_f32() < 0.3;
        }
        (disp, img, targets)
    }

    #[test]
    fn matches_the_naive_reference() {
        let (disp, img, targets) = random_scene(23, 17, 7);
        for (radius, sx, sc) in [(1, 1.0, 10.0), (3, 2.0, 30.0), (5, 9.0, 20.0)] {
            let p = WmedianParams {
                enabled: true,
                radius,
                sigma_xy: sx,
                sigma_rgb: sc,
                edge_px: 0.0,
                ..Default::default()
            };
            let out = weighted_median(&disp, &img, &targets, &p);
            let expected = reference_filter(&disp, &img, &targets, &p);
            // Exact equality: the weights differ only by rounding (f32 vs f64 and the e_min shift), which moves
            // the median only at an exact tie of cumulative weight — not hit by these random weights.
            let mismatches = out.data.iter().zip(&expected).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
            assert_eq!(mismatches, 0, "radius {radius}");
        }
    }

    #[test]
    fn a_sampled_window_matches_the_naive_reference() {
        let (disp, img, targets) = random_scene(29, 19, 5);
        for (radius, step) in [(4, 2), (5, 2), (7, 3), (2, 4)] {
            let p = WmedianParams { radius, sigma_xy: 6.0, step, edge_px: 0.0, ..Default::default() };
            let out = weighted_median(&disp, &img, &targets, &p);
            let expected = reference_filter(&disp, &img, &targets, &p);
            let mismatches = out.data.iter().zip(&expected).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
            assert_eq!(mismatches, 0, "radius {radius}, step {step}");
        }
        // Sampling leaves values out: not the full window's answer.
        let p = WmedianParams { radius: 5, sigma_xy: 6.0, edge_px: 0.0, ..Default::default() };
        let full = weighted_median(&disp, &img, &targets, &p);
        let sampled = weighted_median(&disp, &img, &targets, &WmedianParams { step: 2, ..p });
        assert_ne!(full.data, sampled.data);
    }

    #[test]
    fn same_output_for_one_and_two_threads() {
        let (disp, img, targets) = random_scene(64, 48, 11);
        let p = WmedianParams {
            enabled: true,
            radius: 4,
            sigma_xy: 4.0,
            sigma_rgb: 20.0,
            edge_px: 0.0,
            ..Default::default()
        };
        let run = |n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
                .install(|| weighted_median(&disp, &img, &targets, &p))
        };
        let (a, b) = (run(1), run(2));
        assert!(a.data.iter().zip(&b.data).all(|(x, y)| x.to_bits() == y.to_bits()));
    }

    #[test]
    fn empty_and_tiny_inputs() {
        let out = weighted_median(
            &Plane::new(0, 0, 0.0),
            &RgbImage::new(0, 0),
            &Plane::new(0, 0, true),
            &WmedianParams::default(),
        );
        assert!(out.data.is_empty());
        let out = weighted_median(
            &Plane::from_parts(1, 1, vec![3.5]),
            &RgbImage::new(1, 1),
            &Plane::new(1, 1, true),
            &WmedianParams::default(),
        );
        assert_eq!(out.data, vec![3.5]);
    }

    /// Naive reference of [`depth_edges`].
    fn reference_edges(disp: &DisparityMap, jump: f32) -> Vec<bool> {
        let (w, h) = disp.dims();
        let mut out = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let near: Vec<f32> = (y.saturating_sub(1)..(y + 2).min(h))
                    .flat_map(|yy| (x.saturating_sub(1)..(x + 2).min(w)).map(move |xx| (yy, xx)))
                    .map(|(yy, xx)| disp.data[yy * w + xx])
                    .filter(|v| v.is_finite())
                    .collect();
                if let (Some(lo), Some(hi)) =
                    (near.iter().copied().reduce(f32::min), near.iter().copied().reduce(f32::max))
                {
                    out[y * w + x] = hi - lo > jump;
                }
            }
        }
        out
    }

    #[test]
    fn depth_edges_match_the_reference() {
        let mut rng = Rng::new(7);
        for (w, h) in [(0, 0), (1, 1), (1, 5), (5, 1), (13, 9), (40, 31)] {
            let data =
                (0..w * h).map(|_| if rng.next_f32() < 0.1 { INF } else { (rng.next_f32() * 6.0).floor() }).collect();
            let disp = Plane::from_parts(w, h, data);
            for jump in [0.5, 2.0, 4.5] {
                assert_eq!(depth_edges(&disp, jump).data, reference_edges(&disp, jump), "{w}x{h}, jump {jump}");
            }
        }
        // A slant of less than a pixel per pixel is no edge.
        let ramp = Plane::from_parts(8, 3, (0..24).map(|i| (i % 8) as f32 * 0.9).collect());
        assert!(depth_edges(&ramp, 2.0).data.iter().all(|e| !e));
    }

    #[test]
    fn the_edge_targets_widen_the_edges_and_the_rejected_pixels() {
        // A step from 5 to 20 between x = 7 and 8, one rejected pixel at (2, 4).
        let (w, h) = (16, 9);
        let disp = Plane::from_parts(w, h, (0..w * h).map(|i| if i % w >= 8 { 20.0 } else { 5.0 }).collect());
        let mut trusted = Plane::new(w, h, true);
        trusted.data[4 * w + 2] = false;
        let (narrow, wide) = (edge_targets(&disp, 2.0, 0, &trusted), edge_targets(&disp, 2.0, 1, &trusted));
        for y in 0..h {
            for x in 0..w {
                let want_narrow = (7..=8).contains(&x) || (x, y) == (2, 4);
                let want_wide = (6..=9).contains(&x) || (x.abs_diff(2) <= 1 && y.abs_diff(4) <= 1);
                assert_eq!((narrow.at(x, y), wide.at(x, y)), (want_narrow, want_wide), "({x}, {y})");
            }
        }
    }

    #[test]
    fn the_median_at_depth_edges_undoes_fattening() {
        // Background (disparity 5, grey) on the left, foreground (20, red) from x = 10; the map puts the foreground's
        // disparity on the background's last column, as a window cost does (one pass undoes one column).
        let (w, h) = (20, 12);
        let mut image = RgbImage::new(w, h);
        let mut disp = Plane::new(w, h, 5.0f32);
        for y in 0..h {
            for x in 0..w {
                let fg = x >= 10;
                let colour = if fg { [200.0, 30.0, 30.0] } else { [90.0, 90.0, 90.0] };
                (0..3).for_each(|c| image.channel_mut(c)[y * w + x] = colour[c]);
                if x >= 9 {
                    disp.data[y * w + x] = 20.0;
                }
            }
        }
        let targets = depth_edges(&disp, 2.0);
        assert!(
            targets.data[5 * w + 8] && targets.data[5 * w + 9] && !targets.data[5 * w + 10] && !targets.data[5 * w + 3]
        );
        let out = weighted_median(&disp, &image, &targets, &WmedianParams::default());
        for y in 0..h {
            let row = &out.data[y * w..][..w];
            assert!(row[..10].iter().all(|&d| d == 5.0) && row[10..].iter().all(|&d| d == 20.0), "row {y}: {row:?}");
        }
    }

    #[test]
    fn the_second_run_widens_its_colour_weight_with_the_noise() {
        let p = WmedianParams::default();
        let clean = p.second_run(0.0);
        assert_eq!((clean.radius, clean.sigma_rgb, clean.sigma_xy), (p.edge_radius, p.edge_sigma_rgb, p.sigma_xy));
        // σn 8: √(10² + 3 · 8²) = √292.
        assert!((p.second_run(8.0).sigma_rgb - 292f32.sqrt()).abs() < 1e-4);
    }

    #[test]
    fn validate_names_keys() {
        let p = WmedianParams { edge_px: -1.0, ..Default::default() };
        assert!(p.validate().unwrap_err().to_string().contains("post.wmedian.edge_px"));
        let p = WmedianParams { edge_px: f32::NAN, ..Default::default() };
        assert!(p.validate().unwrap_err().to_string().contains("post.wmedian.edge_px"));
        let p = WmedianParams { radius: 0, ..Default::default() };
        assert!(p.validate().unwrap_err().to_string().contains("post.wmedian.radius"));
        let p = WmedianParams { sigma_rgb: 0.0, ..Default::default() };
        assert!(p.validate().unwrap_err().to_string().contains("post.wmedian.sigma_rgb"));
        let p = WmedianParams { edge_sigma_rgb: -2.0, ..Default::default() };
        assert!(p.validate().unwrap_err().to_string().contains("post.wmedian.edge_sigma_rgb"));
        WmedianParams::default().validate().unwrap();
    }
}
