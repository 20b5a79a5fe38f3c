//! Neighbourhood filters on planes and images: replicated padding, the horizontal Sobel gradient, central
//! differences, a local mean of |v|, and a separable Gaussian blur. Borders are replicated everywhere.

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
    let (w, h) = grey.dims();
    let mut out = Plane::new(w, h, 0.0f32);
    out.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
        let up = grey.row(y.saturating_sub(1));
        let mid = grey.row(y);
        let down = grey.row((y + 1).min(h - 1));
        for (x, g) in row.iter_mut().enumerate() {
            let (l, r) = (x.saturating_sub(1), (x + 1).min(w - 1));
            *g = (up[r] - up[l]) + 2.0 * (mid[r] - mid[l]) + (down[r] - down[l]);
        }
    });
    out
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
