//! Synthetic stereo scenes with exact ground truth, written in MiddEval3 layout.
//!
//! A scene is a slanted background plane plus 3–6 foreground objects (rectangles, discs, star-shaped polygons),
//! each a planar surface with its own disparity `d(x, y) = a·x + b·y + c` (a rectified view of any 3-D plane has
//! an affine disparity) in its own depth band, so the objects are stacked without touching and occlude each other
//! and the background. Every surface carries a seeded colourful texture: multi-scale value noise (cells of
//! 2–32 px) on top of a two-colour palette, different per surface.
//!
//! # Rendering
//! Both views are **ray-cast per sample**. A surface point is named by its left-view coordinates `(x_l, y)`; its
//! texture is a function of those, so both views see the same pattern.
//! - Left view at `(x, y)`: among the surfaces whose shape covers `(x, y)`, the one with the largest disparity.
//! - Right view at `(x_r, y)`: for each surface solve `x_l − d(x_l, y) = x_r`, i.e.
//!   `x_l = (x_r + b·y + c) / (1 − a)` (`|a| < 1` by construction), keep it if the shape covers `(x_l, y)`, and take
//!   the largest disparity.
//!
//! Pixel `x` has its centre at coordinate `x` (Middlebury: left pixel `x` matches right coordinate `x − d`).
//! Colours are the mean of a 2×2 grid of samples at `±0.25 px` (a little anti-aliasing), rounded to 8 bits. The
//! ground truth is the exact plane disparity of the surface visible at the left pixel's centre. The mask is
//! [`MASK_VISIBLE`] when that surface point is seen in the right view too, [`MASK_OCCLUDED`] when another surface is
//! in front of it in the right view or its match `x − d` falls left of the right image's first pixel centre (`< 0`),
//! and [`MASK_NO_GT`] never occurs (the background covers every pixel).
//!
//! # Files ([`write_scene`])
//! `im0.png`, `im1.png` (8-bit RGB), `calib.txt` (Middlebury keys; `f = width`, principal point at the image
//! centre, `doffs = 0`, `baseline = 100`, `vmin`/`vmax` = floor/ceil of the ground truth's range),
//! `disp0GT.pfm`, `mask0nocc.png` (8-bit grey), written all or none, never into a folder that holds a scene.
//!
//! # Determinism and cost
//! One SplitMix64 stream (`crate::rng`) seeded by [`SynthParams::seed`] draws the scene; textures are hashes of
//! integer lattice coordinates (by the same generator's mixer, `mix64`). No clocks, no hash-map iteration, and
//! every pixel is computed independently (rows in parallel), so the same parameters give byte-identical files
//! whatever the thread count. Cost: O(W·H·S) for S surfaces (~0.2 s at 320×240 in release, writing included).
//!
//! # Sequences
//! [`write_synth_sequence`] renders a sequence of frames of one scene with exact ground truth per frame: a camera
//! that pans or moves forward, an object that moves, a cut to another scene ([`Motion`]; see `sequence.rs`).
//!
//! # Files of this module
//! `mod.rs` (the parameters, rendering a scene, writing it), `scene.rs` (the scene model: surfaces, shapes, drawing
//! one from a seed, which surface a ray of a camera meets), `texture.rs` (the surfaces' seeded textures),
//! `sequence.rs` (sequences: the motions, a frame's cameras, writing them).

use std::path::Path;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::image::{DisparityMap, Plane, RgbImage};

mod scene;
mod sequence;
mod texture;

use crate::dataset::{CALIB_FILE, GT_FILE, LEFT_FILE, MASK_FILE, RIGHT_FILE};
use scene::Scene;
pub use sequence::{FrameTruth, GainChange, Motion, SequenceParams, render_frame, write_synth_sequence};

/// Mask value: the pixel is visible in both views.
pub const MASK_VISIBLE: u8 = 255;
/// Mask value: the pixel is occluded in the right view (or its match falls outside it).
pub const MASK_OCCLUDED: u8 = 128;
/// Mask value: no ground truth (never produced by [`render_scene`], listed for the MiddEval3 convention).
pub const MASK_NO_GT: u8 = 0;

/// What to render.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SynthParams {
    /// Image width in pixels (64..=8192).
    pub width: usize,
    /// Image height in pixels (32..=8192).
    pub height: usize,
    /// Disparity search range 0..ndisp−1 written to `calib.txt` (16..=width/2); the scene's disparities lie in
    /// about 6–92 % of it.
    pub ndisp: usize,
    /// Random seed: the same parameters give the same scene, bit for bit.
    pub seed: u64,
}

impl Default for SynthParams {
    fn default() -> Self {
        SynthParams { width: 320, height: 240, ndisp: 48, seed: 1 }
    }
}

impl SynthParams {
    /// Checks the sizes.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] naming the first value out of range.
    pub fn validate(&self) -> Result<()> {
        if !(64..=8192).contains(&self.width) {
            return Err(Error::param("width", self.width, "64..=8192"));
        }
        if !(32..=8192).contains(&self.height) {
            return Err(Error::param("height", self.height, "32..=8192"));
        }
        if self.ndisp < 16 || self.ndisp > self.width / 2 {
            return Err(Error::param("ndisp", self.ndisp, format!("16..={} (half the width)", self.width / 2)));
        }
        Ok(())
    }
}

/// A rendered scene: the pair, the left view's exact ground truth and its occlusion mask.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthScene {
    /// Left view (`im0.png`), 8-bit values stored as `f32`.
    pub left: RgbImage,
    /// Right view (`im1.png`).
    pub right: RgbImage,
    /// Left view's disparity (`disp0GT.pfm`), finite everywhere.
    pub gt: DisparityMap,
    /// [`MASK_VISIBLE`] / [`MASK_OCCLUDED`] per left pixel (`mask0nocc.png`).
    pub mask: Plane<u8>,
    /// Disparity search range for `calib.txt`.
    pub ndisp: usize,
    /// Floor of the smallest ground-truth disparity (`vmin` in `calib.txt`).
    pub vmin: f32,
    /// Ceiling of the largest ground-truth disparity (`vmax` in `calib.txt`), below `ndisp`.
    pub vmax: f32,
}

/// Renders the scene drawn from `params.seed`.
///
/// # Errors
/// [`Error::InvalidParam`] if `params` does not validate.
///
/// # Examples
/// ```
/// let p = jem::synth::SynthParams { width: 96, height: 48, ndisp: 24, seed: 3 };
/// let scene = jem::synth::render_scene(&p).unwrap();
/// assert_eq!(scene.gt.dims(), (96, 48));
/// assert!(0.0 <= scene.vmin && scene.vmax < 24.0);
/// ```
pub fn render_scene(params: &SynthParams) -> Result<SynthScene> {
    params.validate()?;
    Ok(render(&Scene::draw(params), params))
}

/// Renders both views, the ground truth and the mask of `scene` at the size of `params`.
///
/// # Panics
/// If the scene's disparities leave `0..ndisp` (impossible for a drawn scene).
fn render(scene: &Scene, params: &SynthParams) -> SynthScene {
    let (w, h) = (params.width, params.height);
    let left = render_view(scene, w, h, View::Left);
    let right = render_view(scene, w, h, View::Right);

    let mut gt = Plane::new(w, h, f32::INFINITY);
    let mut mask = Plane::new(w, h, MASK_NO_GT);
    gt.data.par_chunks_mut(w).zip(mask.data.par_chunks_mut(w)).enumerate().for_each(|(y, (gt_row, mask_row))| {
        for (x, (g, m)) in gt_row.iter_mut().zip(mask_row.iter_mut()).enumerate() {
            let (s, d) = scene.visible_left(x as f64, y as f64);
            *g = d as f32;
            *m = if scene.seen_from_right(s, x as f64, y as f64, d) { MASK_VISIBLE } else { MASK_OCCLUDED };
        }
    });
    let (lo, hi) = gt.data.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &d| (lo.min(d), hi.max(d)));
    let (vmin, vmax) = (lo.floor(), hi.ceil());
    assert!(vmin >= 0.0 && vmax < params.ndisp as f32, "synthetic disparities {lo}..{hi} outside 0..{}", params.ndisp);
    SynthScene { left, right, gt, mask, ndisp: params.ndisp, vmin, vmax }
}

/// Writes `im0.png`, `im1.png`, `calib.txt`, `disp0GT.pfm` and `mask0nocc.png` into `dir` (created if missing),
/// all or none ([`crate::io::write_all_or_none`]). A folder that already holds a scene is refused
/// ([`check_scene_folder`]).
///
/// # Errors
/// [`Error::Output`] for a folder holding a scene; [`Error::Io`] or [`Error::Image`] naming the file.
pub fn write_scene(dir: &Path, scene: &SynthScene) -> Result<()> {
    check_scene_folder(dir)?;
    crate::io::create_folder(dir)?;
    let (w, h) = scene.left.dims();
    let rgb = |name: &str, img: &RgbImage| {
        let mut bytes = Vec::new();
        image::ImageEncoder::write_image(
            image::codecs::png::PngEncoder::new(&mut bytes),
            &interleave_rgb8(img),
            w as u32,
            h as u32,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|source| Error::Image { path: dir.join(name), source })
        .map(|()| bytes)
    };
    let files = [
        (LEFT_FILE, rgb(LEFT_FILE, &scene.left)?),
        (RIGHT_FILE, rgb(RIGHT_FILE, &scene.right)?),
        (CALIB_FILE, calib_text(w, h, scene.ndisp, scene.vmin, scene.vmax).into_bytes()),
        (GT_FILE, crate::io::pfm::encode_pfm(&scene.gt)),
        (MASK_FILE, encode_mask_png(&dir.join(MASK_FILE), &scene.mask)?),
    ];
    let paths: Vec<std::path::PathBuf> = files.iter().map(|(name, _)| dir.join(name)).collect();
    let refs: Vec<(&Path, &[u8])> = paths.iter().zip(&files).map(|(p, (_, b))| (p.as_path(), b.as_slice())).collect();
    crate::io::write_all_or_none(&refs)
}

/// Refuses a folder that already holds files of a scene (images, calib.txt, ground truth, masks, results
/// `disp0NAME.pfm`/`timeNAME.txt`), as `jem degrade` refuses a folder that is not empty: a new scene written over
/// them would replace the old one, and leave its results beside images they do not belong to. A missing folder,
/// or one holding none of them, is fine.
///
/// # Errors
/// [`Error::Output`] naming the folder and the files found.
pub fn check_scene_folder(dir: &Path) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(dir) else { return Ok(()) };
    let mut found: Vec<String> = entries
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|name| is_scene_file(name))
        .collect();
    if found.is_empty() {
        return Ok(());
    }
    found.sort();
    Err(Error::output_at(
        dir,
        format!("already holds a scene ({}); write the new one into a new or empty folder", found.join(", ")),
    ))
}

/// Whether `name` is one of the files a MiddEval3 scene folder holds.
fn is_scene_file(name: &str) -> bool {
    let result = |prefix: &str, ext: &str| name.starts_with(prefix) && name.ends_with(ext);
    crate::dataset::SCENE_FILES.contains(&name)
        || crate::degrade::COPIED_FILES.contains(&name)
        || result("disp0", ".pfm")
        || result("disp1", ".pfm")
        || result("time", ".txt")
        || result("config", ".toml")
}

/// A mask encoded as an 8-bit grey PNG (`path` names it in errors).
///
/// # Errors
/// [`Error::Image`] naming `path`.
pub(crate) fn encode_mask_png(path: &Path, mask: &Plane<u8>) -> Result<Vec<u8>> {
    let mut png = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut png),
        &mask.data,
        mask.width as u32,
        mask.height as u32,
        image::ExtendedColorType::L8,
    )
    .map_err(|source| Error::Image { path: path.to_path_buf(), source })?;
    Ok(png)
}

/// Middlebury `calib.txt`: identical cameras with focal length = width, principal point at the centre.
fn calib_text(w: usize, h: usize, ndisp: usize, vmin: f32, vmax: f32) -> String {
    let cam = format!("[{w} 0 {}; 0 {w} {}; 0 0 1]", (w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    format!(
        "cam0={cam}\ncam1={cam}\ndoffs=0\nbaseline=100\nwidth={w}\nheight={h}\nndisp={}\nisint=0\nvmin={}\nvmax={}\n\
         dyavg=0\ndymax=0\n",
        ndisp, vmin, vmax
    )
}

/// Interleaved 8-bit RGB from a planar image (values are already whole numbers in 0..=255).
pub(crate) fn interleave_rgb8(img: &RgbImage) -> Vec<u8> {
    (0..img.len()).flat_map(|i| img.rgb(i).map(|v| v.round().clamp(0.0, 255.0) as u8)).collect()
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum View {
    Left,
    Right,
}

/// Renders one view: 2×2 samples per pixel, ray-cast, averaged and rounded to 8 bits.
fn render_view(scene: &Scene, w: usize, h: usize, view: View) -> RgbImage {
    const OFFSETS: [f64; 2] = [-0.25, 0.25];
    let mut rgb = vec![[0u8; 3]; w * h];
    rgb.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, px) in row.iter_mut().enumerate() {
            let mut sum = [0.0f64; 3];
            for dy in OFFSETS {
                for dx in OFFSETS {
                    let (sx, sy) = (x as f64 + dx, y as f64 + dy);
                    let (s, xl) = match view {
                        View::Left => (scene.visible_left(sx, sy).0, sx),
                        View::Right => {
                            let (s, _, xl) = scene.visible_right(sx, sy);
                            (s, xl)
                        }
                    };
                    let c = scene.surfaces[s].texture.colour(xl, sy);
                    for (acc, v) in sum.iter_mut().zip(c) {
                        *acc += v;
                    }
                }
            }
            *px = sum.map(|v| (v / 4.0).round().clamp(0.0, 255.0) as u8);
        }
    });
    let mut out = RgbImage::new(w, h);
    for (i, px) in rgb.iter().enumerate() {
        for (channel, &v) in out.channels.iter_mut().zip(px) {
            channel[i] = f32::from(v);
        }
    }
    out
}

#[cfg(test)]
mod tests;
