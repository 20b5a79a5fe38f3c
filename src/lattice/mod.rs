//! Permutohedral-lattice bilateral filter (Adams, Baek & Davis, Eurographics 2010), the fast message passing of
//! the fully connected term (paper §3).
//!
//! Computes, for every pixel i and channel l, `out_i(l) ≈ Σ_j k(i, j) in_j(l)` with the 5-D Gaussian
//! `k(i, j) = exp(−|p_i − p_j|²/2σx² − |f_i − f_j|²/2σf²)` over position p and RGB colour f, in O(N·M) instead of
//! O(N²·M). Features `(x/σx, y/σx, r/σf, g/σf, b/σf)` are embedded in the (d+1)-dimensional permutohedral lattice
//! (d = 5); each pixel is *splatted* onto the d+1 vertices of its enclosing simplex with barycentric weights, the
//! lattice values are *blurred* with a [1/2 1 1/2] kernel along each of the d+1 lattice directions, and *sliced*
//! back with the same weights.
//!
//! Build once per image ([`Lattice::build`]): per-pixel vertex indices and weights, the vertex hash table, ranges
//! of vertices with the span of pixels contributing to each (so the splat runs range by range in parallel, each
//! range scanning its pixels in order: no racing scatters, every vertex sums in pixel order, results do not
//! depend on the thread count) and the blur neighbours of every vertex. [`Lattice::filter`] then runs any number
//! of channels at once, channels innermost (`[i·nc + c]`, the cost-volume layout), with no allocation after its
//! scratch buffers have grown once.
//!
//! Scale: the lattice's raw output is `Σ_j k̃(i, j) in_j` for a kernel k̃ that approximates a Gaussian up to a
//! constant factor; [`Lattice::filter`] multiplies by [`OUTPUT_SCALE`], measured so that k̃ ≈ k in the interior of
//! a uniform image (see the `lattice_matches_brute_force_gaussian` test and its tolerance).
//!
//! Self contribution: [`Lattice::self_weight`] is the lattice's k̃(i, i) for every pixel, exact for the
//! infinite lattice (see its doc), so callers can leave each pixel's own value out (the paper's j ≠ i).
//!
//! Vertex ids are assigned in order of first appearance while scanning pixels in raster order, which makes the
//! lattice (and every filter result) deterministic. Keys are five 16-bit lattice coordinates (the (d+1)-th is
//! implied by the zero sum; see `Key`); the largest coordinate is ~724 for a Middlebury quarter-resolution image
//! (about 720 × 500 pixels), far from the limit.
//!
//! The splat, slice, blur, self-weight and embedding kernels are compiled for AVX2 + FMA as well and picked at run
//! time, with the same results; the `force-baseline` feature leaves only the baseline versions (see
//! [`crate::fastmath`], "SIMD in jem").

mod embed;
mod keys;

use rayon::prelude::*;

use crate::image::RgbImage;
use embed::{Features, LANES, elevation_scales};
use keys::{Key, assign_vertex_ids};

/// Feature dimension: x, y, r, g, b.
pub(crate) const D: usize = 5;
/// Vertices per simplex.
const D1: usize = D + 1;
/// Marks a missing blur neighbour.
const NONE: u32 = u32::MAX;

/// Factor applied to the sliced values so that the lattice's kernel has the true Gaussian's mass.
///
/// On a uniform-colour image the raw lattice output of an all-ones input, away from the borders, is 0.5536 ×
/// 2πσx² at σx = 5 (0.530 at σx = 3, 0.559 at σx = 8): the lattice kernel is piecewise linear and a little wider
/// than the Gaussian (its mass/peak ratio is ~10% higher). Matching the mass, the quantity a message sums, gives
/// this factor; the peak k̃(i, i) is then ~0.9–1.0 instead of 1. Checked by `lattice_output_scale_matches_mass`.
pub(crate) const OUTPUT_SCALE: f32 = 1.0 / 0.5536;

/// The largest feature value (position/σxy or colour/σrgb) the lattice accepts: its 16-bit keys hold the
/// elevated coordinates, which are at most ~34.6 × the largest feature (2d · (d+1)·√(2/3)/√2 for d = 5), plus
/// d+1, so they stay within ±31 200 and a blur step (at most d+1) never leaves the 16-bit range.
pub(crate) const MAX_FEATURE: f32 = 900.0;

/// Whether an image of this size with these σ can be embedded (see [`MAX_FEATURE`]).
pub(crate) fn features_fit(width: usize, height: usize, sigma_xy: f32, sigma_rgb: f32) -> bool {
    (width.max(height) as f32 / sigma_xy) <= MAX_FEATURE && 255.0 / sigma_rgb <= MAX_FEATURE
}

/// A permutohedral lattice built for one image's features.
#[derive(Clone, Debug)]
pub struct Lattice {
    npix: usize,
    nvert: usize,
    /// `[pixel·D1 + k]`: the k-th vertex of the pixel's simplex.
    pix_vertex: Vec<u32>,
    /// `[pixel·D1 + k]`: its barycentric weight.
    pix_weight: Vec<f32>,
    /// Ranges of vertices splatted in parallel, `(first, end, first pixel, end pixel)`: the pixels contributing
    /// to vertices `first..end` are all within `first pixel..end pixel`.
    splat_ranges: Vec<(usize, usize, usize, usize)>,
    /// `[dir·nvert + v]`: the two blur neighbours of vertex v along lattice direction `dir` (or `NONE`).
    blur_nbr: Vec<[u32; 2]>,
    /// k̃(i, i) per pixel (see [`Lattice::self_weight`]).
    self_weight: Vec<f32>,
}

/// Reusable buffers for [`Lattice::filter`]; grow on first use, then no allocation.
#[derive(Clone, Debug, Default)]
pub struct LatticeScratch {
    a: Vec<f32>,
    b: Vec<f32>,
    zero: Vec<f32>,
}

impl Lattice {
    /// Builds the lattice for an image's (x/σxy, y/σxy, r/σrgb, g/σrgb, b/σrgb) features.
    ///
    /// # Panics
    /// If a σ is not positive, or the features exceed `MAX_FEATURE` (check with `features_fit`; e.g. more
    /// than 4 500 pixels per side at σxy = 5) so that a lattice coordinate could overflow its 16 bits.
    pub fn build(image: &RgbImage, sigma_xy: f32, sigma_rgb: f32) -> Lattice {
        assert!(sigma_xy > 0.0 && sigma_rgb > 0.0, "lattice sigmas must be positive");
        assert!(
            features_fit(image.width, image.height, sigma_xy, sigma_rgb),
            "lattice features too large for 16-bit keys"
        );
        let npix = image.len();
        let scales = [1.0 / sigma_xy, 1.0 / sigma_rgb];

        // 1. Embed every pixel and number the simplex vertices in raster order of first appearance, block by
        //    block in parallel.
        let (pix_vertex, pix_weight, table) =
            assign_vertex_ids(Features::Image { image, scales, elevation: elevation_scales() });
        let keys = &table.keys;
        let nvert = table.len();
        let mut self_weight = vec![0.0f32; npix];
        const CHUNK: usize = 64 * LANES;
        self_weight.par_chunks_mut(CHUNK).zip(pix_weight.par_chunks(CHUNK * D1)).for_each(|(s, w)| self_weights(w, s));

        // 2. Ranges of vertices for the parallel splat, and the pixels each needs.
        let splat_ranges = splat_ranges(&pix_vertex, nvert, 4 * rayon::current_num_threads());

        // 3. Blur neighbours along each lattice direction: key ± (1, …, 1) ∓ (d+1)·e_dir. Only the upper ones
        //    are looked up; v is the lower neighbour of its upper neighbour, so the lower ones are filled by
        //    inverting (one direction per task, in vertex order: no shared writes).
        let mut blur_nbr = vec![[NONE; 2]; D1 * nvert];
        for (dir, nbrs) in blur_nbr.chunks_exact_mut(nvert.max(1)).enumerate() {
            const CHUNK: usize = 128;
            nbrs.par_chunks_mut(CHUNK).zip(keys.par_chunks(CHUNK)).for_each(|(n, keys)| {
                let queries: [Key; CHUNK] =
                    std::array::from_fn(|k| keys.get(k).map_or(Key::default(), |key| key.step(dir, true)));
                let mut ids = [NONE; CHUNK];
                table.get_many(&queries[..keys.len()], &mut ids[..keys.len()]);
                for (n, &id) in n.iter_mut().zip(&ids) {
                    n[1] = id;
                }
            });
        }
        blur_nbr.par_chunks_exact_mut(nvert.max(1)).for_each(|nbrs| {
            for v in 0..nbrs.len() {
                let up = nbrs[v][1];
                if up != NONE {
                    nbrs[up as usize][0] = v as u32;
                }
            }
        });

        Lattice { npix, nvert, pix_vertex, pix_weight, splat_ranges, blur_nbr, self_weight }
    }

    /// Number of pixels the lattice was built for.
    pub fn num_pixels(&self) -> usize {
        self.npix
    }

    /// Number of lattice vertices (≈ 0.4 per pixel on Middlebury Q images at σ = 5/55).
    pub fn num_vertices(&self) -> usize {
        self.nvert
    }

    /// k̃(i, i): the weight the filter gives a pixel's own input, already scaled by `OUTPUT_SCALE`.
    ///
    /// A pixel splats weight w_k onto simplex vertex k and slices back with the same weights, so its self-weight
    /// is Σ_{k,k'} w_k w_k' B(k, k'), where B is the blur's response from vertex k at vertex k'. Two vertices of
    /// one simplex differ by −Σ_{j∈T} n_j along |T| = |k − k'| lattice directions, and the only blur paths between
    /// them step −1 along T (weight ½ each, 1 elsewhere) or +1 along the complement; so
    /// B = ½^m + ½^(d+1−m) for m = |k − k'| > 0 and B = 1 + 2·½^(d+1) for k = k'. This is exact on the infinite
    /// lattice; where intermediate vertices are missing (sparse feature space) the filter's true self-weight is
    /// a little smaller.
    pub fn self_weight(&self) -> &[f32] {
        &self.self_weight
    }

    /// Filters `input` (`num_pixels × channels`, channels innermost) into `output` (same shape):
    /// `output_i(c) = Σ_j k̃(i, j) input_j(c)`, including j = i.
    ///
    /// # Panics
    /// If the slices do not have `num_pixels × channels` elements.
    pub fn filter(&self, input: &[f32], output: &mut [f32], channels: usize, scratch: &mut LatticeScratch) {
        let nc = channels;
        assert_eq!(output.len(), self.npix * nc, "lattice filter output has the wrong size");
        let vals = self.splat_blur(input, None, None, nc, scratch);
        const CHUNK: usize = 256;
        output.par_chunks_mut(nc.max(1) * CHUNK).enumerate().for_each(|(k, out)| {
            slice_pixels(self, vals, k * CHUNK, out, nc.max(1));
        });
    }

    /// The first two steps of [`Lattice::filter`]: splats `input` (each pixel's values multiplied by
    /// `pixel_scale[p]` if given) and blurs; returns the vertex values (`num_vertices × channels`), to be read
    /// per pixel with [`Lattice::slice`]. Lets a caller fuse slicing into its own per-pixel loop.
    ///
    /// With `bands`, pixel p splats only its channels `bands.ranges[p]`: the caller promises that its other
    /// channels are 0, and the result is the same, bit for bit, as splatting them all (adding w·0 to a sum of
    /// non-negative terms changes nothing). With packed bands, `input` holds only those channels
    /// (`Bands::packed`).
    ///
    /// # Panics
    /// If `input` does not have `num_pixels × channels` elements (or, packed, the bands' total), `pixel_scale` or
    /// `bands` not `num_pixels`, or a band is not within `0..channels`.
    pub fn splat_blur<'s>(
        &self,
        input: &[f32],
        pixel_scale: Option<&[f32]>,
        bands: Option<Bands<'_>>,
        channels: usize,
        scratch: &'s mut LatticeScratch,
    ) -> &'s [f32] {
        let nc = channels;
        let values = bands.and_then(|b| b.packed).map_or(self.npix * nc, |o| o.last().copied().unwrap_or(0));
        assert_eq!(input.len(), values, "lattice filter input has the wrong size");
        if let Some(s) = pixel_scale {
            assert_eq!(s.len(), self.npix, "lattice pixel scale has the wrong size");
        }
        if let Some(Bands { ranges, packed }) = bands {
            assert_eq!(ranges.len(), self.npix, "lattice bands have the wrong size");
            assert!(ranges.iter().all(|&[lo, hi]| lo <= hi && hi as usize <= nc), "a lattice band is out of range");
            if let Some(o) = packed {
                assert_eq!(o.len(), self.npix + 1, "lattice band offsets have the wrong size");
                let fits = ranges.iter().zip(o.windows(2)).all(|(&[lo, hi], w)| w[1] - w[0] == (hi - lo) as usize);
                assert!(fits, "lattice band offsets do not match the bands");
            }
        }
        let len = self.nvert * nc;
        // Both are written in full before they are read (the splat zeroes its vertices, each blur pass writes every
        // vertex): what a reused buffer held does not matter, and a grown one is zeroed in parallel.
        scratch.a = crate::image::reuse_storage(std::mem::take(&mut scratch.a), len);
        scratch.b = crate::image::reuse_storage(std::mem::take(&mut scratch.b), len);
        scratch.zero.resize(nc, 0.0);
        if nc == 0 || self.npix == 0 {
            return &scratch.a;
        }
        let LatticeScratch { a, b, zero } = scratch;
        let zero: &[f32] = zero;
        let (mut cur, mut next) = (a, b);

        self.splat(SplatInput { values: input, pixel_scale, bands, channels: nc }, cur);
        const CHUNK: usize = 256;

        // Blur along each of the d+1 directions: v ← v + ½(down + up), a missing neighbour counting as 0.
        for dir in 0..D1 {
            let nbrs = &self.blur_nbr[dir * self.nvert..][..self.nvert];
            let src: &[f32] = cur;
            next.par_chunks_mut(nc * CHUNK).zip(nbrs.par_chunks(CHUNK)).enumerate().for_each(|(k, (dst, nbrs))| {
                blur_vertices(src, zero, k * CHUNK, nbrs, dst, nc);
            });
            std::mem::swap(&mut cur, &mut next);
        }
        cur
    }

    /// The splat: `vals[v]` = Σ over the pixels p with vertex v, in pixel order, of weight × `pixel_scale[p]` ×
    /// `input[p]`. Each range of vertices (in parallel) scans the pixels that contribute to it in order, so the
    /// pixels' values are read in order rather than gathered, and every sum is taken in pixel order whatever
    /// the ranges: the result does not depend on the thread count.
    fn splat(&self, input: SplatInput<'_>, vals: &mut [f32]) {
        let nc = input.channels;
        let mut parts = Vec::with_capacity(self.splat_ranges.len());
        let mut rest: &mut [f32] = vals;
        for &(v0, v1, p0, p1) in &self.splat_ranges {
            let (part, r) = std::mem::take(&mut rest).split_at_mut((v1 - v0) * nc);
            rest = r;
            parts.push((v0, p0..p1, part));
        }
        parts.into_par_iter().for_each(|(v0, pixels, acc)| {
            splat_scatter(self, &input, v0, pixels, acc);
        });
    }

    /// The last step of [`Lattice::filter`] for one pixel: `out = Σ_k w_k · vals[v_k]` (scaled by
    /// `OUTPUT_SCALE`), with `vals` from [`Lattice::splat_blur`] and `out.len()` channels.
    #[inline(always)]
    pub fn slice(&self, vals: &[f32], pixel: usize, out: &mut [f32]) {
        self.slice_channels(vals, pixel, out.len(), 0, out);
    }

    /// [`Lattice::slice`] for the channels `first..first + out.len()` of `channels` only.
    #[inline(always)]
    pub fn slice_channels(&self, vals: &[f32], pixel: usize, channels: usize, first: usize, out: &mut [f32]) {
        // One pass over the channels, the vertices added in their order from 0 (the same sums as accumulating
        // vertex by vertex into a zeroed output, without writing the output D1 + 1 times).
        let len = out.len();
        let ids = &self.pix_vertex[pixel * D1..][..D1];
        let ws = &self.pix_weight[pixel * D1..][..D1];
        let w: [f32; D1] = std::array::from_fn(|k| ws[k] * OUTPUT_SCALE);
        let [s0, s1, s2, s3, s4, s5]: [&[f32]; D1] =
            std::array::from_fn(|k| &vals[ids[k] as usize * channels + first..][..len]);
        for (d, o) in out.iter_mut().enumerate() {
            let acc = 0.0 + w[0] * s0[d];
            let acc = acc + w[1] * s1[d];
            let acc = acc + w[2] * s2[d];
            let acc = acc + w[3] * s3[d];
            let acc = acc + w[4] * s4[d];
            *o = acc + w[5] * s5[d];
        }
    }
}

/// `count` ranges of vertex ids, `(first, end, first pixel, end pixel)`, each with the pixels that contribute to
/// its vertices (all within `first pixel..end pixel`), found in one parallel pass over the pixels' vertices.
fn splat_ranges(pix_vertex: &[u32], nvert: usize, count: usize) -> Vec<(usize, usize, usize, usize)> {
    let count = count.clamp(1, nvert.max(1));
    let per_range = nvert.div_ceil(count).max(1);
    let count = nvert.div_ceil(per_range).max(1);
    const BLOCK: usize = 4096;
    let windows = pix_vertex
        .par_chunks(BLOCK * D1)
        .enumerate()
        .map(|(b, ids)| {
            let mut w = vec![(usize::MAX, 0usize); count];
            for (k, ids) in ids.chunks_exact(D1).enumerate() {
                let p = b * BLOCK + k;
                for &v in ids {
                    let (lo, hi) = &mut w[v as usize / per_range];
                    *lo = (*lo).min(p);
                    *hi = p + 1;
                }
            }
            w
        })
        .reduce(
            || vec![(usize::MAX, 0usize); count],
            |a, b| a.iter().zip(&b).map(|(&(a0, a1), &(b0, b1))| (a0.min(b0), a1.max(b1))).collect(),
        );
    windows
        .iter()
        .enumerate()
        .map(|(r, &(p0, p1))| (r * per_range, ((r + 1) * per_range).min(nvert), p0.min(p1), p1))
        .collect()
}

/// What a splat reads: `channels` values per pixel, each pixel's scaled by `pixel_scale[p]` when given, and only
/// those in the pixel's band when given.
#[derive(Clone, Copy)]
pub(crate) struct SplatInput<'a> {
    pub(crate) values: &'a [f32],
    pub(crate) pixel_scale: Option<&'a [f32]>,
    pub(crate) bands: Option<Bands<'a>>,
    pub(crate) channels: usize,
}

/// Each pixel's channels `ranges[p][0]..ranges[p][1]` (its other channels are 0): where the input holds them.
#[derive(Clone, Copy, Debug)]
pub struct Bands<'a> {
    /// `[lo, hi]` per pixel.
    pub ranges: &'a [[u32; 2]],
    /// `None`: pixel p's channel c at `p · channels + c` (every channel stored); `Some(offsets)`: only the band is
    /// stored, pixel p's channels `lo..hi` at `offsets[p]..offsets[p + 1]` (`num_pixels + 1` offsets).
    pub packed: Option<&'a [usize]>,
}

/// Splats into the vertices `first..first + acc.len() / nc` by scanning the pixels `pixels` (which include
/// every pixel contributing to them) in order and adding each one's value to those of its vertices in the range:
/// every vertex sums its contributions in pixel order. With `bands`, pixel p's values are read and added only in
/// its band (see [`Lattice::splat_blur`]). Compiled for AVX2 + FMA as well (same results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn splat_scatter<'s>(
    lat: &Lattice,
    splat: &SplatInput<'s>,
    first: usize,
    pixels: std::ops::Range<usize>,
    acc: &mut [f32],
) {
    let SplatInput { values: input, pixel_scale, bands, channels: nc } = *splat;
    acc.fill(0.0);
    let count = acc.len() / nc;
    for p in pixels {
        let ids = &lat.pix_vertex[p * D1..][..D1];
        let ws = &lat.pix_weight[p * D1..][..D1];
        let scale = pixel_scale.map_or(1.0, |s| s[p]);
        let [lo, hi] = bands.map_or([0, nc], |b| b.ranges[p].map(|v| v as usize));
        let src = match bands.and_then(|b| b.packed) {
            Some(offsets) => &input[offsets[p]..offsets[p + 1]],
            None => &input[p * nc + lo..][..hi - lo],
        };
        for (&v, &w) in ids.iter().zip(ws) {
            let local = (v as usize).wrapping_sub(first);
            if local < count {
                let w = w * scale;
                for (a, s) in acc[local * nc + lo..][..hi - lo].iter_mut().zip(src) {
                    *a += w * s;
                }
            }
        }
    }
}

/// Slices the pixels `first..` (one `nc`-channel row each in `out`). Compiled for AVX2 + FMA as well (same
/// results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn slice_pixels(lat: &Lattice, vals: &[f32], first: usize, out: &mut [f32], nc: usize) {
    for (p, out) in (first..).zip(out.chunks_exact_mut(nc)) {
        lat.slice(vals, p, out);
    }
}

/// One blur pass for the vertices `first..`: `dst = own + ½(down + up)` from `src`, a missing neighbour reading
/// `zero`. Compiled for AVX2 + FMA as well (same results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn blur_vertices(src: &[f32], zero: &[f32], first: usize, nbrs: &[[u32; 2]], dst: &mut [f32], nc: usize) {
    for ((v, dst), &[down, up]) in (first..).zip(dst.chunks_exact_mut(nc)).zip(nbrs) {
        let own = &src[v * nc..][..nc];
        let lo = if down == NONE { zero } else { &src[down as usize * nc..][..nc] };
        let hi = if up == NONE { zero } else { &src[up as usize * nc..][..nc] };
        for (((d, &o), &l), &h) in dst.iter_mut().zip(own).zip(lo).zip(hi) {
            *d = o + 0.5 * (l + h);
        }
    }
}

/// The blur's response B(m) between two vertices of one simplex m lattice steps apart (see
/// [`Lattice::self_weight`]).
fn blur_response() -> [f32; D1] {
    std::array::from_fn(|m| match m {
        0 => 1.0 + 2.0 * 0.5f32.powi(D1 as i32),
        _ => 0.5f32.powi(m as i32) + 0.5f32.powi((D1 - m) as i32),
    })
}

/// Self-weight Σ_{k,k'} w_k w_k' B(|k − k'|) of one pixel (see [`Lattice::self_weight`]).
fn self_weight_of(w: &[f32; D1], b: &[f32; D1]) -> f32 {
    let mut s = 0.0;
    for k in 0..D1 {
        for k2 in 0..D1 {
            s += w[k] * w[k2] * b[k.abs_diff(k2)];
        }
    }
    s
}

/// [`self_weight_of`] × [`OUTPUT_SCALE`] for the pixels whose weights are `weights` (`D1` each), `LANES` pixels
/// at a time: the same operations in the same order per lane, so the same results, vectorised. Compiled for
/// AVX2 + FMA as well (same results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn self_weights(weights: &[f32], out: &mut [f32]) {
    let b = blur_response();
    let mut groups = weights.chunks_exact(D1 * LANES);
    for (w, out) in (&mut groups).zip(out.chunks_exact_mut(LANES)) {
        let w: [[f32; LANES]; D1] = std::array::from_fn(|k| std::array::from_fn(|l| w[l * D1 + k]));
        let mut s = [0.0f32; LANES];
        for k in 0..D1 {
            for k2 in 0..D1 {
                let bk = b[k.abs_diff(k2)];
                for (s, (&wk, &wk2)) in s.iter_mut().zip(w[k].iter().zip(&w[k2])) {
                    *s += wk * wk2 * bk;
                }
            }
        }
        for (o, s) in out.iter_mut().zip(s) {
            *o = s * OUTPUT_SCALE;
        }
    }
    let done = out.len() / LANES * LANES;
    for (w, o) in groups.remainder().chunks_exact(D1).zip(&mut out[done..]) {
        *o = self_weight_of(w.try_into().expect("D1 weights"), &b) * OUTPUT_SCALE;
    }
}

#[cfg(test)]
mod tests;
