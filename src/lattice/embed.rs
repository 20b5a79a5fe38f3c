//! Embedding a feature vector in the permutohedral lattice (Adams, Baek & Davis 2010, §3.1): the enclosing
//! simplex and its barycentric weights, eight pixels at a time in [`embed_lanes`] (vectorised), with the scalar
//! `embed` kept as the test reference.

use super::*;
use crate::fastmath::integral_to_i32;

/// Per-pixel result of embedding a feature vector: the enclosing simplex (its remainder-0 vertex and the ranking
/// that orders the other vertices) and the barycentric weights.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Embedding {
    /// The simplex's remainder-0 vertex, all d+1 coordinates (they sum to zero).
    pub(super) origin: [i32; D1],
    /// Rank of each coordinate's rounding residual (0 = largest … d = smallest).
    pub(super) rank: [i32; D1],
    pub(super) weights: [f32; D1],
}

/// The per-axis elevation scales √(2/3)·(d+1)/√(i(i+1)) for features i = 1..=d (index i − 1).
pub(super) fn elevation_scales() -> [f32; D] {
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
pub(super) fn embed(f: &[f32; D], scales: &[f32; D]) -> Embedding {
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
pub(super) const LANES: usize = 8;

/// `embed` for `LANES` feature vectors at once (`f[feature][lane]`), written lane by lane so that it
/// vectorises; every lane performs exactly `embed`'s floating-point operations, so the results are
/// bit-identical (tested).
#[inline(always)]
pub(super) fn embed_lanes(f: &[[f32; LANES]; D], scales: &[f32; D]) -> [Embedding; LANES] {
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
    let total: [i32; LANES] = std::array::from_fn(|l| integral_to_i32(total[l] / d1));
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
        origin: std::array::from_fn(|i| integral_to_i32(greedy[i][l])),
        rank: std::array::from_fn(|i| rank[i][l]),
        weights: std::array::from_fn(|k| if k == 0 { bary[0][l] + (1.0 + bary[D1][l]) } else { bary[k][l] }),
    })
}

/// Where [`number_block`](super::keys::number_block) gets each pixel's embedding from.
#[derive(Clone, Copy)]
pub(super) enum Features<'a> {
    /// Embedded on the fly from an image, features (x·s_xy, y·s_xy, r·s_rgb, g·s_rgb, b·s_rgb), `scales` =
    /// [s_xy, s_rgb]; `elevation` from [`elevation_scales`].
    Image { image: &'a RgbImage, scales: [f32; 2], elevation: [f32; D] },
    /// Already embedded (tests).
    #[cfg(test)]
    Embedded(&'a [Embedding]),
}

impl Features<'_> {
    pub(super) fn len(&self) -> usize {
        match self {
            Features::Image { image, .. } => image.len(),
            #[cfg(test)]
            Features::Embedded(e) => e.len(),
        }
    }

    /// The embeddings of the pixels `first..first + n` (n ≤ `LANES`; lanes past n repeat the last pixel).
    #[inline(always)]
    pub(super) fn lanes_at(&self, first: usize, n: usize) -> [Embedding; LANES] {
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
