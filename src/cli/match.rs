//! `jem match` and the default command `jem LEFT RIGHT -o OUT`: load a pair (ndisp from `--ndisp` or the
//! `calib.txt` beside LEFT), check the memory estimate, run the pipeline with a stage spinner, write the disparity
//! map (and the confidence).

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::Args;
use jem::io::calib;
use jem::plan::{NdispSource, Plan, plan_match};
use jem::tile::Strategy;
use jem::{Error, Result};

use super::config::ConfigArgs;
use super::{GlobalArgs, MemoryArg, ThreadsArg};

/// Arguments of `jem match` and of the default command (the help text is on [`Cli`](super::Cli)).
#[derive(Args, Debug, Clone)]
pub(super) struct MatchArgs {
    /// Left (reference) image: PNG or PPM/PGM (8 or 16 bit), or JPEG.
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
    /// Also write the per-pixel confidence (max-marginal of the left view) to this file (.pfm/.exr).
    #[arg(long, value_name = "FILE")]
    confidence: Option<PathBuf>,
    /// Also write a point cloud: binary PLY, x y z (float, left camera frame, baseline units) and the left
    /// image's colour, valid pixels only. Needs cam0 and baseline (calib.txt beside LEFT, or the flags below).
    #[arg(long, value_name = "OUT.ply")]
    cloud: Option<PathBuf>,
    /// Also write metric depth Z = f·B / (d + doffs) (.pfm/.exr; inf where there is none).
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
    #[command(flatten)]
    config: ConfigArgs,
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
    #[command(flatten)]
    memory: MemoryArg,
}

/// Matches one pair.
pub(super) fn run(args: &MatchArgs, global: &GlobalArgs) -> Result<ExitCode> {
    let (Some(left), Some(right), Some(output)) = (&args.left, &args.right, &args.output) else {
        return Err(Error::Input("usage: jem LEFT RIGHT -o OUT (see --help)".into()));
    };
    // Check the output names before doing any work.
    jem::io::DisparityFormat::from_path(output)?;
    if let Some(c) = &args.confidence {
        jem::io::DisparityFormat::from_path(c)?;
    }
    let calib = left.parent().unwrap_or(Path::new(".")).join("calib.txt");
    if let Some(d) = &args.depth
        && jem::io::DisparityFormat::from_path(d)? == jem::io::DisparityFormat::Png16
    {
        return Err(Error::Input(format!("{}: depth is written as .pfm or .exr (floats)", d.display())));
    }
    if let Some(c) = &args.cloud
        && !c.extension().is_some_and(|e| e.eq_ignore_ascii_case("ply"))
    {
        return Err(Error::Input(format!("{}: a point cloud is written as .ply", c.display())));
    }
    // calib.txt, read once when something needs it (the range, or the camera).
    let wants_camera = args.cloud.is_some() || args.depth.is_some();
    let calib_file = if (args.ndisp.is_none() || wants_camera) && calib.is_file() {
        Some(calib::Calib::load(&calib)?)
    } else {
        None
    };
    // The camera is resolved before any work: a missing focal length or baseline is an error at once.
    let camera = if wants_camera {
        let overrides = jem::geometry::CameraOverrides {
            focal: args.focal,
            cx: args.cx,
            cy: args.cy,
            baseline: args.baseline,
            doffs: args.doffs,
        };
        Some(jem::geometry::Camera::resolve(calib_file.as_ref(), &overrides)?)
    } else {
        None
    };
    let outputs: Vec<&Path> = std::iter::once(output.as_path())
        .chain(args.confidence.as_deref())
        .chain(args.cloud.as_deref())
        .chain(args.depth.as_deref())
        .collect();
    jem::io::check_outputs(&[left, right, &calib], &outputs)?;
    let params = args.config.params()?;
    let start = Instant::now();
    // The size from the image header: a pair too large for the memory limit is refused before decoding.
    // The range: --ndisp, else calib.txt's ndisp unless it is missing or not a real bound (≥ half the width),
    // in which case it is measured on the pair (jem::range).
    let stated = match (args.ndisp, &calib_file) {
        (Some(n), _) => Some(n),
        (None, Some(c)) => Some(c.ndisp().map_err(|msg| Error::Calib { path: calib.clone(), msg })?),
        (None, None) => None,
    };
    let source = match (args.ndisp, stated) {
        (Some(n), _) => NdispSource::Given(n),
        (None, Some(n)) => NdispSource::Stated(n),
        (None, None) => NdispSource::Unknown,
    };
    // Both headers, then the limit, before either image is decoded (issue 41: the loading and the range
    // measurement are checked too, and the right image's size before it is decoded).
    let header = jem::io::png::read_pair_header(left, right)?;
    for warning in params.image_warnings(header.width, header.height).iter().filter(|_| !global.quiet) {
        note!("warning: {warning}");
    }
    jem::plan::check_before_decode(&header, source, &params, args.memory.memory_limit())?;
    let (l, r) = jem::io::png::load_rgb_pair_within(left, right, args.memory.memory_limit())?;
    // The range and the way to run: shared with the Python module (jem::plan), so both give the same map.
    let Plan { pair, strategy, ndisp_measured } = plan_match(l, r, source, &params, args.memory.memory_limit())?;
    if ndisp_measured && !global.quiet {
        let was = stated.map_or("no range given".to_string(), |s| format!("calib.txt says {s}"));
        note!("ndisp {}, measured on the pair ({was}; --ndisp N sets it)", pair.ndisp);
    }
    if let (Strategy::Tiled(plan), false) = (strategy, global.quiet) {
        note!(
            "running in tiles of {} px after a coarse level at 1/{} (bounded memory)",
            plan.core_px,
            plan.coarse_factor
        );
    }
    let load_time = start.elapsed();

    let spinner = stage_spinner(global.quiet);
    let out = strategy.run(&params, &pair, &|stage| {
        if let Some(s) = &spinner {
            s.set_message(stage.to_string());
        }
    })?;
    if let Some(s) = spinner {
        s.finish_and_clear();
    }
    // Both outputs or neither: encode both, then write them as one.
    let mut files = vec![(output.as_path(), jem::io::encode_disparity(output, &out.disparity)?)];
    if let Some(c) = &args.confidence {
        files.push((c.as_path(), jem::io::encode_disparity(c, &out.confidence)?));
    }
    if let Some(camera) = &camera {
        if let Some(d) = &args.depth {
            let depth = jem::geometry::depth_map(&out.disparity, camera);
            files.push((d.as_path(), jem::io::encode_disparity(d, &depth)?));
        }
        if let Some(c) = &args.cloud {
            files.push((c.as_path(), jem::geometry::encode_ply(&out.disparity, &pair.left, camera)));
        }
    }
    let refs: Vec<(&Path, &[u8])> = files.iter().map(|(p, b)| (*p, b.as_slice())).collect();
    jem::io::write_all_or_none(&refs)?;
    if global.verbose && !global.quiet {
        note!("{:<14} {:>9.1} ms", "load", load_time.as_secs_f64() * 1e3);
        for (name, d) in &out.timings.stages {
            note!("{name:<14} {:>9.1} ms", d.as_secs_f64() * 1e3);
        }
        note!("{:<14} {:>9.1} ms", "total", start.elapsed().as_secs_f64() * 1e3);
        if let Some(m) = &out.measured {
            note!("{}", describe_measured(m));
        }
        let (w, h) = pair.left.dims();
        let planned = strategy.memory_bytes(w, h, pair.ndisp, &params);
        if let Some(peak) = peak_rss_bytes() {
            note!("memory: peak {} (planned {})", human(peak), human(planned));
        }
    }
    if !global.quiet {
        let seconds = start.elapsed().as_secs_f64();
        note!("{}", wrote_line(args, &out.disparity, pair.ndisp, ndisp_measured, seconds, camera.as_ref()));
    }
    Ok(ExitCode::SUCCESS)
}

/// The last line of a match: `wrote d.pfm (741×497, 96 % valid, ndisp 70, 2.8 s)`, then the other files written.
fn wrote_line(
    args: &MatchArgs,
    disparity: &jem::DisparityMap,
    ndisp: usize,
    measured: bool,
    seconds: f64,
    camera: Option<&jem::geometry::Camera>,
) -> String {
    let (w, h) = disparity.dims();
    let valid = disparity.data.iter().filter(|d| d.is_finite()).count();
    let percent = 100.0 * valid as f64 / disparity.data.len().max(1) as f64;
    let measured = if measured { " measured" } else { "" };
    let output = args.output.as_deref().unwrap_or(Path::new("?")).display();
    let mut line = format!("wrote {output} ({w}×{h}, {percent:.0} % valid, ndisp {ndisp}{measured}, {seconds:.1} s)");
    if let Some(c) = &args.confidence {
        line.push_str(&format!(", confidence {}", c.display()));
    }
    if let Some(d) = &args.depth {
        line.push_str(&format!(", depth {}", d.display()));
    }
    if let (Some(c), Some(camera)) = (&args.cloud, camera) {
        let points = disparity.data.iter().enumerate().filter(|&(i, &d)| camera.point(i % w, i / w, d).is_some());
        line.push_str(&format!(", point cloud {} ({} points)", c.display(), points.count()));
    }
    line
}

/// One line: what the adaptive front end measured on the pair and set from it.
pub(super) fn describe_measured(m: &jem::Measured) -> String {
    let [nl, nr] = m.stats.noise;
    let [gl, gr] = m.stats.gain;
    let gradient = m.gradient.map_or("raw".to_string(), |(mean, eps)| format!("local contrast {mean:.1}, ε {eps:.1}"));
    let [bl, br] = m.stats.cost_blur;
    let blur = if bl > 0.0 || br > 0.0 {
        format!("; cost blur σ {bl:.2} / {br:.2} px (sharpness matched)")
    } else {
        String::new()
    };
    let jpeg = if m.stats.is_jpeg() {
        let ([jl, jr], [bl, br]) = (m.stats.jpeg, m.stats.blocking);
        format!("; JPEG: compression error σ {jl:.2} / {jr:.2}, block steps {bl:.2} / {br:.2}")
    } else {
        String::new()
    };
    let vertical = m.vertical.map_or(String::new(), |v| {
        let (lo, hi) = v.range;
        let done = if v.corrected { "removed" } else { "left" };
        format!("; right view's vertical offset {lo:+.2} to {hi:+.2} px ({done})")
    });
    format!(
        "measured: noise σ {nl:.2} / {nr:.2}, contrast gain {gl:.2} / {gr:.2} (left / right); prior λ {:.2} \
         (at least {:.2} × the cost's flatness), Census support {:.1}, gradient {gradient}{blur}{jpeg}{vertical}",
        m.prior_weight, m.prior_flat, m.census_support
    )
}

/// Bytes as MiB with one decimal.
fn human(bytes: u64) -> String {
    format!("{:.1} MiB", bytes as f64 / f64::from(1u32 << 20))
}

/// This process's peak resident set size (`VmHWM` of /proc/self/status; `None` where there is none).
fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
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
