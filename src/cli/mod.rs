//! Command-line interface: clap derive structs (doc comments are the help text) and one handler per command.
//!
//! Raw flags are merged with the defaults and `--config FILE` into one validated [`jem::Params`] (flags win);
//! the pipeline only ever sees `Params`.
//!
//! This file holds the parser ([`Cli`], the [`GlobalArgs`] every command takes, `--threads` ([`ThreadsArg`]) and
//! `--max-memory` ([`MemoryArg`]) for the commands they mean something to, and `Command`, whose doc
//! comments are the subcommands' help), [`run`], which hands each command to its own file, and
//! [`print_error`]. One file per command: `match.rs` (also the default, `jem LEFT RIGHT -o OUT`), `config.rs`
//! (and the `--config`/`--set`/`--downscale` flags that `match`, `batch` and `sequence` share), `synth.rs`,
//! `degrade.rs`, `batch.rs`, `sequence.rs`, `eval.rs`, `viz.rs`, `report.rs`.
//!
//! Everything the commands print goes through [`note!`] (stderr) and [`out!`] (stdout), which ignore a closed or
//! failing stream: `jem batch … 2>&1 | head -1` must not stop the work (`eprintln!` panics on a
//! closed pipe).

/// Writes a line to stderr, ignoring a closed or failing stderr.
macro_rules! note {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($arg)*);
    }};
}

/// Writes text to stdout (no newline added), ignoring a closed or failing stdout.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let mut stdout = std::io::stdout().lock();
        let _ = write!(stdout, $($arg)*).and_then(|()| stdout.flush());
    }};
}

mod batch;
mod config;
mod degrade;
mod eval;
mod r#match;
mod rectify;
mod report;
mod sequence;
mod signals;
mod synth;
mod usage;
mod viz;

use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use jem::{Error, Result};

use batch::BatchArgs;
use config::ConfigArgs;
use degrade::DegradeArgs;
use eval::EvalArgs;
use r#match::MatchArgs;
use rectify::RectifyArgs;
use report::ReportArgs;
use sequence::SequenceArgs;
use synth::SynthArgs;
use viz::VizArgs;

/// Stereo matching by joint energy minimization.
///
/// `jem LEFT RIGHT -o OUT` reads a rectified pair and writes the left view's disparity map (PFM, EXR or 16-bit
/// PNG by extension). ndisp comes from --ndisp, else from calib.txt beside LEFT.
#[derive(Parser, Debug)]
#[command(name = "jem", version, args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct Cli {
    #[command(subcommand)]
    command: Option<Command>,

    #[command(flatten)]
    match_args: MatchArgs,

    #[command(flatten)]
    global: GlobalArgs,
}

/// Options every command takes.
#[derive(Args, Debug, Clone)]
pub struct GlobalArgs {
    /// Print nothing but errors (not even the last line saying what was written).
    #[arg(long, short, global = true, help_heading = "Global")]
    quiet: bool,
    /// Print per-stage timings to stderr.
    #[arg(long, short, global = true, help_heading = "Global")]
    verbose: bool,
}

/// `--threads`, for the commands that run work in parallel (`match`, `batch`, `sequence`, `synth`, `degrade`,
/// `eval`, `report`; not `config` or `viz`, which have nothing to share out).
#[derive(Args, Debug, Clone, Default)]
pub struct ThreadsArg {
    /// Worker threads (default: one per core). The output does not depend on it.
    #[arg(long, value_name = "N", help_heading = "Resources")]
    threads: Option<usize>,
}

/// `--max-memory`, for the commands that run the pipeline (`match`, `batch`, `sequence`).
#[derive(Args, Debug, Clone, Default)]
pub struct MemoryArg {
    /// Refuse runs estimated to need more memory than this, before allocating (e.g. 1500M, 8G; default: 80% of
    /// physical memory); a pair that does not fit whole runs in tiles.
    #[arg(long, value_name = "SIZE", value_parser = parse_size, help_heading = "Resources")]
    max_memory: Option<u64>,
}

impl MemoryArg {
    /// The memory limit in bytes.
    fn memory_limit(&self) -> u64 {
        self.max_memory.unwrap_or_else(jem::default_memory_limit)
    }
}

/// Moves the flags written before a subcommand to just after it: `jem --threads 1 batch …` becomes
/// `jem batch --threads 1 …`. (The top-level command takes the match arguments too, so clap reads any flag before
/// the subcommand as belonging to a match and then rejects the subcommand name as a stray argument.) `--quiet` and
/// `--verbose` are taken by every subcommand, `--threads` and `--max-memory` only by those where they mean something
/// ([`ThreadsArg`], [`MemoryArg`]): `jem --threads 1 config` is refused as `jem config --threads 1` is.
///
/// Every subcommand's name comes from the parser itself, so none is missed.
pub fn global_flags_after_subcommand(mut args: Vec<std::ffi::OsString>) -> Vec<std::ffi::OsString> {
    let command = <Cli as clap::CommandFactory>::command();
    let is_subcommand = |arg: &str| arg == "help" || command.get_subcommands().any(|c| c.get_name() == arg);
    let mut i = 1;
    while i < args.len() {
        let Some(arg) = args[i].to_str() else { return args };
        match arg {
            "-q" | "--quiet" | "-v" | "--verbose" => i += 1,
            "--threads" | "--max-memory" => i += 2,
            _ if arg.starts_with("--threads=") || arg.starts_with("--max-memory=") => i += 1,
            _ if i > 1 && is_subcommand(arg) => {
                let sub = args.remove(i);
                args.insert(1, sub);
                return args;
            }
            _ => return args,
        }
    }
    args
}

/// Parses `123`, `800K`, `1500M`, `8G` (binary units; a trailing `B`/`iB` is allowed) into bytes.
fn parse_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim().trim_end_matches(['B', 'b']).trim_end_matches('i');
    let (digits, unit) = match t.char_indices().find(|(_, c)| c.is_ascii_alphabetic()) {
        Some((i, _)) => (&t[..i], &t[i..]),
        None => (t, ""),
    };
    let shift = match unit.to_ascii_uppercase().as_str() {
        "" => 0,
        "K" => 10,
        "M" => 20,
        "G" => 30,
        "T" => 40,
        _ => return Err(format!("unknown unit in {text:?} (use K, M, G or T)")),
    };
    let value: f64 = digits.trim().parse().map_err(|_| format!("{text:?} is not a size like 1500M or 8G"))?;
    if !(value.is_finite() && value > 0.0) {
        return Err(format!("{text:?} must be positive"));
    }
    let bytes = value * (1u64 << shift) as f64;
    if bytes < 1.0 {
        return Err(format!("{text:?} is less than one byte (a number without a unit is bytes: 0.5G, 512M)"));
    }
    Ok(bytes as u64)
}

#[derive(Subcommand, Debug)]
// Parsed once per run: the size of its largest variant (a match's arguments) costs nothing.
#[allow(clippy::large_enum_variant)]
enum Command {
    /// Match one pair (the same as `jem LEFT RIGHT -o OUT`).
    Match(MatchArgs),
    /// Rectify a raw pair with its stereo calibration, as OpenCV's stereoRectify and remap do.
    ///
    /// `jem rectify CALIB LEFT RIGHT -o DIR` writes DIR/im0.png, DIR/im1.png (the rectified views, 8-bit; grey when
    /// both raw views are grey) and DIR/calib.txt (Middlebury keys cam0, cam1, doffs, baseline, width, height; the
    /// baseline in the calibration's unit), ready for `jem DIR/im0.png DIR/im1.png -o disp.pfm --depth depth.pfm`,
    /// and DIR/rectify.yml (R1, R2, P1, P2, Q, the size and each view's rectangle of valid pixels validPixROI1/2,
    /// as cv2.FileStorage writes cv2.stereoRectify's results: for cv2.reprojectImageTo3D). --alpha is
    /// stereoRectify's free scaling (default 0: valid pixels only). `jem match --rectify CALIB` does the same
    /// (with alpha 0) before matching.
    /// CALIB: OpenCV FileStorage YAML or XML as cv2.FileStorage writes it (K1 or M1, D1 with 4, 5 or 8
    /// coefficients, K2/M2, D2, R, T; image_width/image_height or a size node; R1, R2, P1, P2 are used when
    /// present), or KITTI's calib_cam_to_cam.txt (cameras 02 and 03; images of KITTI's rectified size S_rect_02 are
    /// taken as already rectified).
    #[command(verbatim_doc_comment)]
    Rectify(RectifyArgs),
    /// Print the effective configuration (defaults ← --config ← --set) as TOML.
    Config(ConfigArgs),
    /// Render a synthetic scene with exact ground truth in MiddEval3 layout (--frames N: a sequence).
    ///
    /// `jem synth OUTDIR` writes im0.png, im1.png, calib.txt, disp0GT.pfm and mask0nocc.png. With --frames N it
    /// writes a stereo sequence as `jem sequence` reads it, exact ground truth per frame: --motion static, pan (the
    /// camera sideways: near objects move faster than the background), dolly (the camera forward: disparities
    /// grow), object (one object moves, the camera stands), cut (another scene from frame N/2); --noise S adds
    /// fresh sensor noise to every frame, --gain-jitter P and --exposure-step K:P change the exposure. truth.txt lists
    /// each frame's camera position, scene, object shift and gain.
    Synth(SynthArgs),
    /// Write a degraded copy of a scene tree (noise, low light, exposure mismatch, blur, misalignment, JPEG), seeded.
    ///
    /// Every scene under SRC (folders with im0.png, im1.png, calib.txt) is copied to OUT under the same relative
    /// path, its images degraded by the recipe, its calib.txt, disp0GT.pfm and mask0nocc.png copied unchanged,
    /// so `jem batch OUT` and `jem eval OUT` work as on SRC. Recipes (grey levels of the 8-bit input):
    ///   noise:S        Gaussian noise of σ S on every channel of both views
    ///   lowlight:G:R   light × G (values taken as linear), photon shot noise, read noise σ R, no gain after
    ///   exposure:G:P   right view only: v -> 255 (G v / 255)^P
    ///   blur:S         Gaussian blur of σ S pixels, both views
    ///   misalign:D:A   right view only: moved down D pixels and rotated A degrees about its centre (imperfect
    ///                  rectification; the ground truth is unchanged)
    ///   jpeg:Q         JPEG compression at quality Q (1-100), both views
    ///   A+B            A, then B
    ///   none           nothing (with --frames: a clean sequence)
    /// OUT is written as a whole or not at all; it must not exist (or be empty) and must be outside SRC.
    /// With --frames N, SRC is one scene and OUT becomes a stereo sequence (as `jem sequence` reads it): frame k is
    /// the scene degraded with its own seed (fresh noise each frame), its window moved k × --pan columns right
    /// (a panning camera; both views and the ground truth cropped alike, so the truth stays exact; matches that
    /// leave the window are marked occluded in mask/), ground truth in gt/<stem>.pfm, calib.txt with the window's
    /// width.
    #[command(verbatim_doc_comment)]
    Degrade(DegradeArgs),
    /// Run the pipeline on every stereo pair under DIR... (MiddEval3, KITTI 2012/2015, ETH3D, as distributed).
    ///
    /// The layout is recognised from the folders (--layout forces it):
    ///   MiddEval3   a scene folder with im0.png, im1.png, calib.txt -> disp0NAME.pfm + timeNAME.txt in it
    ///   KITTI 2015  image_2/ + image_3/ (frames *_10.png)          -> RES/NAME/SPLIT/disp_0/FRAME.png (16-bit, ×256, 0 = invalid)
    ///   KITTI 2012  colored_0/ + colored_1/ (or image_0/ + image_1/) -> as 2015
    ///   ETH3D       scene folders in two_view_*/ (or with a sibling *_gt/) -> RES/NAME/SPLIT/low_res_two_view/SCENE.pfm + SCENE.txt
    /// RES is --results, else results/ beside the data set's folder (kitti/training -> kitti/results); SPLIT is the
    /// data set's folder name (training, testing). It is never inside a data set, a results folder holding another
    /// data set's results (source.txt) is refused, and one a batch is writing is locked against a second batch.
    /// ndisp: --ndisp, else calib.txt, else 192 for KITTI; a missing range, or one of half the width or more (ETH3D
    /// states the width), is measured on the pair. Run times (seconds in the pipeline, loading and writing
    /// excluded) go beside each result (KITTI: RES/NAME/SPLIT/time/FRAME.txt), and so does the configuration it
    /// ran with (every parameter, the command line and jem's version, as TOML that --config reads back; what
    /// `jem report` shows): MiddEval3 configNAME.toml, KITTI and ETH3D RES/NAME/SPLIT/config/FRAME.toml. Each
    /// pair's files are written all or none.
    /// Pairs run in path order; a failing pair is reported and the others still run; the exit code is 2 if any
    /// failed.
    #[command(verbatim_doc_comment)]
    Batch(BatchArgs),
    /// Match every frame of a stereo sequence: `jem sequence DIR -o OUTDIR [--independent]`.
    ///
    /// DIR holds left/ and right/ with the frames (PNG, PPM/PGM, JPEG, BMP, TIFF or WebP), paired by file stem in
    /// sorted order, and optionally calib.txt (Middlebury keys), gt/<stem>.pfm and mask/<stem>.png (for `jem eval
    /// OUTDIR`); or it is a KITTI raw drive folder (image_02/data, image_03/data). Unequal counts or unpaired names
    /// are refused.
    /// Writes OUTDIR/<stem>.pfm (--ext exr|png for the other formats) per frame, times.txt (a line per frame: stem
    /// and seconds from the decoded pair to its map), sequence.txt (what made the folder) and config.toml.
    /// By default each frame is matched with the temporal model: a still camera's frames averaged, a moving
    /// camera's previous answer (moved by its shift) as the prior, scene cuts detected; the range is the first
    /// frame's, held for the sequence. A rerun replays the written frames before the last missing one to rebuild
    /// its state.
    /// --independent matches each frame alone, byte-identical to `jem LEFT RIGHT -o OUT --ndisp N` on that pair
    /// (N: --ndisp, else calib.txt's ndisp; without either the range is measured on each frame, as `jem match`
    /// measures it; --range-once measures it on the first frame and holds it).
    /// A rerun into OUTDIR skips the frames already written (and says so); a folder another run wrote (other
    /// sequence, format or configuration) is refused. Each frame's map and times.txt are written all or none.
    #[command(verbatim_doc_comment)]
    Sequence(SequenceArgs),
    /// Score results against the ground truth: MiddEval3 `evaldisp` style, KITTI devkit D1, ETH3D.
    ///
    /// Every pair under DIR with ground truth is scored, in the layout `jem batch` wrote it (one data set layout
    /// per call): MiddEval3 scenes with disp0GT.pfm; KITTI trees with disp_noc*/ (nonocc) and disp_occ*/ (all);
    /// ETH3D trees with their *_gt/ sibling (or --gt). --results as for batch.
    ///
    /// Ground-truth pixels that are inf are skipped; the mask selects mask0nocc.png == 255 (nonocc) or > 0 (all).
    /// Invalid (inf/NaN) result pixels count in `invalid` and `totbad2` but not in avgErr/rms; valid ones are
    /// clipped to [0, ndisp]. Errors and the bad thresholds 0.5/1/2/4 are in full-resolution pixels (err = s·|d − gt|,
    /// s = 4 for trainingQ, 2 for *H, 1 for *F; in a folder named otherwise, from the scenes' names and image sizes,
    /// said on stderr). All percentages are of the masked GT-valid pixels (bad counts only valid pixels;
    /// totbad2 = bad2 + invalid). "weighted" is the MiddEval3 average (PianoL, Playroom, Playtable,
    /// Shelves, Vintage weigh 0.5, other scenes 1), "mean" the plain one. Scenes whose result is missing or
    /// unreadable are listed, left out of both averages, and make the exit code 2.
    /// KITTI and ETH3D: native pixels, no clipping, every scene weighs 1. KITTI as its devkit: invalid result
    /// pixels are filled (background interpolation) before scoring, `invalid` is the share before the fill, and
    /// D1 = % of GT pixels with error > 3 px and > 5 % of the true disparity. ETH3D --mask all: every GT pixel.
    ///
    /// JSON: one object per --alg (an array when several): {"alg", "layout", "mask", "scale", "scenes": {SCENE:
    /// {"avgerr", "rms", "bad0.5", "bad1", "bad2", "bad4", "invalid", "totbad2"}}, "weighted": {...}, "mean":
    /// {...}}, plus "excluded": {SCENE: reason} when scenes were left out and "paper": {...} with --paper; NaN is
    /// null. KITTI: the keys are "d1", "avgerr", "rms", "bad0.5", "bad1", "bad2", "bad4", "invalid".
    ///
    /// A sequence: `jem eval OUTDIR` scores the per-frame maps `jem sequence` wrote against the sequence's
    /// gt/<stem>.pfm (and mask/<stem>.png where there are masks; without them every GT pixel), --gt naming the
    /// sequence when OUTDIR does not record it. Per frame avgErr, bad2 and invalid as above (the range of the
    /// sequence's calib.txt clips; --scale auto reads the sequence's path, else 1: a sequence made from trainingQ
    /// needs --scale 4), and from frame to frame, over pixels with ground truth in both frames (selected by both
    /// masks) and a valid result in both: flicker = mean |d_t − d_t−1| where the truth changed by less than 0.5 px,
    /// change err = mean |(d_t − d_t−1) − (g_t − g_t−1)| where it changed more (full-resolution px); the last row
    /// holds the means over the frames. JSON: {"frames": {STEM: {metrics, "flicker", "change_err", ...}}, "mean",
    /// "flicker", "change_err", "seconds", ...}.
    ///
    /// Environment: JEM_DATA, if set, is the folder holding paper-results.tsv (used for --paper when --paper-file
    /// is not given; otherwise ../shared/middlebury/paper-results.tsv relative to the current folder).
    #[command(verbatim_doc_comment)]
    Eval(EvalArgs),
    /// Draw a disparity map (colour, error map against --gt) or a contact sheet of a data set's folder.
    ///
    /// `jem viz DISP -o OUT.png [--gt GT]` or `jem viz DIR --alg NAME -o SHEET.png`.
    /// The disparity is colour-mapped (dark indigo = low, through blue, green, yellow to dark red = high; invalid
    /// pixels black) over --vmin..--vmax, else vmin/vmax from calib.txt beside DISP, else the finite data range.
    /// With --gt the picture is the colour map and the error map side by side (disparity | error), under the
    /// benchmark's own rule, recognised from where GT is (--layout says otherwise):
    ///   MiddEval3  bad-2: error > 2 full-resolution px (errors × --scale, else from the path: trainingQ = 4, *H = 2,
    ///              *F = 1, else from the scene's name and size, or from GT's size when only one resolution
    ///              has a MiddEval3 scene of that size; when nothing tells, --scale is needed)
    ///   KITTI      D1: error > 3 px and > 5 % of the true disparity (GT a 16-bit .png in disp_noc*/ or disp_occ*/;
    ///              the sibling map marks occlusions)
    ///   ETH3D      bad-1: error > 1 px (GT in a scene folder of a *_gt/ tree)
    /// Not bad: grey (white = exact), bad: red; occluded pixels (mask0nocc.png beside GT, or KITTI's disp_noc*)
    /// shaded darker, no ground truth dark grey, invalid result black.
    /// For a folder, a contact sheet with one row per scene or frame (sorted): left image | result | error map, each
    /// panel downscaled to at most --panel-width px. MiddEval3 scenes with disp0NAME.pfm; KITTI and ETH3D trees with
    /// their results where `jem batch --alg NAME` writes them (--results as for batch; ETH3D's ground truth from its
    /// *_gt/ sibling or --gt DIR).
    #[command(verbatim_doc_comment)]
    Viz(VizArgs),
    /// Write an HTML page of a data set's results: `jem report DIR --alg A[,B...] -o report.html`.
    ///
    /// One page that opens from the disk in any browser (nothing is loaded from a network), its pictures in the
    /// folder <stem>_files/ beside it. Per scene or frame a row: the left image and, for each --alg, its disparity
    /// in colour and its error map under the benchmark's rule (as jem viz draws them; click for the full size),
    /// and its scores as jem eval computes them: MiddEval3 avgErr, bad-2 (invalid pixels counted as bad), invalid,
    /// the run time in seconds (as each run recorded it; not ranked, runs under other loads being not
    /// comparable), and the paper's avgErr beside an --alg given a --paper column; KITTI D1 and avgErr; ETH3D
    /// bad-1 and avgErr. The last row is the weighted (MiddEval3) or plain mean; the best score of a row is bold.
    /// Click a score's header to sort the rows. A colour bar and the error map's key head the page; the command,
    /// each algorithm's configuration (as jem batch recorded it beside the results) and the machine are at its foot.
    /// The page and its pictures are written all or none; an output that is one of the inputs is refused.
    #[command(verbatim_doc_comment)]
    Report(ReportArgs),
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> Result<ExitCode> {
    signals::install();
    let threads = match &cli.command {
        None => &cli.match_args.threads,
        Some(Command::Match(a)) => &a.threads,
        Some(Command::Synth(a)) => &a.threads,
        Some(Command::Degrade(a)) => &a.threads,
        Some(Command::Batch(a)) => &a.threads,
        Some(Command::Sequence(a)) => &a.threads,
        Some(Command::Eval(a)) => &a.threads,
        Some(Command::Report(a)) => &a.threads,
        Some(Command::Rectify(a)) => &a.threads,
        Some(Command::Config(_) | Command::Viz(_)) => &ThreadsArg::default(),
    };
    if let Some(n) = threads.threads {
        // Refused before any thread starts (the bound is jem::threads', shared with the Python module).
        let n = jem::threads::check_threads("--threads", n as u64)?;
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| Error::argument(format!("cannot start {n} threads: {e}")))?;
    }
    match cli.command {
        None => r#match::run(&cli.match_args, &cli.global),
        Some(Command::Match(args)) => r#match::run(&args, &cli.global),
        Some(Command::Config(args)) => config::run(&args, &cli.global),
        Some(Command::Synth(args)) => synth::run(&args, &cli.global),
        Some(Command::Degrade(args)) => degrade::run(&args, &cli.global),
        Some(Command::Batch(args)) => batch::run(&args, &cli.global),
        Some(Command::Sequence(args)) => sequence::run(&args, &cli.global),
        Some(Command::Eval(args)) => eval::run(&args, &cli.global),
        Some(Command::Viz(args)) => viz::run(&args, &cli.global),
        Some(Command::Report(args)) => report::run(&args, &cli.global),
        Some(Command::Rectify(args)) => rectify::run(&args, &cli.global),
    }
}

/// Handles what clap could not parse (`args`: the command line it was given): `--help` and `--version` are
/// printed as clap prints them (exit 0); a bare `jem` gets the usage and the list of commands, a third path after
/// the two images "did you mean -o PATH?" ([`usage`]); any other argument error is one line, `error: …`, as every
/// other error (clap's own form adds a tip, the usage and "For more information, try '--help'." on 3 to 6 more
/// lines). Exit code 2 for all but help and version.
pub fn usage_error(e: clap::Error, args: &[std::ffi::OsString]) -> ExitCode {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        let _ = e.print();
        return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
    }
    let message = match e.kind() {
        ErrorKind::MissingRequiredArgument if usage::is_bare(args) => usage::usage(),
        ErrorKind::MissingRequiredArgument => one_line_usage_error(&e.render().to_string()),
        _ => usage::stray_output(args).unwrap_or_else(|| one_line_usage_error(&e.render().to_string())),
    };
    note!("{message}");
    ExitCode::from(2)
}

/// clap's message on one line: its first paragraph (the error, and the arguments it lists, joined) and its tip,
/// without the usage and the pointer to --help that follow.
fn one_line_usage_error(rendered: &str) -> String {
    let mut line = String::new();
    for part in rendered.lines().take_while(|l| !l.trim().is_empty()).map(str::trim) {
        if !line.is_empty() {
            line.push_str(if line.ends_with(':') { " " } else { ", " });
        }
        line.push_str(part);
    }
    if !line.starts_with("error:") {
        line.insert_str(0, "error: ");
    }
    let tips: Vec<&str> = rendered.lines().map(str::trim).filter(|l| l.starts_with("tip:")).collect();
    if !tips.is_empty() {
        line.push_str(&format!(" ({})", tips.join("; ")));
    }
    line
}

/// Prints `error: ...` and each cause on one line.
pub fn print_error(err: &Error) {
    note!("error: {}", err.chain());
}

/// The command line as typed, each argument quoted for a POSIX shell where it needs it.
pub(super) fn command_line() -> String {
    let quote = |a: String| {
        let plain = !a.is_empty() && a.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=,:+@%".contains(c));
        if plain { a } else { format!("'{}'", a.replace('\'', "'\\''")) }
    };
    let mut args = std::env::args_os().map(|a| a.to_string_lossy().into_owned());
    let program = args.next().map(|p| {
        let name = std::path::Path::new(&p).file_name().map(|n| n.to_string_lossy().into_owned());
        name.unwrap_or(p)
    });
    program.into_iter().chain(args).map(quote).collect::<Vec<_>>().join(" ")
}
