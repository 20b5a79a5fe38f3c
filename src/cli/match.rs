//! `jem match` and the default command `jem LEFT RIGHT -o OUT`: load a pair (ndisp from `--ndisp` or the
//! `calib.txt` beside LEFT), check the memory estimate, run the pipeline with a stage spinner, write the disparity
//! map (and the confidence).

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::Args;
use jem::io::calib;
use jem::{Error, Matcher, NdispSource, Progress, Result};

use super::config::ConfigArgs;
use super::{GlobalArgs, MemoryArg, ThreadsArg};

/// Arguments of `jem match` and of the default command (the help text is on [`Cli`](super::Cli)).
#[derive(Args, Debug, Clone)]
pub(super) struct MatchArgs {
    /// Left (reference) image: PNG, PPM/PGM, JPEG, BMP, TIFF or WebP (8 or 16 bit).
    #[arg(required = true)]
    left: Option<PathBuf>,
    /// Right image, same size as the left.
    #[arg(required = true)]
    right: Option<PathBuf>,
    /// Output disparity map: .pfm (Middlebury), .exr (float) or .png (16-bit, disparity × 256, 0 = invalid).
    #[arg(long, short, required = true, value_name = "OUT")]
    output: Option<PathBuf>,
    /// Disparity search range 0..N−1 (default: `ndisp` from calib.txt beside LEFT).
    #[arg(long, value_name = "N")]
    ndisp: Option<usize>,
    /// Search the disparities D..D+N−1 instead of 0..N−1 (OpenCV SGBM's minDisparity), for a scene that is nowhere
    /// near infinity; the left view's first D columns, which match nothing there, are written invalid. `calib`:
    /// D is vmin of calib.txt beside LEFT rounded down, and N its ndisp − D (the top of its range kept); vmin is
    /// read only when asked (MiddEval3 states it for display and bars algorithms from using it).
    #[arg(long, value_name = "D|calib")]
    min_disp: Option<MinDisp>,
    /// Rectify the raw pair first with this stereo calibration, as `jem rectify` does (OpenCV FileStorage YAML/XML
    /// or KITTI calib_cam_to_cam.txt): the outputs are then of the rectified left view, the camera for --depth and
    /// --cloud is the rectified one, and calib.txt beside LEFT is not read.
    #[arg(long, value_name = "CALIB")]
    rectify: Option<PathBuf>,
    /// Also write the per-pixel confidence to this file (.pfm/.exr): 0..1, the probability that the disparity is
    /// within 1 px, made to rank the errors (0 where the map is invalid).
    #[arg(long, value_name = "FILE")]
    confidence: Option<PathBuf>,
    /// Also write where the left-right check rejected the left view's pixel, before fill, weighted median and
    /// planes changed its value: an 8-bit grey PNG, 255 = rejected, 0 = passed (all 0 with `post.lrc.mode =
    /// "off"`). `jem eval --regions` reads it as lrmask0NAME.png beside disp0NAME.pfm. The disparity map is the
    /// same with or without it.
    #[arg(long, value_name = "FILE.png")]
    lr_mask: Option<PathBuf>,
    /// Also write a point cloud: binary PLY, x y z (float, left camera frame, baseline units) and the left
    /// image's colour, valid pixels only. Needs cam0 and baseline (calib.txt beside LEFT, or the flags below).
    #[arg(long, value_name = "OUT.ply")]
    cloud: Option<PathBuf>,
    /// Also write metric depth Z = f·B / (d + doffs): .pfm/.exr as floats (inf where there is none), .png as 16 bits
    /// in the baseline's unit rounded, 0 where there is none (RealSense/ZED: millimetres for a baseline in mm); a
    /// depth above 65535 is refused there (--max-depth 65535 leaves such points out).
    #[arg(long, value_name = "FILE")]
    depth: Option<PathBuf>,
    /// Focal length in pixels (default: cam0 of calib.txt).
    #[arg(long, value_name = "PX")]
    focal: Option<f64>,
    /// Principal point x in pixels (default: cam0).
    #[arg(long, value_name = "PX")]
    cx: Option<f64>,
    /// Principal point y in pixels (default: cam0).
    #[arg(long, value_name = "PX")]
    cy: Option<f64>,
    /// Baseline; depth and points come out in its unit (default: `baseline` of calib.txt).
    #[arg(long, value_name = "B")]
    baseline: Option<f64>,
    /// Principal point offset between the views, pixels (default: `doffs` of calib.txt, else 0).
    #[arg(long, value_name = "PX")]
    doffs: Option<f64>,
    /// Leave out of --depth and --cloud every point farther than Z, in the baseline's unit (default: f·B, the
    /// depth of a one-pixel disparity: beyond it half a pixel of error more than doubles the depth).
    #[arg(long, value_name = "Z", allow_negative_numbers = true)]
    max_depth: Option<f64>,
    /// Write invalid (inf; 0 in a 16-bit PNG) where the confidence is below C (0..1): only the reliable pixels in
    /// the disparity map, the depth map and the cloud.
    #[arg(long, value_name = "C", allow_negative_numbers = true)]
    min_confidence: Option<f32>,
    /// Write nothing and fail (exit 2) when the pair looks wrong (views swapped, rows far apart, no texture, ...:
    /// the warnings jem otherwise prints beside a written result).
    #[arg(long)]
    strict: bool,
    #[command(flatten)]
    config: ConfigArgs,
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
    #[command(flatten)]
    memory: MemoryArg,
}

/// `--min-disp`: a number of pixels, or `calib` (from calib.txt's vmin).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum MinDisp {
    /// This many pixels.
    Px(usize),
    /// vmin of calib.txt beside LEFT ([`jem::io::calib::Calib::vmin_search`]).
    Calib,
}

impl std::str::FromStr for MinDisp {
    type Err = Error;
    fn from_str(s: &str) -> std::result::Result<Self, Error> {
        match s {
            "calib" => Ok(MinDisp::Calib),
            _ => s
                .parse()
                .map(MinDisp::Px)
                .map_err(|_| Error::argument(format!("{s:?} is neither a disparity of 0 or more nor calib"))),
        }
    }
}

/// Matches one pair.
pub(super) fn run(args: &MatchArgs, global: &GlobalArgs) -> Result<ExitCode> {
    let mut request = Request::check(args)?;
    let params = args.config.params()?;
    let start = Instant::now();
    let mut matcher = Matcher::new(params.clone())?
        .with_ndisp(NdispSource::resolve(args.ndisp, request.stated_ndisp))
        .with_min_disp(request.min_disp)
        .with_max_memory(args.memory.memory_limit())
        // Always: the pair checks read it (a region of repetitive texture matched doubtfully).
        .with_confidence(true)
        .with_checks(true);
    // With --rectify, the matcher rectifies the raw views.
    matcher.set_rectification(request.rectification.take());
    if let Some(c) = args.min_confidence {
        // With --min-confidence, the map written holds the reliable pixels only.
        matcher = matcher.with_min_confidence(c)?;
    }
    let header = jem::io::read_pair_header(request.left, request.right)?;
    for warning in params.image_warnings(header.width, header.height).iter().filter(|_| !global.quiet) {
        note!("warning: {warning}");
    }
    // Both headers are checked against the memory limit before either image is decoded.
    let (l, r) = matcher.read_pair(request.left, request.right)?;
    let load_time = start.elapsed();
    let out = match_with_progress(&mut matcher, (&l, &r), request.stated_ndisp, global.quiet)?;
    let mut warnings = out.warnings();
    if let (Some(rect), Some(calib)) = (matcher.rectification(), &args.rectify) {
        warnings.extend(rect.warnings().into_iter().map(|w| format!("{}: {w}", calib.display())));
    }
    if args.strict && !warnings.is_empty() {
        return Err(Error::bad_image(format!(
            "the pair looks wrong (--strict: nothing written): {}",
            warnings.join("; ")
        )));
    }
    // The view the map is of: the rectified left view with --rectify.
    let left_view = out.rectified.as_ref().map_or(&l, |r| &r.left);
    write_outputs(args, &request, &out, left_view)?;
    for warning in warnings.iter().filter(|_| !global.quiet) {
        note!("warning: {warning}");
    }
    if let Some(jpeg) = out.measured.as_ref().and_then(jem::Measured::jpeg_note).filter(|_| !global.quiet) {
        note!("note: {jpeg}");
    }
    if global.verbose && !global.quiet {
        note!("{:<14} {:>9.1} ms", "load", load_time.as_secs_f64() * 1e3);
        for (name, d) in &out.timings.stages {
            note!("{name:<14} {:>9.1} ms", d.as_secs_f64() * 1e3);
        }
        note!("{:<14} {:>9.1} ms", "total", start.elapsed().as_secs_f64() * 1e3);
        if let Some(m) = &out.measured {
            note!("{m}");
        }
        if let Some(check) = &out.checks {
            note!("{check}");
        }
        if let Some(peak) = jem::peak_rss_bytes() {
            note!("memory: peak {} (planned {})", human(peak), human(out.plan.memory_bytes));
        }
    }
    if !global.quiet {
        let seconds = start.elapsed().as_secs_f64();
        note!("{}", wrote_line(args, &out, seconds, request.camera.as_ref()));
    }
    Ok(ExitCode::SUCCESS)
}

/// What a match is asked for, checked before any work: the input and output names, the range calib.txt states and
/// the camera (a missing focal length or baseline is an error at once).
struct Request<'a> {
    left: &'a Path,
    right: &'a Path,
    /// The range `calib.txt` beside LEFT states, when no `--ndisp` is given.
    stated_ndisp: Option<usize>,
    /// The smallest disparity searched (`--min-disp`).
    min_disp: usize,
    /// For `--depth` and `--cloud`.
    camera: Option<jem::geometry::Camera>,
    /// With `--rectify`: how the pair is rectified before matching (handed to the matcher).
    rectification: Option<jem::rectify::Rectification>,
}

impl<'a> Request<'a> {
    fn check(args: &'a MatchArgs) -> Result<Request<'a>> {
        let (Some(left), Some(right), Some(output)) = (&args.left, &args.right, &args.output) else {
            return Err(Error::argument("usage: jem LEFT RIGHT -o OUT (see --help)"));
        };
        jem::io::DisparityFormat::from_path(output)?;
        if let Some(c) = args.min_confidence {
            jem::Output::check_min_confidence("--min-confidence", c)?;
        }
        if args.max_depth.is_some() && args.depth.is_none() && args.cloud.is_none() {
            return Err(Error::argument("--max-depth limits --depth and --cloud; give one of them"));
        }
        if let Some(c) = &args.confidence {
            jem::io::DisparityFormat::from_path(c)?;
        }
        if let Some(m) = args.lr_mask.as_ref().filter(|m| !m.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
        {
            return Err(Error::output_at(m, "the left-right mask is written as .png"));
        }
        let calib = left.parent().unwrap_or(Path::new(".")).join(jem::dataset::CALIB_FILE);
        if let Some(d) = &args.depth {
            jem::io::DisparityFormat::from_path(d)?;
        }
        if let Some(c) = &args.cloud
            && !c.extension().is_some_and(|e| e.eq_ignore_ascii_case("ply"))
        {
            return Err(Error::output_at(c, "a point cloud is written as .ply"));
        }
        // calib.txt, read once when something needs it (the range, or the camera); with --rectify, the rectified
        // pair's (it states no range).
        let wants_camera = args.cloud.is_some() || args.depth.is_some();
        let from_vmin = args.min_disp == Some(MinDisp::Calib);
        if from_vmin && args.rectify.is_some() {
            return Err(Error::argument(
                "--min-disp calib reads calib.txt beside LEFT, which --rectify replaces; give --min-disp D",
            ));
        }
        if from_vmin && !calib.is_file() {
            return Err(Error::argument(format!("--min-disp calib: there is no {}", calib.display())));
        }
        let rectification = match &args.rectify {
            Some(c) => Some(super::rectify::plan(c, (left, right), None, args.memory.memory_limit())?),
            None => None,
        };
        let calib_file = match &rectification {
            Some(rect) => Some(calib::Calib::parse(&rect.calib_txt()).map_err(|e| match e {
                Error::Calib { msg, .. } => Error::Calib { path: args.rectify.clone().unwrap_or_default(), msg },
                e => e,
            })?),
            None if (args.ndisp.is_none() || wants_camera || from_vmin) && calib.is_file() => {
                Some(calib::Calib::load(&calib)?)
            }
            None => None,
        };
        let camera = if wants_camera {
            let overrides = jem::geometry::CameraOverrides {
                focal: args.focal,
                cx: args.cx,
                cy: args.cy,
                baseline: args.baseline,
                doffs: args.doffs,
                max_depth: args.max_depth,
            };
            let source = args.rectify.as_deref().unwrap_or(&calib);
            Some(jem::geometry::Camera::resolve(calib_file.as_ref(), source, &overrides, args.cloud.is_some())?)
        } else {
            None
        };
        let outputs: Vec<&Path> = std::iter::once(output.as_path())
            .chain(args.confidence.as_deref())
            .chain(args.lr_mask.as_deref())
            .chain(args.cloud.as_deref())
            .chain(args.depth.as_deref())
            .collect();
        let rectify_calib = args.rectify.as_deref().unwrap_or(&calib);
        jem::io::check_outputs(&[left, right, &calib, rectify_calib], &outputs)?;
        jem::io::check_output_folders(&outputs)?;
        // The range: --ndisp, else calib.txt's (measured instead when it is missing, the file states none, as
        // `jem rectify` writes it, or it is no real bound: half the width or more).
        let stated_ndisp = match &calib_file {
            Some(c) if args.ndisp.is_none() && rectification.is_none() => c.stated_ndisp()?,
            _ => None,
        };
        // --min-disp calib: the smallest disparity from vmin, the range's top kept at calib.txt's ndisp − 1.
        let (min_disp, stated_ndisp) = match (args.min_disp, &calib_file) {
            (Some(MinDisp::Px(d)), _) => (d, stated_ndisp),
            (Some(MinDisp::Calib), Some(c)) => {
                let (d, n) = c.vmin_search()?;
                (d, n.filter(|_| args.ndisp.is_none()))
            }
            _ => (0, stated_ndisp),
        };
        Ok(Request { left, right, stated_ndisp, min_disp, camera, rectification })
    }
}

/// Matches the pair with a stage spinner on a terminal, and says (unless `quiet`) when the range was measured or
/// the pair runs in tiles.
fn match_with_progress(
    matcher: &mut Matcher,
    (left, right): (&jem::RgbImage, &jem::RgbImage),
    stated: Option<usize>,
    quiet: bool,
) -> Result<jem::Output> {
    let spinner = stage_spinner(quiet);
    let out = matcher.match_pair_with(left, right, &|progress| match progress {
        Progress::Planned(plan) if !quiet => {
            if plan.ndisp_measured {
                let was = stated.map_or("no range given".to_string(), |s| format!("calib.txt says {s}"));
                let from = if plan.min_disp > 0 { format!(" from {}", plan.min_disp) } else { String::new() };
                note!("ndisp {}{from}, measured on the pair ({was}; --ndisp N sets it)", plan.ndisp);
            }
            if plan.working_factor > 1 {
                let f = plan.working_factor;
                note!("working at 1/{f}: the views' finest octaves hold no detail of their own (upsampled or out of focus); [working] auto = false matches at full size");
            }
            if let Some(tiles) = plan.tiles {
                note!(
                    "running in tiles of {} px after a coarse level at 1/{} (bounded memory)",
                    tiles.core_px,
                    tiles.coarse_factor
                );
            }
        }
        Progress::Stage(stage) => {
            if let Some(s) = &spinner {
                s.set_message(stage.to_string());
            }
        }
        Progress::Planned(_) => {}
    });
    if let Some(s) = spinner {
        s.finish_and_clear();
    }
    out
}

/// Writes the disparity map and what else was asked for, all or none: every file is encoded first, then they are
/// written as one.
fn write_outputs(args: &MatchArgs, request: &Request<'_>, out: &jem::Output, left: &jem::RgbImage) -> Result<()> {
    let disparity = &out.disparity;
    let output = args.output.as_deref().unwrap_or(Path::new("?"));
    let mut files = vec![(output, jem::io::encode_disparity(output, disparity)?)];
    if let Some(c) = &args.confidence {
        let map = out.confidence_map()?;
        files.push((c.as_path(), jem::io::encode_disparity(c, map)?));
    }
    if let Some(m) = &args.lr_mask {
        files.push((m.as_path(), jem::io::encode_lr_mask(m, &out.consistent)?));
    }
    if let Some(camera) = &request.camera {
        if let Some(d) = &args.depth {
            let depth = jem::geometry::depth_map(disparity, camera);
            files.push((d.as_path(), jem::io::encode_depth(d, &depth)?));
        }
        if let Some(c) = &args.cloud {
            files.push((c.as_path(), jem::geometry::encode_ply(disparity, left, camera)));
        }
    }
    let refs: Vec<(&Path, &[u8])> = files.iter().map(|(p, b)| (*p, b.as_slice())).collect();
    jem::io::write_all_or_none(&refs)
}

/// The last line of a match: `wrote d.pfm (741×497, 96 % valid, ndisp 70, 2.8 s)`, then the other files written.
fn wrote_line(args: &MatchArgs, out: &jem::Output, seconds: f64, camera: Option<&jem::geometry::Camera>) -> String {
    let disparity = &out.disparity;
    let (ndisp, measured) = (out.plan.ndisp, out.plan.ndisp_measured);
    let from = if out.plan.min_disp > 0 { format!(" from {}", out.plan.min_disp) } else { String::new() };
    let (w, h) = disparity.dims();
    let valid = disparity.data().iter().filter(|d| d.is_finite()).count();
    let percent = 100.0 * valid as f64 / disparity.data().len().max(1) as f64;
    let measured = if measured { " measured" } else { "" };
    let output = args.output.as_deref().unwrap_or(Path::new("?")).display();
    let mut line =
        format!("wrote {output} ({w}×{h}, {percent:.0} % valid, ndisp {ndisp}{from}{measured}, {seconds:.1} s)");
    if let Some(c) = &args.confidence {
        line.push_str(&format!(", confidence {}", c.display()));
    }
    if let Some(m) = &args.lr_mask {
        let rejected = out.consistent.data().iter().filter(|ok| !**ok).count();
        let percent = 100.0 * rejected as f64 / out.consistent.data().len().max(1) as f64;
        line.push_str(&format!(", left-right mask {} ({percent:.0} % rejected)", m.display()));
    }
    if let (Some(d), Some(camera)) = (&args.depth, camera) {
        line.push_str(&format!(", depth {} (up to {})", d.display(), camera.max_depth as f32));
    }
    if let (Some(c), Some(camera)) = (&args.cloud, camera) {
        let points = disparity.data().iter().enumerate().filter(|&(i, &d)| camera.point(i % w, i / w, d).is_some());
        line.push_str(&format!(", point cloud {} ({} points)", c.display(), points.count()));
    }
    line
}

/// Bytes as MiB with one decimal.
fn human(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / f64::from(1u32 << 20))
}

/// A spinner on stderr showing the current stage, only on a terminal and without --quiet.
fn stage_spinner(quiet: bool) -> Option<indicatif::ProgressBar> {
    if quiet || !std::io::stderr().is_terminal() {
        return None;
    }
    let bar = indicatif::ProgressBar::new_spinner();
    bar.enable_steady_tick(std::time::Duration::from_millis(100));
    Some(bar)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With --rectify given, a warning that the pair is not rectified does not tell to rectify it; other warnings
    /// are as they were.
    #[test]
    fn a_pair_rectified_with_a_calibration_is_not_told_to_rectify_it() {
        let calib = Path::new("stereo.yml");
        let vertical = "the right view is 6.0 px lower: the pair is not rectified (rectify it with --rectify CALIB)";
        let said = jem::PairCheck::after_rectify(vertical.to_string(), calib);
        let advice = "after --rectify stereo.yml: is it this rig's calibration, and LEFT the left camera's view?";
        assert_eq!(said, format!("the right view is 6.0 px lower: the pair is not rectified {advice}"));
        let rotated =
            jem::PairCheck::after_rectify("rotated by about 1.0° (the pair is not rectified)".to_string(), calib);
        assert_eq!(rotated, format!("rotated by about 1.0° (the pair is not rectified {advice})"));
        let other = "the views look swapped: 90 % of the reliable matches are at negative disparity".to_string();
        assert_eq!(jem::PairCheck::after_rectify(other.clone(), calib), other);
    }
}
