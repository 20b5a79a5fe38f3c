//! The pair checks that read the answer as well as the views.
//!
//! - **A range that clips the scene**: a given range (`--ndisp`, calib.txt) whose top the scene reaches beyond
//!   gathers the answers of everything beyond it near its top ([`top_share`]); past [`MAX_TOP_SHARE`] the range
//!   is measured on the pair as when none is given, and a larger one is suggested when the measurement, less its
//!   margin, still exceeds the given range.
//! - **Views rotated or scaled against each other**: the right view's vertical offset, measured on the row
//!   profiles as the whole pair's is (`super::vertical_offset`), in the image's left and right thirds and in its
//!   top and bottom thirds. A rectified pair has the same offset everywhere (the alignment corrects one offset);
//!   a rotation makes it differ from left to right, a scale from top to bottom. The right view's strip is taken
//!   where the left strip's content is in it: moved by the strip's median disparity.

use crate::image::{DisparityMap, Plane};

/// The answers within this many pixels of a given range's top count as piled up there.
pub(super) const TOP_BAND_PX: f32 = 4.0;

/// More of the valid answers than this share within [`TOP_BAND_PX`] of a given range's top: they pile up there.
/// On MiddEval3 trainingQ with its stated ranges at most 0.4 % do (PianoL); with ranges that clip half the scene
/// (24 or 32 on Adirondack, ArtL, Motorcycle, Teddy) 5.8–29 %.
pub(super) const MAX_TOP_SHARE: f32 = 0.03;

/// The range measurement's margin (`crate::setup::range::find_ndisp`: two labels at 1/4 resolution and 8 px): a
/// measured range suggests a larger one only when it exceeds the given one by more.
pub(super) const MEASURE_MARGIN_PX: usize = 16;

/// A vertical offset that differs by more than this (px) between the thirds of the image: rotated or scaled.
pub(super) const MAX_OFFSET_SPREAD_PX: f32 = 1.5;

/// The share of the valid answers (finite) within [`TOP_BAND_PX`] of `top`, the given range's largest disparity.
pub(super) fn top_share(disparity: &DisparityMap, top: usize) -> f32 {
    let valid = disparity.data().iter().filter(|d| d.is_finite());
    let near_top = |d: f32| usize::from(d >= top as f32 - TOP_BAND_PX);
    let (n, at_top) = valid.fold((0usize, 0usize), |(n, t), &d| (n + 1, t + near_top(d)));
    at_top as f32 / n.max(1) as f32
}

/// The profile correlation a third's offset needs to count. A third is measured without the whole image's test
/// (an offset clearly better than none): a rotation puts small offsets of opposite signs in the two thirds.
const MIN_THIRD_CORRELATION: f64 = 0.5;

/// The right view's vertical offset (px) in the left and the right third of the image and in its top and bottom
/// third (see the module doc); a third whose offset cannot be measured is estimated from the middle third's
/// ([`or_from_middle`]), and `None` when that cannot be measured either.
pub(super) fn offsets_by_third(left: &Plane<f32>, right: &Plane<f32>, disparity: &DisparityMap) -> [Option<f32>; 4] {
    let (w, h) = left.dims();
    let (third_w, third_h) = (w / 3, h / 3);
    let test = super::OffsetTest::Correlation(MIN_THIRD_CORRELATION);
    let columns = |x0: usize| {
        let shift = median_disparity(disparity, x0..x0 + third_w).min(x0);
        let (l, r) = (left.columns(x0..x0 + third_w), right.columns(x0 - shift..x0 - shift + third_w));
        super::vertical_offset_within(&l, &r, 0..h, test)
    };
    let rows = |y0: usize| super::vertical_offset_within(left, right, y0..y0 + third_h, test);
    let [l, r] = or_from_middle(columns(0), columns(w - third_w), || columns(third_w));
    let [t, b] = or_from_middle(rows(0), rows(h - third_h), || rows(third_h));
    [l, r, t, b]
}

/// The offsets of two outer thirds, one that was not measured estimated from the other and the middle third's
/// (measured only then): the offset changes linearly across the image under a rotation or a scale.
fn or_from_middle(a: Option<f32>, b: Option<f32>, middle: impl FnOnce() -> Option<f32>) -> [Option<f32>; 2] {
    match (a, b) {
        (Some(_), Some(_)) | (None, None) => [a, b],
        _ => {
            let m = middle();
            [a.or_else(|| Some(2.0 * m? - b?)), b.or_else(|| Some(2.0 * m? - a?))]
        }
    }
}

/// The median of the valid disparities in the columns `cols` (0 when there is none), rounded to a pixel.
fn median_disparity(disparity: &DisparityMap, cols: std::ops::Range<usize>) -> usize {
    let (w, h) = disparity.dims();
    let mut values: Vec<f32> = (0..h)
        .flat_map(|y| cols.clone().map(move |x| y * w + x))
        .map(|i| disparity.data()[i])
        .filter(|d| d.is_finite() && *d >= 0.0)
        .collect();
    if values.is_empty() {
        return 0;
    }
    crate::imgproc::stats::rank_value(&mut values, 0.5).round() as usize
}
