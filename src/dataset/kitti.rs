//! The KITTI stereo layouts (2012 and 2015 training/testing trees as distributed) and the devkit's handling of
//! invalid result pixels ([`interpolate_background`]).

use std::path::Path;

use super::{Layout, Pair, Purpose};
use crate::image::DisparityMap;

/// The image folders of each layout, the first pair found is used: (left, right).
const IMAGES_2015: [(&str, &str); 1] = [("image_2", "image_3")];
const IMAGES_2012: [(&str, &str); 2] = [("colored_0", "colored_1"), ("image_0", "image_1")];

/// The ground-truth folders: (non-occluded, all).
pub(super) fn truth_folders(layout: Layout) -> (&'static str, &'static str) {
    match layout {
        Layout::Kitti2012 => ("disp_noc", "disp_occ"),
        _ => ("disp_noc_0", "disp_occ_0"),
    }
}

/// The left and right image folders of a KITTI tree at `dir`, and its layout; `None` if `dir` is not one.
fn image_folders(dir: &Path) -> Option<(Layout, &'static str, &'static str)> {
    let both = |(l, r): &(&str, &str)| dir.join(l).is_dir() && dir.join(r).is_dir();
    if let Some((l, r)) = IMAGES_2015.iter().find(|p| both(p)) {
        return Some((Layout::Kitti2015, l, r));
    }
    IMAGES_2012.iter().find(|p| both(p)).map(|(l, r)| (Layout::Kitti2012, *l, *r))
}

/// The KITTI layout of the tree at `dir`, if it is one.
pub(super) fn recognise(dir: &Path) -> Option<Layout> {
    image_folders(dir).map(|(layout, _, _)| layout)
}

/// The frames of the KITTI tree at `dir`: every `*_10.png` of the left folder, sorted by name. A frame whose
/// right image is missing is listed all the same, so that `jem batch` reports it as a failed scene and `jem eval`
/// as missing its result (issue 41: it disappeared without a word). For [`Purpose::Score`], none unless the tree has a truth folder: the non-occluded one or the
/// one of all pixels (many published samples ship only `disp_occ_0/`, which `--mask all` needs alone).
pub(super) fn frames(dir: &Path, layout: Layout, purpose: Purpose) -> Vec<Pair> {
    let Some((_, left, right)) = image_folders(dir) else { return Vec::new() };
    let (noc, occ) = truth_folders(layout);
    if purpose == Purpose::Score && !dir.join(noc).is_dir() && !dir.join(occ).is_dir() {
        return Vec::new();
    }
    let Ok(entries) = std::fs::read_dir(dir.join(left)) else { return Vec::new() };
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| e.file_name().to_str().map(str::to_owned))
        .filter(|n| n.ends_with("_10.png") && !n.starts_with('.'))
        .collect();
    names.sort();
    names
        .into_iter()
        .map(|n| Pair {
            layout,
            name: n.trim_end_matches(".png").to_string(),
            root: dir.to_path_buf(),
            left: dir.join(left).join(&n),
            right: dir.join(right).join(&n),
            calib: None,
        })
        .collect()
}

/// Fills the invalid (non-finite) pixels of a result the way the KITTI development kit does before it scores
/// one: along each row, a run of invalid pixels between two valid ones takes the smaller (farther) of their
/// disparities and runs touching a row's ends take the nearest valid value of the row — the paper's occlusion fill
/// ([`crate::post::fill::fill_occlusions_in_place`]) — then the rows above the first and below the last row with
/// a valid pixel copy that row (rows without one between two such rows stay invalid, as in the devkit). A map
/// with no valid pixel is left as it is.
pub fn interpolate_background(map: &mut DisparityMap) {
    let (w, h) = map.dims();
    crate::post::fill::fill_occlusions_in_place(map);
    // Rows are now either all valid or all invalid; the invalid ones copy the nearest valid row (above first,
    // as the devkit extrapolates upwards from the first valid pixel of each column, then downwards).
    let valid_rows: Vec<usize> = (0..h).filter(|&y| map.data[y * w].is_finite()).collect();
    let (Some(&top), Some(&bottom)) = (valid_rows.first(), valid_rows.last()) else { return };
    for y in (0..top).chain(bottom + 1..h) {
        let src = if y < top { top } else { bottom };
        map.data.copy_within(src * w..(src + 1) * w, y * w);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Plane;

    const INF: f32 = f32::INFINITY;

    #[test]
    fn background_interpolation_by_hand() {
        // Rows 0 and 3: gaps between valid pixels take the smaller neighbour, the ends the nearest value.
        // Rows 1 and 2 have no valid pixel and lie between valid rows: they stay invalid, as in the devkit.
        let rows: [[f32; 6]; 4] =
            [[INF, 5.0, INF, INF, 2.0, INF], [INF; 6], [INF; 6], [1.0, INF, 3.0, f32::NAN, 7.0, 8.0]];
        let mut m = Plane::from_vec(6, 4, rows.concat());
        interpolate_background(&mut m);
        assert_eq!(&m.data[..6], &[5.0, 5.0, 2.0, 2.0, 2.0, 2.0]);
        assert!(m.data[6..18].iter().all(|d| d.is_infinite()), "{:?}", &m.data[6..18]);
        assert_eq!(&m.data[18..], &[1.0, 1.0, 3.0, 3.0, 7.0, 8.0]);

        let mut m = Plane::from_vec(2, 3, vec![INF, INF, 4.0, INF, INF, INF]);
        interpolate_background(&mut m);
        assert_eq!(m.data, vec![4.0; 6]);
        let mut empty = Plane::from_vec(2, 1, vec![INF, INF]);
        interpolate_background(&mut empty);
        assert!(empty.data.iter().all(|d| d.is_infinite()));
    }
}
