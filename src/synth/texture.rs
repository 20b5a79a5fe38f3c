//! The surfaces' textures: a seeded two-colour palette mixed by coarse value noise plus per-channel detail noise,
//! a function of the surface point's left-view coordinates (so both views see the same pattern).

use crate::rng::{SplitMix64, mix64};

/// A surface's colour as a function of its left-view coordinates: a two-colour palette mixed by coarse noise
/// (cells 16 and 32 px) plus per-channel detail noise (cells 2, 4, 8 px).
#[derive(Clone, Debug)]
pub(super) struct Texture {
    key: u64,
    colours: [[f64; 3]; 2],
    detail: f64,
    /// Where the pattern has moved to (a moving object carries its texture): the colour at `(x, y)` is the
    /// unmoved pattern's at `(x, y) − offset`.
    pub(super) offset: [f64; 2],
}

impl Texture {
    pub(super) fn draw(rng: &mut SplitMix64) -> Texture {
        let key = rng.next_u64();
        let mut colour = || [rng.range(30.0, 225.0), rng.range(30.0, 225.0), rng.range(30.0, 225.0)];
        let colours = [colour(), colour()];
        Texture { key, colours, detail: rng.range(110.0, 160.0), offset: [0.0; 2] }
    }

    pub(super) fn colour(&self, x: f64, y: f64) -> [f64; 3] {
        let (x, y) = (x - self.offset[0], y - self.offset[1]);
        const COARSE: [(f64, f64); 2] = [(16.0, 0.4), (32.0, 0.6)];
        const FINE: [(f64, f64); 3] = [(2.0, 0.45), (4.0, 0.35), (8.0, 0.2)];
        let mix = smooth(fbm(self.key, 3, &COARSE, x, y) * 2.0 - 0.5);
        let [p, q] = self.colours;
        let mut out = [0.0; 3];
        for (c, v) in out.iter_mut().enumerate() {
            let detail = fbm(self.key, c as u64, &FINE, x, y) - 0.5;
            *v = (p[c] + (q[c] - p[c]) * mix + self.detail * detail).clamp(0.0, 255.0);
        }
        out
    }
}

/// Sum of value-noise octaves `(cell size px, weight)` for channel `channel`; weights sum to 1, result in 0..1.
fn fbm(key: u64, channel: u64, octaves: &[(f64, f64)], x: f64, y: f64) -> f64 {
    octaves
        .iter()
        .enumerate()
        .map(|(o, &(cell, weight))| {
            weight * value_noise(mix64(key ^ (channel << 8 | o as u64).wrapping_mul(0x9e37_79b9)), x / cell, y / cell)
        })
        .sum()
}

/// Smoothly interpolated random values at integer lattice points, 0..1.
pub(super) fn value_noise(key: u64, x: f64, y: f64) -> f64 {
    let (fx, fy) = (x.floor(), y.floor());
    let (ix, iy) = (fx as i64, fy as i64);
    let (tx, ty) = (smooth(x - fx), smooth(y - fy));
    let at = |i: i64, j: i64| lattice_value(key, i, j);
    let top = at(ix, iy) + (at(ix + 1, iy) - at(ix, iy)) * tx;
    let bottom = at(ix, iy + 1) + (at(ix + 1, iy + 1) - at(ix, iy + 1)) * tx;
    top + (bottom - top) * ty
}

/// A random value in 0..1 for lattice point `(i, j)`.
#[inline]
pub(super) fn lattice_value(key: u64, i: i64, j: i64) -> f64 {
    let h = mix64(key ^ mix64((i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (j as u64)));
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Smoothstep on 0..1 (clamped).
#[inline]
fn smooth(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}
