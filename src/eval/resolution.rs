//! The resolution of MiddEval3 data, for the factor that brings errors to full-resolution pixels: from the path
//! (`trainingQ`, `testH`, ...: [`scale_from_path`]) or, for a copy whose folders are named otherwise, from what it
//! holds: MiddEval3's 30 scenes have known sizes ([`QUARTER_SIZES`]), so a scene folder's name and its image's
//! size tell its resolution ([`scene_resolution`]), and so does a ground-truth file's size, alone when only one
//! resolution has a scene of that size ([`file_resolution`]).

use std::path::Path;

/// The width × height of each MiddEval3 scene's `im0.png` at quarter resolution (`trainingQ`, `testQ`); half
/// resolution is about twice these, full resolution about four times (within a few pixels: the sizes were
/// rounded at each reduction).
pub const QUARTER_SIZES: [(&str, (usize, usize)); 30] = [
    ("Adirondack", (718, 496)),
    ("ArtL", (347, 277)),
    ("Jadeplant", (659, 497)),
    ("Motorcycle", (741, 497)),
    ("MotorcycleE", (741, 497)),
    ("Piano", (707, 481)),
    ("PianoL", (707, 481)),
    ("Pipes", (735, 485)),
    ("Playroom", (699, 476)),
    ("Playtable", (680, 463)),
    ("PlaytableP", (681, 462)),
    ("Recycle", (720, 486)),
    ("Shelves", (738, 497)),
    ("Teddy", (450, 375)),
    ("Vintage", (722, 480)),
    ("Australia", (715, 492)),
    ("AustraliaP", (717, 492)),
    ("Bicycle2", (713, 488)),
    ("Classroom2", (750, 474)),
    ("Classroom2E", (750, 474)),
    ("Computer", (332, 277)),
    ("Crusade", (720, 474)),
    ("CrusadeP", (720, 479)),
    ("Djembe", (719, 494)),
    ("DjembeL", (719, 494)),
    ("Hoops", (721, 498)),
    ("Livingroom", (742, 496)),
    ("Newkuba", (701, 487)),
    ("Plants", (710, 496)),
    ("Staircase", (690, 468)),
];

/// The resolution scale implied by a path: the innermost component named `training`, `test` or `additional`
/// followed by `Q` (4), `H` (2) or `F` (1), as in MiddEval3's `trainingQ`. `None` if there is none.
pub fn scale_from_path(path: &Path) -> Option<u32> {
    path.components().rev().find_map(|c| {
        let name = c.as_os_str().to_str()?;
        let rest = ["training", "test", "additional"].iter().find_map(|p| name.strip_prefix(p))?;
        match rest {
            "Q" => Some(4),
            "H" => Some(2),
            "F" => Some(1),
            _ => None,
        }
    })
}

/// How a resolution was found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ScaleSource {
    /// A folder of the path is named `trainingQ`, `testH`, ... ([`scale_from_path`]).
    Path,
    /// The scene's folder name is a MiddEval3 scene's and its image (or ground truth) has that scene's size at
    /// this resolution.
    SceneSize {
        /// The scene.
        scene: String,
        /// The size measured.
        size: (usize, usize),
    },
    /// A ground truth whose size only scenes of this resolution have.
    UniqueSize {
        /// The size measured.
        size: (usize, usize),
    },
}

/// A MiddEval3 resolution and how it was found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Resolution {
    /// The factor to full-resolution pixels: 4 (Q), 2 (H) or 1 (F).
    pub scale: u32,
    /// How it was found.
    pub source: ScaleSource,
}

impl Resolution {
    /// `quarter resolution (errors ×4)`.
    pub fn name(&self) -> String {
        resolution_name(self.scale)
    }

    /// Whether it was read from the data (not from a folder's name).
    pub fn from_contents(&self) -> bool {
        self.source != ScaleSource::Path
    }

    /// What told it, in words: `Teddy is 450×375, its quarter-resolution size`.
    pub fn reason(&self) -> String {
        let res = match self.scale {
            4 => "quarter",
            2 => "half",
            _ => "full",
        };
        match &self.source {
            ScaleSource::Path => "the folder's name".into(),
            ScaleSource::SceneSize { scene, size } => {
                format!("{scene} is {}×{}, its {res}-resolution size", size.0, size.1)
            }
            ScaleSource::UniqueSize { size } => {
                format!("{}×{} is the size of a MiddEval3 scene at {res} resolution only", size.0, size.1)
            }
        }
    }
}

/// `quarter resolution (errors ×4)`, `half resolution (errors ×2)`, `full resolution`.
pub fn resolution_name(scale: u32) -> String {
    match scale {
        4 => "quarter resolution (errors ×4)".into(),
        2 => "half resolution (errors ×2)".into(),
        1 => "full resolution".into(),
        s => format!("errors ×{s}"),
    }
}

/// The factors a size fits for a scene's quarter-resolution size `q`: `w` within `k + 1` pixels of `k·q.0`, `h`
/// likewise, for `k` = 1 (Q, scale 4), 2 (H, scale 2), 4 (F, scale 1).
fn scales_fitting(q: (usize, usize), size: (usize, usize)) -> impl Iterator<Item = u32> {
    [(1usize, 4u32), (2, 2), (4, 1)].into_iter().filter_map(move |(k, scale)| {
        let near = |v: usize, qv: usize| v.abs_diff(k * qv) <= k + 1;
        (near(size.0, q.0) && near(size.1, q.1)).then_some(scale)
    })
}

/// The resolution of the MiddEval3 scene `scene` at `size`, if the name is a MiddEval3 scene's and the size fits
/// one of its resolutions.
pub fn scale_from_scene_size(scene: &str, size: (usize, usize)) -> Option<u32> {
    let (_, q) = QUARTER_SIZES.iter().find(|(name, _)| *name == scene)?;
    scales_fitting(*q, size).next()
}

/// The one resolution at which some MiddEval3 scene has `size`; `None` when none does or several do.
pub fn scale_from_any_size(size: (usize, usize)) -> Option<u32> {
    let mut found = QUARTER_SIZES.iter().flat_map(|(_, q)| scales_fitting(*q, size));
    let first = found.next()?;
    found.all(|s| s == first).then_some(first)
}

/// The size of a disparity file from its header when it is a PFM, else by reading it.
fn disparity_size(path: &Path) -> Option<(usize, usize)> {
    let is_pfm = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("pfm"));
    if is_pfm {
        return crate::io::pfm::read_pfm_size(path).ok();
    }
    crate::io::read_disparity(path).ok().map(|m| m.dims())
}

/// The resolution of a MiddEval3 scene folder: from its path, else from its name and the size of its `im0.png`
/// (its header only), else of its `disp0GT.pfm`. `None` when nothing tells.
pub fn scene_resolution(scene: &Path) -> Option<Resolution> {
    let resolved = std::fs::canonicalize(scene).unwrap_or_else(|_| scene.to_path_buf());
    if let Some(scale) = scale_from_path(&resolved) {
        return Some(Resolution { scale, source: ScaleSource::Path });
    }
    let name = resolved.file_name()?.to_str()?.to_string();
    let size = crate::io::read_image_header(&scene.join(crate::dataset::LEFT_FILE))
        .ok()
        .map(|h| (h.width, h.height))
        .or_else(|| disparity_size(&scene.join(crate::dataset::GT_FILE)))?;
    let scale = scale_from_scene_size(&name, size)?;
    Some(Resolution { scale, source: ScaleSource::SceneSize { scene: name, size } })
}

/// The resolution of one MiddEval3 ground-truth file: from its path, else from its folder's name (a MiddEval3
/// scene's) and its size, else from its size alone when only one resolution has a scene of that size. `None`
/// when nothing tells.
pub fn file_resolution(gt: &Path) -> Option<Resolution> {
    let resolved = std::fs::canonicalize(gt).unwrap_or_else(|_| gt.to_path_buf());
    if let Some(scale) = scale_from_path(&resolved) {
        return Some(Resolution { scale, source: ScaleSource::Path });
    }
    let size = disparity_size(gt)?;
    let folder = resolved.parent().and_then(Path::file_name).and_then(|n| n.to_str());
    if let Some(scene) = folder.filter(|f| QUARTER_SIZES.iter().any(|(n, _)| n == f)) {
        let scale = scale_from_scene_size(scene, size)?;
        return Some(Resolution { scale, source: ScaleSource::SceneSize { scene: scene.to_string(), size } });
    }
    let scale = scale_from_any_size(size)?;
    Some(Resolution { scale, source: ScaleSource::UniqueSize { size } })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_from_middeval_paths() {
        assert_eq!(scale_from_path(Path::new("/d/MiddEval3/trainingQ/Teddy")), Some(4));
        assert_eq!(scale_from_path(Path::new("MiddEval3/testH/Australia")), Some(2));
        assert_eq!(scale_from_path(Path::new("x/trainingF")), Some(1));
        assert_eq!(scale_from_path(Path::new("trainingQ/trainingH/Teddy")), Some(2));
        assert_eq!(scale_from_path(Path::new("/home/PDF/Teddy")), None);
        assert_eq!(scale_from_path(Path::new("trainingX/Teddy")), None);
    }

    #[test]
    fn a_scene_size_tells_its_resolution_within_the_rounding() {
        assert_eq!(scale_from_scene_size("Teddy", (450, 375)), Some(4));
        // Half and full resolution: about 2× and 4×, a pixel or a few off.
        assert_eq!(scale_from_scene_size("Teddy", (900, 750)), Some(2));
        assert_eq!(scale_from_scene_size("Adirondack", (1436, 992)), Some(2));
        assert_eq!(scale_from_scene_size("Adirondack", (2872, 1984)), Some(1));
        assert_eq!(scale_from_scene_size("ArtL", (1390, 1110)), Some(1));
        assert_eq!(scale_from_scene_size("ArtL", (1394, 1110)), None, "5 px off at full resolution");
        assert_eq!(scale_from_scene_size("Teddy", (452, 375)), Some(4), "2 px off at quarter resolution");
        assert_eq!(scale_from_scene_size("Teddy", (453, 375)), None, "3 px off at quarter resolution");
        assert_eq!(scale_from_scene_size("Teddy", (320, 240)), None);
        assert_eq!(scale_from_scene_size("Tiny", (450, 375)), None, "not a MiddEval3 scene");
    }

    #[test]
    fn a_size_alone_tells_the_resolution_only_when_one_fits() {
        assert_eq!(scale_from_any_size((450, 375)), Some(4));
        assert_eq!(scale_from_any_size((1800, 1500)), Some(1));
        assert_eq!(scale_from_any_size((4, 2)), None);
        // Motorcycle and MotorcycleE share a size: still one resolution.
        assert_eq!(scale_from_any_size((741, 497)), Some(4));
    }

    #[test]
    fn every_known_size_is_unambiguous_at_every_resolution() {
        for (name, q) in QUARTER_SIZES {
            for (k, scale) in [(1, 4), (2, 2), (4, 1)] {
                let size = (k * q.0, k * q.1);
                assert_eq!(scale_from_scene_size(name, size), Some(scale), "{name} ×{k}");
                assert_eq!(scale_from_any_size(size), Some(scale), "{name} ×{k} alone");
            }
        }
    }

    #[test]
    fn a_copied_scene_folder_is_recognised_by_its_name_and_image() {
        let dir = tempfile::tempdir().unwrap();
        let teddy = dir.path().join("copy").join("Teddy");
        std::fs::create_dir_all(&teddy).unwrap();
        crate::io::write_png_rgb8(&teddy.join("im0.png"), 450, 375, &vec![0; 450 * 375 * 3]).unwrap();
        let r = scene_resolution(&teddy).unwrap();
        assert_eq!(r.scale, 4);
        assert!(r.from_contents() && r.reason().contains("Teddy is 450×375"), "{}", r.reason());
        let renamed = dir.path().join("copy").join("Mine");
        std::fs::rename(&teddy, &renamed).unwrap();
        assert_eq!(scene_resolution(&renamed), None, "an unknown name tells nothing");
        let q = dir.path().join("trainingQ").join("Mine");
        std::fs::create_dir_all(&q).unwrap();
        assert_eq!(scene_resolution(&q).map(|r| (r.scale, r.source)), Some((4, ScaleSource::Path)));
    }

    #[test]
    fn a_lone_ground_truth_is_recognised_by_its_folder_or_a_unique_size() {
        let dir = tempfile::tempdir().unwrap();
        let gt = dir.path().join("gt.pfm");
        crate::io::pfm::write_pfm(&gt, &crate::image::Plane::new(900, 750, 1.0)).unwrap();
        let r = file_resolution(&gt).unwrap();
        assert_eq!((r.scale, r.source), (2, ScaleSource::UniqueSize { size: (900, 750) }));
        let in_scene = dir.path().join("Motorcycle");
        std::fs::create_dir(&in_scene).unwrap();
        crate::io::pfm::write_pfm(&in_scene.join("disp0GT.pfm"), &crate::image::Plane::new(741, 497, 1.0)).unwrap();
        assert_eq!(file_resolution(&in_scene.join("disp0GT.pfm")).map(|r| r.scale), Some(4));
        // A scene's folder with another size: its name rules the size match out, no guess from the size alone.
        crate::io::pfm::write_pfm(&in_scene.join("x.pfm"), &crate::image::Plane::new(450, 375, 1.0)).unwrap();
        assert_eq!(file_resolution(&in_scene.join("x.pfm")), None);
        crate::io::pfm::write_pfm(&gt, &crate::image::Plane::new(5, 3, 1.0)).unwrap();
        assert_eq!(file_resolution(&gt), None);
    }
}
