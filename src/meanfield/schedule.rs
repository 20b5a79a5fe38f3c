//! Update schedules (our addition): the paper updates every pixel from the previous iterate (Jacobi, `jacobi`).
//! The default `checkerboard` updates the pixels with x + y even first, then the odd ones from the new even
//! values (red-black), in place in one buffer, in bands of rows that run in parallel. Measured on trainingQ
//! (docs/tuning-log.md, "How the parameters were chosen"): better after the left-right check and the planes, and
//! for the local term alone as good as twice as many Jacobi iterations. Every banding gives the same results bit for bit, so the output
//! does not depend on the thread count.

use rayon::prelude::*;

use super::MeanField;
use super::update::{NeighbourRows, Pass, RowScratch, split_rows, update_row};

/// One pass over row y of a band `[a, b)` in [`MeanField::checkerboard_in_place`]: the band's interior rows
/// a + 1 … b − 2 are `interior` (updated in place), its first and last rows `first` and `last` (the edge
/// buffers); rows a − 1 and b, outside the band, are `outside_above` and `outside_below` when needed.
#[allow(clippy::too_many_arguments)]
fn band_step(
    mf: &MeanField<'_>,
    pass: Pass,
    y: usize,
    (a, b): (usize, usize),
    interior: &mut [f32],
    first: &mut [f32],
    last: &mut [f32],
    outside_above: Option<&[f32]>,
    outside_below: Option<&[f32]>,
    vals: &[f32],
    s: &mut RowScratch,
) {
    let len = first.len();
    if y == a {
        let below = if b - a > 2 { &interior[..len] } else { &*last };
        let nbrs = NeighbourRows { above: outside_above, same: None, below: Some(below) };
        update_row(mf, y, pass, nbrs, None, vals, first, s);
    } else if y + 1 == b {
        let above = if b - a > 2 { &interior[interior.len() - len..] } else { &*first };
        let nbrs = NeighbourRows { above: Some(above), same: None, below: outside_below };
        update_row(mf, y, pass, nbrs, None, vals, last, s);
    } else {
        let r = y - a - 1;
        let (before, rest) = interior.split_at_mut(r * len);
        let (row, after) = rest.split_at_mut(len);
        let above: &[f32] = if r == 0 { first } else { &before[(r - 1) * len..] };
        let below: &[f32] = if after.is_empty() { last } else { &after[..len] };
        let nbrs = NeighbourRows { above: Some(above), same: None, below: Some(below) };
        update_row(mf, y, pass, nbrs, None, vals, row, s);
    }
}

/// Bands of rows for [`MeanField::checkerboard_in_place`]: about two per thread, each at least 3 rows
/// (`[a, b)` ranges covering `0..height`); empty if the image has fewer than 3 rows. The banding changes the
/// order of work only, never the results.
pub(super) fn checkerboard_bands(height: usize, threads: usize) -> Vec<(usize, usize)> {
    if height < 3 {
        return Vec::new();
    }
    let count = (2 * threads.max(1)).min(height / 3).max(1);
    (0..count).map(|k| (k * height / count, (k + 1) * height / count)).collect()
}

impl MeanField<'_> {
    /// Red-black update in two sweeps over the image: pass 1 computes the pixels with x + y even from the
    /// previous Q into `next`; pass 2 the odd ones, whose 4 neighbours are all even, from the pass-1 values,
    /// written over the previous Q (each pixel reads its own old value first), with the even ones copied in.
    /// The reference for [`MeanField::checkerboard_in_place`].
    #[cfg(test)]
    pub(super) fn checkerboard_two_pass(&self, q: &mut [f32], next: &mut [f32], vals: &[f32]) {
        self.sweep(Pass::Even, q, true, vals, next);
        self.sweep(Pass::Odd, next, false, vals, q);
    }

    /// One parallel sweep of `pass` over all rows of `out`: neighbours from `src`, each pixel's own previous
    /// marginal from `src` (`own_in_src`) or from `out` itself.
    pub(super) fn sweep(&self, pass: Pass, src: &[f32], own_in_src: bool, vals: &[f32], out: &mut [f32]) {
        let m = self.cost.ndisp;
        let len = self.cost.width * m;
        out.par_chunks_mut(len).enumerate().for_each_init(
            || RowScratch::new(m),
            |s, (y, row)| {
                let own = own_in_src.then(|| &src[y * len..][..len]);
                update_row(self, y, pass, NeighbourRows::of(src, y, len), own, vals, row, s);
            },
        );
    }

    /// The same update as `checkerboard_two_pass` (the test reference) in place, in one buffer: pass 1 writes the even
    /// pixels over their old values (an even pixel reads only odd neighbours and its own old value), pass 2 the
    /// odd ones (reading the new even values). No second N × M buffer, and no copy of the even pixels.
    ///
    /// The rows run in one sweep per band of rows: pass 2 of row y − 1 right after pass 1 of row y, while rows
    /// y − 1 … y + 1 are in cache. Bands run in parallel; each band's first and last rows are read by the
    /// neighbouring bands during the sweep, so their pass 1 goes into `edges` (two rows per band, copies of the
    /// old rows) and is copied back afterwards, when pass 2 of those rows runs. Without bands (fewer than 3 rows)
    /// the two passes run one after the other. Same results as the two sweeps, bit for bit, for any banding.
    pub(super) fn checkerboard_in_place(
        &self,
        q: &mut [f32],
        vals: &[f32],
        bands: &[(usize, usize)],
        edges: &mut [f32],
    ) {
        let m = self.cost.ndisp;
        let len = self.cost.width * m;
        let h = self.cost.height;
        let mut s = RowScratch::new(m);
        if bands.is_empty() {
            for pass in [Pass::Even, Pass::Odd] {
                for y in 0..h {
                    let (nbrs, row) = split_rows(q, y, len);
                    update_row(self, y, pass, nbrs, None, vals, row, &mut s);
                }
            }
            return;
        }
        {
            // Per band: its first and last rows of Q (read-only here), its interior rows (updated in place), and
            // its two edge buffers.
            let mut tasks = Vec::with_capacity(bands.len());
            let mut rest: &mut [f32] = q;
            let mut edge_rest: &mut [f32] = edges;
            for &(a, b) in bands {
                let (band, r) = std::mem::take(&mut rest).split_at_mut((b - a) * len);
                rest = r;
                let (first, r) = band.split_at_mut(len);
                let (interior, last) = r.split_at_mut((b - a - 2) * len);
                let (edge, r) = std::mem::take(&mut edge_rest).split_at_mut(2 * len);
                edge_rest = r;
                let (first_new, last_new) = edge.split_at_mut(len);
                tasks.push(((a, b), (&*first, &*last), interior, (first_new, last_new)));
            }
            let olds: Vec<(&[f32], &[f32])> = tasks.iter().map(|t| t.1).collect();
            let olds = &olds;
            tasks.into_par_iter().enumerate().for_each(
                |(k, ((a, b), (first, last), interior, (first_new, last_new)))| {
                    first_new.copy_from_slice(first);
                    last_new.copy_from_slice(last);
                    let mut s = RowScratch::new(m);
                    let interior_rows = b - a - 2;
                    for y in a..b {
                        // Pass 1 of row y: rows a − 1 and b are the neighbouring bands' (old) edge rows.
                        {
                            let outside_above = (y == a && a > 0).then(|| olds[k - 1].1);
                            let outside_below = (y + 1 == b && b < h).then(|| olds[k + 1].0);
                            band_step(
                                self,
                                Pass::Even,
                                y,
                                (a, b),
                                interior,
                                first_new,
                                last_new,
                                outside_above,
                                outside_below,
                                vals,
                                &mut s,
                            );
                        }
                        // Pass 2 of the interior row y − 1 (rows a + 1 ..= b − 2), now that pass 1 of y is done.
                        if y >= a + 2 && interior_rows > 0 {
                            band_step(
                                self,
                                Pass::Odd,
                                y - 1,
                                (a, b),
                                interior,
                                first_new,
                                last_new,
                                None,
                                None,
                                vals,
                                &mut s,
                            );
                        }
                    }
                },
            );
        }
        // Pass 1 of the edge rows back into Q, then their pass 2 (reading only the even pixels of the rows
        // around, all final now).
        for (&(a, b), edge) in bands.iter().zip(edges.chunks_exact(2 * len)) {
            q[a * len..][..len].copy_from_slice(&edge[..len]);
            q[(b - 1) * len..][..len].copy_from_slice(&edge[len..]);
        }
        for &(a, b) in bands {
            for y in [a, b - 1] {
                let (nbrs, row) = split_rows(q, y, len);
                update_row(self, y, Pass::Odd, nbrs, None, vals, row, &mut s);
            }
        }
    }
}
