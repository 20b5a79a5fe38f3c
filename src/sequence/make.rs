//! Sequences made from one scene with ground truth ([`sequence_from_scene`], `jem degrade --frames`): a static
//! camera whose sensor noise is fresh each frame, or a window sliding across the pair (a camera panning over a
//! static scene), or both. The ground truth of every frame is exact: the scene's, cropped with the frame.
//!
//! Frame `k` is the window of columns `k·pan .. k·pan + W'` of both views, `W' = W − (N − 1)·pan` (cropping both
//! views at the same columns keeps the pair rectified and every disparity as it was), degraded by the recipe
//! with its own seed ([`frame_seed`]). Its ground truth is the scene's `disp0GT.pfm` cropped the same way, its mask
//! the scene's `mask0nocc.png` cropped, with the pixels whose match falls left of the right window (`x − d < 0`)
//! marked occluded. `calib.txt` is the scene's with `width` set to `W'` (`cam0`/`cam1` are the first frame's).

use std::path::Path;

use super::write::{SequenceFrame, write_sequence};
use crate::dataset::{CALIB_FILE, LEFT_FILE, RIGHT_FILE};
use crate::degrade::{Recipe, View};
use crate::error::{Error, Result};
use crate::image::{Plane, RgbImage};

/// How to make a sequence from a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct FromScene {
    /// Frames to write (at least 2).
    pub frames: usize,
    /// What each frame's views go through (an empty recipe leaves them clean).
    pub recipe: Recipe,
    /// The seed of the first frame's noise; frame k's is [`frame_seed`]`(seed, k)`.
    pub seed: u64,
    /// Columns the window moves right per frame (0: a static camera).
    pub pan_px: usize,
}

/// The narrowest window a pan may leave.
const MIN_WINDOW_PX: usize = 32;

/// The noise seed of frame `k` of a sequence seeded `seed`: a different stream per frame, the same on every run.
pub fn frame_seed(seed: u64, k: usize) -> u64 {
    crate::rng::mix64(seed ^ crate::rng::mix64(k as u64 + 1))
}

/// Writes the sequence `how` describes, made from the MiddEval3 scene folder `scene` (`im0.png`, `im1.png`,
/// `calib.txt`; `disp0GT.pfm` and `mask0nocc.png` when it has them), into `out` (see [`write_sequence`] for how
/// it is written). Returns the number of frames.
///
/// # Errors
/// [`Error::InvalidParam`] for fewer than 2 frames or a pan that leaves a window narrower than 32 px;
/// [`Error::InputImage`] for a ground truth or mask of another size than the images; unreadable files, naming them;
/// as [`write_sequence`].
pub fn sequence_from_scene(scene: &Path, out: &Path, how: &FromScene) -> Result<usize> {
    if how.frames < 2 {
        return Err(Error::param("--frames", how.frames, "at least 2"));
    }
    let (left, right) = crate::io::png::load_rgb_pair(&scene.join(LEFT_FILE), &scene.join(RIGHT_FILE))?;
    let (w, h) = left.dims();
    let travel = (how.frames - 1).saturating_mul(how.pan_px);
    if travel + MIN_WINDOW_PX > w {
        return Err(Error::param(
            "--pan",
            how.pan_px,
            format!(
                "at most {} px for {} frames of a {w} px wide scene",
                (w - MIN_WINDOW_PX) / (how.frames - 1),
                how.frames
            ),
        ));
    }
    let window = w - travel;
    let truth = crate::dataset::Truth::in_scene(scene);
    let gt_path = truth.disparity;
    let gt = gt_path.is_file().then(|| crate::io::pfm::read_pfm(&gt_path)).transpose()?;
    let mask_path = truth.mask.unwrap_or_default();
    let mask = mask_path.is_file().then(|| crate::io::png::load_grey8(&mask_path)).transpose()?;
    if let Some(g) = &gt {
        crate::eval::check_size(&gt_path, "ground truth", g.dims(), "the images", (w, h))?;
    }
    if let Some(m) = &mask {
        crate::eval::check_size(&mask_path, "mask", m.dims(), "the images", (w, h))?;
    }
    let calib_path = scene.join(CALIB_FILE);
    let calib = String::from_utf8(crate::io::read_capped(&calib_path, crate::io::MAX_CALIB_BYTES, CALIB_FILE)?)
        .map_err(|_| Error::Calib { path: calib_path.clone(), msg: "not a text file".into() })?;
    let calib = calib_with_width(&calib, window);
    let note = format!(
        "made from {} by jem {}: {} frames, window {window} px moving {} px per frame, recipe {}, seed {}\n",
        scene.display(),
        env!("CARGO_PKG_VERSION"),
        how.frames,
        how.pan_px,
        how.recipe,
        how.seed
    );
    let mut frame = |k: usize| -> Result<SequenceFrame> {
        let x0 = k * how.pan_px;
        let seed = frame_seed(how.seed, k);
        let crop_rgb =
            |img: &RgbImage, view| crate::degrade::degrade(&crop_image(img, x0, window), &how.recipe, view, seed);
        let gt = gt.as_ref().map(|g| crop_plane(g, x0, window));
        let mask = mask.as_ref().map(|m| {
            let mut m = crop_plane(m, x0, window);
            if let Some(g) = &gt {
                occlude_outside(&mut m, g);
            }
            m
        });
        Ok(SequenceFrame { left: crop_rgb(&left, View::Left)?, right: crop_rgb(&right, View::Right)?, gt, mask })
    };
    let mut files = || vec![(CALIB_FILE, calib.clone()), ("made.txt", note.clone())];
    Ok(write_sequence(out, how.frames, &mut frame, &mut files)?.len())
}

/// Columns `x0 .. x0 + width` of a plane.
fn crop_plane<T: Copy>(plane: &Plane<T>, x0: usize, width: usize) -> Plane<T> {
    let data = (0..plane.height).flat_map(|y| plane.row(y)[x0..x0 + width].iter().copied()).collect();
    Plane::from_parts(width, plane.height, data)
}

/// Columns `x0 .. x0 + width` of an image.
fn crop_image(img: &RgbImage, x0: usize, width: usize) -> RgbImage {
    let mut out = RgbImage::new(width, img.height);
    for (dst, src) in out.channels.iter_mut().zip(&img.channels) {
        for (y, row) in dst.chunks_exact_mut(width).enumerate() {
            row.copy_from_slice(&src[y * img.width + x0..][..width]);
        }
    }
    out
}

/// Marks occluded (128) the non-occluded pixels whose match `x − d` falls left of the image (`< 0`).
fn occlude_outside(mask: &mut Plane<u8>, gt: &Plane<f32>) {
    let w = mask.width;
    for (i, (m, &d)) in mask.data.iter_mut().zip(&gt.data).enumerate() {
        if *m == 255 && d.is_finite() && ((i % w) as f32) < d {
            *m = 128;
        }
    }
}

/// A `calib.txt` with its `width` line set to `width` (added when it has none).
fn calib_with_width(text: &str, width: usize) -> String {
    let mut found = false;
    let mut out: String = text
        .lines()
        .map(|l| {
            if l.trim_start().starts_with("width=") {
                found = true;
                format!("width={width}\n")
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    if !found {
        out.push_str(&format!("width={width}\n"));
    }
    out
}
