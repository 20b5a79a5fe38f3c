//! Left-right consistency check (paper §4).
//!
//! Left pixel x with disparity d_L(x) corresponds to right pixel x' = x − round(d_L(x)). It is *consistent* when
//! x' is inside the image and |d_L(x) − d_R(x')| ≤ `thresh_px`. Two treatments of inconsistent pixels:
//! - [`LrcMode::Correct`] — the two-step method's LRC (Mozerov & van de Weijer), used by the paper's Tables 1–2:
//!   the pixel takes min(d_L(x), d_R(x')) (or its own value when x' is outside), so the map stays dense.
//!   Occlusions are where the background should win, and the smaller disparity is the background one.
//! - [`LrcMode::Invalidate`] — the pixel becomes `inf` for the later stages.

use rayon::prelude::*;

use crate::image::{DisparityMap, Plane};
use crate::params::LrcMode;

/// Marks where the left map agrees with the right map: `true` = consistent.
///
/// # Panics
/// If the maps differ in size.
pub fn consistency_mask(left: &DisparityMap, right: &DisparityMap, thresh_px: f32) -> Plane<bool> {
    assert_eq!(left.dims(), right.dims(), "left and right disparity maps differ in size");
    let w = left.width;
    let mut mask = Plane::new(left.width, left.height, false);
    mask.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let (lrow, rrow) = (left.row(y), right.row(y));
        for (x, ok) in row.iter_mut().enumerate() {
            let d = lrow[x];
            *ok = match matching_x(x, d, w) {
                Some(xr) => (d - rrow[xr]).abs() <= thresh_px,
                None => false,
            };
        }
    });
    mask
}

/// Where the left map's own pixels see their match in the right view: each left pixel goes to its match x − round(d),
/// the largest disparity (the nearest surface) winning per right pixel, and a pixel is visible when the winner at its
/// match is within `thresh_px` of its own disparity. What the left map alone says about occlusion: a pixel whose
/// match a nearer surface of the map covers is hidden. `false` where the match is outside the view or d is not
/// finite.
pub fn visible_in_right(left: &DisparityMap, thresh_px: f32) -> Plane<bool> {
    let w = left.width;
    let mut mask = Plane::new(left.width, left.height, false);
    mask.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
        let lrow = left.row(y);
        let mut nearest = vec![f32::NEG_INFINITY; w];
        for (x, &d) in lrow.iter().enumerate() {
            if let Some(xr) = matching_x(x, d, w) {
                nearest[xr] = nearest[xr].max(d);
            }
        }
        for (x, ok) in row.iter_mut().enumerate() {
            let d = lrow[x];
            *ok = matching_x(x, d, w).is_some_and(|xr| nearest[xr] - d <= thresh_px);
        }
    });
    mask
}

/// x − round(d) when that is a valid column and d is finite.
#[inline]
fn matching_x(x: usize, d: f32, width: usize) -> Option<usize> {
    if !d.is_finite() {
        return None;
    }
    let xr = x as f32 - d.round();
    (xr >= 0.0 && xr < width as f32).then_some(xr as usize)
}

/// Applies the check to the left map. Returns the new map and the consistency mask.
///
/// # Panics
/// If the maps differ in size.
pub fn left_right_check(
    left: &DisparityMap,
    right: &DisparityMap,
    mode: LrcMode,
    thresh_px: f32,
) -> (DisparityMap, Plane<bool>) {
    let mask = consistency_mask(left, right, thresh_px);
    let w = left.width;
    let mut out = left.clone();
    match mode {
        LrcMode::Off => {}
        LrcMode::Invalidate => {
            out.data.iter_mut().zip(&mask.data).filter(|(_, ok)| !**ok).for_each(|(d, _)| *d = f32::INFINITY);
        }
        LrcMode::Correct => {
            out.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
                let (mrow, rrow) = (mask.row(y), right.row(y));
                for (x, d) in row.iter_mut().enumerate() {
                    if !mrow[x]
                        && let Some(xr) = matching_x(x, *d, w)
                    {
                        *d = d.min(rrow[xr]);
                    }
                }
            });
        }
    }
    (out, mask)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(w: usize, v: &[f32]) -> DisparityMap {
        Plane::from_parts(w, v.len() / w, v.to_vec())
    }

    #[test]
    fn consistent_shift_passes() {
        // Constant disparity 2 on both views: consistent wherever x − 2 is in the image.
        let l = map(6, &[2.0; 6]);
        let r = map(6, &[2.0; 6]);
        let m = consistency_mask(&l, &r, 1.0);
        assert_eq!(m.data, vec![false, false, true, true, true, true]);
    }

    #[test]
    fn invalidate_and_correct() {
        let l = map(5, &[0.0, 1.0, 3.0, 1.0, 1.4]);
        let r = map(5, &[0.0, 1.0, 0.0, 5.0, 1.0]);
        // x=0: d 0 → xr 0, |0−0| ok. x=1: xr 0, |1−0| = 1 ok. x=2: d 3 → xr −1 out → invalid.
        // x=3: xr 2, |1−0| = 1 ok. x=4: d 1.4 → xr 3, |1.4−5| > 1 → invalid, corrected to min(1.4, 5) = 1.4.
        let (inv, mask) = left_right_check(&l, &r, LrcMode::Invalidate, 1.0);
        assert_eq!(mask.data, vec![true, true, false, true, false]);
        assert!(inv.data[2].is_infinite() && inv.data[4].is_infinite());
        assert_eq!(inv.data[3], 1.0);
        let (cor, _) = left_right_check(&l, &r, LrcMode::Correct, 1.0);
        assert_eq!(cor.data, vec![0.0, 1.0, 3.0, 1.0, 1.4]);
        let r2 = map(5, &[0.0, 1.0, 0.0, 0.2, 1.0]);
        let (cor, _) = left_right_check(&map(5, &[0.0, 0.0, 0.0, 0.0, 1.6]), &r2, LrcMode::Correct, 0.5);
        // x=4: d 1.6 → xr 2 (round 2), |1.6−0| > 0.5 → min(1.6, 0) = 0.
        assert_eq!(cor.data[4], 0.0);
    }

    #[test]
    fn a_pixel_is_hidden_where_a_nearer_surface_of_the_map_covers_its_match() {
        // x = 1..=3 (d 1) match 0..=2; x = 5 (d 4) matches 1 and covers x = 2's match; x = 4 (d 9) leaves the view.
        let l = map(6, &[0.0, 1.0, 1.0, 1.0, 9.0, 4.0]);
        assert_eq!(visible_in_right(&l, 1.0).data, vec![true, true, false, true, false, true]);
        // Within the tolerance a nearer surface does not hide: x = 3 at d 1.8 matches 1, as x = 2 at d 1 does.
        let l = map(6, &[0.0, 1.0, 1.0, 1.8, f32::INFINITY, 0.0]);
        assert_eq!(visible_in_right(&l, 1.0).data, vec![true, true, true, true, false, true]);
    }

    #[test]
    fn off_keeps_the_map() {
        let l = map(3, &[5.0, 0.0, 1.0]);
        let (out, _) = left_right_check(&l, &map(3, &[0.0; 3]), LrcMode::Off, 1.0);
        assert_eq!(out, l);
    }
}
