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
