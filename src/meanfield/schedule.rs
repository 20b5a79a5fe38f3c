//! Update schedules (our addition): the paper updates every pixel from the previous iterate (Jacobi, `jacobi`).
//! The default `checkerboard` updates the pixels with x + y even first, then the odd ones from the new even
//! values (red-black), in place in one buffer, in bands of rows that run in parallel. Measured on trainingQ
//! (docs/tuning-log.md, "How the parameters were chosen"): better after the left-right check and the planes, and
//! for the local term alone as good as twice as many Jacobi iterations. Every banding gives the same results bit for bit, so the output
//! does not depend on the thread count.

use rayon::prelude::*;

use super::MeanField;
use super::update::{NeighbourRows, Pass, RowScratch, rows_of, split_rows};

/// A band of rows `[a, b)` of [`MeanField::checkerboard_in_place`] as one task sees it: its interior rows
/// a + 1 … b − 2 (`interior`, updated in place), the new values of its first and last rows (`first`, `last`: the
/// edge buffers), the old values of those two rows (`old_first`, `old_last`, read by the neighbouring bands), and
/// the rows a − 1 and b outside it (`outside`: the neighbouring bands' old edge rows; `None` at the image's edge).
struct Band<'b> {
    rows: (usize, usize),
    interior: &'b mut [f32],
    first: &'b mut [f32],
    last: &'b mut [f32],
    outside: (Option<&'b [f32]>, Option<&'b [f32]>),
}

impl Band<'_> {
    /// One pass over row y of the band (the rows outside it are read on pass 1 only).
    fn step(&mut self, mf: &MeanField<'_>, pass: Pass, y: usize, vals: &[f32], s: &mut RowScratch) {
        let (a, b) = self.rows;
        // Where row r starts within the interior (rows a + 1 … b − 2).
        let rel = |r: usize| mf.row_starts[r] - mf.row_starts[a + 1];
        let interior = &mut *self.interior;
        let (outside_above, outside_below) = if pass == Pass::Even { self.outside } else { (None, None) };
        if y == a {
            let below = if b - a > 2 { &interior[..rel(a + 2)] } else { &*self.last };
            let nbrs = NeighbourRows { above: outside_above, same: None, below: Some(below), own: None };
            mf.update(y, pass, nbrs, vals, self.first, s);
        } else if y + 1 == b {
            let above = if b - a > 2 { &interior[rel(b - 2)..] } else { &*self.first };
            let nbrs = NeighbourRows { above: Some(above), same: None, below: outside_below, own: None };
            mf.update(y, pass, nbrs, vals, self.last, s);
        } else {
            let (before, rest) = interior.split_at_mut(rel(y));
            let (row, after) = rest.split_at_mut(rel(y + 1) - rel(y));
            let above: &[f32] = if y == a + 1 { self.first } else { &before[rel(y - 1)..] };
            let below: &[f32] = if y + 2 == b { self.last } else { &after[..rel(y + 2) - rel(y + 1)] };
            let nbrs = NeighbourRows { above: Some(above), same: None, below: Some(below), own: None };
            mf.update(y, pass, nbrs, vals, row, s);
        }
    }

    /// The band's sweep: pass 1 of each row y, then pass 2 of the interior row y − 1 (rows a + 1 ..= b − 2),
    /// whose neighbours' pass 1 is then done. The first and last rows' pass 2 waits for the neighbouring bands.
    fn sweep(&mut self, mf: &MeanField<'_>, vals: &[f32]) {
        let (a, b) = self.rows;
        let mut s = RowScratch::new(mf.cost.ndisp);
        for y in a..b {
            self.step(mf, Pass::Even, y, vals, &mut s);
            if y >= a + 2 && b - a > 2 {
                self.step(mf, Pass::Odd, y - 1, vals, &mut s);
            }
        }
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
        let rs = &self.row_starts;
        rows_of(out, rs).into_par_iter().enumerate().for_each_init(
            || RowScratch::new(self.cost.ndisp),
            |s, (y, row)| {
                let own = own_in_src.then(|| &src[rs[y]..rs[y + 1]]);
                self.update(y, pass, NeighbourRows { own, ..NeighbourRows::of(src, y, rs) }, vals, row, s);
            },
        );
    }

    /// Pass 1 of every row and pass 2 of the bands' interior rows, the bands in parallel: each band's first and
    /// last rows of `q` stay old (the neighbouring bands read them), their pass 1 going into `edges` (two rows per
    /// band, starting as copies of the old rows).
    fn sweep_bands(&self, q: &mut [f32], vals: &[f32], bands: &[(usize, usize)], edges: &mut [f32]) {
        let rs = &self.row_starts;
        let h = self.cost.height;
        let mut parts = Vec::with_capacity(bands.len());
        let (mut rest, mut edge_rest): (&mut [f32], &mut [f32]) = (q, edges);
        for &(a, b) in bands {
            let (band, r) = std::mem::take(&mut rest).split_at_mut(rs[b] - rs[a]);
            rest = r;
            let (first, r) = band.split_at_mut(rs[a + 1] - rs[a]);
            let (interior, last) = r.split_at_mut(rs[b - 1] - rs[a + 1]);
            let (edge, r) = std::mem::take(&mut edge_rest).split_at_mut(first.len() + last.len());
            edge_rest = r;
            let (first_new, last_new) = edge.split_at_mut(first.len());
            first_new.copy_from_slice(first);
            last_new.copy_from_slice(last);
            parts.push(((a, b), (&*first, &*last), interior, (first_new, last_new)));
        }
        let olds: Vec<(&[f32], &[f32])> = parts.iter().map(|p| p.1).collect();
        let tasks: Vec<Band<'_>> = parts
            .into_iter()
            .enumerate()
            .map(|(k, ((a, b), _, interior, (first, last)))| {
                let above = (a > 0).then(|| olds[k - 1].1);
                let below = (b < h).then(|| olds[k + 1].0);
                Band { rows: (a, b), interior, first, last, outside: (above, below) }
            })
            .collect();
        tasks.into_par_iter().for_each(|mut band| band.sweep(self, vals));
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
        let rs = &self.row_starts;
        let h = self.cost.height;
        let mut s = RowScratch::new(self.cost.ndisp);
        if bands.is_empty() {
            for pass in [Pass::Even, Pass::Odd] {
                for y in 0..h {
                    let (nbrs, row) = split_rows(q, y, rs);
                    self.update(y, pass, nbrs, vals, row, &mut s);
                }
            }
            return;
        }
        self.sweep_bands(q, vals, bands, edges);
        // Pass 1 of the edge rows back into Q, then their pass 2 (reading only the even pixels of the rows
        // around, all final now).
        let mut edge = &edges[..];
        for &(a, b) in bands {
            let (first, last) = (rs[a]..rs[a + 1], rs[b - 1]..rs[b]);
            let (first_new, rest) = edge.split_at(first.len());
            let (last_new, rest) = rest.split_at(last.len());
            q[first].copy_from_slice(first_new);
            q[last].copy_from_slice(last_new);
            edge = rest;
        }
        for &(a, b) in bands {
            for y in [a, b - 1] {
                let (nbrs, row) = split_rows(q, y, rs);
                self.update(y, Pass::Odd, nbrs, vals, row, &mut s);
            }
        }
    }
}
