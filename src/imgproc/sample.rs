//! Sampling a plane between its pixels: bilinear, and the cubic convolution kernel of Keys.

/// Bilinear sample of a row-major `w × h` plane at (x, y), clamped to the image.
pub(crate) fn sample_bilinear(data: &[f32], w: usize, h: usize, x: f64, y: f64) -> f64 {
    Bilinear::new(w, h, x, y).sample(data)
}

/// Where and with which weights a bilinear sample at one position reads a `w × h` plane: computed once, applied to
/// several planes of that size (a view and its gradients) at the cost of the four reads.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Bilinear {
    /// Index of the top-left pixel, and the offsets of the right and lower neighbours (0 on a one-pixel side).
    at: usize,
    right: usize,
    down: usize,
    fx: f64,
    fy: f64,
}

impl Bilinear {
    /// The sample at (x, y) of a `w × h` plane, clamped to the image.
    pub(crate) fn new(w: usize, h: usize, x: f64, y: f64) -> Self {
        let x = x.clamp(0.0, (w - 1) as f64);
        let y = y.clamp(0.0, (h - 1) as f64);
        // (x, y ≥ 0 after the clamp, so the conversion is the floor.)
        let (x0, y0) = ((x as usize).min(w.saturating_sub(2)), (y as usize).min(h.saturating_sub(2)));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let (right, down) = (usize::from(x0 + 1 < w), if y0 + 1 < h { w } else { 0 });
        Bilinear { at: y0 * w + x0, right, down, fx, fy }
    }

    /// The sample of `data` (a plane of the size given to [`Bilinear::new`]).
    pub(crate) fn sample(&self, data: &[f32]) -> f64 {
        let Bilinear { at, right, down, fx, fy } = *self;
        let px = |i: usize| f64::from(data[i]);
        let top = px(at) * (1.0 - fx) + px(at + right) * fx;
        let bottom = px(at + down) * (1.0 - fx) + px(at + down + right) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// Keys' cubic convolution kernel (a = −½).
pub(crate) fn keys(t: f64) -> f64 {
    let t = t.abs();
    if t < 1.0 {
        (1.5 * t - 2.5) * t * t + 1.0
    } else if t < 2.0 {
        ((-0.5 * t + 2.5) * t - 4.0) * t + 2.0
    } else {
        0.0
    }
}

/// The sub-pixel steps a remap position is rounded to: 1/32 px, as OpenCV's fixed-point `remap` rounds them, so
/// that an image resampled through the same maps comes out as OpenCV's does.
const REMAP_STEPS_PER_PX: f32 = 32.0;

/// Bilinear resampling of a row-major `w × h` plane through per-pixel source positions (`map_x`, `map_y`, the
/// output's size): each output pixel takes the source at its position, a tap outside the source counting as 0
/// (OpenCV's `remap` with `INTER_LINEAR` and a constant-0 border); positions are rounded to 1/32 px first.
///
/// # Panics
/// If the maps differ in length, or `src.len() != w * h`.
pub(crate) fn remap_bilinear(src: &[f32], w: usize, h: usize, map_x: &[f32], map_y: &[f32]) -> Vec<f32> {
    assert_eq!(map_x.len(), map_y.len(), "remap: maps of different sizes");
    assert_eq!(src.len(), w * h, "remap: source is not {w}x{h}");
    let tap = |x: i64, y: i64| -> f32 {
        if x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h { src[y as usize * w + x as usize] } else { 0.0 }
    };
    map_x
        .iter()
        .zip(map_y)
        .map(|(&mx, &my)| {
            if !(mx.is_finite() && my.is_finite()) {
                return 0.0;
            }
            let (qx, qy) = ((mx * REMAP_STEPS_PER_PX).round_ties_even(), (my * REMAP_STEPS_PER_PX).round_ties_even());
            // Beyond any image (and beyond i64): every tap is outside.
            if qx.abs() > 1e15 || qy.abs() > 1e15 {
                return 0.0;
            }
            let (qx, qy) = (qx as i64, qy as i64);
            let steps = REMAP_STEPS_PER_PX as i64;
            let (x0, y0) = (qx.div_euclid(steps), qy.div_euclid(steps));
            let (fx, fy) =
                (qx.rem_euclid(steps) as f32 / REMAP_STEPS_PER_PX, qy.rem_euclid(steps) as f32 / REMAP_STEPS_PER_PX);
            let top = tap(x0, y0) * (1.0 - fx) + tap(x0 + 1, y0) * fx;
            let bottom = tap(x0, y0 + 1) * (1.0 - fx) + tap(x0 + 1, y0 + 1) * fx;
            top * (1.0 - fy) + bottom * fy
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_interpolates_inside_and_clamps_at_the_borders() {
        // 3 × 2: f(x, y) = 10x + 100y, which bilinear interpolation reproduces exactly inside.
        let data = [0.0, 10.0, 20.0, 100.0, 110.0, 120.0];
        for (x, y, want) in
            [(0.5, 0.5, 55.0), (1.25, 0.0, 12.5), (2.0, 1.0, 120.0), (-3.0, 0.25, 25.0), (9.0, 7.0, 120.0)]
        {
            assert_eq!(sample_bilinear(&data, 3, 2, x, y), want, "at ({x}, {y})");
        }
        // One-pixel sides: a column and a row.
        assert_eq!(sample_bilinear(&[4.0, 8.0], 1, 2, 0.7, 0.5), 6.0);
        assert_eq!(sample_bilinear(&[4.0, 8.0], 2, 1, 0.5, 0.7), 6.0);
        assert_eq!(sample_bilinear(&[4.0], 1, 1, 0.3, -2.0), 4.0);
    }

    #[test]
    fn remap_at_whole_pixels_copies_and_halfway_averages() {
        let src = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0];
        let out = remap_bilinear(&src, 3, 2, &[2.0, 0.0, 0.5, 1.0], &[0.0, 1.0, 0.0, 0.5]);
        assert_eq!(out, vec![20.0, 30.0, 5.0, 25.0]);
    }

    #[test]
    fn remap_outside_the_source_fades_to_zero_over_one_pixel() {
        let src = [100.0; 4];
        let out = remap_bilinear(&src, 2, 2, &[-0.5, -1.0, 1.5, 5.0, f32::NAN], &[0.0, 0.0, 1.0, 0.0, 0.0]);
        assert_eq!(out, vec![50.0, 0.0, 50.0, 0.0, 0.0]);
    }

    #[test]
    fn remap_positions_are_rounded_to_a_thirty_second_of_a_pixel() {
        let src = [0.0, 32.0];
        // 0.26 px is 8.32 steps: rounded to 8 steps, a quarter of the way.
        assert_eq!(remap_bilinear(&src, 2, 1, &[0.26], &[0.0]), vec![8.0]);
    }
}
