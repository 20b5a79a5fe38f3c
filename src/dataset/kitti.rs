//! The KITTI stereo layouts (2012 and 2015 training/testing trees as distributed) and the devkit's handling of
//! invalid result pixels ([`crate::eval::interpolate_background`]).

use std::path::Path;

use super::{Layout, Pair, Purpose};

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
/// as missing its result (never dropped without a word). For [`Purpose::Score`], none unless the tree has a truth folder: the non-occluded one or the
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
