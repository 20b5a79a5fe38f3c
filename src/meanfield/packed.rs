//! Packed label bands (our addition): in label bands ([`super::bands`]) each pixel's marginal is 0 outside its
//! band, so only its band is stored, the pixels one after another (compressed rows: pixel i's labels `lo..hi` at
//! `offsets[i]..offsets[i + 1]`). The cost of the bands is packed the same way for a run of more than one iteration,
//! when that takes no more memory than the dense marginals it replaces.
//!
//! Why: an update reads, per pixel, its cost, its own marginal and its four neighbours'. In the dense layout those
//! are runs of the band's labels out of rows of all labels, so the memory traffic stays about the dense update's
//! (the hardware fetches whole neighbourhoods of cache lines) and bands of a third of the labels saved no time.
//! Packed, an iteration's traffic follows the bands. The results are the dense banded run's, bit for bit: every sum
//! adds the same non-zero terms in the same order (a neighbour's labels outside its band are the zeros it skips).

use rayon::prelude::*;

use super::bands::LabelBands;
use super::energy::{FullTerm, LocalTerm, pixel_energies, softmax_neg_padded};
use super::update::{NeighbourRows, Pass, PixelStep, RowScratch};
use super::{MeanField, PairwiseWeights};
use crate::image::CostVolume;

/// Where each pixel's band lives in a packed buffer, and (when packed) the bands' cost.
#[derive(Debug)]
pub(super) struct Packed {
    /// Pixel i's labels `bands.of(i)` at `offsets[i]..offsets[i + 1]`; `N + 1` entries.
    pub(super) offsets: Vec<usize>,
    /// The cost of each pixel's band, laid out like the marginals; empty: read from the dense volume.
    pub(super) cost: Vec<f32>,
}

impl Packed {
    /// The layout of `bands`, with the bands' cost packed out of `cost` (into a buffer from `take`) if `pack_cost`
    /// and the bands hold at most half the volume's labels: then the packed cost and marginals together take no
    /// more memory than the dense marginals. (Packing reads the cost once, as an update does: it pays from the
    /// second iteration on.)
    pub(super) fn new(
        bands: &LabelBands,
        cost: &CostVolume,
        pack_cost: bool,
        take: &mut dyn FnMut(usize) -> Vec<f32>,
    ) -> Self {
        let mut offsets = Vec::with_capacity(bands.as_slice().len() + 1);
        let mut total = 0usize;
        offsets.push(0);
        for &[lo, hi] in bands.as_slice() {
            total += (hi - lo) as usize;
            offsets.push(total);
        }
        let mut packed = Packed { offsets, cost: Vec::new() };
        if pack_cost && 2 * total <= cost.data.len() {
            // Written in full below.
            let mut out = take(total);
            packed.for_pixel_chunks(&mut out, |first, chunk| {
                for (j, (lo, hi)) in (first..).map(|i| bands.of(i)).take(chunk.pixels).enumerate() {
                    let at = packed.offsets[first + j] - packed.offsets[first];
                    chunk.values[at..][..hi - lo].copy_from_slice(&cost.pixel(first + j)[lo..hi]);
                }
            });
            packed.cost = out;
        }
        packed
    }

    /// The values a packed buffer holds.
    pub(super) fn len(&self) -> usize {
        self.offsets.last().copied().unwrap_or(0)
    }

    /// Where row y of a `width`-wide view starts in a packed buffer.
    pub(super) fn row_starts(&self, width: usize, height: usize) -> Vec<usize> {
        (0..=height).map(|y| self.offsets[y * width]).collect()
    }

    /// Runs `f(first pixel, chunk)` in parallel over chunks of consecutive pixels of a packed buffer.
    fn for_pixel_chunks(&self, buf: &mut [f32], f: impl Fn(usize, PixelChunk<'_>) + Sync) {
        const CHUNK: usize = 1024;
        let n = self.offsets.len() - 1;
        let mut parts = Vec::with_capacity(n.div_ceil(CHUNK));
        let mut rest = buf;
        for first in (0..n).step_by(CHUNK) {
            let end = (first + CHUNK).min(n);
            let (part, r) = std::mem::take(&mut rest).split_at_mut(self.offsets[end] - self.offsets[first]);
            rest = r;
            parts.push((first, PixelChunk { pixels: end - first, values: part }));
        }
        parts.into_par_iter().for_each(|(first, chunk)| f(first, chunk));
    }

    /// The packed `q` as softmax(−`scale` · cost) over each pixel's band of `cost` (the marginals of
    /// [`super::energy::unary_marginals`], bit for bit).
    pub(super) fn fill_unary(&self, q: &mut [f32], bands: &LabelBands, cost: &CostVolume, scale: f32) {
        self.for_pixel_chunks(q, |first, chunk| {
            let range = first..first + chunk.pixels;
            unary_in_bands(cost, (bands, &self.offsets[range.start..=range.end]), range, scale, chunk.values);
        });
    }

    /// The packed marginals `q` as a dense `N × m` volume into `out` (0 outside the bands).
    pub(super) fn unpack(&self, q: &[f32], bands: &LabelBands, m: usize, out: &mut [f32]) {
        const CHUNK: usize = 1024;
        out.par_chunks_mut(m * CHUNK).enumerate().for_each(|(k, out)| {
            for (j, dense) in out.chunks_exact_mut(m).enumerate() {
                let i = k * CHUNK + j;
                let (lo, hi) = bands.of(i);
                dense[..lo].fill(0.0);
                dense[lo..hi].copy_from_slice(&q[self.offsets[i]..self.offsets[i + 1]]);
                dense[hi..].fill(0.0);
            }
        });
    }
}

/// The unary marginals of the pixels `pixels` into their packed bands `out` (`offsets` from the first pixel's, one
/// more than the pixels), each through the padded softmax (no scalar tail; bit-identical to the in-place one).
/// Compiled for AVX2 + FMA as well (same results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn unary_in_bands(
    cost: &CostVolume,
    (bands, offsets): (&LabelBands, &[usize]),
    pixels: std::ops::Range<usize>,
    scale: f32,
    out: &mut [f32],
) {
    let lanes = cost.ndisp.next_multiple_of(8);
    let (mut en, mut ex) = (vec![0.0f32; lanes], vec![0.0f32; lanes]);
    for (k, i) in pixels.enumerate() {
        let (lo, hi) = bands.of(i);
        let len = hi - lo;
        let padded = len.next_multiple_of(8);
        en[..len].iter_mut().zip(&cost.pixel(i)[lo..hi]).for_each(|(e, c)| *e = c * scale);
        en[len..padded].fill(0.0);
        let at = offsets[k] - offsets[0];
        softmax_neg_padded(&en[..padded], &mut ex[..padded], &mut out[at..][..len]);
    }
}

/// Consecutive pixels' values in a packed buffer.
struct PixelChunk<'a> {
    pixels: usize,
    values: &'a mut [f32],
}

/// Adds `weight × q` to P̃ over the labels both hold: `p_padded[k]` is P̃(a − 1 + k) for the labels a − 1 ..= b of
/// a pixel with labels a..b; `q` holds a neighbour's labels `na..nb`.
#[inline(always)]
fn add_neighbour(
    p_padded: &mut [f32],
    (a, b, m): (usize, usize, usize),
    weight: f32,
    q: &[f32],
    (na, nb): (usize, usize),
) {
    let lo = a.saturating_sub(1).max(na);
    let hi = (b + 1).min(m).min(nb);
    if lo >= hi {
        return;
    }
    let dst = &mut p_padded[lo + 1 - a..][..hi - lo];
    for (p, v) in dst.iter_mut().zip(&q[lo - na..hi - na]) {
        *p += weight * v;
    }
}

/// [`super::update::update_row`] on packed marginals (`mf.packed`, with its label bands): the rows in `nbrs` and
/// `out_row` are packed rows (row y at `mf.row_starts[y]..mf.row_starts[y + 1]` of the packed buffer). The same
/// results as the dense banded update.
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
pub(super) fn update_row_packed<'c, 'r>(
    mf: &MeanField<'c>,
    y: usize,
    pass: Pass,
    nbrs: NeighbourRows<'r>,
    vals: &[f32],
    out_row: &mut [f32],
    s: &mut RowScratch,
) {
    let (Some(packed), Some(bands)) = (&mf.packed, &mf.label_bands) else {
        unreachable!("a packed update without packed bands")
    };
    let (w, m) = (mf.cost.width, mf.cost.ndisp);
    let PairwiseWeights { fcm, lcm } = mf.weights;
    let full_kernel = mf.full.as_ref().filter(|_| fcm > 0.0);
    let off = &packed.offsets;
    let base = off[y * w];
    let above_base = (y > 0).then(|| off[(y - 1) * w]);
    let below_base = nbrs.below.map(|_| off[(y + 1) * w]);
    for x in 0..w {
        let i = y * w + x;
        let (start, end) = (off[i] - base, off[i + 1] - base);
        match nbrs.step_of(mf, pass, x, y) {
            PixelStep::Compute => {}
            PixelStep::Keep => continue,
            PixelStep::Copy(from) => {
                out_row[start..end].copy_from_slice(&from[start..end]);
                continue;
            }
        }
        let (a, b) = bands.of(i);
        let len = b - a;
        let (before, rest) = out_row.split_at_mut(start);
        let (e, after) = rest.split_at_mut(len);
        let (before, after): (&[f32], &[f32]) = (before, after);
        let own: &[f32] = match nbrs.own {
            Some(r) => &r[start..end],
            None => e,
        };
        let full = full_kernel.map(|kernel| {
            kernel.slice_labels(vals, i, m, a, &mut s.msg[..len]);
            let (out_scale, self_weight) = kernel.message_factors(i);
            FullTerm { msg: &s.msg[..len], own, omega: fcm, out_scale, self_weight }
        });
        let local = (lcm > 0.0).then(|| {
            // P̃ of the labels a − 1 ..= b, the neighbours added in the dense update's order: left, right, up, down.
            let p_padded = &mut s.p_padded[..len + 2];
            p_padded.fill(0.0);
            let me = (a, b, m);
            if x > 0 {
                let q = match nbrs.same {
                    Some(same) => &same[off[i - 1] - base..start],
                    None => &before[off[i - 1] - base..],
                };
                add_neighbour(p_padded, me, mf.local.right.data[i - 1], q, bands.of(i - 1));
            }
            if x + 1 < w {
                let q = match nbrs.same {
                    Some(same) => &same[end..off[i + 2] - base],
                    None => &after[..off[i + 2] - off[i + 1]],
                };
                add_neighbour(p_padded, me, mf.local.right.data[i], q, bands.of(i + 1));
            }
            if let (Some(row), Some(rb)) = (nbrs.above, above_base) {
                let q = &row[off[i - w] - rb..off[i - w + 1] - rb];
                add_neighbour(p_padded, me, mf.local.down.data[i - w], q, bands.of(i - w));
            }
            if let (Some(row), Some(rb)) = (nbrs.below, below_base) {
                let q = &row[off[i + w] - rb..off[i + w + 1] - rb];
                add_neighbour(p_padded, me, mf.local.down.data[i], q, bands.of(i + w));
            }
            LocalTerm { p_padded: &s.p_padded[..len + 2], omega: lcm, beta: mf.beta }
        });
        let cost = if packed.cost.is_empty() { &mf.cost.pixel(i)[a..b] } else { &packed.cost[off[i]..off[i + 1]] };
        pixel_energies(cost, mf.unary_scale, full, local, &mut s.energy[..len]);
        let lanes = len.next_multiple_of(8);
        softmax_neg_padded(&s.energy[..lanes], &mut s.exps[..lanes], e);
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{banded_pair, random_bands, random_cost};
    use super::super::{Buffers, MeanField, PairwiseWeights, decode_marginals};
    use super::LabelBands;
    use crate::image::Plane;
    use crate::params::{MeanFieldParams, Schedule};

    /// Packed label bands (only the bands stored) give the marginals of the dense banded run bit for bit, with either
    /// schedule and any thread count, with the bands' cost packed or read from the dense volume; their decoded
    /// disparities and confidences are the dense decode's of those marginals.
    #[test]
    fn meanfield_packed_bands_are_the_dense_banded_run() {
        let (w, h, m) = (23, 14, 11);
        let cost = random_cost(w, h, m, 31, 20.0);
        let (image, _, _) = banded_pair(w, h);
        let weights = PairwiseWeights { fcm: 6.0, lcm: 1.5 };
        // Random bands and narrow ones hold less than half the labels (the cost is packed), all labels more (it is
        // not).
        let narrow = LabelBands::around(
            (&Plane::new(w, h, 5.0), &Plane::new(w, h, 5.0)),
            &Plane::new(w, h, f32::INFINITY),
            m,
            0,
            1.0,
            0,
        );
        for bands in [random_bands(w, h, m, 32), narrow, LabelBands::full(w, h, m)] {
            for schedule in [Schedule::Checkerboard, Schedule::Jacobi] {
                let p = MeanFieldParams { schedule, ..MeanFieldParams::default() };
                let run = |packed: bool, threads: usize| {
                    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                    pool.install(|| {
                        let (b, buffers) = (bands.clone(), Buffers::default());
                        let mut mf = match packed {
                            true => MeanField::in_label_bands(&cost, &image, &p, weights, buffers, b),
                            false => MeanField::in_dense_label_bands(&cost, &image, &p, weights, buffers, b),
                        };
                        assert_eq!(mf.packed.is_some(), packed);
                        let cost_packed = mf.packed.as_ref().is_some_and(|p| !p.cost.is_empty());
                        assert_eq!(cost_packed, packed && p.iterations > 1 && 2.0 * bands.mean_width() <= m as f64);
                        for _ in 0..3 {
                            mf.step();
                        }
                        let q = mf.marginals().into_owned();
                        // The dense run's answer from its marginals as a volume, by the dense decode.
                        let decoded = match packed {
                            true => mf.decode(true),
                            false => decode_marginals(&mf.into_marginals(), true),
                        };
                        (q, decoded.0.data, decoded.1.data)
                    })
                };
                let dense = run(false, 2);
                for threads in [1, 3] {
                    let packed = run(true, threads);
                    let same = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
                    assert!(same(&dense.0, &packed.0), "{schedule:?}, {threads} threads: marginals");
                    assert!(same(&dense.1, &packed.1) && same(&dense.2, &packed.2), "{schedule:?}: decoded");
                }
            }
        }
    }
}
