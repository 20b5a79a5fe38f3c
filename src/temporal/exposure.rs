//! Exposure changes between frames: a camera's auto-exposure changes its gain (and, less, its black level) from
//! frame to frame, which moves every grey value of a still scene. The temporal model fits the affine map
//! v ↦ gain·v + offset that takes a reference view (the previous frame, or the running mean) to the current frame
//! and compensates it before it tests for stillness and before it averages: an exposure change is then neither
//! motion nor a cut, and the running means do not start again.
//!
//! The fit compares the means of 8 × 8 blocks, not pixels: a block's mean carries an eighth of a pixel's noise, so the
//! noise hardly biases the gain (a regression on pixels shrinks it by var(signal) / (var(signal) + var(noise)), 1 % at
//! σ 8). Blocks holding a clipped pixel (near 0 or 255, where the gain cannot act) are left out, and so are blocks the
//! fit does not explain (something moved there): from the median ratio of the blocks' means, least squares three times
//! on the blocks within three robust deviations (1.4826 × the median absolute residual, at least half a grey level) of
//! the line. A map that changes the reference by less than half a grey level on average is no exposure change (the
//! fit's own error is of that order, and a camera that did not change its exposure keeps its frames as they are).
//!
//! The map is one for the whole image (what an exposure or gain change does); a vignetting that changes between
//! frames (another aperture) is left to the still test.

use rayon::prelude::*;

use super::motion::Shift;
use crate::image::{Plane, RgbImage};
use crate::imgproc::stats::nth_smallest;

/// An exposure change: the current frame's grey ≈ `gain` × the reference's + `offset` (grey levels, 0–255).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exposure {
    /// The factor on the reference's values.
    pub gain: f32,
    /// Added after the factor, in grey levels.
    pub offset: f32,
}

/// The side of the blocks whose means are compared.
const BLOCK_PX: usize = 8;

/// The fewest blocks a fit stands on.
const MIN_BLOCKS: usize = 16;

/// Grey values at or beyond these are taken as clipped (the sensor's or the 8-bit range's limit): a clipped pixel
/// does not follow the gain. The margin holds the grey of a pixel with one channel clipped.
const CLIP_LOW: f32 = 2.0;
/// See [`CLIP_LOW`].
const CLIP_HIGH: f32 = 250.0;

/// The gains taken as an exposure change of one scene; beyond them the frames are compared as they are.
const GAIN_RANGE: (f32, f32) = (0.5, 2.0);

/// The largest offset taken as an exposure change (a quarter of the range).
const MAX_OFFSET: f32 = 64.0;

/// Below this mean change of the reference (grey levels) the map is no exposure change.
const MIN_CHANGE: f64 = 0.5;

/// Below this spread of the blocks' reference means (grey levels, standard deviation) gain and offset cannot be
/// told apart: the gain alone is fitted (an exposure change is a factor).
const MIN_SPREAD: f64 = 4.0;

/// Residuals beyond this many robust deviations are outliers (something moved there).
const OUTLIER_DEVIATIONS: f64 = 3.0;

impl Exposure {
    /// `v` under this change.
    pub(crate) fn apply(self, v: f32) -> f32 {
        self.gain * v + self.offset
    }

    /// The plane under this change.
    pub(crate) fn apply_plane(self, p: &Plane<f32>) -> Plane<f32> {
        Plane::from_parts(p.width, p.height, p.data.iter().map(|&v| self.apply(v)).collect())
    }

    /// Every channel of `img` under this change, clipped to 0–255 (as a camera clips), in place.
    pub(crate) fn apply_image(self, img: &mut RgbImage) {
        for ch in &mut img.channels {
            ch.iter_mut().for_each(|v| *v = self.apply(*v).clamp(0.0, 255.0));
        }
    }
}

/// The exposure change that takes `reference` to `current` where `current`'s (x, y) shows `reference`'s
/// (x + dx, y + dy) (see the module doc); `None` when there is none to compensate: no change beyond
/// [`MIN_CHANGE`], too few blocks to fit, or a fit outside [`GAIN_RANGE`] / [`MAX_OFFSET`] (another scene, not an
/// exposure).
pub(crate) fn fit(reference: &Plane<f32>, current: &Plane<f32>, shift: Shift) -> Option<Exposure> {
    let blocks = block_means(reference, current, shift);
    if blocks.len() < MIN_BLOCKS {
        return None;
    }
    let mut keep = vec![true; blocks.len()];
    // The start is the median ratio, which a minority of changed blocks cannot pull (a least-squares start can
    // lean so far towards them that the first cut keeps some).
    let mut ratios: Vec<f64> = blocks.iter().filter(|b| b.0 > 1.0).map(|&(r, c)| c / r).collect();
    if ratios.is_empty() {
        return None;
    }
    let mid = ratios.len() / 2;
    let mut line = (nth_smallest(&mut ratios, mid), 0.0);
    for _ in 0..3 {
        let residuals: Vec<f64> = blocks.iter().map(|&(r, c)| c - (line.0 * r + line.1)).collect();
        let mut abs: Vec<f64> = residuals.iter().map(|e| e.abs()).collect();
        let mid = abs.len() / 2;
        let median = nth_smallest(&mut abs, mid);
        let limit = (OUTLIER_DEVIATIONS * 1.4826 * median).max(0.5);
        keep.iter_mut().zip(&residuals).for_each(|(k, e)| *k = e.abs() <= limit);
        line = least_squares(&blocks, &keep)?;
    }
    let (gain, offset) = (line.0 as f32, line.1 as f32);
    let plausible = (GAIN_RANGE.0..=GAIN_RANGE.1).contains(&gain) && offset.abs() <= MAX_OFFSET;
    let kept: Vec<f64> = blocks.iter().zip(&keep).filter(|(_, k)| **k).map(|(&(r, _), _)| r).collect();
    let change = kept.iter().map(|r| ((line.0 - 1.0) * r + line.1).abs()).sum::<f64>() / kept.len().max(1) as f64;
    (plausible && change >= MIN_CHANGE).then_some(Exposure { gain, offset })
}

/// The least-squares line c ≈ g·r + o through the kept blocks (the gain alone, o = 0, when their reference means
/// spread less than [`MIN_SPREAD`]); `None` for fewer than [`MIN_BLOCKS`] of them.
fn least_squares(blocks: &[(f64, f64)], keep: &[bool]) -> Option<(f64, f64)> {
    let kept = || blocks.iter().zip(keep).filter(|(_, k)| **k).map(|(b, _)| *b);
    let n = kept().count();
    if n < MIN_BLOCKS {
        return None;
    }
    let (sr, sc) = kept().fold((0.0, 0.0), |(a, b), (r, c)| (a + r, b + c));
    let (mr, mc) = (sr / n as f64, sc / n as f64);
    let (srr, src) = kept().fold((0.0, 0.0), |(a, b), (r, c)| (a + (r - mr) * (r - mr), b + (r - mr) * (c - mc)));
    if srr / (n as f64) < MIN_SPREAD * MIN_SPREAD {
        return (mr > 1.0).then(|| (mc / mr, 0.0));
    }
    let g = src / srr;
    Some((g, mc - g * mr))
}

/// The (reference, current) means of the 8 × 8 blocks of `current` whose shifted block lies inside `reference`,
/// none of either's pixels clipped; in row-major block order (the same list whatever the thread count).
fn block_means(reference: &Plane<f32>, current: &Plane<f32>, shift: Shift) -> Vec<(f64, f64)> {
    let (w, h) = current.dims();
    let (bw, bh) = (w / BLOCK_PX, h / BLOCK_PX);
    let inside = |x: usize, y: usize| {
        let (rx, ry) = (x as i64 + shift.dx, y as i64 + shift.dy);
        rx >= 0 && ry >= 0 && rx + BLOCK_PX as i64 <= w as i64 && ry + BLOCK_PX as i64 <= h as i64
    };
    let rows: Vec<Vec<(f64, f64)>> = (0..bh)
        .into_par_iter()
        .map(|by| {
            let y0 = by * BLOCK_PX;
            (0..bw)
                .filter_map(|bx| {
                    let x0 = bx * BLOCK_PX;
                    if !inside(x0, y0) {
                        return None;
                    }
                    let (rx, ry) = ((x0 as i64 + shift.dx) as usize, (y0 as i64 + shift.dy) as usize);
                    let r = block_mean(reference, rx, ry)?;
                    let c = block_mean(current, x0, y0)?;
                    Some((r, c))
                })
                .collect()
        })
        .collect();
    rows.into_iter().flatten().collect()
}

/// The mean of the 8 × 8 block at (x0, y0), `None` when a pixel of it is clipped.
fn block_mean(p: &Plane<f32>, x0: usize, y0: usize) -> Option<f64> {
    let mut sum = 0.0f64;
    for y in y0..y0 + BLOCK_PX {
        for &v in &p.row(y)[x0..x0 + BLOCK_PX] {
            if !(CLIP_LOW..=CLIP_HIGH).contains(&v) {
                return None;
            }
            sum += f64::from(v);
        }
    }
    Some(sum / (BLOCK_PX * BLOCK_PX) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::internals::SplitMix64;

    const STILL: Shift = Shift { dx: 0, dy: 0, residual: 0.0 };

    /// A textured grey image in 30..200, with Gaussian-ish noise of about `noise` grey levels, seeded.
    fn texture(w: usize, h: usize, noise: f32, seed: u64) -> Plane<f32> {
        let mut rng = SplitMix64::new(seed);
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let n: f32 = (0..4).map(|_| rng.next_f64() as f32 - 0.5).sum::<f32>() * 1.73;
                115.0 + 60.0 * (x * 0.05).sin() * (y * 0.07).cos() + 20.0 * (x * 0.31 + y * 0.1).sin() + noise * n
            })
            .collect();
        Plane::from_parts(w, h, data)
    }

    #[test]
    fn a_gain_and_offset_are_found_through_the_noise() {
        let reference = texture(160, 120, 0.0, 1);
        let noisy = texture(160, 120, 6.0, 2);
        let current = Exposure { gain: 1.1, offset: -3.0 }.apply_plane(&noisy);
        let e = fit(&reference, &current, STILL).expect("an exposure change");
        assert!((e.gain - 1.1).abs() < 0.005 && (e.offset + 3.0).abs() < 0.6, "{e:?}");
    }

    #[test]
    fn no_change_beyond_the_noise_is_no_exposure_change() {
        let (a, b) = (texture(160, 120, 6.0, 1), texture(160, 120, 6.0, 2));
        assert_eq!(fit(&a, &b, STILL), None);
        // A quarter of a grey level is below what the fit compensates.
        assert_eq!(fit(&a, &Exposure { gain: 1.0, offset: 0.25 }.apply_plane(&b), STILL), None);
    }

    #[test]
    fn a_moving_object_does_not_pull_the_fit() {
        let reference = texture(160, 120, 0.0, 1);
        let mut current = Exposure { gain: 0.95, offset: 0.0 }.apply_plane(&reference);
        // A bright object over a sixth of the image.
        for y in 20..80 {
            for x in 40..90 {
                current.data[y * 160 + x] = 245.0 - 0.5 * (x as f32 - 40.0);
            }
        }
        let e = fit(&reference, &current, STILL).expect("an exposure change");
        assert!((e.gain - 0.95).abs() < 1e-3 && e.offset.abs() < 0.2, "{e:?}");
    }

    #[test]
    fn the_fit_follows_the_shift_and_skips_clipped_blocks() {
        let big = texture(200, 140, 0.0, 3);
        let crop = |p: &Plane<f32>, x0: usize, y0: usize| {
            let data = (0..120).flat_map(|y| p.row(y0 + y)[x0..x0 + 160].to_vec()).collect();
            Plane::from_parts(160, 120, data)
        };
        // Brighter by 25 %: the brightest parts clip at 255 and are left out.
        let brighter = Plane::from_parts(200, 140, big.data.iter().map(|v| (v * 1.25).min(255.0)).collect());
        let (reference, current) = (crop(&big, 10, 5), crop(&brighter, 16, 3));
        let e = fit(&reference, &current, Shift { dx: 6, dy: -2, residual: 0.0 }).expect("an exposure change");
        assert!((e.gain - 1.25).abs() < 1e-3 && e.offset.abs() < 0.1, "{e:?}");
    }

    #[test]
    fn another_scene_is_no_exposure_change() {
        let a = texture(160, 120, 0.0, 1);
        let other = Plane::from_parts(160, 120, (0..160 * 120).map(|i| ((i * 7919) % 173) as f32 + 40.0).collect());
        assert_eq!(fit(&a, &other, STILL), None);
    }

    #[test]
    fn a_flat_image_takes_the_gain_alone() {
        let flat = Plane::new(64, 64, 100.0f32);
        let e = fit(&flat, &Exposure { gain: 1.2, offset: 0.0 }.apply_plane(&flat), STILL).unwrap();
        assert_eq!((e.gain, e.offset), (1.2, 0.0));
    }
}
