//! An HTML report of results (what `jem report` writes): one page that opens from the disk in any browser, with
//! its pictures in a folder beside it (`<stem>_files/`), nothing loaded from a network.
//!
//! Per scene (or frame) a row: the left image and, for each algorithm, its disparity in colour and its error map
//! under the benchmark's rule (thumbnails that link to the full-size pictures: [`crate::viz::render_row`]), and
//! its scores as `jem eval` computes them ([`crate::eval::evaluate_dir`]): MiddEval3 avgErr, bad-2 (invalid
//! pixels counted as bad, as the contact sheet's), invalid and the run time, with the paper's avgErr for an
//! algorithm given a paper column; KITTI D1 and avgErr; ETH3D bad-1 and avgErr. A summary row holds the weighted
//! (MiddEval3) or plain mean. A click on a score's header sorts the rows (a few lines of inline JavaScript); a
//! colour bar and the error map's legend say how to read the pictures; the foot holds the command, each
//! algorithm's configuration where it was recorded, and the machine.
//!
//! Writing: the pictures are drawn and encoded a few scenes at a time (as many as there are threads), each
//! staged to its temporary file at once ([`crate::io::AllOrNone`]), so memory holds a few scenes' pictures, not
//! the data set's; the page is staged last and everything is renamed into place together, or nothing is. An
//! output that is one of the inputs is refused before any work.
//!
//! Files: `mod.rs` (finding the rows and scores, drawing and writing), `html.rs` (the page), `page.css` and
//! `page.js` (its style and its sorting, inlined into the page).

mod html;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;

use crate::dataset::Layout;
use crate::error::{Error, Result};
use crate::eval::{AlgReport, MaskMode, Metrics, PaperColumn, Sources};
use crate::viz::{Canvas, ErrorRule, SheetOptions, SheetRow};

/// What [`write_report`] reports on, and how.
#[derive(Clone, Debug)]
pub struct ReportOptions {
    /// The algorithms, in their columns' order (results as `jem batch --alg NAME` wrote them).
    pub algs: Vec<String>,
    /// The paper's column to show beside each algorithm (`None`: none), one per algorithm (or empty).
    pub papers: Vec<Option<PaperColumn>>,
    /// Which pixels are scored.
    pub mask: MaskMode,
    /// MiddEval3's factor to full-resolution pixels (default: inferred, as `jem eval` infers it).
    pub scale: Option<u32>,
    /// Read the data as this layout instead of recognising it.
    pub layout: Option<Layout>,
    /// ETH3D's ground-truth tree (default: the sibling `<name>_gt/`).
    pub gt: Option<PathBuf>,
    /// Where KITTI and ETH3D results are (default: `results/` beside the data set).
    pub results: Option<PathBuf>,
    /// The largest width of a thumbnail, in pixels.
    pub thumb_width: usize,
    /// The command that made the report, shown at its foot.
    pub command: String,
}

/// What [`write_report`] wrote.
#[derive(Clone, Debug)]
pub struct ReportSummary {
    /// The page.
    pub page: PathBuf,
    /// The folder of its pictures.
    pub files: PathBuf,
    /// Rows written.
    pub scenes: usize,
    /// Pictures written (full size and thumbnails).
    pub pictures: usize,
    /// Pictures that could not be drawn: their cells say so.
    pub not_drawn: Vec<NotDrawn>,
    /// How the MiddEval3 resolution was found, when the data told it (see [`AlgReport::scale_inferred`]).
    pub scale_inferred: Option<String>,
    /// Runs that were writing these results while the report was made.
    pub writers: Vec<String>,
}

/// An algorithm's pictures of a scene that could not be drawn.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NotDrawn {
    /// The scene (or frame).
    pub scene: String,
    /// The algorithm.
    pub alg: String,
    /// Why.
    pub reason: String,
}

/// The pictures of one algorithm in one row: file names in the pictures folder.
#[derive(Clone, Debug, PartialEq)]
struct Pictures {
    colour: Picture,
    error: Picture,
    /// The disparities the colours span.
    range: (f32, f32),
}

/// A picture at full size and its thumbnail, as file names in the pictures folder.
#[derive(Clone, Debug, PartialEq)]
struct Picture {
    full: String,
    thumb: String,
    /// The thumbnail's size, for the page's layout before it loads.
    thumb_size: (usize, usize),
}

/// One algorithm's cell of a row.
#[derive(Clone, Debug, Default)]
struct AlgCell {
    /// Its pictures, or why there are none (`None`: no result).
    pictures: Option<std::result::Result<Pictures, String>>,
    /// Its scores, or why there are none (`None`: the scene has no ground truth).
    metrics: Option<std::result::Result<Metrics, Arc<Error>>>,
    /// Its run time, in seconds.
    seconds: Option<f64>,
    /// The paper's avgErr for the scene, when a paper column is shown.
    paper: Option<f64>,
}

/// One row of the page: a scene or frame.
#[derive(Clone, Debug)]
struct Row {
    name: String,
    location: PathBuf,
    /// MiddEval3's weight of the scene in the summary row.
    weight: Option<f64>,
    left: Option<Picture>,
    cells: Vec<AlgCell>,
}

/// The scores a layout's table shows for each algorithm, with their header and the metric key.
#[derive(Clone, Copy, Debug)]
struct Column {
    /// The header.
    title: &'static str,
    /// What it means (the header's tooltip).
    help: &'static str,
    /// The metric it shows.
    value: fn(&Metrics) -> f64,
    /// Digits after the point.
    digits: usize,
}

/// The score columns of a layout.
fn columns(layout: Layout) -> Vec<Column> {
    let avgerr =
        Column { title: "avgErr", help: "mean absolute error of the valid pixels", value: |m| m.avgerr, digits: 2 };
    match layout {
        Layout::Middlebury => vec![
            Column { help: "mean absolute error of the valid pixels, in full-resolution pixels", ..avgerr },
            Column {
                title: "bad-2",
                help: "% of the pixels with an error above 2 full-resolution pixels, invalid ones counted as bad",
                value: |m| m.totbad2,
                digits: 1,
            },
            Column { title: "invalid", help: "% of the pixels without a disparity", value: |m| m.invalid, digits: 1 },
        ],
        Layout::Kitti2015 | Layout::Kitti2012 => vec![
            Column {
                title: "D1",
                help: "% of the pixels with an error above 3 px and 5 % of the true disparity (after the devkit's fill)",
                value: |m| m.d1,
                digits: 1,
            },
            avgerr,
        ],
        Layout::Eth3d => vec![
            Column {
                title: "bad-1",
                help: "% of the pixels with an error above 1 px, invalid ones counted as bad",
                value: |m| m.bad1 + m.invalid,
                digits: 1,
            },
            avgerr,
        ],
    }
}

/// The report's content before it is written as a page.
#[derive(Clone, Debug)]
struct Model {
    dir: PathBuf,
    layout: Layout,
    rule: Option<ErrorRule>,
    mask: MaskMode,
    algs: Vec<String>,
    papers: Vec<Option<PaperColumn>>,
    evals: Vec<Option<AlgReport>>,
    rows: Vec<Row>,
    /// Each algorithm's configurations as its runs recorded them, and how many results it has.
    configs: Vec<(Vec<Recorded>, usize)>,
    command: String,
    machine: String,
}

/// Checks the options and the output's name; returns the pictures folder (`<stem>_files` beside `out`).
fn check_request(out: &Path, opts: &ReportOptions) -> Result<PathBuf> {
    let ext = out.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("html" | "htm")) {
        return Err(Error::output_at(out, "a report is an HTML page (use a .html name)"));
    }
    if opts.algs.is_empty() {
        return Err(Error::argument("no --alg: name the results to report on"));
    }
    for (i, a) in opts.algs.iter().enumerate() {
        crate::batch::validate_alg_name(a)?;
        if opts.algs[..i].contains(a) {
            return Err(Error::argument(format!("--alg {a} is given twice")));
        }
    }
    if !opts.papers.is_empty() && opts.papers.len() != opts.algs.len() {
        return Err(Error::argument(format!(
            "{} paper columns for {} algorithms: give one per --alg (- for none)",
            opts.papers.len(),
            opts.algs.len()
        )));
    }
    if !(32..=1024).contains(&opts.thumb_width) {
        return Err(Error::param("--thumb-width", opts.thumb_width, "32 to 1024 pixels"));
    }
    let stem = out
        .file_stem()
        .and_then(|s| s.to_str())
        .filter(|s| !s.is_empty())
        .ok_or_else(|| Error::output_at(out, "the page needs a name that is text (its pictures go beside it)"))?;
    let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !parent.is_dir() {
        return Err(Error::output_at(out, format!("the folder {} does not exist", parent.display())));
    }
    let files = out.with_file_name(format!("{stem}_files"));
    if files.exists() && !files.is_dir() {
        return Err(Error::output_at(&files, "the report's pictures go there, but it is a file, not a folder"));
    }
    Ok(files)
}

/// Writes the report of `opts.algs`' results under `dir` to the page `out` and its pictures to `<stem>_files/`
/// beside it (see the module doc), all or none.
///
/// # Errors
/// Bad options or output name, no results of an algorithm, no scene that could be drawn, an output that is one of
/// the inputs, or a file that could not be written (nothing is then written).
pub fn write_report(dir: &Path, out: &Path, opts: &ReportOptions) -> Result<ReportSummary> {
    let files = check_request(out, opts)?;
    let sheet_opts =
        SheetOptions { scale: opts.scale, layout: opts.layout, results: opts.results.clone(), gt: opts.gt.clone() };
    let per_alg: Vec<Vec<SheetRow>> =
        opts.algs.iter().map(|a| crate::viz::sheet_rows(dir, a, &sheet_opts)).collect::<Result<_>>()?;
    let inputs: Vec<&Path> = per_alg.iter().flatten().flat_map(SheetRow::paths).collect();
    crate::io::check_outputs(&inputs, &[out])?;
    let has_truth = per_alg.iter().flatten().any(|r| r.truth.is_some());
    let sources = Sources { layout: opts.layout, gt: opts.gt.clone(), results: opts.results.clone() };
    let evals: Vec<Option<AlgReport>> = opts
        .algs
        .iter()
        .map(|a| has_truth.then(|| crate::eval::evaluate_dir(dir, a, opts.mask, opts.scale, &sources)).transpose())
        .collect::<Result<_>>()?;
    let layout = layout_of(&evals, &per_alg);
    let mut rows = join_rows(&opts.algs, &per_alg, &evals, &opts.papers);
    let created = !files.exists();
    if created {
        std::fs::create_dir(&files).map_err(|e| Error::io(&files, e))?;
    }
    // What a killed report (kill -9) left: its temporary pictures and page.
    crate::io::sweep_stale_temps(&files);
    crate::io::sweep_stale_temps(out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")));
    let written = (|| {
        let mut set = crate::io::AllOrNone::new();
        let names: Vec<String> = (0..rows.len()).map(|i| file_stem(i, &rows[i].name)).collect();
        let (pictures, not_drawn) = draw_rows(&mut rows, &names, &per_alg, &files, opts, &mut set)?;
        if rows.iter().all(|r| r.left.is_none()) {
            let why: Vec<String> = not_drawn.iter().map(|n| format!("{} ({}): {}", n.scene, n.alg, n.reason)).collect();
            return Err(Error::dataset(format!("no scene could be drawn: {}", why.join("; "))));
        }
        let rule = per_alg.iter().flatten().find(|r| r.truth.is_some()).map(|r| r.rule);
        let model = Model {
            dir: dir.to_path_buf(),
            layout,
            rule,
            mask: opts.mask,
            algs: opts.algs.clone(),
            papers: if opts.papers.is_empty() { vec![None; opts.algs.len()] } else { opts.papers.clone() },
            evals: evals.clone(),
            rows,
            configs: per_alg.iter().map(|rows| (recorded_configs(rows), rows.len())).collect(),
            command: opts.command.clone(),
            machine: machine(),
        };
        let folder = files.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let page = html::page(&model, folder);
        set.add(out, page.as_bytes())?;
        set.commit()?;
        Ok((model.rows.len(), pictures, not_drawn))
    })();
    match written {
        Ok((scenes, pictures, not_drawn)) => Ok(ReportSummary {
            page: out.to_path_buf(),
            files,
            scenes,
            pictures,
            not_drawn,
            scale_inferred: evals.iter().flatten().find_map(|e| e.scale_inferred.clone()),
            writers: evals.iter().flatten().flat_map(|e| e.writers.clone()).collect(),
        }),
        Err(e) => {
            if created {
                // Empty: every staged file was removed with the set.
                let _ = std::fs::remove_dir(&files);
            }
            Err(e)
        }
    }
}

/// The layout of the report: `jem eval`'s, else the one the rows' error rule implies (the two KITTI layouts show
/// the same scores).
fn layout_of(evals: &[Option<AlgReport>], per_alg: &[Vec<SheetRow>]) -> Layout {
    if let Some(e) = evals.iter().flatten().next() {
        return e.layout;
    }
    match per_alg.iter().flatten().next().map(|r| r.rule) {
        Some(ErrorRule::KittiD1) => Layout::Kitti2015,
        Some(ErrorRule::Eth3d) => Layout::Eth3d,
        _ => Layout::Middlebury,
    }
}

/// The rows: every scene any algorithm has a result for or `jem eval` scored, sorted by location, with each
/// algorithm's scores and the paper's avgErr.
fn join_rows(
    algs: &[String],
    per_alg: &[Vec<SheetRow>],
    evals: &[Option<AlgReport>],
    papers: &[Option<PaperColumn>],
) -> Vec<Row> {
    let mut rows: BTreeMap<PathBuf, Row> = BTreeMap::new();
    let blank = |name: &str, location: &Path| Row {
        name: name.to_string(),
        location: location.to_path_buf(),
        weight: None,
        left: None,
        cells: vec![AlgCell::default(); algs.len()],
    };
    for (a, sheet) in per_alg.iter().enumerate() {
        for r in sheet {
            let row = rows.entry(r.location.clone()).or_insert_with(|| blank(&r.name, &r.location));
            row.cells[a].pictures = Some(Err("not drawn yet".into()));
        }
    }
    for (a, eval) in evals.iter().enumerate() {
        for s in eval.iter().flat_map(|e| &e.scenes) {
            let row = rows.entry(s.dir.clone()).or_insert_with(|| blank(&s.name, &s.dir));
            // eval's names are unique (paths where scene names repeat).
            row.name.clone_from(&s.name);
            if eval.as_ref().is_some_and(|e| e.layout == Layout::Middlebury) {
                row.weight = Some(s.weight);
            }
            row.cells[a].metrics = Some(s.metrics.clone());
            row.cells[a].seconds = s.seconds;
            let paper = papers.get(a).and_then(Option::as_ref);
            let scene = s.dir.file_name().and_then(|n| n.to_str()).unwrap_or(&s.name);
            row.cells[a].paper = paper.and_then(|p| p.scenes.get(scene).copied());
        }
    }
    rows.into_values().collect()
}

/// A picture file's stem for row `index`: its number (so names never collide) and its name in safe characters.
fn file_stem(index: usize, name: &str) -> String {
    let safe: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' })
        .take(48)
        .collect();
    format!("{:03}-{safe}", index + 1)
}

/// A picture's encoded files: (name, bytes) of the full size and the thumbnail, and the thumbnail's size.
type Encoded = (Picture, [(String, Vec<u8>); 2]);

/// Encodes a picture and its thumbnail as PNGs named `stem.png` and `stem.thumb.png`.
fn encode(canvas: &Canvas, stem: &str, thumb_width: usize) -> Result<Encoded> {
    let thumb = crate::viz::fit_width(canvas, thumb_width);
    let (full, small) = (format!("{stem}.png"), format!("{stem}.thumb.png"));
    let bytes = |c: &Canvas, name: &str| crate::io::png::encode_rgb8_png(Path::new(name), c.width, c.height, &c.data);
    let files = [(full.clone(), bytes(canvas, &full)?), (small.clone(), bytes(&thumb, &small)?)];
    Ok((Picture { full, thumb: small, thumb_size: (thumb.width, thumb.height) }, files))
}

/// What drawing one row gave: its left picture and each algorithm's pictures (or why not), with their files.
type DrawnRow = (Option<Encoded>, Vec<Option<std::result::Result<(Pictures, Vec<Encoded>), String>>>);

/// Draws one row: the left image once, each algorithm's colour and error maps.
fn draw_row(row: &Row, stem: &str, sheets: &[Option<&SheetRow>], algs: &[String], thumb: usize) -> DrawnRow {
    let mut left = None;
    let mut cells = Vec::with_capacity(algs.len());
    for (sheet, alg) in sheets.iter().zip(algs) {
        let Some(sheet) = sheet else {
            cells.push(None);
            continue;
        };
        let drawn = crate::viz::render_row(sheet).and_then(|p| {
            if left.is_none() {
                left = Some(encode(&p.left, &format!("{stem}-left"), thumb)?);
            }
            let colour = encode(&p.colour, &format!("{stem}-{alg}-disparity"), thumb)?;
            let error = encode(&p.error, &format!("{stem}-{alg}-error"), thumb)?;
            let pictures = Pictures { colour: colour.0.clone(), error: error.0.clone(), range: p.range };
            Ok((pictures, vec![colour, error]))
        });
        cells.push(Some(drawn.map_err(|e| format!("{} cannot be drawn: {e}", row.name))));
    }
    (left, cells)
}

/// Draws every row's pictures, a few rows at a time (in parallel), staging their files into `set` as they come;
/// fills in the rows' pictures. Returns the number of files and what could not be drawn.
fn draw_rows(
    rows: &mut [Row],
    names: &[String],
    per_alg: &[Vec<SheetRow>],
    files: &Path,
    opts: &ReportOptions,
    set: &mut crate::io::AllOrNone,
) -> Result<(usize, Vec<NotDrawn>)> {
    let algs = &opts.algs;
    let sheet_of = |row: &Row, a: usize| per_alg[a].iter().find(|s| s.location == row.location);
    let (mut count, mut not_drawn) = (0, Vec::new());
    let batch = rayon::current_num_threads().max(1);
    for start in (0..rows.len()).step_by(batch) {
        let end = (start + batch).min(rows.len());
        let drawn: Vec<DrawnRow> = (start..end)
            .into_par_iter()
            .map(|i| {
                let sheets: Vec<Option<&SheetRow>> = (0..algs.len()).map(|a| sheet_of(&rows[i], a)).collect();
                draw_row(&rows[i], &names[i], &sheets, algs, opts.thumb_width)
            })
            .collect();
        for (i, (left, cells)) in (start..end).zip(drawn) {
            let mut stage = |encoded: &Encoded| -> Result<()> {
                for (name, bytes) in &encoded.1 {
                    set.add(&files.join(name), bytes)?;
                    count += 1;
                }
                Ok(())
            };
            if let Some(l) = &left {
                stage(l)?;
            }
            rows[i].left = left.map(|l| l.0);
            for (a, cell) in cells.into_iter().enumerate() {
                rows[i].cells[a].pictures = match cell {
                    None => None,
                    Some(Ok((pictures, encoded))) => {
                        encoded.iter().try_for_each(&mut stage)?;
                        Some(Ok(pictures))
                    }
                    Some(Err(e)) => {
                        not_drawn.push(NotDrawn {
                            scene: rows[i].name.clone(),
                            alg: algs[a].clone(),
                            reason: e.clone(),
                        });
                        Some(Err(e))
                    }
                };
            }
        }
    }
    Ok((count, not_drawn))
}

/// A configuration recorded beside results (`jem batch`, [`crate::batch::config_record`]), and the scenes whose
/// results it made.
#[derive(Clone, Debug, PartialEq)]
struct Recorded {
    text: String,
    scenes: Vec<String>,
}

/// The configurations recorded beside an algorithm's results, each with its scenes, in the rows' order; results
/// with none recorded (written by another program) are in none of them.
fn recorded_configs(rows: &[SheetRow]) -> Vec<Recorded> {
    let mut found: Vec<Recorded> = Vec::new();
    for row in rows {
        let Some(text) = crate::io::read_small_text(&row.config, crate::io::MAX_CONFIG_BYTES) else { continue };
        match found.iter_mut().find(|r| r.text == text) {
            Some(r) => r.scenes.push(row.name.clone()),
            None => found.push(Recorded { text, scenes: vec![row.name.clone()] }),
        }
    }
    found
}

/// The machine the report was made on: its CPU, its cores and jem's version.
fn machine() -> String {
    let cores = std::thread::available_parallelism().map_or(0, std::num::NonZero::get);
    let cpu = match crate::process::cpu_model() {
        Some((model, n)) => format!("{model} ({n} logical processors)"),
        None => "CPU model unknown".into(),
    };
    format!("{cpu}; {cores} cores available to jem; jem {}", env!("CARGO_PKG_VERSION"))
}

#[cfg(test)]
mod tests;
