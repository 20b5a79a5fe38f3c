//! A search range that starts above zero (`--min-disp D`, OpenCV SGBM's `minDisparity`): disparities D…D+ndisp−1.
//!
//! The pair is cut so that the pipeline's disparity 0 is the pair's D: the left view loses its first D columns,
//! the right view its last D ([`cut_pair`]). A left pixel x (x ≥ D) at disparity D + d' matches the right pixel
//! x − D − d', which is the cut right view's pixel (x − D) − d': the cut pair is an ordinary pair whose disparities
//! are the pair's less D, and one whose match falls left of the right view's edge (x − D − d' < 0) is out of view in
//! both. So the whole pipeline — cost, inference, the left-right check (which compares the two cut views' maps,
//! both in the cut frame), fill, weighted median, planes, the range measurement, tiles — runs unchanged on the cut
//! pair. The answer is put back at its columns with D added ([`widen_output`]); the left view's first D columns,
//! whose every match at D or more would lie left of the right view, are invalid there (`inf`, confidence 0,
//! rejected by the left-right check). Depth and point clouds are computed from the widened map, in the full
//! view's pixel coordinates, so they need nothing else.
//!
//! This is the right view moved D columns to the right before matching (the design of OpenCV's `minDisparity`),
//! with the D columns that would then hold no picture dropped from both views instead of filled: the pipeline's
//! rule for matches outside the view (a constant cost) then holds for them, as it does at disparity 0.
//! D = 0 leaves the pair and the output as they are.

use crate::error::{Error, Result};
use crate::image::{Plane, RgbImage};

/// The pair as the pipeline matches it at disparities `min_disp`… (the module doc): the left view's columns
/// `min_disp..`, the right view's `..width − min_disp`.
///
/// # Errors
/// [`Error::InvalidParam`] when fewer than 2 columns would be left.
pub(crate) fn cut_pair(left: &RgbImage, right: &RgbImage, min_disp: usize) -> Result<(RgbImage, RgbImage)> {
    check(left.width().min(right.width()), min_disp)?;
    Ok((left.columns_from(min_disp), right.columns_to(right.width() - min_disp)))
}

/// Refuses a `min_disp` that leaves fewer than 2 columns of a `width`-pixel-wide pair to match.
///
/// # Errors
/// [`Error::InvalidParam`] naming `--min-disp`.
pub(crate) fn check(width: usize, min_disp: usize) -> Result<()> {
    if min_disp > 0 && min_disp + 2 > width {
        return Err(Error::param(
            "--min-disp",
            min_disp,
            format!("less than the width less 1 ({}): the views are {width} px wide", width.saturating_sub(1)),
        ));
    }
    Ok(())
}

/// `plane` (of the cut pair) put back at its columns of a view `min_disp` columns wider, the first `min_disp`
/// columns `fill`.
pub(crate) fn widen<T: Copy>(plane: &Plane<T>, min_disp: usize, fill: T) -> Plane<T> {
    let (w, h) = plane.dims();
    let mut data = Vec::with_capacity((w + min_disp) * h);
    for y in 0..h {
        data.extend(std::iter::repeat_n(fill, min_disp));
        data.extend_from_slice(plane.row(y));
    }
    Plane::from_parts(w + min_disp, h, data)
}

/// The maps of a match of the cut pair as maps of the whole left view: disparities + `min_disp`, the first
/// `min_disp` columns invalid (`inf`), of confidence 0 and rejected by the left-right check.
pub(crate) fn widen_output(
    disparity: &Plane<f32>,
    confidence: Option<&Plane<f32>>,
    consistent: &Plane<bool>,
    min_disp: usize,
) -> (Plane<f32>, Option<Plane<f32>>, Plane<bool>) {
    let mut d = widen(disparity, min_disp, f32::INFINITY);
    // `inf + D` stays `inf`; every finite value moves up by D.
    d.data_mut().iter_mut().for_each(|v| *v += min_disp as f32);
    (d, confidence.map(|c| widen(c, min_disp, 0.0)), widen(consistent, min_disp, false))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6×1 pair: the cut left view starts at column D, the cut right view ends D columns early.
    #[test]
    fn the_pair_is_cut_so_that_disparity_zero_is_min_disp() {
        let ramp = |offset: f32| {
            let c = (0..6).map(|x| x as f32 + offset).collect::<Vec<_>>();
            RgbImage::from_channels(6, 1, [c.clone(), c.clone(), c]).unwrap()
        };
        let (l, r) = cut_pair(&ramp(0.0), &ramp(100.0), 2).unwrap();
        assert_eq!(l.channel(0), [2.0, 3.0, 4.0, 5.0]);
        assert_eq!(r.channel(0), [100.0, 101.0, 102.0, 103.0]);
        assert!(cut_pair(&ramp(0.0), &ramp(0.0), 4).is_ok());
        let e = cut_pair(&ramp(0.0), &ramp(0.0), 5).unwrap_err().to_string();
        assert!(e.contains("--min-disp") && e.contains("6 px wide"), "{e}");
        assert!(check(1, 0).is_ok());
    }

    #[test]
    fn the_answer_is_put_back_with_min_disp_added() {
        let disparity = Plane::from_parts(2, 2, vec![0.0, 1.5, f32::INFINITY, 3.0]);
        let confidence = Plane::from_parts(2, 2, vec![0.5, 0.25, 0.0, 1.0]);
        let consistent = Plane::from_parts(2, 2, vec![true, false, true, true]);
        let (d, c, k) = widen_output(&disparity, Some(&confidence), &consistent, 1);
        let inf = f32::INFINITY;
        assert_eq!(d.dims(), (3, 2));
        assert_eq!(d.data(), [inf, 1.0, 2.5, inf, inf, 4.0]);
        assert_eq!(c.unwrap().data(), [0.0, 0.5, 0.25, 0.0, 0.0, 1.0]);
        assert_eq!(k.data(), [false, true, false, false, true, true]);
    }
}
