//! Depth maps in colour: coloured by inverse depth (near dark red, far indigo, the disparity map's colours: a
//! depth map and its disparity map look alike), over a range robust to a few absurd depths, with a scale bar
//! labelled in the depth's unit under the picture.

use super::{Canvas, colormap, vstack};
use crate::image::Plane;
use crate::imgproc::stats::rank_value;

/// The share of the finite depths left outside the automatic range at each end: a handful of pixels put
/// kilometres away (the sky, a mismatch) must not squeeze the scene into one colour.
const RANGE_TAIL: f64 = 0.02;

/// The automatic range (near, far) of a depth map: its 2nd and 98th percentiles over positive finite values, or
/// `None` when there are none.
pub fn depth_range(depth: &Plane<f32>) -> Option<(f32, f32)> {
    let mut v: Vec<f32> = depth.data().iter().copied().filter(|z| z.is_finite() && *z > 0.0).collect();
    if v.is_empty() {
        return None;
    }
    Some((rank_value(&mut v, RANGE_TAIL), rank_value(&mut v, 1.0 - RANGE_TAIL)))
}

/// The picture of a depth map over `[near, far]`: each pixel coloured by 1/Z (pixels without depth black), and
/// under it the scale bar.
pub fn colorize_depth(depth: &Plane<f32>, near: f32, far: f32) -> Canvas {
    let scale = InverseScale::new(near, far);
    let mut data = Vec::with_capacity(depth.data().len() * 3);
    for &z in depth.data() {
        data.extend_from_slice(&if z.is_finite() && z > 0.0 { colormap(scale.t(z)) } else { [0, 0, 0] });
    }
    let picture = Canvas { width: depth.width(), height: depth.height(), data };
    let bar = scale_bar(&scale, depth.width().max(64));
    vstack(&[picture, bar], 2)
}

/// Depth to colour position: t = (1/Z − 1/far) / (1/near − 1/far), 1 at `near`, 0 at `far`.
struct InverseScale {
    near: f64,
    far: f64,
}

impl InverseScale {
    fn new(near: f32, far: f32) -> Self {
        InverseScale { near: f64::from(near.min(far)), far: f64::from(near.max(far)) }
    }

    fn t(&self, z: f32) -> f32 {
        let span = 1.0 / self.near - 1.0 / self.far;
        if !(span > 0.0 && span.is_finite()) {
            return 0.5;
        }
        ((1.0 / f64::from(z) - 1.0 / self.far) / span) as f32
    }
}

/// Glyphs 3 × 5 for the labels, one row per 3 bits (top row first, leftmost pixel the high bit).
fn glyph(c: char) -> Option<[u8; 5]> {
    Some(match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '.' => [0, 0, 0, 0, 2],
        '-' => [0, 0, 7, 0, 0],
        'e' => [0, 7, 7, 4, 7],
        _ => return None,
    })
}

/// Pixel size of a glyph's dot.
const DOT: usize = 2;

/// The width in pixels of `text` drawn by [`draw_text`].
fn text_width(text: &str) -> usize {
    text.chars().count() * 4 * DOT
}

/// Draws `text` (digits, '.', '-', 'e') in white with its top-left corner at (x0, y0), clipping at the borders.
fn draw_text(canvas: &mut Canvas, text: &str, x0: usize, y0: usize) {
    for (k, c) in text.chars().enumerate() {
        let Some(rows) = glyph(c) else { continue };
        for (r, bits) in rows.iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) == 0 {
                    continue;
                }
                for (dy, dx) in (0..DOT).flat_map(|dy| (0..DOT).map(move |dx| (dy, dx))) {
                    let (x, y) = (x0 + (4 * k + col) * DOT + dx, y0 + r * DOT + dy);
                    if x < canvas.width && y < canvas.height {
                        canvas.data[(y * canvas.width + x) * 3..][..3].copy_from_slice(&[255, 255, 255]);
                    }
                }
            }
        }
    }
}

/// A label for a round depth: as short as it prints.
fn label(v: f64) -> String {
    let s = format!("{v}");
    if s.len() <= 8 { s } else { format!("{v:.1e}") }
}

/// The colour scale under the picture: a strip from `near` (left) to `far` (right), ticks at round depths (1, 2,
/// 5 × a power of ten) labelled where they do not overlap.
fn scale_bar(scale: &InverseScale, width: usize) -> Canvas {
    const STRIP: usize = 10;
    const TICK: usize = 4;
    let mut bar = Canvas::new(width, STRIP + TICK + 2 + 5 * DOT + 2, [0, 0, 0]);
    // Position along the strip is linear in 1/Z, as the colours are.
    let x_of = |z: f64| -> f64 {
        let t = f64::from(scale.t(z as f32));
        (1.0 - t) * (width - 1) as f64
    };
    for x in 0..width {
        let t = 1.0 - x as f32 / (width - 1).max(1) as f32;
        for y in 0..STRIP {
            bar.data[(y * width + x) * 3..][..3].copy_from_slice(&colormap(t));
        }
    }
    let (near, far) = (scale.near, scale.far);
    if !(near > 0.0 && far > near && far.is_finite()) {
        return bar;
    }
    // Candidates: round depths of every decade (1, 2, 5 × 10^k), which spread over an inverse scale, and the
    // multiples of a round step that gives a few ticks, for a narrow range; drawn left to right where they fit.
    let mut values: Vec<f64> = Vec::new();
    for k in near.log10().floor() as i32..=far.log10().ceil() as i32 {
        values.extend([1.0, 2.0, 5.0].map(|m| m * 10f64.powi(k)));
    }
    let span = far - near;
    let decade = 10f64.powi(span.log10().floor() as i32);
    let step = [0.1, 0.2, 0.5, 1.0].map(|m| m * decade).into_iter().find(|s| span / s <= 8.0).unwrap_or(decade);
    let first = (near / step).ceil() as i64;
    values.extend((first..=(far / step).floor() as i64).map(|i| i as f64 * step));
    let mut ticks: Vec<(usize, f64)> =
        values.into_iter().filter(|v| (near..=far).contains(v)).map(|v| (x_of(v).round() as usize, v)).collect();
    ticks.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    ticks.dedup_by(|a, b| a.0 == b.0);
    let mut next_free = 0usize;
    for (x, v) in ticks {
        let text = label((v / step).round() * step);
        let text = if text.len() > label(v).len() { label(v) } else { text };
        let w = text_width(&text);
        let left = x.saturating_sub(w / 2).min(width.saturating_sub(w));
        if left < next_free || left + w > width {
            continue;
        }
        for y in STRIP..STRIP + TICK {
            bar.data[(y * width + x.min(width - 1)) * 3..][..3].copy_from_slice(&[255, 255, 255]);
        }
        draw_text(&mut bar, &text, left, STRIP + TICK + 2);
        next_free = left + w + 3 * DOT;
    }
    bar
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_range_leaves_out_a_few_absurd_depths() {
        let mut data: Vec<f32> = (1..=100).map(|v| v as f32).collect();
        data[99] = 4e9; // the sky, thousands of kilometres away
        data.push(f32::INFINITY);
        let (near, far) = depth_range(&Plane::from_parts(101, 1, data)).unwrap();
        assert_eq!((near, far), (3.0, 98.0));
        assert!(depth_range(&Plane::from_parts(1, 1, vec![f32::INFINITY])).is_none());
    }

    #[test]
    fn near_is_dark_red_far_is_indigo_and_no_depth_is_black() {
        let depth = Plane::from_parts(3, 1, vec![1.0, 10.0, f32::INFINITY]);
        let picture = colorize_depth(&depth, 1.0, 10.0);
        assert_eq!(picture.get(0, 0), colormap(1.0));
        assert_eq!(picture.get(1, 0), colormap(0.0));
        assert_eq!(picture.get(2, 0), [0, 0, 0]);
        // The scale bar below: near at the left.
        assert!(picture.height > 20 && picture.width == 64);
        assert_eq!(picture.get(0, 3), colormap(1.0));
    }

    #[test]
    fn labels_are_drawn_and_the_half_way_colour_is_at_the_harmonic_mean() {
        let scale = InverseScale::new(1.0, 3.0);
        // 1/Z half-way between 1 and 1/3: Z = 1.5.
        assert!((scale.t(1.5) - 0.5).abs() < 1e-6);
        let bar = scale_bar(&scale, 200);
        let white = bar.data.chunks(3).filter(|p| *p == [255, 255, 255]).count();
        assert!(white > 20, "no labels drawn");
        assert_eq!(label(0.5), "0.5");
        assert_eq!(label(2000.0), "2000");
    }
}
