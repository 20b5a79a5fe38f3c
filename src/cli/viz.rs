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
    /// A disparity map (.pfm, .exr or 16-bit .png), or a folder of scenes (with --alg).
    #[arg(value_name = "DISP|DIR")]
    input: PathBuf,
    /// Output PNG.
    #[arg(long, short, value_name = "OUT.png")]
    output: PathBuf,
    /// Ground truth for the error map (.pfm); mask0nocc.png beside it marks occlusions.
    #[arg(long, value_name = "GT.pfm")]
    gt: Option<PathBuf>,
    /// Low end of the colour range (disparity px).
    #[arg(long, value_name = "A", allow_negative_numbers = true)]
    vmin: Option<f32>,
    /// High end of the colour range (disparity px).
    #[arg(long, value_name = "B", allow_negative_numbers = true)]
    vmax: Option<f32>,
    /// With a folder: draw disp0NAME.pfm of each scene.
    #[arg(long, value_name = "NAME")]
    alg: Option<String>,
    /// Factor to full-resolution px for the error threshold (default: from the path, trainingQ = 4; else 1).
    #[arg(long, value_name = "1|2|4")]
    scale: Option<u32>,
    /// Largest panel width of a contact sheet, in pixels.
    #[arg(long, value_name = "PX", default_value_t = 320)]
    panel_width: usize,
}

/// Draws one map, or a contact sheet of a folder.
pub(super) fn run(args: &VizArgs, global: &GlobalArgs) -> Result<ExitCode> {
    use jem::viz;
    let ext = args.output.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if ext.as_deref() != Some("png") {
        return Err(Error::Input(format!("{}: viz writes PNG (use a .png name)", args.output.display())));
    }
    if let Some(s) = args.scale
        && ![1, 2, 4].contains(&s)
    {
        return Err(Error::param("--scale", s, "1, 2 or 4"));
    }
    if args.input.is_dir() {
        let Some(alg) = &args.alg else {
            return Err(Error::Input(format!(
                "{} is a folder: give --alg NAME for a contact sheet",
                args.input.display()
            )));
        };
        jem::batch::validate_alg_name(alg)?;
        if args.panel_width < 16 {
            return Err(Error::param("--panel-width", args.panel_width, "at least 16"));
        }
        // The sheet reads these files of every scene: the output must be none of them.
        let result = format!("disp0{alg}.pfm");
        let names = ["im0.png", result.as_str(), "disp0GT.pfm", "mask0nocc.png", "calib.txt"];
        let scenes = jem::batch::find_dirs_with(std::slice::from_ref(&args.input), &["im0.png", &result])?;
        let read: Vec<PathBuf> = scenes.iter().flat_map(|s| names.iter().map(move |n| s.join(n))).collect();
        let read_refs: Vec<&Path> = read.iter().map(PathBuf::as_path).collect();
        jem::io::check_outputs(&read_refs, &[&args.output])?;
        let sheet = viz::contact_sheet(&args.input, alg, args.scale, args.panel_width)?;
        sheet.canvas.write_png(&args.output)?;
        for (dir, e) in &sheet.skipped {
            note!("warning: {} left out: {e}", dir.display());
        }
        if !global.quiet {
            let names: Vec<String> = sheet.rows.iter().map(|s| jem::batch::scene_name(s)).collect();
            let (w, h) = (sheet.canvas.width, sheet.canvas.height);
            note!("wrote {} ({w}×{h}): {} rows ({})", args.output.display(), names.len(), names.join(", "));
        }
        return Ok(ExitCode::SUCCESS);
    }
    for (flag, v) in [("--vmin", args.vmin), ("--vmax", args.vmax)] {
        if v.is_some_and(|v| !v.is_finite()) {
            return Err(Error::param(flag, v.unwrap(), "a finite number"));
        }
    }
    let dir = args.input.parent().unwrap_or(Path::new("."));
    let mut read = vec![args.input.clone(), dir.join("calib.txt")];
    if let Some(gt) = &args.gt {
        read.extend([gt.clone(), gt.parent().unwrap_or(Path::new(".")).join("mask0nocc.png")]);
    }
    let read_refs: Vec<&Path> = read.iter().map(PathBuf::as_path).collect();
    jem::io::check_outputs(&read_refs, &[&args.output])?;
    let disp = jem::io::read_disparity(&args.input)?;
    let calib = viz::calib_range(&args.input.parent().unwrap_or(Path::new(".")).join("calib.txt"));
    let data = viz::finite_range(&disp);
    let vmin = args.vmin.or(calib.map(|c| c.0)).or(data.map(|d| d.0)).unwrap_or(0.0);
    let vmax = args.vmax.or(calib.map(|c| c.1)).or(data.map(|d| d.1)).unwrap_or(1.0);
    if (args.vmin.is_some() || args.vmax.is_some()) && vmin >= vmax {
        return Err(Error::param("--vmin / --vmax", format!("{vmin} / {vmax}"), "a range with --vmin below --vmax"));
    }
    let colour = viz::colorize(&disp, vmin, vmax);
    let (picture, error) = match &args.gt {
        None => (colour, String::new()),
        Some(gt_path) => {
            let (gt, mask) = viz::load_gt_for(&disp, gt_path)?;
            let scale = args.scale.or_else(|| viz::resolved_scale(gt_path)).unwrap_or(1);
            let error = format!(" | error map against {} (red: error > 2 px ×{scale})", gt_path.display());
            (viz::hstack(&[colour, viz::error_map(&disp, &gt, mask.as_ref(), scale)], 4), error)
        }
    };
    picture.write_png(&args.output)?;
    if !global.quiet {
        let (w, h) = (picture.width, picture.height);
        note!("wrote {} ({w}×{h}): disparity coloured over {vmin}..{vmax}{error}", args.output.display());
    }
    Ok(ExitCode::SUCCESS)
}
