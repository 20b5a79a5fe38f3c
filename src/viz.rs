//! Pictures of disparity maps: colour-mapped disparities, benchmark-style error maps and contact sheets (what
//! `jem viz` draws).
//!
//! - [`colorize`]: disparity → colour through [`colormap`], a turbo-like rainbow from dark indigo (low disparity,
//!   far) through blue, cyan, green, yellow and orange to dark red (high disparity, near), piecewise linear between
//!   nine hand-picked stops (our own, not a copy of turbo's or jet's tables). Values are clamped to
//!   `[vmin, vmax]`; invalid (non-finite) pixels are black.
//! - [`error_map`]: per pixel, `err = s·|d − gt|` in full-resolution pixels (s = 4 for Q, 2 for H), with the
//!   MiddEval3 bad-2 threshold ([`ERROR_THRESHOLD_PX`]):
//!
//!   | pixel                                        | colour                                       |
//!   |----------------------------------------------|----------------------------------------------|
//!   | no ground truth (GT not finite, or mask 0)   | dark grey (48, 48, 48)                       |
//!   | result invalid (not finite)                  | black                                        |
//!   | non-occluded (mask 255 or no mask), err ≤ 2  | grey from white (err 0) to 205 (err 2)       |
//!   | non-occluded, err > 2                        | red (230, 30, 30)                            |
//!   | occluded (mask 128), err ≤ 2                 | the same grey, shaded darker and bluish       |
//!   | occluded, err > 2                            | dark red (140, 40, 40)                       |
//!
//! - [`contact_sheet`]: one row per scene, `left image | colour result | error map` (a dark panel where a scene has
//!   no ground truth), each panel downscaled (area average) to at most `panel_width` pixels wide.
//!
//! Images are [`Canvas`]es: interleaved 8-bit RGB, row-major, `data[(y·w + x)·3 + c]`. Everything is O(pixels).

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::image::{DisparityMap, Plane, RgbImage};
use crate::io::calib::Calib;

/// Errors above this many full-resolution pixels are "bad" in [`error_map`] (MiddEval3's bad-2).
pub const ERROR_THRESHOLD_PX: f32 = 2.0;

/// Background of sheets and panels without content.
const BACKGROUND: [u8; 3] = [24, 24, 24];
/// Pixels without ground truth in an error map.
const NO_GT: [u8; 3] = [48, 48, 48];

/// An 8-bit RGB image, interleaved, row-major: `data[(y * width + x) * 3 + c]`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Canvas {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height * 3` bytes.
    pub data: Vec<u8>,
}

impl Canvas {
    /// A canvas filled with one colour.
    pub fn new(width: usize, height: usize, fill: [u8; 3]) -> Self {
        let mut data = Vec::with_capacity(width * height * 3);
        for _ in 0..width * height {
            data.extend_from_slice(&fill);
        }
        Canvas { width, height, data }
    }

    /// The colour at (x, y).
    pub fn get(&self, x: usize, y: usize) -> [u8; 3] {
        let i = (y * self.width + x) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }

    /// Copies `src` with its top-left corner at (x0, y0), clipping at the borders.
    pub fn blit(&mut self, src: &Canvas, x0: usize, y0: usize) {
        if x0 >= self.width || y0 >= self.height {
            return;
        }
        let w = src.width.min(self.width - x0);
        for y in 0..src.height.min(self.height - y0) {
            let s = &src.data[y * src.width * 3..][..w * 3];
            self.data[((y0 + y) * self.width + x0) * 3..][..w * 3].copy_from_slice(s);
        }
    }

    /// Writes the canvas as a PNG, atomically.
    ///
    /// # Errors
    /// [`Error::Image`] or [`Error::Io`] naming the path.
    pub fn write_png(&self, path: &Path) -> Result<()> {
        crate::io::png::write_rgb8_png(path, self.width, self.height, &self.data)
    }

    /// An [`RgbImage`] (0..=255 floats) rounded to 8 bits.
    pub fn from_rgb_image(img: &RgbImage) -> Canvas {
        let mut data = Vec::with_capacity(img.len() * 3);
        for i in 0..img.len() {
            for v in img.rgb(i) {
                data.push(v.round().clamp(0.0, 255.0) as u8);
            }
        }
        Canvas { width: img.width, height: img.height, data }
    }
}

/// Colour-map stops (position, RGB), chosen by hand: dark indigo → blue → sky → cyan-green → green → yellow →
/// orange → red → dark red. Brightness rises to the middle and falls at the red end, so both ends stay
/// distinguishable from the black used for invalid pixels.
const STOPS: [(f32, [f32; 3]); 9] = [
    (0.0, [48.0, 18.0, 90.0]),
    (0.125, [60.0, 80.0, 210.0]),
    (0.25, [40.0, 155.0, 245.0]),
    (0.375, [30.0, 215.0, 195.0]),
    (0.5, [100.0, 245.0, 100.0]),
    (0.625, [195.0, 240.0, 50.0]),
    (0.75, [250.0, 180.0, 40.0]),
    (0.875, [230.0, 90.0, 25.0]),
    (1.0, [130.0, 10.0, 5.0]),
];

/// The colour of `t` in [0, 1] (clamped; NaN maps to 0).
pub fn colormap(t: f32) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let k = STOPS.iter().position(|(p, _)| *p >= t).unwrap_or(STOPS.len() - 1).max(1);
    let ((p0, c0), (p1, c1)) = (STOPS[k - 1], STOPS[k]);
    let f = ((t - p0) / (p1 - p0)).clamp(0.0, 1.0);
    [0, 1, 2].map(|c| (c0[c] + f * (c1[c] - c0[c])).round().clamp(0.0, 255.0) as u8)
}

/// The smallest and largest finite values, or `None` if there is none.
pub fn finite_range(map: &Plane<f32>) -> Option<(f32, f32)> {
    map.data.iter().filter(|v| v.is_finite()).fold(None, |acc, &v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// Colour-maps a disparity map over `[vmin, vmax]` (an empty or reversed range maps everything to the low end);
/// non-finite pixels are black.
pub fn colorize(disp: &DisparityMap, vmin: f32, vmax: f32) -> Canvas {
    let span = vmax - vmin;
    let mut data = Vec::with_capacity(disp.data.len() * 3);
    for &d in &disp.data {
        let c = if !d.is_finite() {
            [0, 0, 0]
        } else if span > 0.0 {
            colormap((d - vmin) / span)
        } else {
            colormap(0.0)
        };
        data.extend_from_slice(&c);
    }
    Canvas { width: disp.width, height: disp.height, data }
}

/// The benchmark-style error map (colours in the module doc); `scale` converts to full-resolution pixels.
///
/// # Panics
/// If the result, the GT and the mask differ in size.
pub fn error_map(result: &DisparityMap, gt: &DisparityMap, mask: Option<&Plane<u8>>, scale: u32) -> Canvas {
    assert_eq!(result.dims(), gt.dims(), "result and ground truth sizes differ");
    if let Some(m) = mask {
        assert_eq!(m.dims(), gt.dims(), "mask and ground truth sizes differ");
    }
    let s = scale as f32;
    let mut data = Vec::with_capacity(gt.data.len() * 3);
    for (i, (&d, &g)) in result.data.iter().zip(&gt.data).enumerate() {
        let m = mask.map_or(255, |m| m.data[i]);
        let c = if !g.is_finite() || m == 0 {
            NO_GT
        } else if !d.is_finite() {
            [0, 0, 0]
        } else {
            let err = s * (d - g).abs();
            let occluded = m != 255;
            match (err > ERROR_THRESHOLD_PX, occluded) {
                (true, false) => [230, 30, 30],
                (true, true) => [140, 40, 40],
                (false, occ) => {
                    let grey = 255.0 - 50.0 * err / ERROR_THRESHOLD_PX;
                    if occ {
                        [0.5 * grey, 0.55 * grey, 0.7 * grey].map(|v| v.round() as u8)
                    } else {
                        [grey.round() as u8; 3]
                    }
                }
            }
        };
        data.extend_from_slice(&c);
    }
    Canvas { width: gt.width, height: gt.height, data }
}

/// Downscales (or copies) to `width × height` by area averaging: each output pixel is the mean of the input
/// pixels its footprint covers (whole pixels; at least one). Upscaling repeats pixels.
pub fn resize_area(src: &Canvas, width: usize, height: usize) -> Canvas {
    if (width, height) == (src.width, src.height) || src.width == 0 || src.height == 0 {
        return if (width, height) == (src.width, src.height) {
            src.clone()
        } else {
            Canvas::new(width, height, BACKGROUND)
        };
    }
    let span = |o: usize, n_out: usize, n_in: usize| {
        let a = o * n_in / n_out;
        let b = ((o + 1) * n_in).div_ceil(n_out).clamp(a + 1, n_in);
        (a, b)
    };
    let mut out = Canvas::new(width, height, [0; 3]);
    for oy in 0..height {
        let (y0, y1) = span(oy, height, src.height);
        for ox in 0..width {
            let (x0, x1) = span(ox, width, src.width);
            let mut sum = [0u32; 3];
            for y in y0..y1 {
                for x in x0..x1 {
                    for (s, v) in sum.iter_mut().zip(src.get(x, y)) {
                        *s += u32::from(v);
                    }
                }
            }
            let n = ((y1 - y0) * (x1 - x0)) as u32;
            let i = (oy * width + ox) * 3;
            for (dst, s) in out.data[i..i + 3].iter_mut().zip(sum) {
                *dst = ((s + n / 2) / n) as u8;
            }
        }
    }
    out
}

/// Downscales to at most `max_width` wide, keeping the aspect ratio (no upscaling).
fn fit_width(src: &Canvas, max_width: usize) -> Canvas {
    if src.width <= max_width {
        return src.clone();
    }
    let h = (src.height * max_width).div_ceil(src.width).max(1);
    resize_area(src, max_width, h)
}

/// Places canvases side by side, top-aligned, `gap` pixels apart, on the background colour.
pub fn hstack(parts: &[Canvas], gap: usize) -> Canvas {
    let width = parts.iter().map(|p| p.width).sum::<usize>() + gap * parts.len().saturating_sub(1);
    let height = parts.iter().map(|p| p.height).max().unwrap_or(0);
    let mut out = Canvas::new(width, height, BACKGROUND);
    let mut x = 0;
    for p in parts {
        out.blit(p, x, 0);
        x += p.width + gap;
    }
    out
}

/// Stacks canvases top to bottom, left-aligned, `gap` pixels apart, on the background colour.
pub fn vstack(parts: &[Canvas], gap: usize) -> Canvas {
    let height = parts.iter().map(|p| p.height).sum::<usize>() + gap * parts.len().saturating_sub(1);
    let width = parts.iter().map(|p| p.width).max().unwrap_or(0);
    let mut out = Canvas::new(width, height, BACKGROUND);
    let mut y = 0;
    for p in parts {
        out.blit(p, 0, y);
        y += p.height + gap;
    }
    out
}

/// `vmin`/`vmax` from a `calib.txt`, if it exists and has both with `vmin < vmax`.
pub fn calib_range(calib: &Path) -> Option<(f32, f32)> {
    let c = Calib::load(calib).ok()?;
    let (lo, hi) = (c.float("vmin")?, c.float("vmax")?);
    (lo < hi).then_some((lo, hi))
}

/// Loads `mask0nocc.png` beside a GT file, if present and of the GT's size.
fn mask_beside(gt_path: &Path, gt: &DisparityMap) -> Result<Option<Plane<u8>>> {
    let path = gt_path.parent().unwrap_or(Path::new(".")).join("mask0nocc.png");
    if !path.is_file() {
        return Ok(None);
    }
    let m = crate::io::png::load_grey8(&path)?;
    crate::eval::check_size(&path, "mask", m.dims(), "the ground truth", gt.dims())?;
    Ok(Some(m))
}

/// Loads a GT map (and the `mask0nocc.png` beside it) and checks its size against `result`.
///
/// # Errors
/// Unreadable files or unequal sizes.
pub fn load_gt_for(result: &DisparityMap, gt_path: &Path) -> Result<(DisparityMap, Option<Plane<u8>>)> {
    let gt = crate::io::read_disparity(gt_path)?;
    crate::eval::check_size(gt_path, "ground truth", gt.dims(), "the result", result.dims())?;
    let mask = mask_beside(gt_path, &gt)?;
    Ok((gt, mask))
}

/// One contact-sheet row for a scene folder: `im0.png | disp0<alg>.pfm coloured | error map` (a dark panel when
/// the scene has no `disp0GT.pfm`). The colour range is `vmin`/`vmax` from `calib.txt`, else the GT's finite
/// range, else the result's. `scale = None` infers it from the path ([`crate::eval::scale_from_path`]), else 1.
///
/// # Errors
/// Unreadable files or unequal sizes.
pub fn scene_row(dir: &Path, alg: &str, scale: Option<u32>, panel_width: usize) -> Result<Canvas> {
    let result = crate::io::read_disparity(&dir.join(format!("disp0{alg}.pfm")))?;
    let left = Canvas::from_rgb_image(&crate::io::png::load_rgb(&dir.join("im0.png"))?);
    if (left.width, left.height) != result.dims() {
        return Err(Error::Input(format!("{}: result and im0.png differ in size", dir.display())));
    }
    let gt_path = dir.join("disp0GT.pfm");
    let gt = if gt_path.is_file() { Some(load_gt_for(&result, &gt_path)?) } else { None };
    let range = calib_range(&dir.join("calib.txt"))
        .or_else(|| gt.as_ref().and_then(|(g, _)| finite_range(g)))
        .or_else(|| finite_range(&result))
        .unwrap_or((0.0, 1.0));
    let scale = scale.or_else(|| resolved_scale(dir)).unwrap_or(1);
    let colour = colorize(&result, range.0, range.1);
    let error = match &gt {
        Some((g, m)) => error_map(&result, g, m.as_ref(), scale),
        None => Canvas::new(result.width, result.height, NO_GT),
    };
    let panels: Vec<Canvas> = [left, colour, error].iter().map(|c| fit_width(c, panel_width)).collect();
    Ok(hstack(&panels, 4))
}

/// The scale implied by a path after resolving it (so `.` inside `trainingQ` works).
pub fn resolved_scale(path: &Path) -> Option<u32> {
    let p = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    crate::eval::scale_from_path(&p)
}

/// What [`contact_sheet`] drew.
#[derive(Clone, Debug)]
pub struct Sheet {
    /// The picture.
    pub canvas: Canvas,
    /// The scene folders drawn, in row order.
    pub rows: Vec<PathBuf>,
    /// Scenes left out because their files could not be drawn, with the reason.
    pub skipped: Vec<(PathBuf, String)>,
}

/// A contact sheet of every scene folder under `dir` that has `im0.png` and `disp0<alg>.pfm`, sorted by path,
/// one [`scene_row`] per scene, 8 pixels apart. A scene whose files cannot be drawn is left out and listed in
/// [`Sheet::skipped`].
///
/// # Errors
/// No such scene under `dir`, or none of them could be drawn.
pub fn contact_sheet(dir: &Path, alg: &str, scale: Option<u32>, panel_width: usize) -> Result<Sheet> {
    let result_name = format!("disp0{alg}.pfm");
    let scenes = crate::batch::find_dirs_with(&[dir.to_path_buf()], &["im0.png", &result_name])?;
    if scenes.is_empty() {
        return Err(Error::Input(format!("no scene folder with im0.png and {result_name} under {}", dir.display())));
    }
    let (mut canvases, mut rows, mut skipped) = (Vec::new(), Vec::new(), Vec::new());
    for s in scenes {
        match scene_row(&s, alg, scale, panel_width) {
            Ok(c) => {
                canvases.push(c);
                rows.push(s);
            }
            Err(e) => skipped.push((s, e.to_string())),
        }
    }
    if canvases.is_empty() {
        let why: Vec<String> = skipped.iter().map(|(_, e)| e.clone()).collect();
        return Err(Error::Input(format!("no scene could be drawn: {}", why.join("; "))));
    }
    Ok(Sheet { canvas: vstack(&canvases, 8), rows, skipped })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colormap_ends_and_monotone_stops() {
        assert_eq!(colormap(0.0), [48, 18, 90]);
        assert_eq!(colormap(1.0), [130, 10, 5]);
        assert_eq!(colormap(-3.0), colormap(0.0));
        assert_eq!(colormap(f32::NAN), colormap(0.0));
        assert_eq!(colormap(0.5), [100, 245, 100]);
        // Halfway between the first two stops.
        assert_eq!(colormap(0.0625), [54, 49, 150]);
        for w in STOPS.windows(2) {
            assert!(w[0].0 < w[1].0);
        }
    }

    #[test]
    fn colorize_range_and_invalid() {
        let d = Plane::from_vec(4, 1, vec![10.0, 30.0, f32::INFINITY, 100.0]);
        let c = colorize(&d, 10.0, 30.0);
        assert_eq!(c.get(0, 0), colormap(0.0));
        assert_eq!(c.get(1, 0), colormap(1.0));
        assert_eq!(c.get(2, 0), [0, 0, 0]);
        assert_eq!(c.get(3, 0), colormap(1.0));
        assert_eq!(finite_range(&d), Some((10.0, 100.0)));
        assert_eq!(finite_range(&Plane::new(2, 2, f32::NAN)), None);
    }

    #[test]
    fn error_map_classes() {
        // Scale 4: threshold 2 full-res px = 0.5 px here.
        let gt = Plane::from_vec(6, 1, vec![1.0, 1.0, 1.0, 1.0, f32::INFINITY, 1.0]);
        let r = Plane::from_vec(6, 1, vec![1.0, 1.5, 1.75, f32::INFINITY, 3.0, 1.75]);
        let mask = Plane::from_vec(6, 1, vec![255, 255, 255, 255, 255, 128]);
        let e = error_map(&r, &gt, Some(&mask), 4);
        assert_eq!(e.get(0, 0), [255; 3]);
        assert_eq!(e.get(1, 0), [205; 3]); // err exactly 2: not bad
        assert_eq!(e.get(2, 0), [230, 30, 30]);
        assert_eq!(e.get(3, 0), [0, 0, 0]);
        assert_eq!(e.get(4, 0), NO_GT);
        assert_eq!(e.get(5, 0), [140, 40, 40]);
    }

    #[test]
    fn area_resize_averages_blocks() {
        let mut c = Canvas::new(4, 2, [0; 3]);
        c.data[..3].copy_from_slice(&[100, 200, 40]);
        c.data[3..6].copy_from_slice(&[0, 0, 0]);
        c.data[12..15].copy_from_slice(&[0, 0, 0]);
        c.data[15..18].copy_from_slice(&[100, 200, 40]);
        let r = resize_area(&c, 2, 1);
        assert_eq!(r.get(0, 0), [50, 100, 20]);
        assert_eq!(r.get(1, 0), [0, 0, 0]);
        let f = fit_width(&Canvas::new(10, 5, [9; 3]), 4);
        assert_eq!((f.width, f.height), (4, 2));
        assert_eq!(f.get(3, 1), [9; 3]);
    }

    #[test]
    fn stacking_pads_with_background() {
        let a = Canvas::new(2, 1, [1; 3]);
        let b = Canvas::new(1, 2, [2; 3]);
        let h = hstack(&[a.clone(), b.clone()], 1);
        assert_eq!((h.width, h.height), (4, 2));
        assert_eq!([h.get(0, 0), h.get(2, 0), h.get(3, 1), h.get(0, 1)], [[1; 3], BACKGROUND, [2; 3], BACKGROUND]);
        let v = vstack(&[a, b], 0);
        assert_eq!((v.width, v.height), (2, 3));
        assert_eq!([v.get(1, 0), v.get(0, 2), v.get(1, 2)], [[1; 3], [2; 3], BACKGROUND]);
    }
}
