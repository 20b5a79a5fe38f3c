//! Where a picture's files are, for each benchmark layout: the rows of a contact sheet ([`sheet_rows`]: MiddEval3
//! scene folders, KITTI frames, ETH3D scenes, with their results where `jem batch` writes them), the ground truth
//! of one map and its benchmark's [`ErrorRule`] ([`gt_rule`]), and drawing them ([`render_row`],
//! [`contact_sheet`]).
//!
//! Occlusions: MiddEval3's `mask0nocc.png` is used as it is (255 visible, 128 occluded, 0 no truth); ETH3D's marks
//! visible pixels with 255 and every other ground-truth pixel is occluded; KITTI has no mask, so the map of all
//! pixels (`disp_occ*`) is the truth and the pixels missing from the non-occluded map (`disp_noc*`) are occluded.

use std::path::{Path, PathBuf};

use super::{
    BACKGROUND, Canvas, ErrorRule, NO_GT, calib_range, colorize, error_map, finite_range, fit_width, hstack, vstack,
};
use crate::dataset::{CALIB_FILE, Discovery, LEFT_FILE, Layout, Pair, Purpose, Truth};
use crate::error::{Error, Result};
use crate::eval::{Resolution, file_resolution, scene_resolution};
use crate::image::{DisparityMap, Plane};

/// How [`sheet_rows`] finds the rows.
#[derive(Clone, Debug, Default)]
pub struct SheetOptions {
    /// MiddEval3's factor to full-resolution pixels (default: from each scene's path, `trainingQ` = 4, else from
    /// its name and image size; required when neither tells and a scene has ground truth).
    pub scale: Option<u32>,
    /// Read the tree as this layout instead of recognising it (as `jem batch --layout`).
    pub layout: Option<Layout>,
    /// Where KITTI and ETH3D results are (`RESULTS/NAME/SPLIT/`; default: `results/` beside the data set).
    pub results: Option<PathBuf>,
    /// ETH3D's ground-truth tree (default: the sibling `<name>_gt/`).
    pub gt: Option<PathBuf>,
}

/// What marks the occluded pixels of a ground truth.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Occlusion {
    /// A mask: MiddEval3's `mask0nocc.png` (used as it is) or ETH3D's (255 visible, any other value occluded).
    Mask(PathBuf),
    /// KITTI's non-occluded map (`disp_noc*`): a pixel with truth that this map lacks is occluded.
    NonOccludedMap(PathBuf),
}

/// A ground truth's files.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TruthFiles {
    /// The ground-truth disparities (KITTI: the map of all pixels when there is one).
    pub disparity: PathBuf,
    /// What marks occlusions, if anything.
    pub occlusion: Option<Occlusion>,
}

impl TruthFiles {
    /// The files of `truth` that exist: none without its disparity map; its mask when that exists.
    fn existing(truth: Truth) -> Option<TruthFiles> {
        truth.disparity.is_file().then(|| TruthFiles {
            occlusion: truth.mask.filter(|m| m.is_file()).map(Occlusion::Mask),
            disparity: truth.disparity,
        })
    }

    /// Every file it reads.
    pub fn paths(&self) -> Vec<&Path> {
        let occ = self.occlusion.as_ref().map(|o| match o {
            Occlusion::Mask(p) | Occlusion::NonOccludedMap(p) => p.as_path(),
        });
        std::iter::once(self.disparity.as_path()).chain(occ).collect()
    }
}

/// One row of a contact sheet: its files and its error rule.
#[derive(Clone, Debug)]
pub struct SheetRow {
    /// The scene or frame name.
    pub name: String,
    /// Where the pair is (for messages): its scene folder, or a KITTI frame's left image.
    pub location: PathBuf,
    /// The left image.
    pub left: PathBuf,
    /// The result.
    pub result: PathBuf,
    /// The ground truth, if the data set has it.
    pub truth: Option<TruthFiles>,
    /// A `calib.txt` whose `vmin`/`vmax` set the colour range.
    pub calib: Option<PathBuf>,
    /// The benchmark's rule for the error map.
    pub rule: ErrorRule,
    /// How a MiddEval3 row's resolution was found, when no `--scale` gave it.
    pub resolution: Option<Resolution>,
    /// Where the run's configuration is recorded beside the result
    /// ([`crate::dataset::ResultFiles::config`]; absent when no `jem batch` recorded it).
    pub config: PathBuf,
}

impl SheetRow {
    /// Every file the row reads.
    pub fn paths(&self) -> Vec<&Path> {
        let mut p = vec![self.left.as_path(), self.result.as_path()];
        p.extend(self.truth.iter().flat_map(TruthFiles::paths));
        p.extend(self.calib.as_deref());
        p
    }
}

/// The MiddEval3 resolution of a scene folder or a ground-truth file: `scale` when given, else what
/// [`scene_resolution`] or [`file_resolution`] finds (its path; its name and size).
fn middlebury_resolution(path: &Path, scale: Option<u32>) -> Result<(u32, Option<Resolution>)> {
    if let Some(s) = scale {
        return Ok((s, None));
    }
    let found = if path.is_dir() { scene_resolution(path) } else { file_resolution(path) };
    let Some(res) = found else {
        return Err(Error::dataset(format!(
            "cannot tell the resolution of {}: no trainingQ/H/F-like folder in its path, and its name and size are \
             not a MiddEval3 scene's; the error map's MiddEval3 rule (bad-2 at full resolution) needs it: pass \
             --scale 1, 2 or 4 (or --layout for a KITTI or ETH3D tree)",
            path.display()
        )));
    };
    Ok((res.scale, Some(res)))
}

/// The KITTI ground truth of a frame: the map of all pixels with the non-occluded map marking occlusions, or the
/// one that exists.
fn kitti_truth(all: PathBuf, nonocc: PathBuf) -> Option<TruthFiles> {
    match (all.is_file(), nonocc.is_file()) {
        (true, true) => Some(TruthFiles { disparity: all, occlusion: Some(Occlusion::NonOccludedMap(nonocc)) }),
        (true, false) => Some(TruthFiles { disparity: all, occlusion: None }),
        (false, true) => Some(TruthFiles { disparity: nonocc, occlusion: None }),
        (false, false) => None,
    }
}

/// A ground truth, its benchmark's error rule, and how its resolution was found ([`gt_rule`]).
#[derive(Clone, Debug)]
pub struct TruthRule {
    /// The files.
    pub files: TruthFiles,
    /// The rule of its error map.
    pub rule: ErrorRule,
    /// MiddEval3: how its resolution was found, when no `--scale` gave it.
    pub resolution: Option<Resolution>,
}

/// The ground truth of one map at `gt` and its benchmark's error rule: KITTI D1 for a `.png` in a `disp_noc*` or
/// `disp_occ*` folder (its sibling map marks occlusions), ETH3D bad-1 in a scene folder of a `*_gt` tree, else
/// MiddEval3 bad-2 at the scale `scale` gives, else the one [`file_resolution`] finds (the path; the folder's
/// name and the file's size; its size alone), an error when none does. `layout` overrides the recognition.
///
/// # Errors
/// A MiddEval3 ground truth whose resolution is unknown.
pub fn gt_rule(gt: &Path, layout: Option<Layout>, scale: Option<u32>) -> Result<TruthRule> {
    let folder = gt.parent().unwrap_or(Path::new("."));
    let folder_name = folder.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let scene_parent = std::fs::canonicalize(folder).ok().and_then(|f| f.parent().map(Path::to_path_buf));
    let in_gt_tree =
        scene_parent.as_deref().and_then(Path::file_name).and_then(|n| n.to_str()).is_some_and(|n| n.ends_with("_gt"));
    let layout = layout.unwrap_or(if folder_name.starts_with("disp_noc") || folder_name.starts_with("disp_occ") {
        Layout::Kitti2015
    } else if in_gt_tree {
        Layout::Eth3d
    } else {
        Layout::Middlebury
    });
    let mask = Truth::in_scene(folder).mask.filter(|m| m.is_file()).map(Occlusion::Mask);
    Ok(match layout {
        Layout::Kitti2015 | Layout::Kitti2012 => {
            // The sibling map (disp_noc_0 <-> disp_occ_0) with the same file name, if there is one.
            let file = gt.file_name().unwrap_or_default();
            let sibling = |from: &str, to: &str| {
                let rest = folder_name.strip_prefix(from)?;
                Some(folder.with_file_name(format!("{to}{rest}")).join(file)).filter(|p| p.is_file())
            };
            let given = gt.to_path_buf();
            let truth = match (sibling("disp_noc", "disp_occ"), sibling("disp_occ", "disp_noc")) {
                (Some(all), _) => TruthFiles { disparity: all, occlusion: Some(Occlusion::NonOccludedMap(given)) },
                (None, Some(nonocc)) => {
                    TruthFiles { disparity: given, occlusion: Some(Occlusion::NonOccludedMap(nonocc)) }
                }
                (None, None) => TruthFiles { disparity: given, occlusion: None },
            };
            TruthRule { files: truth, rule: ErrorRule::KittiD1, resolution: None }
        }
        Layout::Eth3d => TruthRule {
            files: TruthFiles { disparity: gt.to_path_buf(), occlusion: mask },
            rule: ErrorRule::Eth3d,
            resolution: None,
        },
        Layout::Middlebury => {
            let (scale, resolution) = middlebury_resolution(gt, scale)?;
            let files = TruthFiles { disparity: gt.to_path_buf(), occlusion: mask };
            TruthRule { files, rule: ErrorRule::Middlebury { scale }, resolution }
        }
    })
}

/// Loads a ground truth for `result` (sizes checked) and its occlusion mask in MiddEval3's values (255 visible,
/// 128 occluded, 0 no truth).
///
/// # Errors
/// Unreadable files or unequal sizes.
pub fn load_truth(
    result: &DisparityMap,
    truth: &TruthFiles,
    rule: ErrorRule,
) -> Result<(DisparityMap, Option<Plane<u8>>)> {
    let gt = crate::io::read_disparity(&truth.disparity)?;
    crate::eval::check_size(&truth.disparity, "ground truth", gt.dims(), "the result", result.dims())?;
    let mask = match &truth.occlusion {
        None => None,
        Some(Occlusion::Mask(path)) => {
            let mut m = crate::io::png::load_grey8(path)?;
            crate::eval::check_size(path, "mask", m.dims(), "the ground truth", gt.dims())?;
            if rule == ErrorRule::Eth3d {
                m.data.iter_mut().for_each(|v| *v = if *v == 255 { 255 } else { 128 });
            }
            Some(m)
        }
        Some(Occlusion::NonOccludedMap(path)) => {
            let nonocc = crate::io::read_disparity(path)?;
            crate::eval::check_size(path, "non-occluded map", nonocc.dims(), "the ground truth", gt.dims())?;
            let data = nonocc.data.iter().map(|d| if d.is_finite() { 255 } else { 128 }).collect();
            Some(Plane::from_parts(gt.width, gt.height, data))
        }
    };
    Ok((gt, mask))
}

/// The rows of a contact sheet of `alg`'s results under `dir`, sorted: the KITTI frames or ETH3D scenes that have a
/// result where `jem batch` writes it, or, when the tree holds neither, every MiddEval3 scene folder with
/// `im0.png` and `disp0<alg>.pfm`.
///
/// # Errors
/// Nothing to draw, data sets of two layouts, a results folder holding another data set's results, or a MiddEval3
/// scene with ground truth whose resolution is unknown (see [`gt_rule`]).
pub fn sheet_rows(dir: &Path, alg: &str, opts: &SheetOptions) -> Result<Vec<SheetRow>> {
    let how = Discovery { layout: opts.layout, gt: opts.gt.clone() };
    let pairs: Vec<Pair> = crate::dataset::discover(&[dir.to_path_buf()], Purpose::Run, &how)?
        .into_iter()
        .filter(|p| p.layout != Layout::Middlebury)
        .collect();
    if pairs.is_empty() {
        return middlebury_rows(dir, alg, opts);
    }
    if let Some(other) = pairs.iter().find(|p| p.layout != pairs[0].layout) {
        return Err(Error::dataset(format!(
            "{} holds {} and {} data ({} and {}); draw one data set at a time",
            dir.display(),
            pairs[0].layout.name(),
            other.layout.name(),
            pairs[0].root.display(),
            other.root.display()
        )));
    }
    crate::dataset::check_results_dirs(&pairs, alg, opts.results.as_deref(), false)?;
    let rows: Vec<SheetRow> = pairs
        .iter()
        .filter_map(|pair| {
            let files = pair.result_files(alg, opts.results.as_deref());
            files.disparity.is_file().then(|| pair_row(pair, files.disparity, files.config, opts))
        })
        .collect();
    if rows.is_empty() {
        let dirs: std::collections::BTreeSet<String> = pairs
            .iter()
            .filter_map(|p| {
                p.result_files(alg, opts.results.as_deref()).disparity.parent().map(|d| d.display().to_string())
            })
            .collect();
        return Err(Error::dataset(format!(
            "no result of {alg} for the {} {} pair(s) under {} (looked in {}; run `jem batch` first, or give --results)",
            pairs.len(),
            pairs[0].layout.name(),
            dir.display(),
            dirs.into_iter().collect::<Vec<_>>().join(", ")
        )));
    }
    Ok(rows)
}

/// A KITTI or ETH3D pair's row.
fn pair_row(pair: &Pair, result: PathBuf, config: PathBuf, opts: &SheetOptions) -> SheetRow {
    let truth = if pair.layout.is_kitti() {
        kitti_truth(pair.truth(true, None).disparity, pair.truth(false, None).disparity)
    } else {
        TruthFiles::existing(pair.truth(false, opts.gt.as_deref()))
    };
    let calib = pair.calib.clone().filter(|c| c.is_file());
    SheetRow {
        name: pair.name.clone(),
        location: pair.location(),
        left: pair.left.clone(),
        result,
        truth,
        calib,
        rule: ErrorRule::for_layout(pair.layout, 1),
        resolution: None,
        config,
    }
}

/// Every MiddEval3 scene folder under `dir` with `im0.png` and `disp0<alg>.pfm`.
fn middlebury_rows(dir: &Path, alg: &str, opts: &SheetOptions) -> Result<Vec<SheetRow>> {
    let result_name = format!("disp0{alg}.pfm");
    let scenes = crate::dataset::walk::find_dirs_with(&[dir.to_path_buf()], &[LEFT_FILE, &result_name])?;
    if scenes.is_empty() {
        return Err(Error::dataset(format!(
            "no scene folder with im0.png and {result_name} (MiddEval3), nor a KITTI or ETH3D tree, under {}",
            dir.display()
        )));
    }
    scenes
        .into_iter()
        .map(|s| {
            let truth = TruthFiles::existing(Truth::in_scene(&s));
            let (scale, resolution) = match &truth {
                Some(_) => middlebury_resolution(&s, opts.scale)?,
                None => (opts.scale.unwrap_or(1), None),
            };
            Ok(SheetRow {
                name: crate::batch::scene_name(&s),
                location: s.clone(),
                left: s.join(LEFT_FILE),
                result: s.join(&result_name),
                truth,
                calib: Some(s.join(CALIB_FILE)),
                rule: ErrorRule::Middlebury { scale },
                resolution,
                config: s.join(format!("config{alg}.toml")),
            })
        })
        .collect()
}

/// One row's pictures at full size, and what a reader needs beside them.
#[derive(Clone, Debug)]
pub struct RowPictures {
    /// The left image.
    pub left: Canvas,
    /// The result in colour ([`colorize`] over [`RowPictures::range`]).
    pub colour: Canvas,
    /// The error map under the row's rule ([`error_map`]); a dark panel without ground truth.
    pub error: Canvas,
    /// The disparities the colours span: `vmin`/`vmax` of the row's `calib.txt`, else the ground truth's finite
    /// range, else the result's.
    pub range: (f32, f32),
    /// The row's headline scores under its benchmark's rule, when it has ground truth.
    pub score: Option<RowScore>,
}

/// A row's headline scores, as `jem eval` computes them (non-occluded pixels).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RowScore {
    /// Mean absolute error over the valid pixels (full-resolution pixels for MiddEval3).
    pub avgerr: f64,
    /// The benchmark's bad-pixel share, in % ([`RowScore::bad_name`]).
    pub bad: f64,
    /// Its name: `bad-2` (MiddEval3, invalid pixels counted), `D1` (KITTI), `bad-1` (ETH3D).
    pub bad_name: &'static str,
}

impl RowScore {
    /// `avgErr 1.53, bad-2 9.1 %`.
    pub fn describe(&self) -> String {
        format!("avgErr {:.2}, {} {:.1} %", self.avgerr, self.bad_name, self.bad)
    }
}

/// Draws one row at full size (see [`RowPictures`]).
///
/// # Errors
/// Unreadable files or unequal sizes.
pub fn render_row(row: &SheetRow) -> Result<RowPictures> {
    let result = crate::io::read_disparity(&row.result)?;
    let left = Canvas::from_rgb_image(&crate::io::png::load_rgb(&row.left)?);
    if (left.width, left.height) != result.dims() {
        return Err(Error::bad_image_at(
            &row.result,
            format!(
                "the result is {}x{} but the left image {} is {}x{}",
                result.width,
                result.height,
                row.left.display(),
                left.width,
                left.height
            ),
        ));
    }
    let gt = row.truth.as_ref().map(|t| load_truth(&result, t, row.rule)).transpose()?;
    let range = row
        .calib
        .as_deref()
        .and_then(calib_range)
        .or_else(|| gt.as_ref().and_then(|(g, _)| finite_range(g)))
        .or_else(|| finite_range(&result))
        .unwrap_or((0.0, 1.0));
    let colour = colorize(&result, range.0, range.1);
    let (error, score) = match &gt {
        Some((g, m)) => (error_map(&result, g, m.as_ref(), row.rule), Some(score(&result, g, m.as_ref(), row))),
        None => (Canvas::new(result.width, result.height, NO_GT), None),
    };
    Ok(RowPictures { left, colour, error, range, score })
}

/// The row's scores under its rule, on its non-occluded pixels: MiddEval3's avgErr and bad-2 + invalid, KITTI's D1
/// (the result filled as the devkit fills it first), ETH3D's bad-1.
fn score(result: &DisparityMap, gt: &DisparityMap, mask: Option<&Plane<u8>>, row: &SheetRow) -> RowScore {
    use crate::eval::{MaskMode, evaluate};
    let ndisp = row.calib.as_deref().and_then(|c| crate::io::calib::read_ndisp(c).ok()).unwrap_or(usize::MAX / 2);
    match row.rule {
        ErrorRule::Middlebury { scale } => {
            let m = evaluate(result, gt, mask, ndisp, scale, MaskMode::Nonocc);
            RowScore { avgerr: m.avgerr, bad: m.totbad2, bad_name: "bad-2" }
        }
        ErrorRule::KittiD1 => {
            let mut filled = result.clone();
            crate::eval::interpolate_background(&mut filled);
            let m = evaluate(&filled, gt, mask, ndisp, 1, MaskMode::Nonocc);
            RowScore { avgerr: m.avgerr, bad: m.d1, bad_name: "D1" }
        }
        ErrorRule::Eth3d => {
            let m = evaluate(result, gt, mask, ndisp, 1, MaskMode::Nonocc);
            RowScore { avgerr: m.avgerr, bad: m.bad1 + m.invalid, bad_name: "bad-1" }
        }
    }
}

/// What [`contact_sheet`] drew.
#[derive(Clone, Debug)]
pub struct Sheet {
    /// The picture.
    pub canvas: Canvas,
    /// The rows drawn, in order.
    pub rows: Vec<SheetRow>,
    /// Rows left out because their files could not be drawn, with the reason.
    pub skipped: Vec<(SheetRow, String)>,
}

/// Labels are drawn at this many canvas pixels per font pixel.
const TEXT_SCALE: usize = 2;
/// Label colours: names and headers, figures.
const TEXT: [u8; 3] = [235, 235, 235];
const DIM_TEXT: [u8; 3] = [170, 170, 170];
/// Room around labels.
const PAD: usize = 8;
/// The width of the label column, in characters.
const LABEL_CHARS: usize = 15;

/// A contact sheet of `rows` (from [`sheet_rows`]) under a header naming the columns (`alg` names the result's):
/// each row `name and scores | left image | result in colour | error map`, the panels at most `panel_width`
/// wide; below them a colour bar (the colours from each row's low to its high disparity, the row's range beside
/// its name) and the error map's legend. A row whose files cannot be drawn is left out and listed in
/// [`Sheet::skipped`].
///
/// # Errors
/// None of the rows could be drawn.
pub fn contact_sheet(rows: Vec<SheetRow>, alg: &str, panel_width: usize) -> Result<Sheet> {
    let (mut drawn_rows, mut drawn, mut skipped) = (Vec::new(), Vec::new(), Vec::new());
    for row in rows {
        match render_row(&row) {
            Ok(p) => {
                drawn_rows.push(labelled_row(&row, &p, panel_width));
                drawn.push(row);
            }
            Err(e) => skipped.push((row, e.to_string())),
        }
    }
    if drawn_rows.is_empty() {
        let why: Vec<String> = skipped.iter().map(|(_, e)| e.clone()).collect();
        return Err(Error::dataset(format!("no scene could be drawn: {}", why.join("; "))));
    }
    let rule = drawn.iter().find(|r| r.truth.is_some()).map(|r| r.rule);
    let header = header(&drawn_rows[0], alg, rule, panel_width);
    let body_width = drawn_rows.iter().map(|c| c.width).max().unwrap_or(0);
    let footer = footer(body_width.max(header.width));
    let mut parts = vec![header];
    parts.extend(drawn_rows);
    parts.push(footer);
    Ok(Sheet { canvas: vstack(&parts, PAD), rows: drawn, skipped })
}

/// The width of the label column in pixels.
fn label_width() -> usize {
    super::font::text_size(&"M".repeat(LABEL_CHARS), TEXT_SCALE).0 + PAD
}

/// A row: its label (name, scores, disparity range) beside its three panels.
fn labelled_row(row: &SheetRow, p: &RowPictures, panel_width: usize) -> Canvas {
    let panels: Vec<Canvas> = [&p.left, &p.colour, &p.error].iter().map(|c| fit_width(c, panel_width)).collect();
    let panels = hstack(&panels, 4);
    let line = super::font::GLYPH.1 * TEXT_SCALE + 4;
    let mut label = Canvas::new(label_width(), panels.height.max(4 * line), BACKGROUND);
    let name: String = row.name.chars().take(LABEL_CHARS).collect();
    super::font::draw_text(&mut label, (0, 0), &name, TEXT, TEXT_SCALE);
    let mut lines = Vec::new();
    if let Some(s) = p.score {
        lines.push(format!("avgErr {:.2}", s.avgerr));
        lines.push(format!("{} {:.1}%", s.bad_name, s.bad));
    }
    lines.push(format!("d {:.0}..{:.0}", p.range.0, p.range.1));
    for (k, text) in lines.iter().enumerate() {
        super::font::draw_text(&mut label, (0, (k + 1) * line), text, DIM_TEXT, TEXT_SCALE);
    }
    hstack(&[label, panels], 0)
}

/// The column titles over the first row's panels.
fn header(first: &Canvas, alg: &str, rule: Option<ErrorRule>, panel_width: usize) -> Canvas {
    let line = super::font::GLYPH.1 * TEXT_SCALE;
    let mut c = Canvas::new(first.width, line + 2, BACKGROUND);
    let error_title = match rule {
        Some(ErrorRule::Middlebury { .. }) => "error: bad-2",
        Some(ErrorRule::KittiD1) => "error: D1",
        Some(ErrorRule::Eth3d) => "error: bad-1",
        None => "error (no truth)",
    };
    let titles = ["scene", "left image", alg, error_title];
    // The panels' left edges: after the label column, then each panel's width and the 4-pixel gap.
    let step = (first.width - label_width() + 4) / 3;
    let x = [0, label_width(), label_width() + step, label_width() + 2 * step];
    for (title, x) in titles.iter().zip(x) {
        let max_chars = (panel_width / ((super::font::GLYPH.0 + 1) * TEXT_SCALE)).max(4);
        let t: String = title.chars().take(max_chars).collect();
        super::font::draw_text(&mut c, (x, 0), &t, TEXT, TEXT_SCALE);
    }
    c
}

/// The colour bar (low to high disparity) and the error map's legend.
fn footer(width: usize) -> Canvas {
    let line = super::font::GLYPH.1 * TEXT_SCALE;
    let mut c = Canvas::new(width.max(600), 2 * line + 3 * PAD, BACKGROUND);
    let (far, near) = ("low d (far)", "high d (near)");
    let far_w = super::font::text_size(far, TEXT_SCALE).0;
    super::font::draw_text(&mut c, (0, 0), far, DIM_TEXT, TEXT_SCALE);
    let bar = 256;
    for x in 0..bar {
        let colour = super::colormap(x as f32 / (bar - 1) as f32);
        for y in 0..line {
            let i = (y * c.width + far_w + PAD + x) * 3;
            c.data[i..i + 3].copy_from_slice(&colour);
        }
    }
    super::font::draw_text(&mut c, (far_w + 2 * PAD + bar, 0), near, DIM_TEXT, TEXT_SCALE);
    let y = line + 2 * PAD;
    let mut x = 0;
    let legend: [([u8; 3], &str); 4] =
        [([205, 205, 205], "good"), ([230, 30, 30], "bad"), ([0, 0, 0], "invalid"), (NO_GT, "no truth")];
    for (colour, text) in legend {
        for yy in y..y + line {
            for xx in x..(x + line).min(c.width) {
                let i = (yy * c.width + xx) * 3;
                c.data[i..i + 3].copy_from_slice(&colour);
            }
        }
        let after = x + line + PAD / 2;
        super::font::draw_text(&mut c, (after, y), text, DIM_TEXT, TEXT_SCALE);
        x = after + super::font::text_size(text, TEXT_SCALE).0 + 2 * PAD;
    }
    c
}

#[cfg(test)]
#[path = "sheet_tests.rs"]
mod tests;
