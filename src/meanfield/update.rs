//! The update of one row of pixels (Algorithm 1's compatibility transform and local update): each pixel slices
//! its fully connected message from the lattice, sums its four neighbours' marginals into P̃, computes its
//! energies ([`super::energy`]) and writes softmax(−E) over its marginal.
//!
//! The update is the only O(N·M) loop of an iteration besides the lattice; it is compiled for AVX2 + FMA as well
//! and picked at run time, with the same results (Rust never contracts a·b + c into an FMA).

use super::energy::{FullTerm, LocalTerm, pixel_energies, softmax_neg_padded};
use super::packed::update_row_packed;
use super::{MeanField, PairwiseWeights};

/// Which pixels one update pass computes: all, or one colour of the checkerboard ((x + y) even or odd).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Pass {
    All,
    Even,
    Odd,
}

/// Per-thread scratch of the row update, `M` labels.
pub(super) struct RowScratch {
    /// The sliced fully connected message.
    pub(super) msg: Vec<f32>,
    /// P̃ with a zero at each end.
    pub(super) p_padded: Vec<f32>,
    /// The energies E(d), padded with zeros to a multiple of 8 labels.
    pub(super) energy: Vec<f32>,
    /// exp(min E − E(d)), as long as `energy`.
    pub(super) exps: Vec<f32>,
    /// A row of zeros standing in for missing neighbours.
    pub(super) zeros: Vec<f32>,
}

impl RowScratch {
    pub(super) fn new(m: usize) -> Self {
        let lanes = m.next_multiple_of(8);
        RowScratch {
            msg: vec![0.0; m],
            p_padded: vec![0.0; m + 2],
            energy: vec![0.0; lanes],
            exps: vec![0.0; lanes],
            zeros: vec![0.0; m],
        }
    }
}

/// Computes the new Q for row `y` into `out_row`: neighbours' marginals come from `nbrs` (rows y − 1, y, y + 1;
/// row y from `out_row` itself when `nbrs.same` is `None`), the pixel's own previous marginal (for the self
/// term) from `nbrs.own`, or from `out_row` itself when `None`. `pass` picks the pixels to compute; with
/// [`Pass::Odd`] and a separate `nbrs.same`, the even pixels are copied from it.
/// Compiled for AVX2 + FMA as well, picked at run time (same results: no contraction of a·b + c).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
pub(super) fn update_row<'c, 'r>(
    mf: &MeanField<'c>,
    y: usize,
    pass: Pass,
    nbrs: NeighbourRows<'r>,
    vals: &[f32],
    out_row: &mut [f32],
    s: &mut RowScratch,
) {
    let (w, m) = (mf.cost.width, mf.cost.ndisp);
    let PairwiseWeights { fcm, lcm } = mf.weights;
    let full_kernel = mf.full.as_ref().filter(|_| fcm > 0.0);
    for x in 0..w {
        let i = y * w + x;
        match nbrs.step_of(mf, pass, x, y) {
            PixelStep::Compute => {}
            PixelStep::Keep => continue,
            PixelStep::Copy(from) => {
                out_row[x * m..][..m].copy_from_slice(&from[x * m..][..m]);
                continue;
            }
        }
        // The pixel's own slot, and the row's other pixels (its left and right neighbours when updating in
        // place: they are of the other colour, so not written by this pass).
        let (before, rest) = out_row.split_at_mut(x * m);
        let (e, after) = rest.split_at_mut(m);
        let (before, after): (&[f32], &[f32]) = (before, after);
        let own: &[f32] = match nbrs.own {
            Some(r) => &r[x * m..][..m],
            None => e,
        };
        // The pixel's labels a..b (all of them without label bands; outside its band its marginal stays 0).
        let (a, b) = mf.label_bands.as_ref().map_or((0, m), |bands| bands.of(i));
        let len = b - a;
        let own = &own[a..b];
        let full = full_kernel.map(|kernel| {
            kernel.slice_labels(vals, i, m, a, &mut s.msg[..len]);
            let (out_scale, self_weight) = kernel.message_factors(i);
            FullTerm { msg: &s.msg[..len], own, omega: fcm, out_scale, self_weight }
        });
        let local = (lcm > 0.0).then(|| {
            // Missing neighbours (image border) read a row of zeros with weight 0.
            let zeros = &s.zeros[..];
            let (l, r) = ((x > 0).then(|| x - 1), (x + 1 < w).then_some(x + 1));
            let wts = [
                l.map_or(0.0, |_| mf.local.right.data[i - 1]),
                r.map_or(0.0, |_| mf.local.right.data[i]),
                nbrs.above.map_or(0.0, |_| mf.local.down.data[i - w]),
                nbrs.below.map_or(0.0, |_| mf.local.down.data[i]),
            ];
            let ql = l.map_or(zeros, |l| match nbrs.same {
                Some(same) => &same[l * m..][..m],
                None => &before[l * m..][..m],
            });
            let qr = r.map_or(zeros, |r| match nbrs.same {
                Some(same) => &same[r * m..][..m],
                None => &after[..m],
            });
            let qu = nbrs.above.map_or(zeros, |row| &row[x * m..][..m]);
            let qd = nbrs.below.map_or(zeros, |row| &row[x * m..][..m]);
            // P̃ of the labels a − 1 ..= b (`p_padded[k]` = P̃(a − 1 + k), 0 outside the labels), accumulated in
            // the order left, right, up, down (the sequential reference's order).
            let p_padded = &mut s.p_padded[..len + 2];
            let (lo, hi) = (a.saturating_sub(1), (b + 1).min(m));
            p_padded[0] = 0.0;
            p_padded[len + 1] = 0.0;
            let terms = ql[lo..hi].iter().zip(&qr[lo..hi]).zip(&qu[lo..hi]).zip(&qd[lo..hi]);
            for (p, (((l, r), u), d)) in p_padded[lo + 1 - a..].iter_mut().zip(terms) {
                *p = wts[0] * l + wts[1] * r + wts[2] * u + wts[3] * d;
            }
            LocalTerm { p_padded: &s.p_padded[..len + 2], omega: lcm, beta: mf.beta }
        });
        pixel_energies(&mf.cost.pixel(i)[a..b], mf.unary_scale, full, local, &mut s.energy[..len]);
        let lanes = len.next_multiple_of(8);
        softmax_neg_padded(&s.energy[..lanes], &mut s.exps[..lanes], &mut e[a..b]);
    }
}

/// The marginals of the rows around the row being updated (each `width × M`; `None` outside the image, and
/// `same` is `None` when the row is updated in place).
#[derive(Clone, Copy)]
pub(super) struct NeighbourRows<'s> {
    pub(super) above: Option<&'s [f32]>,
    pub(super) same: Option<&'s [f32]>,
    pub(super) below: Option<&'s [f32]>,
    /// Row y's own previous marginals (the self term), when the row being written does not hold them.
    pub(super) own: Option<&'s [f32]>,
}

/// What an update pass does with one pixel.
pub(super) enum PixelStep<'s> {
    /// Computes its new marginal.
    Compute,
    /// Leaves it: the row being written already holds it.
    Keep,
    /// Copies its marginal from this row (the row being written is apart from the one that holds it).
    Copy(&'s [f32]),
}

impl<'s> NeighbourRows<'s> {
    /// What `pass` does with pixel (x, y): the other colour's pixels and the settled ones keep their marginals,
    /// copied from `same` (the other colour) or `own` (settled) when the row is written apart from them.
    #[inline(always)]
    pub(super) fn step_of(&self, mf: &MeanField<'_>, pass: Pass, x: usize, y: usize) -> PixelStep<'s> {
        let odd = (x + y) % 2 == 1;
        let kept_in = |row: Option<&'s [f32]>| row.map_or(PixelStep::Keep, PixelStep::Copy);
        match pass {
            Pass::Even if odd => PixelStep::Keep,
            Pass::Odd if !odd => kept_in(self.same),
            _ if mf.is_settled(y * mf.cost.width + x) => kept_in(self.own),
            _ => PixelStep::Compute,
        }
    }

    /// Rows y − 1, y, y + 1 of a whole volume whose row r is `volume[row_starts[r]..row_starts[r + 1]]`.
    pub(super) fn of(volume: &'s [f32], y: usize, row_starts: &[usize]) -> Self {
        let h = row_starts.len() - 1;
        let row = |r: usize| &volume[row_starts[r]..row_starts[r + 1]];
        NeighbourRows {
            above: (y > 0).then(|| row(y - 1)),
            same: Some(row(y)),
            below: (y + 1 < h).then(|| row(y + 1)),
            own: None,
        }
    }
}

/// Splits rows y − 1, y, y + 1 out of a volume whose row r is `volume[row_starts[r]..row_starts[r + 1]]`: row y
/// mutable, its neighbours as [`NeighbourRows`] with `same` = `None` (for an update in place).
pub(super) fn split_rows<'v>(
    volume: &'v mut [f32],
    y: usize,
    row_starts: &[usize],
) -> (NeighbourRows<'v>, &'v mut [f32]) {
    let h = row_starts.len() - 1;
    let (before, rest) = volume.split_at_mut(row_starts[y]);
    let (row, after) = rest.split_at_mut(row_starts[y + 1] - row_starts[y]);
    let above = (y > 0).then(|| &before[row_starts[y - 1]..]);
    let below = (y + 1 < h).then(|| &after[..row_starts[y + 2] - row_starts[y + 1]]);
    (NeighbourRows { above, same: None, below, own: None }, row)
}

/// A volume cut into its rows (row r: `row_starts[r]..row_starts[r + 1]`).
pub(super) fn rows_of<'v>(mut volume: &'v mut [f32], row_starts: &[usize]) -> Vec<&'v mut [f32]> {
    row_starts
        .windows(2)
        .map(|r| {
            let (row, rest) = std::mem::take(&mut volume).split_at_mut(r[1] - r[0]);
            volume = rest;
            row
        })
        .collect()
}

impl MeanField<'_> {
    /// [`update_row`], or [`update_row_packed`] when Q is packed (the rows then packed rows).
    pub(super) fn update(
        &self,
        y: usize,
        pass: Pass,
        nbrs: NeighbourRows<'_>,
        vals: &[f32],
        out_row: &mut [f32],
        s: &mut RowScratch,
    ) {
        match self.packed {
            Some(_) => update_row_packed(self, y, pass, nbrs, vals, out_row, s),
            None => update_row(self, y, pass, nbrs, vals, out_row, s),
        }
    }
}
