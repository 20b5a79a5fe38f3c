//! `jem sequence DIR -o OUTDIR`: matches every frame of a stereo sequence ([`jem::sequence::run`]), showing a line
//! per frame, and says what it wrote.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use jem::sequence::{Event, RangeRule, RunOptions, Sequence};
use jem::{Error, Result};

use super::config::ConfigArgs;
use super::{GlobalArgs, MemoryArg, ThreadsArg};

/// Arguments of `jem sequence` (the help text is on [`Command::Sequence`](super::Command::Sequence)).
#[derive(Args, Debug, Clone)]
pub(super) struct SequenceArgs {
    /// The sequence folder: left/ and right/ holding the frames (PNG, PPM/PGM, JPEG, BMP, TIFF, WebP), paired by
    /// file name, with an optional calib.txt; or a KITTI raw drive folder (image_02/data, image_03/data).
    #[arg(value_name = "DIR")]
    dir: PathBuf,
    /// Output folder (created if missing): OUTDIR/<frame stem>.EXT per frame, times.txt, sequence.txt, config.toml.
    #[arg(long, short, value_name = "OUTDIR")]
    output: PathBuf,
    /// Match each frame alone, as `jem LEFT RIGHT -o OUT` matches that pair (byte-identical maps), instead of with
    /// the temporal model (a still camera's frames averaged, a moving camera's previous answer as the prior, scene
    /// cuts detected).
    #[arg(long)]
    independent: bool,
    /// Format of the per-frame maps: pfm (Middlebury), exr (float) or png (16-bit, disparity × 256, 0 = invalid).
    #[arg(long, value_name = "pfm|exr|png", default_value = "pfm")]
    ext: String,
    /// Disparity search range 0..N−1 for every frame (default: ndisp of DIR/calib.txt, else measured on each
    /// frame as `jem match` measures it).
    #[arg(long, value_name = "N")]
    ndisp: Option<usize>,
    /// Search the disparities D…D+N−1 in every frame instead of 0…N−1 (as `jem match --min-disp`; N from
    /// --ndisp, calib.txt or measured from D up). The left views' first D columns come out invalid.
    #[arg(long, value_name = "D", default_value_t = 0)]
    min_disp: usize,
    /// Settle the range once, on the first frame, and hold it for the whole sequence (instead of per frame).
    #[arg(long)]
    range_once: bool,
    /// Rectify every frame first with this stereo calibration, as `jem match --rectify` does (OpenCV FileStorage
    /// YAML/XML or KITTI calib_cam_to_cam.txt); the maps are then of the rectified left views.
    #[arg(long, value_name = "CALIB")]
    rectify: Option<PathBuf>,
    #[command(flatten)]
    config: ConfigArgs,
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
    #[command(flatten)]
    memory: MemoryArg,
}

/// Matches the sequence and prints the closing line.
pub(super) fn run(args: &SequenceArgs, global: &GlobalArgs) -> Result<ExitCode> {
    if args.ndisp == Some(0) {
        return Err(Error::param("--ndisp", 0, "at least 1"));
    }
    let format = jem::io::DisparityFormat::from_path(&PathBuf::from(format!("frame.{}", args.ext)))
        .map_err(|_| Error::param("--ext", &args.ext, "pfm, exr or png"))?;
    let params = args.config.params()?;
    let seq = Sequence::open(&args.dir)?;
    let total = seq.frames.len();
    // Planned on the first frame's headers (every frame of a sequence has its size), before any image is decoded.
    let rectification = match (&args.rectify, seq.frames.first()) {
        (Some(c), Some(f)) => Some(super::rectify::plan(c, (&f.left, &f.right), None, args.memory.memory_limit())?),
        _ => None,
    };
    if let (Some(rect), Some(calib)) = (&rectification, &args.rectify) {
        super::rectify::warn(rect, calib, global.quiet);
    }
    let mut matcher = jem::Matcher::new(params)?
        .with_ndisp(args.ndisp.map_or(jem::NdispSource::Unknown, jem::NdispSource::Given))
        .with_max_memory(args.memory.memory_limit())
        .with_temporal(!args.independent)
        .with_min_disp(args.min_disp);
    if let Some(rect) = rectification {
        matcher = matcher.with_rectification(rect);
    }
    let range = if args.range_once || !args.independent { RangeRule::FirstFrame } else { RangeRule::PerFrame };
    let opts = RunOptions { format, range };
    let quiet = global.quiet;
    // Said once the output folder is taken, with the first frame, so that a refusal is the only line.
    let started = std::cell::Cell::new(false);
    let header = || {
        if !quiet && !started.replace(true) {
            note!(
                "{total} frames in {} ({}), writing to {}",
                args.dir.display(),
                seq.layout.name(),
                args.output.display()
            );
        }
    };
    // Skipped frames are reported as one line per run of them, when the next frame starts or at the end.
    let skipped: std::cell::RefCell<Vec<String>> = Default::default();
    let flush_skipped = || {
        let mut s = skipped.borrow_mut();
        if !quiet && !s.is_empty() {
            let span = if s.len() == 1 { s[0].clone() } else { format!("{} … {}", s[0], s[s.len() - 1]) };
            note!("skipped {} frame(s) already written ({span})", s.len());
        }
        s.clear();
    };
    let replayed = std::cell::Cell::new(0usize);
    let on_event = |event: Event<'_>| match event {
        Event::Note(line) => {
            if !quiet {
                note!("{line}");
            }
        }
        Event::Replayed { index, .. } => {
            header();
            if !quiet && replayed.replace(replayed.get() + 1) == 0 {
                note!(
                    "rebuilding the temporal model's state: the frames written already are matched again (not rewritten)"
                );
            }
            let _ = index;
        }
        Event::Skipped { stem, .. } => {
            header();
            skipped.borrow_mut().push(stem.to_string());
        }
        Event::Started { .. } => {
            header();
            flush_skipped();
        }
        Event::Stage { .. } => {}
        Event::Finished { index, run } if !quiet => {
            let measured = if run.ndisp_measured { " measured" } else { "" };
            let kind = run.kind.map_or(String::new(), |k| format!(", {}", describe_kind(k)));
            let exposure = run.exposure.map_or(String::new(), |e| format!(", {}", describe_exposure(e)));
            let (stem, ndisp, seconds) = (&run.stem, run.ndisp, run.seconds);
            note!("[{}/{total}] {stem}: ndisp {ndisp}{measured}{kind}{exposure}, {seconds:.2} s", index + 1);
            if global.verbose {
                let stages: Vec<String> = run.stages.iter().map(|(n, s)| format!("{n} {:.0}", s * 1e3)).collect();
                note!("  stages (ms): {}", stages.join(", "));
            }
        }
        Event::Finished { .. } => {}
    };
    let summary = jem::sequence::run(&seq, &args.output, matcher, &opts, &on_event)?;
    flush_skipped();
    if !quiet {
        note!("{}", closing_line(&seq, args, &summary));
    }
    Ok(ExitCode::SUCCESS)
}

/// How the temporal model matched a frame, in words.
fn describe_kind(kind: jem::FrameKind) -> String {
    match kind {
        jem::FrameKind::First => "first frame".into(),
        jem::FrameKind::Cut => "scene cut: matched as a first frame".into(),
        jem::FrameKind::Still { frames } => format!("still camera, the mean of up to {frames} frames"),
        jem::FrameKind::Moving { dx, dy } => format!("camera moved ({dx:+}, {dy:+}) px, the previous answer as prior"),
        jem::FrameKind::Travelling { tracks } => {
            format!("camera moved in depth or turned ({tracks} tracked points), the previous answer carried as prior")
        }
    }
}

/// The exposure change the temporal model compensated, in words: `exposure ×1.100 −3.0 compensated`.
fn describe_exposure(e: jem::Exposure) -> String {
    let offset = if e.offset.abs() >= 0.05 { format!(" {:+.1}", e.offset).replace('-', "−") } else { String::new() };
    format!("exposure ×{:.3}{offset} compensated", e.gain)
}

/// `wrote 10 frames to OUT (7 run, 3 already there; 320×240, ndisp 48 from calib.txt, 2.13 s per frame run)`.
fn closing_line(seq: &Sequence, args: &SequenceArgs, summary: &jem::sequence::RunSummary) -> String {
    let (ran, skipped, replayed) = (summary.ran.len(), summary.skipped.len(), summary.replayed.len());
    if ran == 0 {
        return format!("nothing to do: all {skipped} frames are in {} already", args.output.display());
    }
    let counts = match (skipped, replayed) {
        (0, 0) => String::new(),
        (_, 0) => format!("{ran} run, {skipped} already there; "),
        _ => format!(
            "{ran} run, {} already there ({replayed} matched again for the temporal state); ",
            skipped + replayed
        ),
    };
    let size = summary.ran.first().map_or(String::new(), |r| format!("{}×{}, ", r.size.0, r.size.1));
    let (lo, hi) = summary.ran.iter().fold((usize::MAX, 0), |(lo, hi), r| (lo.min(r.ndisp), hi.max(r.ndisp)));
    let measured = summary.ran.iter().any(|r| r.ndisp_measured);
    let range = match (summary.settled, args.ndisp, &seq.calib) {
        (Some((n, true)), _, _) => format!("ndisp {n} measured on the first frame"),
        (Some((n, false)), _, _) | (None, Some(n), _) => format!("ndisp {n}"),
        (None, None, _) if measured && lo == hi => format!("ndisp {lo} measured"),
        (None, None, _) if measured => format!("ndisp {lo}–{hi} measured per frame"),
        (None, None, Some(_)) => format!("ndisp {lo} from calib.txt"),
        (None, None, None) => format!("ndisp {lo}"),
    };
    let range = match args.min_disp {
        0 => range,
        d => format!("{range}, searched from {d}"),
    };
    let mean = summary.ran.iter().map(|r| r.seconds).sum::<f64>() / ran as f64;
    format!(
        "wrote {} frames to {} ({counts}{size}{range}, {mean:.2} s per frame run; times in {})",
        ran + skipped + replayed,
        args.output.display(),
        jem::sequence::TIMES_FILE
    )
}
