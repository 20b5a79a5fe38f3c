//! Where a result's error is (`jem eval --regions`): a MiddEval3 scene's avgErr split by region and by error size.
//!
//! # Pixels and errors
//! The pixels and errors of [`evaluate`](super::evaluate) with the nonocc mask: ground truth finite and
//! `mask0nocc.png == 255`; a valid result is clipped to `[0, ndisp]` and its error is `s·|d − gt|` in
//! full-resolution px (`s` = 4 for Q, 2 for H, 1 for F). Invalid result pixels are left out, as avgErr leaves them
//! out. Let `n` be the number of valid scored pixels.
//!
//! # The split adds up
//! A region's (or an error size's) **contribution** is the sum of the errors in it divided by `n`, the number of
//! *all* valid scored pixels, not of the region's own: so the contributions of the regions (and those of the error
//! sizes) add up to the scene's avgErr. Its **gross** contribution counts only the errors over [`GROSS_PX`]; those
//! add up to the by-size column "> 8". The weighted row is the MiddEval3 weighted mean of the scenes' rows (the
//! weights of [`scene_weight`](super::scene_weight)), so it adds up to the weighted avgErr.
//!
//! # Regions
//! Each scored pixel is in exactly one, the first of these that holds:
//! 1. **rejected** by the left-right check: nonzero in `lrmask0<alg>.png`, the mask `jem batch --lr-mask` (or
//!    `jem match --lr-mask`) writes: where the check rejected the pixel before fill, weighted median and planes gave
//!    it a value. Without that file the region is not reported ("-" / `null`) and its pixels fall into the others.
//! 2. **near a depth edge**: within [`EDGE_RADIUS_PX`] px (Chebyshev distance, i.e. a 7 × 7 square, at the
//!    evaluated resolution) of a ground-truth depth edge. A pixel is on an edge when its ground truth differs by more
//!    than [`EDGE_JUMP_PX`] px (at the evaluated resolution, not ×s) from a 4-neighbour's, both finite; both pixels
//!    of such a pair are on the edge. Every finite ground-truth pixel counts, occluded ones too.
//! 3. **textureless**: among the [`TEXTURELESS_SHARE`] (15 %) of the scene's scored pixels (valid or not) with the
//!    least texture, ties broken by raster order. Texture: the mean over the 5 × 5 window (borders replicated) of the
//!    Sobel gradient magnitude √(gx² + gy²) of the left image's grey (BT.601 luma, 0–255). The 15 % are chosen
//!    before the priority, so the region holds at most 15 % of the pixels.
//! 4. **near an occlusion**: within [`OCCLUSION_RADIUS_PX`] px (Chebyshev) of a pixel `mask0nocc.png` marks
//!    occluded (128).
//! 5. **rest**: everything else.
//!
//! Error sizes: ≤ 1 px, (1, 2], (2, 4], (4, 8] and > 8 px (full resolution).
//!
//! Complexity: O(w·h) per scene besides the sort of the scored pixels by texture (O(n log n)).

use std::path::Path;
use std::sync::Arc;

use rayon::prelude::*;

use super::metrics::{check_size, pixel_error, scene_result};
use super::report::AlgReport;
use crate::dataset::LEFT_FILE;
use crate::dataset::Layout;
use crate::error::{Error, Result};
use crate::image::{DisparityMap, Plane, RgbImage};
use crate::imgproc::filter::{local_mean_abs, sobel_magnitude};

/// The regions in priority order: their JSON keys.
pub const REGION_KEYS: [&str; 5] = ["rejected", "near_edge", "textureless", "near_occlusion", "rest"];
/// The error sizes: their JSON keys (≤ 1, 1–2, 2–4, 4–8, > 8 full-resolution px).
pub const SIZE_KEYS: [&str; 5] = ["le1", "1-2", "2-4", "4-8", "gt8"];
/// The upper bounds of the first four error sizes, full-resolution px (inclusive).
pub const SIZE_BOUNDS_PX: [f64; 4] = [1.0, 2.0, 4.0, 8.0];
/// An error over this many full-resolution px is gross.
pub const GROSS_PX: f64 = 8.0;
/// A ground-truth jump over this many px (at the evaluated resolution) between 4-neighbours is a depth edge.
pub const EDGE_JUMP_PX: f32 = 1.0;
/// "Near a depth edge": within this Chebyshev distance of one, px at the evaluated resolution.
pub const EDGE_RADIUS_PX: usize = 3;
/// "Near an occlusion": within this Chebyshev distance of an occluded pixel (mask 128).
pub const OCCLUSION_RADIUS_PX: usize = 3;
/// The share of the scored pixels with the least texture that is "textureless".
pub const TEXTURELESS_SHARE: f64 = 0.15;
/// The texture measure's window: (2·r + 1)², r = 2 (5 × 5).
pub const TEXTURE_RADIUS_PX: usize = 2;

/// The value of a pixel that is not scored in [`region_map`].
pub const NOT_SCORED: u8 = u8::MAX;

/// One scene's (or the weighted mean's) split; indices follow [`REGION_KEYS`] and [`SIZE_KEYS`].
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct RegionSplit {
    /// The avgErr the split adds up to (full-resolution px).
    pub avgerr: f64,
    /// Each region's contribution: Σ err in it / all valid scored pixels.
    pub error: [f64; 5],
    /// The same for the errors over [`GROSS_PX`] only.
    pub gross: [f64; 5],
    /// Each region's share of the valid scored pixels, %.
    pub pixels: [f64; 5],
    /// Each error size's contribution: Σ err of that size / all valid scored pixels.
    pub by_size: [f64; 5],
    /// Whether the left-right mask was there (else region 0 is empty and not reported).
    pub has_lr_mask: bool,
    /// Valid scored pixels (for a mean: the total over its scenes).
    pub pixels_valid: u64,
}

impl RegionSplit {
    /// The total gross contribution (the errors over [`GROSS_PX`] / all valid scored pixels).
    pub fn gross_total(&self) -> f64 {
        self.gross.iter().sum()
    }
}

/// What [`split_by_region`] scores: maps of one size.
#[derive(Clone, Copy)]
pub struct RegionInputs<'a> {
    /// The result (`inf` = invalid).
    pub result: &'a DisparityMap,
    /// The ground truth (`inf` = unknown).
    pub gt: &'a DisparityMap,
    /// `mask0nocc.png`: 255 non-occluded, 128 occluded, 0 no ground truth.
    pub mask: &'a Plane<u8>,
    /// The left image (the texture measure).
    pub left: &'a RgbImage,
    /// Where the left-right check rejected the pixel (nonzero), if the run wrote it.
    pub lr_mask: Option<&'a Plane<u8>>,
    /// The search range (valid disparities are clipped to `[0, ndisp]`).
    pub ndisp: usize,
    /// The factor to full-resolution px.
    pub scale: u32,
}

/// Each pixel's region (index into [`REGION_KEYS`]), [`NOT_SCORED`] where the pixel is not scored (see the module
/// doc for the rules).
///
/// # Panics
/// If the maps differ in size.
pub fn region_map(gt: &DisparityMap, mask: &Plane<u8>, left: &RgbImage, lr_mask: Option<&Plane<u8>>) -> Plane<u8> {
    let (w, h) = gt.dims();
    assert_eq!(mask.dims(), (w, h), "mask and ground truth sizes differ");
    assert_eq!(left.dims(), (w, h), "left image and ground truth sizes differ");
    if let Some(m) = lr_mask {
        assert_eq!(m.dims(), (w, h), "left-right mask and ground truth sizes differ");
    }
    let scored: Vec<bool> = gt.data().iter().zip(mask.data()).map(|(g, &m)| g.is_finite() && m == 255).collect();
    let near_edge = dilate(&depth_edges(gt), w, h, EDGE_RADIUS_PX);
    let occluded: Vec<bool> = mask.data().iter().map(|&m| m == 128).collect();
    let near_occlusion = dilate(&occluded, w, h, OCCLUSION_RADIUS_PX);
    let textureless = least_textured(left, &scored, TEXTURELESS_SHARE);
    let data = (0..w * h)
        .map(|i| {
            if !scored[i] {
                NOT_SCORED
            } else if lr_mask.is_some_and(|m| m.data()[i] != 0) {
                0
            } else if near_edge[i] {
                1
            } else if textureless[i] {
                2
            } else if near_occlusion[i] {
                3
            } else {
                4
            }
        })
        .collect();
    Plane::from_parts(w, h, data)
}

/// The split of one result (see the module doc); `None` when no scored pixel has a valid result.
///
/// # Panics
/// If the maps differ in size.
pub fn split_by_region(inp: &RegionInputs<'_>) -> Option<RegionSplit> {
    assert_eq!(inp.result.dims(), inp.gt.dims(), "result and ground truth sizes differ");
    let regions = region_map(inp.gt, inp.mask, inp.left, inp.lr_mask);
    let (s, max_d) = (f64::from(inp.scale), inp.ndisp as f64);
    let (mut sum, mut valid) = (0.0f64, 0u64);
    let (mut error, mut gross, mut count, mut by_size) = ([0.0f64; 5], [0.0f64; 5], [0u64; 5], [0.0f64; 5]);
    for ((&d, &g), &r) in inp.result.data().iter().zip(inp.gt.data()).zip(regions.data()) {
        if r == NOT_SCORED || !d.is_finite() {
            continue;
        }
        let err = pixel_error(d, g, s, max_d);
        let r = usize::from(r);
        sum += err;
        valid += 1;
        error[r] += err;
        count[r] += 1;
        if err > GROSS_PX {
            gross[r] += err;
        }
        by_size[SIZE_BOUNDS_PX.iter().position(|&b| err <= b).unwrap_or(4)] += err;
    }
    if valid == 0 {
        return None;
    }
    let n = valid as f64;
    Some(RegionSplit {
        avgerr: sum / n,
        error: error.map(|e| e / n),
        gross: gross.map(|e| e / n),
        pixels: count.map(|c| 100.0 * c as f64 / n),
        by_size: by_size.map(|e| e / n),
        has_lr_mask: inp.lr_mask.is_some(),
        pixels_valid: valid,
    })
}

/// Pixels with a finite ground truth that differs by more than [`EDGE_JUMP_PX`] from a finite 4-neighbour's.
fn depth_edges(gt: &DisparityMap) -> Vec<bool> {
    let (w, h) = gt.dims();
    let g = gt.data();
    let mut edge = vec![false; w * h];
    let jump = |a: f32, b: f32| a.is_finite() && b.is_finite() && (a - b).abs() > EDGE_JUMP_PX;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x + 1 < w && jump(g[i], g[i + 1]) {
                edge[i] = true;
                edge[i + 1] = true;
            }
            if y + 1 < h && jump(g[i], g[i + w]) {
                edge[i] = true;
                edge[i + w] = true;
            }
        }
    }
    edge
}

/// The pixels within Chebyshev distance `r` of a `true` one (a (2r + 1)² square): a row pass, then a column pass.
fn dilate(mask: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    let mut rows = vec![false; w * h];
    for y in 0..h {
        let src = &mask[y * w..][..w];
        for (x, o) in rows[y * w..][..w].iter_mut().enumerate() {
            *o = src[x.saturating_sub(r)..(x + r + 1).min(w)].iter().any(|&v| v);
        }
    }
    let mut out = vec![false; w * h];
    for y in 0..h {
        let (lo, hi) = (y.saturating_sub(r), (y + r + 1).min(h));
        for x in 0..w {
            out[y * w + x] = (lo..hi).any(|k| rows[k * w + x]);
        }
    }
    out
}

/// The `share` of the `scored` pixels with the least texture (5 × 5 mean Sobel magnitude of the grey left image),
/// ties in raster order; the count is rounded to the nearest pixel.
fn least_textured(left: &RgbImage, scored: &[bool], share: f64) -> Vec<bool> {
    let texture = local_mean_abs(&sobel_magnitude(&left.to_grey()), TEXTURE_RADIUS_PX);
    let mut order: Vec<usize> = (0..scored.len()).filter(|&i| scored[i]).collect();
    order.sort_by(|&a, &b| texture.data()[a].total_cmp(&texture.data()[b]).then(a.cmp(&b)));
    let take = (share * order.len() as f64).round() as usize;
    let mut out = vec![false; scored.len()];
    order.iter().take(take).for_each(|&i| out[i] = true);
    out
}

/// Splits `disp0<alg>.pfm` of a MiddEval3 scene folder (with its `disp0GT.pfm`, `mask0nocc.png`, `im0.png`,
/// `calib.txt` and, when there, `lrmask0<alg>.png`).
///
/// # Errors
/// A missing or malformed file (naming it), maps of different sizes, or no scored pixel with a valid result.
pub fn split_scene(dir: &Path, alg: &str, scale: u32) -> Result<RegionSplit> {
    let (result_path, ndisp) = scene_result(dir, alg)?;
    let crate::dataset::Truth { disparity: gt_path, mask } = crate::dataset::Truth::in_scene(dir);
    let gt = crate::io::read_disparity(&gt_path)?;
    let result = crate::io::read_disparity(&result_path)?;
    let truth = format!("the ground truth {}", gt_path.display());
    check_size(&result_path, "result", result.dims(), &truth, gt.dims())?;
    let mask_path = mask.unwrap_or_default();
    let mask = crate::io::read_grey8(&mask_path)?;
    check_size(&mask_path, "mask", mask.dims(), &truth, gt.dims())?;
    let left_path = dir.join(LEFT_FILE);
    let left = crate::io::read_image(&left_path)?;
    check_size(&left_path, "left image", left.dims(), &truth, gt.dims())?;
    let lr_path = dir.join(format!("lrmask0{alg}.png"));
    let lr_mask = if lr_path.is_file() { Some(crate::io::read_grey8(&lr_path)?) } else { None };
    if let Some(m) = &lr_mask {
        check_size(&lr_path, "left-right mask", m.dims(), &truth, gt.dims())?;
    }
    let inputs =
        RegionInputs { result: &result, gt: &gt, mask: &mask, left: &left, lr_mask: lr_mask.as_ref(), ndisp, scale };
    split_by_region(&inputs).ok_or_else(|| Error::dataset_at(&result_path, "no scored pixel with a valid result"))
}

/// One algorithm's splits over the scenes of an [`AlgReport`].
#[derive(Clone, Debug)]
pub struct RegionReport {
    /// Algorithm name.
    pub alg: String,
    /// Factor to full-resolution px.
    pub scale: u32,
    /// (scene name, MiddEval3 weight, its split or why there is none), in the report's order.
    pub scenes: Vec<(String, f64, std::result::Result<RegionSplit, Arc<Error>>)>,
}

impl RegionReport {
    /// The weighted mean of the scenes' splits (`None` if none was split). Its `has_lr_mask` holds when every
    /// scene had the mask; otherwise the rejected region is not reported.
    pub fn weighted(&self) -> Option<RegionSplit> {
        let ok: Vec<(f64, &RegionSplit)> =
            self.scenes.iter().filter_map(|(_, w, s)| s.as_ref().ok().map(|s| (*w, s))).collect();
        let total: f64 = ok.iter().map(|(w, _)| w).sum();
        if ok.is_empty() || total <= 0.0 {
            return None;
        }
        let mut m = RegionSplit { has_lr_mask: ok.iter().all(|(_, s)| s.has_lr_mask), ..RegionSplit::default() };
        for (w, s) in &ok {
            let f = w / total;
            m.avgerr += f * s.avgerr;
            for k in 0..5 {
                m.error[k] += f * s.error[k];
                m.gross[k] += f * s.gross[k];
                m.pixels[k] += f * s.pixels[k];
                m.by_size[k] += f * s.by_size[k];
            }
            m.pixels_valid += s.pixels_valid;
        }
        Some(m)
    }
}

/// The splits of the scenes `report` scored (in parallel).
///
/// # Errors
/// [`Error::Argument`] unless the report is of a MiddEval3 tree scored with the nonocc mask.
pub fn split_report(report: &AlgReport) -> Result<RegionReport> {
    if report.layout != Layout::Middlebury {
        return Err(Error::argument(format!(
            "--regions splits MiddEval3 results only (this is a {} data set)",
            report.layout.name()
        )));
    }
    if report.mask != super::MaskMode::Nonocc {
        return Err(Error::argument("--regions scores the non-occluded pixels: use it with --mask nonocc"));
    }
    let scenes = report
        .scenes
        .par_iter()
        .map(|s| {
            let split = match &s.metrics {
                Ok(_) => split_scene(&s.dir, &report.alg, report.scale).map_err(Arc::new),
                Err(e) => Err(e.clone()),
            };
            (s.name.clone(), s.weight, split)
        })
        .collect();
    Ok(RegionReport { alg: report.alg.clone(), scale: report.scale, scenes })
}

#[cfg(test)]
mod tests {
    use super::*;

    const INF: f32 = f32::INFINITY;

    /// A 24 × 16 scene: ground truth 10 left of x = 12 and 2 from it (edge pixels x = 11, 12: near the edge
    /// x = 8..=15); columns 0–1 occluded (mask 128: near an occlusion x ≤ 4); a strong texture except a flat patch
    /// at x ≥ 18 (its inner columns x = 21..=23 have no texture at all: the least textured); the left-right check
    /// rejected (5..=6, 10..=12) and (12, 3).
    fn planted() -> (DisparityMap, Plane<u8>, RgbImage, Plane<u8>) {
        let (w, h) = (24, 16);
        let gt = Plane::from_parts(w, h, (0..w * h).map(|i| if i % w < 12 { 10.0 } else { 2.0 }).collect());
        let mask = Plane::from_parts(w, h, (0..w * h).map(|i| if i % w < 2 { 128 } else { 255 }).collect());
        let grey: Vec<f32> = (0..w * h)
            .map(|i| if i % w >= 18 { 128.0 } else { (((i % w) * 7 + (i / w) * 13) % 5) as f32 * 50.0 })
            .collect();
        let left = RgbImage::from_channels(w, h, [grey.clone(), grey.clone(), grey]).unwrap();
        let mut lr = Plane::new(w, h, 0u8);
        for (x, y) in [(5, 10), (6, 10), (5, 11), (6, 11), (5, 12), (6, 12), (12, 3)] {
            lr.data[y * w + x] = 255;
        }
        (gt, mask, left, lr)
    }

    #[test]
    fn planted_errors_land_in_their_regions_and_add_up() {
        let (gt, mask, left, lr) = planted();
        let w = gt.width;
        let regions = region_map(&gt, &mask, &left, Some(&lr));
        let at = |x: usize, y: usize| regions.data[y * w + x];
        assert_eq!([at(12, 3), at(13, 7), at(22, 5), at(3, 8), at(6, 2), at(0, 0)], [0, 1, 2, 3, 4, NOT_SCORED]);
        assert!((0..16).all(|y| (21..24).all(|x| at(x, y) == 2)), "the flat columns are textureless");
        // Planted errors (Q px, ×4 full resolution): rejected 3 → 12 (gross), near edge 2.5 → 10 (gross),
        // textureless 1 → 4, near an occlusion 0.25 → 1, the rest 0.375 → 1.5; one invalid pixel (left out), one
        // error on an occluded pixel (not scored).
        let mut result = gt.clone();
        for (x, y, e) in [(12, 3, 3.0), (13, 7, 2.5), (22, 5, 1.0), (3, 8, 0.25), (6, 2, 0.375), (0, 0, 5.0)] {
            result.data[y * w + x] += e;
        }
        result.data[7 * w + 7] = INF;
        let inputs = RegionInputs {
            result: &result,
            gt: &gt,
            mask: &mask,
            left: &left,
            lr_mask: Some(&lr),
            ndisp: 16,
            scale: 4,
        };
        let s = split_by_region(&inputs).unwrap();
        let n = (24 * 16 - 32 - 1) as f64;
        let close = |a: &[f64; 5], b: [f64; 5]| a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-12);
        assert_eq!(s.pixels_valid, 351);
        assert!(close(&s.error, [12.0 / n, 10.0 / n, 4.0 / n, 1.0 / n, 1.5 / n]), "{:?}", s.error);
        assert!(close(&s.gross, [12.0 / n, 10.0 / n, 0.0, 0.0, 0.0]), "{:?}", s.gross);
        assert!(close(&s.by_size, [1.0 / n, 1.5 / n, 4.0 / n, 0.0, 22.0 / n]), "{:?}", s.by_size);
        let avgerr = crate::eval::evaluate(&result, &gt, Some(&mask), 16, 4, crate::eval::MaskMode::Nonocc).avgerr;
        assert!((s.avgerr - avgerr).abs() < 1e-12 && (s.error.iter().sum::<f64>() - avgerr).abs() < 1e-12);
        assert!((s.pixels.iter().sum::<f64>() - 100.0).abs() < 1e-9 && (s.pixels[0] - 700.0 / n).abs() < 1e-9);
        // Without the mask the rejected pixels fall into the others: (12, 3) is near the edge.
        let s = split_by_region(&RegionInputs { lr_mask: None, ..inputs }).unwrap();
        assert!(!s.has_lr_mask && close(&s.error, [0.0, 22.0 / n, 4.0 / n, 1.0 / n, 1.5 / n]), "{:?}", s.error);
    }

    #[test]
    fn edges_are_jumps_over_one_px_between_finite_neighbours() {
        // Row: 5, 5, 6, 8, inf, 0 → jumps 1 (no), 2 (yes: pixels 2 and 3), the inf breaks nothing.
        let gt = Plane::from_parts(6, 1, vec![5.0, 5.0, 6.0, 8.0, INF, 0.0]);
        assert_eq!(depth_edges(&gt), vec![false, false, true, true, false, false]);
        let gt = Plane::from_parts(1, 3, vec![1.0, 2.5, 2.5]);
        assert_eq!(depth_edges(&gt), vec![true, true, false]);
    }

    #[test]
    fn dilation_is_a_square() {
        let mut m = vec![false; 7 * 5];
        m[2 * 7 + 3] = true;
        let d = dilate(&m, 7, 5, 1);
        let on: Vec<usize> = (0..35).filter(|&i| d[i]).collect();
        assert_eq!(on, vec![9, 10, 11, 16, 17, 18, 23, 24, 25]);
    }

    #[test]
    fn the_least_textured_share_rounds_and_breaks_ties_in_raster_order() {
        // A flat image: every pixel ties; 15 % of 20 scored pixels = 3, the first three in raster order.
        let left = RgbImage::new(5, 4);
        let mut scored = vec![true; 20];
        scored[0] = false;
        let t = least_textured(&left, &scored, 0.15);
        assert_eq!((0..20).filter(|&i| t[i]).collect::<Vec<_>>(), vec![1, 2, 3]);
    }
}
