//! Permutohedral-lattice bilateral filter (Adams, Baek & Davis, Eurographics 2010), the fast message passing of
//! the fully connected term (paper §3, SPEC §3).
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
//! implied by the zero sum; see `Key`); the largest coordinate is ~724 at quarter resolution (SPEC §6), far
//! from the limit.
//!
//! The splat, slice, blur, self-weight and embedding kernels are compiled for AVX2 + FMA as well and picked at run
//! time, with the same results; the `force-baseline` feature leaves only the baseline versions (see
//! [`crate::fastmath`], "SIMD in jem").

use rayon::prelude::*;

use crate::image::RgbImage;

/// Feature dimension: x, y, r, g, b.
pub const D: usize = 5;
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
pub const OUTPUT_SCALE: f32 = 1.0 / 0.5536;

/// The largest feature value (position/σxy or colour/σrgb) the lattice accepts: its 16-bit keys hold the
/// elevated coordinates, which are at most ~34.6 × the largest feature (2d · (d+1)·√(2/3)/√2 for d = 5), plus
/// d+1, so they stay within ±31 200 and a blur step (at most d+1) never leaves the 16-bit range.
pub const MAX_FEATURE: f32 = 900.0;

/// Whether an image of this size with these σ can be embedded (see [`MAX_FEATURE`]).
pub fn features_fit(width: usize, height: usize, sigma_xy: f32, sigma_rgb: f32) -> bool {
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

/// Per-pixel result of embedding a feature vector: the enclosing simplex (its remainder-0 vertex and the ranking
/// that orders the other vertices) and the barycentric weights.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Embedding {
    /// The simplex's remainder-0 vertex, all d+1 coordinates (they sum to zero).
    origin: [i32; D1],
    /// Rank of each coordinate's rounding residual (0 = largest … d = smallest).
    rank: [i32; D1],
    weights: [f32; D1],
}

impl Embedding {
    /// The key of the simplex vertex with remainder `rem`: the origin plus the canonical offset `rem` for the
    /// coordinates ranked within the first d+1−rem, `rem` − (d+1) for the others. The d+1-th coordinate is
    /// implied by the zero sum and left out.
    #[inline(always)]
    fn key(&self, rem: usize) -> Key {
        Key::from_coords(std::array::from_fn(|i| {
            let offset = if self.rank[i] as usize <= D - rem { rem as i32 } else { rem as i32 - D1 as i32 };
            self.origin[i] + offset
        }))
    }

    /// All d+1 vertex keys, by remainder.
    #[cfg(test)]
    fn keys(&self) -> [Key; D1] {
        std::array::from_fn(|rem| self.key(rem))
    }
}

impl Lattice {
    /// Builds the lattice for an image's (x/σxy, y/σxy, r/σrgb, g/σrgb, b/σrgb) features.
    ///
    /// # Panics
    /// If a σ is not positive, or the features exceed [`MAX_FEATURE`] (check with [`features_fit`]; e.g. more
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

    /// k̃(i, i): the weight the filter gives a pixel's own input, already scaled by [`OUTPUT_SCALE`].
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
        let vals = self.splat_blur(input, None, nc, scratch);
        const CHUNK: usize = 256;
        output.par_chunks_mut(nc.max(1) * CHUNK).enumerate().for_each(|(k, out)| {
            slice_pixels(self, vals, k * CHUNK, out, nc.max(1));
        });
    }

    /// The first two steps of [`Lattice::filter`]: splats `input` (each pixel's values multiplied by
    /// `pixel_scale[p]` if given) and blurs; returns the vertex values (`num_vertices × channels`), to be read
    /// per pixel with [`Lattice::slice`]. Lets a caller fuse slicing into its own per-pixel loop.
    ///
    /// # Panics
    /// If `input` does not have `num_pixels × channels` elements or `pixel_scale` not `num_pixels`.
    pub fn splat_blur<'s>(
        &self,
        input: &[f32],
        pixel_scale: Option<&[f32]>,
        channels: usize,
        scratch: &'s mut LatticeScratch,
    ) -> &'s [f32] {
        let nc = channels;
        assert_eq!(input.len(), self.npix * nc, "lattice filter input has the wrong size");
        if let Some(s) = pixel_scale {
            assert_eq!(s.len(), self.npix, "lattice pixel scale has the wrong size");
        }
        let len = self.nvert * nc;
        scratch.a.resize(len, 0.0);
        scratch.b.resize(len, 0.0);
        scratch.zero.resize(nc, 0.0);
        if nc == 0 || self.npix == 0 {
            return &scratch.a;
        }
        let LatticeScratch { a, b, zero } = scratch;
        let zero: &[f32] = zero;
        let (mut cur, mut next) = (a, b);

        self.splat(input, pixel_scale, nc, cur);
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
    fn splat(&self, input: &[f32], pixel_scale: Option<&[f32]>, nc: usize, vals: &mut [f32]) {
        let mut parts = Vec::with_capacity(self.splat_ranges.len());
        let mut rest: &mut [f32] = vals;
        for &(v0, v1, p0, p1) in &self.splat_ranges {
            let (part, r) = std::mem::take(&mut rest).split_at_mut((v1 - v0) * nc);
            rest = r;
            parts.push((v0, p0..p1, part));
        }
        parts.into_par_iter().for_each(|(v0, pixels, acc)| {
            splat_scatter(self, input, pixel_scale, v0, pixels, acc, nc);
        });
    }

    /// The last step of [`Lattice::filter`] for one pixel: `out = Σ_k w_k · vals[v_k]` (scaled by
    /// [`OUTPUT_SCALE`]), with `vals` from [`Lattice::splat_blur`] and `out.len()` channels.
    #[inline(always)]
    pub fn slice(&self, vals: &[f32], pixel: usize, out: &mut [f32]) {
        let nc = out.len();
        let ids = &self.pix_vertex[pixel * D1..][..D1];
        let ws = &self.pix_weight[pixel * D1..][..D1];
        let w: [f32; D1] = std::array::from_fn(|k| ws[k] * OUTPUT_SCALE);
        let [s0, s1, s2, s3, s4, s5]: [&[f32]; D1] = std::array::from_fn(|k| &vals[ids[k] as usize * nc..][..nc]);
        // One pass over the labels, the vertices added in their order from 0 (the same sums as accumulating
        // vertex by vertex into a zeroed output, without writing the output D1 + 1 times).
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

/// Splats into the vertices `first..first + acc.len() / nc` by scanning the pixels `pixels` (which include
/// every pixel contributing to them) in order and adding each one's value to those of its vertices in the range:
/// every vertex sums its contributions in pixel order. Compiled for AVX2 + FMA as well (same results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn splat_scatter(
    lat: &Lattice,
    input: &[f32],
    pixel_scale: Option<&[f32]>,
    first: usize,
    pixels: std::ops::Range<usize>,
    acc: &mut [f32],
    nc: usize,
) {
    acc.fill(0.0);
    let count = acc.len() / nc;
    for p in pixels {
        let ids = &lat.pix_vertex[p * D1..][..D1];
        let ws = &lat.pix_weight[p * D1..][..D1];
        let scale = pixel_scale.map_or(1.0, |s| s[p]);
        let src = &input[p * nc..][..nc];
        for (&v, &w) in ids.iter().zip(ws) {
            let local = (v as usize).wrapping_sub(first);
            if local < count {
                let w = w * scale;
                for (a, s) in acc[local * nc..][..nc].iter_mut().zip(src) {
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

/// The per-axis elevation scales √(2/3)·(d+1)/√(i(i+1)) for features i = 1..=d (index i − 1).
fn elevation_scales() -> [f32; D] {
    std::array::from_fn(|k| {
        let i = k + 1;
        (D1 as f32) * (2.0f32 / 3.0).sqrt() / ((i * (i + 1)) as f32).sqrt()
    })
}

/// Embeds a feature vector in the permutohedral lattice: the enclosing simplex and barycentric weights.
///
/// The feature is scaled (`scales` from [`elevation_scales`]) so that the lattice blur has unit standard
/// deviation per feature unit, lifted onto the hyperplane Σ x = 0 of R^(d+1), rounded to the nearest
/// remainder-0 lattice point, and the simplex is read off the ranking of the rounding residuals (Adams et al.
/// 2010, §3.1). The scalar reference for [`embed_lanes`], which the build uses.
#[cfg(test)]
fn embed(f: &[f32; D], scales: &[f32; D]) -> Embedding {
    // Elevation onto the hyperplane (E matrix).
    let mut elevated = [0.0f32; D1];
    let mut sum = 0.0f32;
    for i in (1..=D).rev() {
        let cf = f[i - 1] * scales[i - 1];
        elevated[i] = sum - i as f32 * cf;
        sum += cf;
    }
    elevated[0] = sum;

    // Nearest remainder-0 point, and the ranking of the residuals.
    let d1 = D1 as f32;
    let mut greedy = [0i32; D1];
    let mut total = 0i32;
    for i in 0..D1 {
        let v = elevated[i] / d1;
        let up = v.ceil() * d1;
        let down = v.floor() * d1;
        greedy[i] = if up - elevated[i] < elevated[i] - down { up as i32 } else { down as i32 };
        total += greedy[i];
    }
    let total = total / D1 as i32;
    let mut rank = [0i32; D1];
    for i in 0..D {
        for j in i + 1..D1 {
            if (elevated[i] - greedy[i] as f32) < (elevated[j] - greedy[j] as f32) {
                rank[i] += 1;
            } else {
                rank[j] += 1;
            }
        }
    }
    // Fix the point so its coordinates sum to zero.
    if total > 0 {
        for i in 0..D1 {
            if rank[i] >= D1 as i32 - total {
                greedy[i] -= D1 as i32;
                rank[i] += total - D1 as i32;
            } else {
                rank[i] += total;
            }
        }
    } else if total < 0 {
        for i in 0..D1 {
            if rank[i] < -total {
                greedy[i] += D1 as i32;
                rank[i] += D1 as i32 + total;
            } else {
                rank[i] += total;
            }
        }
    }

    // Barycentric weights from the sorted residuals.
    let mut bary = [0.0f32; D1 + 1];
    for i in 0..D1 {
        let delta = (elevated[i] - greedy[i] as f32) / d1;
        let r = rank[i] as usize;
        bary[D - r] += delta;
        bary[D1 - r] -= delta;
    }
    bary[0] += 1.0 + bary[D1];
    let mut weights = [0.0f32; D1];
    weights.copy_from_slice(&bary[..D1]);
    Embedding { origin: greedy, rank, weights }
}

/// Pixels embedded at once by [`embed_lanes`]: one AVX2 register of `f32`.
const LANES: usize = 8;

/// [`embed`] for `LANES` feature vectors at once (`f[feature][lane]`), written lane by lane so that it
/// vectorises; every lane performs exactly [`embed`]'s floating-point operations, so the results are
/// bit-identical (tested).
#[inline(always)]
fn embed_lanes(f: &[[f32; LANES]; D], scales: &[f32; D]) -> [Embedding; LANES] {
    let mut elevated = [[0.0f32; LANES]; D1];
    let mut sum = [0.0f32; LANES];
    for i in (1..=D).rev() {
        for l in 0..LANES {
            let cf = f[i - 1][l] * scales[i - 1];
            elevated[i][l] = sum[l] - i as f32 * cf;
            sum[l] += cf;
        }
    }
    elevated[0] = sum;

    // The nearest remainder-0 point, kept in f32 (its coordinates are integers far below 2²⁴, so exact), and
    // its coordinate sum over d+1 (exact as well: a sum of multiples of d+1).
    let d1 = D1 as f32;
    let mut greedy = [[0.0f32; LANES]; D1];
    let mut total = [0.0f32; LANES];
    for i in 0..D1 {
        for l in 0..LANES {
            let e = elevated[i][l];
            let v = e / d1;
            let up = v.ceil() * d1;
            let down = v.floor() * d1;
            greedy[i][l] = if up - e < e - down { up } else { down };
            total[l] += greedy[i][l];
        }
    }
    let total: [i32; LANES] = std::array::from_fn(|l| (total[l] / d1) as i32);
    let mut rank = [[0i32; LANES]; D1];
    for i in 0..D {
        for j in i + 1..D1 {
            for l in 0..LANES {
                let below = (elevated[i][l] - greedy[i][l]) < (elevated[j][l] - greedy[j][l]);
                rank[i][l] += i32::from(below);
                rank[j][l] += i32::from(!below);
            }
        }
    }
    // Fix the point so its coordinates sum to zero (no change where the total is already 0).
    let n = D1 as i32;
    for i in 0..D1 {
        for l in 0..LANES {
            let (t, r) = (total[l], rank[i][l]);
            let (dg, dr) = if t > 0 {
                if r >= n - t { (-d1, t - n) } else { (0.0, t) }
            } else if r < -t {
                (d1, n + t)
            } else {
                (0.0, t)
            };
            greedy[i][l] += dg;
            rank[i][l] += dr;
        }
    }

    // Barycentric weights: the same additions into the same slots, in the same order, as `embed`.
    let mut bary = [[0.0f32; LANES]; D1 + 1];
    for i in 0..D1 {
        for l in 0..LANES {
            let delta = (elevated[i][l] - greedy[i][l]) / d1;
            let r = rank[i][l];
            for (k, b) in bary.iter_mut().enumerate() {
                let k = k as i32;
                let v = b[l];
                b[l] = if k == D as i32 - r { v + delta } else { v };
                let v = b[l];
                b[l] = if k == n - r { v - delta } else { v };
            }
        }
    }
    std::array::from_fn(|l| Embedding {
        origin: std::array::from_fn(|i| greedy[i][l] as i32),
        rank: std::array::from_fn(|i| rank[i][l]),
        weights: std::array::from_fn(|k| if k == 0 { bary[0][l] + (1.0 + bary[D1][l]) } else { bary[k][l] }),
    })
}

/// Where [`number_block`] gets each pixel's embedding from.
#[derive(Clone, Copy)]
enum Features<'a> {
    /// Embedded on the fly from an image, features (x·s_xy, y·s_xy, r·s_rgb, g·s_rgb, b·s_rgb), `scales` =
    /// [s_xy, s_rgb]; `elevation` from [`elevation_scales`].
    Image { image: &'a RgbImage, scales: [f32; 2], elevation: [f32; D] },
    /// Already embedded (tests).
    #[cfg(test)]
    Embedded(&'a [Embedding]),
}

impl Features<'_> {
    fn len(&self) -> usize {
        match self {
            Features::Image { image, .. } => image.len(),
            #[cfg(test)]
            Features::Embedded(e) => e.len(),
        }
    }

    /// The embeddings of the pixels `first..first + n` (n ≤ `LANES`; lanes past n repeat the last pixel).
    #[inline(always)]
    fn lanes_at(&self, first: usize, n: usize) -> [Embedding; LANES] {
        let pixel = |l: usize| first + l.min(n - 1);
        match self {
            Features::Image { image, scales: [sxy, srgb], elevation } => {
                let w = image.width;
                let (mut x, mut y) = (first % w, first / w);
                let mut px = [[0.0f32; D]; LANES];
                for (l, px) in px.iter_mut().enumerate() {
                    let [r, g, b] = image.rgb(pixel(l));
                    *px = [x as f32 * sxy, y as f32 * sxy, r * srgb, g * srgb, b * srgb];
                    if l + 1 < n {
                        x += 1;
                        if x == w {
                            (x, y) = (0, y + 1);
                        }
                    }
                }
                let f = std::array::from_fn(|k| std::array::from_fn(|l| px[l][k]));
                embed_lanes(&f, elevation)
            }
            #[cfg(test)]
            Features::Embedded(e) => std::array::from_fn(|l| e[pixel(l)]),
        }
    }
}

/// Ids, weights and keys of the simplex vertices of all pixels, numbered by first appearance in raster order:
/// per-entry ids and barycentric weights (`[pixel·D1 + k]`), the keys in id order, and the table from key to
/// id.
///
/// Blocks of pixels are embedded and numbered in parallel, each with its own table, and the blocks' keys are
/// then merged in block order into one table; a key's global id is thus its first appearance in the whole
/// raster, exactly as in one sequential pass, whatever the number of blocks or threads.
fn assign_vertex_ids(features: Features<'_>) -> (Vec<u32>, Vec<f32>, KeyTable) {
    let block = features.len().div_ceil(rayon::current_num_threads().max(1)).max(16_384);
    assign_vertex_ids_in_blocks(features, block)
}

/// [`assign_vertex_ids`] with a given block size in pixels.
fn assign_vertex_ids_in_blocks(features: Features<'_>, block: usize) -> (Vec<u32>, Vec<f32>, KeyTable) {
    let npix = features.len();
    let block = block.max(1);
    let mut pix_vertex = vec![0u32; npix * D1];
    let mut pix_weight = vec![0.0f32; npix * D1];
    // Per block: local ids into pix_vertex, and the block's table of keys in local id order. The first block's
    // table becomes the global one (its ids already are global), so it gets room for the whole image (about 0.4
    // vertices per pixel on natural images; a table grows if there are more).
    let mut tables: Vec<KeyTable> = pix_vertex
        .par_chunks_mut(block * D1)
        .zip(pix_weight.par_chunks_mut(block * D1))
        .enumerate()
        .map(|(b, (ids, weights))| {
            let expected = if b == 0 { npix } else { ids.len() / D1 } / 2;
            number_block(features, b * block, ids, weights, expected, npix * D1)
        })
        .collect();
    if tables.is_empty() {
        return (pix_vertex, pix_weight, KeyTable::with_capacity(0, 0));
    }
    let rest = tables.split_off(1);
    let mut table = tables.pop().expect("the first block's table");
    let maps: Vec<Vec<u32>> = rest.iter().map(|t| t.keys.iter().map(|key| table.insert(key)).collect()).collect();
    pix_vertex.par_chunks_mut(block * D1).skip(1).zip(maps.par_iter()).for_each(|(ids, map)| {
        ids.iter_mut().for_each(|id| *id = map[*id as usize]);
    });
    (pix_vertex, pix_weight, table)
}

/// Embeds the pixels `first..` (as many as `ids` has room for) and numbers their vertices by first appearance
/// (ids into `ids`, barycentric weights into `weights`), returning the block's table (sized for `expected`
/// keys, it grows if there are more; ids below `max_keys`, the whole image's bound, as it may become the global
/// table), its keys in id order. Compiled for
/// AVX2 + FMA as well, where the embedding's rounding is one instruction instead of a libm call (same results).
#[cfg_attr(not(feature = "force-baseline"), multiversion::multiversion(targets("x86_64+avx2+fma")))]
fn number_block<'f>(
    features: Features<'f>,
    first: usize,
    ids: &mut [u32],
    weights: &mut [f32],
    expected: usize,
    max_keys: usize,
) -> KeyTable {
    let mut table = KeyTable::with_capacity(expected, max_keys);
    // Horizontally adjacent pixels often lie in the same simplex (then they share all ids) and otherwise share
    // some of its vertices: a vertex can only equal the previous pixel's vertex of the same remainder, so
    // compare with that one (one comparison) and probe the table only on a miss. Same ids as probing every key.
    let mut prev: Option<(Embedding, [Key; D1], [u32; D1])> = None;
    let npix = ids.len() / D1;
    let mut batch = [Embedding::default(); LANES];
    for (k, (ids, wts)) in ids.chunks_exact_mut(D1).zip(weights.chunks_exact_mut(D1)).enumerate() {
        if k % LANES == 0 {
            batch = features.lanes_at(first + k, (npix - k).min(LANES));
        }
        let e = batch[k % LANES];
        wts.copy_from_slice(&e.weights);
        if let Some((pe, pkeys, pids)) = &mut prev {
            if pe.origin == e.origin && pe.rank == e.rank {
                ids.copy_from_slice(pids);
                continue;
            }
            for (rem, (id, (pkey, pid))) in ids.iter_mut().zip(pkeys.iter_mut().zip(pids.iter_mut())).enumerate() {
                let key = e.key(rem);
                if key != *pkey {
                    *pkey = key;
                    *pid = table.insert(&key);
                }
                *id = *pid;
            }
            *pe = e;
        } else {
            let keys: [Key; D1] = std::array::from_fn(|rem| e.key(rem));
            for (id, key) in ids.iter_mut().zip(&keys) {
                *id = table.insert(key);
            }
            let mut own = [0u32; D1];
            own.copy_from_slice(ids);
            prev = Some((e, keys, own));
        }
    }
    table
}

/// A lattice vertex: its first d coordinates (the d+1-th is minus their sum), each stored biased by 2¹⁵ in a
/// 16-bit lane, lanes 0–3 in `lo` and lane 4 in `hi`. Built and compared in registers; the bias keeps every lane
/// away from wrapping, so a blur step is one add per word (see [`MAX_FEATURE`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C, packed)]
struct Key {
    lo: u64,
    hi: u16,
}

const KEY_BIAS: i32 = 1 << 15;

impl Key {
    /// The key of lattice coordinates `c` (the first d).
    ///
    /// # Panics
    /// If a coordinate does not fit 16 bits (prevented by [`features_fit`]).
    #[inline(always)]
    fn from_coords(c: [i32; D]) -> Key {
        let lane = |v: i32| u16::try_from(v + KEY_BIAS).expect("lattice coordinate overflows 16 bits");
        let lo = (0..4).fold(0u64, |lo, i| lo | u64::from(lane(c[i])) << (16 * i));
        Key { lo, hi: lane(c[4]) }
    }

    /// The lattice coordinates.
    #[cfg(test)]
    fn coords(&self) -> [i32; D] {
        let Key { lo, hi } = *self;
        std::array::from_fn(|i| if i < 4 { (lo >> (16 * i)) as u16 } else { hi } as i32 - KEY_BIAS)
    }

    /// The neighbour one blur step along lattice direction `dir` (0..=d), up or down: ±((1, …, 1) − (d+1)·e_dir)
    /// (for dir = d the moved coordinate is the implied one, so only the all-ones part shows).
    #[inline(always)]
    fn step(&self, dir: usize, up: bool) -> Key {
        let Key { lo, hi } = *self;
        let moved = |c: usize| {
            let lane = if c < 4 { (lo >> (16 * c)) as u16 } else { hi };
            let offset = 1 - if c == dir { D1 as i16 } else { 0 };
            lane.wrapping_add((if up { offset } else { -offset }) as u16)
        };
        Key { lo: (0..4).fold(0u64, |w, c| w | u64::from(moved(c)) << (16 * c)), hi: moved(4) }
    }
}

/// Open-addressing hash table from lattice keys to vertex ids, numbering new keys in insertion order (linear
/// probing, power-of-two capacity). A slot is 4 bytes: the id in the low bits (as many as the largest possible
/// id needs) and the top bits of the key's hash above it, so the table stays small enough for the L2 cache and a
/// probe reads the stored key (`keys[id]`, usually cached: ids follow the raster) only when those bits match.
struct KeyTable {
    /// `hash_bits | id`, or `EMPTY`.
    slots: Vec<u32>,
    /// The keys in id order.
    keys: Vec<Key>,
    mask: usize,
    /// Selects the id bits of a slot; the rest hold hash bits. Ids stay below it, so a slot is never `EMPTY`.
    id_mask: u32,
}

const EMPTY: u32 = u32::MAX;

impl KeyTable {
    /// A table with room for `n` keys that will never hold more than `max_keys`.
    ///
    /// # Panics
    /// If `max_keys` ≥ 2³¹.
    fn with_capacity(n: usize, max_keys: usize) -> Self {
        assert!(max_keys < 1 << 31, "too many lattice vertices for 32-bit ids");
        let id_bits = usize::BITS - max_keys.leading_zeros();
        let cap = (n + n / 3 + 1).next_power_of_two().max(16);
        KeyTable { slots: vec![EMPTY; cap], keys: Vec::with_capacity(n), mask: cap - 1, id_mask: (1 << id_bits) - 1 }
    }

    /// Number of keys.
    fn len(&self) -> usize {
        self.keys.len()
    }

    /// The slot of key id `id` with hash `h`.
    #[inline]
    fn slot(&self, h: u64, id: usize) -> u32 {
        (h >> 32) as u32 & !self.id_mask | id as u32
    }

    /// Rehashes into a table twice the size (ids are kept, so vertex numbering does not change).
    fn grow(&mut self) {
        let cap = self.slots.len() * 2;
        self.slots = vec![EMPTY; cap];
        self.mask = cap - 1;
        for (id, key) in self.keys.iter().enumerate() {
            let h = Self::hash(key);
            let mut s = h as usize & self.mask;
            while self.slots[s] != EMPTY {
                s = (s + 1) & self.mask;
            }
            self.slots[s] = self.slot(h, id);
        }
    }

    #[inline]
    fn hash(key: &Key) -> u64 {
        let Key { lo, hi } = *key;
        let h = (lo ^ u64::from(hi).rotate_right(23)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let h = (h ^ (h >> 32)).wrapping_mul(0xD6E8_FEB8_6659_FD93);
        h ^ (h >> 32)
    }

    /// Whether `slot` holds `key` (whose hash is `h`); the key itself is read only when the hash bits match.
    #[inline]
    fn holds(&self, slot: u32, h: u64, key: &Key) -> bool {
        slot != EMPTY
            && (slot ^ (h >> 32) as u32) & !self.id_mask == 0
            && self.keys[(slot & self.id_mask) as usize] == *key
    }

    /// Linear probing from hash `h`: the slot index holding `key`, or the empty slot where it would go.
    #[inline]
    fn probe(&self, h: u64, key: &Key) -> usize {
        let mut s = h as usize & self.mask;
        while self.slots[s] != EMPTY && !self.holds(self.slots[s], h, key) {
            s = (s + 1) & self.mask;
        }
        s
    }

    /// The id of `key`, inserting it with the next id (the number of keys so far) if absent. Doubles the
    /// table when it would become more than 3/4 full, so probing always ends (images with very noisy colours
    /// have up to d+1 distinct vertices per pixel).
    fn insert(&mut self, key: &Key) -> u32 {
        if 4 * (self.keys.len() + 1) > 3 * self.slots.len() {
            self.grow();
        }
        let h = Self::hash(key);
        let s = self.probe(h, key);
        if self.slots[s] == EMPTY {
            let id = self.keys.len();
            self.slots[s] = self.slot(h, id);
            self.keys.push(*key);
        }
        self.slots[s] & self.id_mask
    }

    /// [`KeyTable::get`] for many keys: the first slot of every key is loaded in a branch-free loop before any
    /// is examined, so the cache misses overlap instead of waiting on each other.
    fn get_many(&self, keys: &[Key], ids: &mut [u32]) {
        const MAX: usize = 128;
        for (keys, ids) in keys.chunks(MAX).zip(ids.chunks_mut(MAX)) {
            let mut hashes = [0u64; MAX];
            let mut first = [0u32; MAX];
            for ((h, f), key) in hashes.iter_mut().zip(first.iter_mut()).zip(keys) {
                *h = Self::hash(key);
                *f = self.slots[*h as usize & self.mask];
            }
            for (((id, key), &h), &f) in ids.iter_mut().zip(keys).zip(&hashes).zip(&first) {
                *id = match f {
                    EMPTY => NONE,
                    _ if self.holds(f, h, key) => f & self.id_mask,
                    _ => self.get(key),
                };
            }
        }
    }

    /// The id of `key`, or `NONE`.
    fn get(&self, key: &Key) -> u32 {
        let slot = self.slots[self.probe(Self::hash(key), key)];
        if slot == EMPTY { NONE } else { slot & self.id_mask }
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // index loops read best in reference implementations
mod tests {
    use super::*;
    use crate::test_util::rand_vec;

    /// A piecewise-constant colour image with a few regions plus mild noise: the kind of structure the
    /// bilateral kernel is meant for.
    fn test_image(w: usize, h: usize, seed: u64) -> RgbImage {
        let noise = rand_vec(w * h * 3, seed);
        let mut img = RgbImage::new(w, h);
        let palette = [[200.0, 40.0, 40.0], [30.0, 160.0, 60.0], [90.0, 90.0, 220.0], [240.0, 230.0, 120.0]];
        for y in 0..h {
            for x in 0..w {
                let region = usize::from(x * 3 > w) + 2 * usize::from(y * 2 > h + x / 3);
                for c in 0..3 {
                    img.channels[c][y * w + x] = palette[region][c] + 30.0 * (noise[(y * w + x) * 3 + c] - 0.5);
                }
            }
        }
        img
    }

    /// Dense O(N²) reference: Σ_j k(i, j) in_j, including j = i.
    fn brute_force(img: &RgbImage, input: &[f32], nc: usize, sxy: f32, srgb: f32) -> Vec<f32> {
        let (w, n) = (img.width, img.len());
        let mut out = vec![0.0f32; n * nc];
        for i in 0..n {
            let (xi, yi, fi) = ((i % w) as f32, (i / w) as f32, img.rgb(i));
            for j in 0..n {
                let (xj, yj, fj) = ((j % w) as f32, (j / w) as f32, img.rgb(j));
                let dp = ((xi - xj).powi(2) + (yi - yj).powi(2)) / (2.0 * sxy * sxy);
                let df = fi.iter().zip(&fj).map(|(a, b)| (a - b).powi(2)).sum::<f32>() / (2.0 * srgb * srgb);
                let k = (-dp - df).exp();
                for c in 0..nc {
                    out[i * nc + c] += k * input[j * nc + c];
                }
            }
        }
        out
    }

    fn filtered(lat: &Lattice, input: &[f32], nc: usize) -> Vec<f32> {
        let mut out = vec![0.0; input.len()];
        lat.filter(input, &mut out, nc, &mut LatticeScratch::default());
        out
    }

    /// The lattice against the dense Gaussian on a small piecewise-constant colour image with noise.
    ///
    /// Tolerance: the permutohedral lattice replaces the Gaussian by a piecewise-linear kernel of the same mass
    /// but a slightly different shape (wider shoulders, lower peak) whose exact values depend on where a pixel
    /// falls in its simplex; Adams et al. report errors of several percent. We require a relative L2 error below
    /// 12% over the image (measured: 8.7%) and every pixel within 35% of the reference.
    #[test]
    fn lattice_matches_brute_force_gaussian() {
        let img = test_image(40, 32, 3);
        let nc = 3;
        let input = rand_vec(img.len() * nc, 9);
        let lat = Lattice::build(&img, 5.0, 55.0);
        let out = filtered(&lat, &input, nc);
        let reference = brute_force(&img, &input, nc, 5.0, 55.0);
        let (mut err2, mut ref2, mut worst) = (0.0f64, 0.0f64, 0.0f64);
        for (a, b) in out.iter().zip(&reference) {
            err2 += f64::from(a - b).powi(2);
            ref2 += f64::from(*b).powi(2);
            worst = worst.max(f64::from((a - b).abs() / b));
        }
        let rel = (err2 / ref2).sqrt();
        eprintln!("lattice vs brute force: relative L2 error {rel:.4}, worst pixel {worst:.4}");
        assert!(rel < 0.12, "relative L2 error {rel}");
        assert!(worst < 0.35, "worst pixel relative error {worst}");
    }

    #[test]
    fn lattice_output_scale_matches_mass() {
        let (w, h) = (160, 160);
        let uni = RgbImage { width: w, height: h, channels: [vec![100.0; w * h], vec![50.0; w * h], vec![0.0; w * h]] };
        let lat = Lattice::build(&uni, 5.0, 55.0);
        let out = filtered(&lat, &vec![1.0; w * h], 1);
        let interior: Vec<f32> =
            (50..110).flat_map(|y| (50..110).map(move |x| (x, y))).map(|(x, y)| out[y * w + x]).collect();
        let mean = interior.iter().map(|&v| f64::from(v)).sum::<f64>() / interior.len() as f64;
        let mass = 2.0 * std::f64::consts::PI * 25.0;
        assert!((mean / mass - 1.0).abs() < 0.01, "interior mean {mean} vs Gaussian mass {mass}");
    }

    #[test]
    fn lattice_constant_input_stays_constant_under_normalisation() {
        let img = test_image(30, 20, 5);
        let lat = Lattice::build(&img, 5.0, 55.0);
        let n = img.len();
        let norm = filtered(&lat, &vec![1.0; n], 1);
        let mut input = vec![0.0; n * 2];
        for i in 0..n {
            input[2 * i] = 3.5;
            input[2 * i + 1] = -1.25;
        }
        let out = filtered(&lat, &input, 2);
        for i in 0..n {
            assert!((out[2 * i] / norm[i] - 3.5).abs() < 1e-4);
            assert!((out[2 * i + 1] / norm[i] + 1.25).abs() < 1e-4);
        }
    }

    #[test]
    fn lattice_is_identical_with_1_and_2_threads() {
        let img = test_image(50, 40, 11);
        let input = rand_vec(img.len() * 7, 2);
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let lat = Lattice::build(&img, 5.0, 55.0);
                (filtered(&lat, &input, 7), lat.self_weight().to_vec(), lat.num_vertices())
            })
        };
        let (a, b) = (run(1), run(2));
        assert_eq!(a.2, b.2);
        assert!(a.0.iter().zip(&b.0).all(|(x, y)| x.to_bits() == y.to_bits()));
        assert!(a.1.iter().zip(&b.1).all(|(x, y)| x.to_bits() == y.to_bits()));
    }

    /// The analytic self-weight against the filter's actual response to a unit impulse at that pixel. It is
    /// exact on the infinite lattice; on an image, missing intermediate vertices make the true value up to ~15%
    /// smaller, never larger.
    #[test]
    fn lattice_self_weight_matches_impulse_response() {
        let img = test_image(24, 20, 8);
        let lat = Lattice::build(&img, 5.0, 55.0);
        let n = img.len();
        for i in (0..n).step_by(37) {
            let mut delta = vec![0.0; n];
            delta[i] = 1.0;
            let actual = filtered(&lat, &delta, 1)[i];
            let predicted = lat.self_weight()[i];
            assert!(actual <= predicted * 1.0001 && actual >= predicted * 0.85, "pixel {i}: {actual} vs {predicted}");
        }
    }

    #[test]
    fn lattice_embedding_weights_form_a_partition_of_unity() {
        for f in [[0.0; D], [1.3, -2.2, 0.7, 4.1, 0.05], [100.0, 37.5, 2.0, 2.0, 2.0]] {
            let e = embed(&f, &elevation_scales());
            let sum: f32 = e.weights.iter().sum();
            assert!((sum - 1.0).abs() < 1e-5 && e.weights.iter().all(|&w| w >= -1e-6), "{f:?}: {:?}", e.weights);
            // The d+1 vertices are distinct lattice points whose coordinates have remainders 0..=d.
            // Vertex `rem` is a remainder-`rem` lattice point: every coordinate ≡ rem (mod d+1), including the
            // implied last one (minus the sum of the others).
            for (rem, key) in e.keys().iter().enumerate() {
                let coords = key.coords();
                let last = -coords.iter().sum::<i32>();
                for c in coords.into_iter().chain([last]) {
                    assert_eq!(c.rem_euclid(D1 as i32), rem as i32, "vertex {rem} of {f:?}");
                }
            }
        }
    }

    /// The eight-lane embedding against the scalar one, bit for bit, on random features of every magnitude the
    /// lattice accepts, integer-valued ones (ties in the rounding) and partial batches.
    #[test]
    fn lattice_embed_lanes_matches_scalar_embed() {
        let scales = elevation_scales();
        let noise = rand_vec(4096 * D, 12);
        for (b, chunk) in noise.chunks_exact(LANES * D).enumerate() {
            let magnitude = [1.0, 10.0, 100.0, MAX_FEATURE][b % 4];
            let mut f = [[0.0f32; LANES]; D];
            for (k, &u) in chunk.iter().enumerate() {
                let v = u * magnitude;
                f[k % D][k / D] = if b % 5 == 0 { v.round() } else { v };
            }
            let lanes = embed_lanes(&f, &scales);
            for l in 0..LANES {
                let e = embed(&std::array::from_fn(|k| f[k][l]), &scales);
                assert_eq!((e.origin, e.rank), (lanes[l].origin, lanes[l].rank), "batch {b} lane {l}");
                assert!(e.weights.iter().zip(&lanes[l].weights).all(|(a, b)| a.to_bits() == b.to_bits()));
            }
        }
    }

    /// The range-parallel splat against a plain per-vertex sum over the pixels in order, bit for bit, for several
    /// range counts (one range: a single sequential scan).
    #[test]
    fn lattice_splat_matches_per_vertex_sums() {
        let img = test_image(33, 21, 4);
        let nc = 3;
        let input = rand_vec(img.len() * nc, 5);
        let scale: Vec<f32> = rand_vec(img.len(), 6).iter().map(|s| 0.5 + s).collect();
        let mut lat = Lattice::build(&img, 3.0, 30.0);
        let nv = lat.num_vertices();
        let mut reference = vec![0.0f32; nv * nc];
        for p in 0..img.len() {
            for k in 0..D1 {
                let v = lat.pix_vertex[p * D1 + k] as usize;
                let w = lat.pix_weight[p * D1 + k] * scale[p];
                for c in 0..nc {
                    reference[v * nc + c] += w * input[p * nc + c];
                }
            }
        }
        for count in [1, 2, 5, 64] {
            lat.splat_ranges = splat_ranges(&lat.pix_vertex, nv, count);
            let mut vals = vec![0.0; nv * nc];
            lat.splat(&input, Some(&scale), nc, &mut vals);
            assert!(vals.iter().zip(&reference).all(|(a, b)| a.to_bits() == b.to_bits()), "{count} ranges");
        }
    }

    /// The blur neighbours (upper ones looked up, lower ones by inversion) against a direct lookup of both.
    #[test]
    fn lattice_blur_neighbours_match_direct_lookups() {
        let img = test_image(45, 31, 2);
        let lat = Lattice::build(&img, 3.0, 30.0);
        let features = Features::Image { image: &img, scales: [1.0 / 3.0, 1.0 / 30.0], elevation: elevation_scales() };
        let (_, _, table) = assign_vertex_ids(features);
        let nvert = lat.num_vertices();
        assert_eq!(table.len(), nvert);
        let mut found = 0;
        for dir in 0..D1 {
            for (v, key) in table.keys.iter().enumerate() {
                let expected = [table.get(&key.step(dir, false)), table.get(&key.step(dir, true))];
                assert_eq!(lat.blur_nbr[dir * nvert + v], expected, "vertex {v} direction {dir}");
                found += expected.iter().filter(|&&id| id != NONE).count();
            }
        }
        assert!(found > nvert, "too few neighbours for a meaningful test: {found}");
    }

    /// The vectorised self-weights against the scalar sum, bit for bit, with a partial group at the end.
    #[test]
    fn lattice_self_weights_match_scalar_sum() {
        let n = 8 * LANES + 5;
        let weights = rand_vec(n * D1, 21);
        let mut out = vec![0.0; n];
        self_weights(&weights, &mut out);
        for (w, o) in weights.chunks_exact(D1).zip(&out) {
            let expected = self_weight_of(w.try_into().unwrap(), &blur_response()) * OUTPUT_SCALE;
            assert_eq!(o.to_bits(), expected.to_bits());
        }
    }

    /// Packed keys against plain coordinate arithmetic: round trip, and a blur step in every direction, for
    /// coordinates of both signs up to the largest the features allow.
    #[test]
    fn lattice_keys_step_like_coordinates() {
        let big = (34.6 * MAX_FEATURE) as i32 + D1 as i32;
        for c in [[0, 0, 0, 0, 0], [1, -2, 3, -4, 5], [-big, big, -7, 0, big], [big, big, big, big, -big]] {
            let key = Key::from_coords(c);
            assert_eq!(key.coords(), c);
            for dir in 0..D1 {
                for up in [false, true] {
                    let sign = if up { 1 } else { -1 };
                    let expected: [i32; D] =
                        std::array::from_fn(|i| c[i] + sign * (1 - if i == dir { D1 as i32 } else { 0 }));
                    assert_eq!(key.step(dir, up).coords(), expected, "{c:?} dir {dir} up {up}");
                }
            }
        }
    }

    /// White-noise colours put nearly every pixel in its own simplex (up to d+1 new vertices per pixel).
    #[test]
    fn lattice_handles_noise_images() {
        let (w, h) = (40, 30);
        let noise = rand_vec(w * h * 3, 4);
        let mut img = RgbImage::new(w, h);
        for c in 0..3 {
            for i in 0..w * h {
                img.channels[c][i] = 255.0 * noise[i * 3 + c];
            }
        }
        let lat = Lattice::build(&img, 1.0, 5.0);
        assert!(lat.num_vertices() > 2 * w * h, "{} vertices", lat.num_vertices());
        let out = filtered(&lat, &vec![1.0; w * h], 1);
        assert!(out.iter().all(|v| v.is_finite() && *v > 0.0));
    }

    /// Block-parallel vertex numbering against one plain sequential pass over every key (a `HashMap` from key to
    /// id, first appearance in raster order), for block sizes from 1 pixel to the whole image.
    #[test]
    fn lattice_vertex_ids_match_sequential_numbering() {
        let (w, h) = (37, 23);
        let img = test_image(w, h, 6);
        let embeddings: Vec<Embedding> = (0..w * h)
            .map(|i| {
                let [r, g, b] = img.rgb(i);
                embed(&[(i % w) as f32 / 2.0, (i / w) as f32 / 2.0, r / 20.0, g / 20.0, b / 20.0], &elevation_scales())
            })
            .collect();
        // The reference numbers plain coordinates, independently of the packed keys and their hash.
        let mut ids_ref = Vec::new();
        let mut coords_ref: Vec<[i32; D]> = Vec::new();
        let mut seen = std::collections::HashMap::new();
        for e in &embeddings {
            for key in &e.keys() {
                let id = *seen.entry(key.coords()).or_insert_with(|| {
                    coords_ref.push(key.coords());
                    coords_ref.len() as u32 - 1
                });
                ids_ref.push(id);
            }
        }
        assert!(coords_ref.len() > 100, "too few vertices for a meaningful test: {}", coords_ref.len());
        for block in [1, 5, 37, 100, 851, w * h] {
            let (ids, weights, table) = assign_vertex_ids_in_blocks(Features::Embedded(&embeddings), block);
            let keys = &table.keys;
            assert_eq!(ids, ids_ref, "block {block}");
            assert!(weights.iter().eq(embeddings.iter().flat_map(|e| e.weights.iter())), "block {block}");
            assert!(keys.iter().map(Key::coords).eq(coords_ref.iter().copied()), "block {block}");
            for (id, key) in keys.iter().enumerate() {
                assert_eq!(table.get(key), id as u32);
            }
        }
    }

    #[test]
    fn lattice_handles_tiny_images() {
        for (w, h) in [(1, 1), (2, 1), (1, 3)] {
            let img = test_image(w, h, 1);
            let lat = Lattice::build(&img, 5.0, 55.0);
            let out = filtered(&lat, &vec![1.0; w * h], 1);
            assert!(out.iter().all(|v| v.is_finite() && *v > 0.0));
        }
    }
}
