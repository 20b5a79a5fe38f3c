//! Pictures of disparity maps: colour-mapped disparities, benchmark-style error maps and contact sheets (what
//! `jem viz` draws).
//!
//! - [`colorize`]: disparity → colour through [`colormap`], a turbo-like rainbow from dark indigo (low disparity,
//!   far) through blue, cyan, green, yellow and orange to dark red (high disparity, near), piecewise linear between
//!   nine hand-picked stops (our own, not a copy of turbo's or jet's tables). Values are clamped to
//!   `[vmin, vmax]`; invalid (non-finite) pixels are black.
//! - [`error_map`]: per pixel, the error `|d − gt|` against the threshold of the benchmark's own rule
//!   ([`ErrorRule`]): MiddEval3 bad-2 (`s·|d − gt| > 2` full-resolution pixels, s = 4 for Q, 2 for H), KITTI D1
//!   (`> 3 px` and `> 5 %` of the true disparity), ETH3D bad-1 (`> 1 px`, its usual headline):
//!
//!   | pixel                                        | colour                                       |
//!   |----------------------------------------------|----------------------------------------------|
//!   | no ground truth (GT not finite, or mask 0)   | dark grey (48, 48, 48)                       |
//!   | result invalid (not finite)                  | black                                        |
//!   | non-occluded (mask 255 or no mask), not bad  | grey from white (err 0) to 205 (err = threshold) |
//!   | non-occluded, bad                            | red (230, 30, 30)                            |
//!   | occluded (mask 128), not bad                 | the same grey, shaded darker and bluish       |
//!   | occluded, bad                                | dark red (140, 40, 40)                       |
//!
//!   Invalid pixels stay black in every rule (KITTI's devkit fills them before it scores; the map shows where they
//!   were).
//! - [`contact_sheet`]: one row per scene or frame of a MiddEval3, KITTI or ETH3D tree, `left image | colour
//!   result | error map` (a dark panel where there is no ground truth), each panel downscaled (area average) to at
//!   most `panel_width` pixels wide; `sheet.rs` finds the rows where the [`dataset`](crate::dataset) layout puts
//!   the files.
//!
//! - **Depth maps** ([`colorize_depth`], `depth.rs`): coloured by inverse depth over a robust range
//!   ([`depth_range`]), with a labelled scale bar under the picture.
//!
//! Images are [`Canvas`]es: interleaved 8-bit RGB, row-major, `data[(y·w + x)·3 + c]`. Everything is O(pixels).

mod depth;
pub(crate) mod font;
mod sheet;

pub use depth::{colorize_depth, depth_range};
pub use sheet::{
    Occlusion, RowPictures, RowScore, Sheet, SheetOptions, SheetRow, TruthFiles, TruthRule, contact_sheet, gt_rule,
    load_truth, render_row, sheet_rows,
};

use std::path::Path;

use crate::error::Result;
use crate::image::{DisparityMap, Plane, RgbImage};
use crate::io::calib::Calib;

/// Errors above this many full-resolution pixels are "bad" in a MiddEval3 [`error_map`] (its bad-2).
pub const ERROR_THRESHOLD_PX: f32 = 2.0;

/// Which benchmark's rule makes a pixel "bad" in an [`error_map`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ErrorRule {
    /// MiddEval3 bad-2: `scale·|d − gt| > 2` full-resolution pixels (`scale` = 4 for Q, 2 for H, 1 for F).
    Middlebury {
        /// Factor from the map's pixels to full-resolution pixels.
        scale: u32,
    },
    /// KITTI D1: `|d − gt| > 3` px and `> 5 %` of the true disparity (the devkit's outlier).
    KittiD1,
    /// ETH3D bad-1: `|d − gt| > 1` px, the benchmark's usual headline.
    Eth3d,
}

impl ErrorRule {
    /// The rule of a data set's layout (`scale` is used by MiddEval3 only).
    pub fn for_layout(layout: crate::dataset::Layout, scale: u32) -> Self {
        use crate::dataset::Layout;
        match layout {
            Layout::Middlebury => ErrorRule::Middlebury { scale },
            Layout::Kitti2015 | Layout::Kitti2012 => ErrorRule::KittiD1,
            Layout::Eth3d => ErrorRule::Eth3d,
        }
    }

    /// The error of `d` against `g` and the threshold above which it is bad, in the same unit (full-resolution
    /// pixels for MiddEval3, the map's pixels otherwise).
    #[inline]
    fn error_and_threshold(self, d: f32, g: f32) -> (f32, f32) {
        match self {
            ErrorRule::Middlebury { scale } => (scale as f32 * (d - g).abs(), ERROR_THRESHOLD_PX),
            ErrorRule::KittiD1 => {
                let t = (crate::eval::D1_THRESHOLD_PX as f32).max(crate::eval::D1_RELATIVE as f32 * g.abs());
                ((d - g).abs(), t)
            }
            ErrorRule::Eth3d => ((d - g).abs(), 1.0),
        }
    }

    /// The rule in words: `MiddEval3 bad-2 (error > 2 px at full resolution, ×4)`.
    pub fn describe(self) -> String {
        match self {
            ErrorRule::Middlebury { scale: 1 } => "MiddEval3 bad-2 (error > 2 px)".into(),
            ErrorRule::Middlebury { scale } => format!("MiddEval3 bad-2 (error > 2 px at full resolution, ×{scale})"),
            ErrorRule::KittiD1 => "KITTI D1 (error > 3 px and > 5 % of the true disparity)".into(),
            ErrorRule::Eth3d => "ETH3D bad-1 (error > 1 px)".into(),
        }
    }
}

/// Background of sheets and panels without content.
pub(crate) const BACKGROUND: [u8; 3] = [24, 24, 24];
/// Pixels without ground truth in an error map.
pub(crate) const NO_GT: [u8; 3] = [48, 48, 48];

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
    /// [`Error::Image`](crate::Error::Image) or [`Error::Io`](crate::Error::Io) naming the path.
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

/// The colour range `jem viz` draws a map over: each end as given, else `calib`'s (a `calib.txt`'s `vmin`/`vmax`:
/// [`calib_range`]), else the map's finite range ([`finite_range`]), else `0..1`. `names` name the two ends in
/// messages (`--vmin`, `--vmax`).
///
/// # Errors
/// [`Error::InvalidParam`](crate::Error::InvalidParam) for a given end that is not finite, or ends (one given at
/// least) that make an empty or reversed range.
pub fn colour_range(
    disp: &DisparityMap,
    given: (Option<f32>, Option<f32>),
    calib: Option<(f32, f32)>,
    names: (&str, &str),
) -> Result<(f32, f32)> {
    for (name, v) in [(names.0, given.0), (names.1, given.1)] {
        if let Some(v) = v.filter(|v| !v.is_finite()) {
            return Err(crate::Error::param(name, v, "a finite number"));
        }
    }
    let data = finite_range(disp);
    let vmin = given.0.or(calib.map(|c| c.0)).or(data.map(|d| d.0)).unwrap_or(0.0);
    let vmax = given.1.or(calib.map(|c| c.1)).or(data.map(|d| d.1)).unwrap_or(1.0);
    if (given.0.is_some() || given.1.is_some()) && vmin >= vmax {
        return Err(crate::Error::param(
            &format!("{} / {}", names.0, names.1),
            format!("{vmin} / {vmax}"),
            format!("a range with {} below {}", names.0, names.1),
        ));
    }
    Ok((vmin, vmax))
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

/// The benchmark-style error map under `rule` (colours in the module doc).
///
/// # Panics
/// If the result, the GT and the mask differ in size.
pub fn error_map(result: &DisparityMap, gt: &DisparityMap, mask: Option<&Plane<u8>>, rule: ErrorRule) -> Canvas {
    assert_eq!(result.dims(), gt.dims(), "result and ground truth sizes differ");
    if let Some(m) = mask {
        assert_eq!(m.dims(), gt.dims(), "mask and ground truth sizes differ");
    }
    let mut data = Vec::with_capacity(gt.data.len() * 3);
    for (i, (&d, &g)) in result.data.iter().zip(&gt.data).enumerate() {
        let m = mask.map_or(255, |m| m.data[i]);
        let c = if !g.is_finite() || m == 0 {
            NO_GT
        } else if !d.is_finite() {
            [0, 0, 0]
        } else {
            let (err, threshold) = rule.error_and_threshold(d, g);
            let occluded = m != 255;
            match (err > threshold, occluded) {
                (true, false) => [230, 30, 30],
                (true, true) => [140, 40, 40],
                (false, occ) => {
                    let grey = 255.0 - 50.0 * err / threshold;
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
pub(crate) fn fit_width(src: &Canvas, max_width: usize) -> Canvas {
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
        let d = Plane::from_parts(4, 1, vec![10.0, 30.0, f32::INFINITY, 100.0]);
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
        let gt = Plane::from_parts(6, 1, vec![1.0, 1.0, 1.0, 1.0, f32::INFINITY, 1.0]);
        let r = Plane::from_parts(6, 1, vec![1.0, 1.5, 1.75, f32::INFINITY, 3.0, 1.75]);
        let mask = Plane::from_parts(6, 1, vec![255, 255, 255, 255, 255, 128]);
        let e = error_map(&r, &gt, Some(&mask), ErrorRule::Middlebury { scale: 4 });
        assert_eq!(e.get(0, 0), [255; 3]);
        assert_eq!(e.get(1, 0), [205; 3]); // err exactly 2: not bad
        assert_eq!(e.get(2, 0), [230, 30, 30]);
        assert_eq!(e.get(3, 0), [0, 0, 0]);
        assert_eq!(e.get(4, 0), NO_GT);
        assert_eq!(e.get(5, 0), [140, 40, 40]);
    }

    #[test]
    fn error_rules_of_each_benchmark() {
        // KITTI D1: bad only above 3 px *and* 5 % of the truth (strict); ETH3D: above 1 px; MiddEval3 ×1: above 2.
        let gt = Plane::from_parts(5, 1, vec![20.0, 100.0, 100.0, 20.0, 20.0]);
        let r = Plane::from_parts(5, 1, vec![23.0, 105.0, 105.5, 21.0, 21.5]);
        let kitti = error_map(&r, &gt, None, ErrorRule::KittiD1);
        let bad = |c: &Canvas| (0..5).map(|x| c.get(x, 0) == [230, 30, 30]).collect::<Vec<_>>();
        assert_eq!(bad(&kitti), [false, false, true, false, false]);
        assert_eq!(kitti.get(0, 0), [205; 3]); // err 3 = the threshold
        let eth3d = error_map(&r, &gt, None, ErrorRule::Eth3d);
        assert_eq!(bad(&eth3d), [true, true, true, false, true]);
        let middlebury = error_map(&r, &gt, None, ErrorRule::Middlebury { scale: 1 });
        assert_eq!(bad(&middlebury), [true, true, true, false, false]);
        assert_eq!(ErrorRule::for_layout(crate::dataset::Layout::Kitti2012, 4), ErrorRule::KittiD1);
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
