//! Label windows: a tile of [`super::tile`] whose disparities the coarse answer puts in a narrow part of the range
//! is matched on those labels only, its right views shifted so that label d' is disparity lo + d'.

use crate::error::Result;
use crate::image::{DisparityMap, Plane, RgbImage, StereoPair};

/// A rectangle `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Rect {
    pub x0: usize,
    pub y0: usize,
    pub x1: usize,
    pub y1: usize,
}

/// The label window `(lo, labels)` that holds every finite disparity of `coarse` inside `r`, widened by `margin`
/// labels and clipped to `0..ndisp`; `None` when there is no finite disparity there.
pub(crate) fn window_in(coarse: &DisparityMap, r: Rect, ndisp: usize, margin: usize) -> Option<(usize, usize)> {
    let (mut dmin, mut dmax) = (f32::INFINITY, f32::NEG_INFINITY);
    for y in r.y0..r.y1 {
        for &d in coarse.row(y)[r.x0..r.x1].iter().filter(|d| d.is_finite()) {
            dmin = dmin.min(d);
            dmax = dmax.max(d);
        }
    }
    if !dmin.is_finite() {
        return None;
    }
    // (A negative disparity counts as 0: the casts saturate.)
    let lo = (dmin.floor() as usize).saturating_sub(margin).min(ndisp - 1);
    let hi = (dmax.ceil() as usize + margin).clamp(lo, ndisp - 1);
    Some((lo, hi - lo + 1))
}

/// The crop `r` of the guidance and the cost pair, right views shifted by `lo` columns ([`cut`]), with `labels`
/// labels; the cost pair is `None` when it is the guidance pair itself.
pub(crate) fn cut_pairs(
    guide: &StereoPair,
    cost: &StereoPair,
    r: Rect,
    lo: usize,
    labels: usize,
) -> Result<(StereoPair<'static>, Option<StereoPair<'static>>)> {
    let pair = |p: &StereoPair| StereoPair::new(cut(&p.left, r, 0), cut(&p.right, r, lo), labels);
    let cost = if std::ptr::eq(guide, cost) { None } else { Some(pair(cost)?) };
    Ok((pair(guide)?, cost))
}

/// The crop `r` of `img`, shifted left by `shift` columns (column x of the crop is column `r.x0 + x − shift` of
/// the image; columns left of the image repeat its first column).
fn cut(img: &RgbImage, r: Rect, shift: usize) -> RgbImage {
    let (cw, ch) = (r.x1 - r.x0, r.y1 - r.y0);
    let mut out = RgbImage::new(cw, ch);
    for (dst, src) in out.channels.iter_mut().zip(&img.channels) {
        for y in 0..ch {
            let row = &src[(r.y0 + y) * img.width..][..img.width];
            for (x, v) in dst[y * cw..][..cw].iter_mut().enumerate() {
                *v = row[(r.x0 + x).saturating_sub(shift)];
            }
        }
    }
    out
}

/// The crop `r` of a plane, each value mapped by `f`.
pub(crate) fn cut_plane(p: &Plane<f32>, r: Rect, f: impl Fn(f32) -> f32) -> Plane<f32> {
    let (cw, ch) = (r.x1 - r.x0, r.y1 - r.y0);
    let mut data = Vec::with_capacity(cw * ch);
    for y in r.y0..r.y1 {
        data.extend(p.row(y)[r.x0..r.x1].iter().map(|&v| f(v)));
    }
    Plane::from_parts(cw, ch, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_label_window_holds_the_finite_disparities_and_its_margin() {
        let coarse = Plane::from_parts(3, 2, vec![10.2, f32::INFINITY, 20.7, 3.0, 40.0, 2.5]);
        let top = Rect { x0: 0, y0: 0, x1: 3, y1: 1 };
        assert_eq!(window_in(&coarse, top, 100, 4), Some((6, 20)));
        assert_eq!(window_in(&coarse, top, 24, 4), Some((6, 18)), "clipped to the range");
        let middle = Rect { x0: 1, y0: 0, x1: 2, y1: 1 };
        assert_eq!(window_in(&coarse, middle, 100, 4), None, "no finite disparity");
        let all = Rect { x0: 0, y0: 0, x1: 3, y1: 2 };
        assert_eq!(window_in(&coarse, all, 100, 0), Some((2, 39)));
    }

    #[test]
    fn cut_shifts_and_repeats_the_first_column() {
        let mut img = RgbImage::new(6, 2);
        for (i, v) in img.channels[0].iter_mut().enumerate() {
            *v = i as f32;
        }
        let c = cut(&img, Rect { x0: 1, y0: 1, x1: 4, y1: 2 }, 2);
        // Columns 1−2, 2−2, 3−2 of row 1 → −1 (repeats column 0), 0, 1.
        assert_eq!(c.channels[0], vec![6.0, 6.0, 7.0]);
        let c = cut(&img, Rect { x0: 2, y0: 0, x1: 5, y1: 1 }, 0);
        assert_eq!(c.channels[0], vec![2.0, 3.0, 4.0]);
    }
}
