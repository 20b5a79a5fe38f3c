//! `jem viz`: draws a disparity map in colour (beside its error map with `--gt`), or a contact sheet of a folder
//! of scenes, with [`jem::viz`].

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use jem::{Error, Result};

use super::GlobalArgs;

/// Arguments of `jem viz` (the help text is on [`Command::Viz`](super::Command::Viz)).
#[derive(Args, Debug, Clone)]
pub(super) struct VizArgs {
    /// A disparity map (.pfm, .exr or 16-bit .png), or a data set's folder (with --alg): MiddEval3 scenes, a KITTI
    /// or an ETH3D tree.
    #[arg(value_name = "DISP|DIR")]
    input: PathBuf,
    /// Output PNG.
    #[arg(long, short, value_name = "OUT.png")]
    output: PathBuf,
    /// Ground truth for the error map: a file (.pfm, or KITTI's 16-bit .png) beside DISP; with a folder, ETH3D's
    /// ground-truth tree (default: its sibling *_gt/).
    #[arg(long, value_name = "GT")]
    gt: Option<PathBuf>,
    /// Low end of the colour range (disparity px).
    #[arg(long, value_name = "A", allow_negative_numbers = true)]
    vmin: Option<f32>,
    /// High end of the colour range (disparity px).
    #[arg(long, value_name = "B", allow_negative_numbers = true)]
    vmax: Option<f32>,
    /// With a folder: draw NAME's results (MiddEval3 disp0NAME.pfm; KITTI and ETH3D where `jem batch --alg NAME`
    /// writes them).
    #[arg(long, value_name = "NAME")]
    alg: Option<String>,
    /// MiddEval3: factor to full-resolution px for the bad-2 rule (default: from the path, trainingQ = 4, *H = 2,
    /// *F = 1, else from the scene's name and size; required when nothing tells). KITTI and ETH3D are in native
    /// pixels.
    #[arg(long, value_name = "1|2|4")]
    scale: Option<u32>,
    /// Read the data as this layout (middlebury, eth3d, kitti2015, kitti2012) instead of recognising it; sets the
    /// error rule.
    #[arg(long, value_name = "LAYOUT")]
    layout: Option<jem::dataset::Layout>,
    /// Where KITTI and ETH3D results are: RESULTS/NAME/SPLIT/ (default: results/ beside the data set, as batch).
    #[arg(long, value_name = "RESULTS")]
    results: Option<PathBuf>,
    /// DISP is a depth map (jem --depth): coloured by inverse depth (near dark red, far indigo) with a labelled
    /// scale bar under it, over --vmin..--vmax in the depth's unit, else the 2nd to 98th percentile of its depths.
    #[arg(long)]
    depth: bool,
    /// Largest panel width of a contact sheet, in pixels.
    #[arg(long, value_name = "PX", default_value_t = 320)]
    panel_width: usize,
}

/// Draws one map, or a contact sheet of a folder.
pub(super) fn run(args: &VizArgs, global: &GlobalArgs) -> Result<ExitCode> {
    use jem::viz;
    let ext = args.output.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if ext.as_deref() != Some("png") {
        return Err(Error::output_at(&args.output, "viz writes PNG (use a .png name)"));
    }
    if let Some(s) = args.scale
        && ![1, 2, 4].contains(&s)
    {
        return Err(Error::param("--scale", s, "1, 2 or 4"));
    }
    if args.input.is_dir() {
        return sheet(args, global);
    }
    // Before any file is read (colour_range checks them again with the map).
    for (flag, v) in [("--vmin", args.vmin), ("--vmax", args.vmax)] {
        if let Some(v) = v.filter(|v| !v.is_finite()) {
            return Err(Error::param(flag, v, "a finite number"));
        }
    }
    let dir = args.input.parent().unwrap_or(Path::new("."));
    let truth = args.gt.as_deref().map(|gt| (gt, viz::gt_rule(gt, args.layout, args.scale)));
    let mut read = vec![args.input.as_path().to_path_buf(), dir.join(jem::dataset::CALIB_FILE)];
    if let Some((gt, rule)) = &truth {
        read.push(gt.to_path_buf());
        if let Ok(found) = rule {
            read.extend(found.files.paths().into_iter().map(Path::to_path_buf));
        }
    }
    let read_refs: Vec<&Path> = read.iter().map(PathBuf::as_path).collect();
    jem::io::check_outputs(&read_refs, &[&args.output])?;
    // A depth PNG holds the depth itself, not a disparity × 256.
    let disp = if args.depth { jem::io::read_depth(&args.input)? } else { jem::io::read_disparity(&args.input)? };
    if args.depth {
        if args.gt.is_some() {
            return Err(Error::argument("--gt scores disparity maps; a depth map (--depth) is drawn alone"));
        }
        let auto = viz::depth_range(&disp);
        let near = args.vmin.or(auto.map(|r| r.0)).unwrap_or(1.0);
        let far = args.vmax.or(auto.map(|r| r.1)).unwrap_or(near);
        if (args.vmin.is_some() || args.vmax.is_some()) && !(near > 0.0 && near < far) {
            return Err(Error::param("--vmin / --vmax", format!("{near} / {far}"), "depths with 0 < --vmin < --vmax"));
        }
        let picture = viz::colorize_depth(&disp, near, far);
        picture.write_png(&args.output)?;
        if !global.quiet {
            let (w, h) = (picture.width, picture.height);
            note!(
                "wrote {} ({w}×{h}): depth coloured by 1/Z from {} (dark red) to {} (indigo), scale bar below",
                args.output.display(),
                three_digits(near),
                three_digits(far)
            );
        }
        return Ok(ExitCode::SUCCESS);
    }
    let truth = match truth {
        None => None,
        Some((_, Ok(t))) => Some(t),
        // A ground truth that cannot be read is the first thing to say; then that its resolution is unknown.
        Some((gt, Err(e))) => {
            jem::io::read_disparity(gt)?;
            return Err(e);
        }
    };
    let calib = viz::calib_range(&dir.join(jem::dataset::CALIB_FILE));
    let (vmin, vmax) = viz::colour_range(&disp, (args.vmin, args.vmax), calib, ("--vmin", "--vmax"))?;
    let colour = viz::colorize(&disp, vmin, vmax);
    let (picture, error) = match &truth {
        None => (colour, String::new()),
        Some(found) => {
            let (files, rule) = (&found.files, found.rule);
            let (gt, mask) = viz::load_truth(&disp, files, rule)?;
            if let Some(res) = found.resolution.as_ref().filter(|r| r.from_contents() && !global.quiet) {
                let gt = files.disparity.display();
                note!("note: {gt}: {}, as {} (--scale sets it)", res.name(), res.reason());
            }
            let error = format!(" | error map against {}, red: {}", files.disparity.display(), rule.describe());
            (viz::hstack(&[colour, viz::error_map(&disp, &gt, mask.as_ref(), rule)], 4), error)
        }
    };
    picture.write_png(&args.output)?;
    if !global.quiet {
        let (w, h) = (picture.width, picture.height);
        note!("wrote {} ({w}×{h}): disparity coloured over {vmin:.2}..{vmax:.2}{error}", args.output.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// A contact sheet of a data set's folder.
fn sheet(args: &VizArgs, global: &GlobalArgs) -> Result<ExitCode> {
    use jem::viz;
    let Some(alg) = &args.alg else {
        return Err(Error::argument(format!(
            "{} is a folder: give --alg NAME for a contact sheet",
            args.input.display()
        )));
    };
    jem::batch::validate_alg_name(alg)?;
    if args.panel_width < 16 {
        return Err(Error::param("--panel-width", args.panel_width, "at least 16"));
    }
    let opts = viz::SheetOptions {
        scale: args.scale,
        layout: args.layout,
        results: args.results.clone(),
        gt: args.gt.clone(),
    };
    let rows = viz::sheet_rows(&args.input, alg, &opts)?;
    if !global.quiet {
        note_inferred_resolution(&args.input, &rows);
    }
    // The sheet reads these files of every row: the output must be none of them.
    let read: Vec<&Path> = rows.iter().flat_map(viz::SheetRow::paths).collect();
    jem::io::check_outputs(&read, &[&args.output])?;
    let sheet = viz::contact_sheet(rows, alg, args.panel_width)?;
    sheet.canvas.write_png(&args.output)?;
    for (row, e) in &sheet.skipped {
        note!("warning: {} left out: {e}", row.location.display());
    }
    if !global.quiet {
        let names: Vec<&str> = sheet.rows.iter().map(|r| r.name.as_str()).collect();
        let (w, h) = (sheet.canvas.width, sheet.canvas.height);
        let rules: std::collections::BTreeSet<String> =
            sheet.rows.iter().filter(|r| r.truth.is_some()).map(|r| r.rule.describe()).collect();
        let rules = if rules.is_empty() {
            "none (no ground truth)".into()
        } else {
            rules.into_iter().collect::<Vec<_>>().join(", ")
        };
        note!(
            "wrote {} ({w}×{h}): {} rows ({}); error maps: {rules}",
            args.output.display(),
            names.len(),
            names.join(", ")
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// One line saying which resolution the scenes' names and image sizes told, when they did (no `--scale` and no
/// trainingQ/H/F-like folder).
pub(super) fn note_inferred_resolution(dir: &Path, rows: &[jem::viz::SheetRow]) {
    let inferred: Vec<&jem::eval::Resolution> =
        rows.iter().filter_map(|r| r.resolution.as_ref()).filter(|r| r.from_contents()).collect();
    let scales: std::collections::BTreeSet<u32> = inferred.iter().map(|r| r.scale).collect();
    let names: Vec<String> = scales.iter().map(|&s| jem::eval::resolution_name(s)).collect();
    if !inferred.is_empty() {
        let n = inferred.len();
        let of = if n == rows.len() { "its".to_string() } else { format!("{n} of its") };
        note!(
            "note: {}: {}, from the names and image sizes of {of} {} MiddEval3 scene(s) (--scale sets it)",
            dir.display(),
            names.join(" and "),
            rows.len()
        );
    }
}

/// `v` with three significant digits (at least its integer part): a range's ends as a reader reads them.
fn three_digits(v: f32) -> String {
    let decimals =
        if v == 0.0 || !v.is_finite() { 0 } else { (2 - v.abs().log10().floor() as i32).clamp(0, 6) as usize };
    format!("{v:.decimals$}")
}
