//! Sampling a plane between its pixels: bilinear, and the cubic convolution kernel of Keys.

/// Bilinear sample of a row-major `w × h` plane at (x, y), clamped to the image.
pub(crate) fn sample_bilinear(data: &[f32], w: usize, h: usize, x: f64, y: f64) -> f64 {
    let x = x.clamp(0.0, (w - 1) as f64);
    let y = y.clamp(0.0, (h - 1) as f64);
    let (x0, y0) = ((x.floor() as usize).min(w.saturating_sub(2)), (y.floor() as usize).min(h.saturating_sub(2)));
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let at = |x: usize, y: usize| f64::from(data[y * w + x]);
    let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
    let bottom = at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx;
    top * (1.0 - fy) + bottom * fy
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
