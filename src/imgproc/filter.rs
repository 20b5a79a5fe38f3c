//! Neighbourhood filters on planes and images: replicated padding, the Sobel gradient (horizontal, magnitude), central
//! differences, a local mean of |v|, a separable Gaussian blur, and the minimum or maximum over a square window.
//! Borders are replicated everywhere.
//!
//! Three box means, which agree to float rounding but not bit for bit (the test
//! `the_box_means_agree_but_round_differently` holds both), each kept for the callers whose outputs were measured
//! with its rounding (merging two would change those outputs):
//! - [`box_mean`]: each window summed on its own, row by row, in `f32`; O(r²) a pixel, for the small windows of the
//!   temporal tests (r 1 to 3).
//! - [`local_mean_abs`]: the mean of |v|, row sums first and then sums of them, in `f32`; O(r) a pixel (the cost's
//!   gradient normalisation, the texture regions, the prior's lost pixels).
//! - [`box_mean_separable`]: running sums in `f64`; O(1) a pixel, for wide windows (the confidence's features, the
//!   sub-pixel normalisation).
//!
//! Likewise two 2×2-and-larger block means: [`box_reduce`] (each block's rows summed, then the row sums; the
//! temporal pyramids) and [`crate::scale::downsample_plane`] (each block's columns summed, then the column sums; the
//! pipeline's reduced resolutions).

use rayon::prelude::*;

use crate::image::{Plane, RgbImage};

/// The plane with `px` columns and `py` rows of replicated border on each side, row-major, width `w + 2·px`.
pub(crate) fn pad_replicate(p: &Plane<f32>, px: usize, py: usize) -> Vec<f32> {
    let (w, h) = p.dims();
    let pw = w + 2 * px;
    let mut out = vec![0.0f32; pw * (h + 2 * py)];
    for (py_i, row) in out.chunks_exact_mut(pw).enumerate() {
        let src = p.row(py_i.saturating_sub(py).min(h - 1));
        row[..px].fill(src[0]);
        row[px..px + w].copy_from_slice(src);
        row[px + w..].fill(src[w - 1]);
    }
    out
}

/// Horizontal Sobel gradient (`[-1 0 1; -2 0 2; -1 0 1]`), borders replicated.
pub(crate) fn sobel_x(grey: &Plane<f32>) -> Plane<f32> {
    sobel_map(grey, |gx, _| gx)
}

/// Sobel gradient magnitude √(gx² + gy²) (`[-1 0 1; -2 0 2; -1 0 1]` and its transpose), borders replicated.
#[cfg(feature = "toolkit")]
pub(crate) fn sobel_magnitude(grey: &Plane<f32>) -> Plane<f32> {
    sobel_map(grey, f32::hypot)
}

/// `f(gx, gy)` of each pixel's Sobel gradients ([`sobel_at`]), borders replicated.
fn sobel_map(grey: &Plane<f32>, f: impl Fn(f32, f32) -> f32 + Sync) -> Plane<f32> {
    let (w, h) = grey.dims();
    let mut out = Plane::new(w, h, 0.0f32);
    out.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
        let up = grey.row(y.saturating_sub(1));
        let mid = grey.row(y);
        let down = grey.row((y + 1).min(h - 1));
        for (x, g) in row.iter_mut().enumerate() {
            let (gx, gy) = sobel_at([up, mid, down], x);
            *g = f(gx, gy);
        }
    });
    out
}

/// The Sobel gradients (x, y) at column `x` of the middle of three rows (the rows above and below already replicated
/// at the image's border; columns replicated here).
fn sobel_at([up, mid, down]: [&[f32]; 3], x: usize) -> (f32, f32) {
    let (l, r) = (x.saturating_sub(1), (x + 1).min(mid.len() - 1));
    let gx = (up[r] - up[l]) + 2.0 * (mid[r] - mid[l]) + (down[r] - down[l]);
    let gy = (down[l] - up[l]) + 2.0 * (down[x] - up[x]) + (down[r] - up[r]);
    (gx, gy)
}

/// Horizontal and vertical central differences (one-sided at the borders).
pub(crate) fn central_differences(p: &Plane<f32>) -> (Plane<f32>, Plane<f32>) {
    let (w, h) = p.dims();
    let diff = |a: f32, b: f32, span: usize| (b - a) / span as f32;
    let mut gx = Plane::new(w, h, 0.0f32);
    let mut gy = Plane::new(w, h, 0.0f32);
    if w < 2 || h < 2 {
        return (gx, gy);
    }
    gx.data.par_chunks_mut(w).zip(gy.data.par_chunks_mut(w)).enumerate().for_each(|(y, (rx, ry))| {
        let row = p.row(y);
        for (x, g) in rx.iter_mut().enumerate() {
            let (l, r) = (x.saturating_sub(1), (x + 1).min(w - 1));
            *g = diff(row[l], row[r], r - l);
        }
        let (u, d) = (y.saturating_sub(1), (y + 1).min(h - 1));
        for ((g, &a), &b) in ry.iter_mut().zip(p.row(u)).zip(p.row(d)) {
            *g = diff(a, b, d - u);
        }
    });
    (gx, gy)
}

/// The mean of |v| over the (2r + 1)² window around each pixel, borders replicated: a row sum over dx = −r..r,
/// then the sum of those over dy = −r..r, each in that order, divided by (2r + 1)².
pub(crate) fn local_mean_abs(p: &Plane<f32>, r: usize) -> Plane<f32> {
    let (w, h) = p.dims();
    let mut rows = Plane::new(w, h, 0.0f32);
    rows.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, out)| {
        let src = p.row(y);
        for (x, o) in out.iter_mut().enumerate() {
            *o = (0..=2 * r).map(|k| src[(x + k).saturating_sub(r).min(w - 1)].abs()).fold(0.0, |acc, v| acc + v);
        }
    });
    let norm = 1.0 / ((2 * r + 1) * (2 * r + 1)) as f32;
    let mut out = Plane::new(w, h, 0.0f32);
    out.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, o)| {
        o.fill(0.0);
        for k in 0..=2 * r {
            let src = rows.row((y + k).saturating_sub(r).min(h - 1));
            o.iter_mut().zip(src).for_each(|(a, &v)| *a += v);
        }
        o.iter_mut().for_each(|a| *a *= norm);
    });
    out
}

/// A separable Gaussian blur of every channel (σ px, radius ⌈3σ⌉, borders replicated; not quantised).
pub(crate) fn gaussian_blur(img: &RgbImage, sigma: f32) -> RgbImage {
    let (w, h) = img.dims();
    let mut out = img.clone();
    for ch in &mut out.channels {
        *ch = gaussian_blur_plane(ch, w, h, sigma);
    }
    out
}

/// [`gaussian_blur`] of one row-major `w` × `h` channel.
pub(crate) fn gaussian_blur_plane(data: &[f32], w: usize, h: usize, sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 || data.is_empty() {
        return data.to_vec();
    }
    let r = (3.0 * sigma).ceil() as usize;
    let kernel: Vec<f32> =
        (0..=2 * r).map(|k| (-((k as f32 - r as f32).powi(2)) / (2.0 * sigma * sigma)).exp()).collect();
    let total: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / total).collect();
    let mut tmp = vec![0.0f32; w * h];
    tmp.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let src = &data[y * w..][..w];
        for (x, o) in row.iter_mut().enumerate() {
            *o = kernel.iter().enumerate().map(|(k, kv)| kv * src[(x + k).saturating_sub(r).min(w - 1)]).sum();
        }
    });
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (k, kv) in kernel.iter().enumerate() {
            let src = &tmp[(y + k).saturating_sub(r).min(h - 1) * w..][..w];
            row.iter_mut().zip(src).for_each(|(o, s)| *o += kv * s);
        }
    });
    out
}

/// `pick` (`f32::min` or `f32::max`) of the finite values of `p` in the square of radius `r` around every
/// pixel, in two separable passes; `empty` (the identity of `pick`: `inf` for the minimum) where there is none.
pub(crate) fn window_extreme(
    p: &Plane<f32>,
    r: usize,
    empty: f32,
    pick: impl Fn(f32, f32) -> f32 + Copy + Sync,
) -> Plane<f32> {
    let (w, h) = (p.width, p.height);
    let mut rows = Plane::new(w, h, empty);
    rows.data.par_chunks_mut(w.max(1)).zip(p.data.par_chunks(w.max(1))).for_each(|(dst, src)| {
        let finite: Vec<f32> = src.iter().map(|&v| if v.is_finite() { v } else { empty }).collect();
        running_extreme(&finite, r, empty, pick, dst);
    });
    let mut out = Plane::new(w, h, empty);
    out.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, dst)| {
        for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
            dst.iter_mut().zip(rows.row(yy)).for_each(|(o, &v)| *o = pick(*o, v));
        }
    });
    out
}

/// `out[x]` = `pick` of `src[x − r ..= x + r]` (within the slice) for every x, in O(1) per value (van Herk /
/// Gil–Werman: the running extremes from the start and from the end of blocks of 2r + 1, two per window).
fn running_extreme(src: &[f32], r: usize, empty: f32, pick: impl Fn(f32, f32) -> f32, out: &mut [f32]) {
    let k = 2 * r + 1;
    let n = src.len() + 2 * r;
    let padded = |i: usize| if i < r || i >= r + src.len() { empty } else { src[i - r] };
    let (mut from_start, mut to_end) = (vec![empty; n], vec![empty; n]);
    for i in 0..n {
        from_start[i] = if i % k == 0 { padded(i) } else { pick(from_start[i - 1], padded(i)) };
    }
    for i in (0..n).rev() {
        to_end[i] = if i % k == k - 1 || i + 1 == n { padded(i) } else { pick(to_end[i + 1], padded(i)) };
    }
    // Window x of the padded row is x ..= x + 2r: the end of x's block and the start of the next one.
    for (x, o) in out.iter_mut().enumerate() {
        *o = pick(to_end[x], from_start[x + 2 * r]);
    }
}

/// The plane reduced `factor` times by the mean of each `factor` × `factor` block (the last row and column of
/// blocks may be partial): the sum of each of the block's rows, then the sum of those (not the order of
/// [`crate::scale::downsample_plane`]; see the module doc).
///
/// # Panics
/// If `factor` is 0.
pub(crate) fn box_reduce(p: &Plane<f32>, factor: usize) -> Plane<f32> {
    let (w, h) = p.dims();
    let (rw, rh) = (w.div_ceil(factor), h.div_ceil(factor));
    let mut out = Plane::new(rw, rh, 0.0f32);
    out.data.par_chunks_mut(rw.max(1)).enumerate().for_each(|(by, row)| {
        let (y0, y1) = (by * factor, ((by + 1) * factor).min(h));
        for (bx, o) in row.iter_mut().enumerate() {
            let (x0, x1) = (bx * factor, ((bx + 1) * factor).min(w));
            let sum: f32 = (y0..y1).map(|y| p.row(y)[x0..x1].iter().sum::<f32>()).sum();
            *o = sum / ((y1 - y0) * (x1 - x0)) as f32;
        }
    });
    out
}

/// The mean of each pixel's (2r + 1)² window (borders replicated), each window summed on its own row by row (see the
/// module doc for the other box means).
pub(crate) fn box_mean(p: &Plane<f32>, r: usize) -> Plane<f32> {
    let (w, h) = p.dims();
    let mut out = Plane::new(w, h, 0.0f32);
    let norm = 1.0 / ((2 * r + 1) * (2 * r + 1)) as f32;
    out.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let mut sum = 0.0f32;
            for k in 0..=2 * r {
                let src = p.row((y + k).saturating_sub(r).min(h - 1));
                for j in 0..=2 * r {
                    sum += src[(x + j).saturating_sub(r).min(w - 1)];
                }
            }
            *o = sum * norm;
        }
    });
    out
}

/// [`box_mean`] in O(1) per pixel rather than O(r²): running sums (in `f64`, so adding and dropping values leaves
/// no drift) along each row over dx = −r..r, then down each column over dy = −r..r, in bands of
/// [`BOX_BAND_ROWS`] rows; borders replicated. The bands are fixed and each is summed by one thread in a fixed
/// order, so the result does not depend on the thread count.
pub(crate) fn box_mean_separable(p: &Plane<f32>, r: usize) -> Plane<f32> {
    let (w, h) = p.dims();
    if w == 0 || h == 0 {
        return p.clone();
    }
    let mut rows = Plane::new(w, h, 0.0f64);
    rows.data.par_chunks_mut(w).zip(p.data.par_chunks(w)).for_each(|(out, src)| {
        let at = |x: usize| f64::from(src[x.saturating_sub(r).min(w - 1)]);
        // Window of x is padded columns x ..= x + 2r, column c of the padding being src[c − r] clamped.
        let mut sum: f64 = (0..=2 * r).map(at).sum();
        for (x, o) in out.iter_mut().enumerate() {
            *o = sum;
            sum += at(x + 2 * r + 1) - at(x);
        }
    });
    let norm = 1.0 / ((2 * r + 1) * (2 * r + 1)) as f64;
    let row = |y: usize| rows.row(y.saturating_sub(r).min(h - 1));
    let mut out = Plane::new(w, h, 0.0f32);
    out.data.par_chunks_mut(w * BOX_BAND_ROWS).enumerate().for_each(|(band, dst)| {
        let y0 = band * BOX_BAND_ROWS;
        let mut acc = vec![0.0f64; w];
        for k in 0..=2 * r {
            acc.iter_mut().zip(row(y0 + k)).for_each(|(a, &v)| *a += v);
        }
        for (dy, o) in dst.chunks_exact_mut(w).enumerate() {
            o.iter_mut().zip(&acc).for_each(|(o, &a)| *o = (a * norm) as f32);
            let y = y0 + dy;
            let (add, drop) = (row(y + 2 * r + 1), row(y));
            acc.iter_mut().zip(add).zip(drop).for_each(|((a, &p), &m)| *a += p - m);
        }
    });
    out
}

/// Rows per band of [`box_mean_separable`]'s column sums: each band starts its running sums afresh.
const BOX_BAND_ROWS: usize = 32;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sobel_magnitude_by_hand() {
        // A vertical step 0 | 10 between columns 1 and 2: gx = 40 on both sides of it, gy = 0; flat elsewhere.
        let p = Plane::from_parts(4, 3, [0.0, 0.0, 10.0, 10.0].repeat(3));
        assert_eq!(sobel_magnitude(&p).data, [0.0, 40.0, 40.0, 0.0].repeat(3));
        // The transpose gives the same magnitude.
        let t = Plane::from_parts(3, 4, [[0.0; 3], [0.0; 3], [10.0; 3], [10.0; 3]].concat());
        assert_eq!(sobel_magnitude(&t).data, [[0.0; 3], [40.0; 3], [40.0; 3], [0.0; 3]].concat());
    }

    #[test]
    fn the_separable_box_mean_is_the_box_mean() {
        // 70 rows: more than one band of the column sums.
        let data: Vec<f32> = (0..7 * 70).map(|i| ((i * 37) % 11) as f32 - 3.0).collect();
        let p = Plane::from_parts(7, 70, data);
        for r in [0, 1, 2, 6] {
            let (fast, slow) = (box_mean_separable(&p, r), box_mean(&p, r));
            for (a, b) in fast.data.iter().zip(&slow.data) {
                assert!((a - b).abs() < 1e-5, "r {r}: {a} vs {b}");
            }
        }
    }

    /// Each pair of box means (and the two block means) agrees within float rounding, and differs somewhere in the
    /// last bit: they sum in different orders, so one cannot stand in for another without changing outputs.
    #[test]
    fn the_box_means_agree_but_round_differently() {
        let data: Vec<f32> = crate::test_util::rand_vec(61 * 47, 9).iter().map(|v| v * 200.0 + 0.1).collect();
        let p = Plane::from_parts(61, 47, data);
        let close_not_equal = |a: &Plane<f32>, b: &Plane<f32>, what: &str| {
            assert!(a.data.iter().zip(&b.data).all(|(x, y)| (x - y).abs() <= 1e-4 * x.abs().max(1.0)), "{what}");
            assert!(a.data.iter().zip(&b.data).any(|(x, y)| x.to_bits() != y.to_bits()), "{what}: bit-identical");
        };
        let direct = box_mean(&p, 2);
        close_not_equal(&direct, &local_mean_abs(&p, 2), "box_mean, local_mean_abs");
        close_not_equal(&direct, &box_mean_separable(&p, 2), "box_mean, box_mean_separable");
        close_not_equal(&local_mean_abs(&p, 2), &box_mean_separable(&p, 2), "local_mean_abs, box_mean_separable");
        close_not_equal(&box_reduce(&p, 3), &crate::scale::downsample_plane(&p, 3), "box_reduce, downsample_plane");
    }

    #[test]
    fn box_means_and_reductions_by_hand() {
        let p = Plane::from_parts(3, 2, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(box_reduce(&p, 2).data, vec![3.0, 4.5]);
        assert_eq!(box_reduce(&p, 1).data, p.data);
        let m = box_mean(&p, 1);
        // Pixel (0, 0): rows 0, 0, 1 and columns 0, 0, 1 (replicated).
        assert_eq!(m.data[0], (1.0 + 1.0 + 2.0) * 2.0 / 9.0 + (4.0 + 4.0 + 5.0) / 9.0);
        assert_eq!(box_mean(&p, 0).data, p.data);
    }

    #[test]
    fn window_extreme_matches_the_direct_window() {
        let (w, h) = (13, 29);
        let vals = crate::test_util::rand_vec(w * h, 9);
        let data = vals.iter().map(|&v| if v < 0.15 { f32::INFINITY } else { v * 10.0 }).collect();
        let p = Plane::from_parts(w, h, data);
        for r in [0, 1, 2, 7, 14, 40] {
            for (empty, pick) in [(f32::INFINITY, f32::min as fn(f32, f32) -> f32), (f32::NEG_INFINITY, f32::max)] {
                let out = window_extreme(&p, r, empty, pick);
                for y in 0..h {
                    for x in 0..w {
                        let mut want = empty;
                        for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                            for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                                let v = p.data[yy * w + xx];
                                want = if v.is_finite() { pick(want, v) } else { want };
                            }
                        }
                        assert_eq!(out.data[y * w + x], want, "r {r} at ({x}, {y})");
                    }
                }
            }
        }
    }

    #[test]
    fn running_extreme_matches_the_direct_window() {
        let src: Vec<f32> = crate::test_util::rand_vec(23, 5).iter().map(|v| v * 10.0).collect();
        for r in [0, 1, 3, 11, 30] {
            for (empty, pick) in [(f32::INFINITY, f32::min as fn(f32, f32) -> f32), (f32::NEG_INFINITY, f32::max)] {
                let mut out = vec![0.0; src.len()];
                running_extreme(&src, r, empty, pick, &mut out);
                for (x, &o) in out.iter().enumerate() {
                    let window = &src[x.saturating_sub(r)..(x + r + 1).min(src.len())];
                    assert_eq!(o, window.iter().fold(empty, |a, &v| pick(a, v)), "r {r}, x {x}");
                }
            }
        }
    }
}
