//! Command-line interface: clap derive structs (doc comments are the help text) and one handler per command.
//!
//! Raw flags are merged with the defaults and `--config FILE` into one validated [`jem::Params`] (flags win);
//! the pipeline only ever sees `Params`.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::{Args, Parser, Subcommand};
use jem::io::calib;
use jem::{Error, Params, Result, StereoPair};

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
    /// Worker threads (default: one per core).
    #[arg(long, global = true, value_name = "N", help_heading = "Global")]
    threads: Option<usize>,
    /// Print nothing but errors.
    #[arg(long, short, global = true, help_heading = "Global")]
    quiet: bool,
    /// Print per-stage timings to stderr.
    #[arg(long, short, global = true, help_heading = "Global")]
    verbose: bool,
    /// Refuse runs estimated to need more memory than this, before allocating (e.g. 1500M, 8G; default: 80% of
    /// physical memory).
    #[arg(long, global = true, value_name = "SIZE", value_parser = parse_size, help_heading = "Global")]
    max_memory: Option<u64>,
}

impl GlobalArgs {
    /// The memory limit in bytes.
    fn memory_limit(&self) -> u64 {
        self.max_memory.unwrap_or_else(jem::default_memory_limit)
    }
}

/// Moves global flags written before a subcommand to just after it: `jem --threads 1 batch …` becomes
/// `jem batch --threads 1 …`. (The top-level command takes the match arguments too, so clap reads any flag before
/// the subcommand as belonging to a match and then rejects the subcommand name as a stray argument.)
pub fn global_flags_after_subcommand(mut args: Vec<std::ffi::OsString>) -> Vec<std::ffi::OsString> {
    const SUBCOMMANDS: [&str; 7] = ["match", "config", "synth", "batch", "eval", "viz", "help"];
    let mut i = 1;
    while i < args.len() {
        let Some(arg) = args[i].to_str() else { return args };
        match arg {
            "-q" | "--quiet" | "-v" | "--verbose" => i += 1,
            "--threads" | "--max-memory" => i += 2,
            _ if arg.starts_with("--threads=") || arg.starts_with("--max-memory=") => i += 1,
            _ if i > 1 && SUBCOMMANDS.contains(&arg) => {
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
    Ok((value * (1u64 << shift) as f64) as u64)
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Match one pair (the same as `jem LEFT RIGHT -o OUT`).
    Match(MatchArgs),
    /// Print the effective configuration (defaults ← --config ← --set) as TOML.
    Config(ConfigArgs),
    /// Render a synthetic scene with exact ground truth in MiddEval3 layout.
    Synth(SynthArgs),
    /// Run the pipeline on every scene under DIR... (MiddEval3 layout): disp0NAME.pfm + timeNAME.txt.
    ///
    /// A scene is a folder with im0.png, im1.png and calib.txt (ndisp is read from it); every scene under each DIR is
    /// found recursively and processed in path order. Each gets disp0NAME.pfm and timeNAME.txt (seconds spent in the
    /// pipeline for that pair, loading and writing excluded), written atomically. A failing scene is reported and the
    /// others still run; the exit code is 2 if any scene failed.
    #[command(verbatim_doc_comment)]
    Batch(BatchArgs),
    /// Score disp0NAME.pfm results against the ground truth, MiddEval3 `evaldisp` style.
    ///
    /// Every scene folder under DIR with a disp0GT.pfm is scored.
    ///
    /// Ground-truth pixels that are inf are skipped; the mask selects mask0nocc.png == 255 (nonocc) or > 0 (all).
    /// Invalid (inf/NaN) result pixels count in `invalid` and `totbad2` but not in avgErr/rms; valid ones are
    /// clipped to [0, ndisp]. Errors and the bad thresholds 0.5/1/2/4 are in full-resolution pixels (err = s·|d − gt|,
    /// s = 4 for trainingQ, 2 for *H, 1 for *F). All percentages are of the masked GT-valid pixels (bad counts only
    /// valid pixels; totbad2 = bad2 + invalid). "weighted" is the MiddEval3 average (PianoL, Playroom, Playtable,
    /// Shelves, Vintage weigh 0.5, other scenes 1), "mean" the plain one. Scenes whose result is missing or
    /// unreadable are listed, left out of both averages, and make the exit code 2.
    ///
    /// JSON: one object per --alg (an array when several): {"alg", "mask", "scale", "scenes": {SCENE: {"avgerr",
    /// "rms", "bad0.5", "bad1", "bad2", "bad4", "invalid", "totbad2"}}, "weighted": {...}, "mean": {...}}, plus
    /// "excluded": {SCENE: reason} when scenes were left out and "paper": {...} with --paper; NaN is null.
    ///
    /// Environment: JEM_DATA, if set, is the folder holding paper-results.tsv (used for --paper when --paper-file
    /// is not given; otherwise ../shared/middlebury/paper-results.tsv relative to the current folder).
    #[command(verbatim_doc_comment)]
    Eval(EvalArgs),
    /// Draw a disparity map (colour, error map against --gt) or a contact sheet of a folder.
    ///
    /// `jem viz DISP -o OUT.png [--gt GT.pfm]` or `jem viz DIR --alg NAME -o SHEET.png`.
    /// The disparity is colour-mapped (dark indigo = low, through blue, green, yellow to dark red = high; invalid
    /// pixels black) over --vmin..--vmax, else vmin/vmax from calib.txt beside DISP, else the finite data range.
    /// With --gt the picture is the colour map and the error map side by side (disparity | error): error ≤ 2
    /// full-resolution px in grey (white = exact), > 2 px in red, occluded pixels (mask0nocc.png beside GT == 128)
    /// shaded darker, no ground truth dark grey, invalid result black.
    /// For a folder, a contact sheet with one row per scene (sorted by path): left image | result | error map,
    /// each panel downscaled to at most --panel-width px.
    #[command(verbatim_doc_comment)]
    Viz(VizArgs),
}

/// Which parameters to use.
#[derive(Args, Debug, Clone, Default)]
pub struct ConfigArgs {
    /// TOML config file (see configs/); defaults are used for keys it does not set.
    #[arg(long, short = 'c', value_name = "FILE", help_heading = "Configuration")]
    config: Option<PathBuf>,
    /// Override one key, e.g. `--set meanfield.iterations=8` (repeatable; wins over --config).
    #[arg(long = "set", value_name = "KEY=VALUE", help_heading = "Configuration")]
    overrides: Vec<String>,
    /// Run at 1/N resolution and upsample the disparity map (the `downscale` key; wins over --config and --set):
    /// ~1/N³ of the memory and time of inference.
    #[arg(long, value_name = "N", allow_negative_numbers = true, help_heading = "Configuration")]
    downscale: Option<String>,
}

impl ConfigArgs {
    fn params(&self) -> Result<Params> {
        let mut overrides = self.overrides.clone();
        if let Some(text) = &self.downscale {
            overrides.push(format!("downscale={}", parse_downscale(text)?));
        }
        Params::load(self.config.as_deref(), &overrides)
    }
}

/// The `--downscale` value: an integer ≥ 1 (parsed here rather than by clap, for a one-line error).
fn parse_downscale(text: &str) -> Result<usize> {
    match text.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(Error::param("--downscale", format!("{text:?}"), "an integer >= 1; 1 = full resolution")),
    }
}

#[derive(Args, Debug, Clone)]
struct MatchArgs {
    /// Left (reference) image: PNG or PPM/PGM, 8 or 16 bit.
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
    #[command(flatten)]
    config: ConfigArgs,
}

#[derive(Args, Debug, Clone)]
struct SynthArgs {
    /// Folder to write the scene into (created if missing).
    outdir: PathBuf,
    /// Random seed: the same seed gives byte-identical files.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Image width in pixels (64..=8192).
    #[arg(long, default_value_t = 320, value_name = "W")]
    width: usize,
    /// Image height in pixels (32..=8192).
    #[arg(long, default_value_t = 240, value_name = "H")]
    height: usize,
    /// Disparity search range written to calib.txt (16..=W/2); the scene's disparities span about 6-92 % of it.
    #[arg(long, default_value_t = 48, value_name = "N")]
    ndisp: usize,
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> Result<ExitCode> {
    if let Some(n) = cli.global.threads {
        if n == 0 {
            return Err(Error::param("--threads", 0, "at least 1"));
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| Error::Input(format!("cannot start {n} threads: {e}")))?;
    }
    match cli.command {
        None => run_match(&cli.match_args, &cli.global),
        Some(Command::Match(args)) => run_match(&args, &cli.global),
        Some(Command::Config(args)) => {
            print!("{}", args.params()?.to_toml());
            Ok(ExitCode::SUCCESS)
        }
        Some(Command::Synth(args)) => run_synth(&args, &cli.global),
        Some(Command::Batch(args)) => run_batch(&args, &cli.global),
        Some(Command::Eval(args)) => run_eval(&args),
        Some(Command::Viz(args)) => run_viz(&args, &cli.global),
    }
}

/// Prints `error: ...` and each cause on one line.
pub fn print_error(err: &Error) {
    let mut msg = format!("error: {err}");
    let mut source = std::error::Error::source(err);
    while let Some(s) = source {
        msg.push_str(": ");
        msg.push_str(&s.to_string());
        source = s.source();
    }
    eprintln!("{msg}");
}

/// ndisp from the flag, else from calib.txt beside the left image.
fn resolve_ndisp(flag: Option<usize>, left: &Path) -> Result<usize> {
    if let Some(n) = flag {
        return Ok(n);
    }
    let calib_path = left.parent().unwrap_or(Path::new(".")).join("calib.txt");
    if !calib_path.exists() {
        return Err(Error::Input(format!(
            "no --ndisp given and no calib.txt beside {} to read it from",
            left.display()
        )));
    }
    calib::read_ndisp(&calib_path)
}

/// Loads a pair and checks sizes and ndisp.
pub fn load_pair(left: &Path, right: &Path, ndisp: Option<usize>) -> Result<StereoPair> {
    let (l, r) = jem::io::png::load_rgb_pair(left, right)?;
    let ndisp = resolve_ndisp(ndisp, left)?;
    StereoPair::new(l, r, ndisp)
}

fn run_match(args: &MatchArgs, global: &GlobalArgs) -> Result<ExitCode> {
    let (Some(left), Some(right), Some(output)) = (&args.left, &args.right, &args.output) else {
        return Err(Error::Input("usage: jem LEFT RIGHT -o OUT (see --help)".into()));
    };
    // Check the output names before doing any work.
    jem::io::DisparityFormat::from_path(output)?;
    if let Some(c) = &args.confidence {
        jem::io::DisparityFormat::from_path(c)?;
    }
    let params = args.config.params()?;
    let start = Instant::now();
    let pair = load_pair(left, right, args.ndisp)?;
    jem::check_memory(pair.left.width, pair.left.height, pair.ndisp, &params, global.memory_limit())?;
    let load_time = start.elapsed();

    let spinner = stage_spinner(global.quiet);
    let out = jem::run_observed(&params, &pair, &|stage| {
        if let Some(s) = &spinner {
            s.set_message(stage.to_string());
        }
    })?;
    if let Some(s) = spinner {
        s.finish_and_clear();
    }
    jem::io::write_disparity(output, &out.disparity)?;
    if let Some(c) = &args.confidence {
        jem::io::write_disparity(c, &out.confidence)?;
    }
    if global.verbose && !global.quiet {
        eprintln!("{:<14} {:>9.1} ms", "load", load_time.as_secs_f64() * 1e3);
        for (name, d) in &out.timings.stages {
            eprintln!("{name:<14} {:>9.1} ms", d.as_secs_f64() * 1e3);
        }
        eprintln!("{:<14} {:>9.1} ms", "total", start.elapsed().as_secs_f64() * 1e3);
    }
    Ok(ExitCode::SUCCESS)
}

fn run_synth(args: &SynthArgs, global: &GlobalArgs) -> Result<ExitCode> {
    let params = jem::synth::SynthParams { width: args.width, height: args.height, ndisp: args.ndisp, seed: args.seed };
    let scene = jem::synth::render_scene(&params)?;
    jem::synth::write_scene(&args.outdir, &scene)?;
    if !global.quiet {
        eprintln!(
            "wrote {}/{{im0.png,im1.png,calib.txt,disp0GT.pfm,mask0nocc.png}}: {}x{}, ndisp {}, disparities {}..{}, \
             seed {}",
            args.outdir.display(),
            params.width,
            params.height,
            scene.ndisp,
            scene.vmin,
            scene.vmax,
            params.seed
        );
    }
    Ok(ExitCode::SUCCESS)
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

// ---------------------------------------------------------------------------------------------------------------
// jem batch

/// Arguments of `jem batch` (the help text is on [`Command::Batch`]).
#[derive(Args, Debug, Clone)]
struct BatchArgs {
    /// Folders to search, recursively, for scene folders.
    #[arg(required = true, value_name = "DIR")]
    dirs: Vec<PathBuf>,
    /// Algorithm name: the outputs are disp0NAME.pfm and timeNAME.txt (letters, digits, _ and - only).
    #[arg(long, value_name = "NAME")]
    alg: String,
    #[command(flatten)]
    config: ConfigArgs,
    /// Scenes processed at the same time (each run is multi-threaded already; more jobs need more memory).
    #[arg(long, short = 'j', value_name = "N", default_value_t = 1)]
    jobs: usize,
    /// Process only part I of N (1-based) of the sorted scene list: scene k (0-based) belongs to part
    /// k mod N + 1. Over I = 1..N every scene is processed exactly once, e.g. one part per job of a job array.
    #[arg(long, value_name = "I/N")]
    shard: Option<jem::batch::Shard>,
    /// Skip scenes that already have disp0NAME.pfm (to resume an interrupted run).
    #[arg(long)]
    skip_existing: bool,
}

/// What the batch display shows while scenes run.
struct BatchDisplay {
    bar: Option<indicatif::ProgressBar>,
    quiet: bool,
    total: usize,
    done: std::sync::atomic::AtomicUsize,
    active: std::sync::Mutex<std::collections::BTreeMap<usize, (String, String)>>,
}

impl BatchDisplay {
    fn new(total: usize, quiet: bool) -> Self {
        let bar = (!quiet && std::io::stderr().is_terminal()).then(|| {
            let style = indicatif::ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] [{bar:30}] {pos}/{len} scenes, ETA {eta}  {wide_msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> ");
            let bar = indicatif::ProgressBar::new(total as u64).with_style(style);
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            bar
        });
        BatchDisplay { bar, quiet, total, done: 0.into(), active: Default::default() }
    }

    fn line(&self, msg: &str) {
        match &self.bar {
            Some(bar) => bar.println(msg),
            None => eprintln!("{msg}"),
        }
    }

    fn refresh(&self) {
        let (Some(bar), Ok(active)) = (&self.bar, self.active.lock()) else {
            return;
        };
        let msg: Vec<String> = active.values().map(|(name, stage)| format!("{name} ({stage})")).collect();
        bar.set_message(msg.join(", "));
    }

    fn on_event(&self, event: jem::batch::Event<'_>) {
        use jem::batch::{Event, SceneStatus};
        match event {
            Event::Started { index, name } => {
                if let Ok(mut a) = self.active.lock() {
                    a.insert(index, (name.to_string(), "starting".into()));
                }
                self.refresh();
            }
            Event::Stage { index, stage } => {
                if let Ok(mut a) = self.active.lock() {
                    if let Some(entry) = a.get_mut(&index) {
                        entry.1 = stage.to_string();
                    }
                }
                self.refresh();
            }
            Event::Finished { index, report } => {
                if let Ok(mut a) = self.active.lock() {
                    a.remove(&index);
                }
                let n = self.done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                let head = format!("[{n}/{}] {}", self.total, report.name);
                match &report.status {
                    SceneStatus::Failed(e) => self.line(&format!("{head}: FAILED: {e}")),
                    _ if self.quiet || self.bar.is_some() => {}
                    SceneStatus::Skipped => self.line(&format!("{head}: skipped (result exists)")),
                    SceneStatus::Done(r) => {
                        self.line(&format!("{head}: {}x{}, ndisp {}, {:.3} s", r.size.0, r.size.1, r.ndisp, r.seconds))
                    }
                }
                if let Some(bar) = &self.bar {
                    bar.inc(1);
                }
                self.refresh();
            }
        }
    }
}

fn run_batch(args: &BatchArgs, global: &GlobalArgs) -> Result<ExitCode> {
    use jem::batch::{BatchOptions, SceneStatus};
    jem::batch::validate_alg_name(&args.alg)?;
    if args.jobs == 0 {
        return Err(Error::param("--jobs", 0, "at least 1"));
    }
    let params = args.config.params()?;
    let all = jem::batch::find_scenes(&args.dirs)?;
    if all.is_empty() {
        let dirs: Vec<String> = args.dirs.iter().map(|d| d.display().to_string()).collect();
        return Err(Error::Input(format!(
            "no scene folder (with im0.png, im1.png and calib.txt) under {}",
            dirs.join(", ")
        )));
    }
    let scenes = match args.shard {
        Some(shard) => shard.select(&all),
        None => all.clone(),
    };
    if !global.quiet {
        let shard =
            args.shard.map(|s| format!(" (shard {}/{} of {})", s.index, s.count, all.len())).unwrap_or_default();
        eprintln!("{} scene(s){shard}, alg {}, {} job(s)", scenes.len(), args.alg, args.jobs);
    }
    let opts = BatchOptions {
        alg: args.alg.clone(),
        jobs: args.jobs,
        skip_existing: args.skip_existing,
        max_memory_bytes: global.memory_limit(),
    };
    let display = BatchDisplay::new(scenes.len(), global.quiet);

    // Panics inside the pipeline are caught and reported per scene; keep the default hook's message and
    // backtrace note off the terminal unless -v.
    let previous_hook = (!global.verbose).then(|| {
        let prev = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        prev
    });
    let reports = jem::batch::run_batch(&scenes, &params, &opts, &|e| display.on_event(e));
    if let Some(prev) = previous_hook {
        std::panic::set_hook(prev);
    }
    if let Some(bar) = &display.bar {
        bar.finish_and_clear();
    }

    let failed = reports.iter().filter(|r| matches!(r.status, SceneStatus::Failed(_))).count();
    if !global.quiet {
        print!("{}", batch_summary(&reports, global.verbose));
    }
    Ok(if failed > 0 { ExitCode::from(2) } else { ExitCode::SUCCESS })
}

/// The end-of-run table: scene, size, ndisp, seconds (and per-stage seconds with -v), status; then counts and
/// the failures.
fn batch_summary(reports: &[jem::batch::SceneReport], verbose: bool) -> String {
    use jem::batch::SceneStatus;
    let mut stages: Vec<&'static str> = Vec::new();
    if verbose {
        for r in reports {
            if let SceneStatus::Done(run) = &r.status {
                for (name, _) in &run.timings.stages {
                    if !stages.contains(name) {
                        stages.push(name);
                    }
                }
            }
        }
    }
    let mut header: Vec<String> = ["scene", "size", "ndisp", "seconds"].map(String::from).to_vec();
    header.extend(stages.iter().map(|s| s.to_string()));
    header.push("status".into());
    let mut rows = vec![header];
    let (mut done, mut skipped, mut failed, mut total_s) = (0, 0, 0, 0.0);
    for r in reports {
        let mut row = vec![r.name.clone()];
        match &r.status {
            SceneStatus::Done(run) => {
                done += 1;
                total_s += run.seconds;
                row.extend([
                    format!("{}x{}", run.size.0, run.size.1),
                    run.ndisp.to_string(),
                    format!("{:.3}", run.seconds),
                ]);
                for s in &stages {
                    let t =
                        run.timings.stages.iter().filter(|(n, _)| n == s).map(|(_, d)| d.as_secs_f64()).sum::<f64>();
                    row.push(format!("{t:.3}"));
                }
                row.push("ok".into());
            }
            other => {
                row.extend(std::iter::repeat_n("-".to_string(), 3 + stages.len()));
                if matches!(other, SceneStatus::Skipped) {
                    skipped += 1;
                    row.push("skipped".into());
                } else {
                    failed += 1;
                    row.push("FAILED".into());
                }
            }
        }
        rows.push(row);
    }
    let mut out = text_table(&rows, 1);
    let mean = if done > 0 { format!(", mean {:.3} s per pair", total_s / done as f64) } else { String::new() };
    out.push_str(&format!(
        "{} scene(s): {done} done, {skipped} skipped, {failed} failed; pipeline time {total_s:.3} s{mean}\n",
        reports.len()
    ));
    if failed > 0 {
        out.push_str("failures:\n");
        for r in reports {
            if let SceneStatus::Failed(e) = &r.status {
                out.push_str(&format!("  {} ({}): {e}\n", r.name, r.dir.display()));
            }
        }
    }
    out
}

/// Aligns rows of cells into columns (the first `text_cols` left-aligned, the rest right-aligned except the last).
fn text_table(rows: &[Vec<String>], text_cols: usize) -> String {
    let ncol = rows.iter().map(Vec::len).max().unwrap_or(0);
    let widths: Vec<usize> =
        (0..ncol).map(|c| rows.iter().filter_map(|r| r.get(c)).map(|v| v.chars().count()).max().unwrap_or(0)).collect();
    let mut out = String::new();
    for r in rows {
        let cells: Vec<String> = r
            .iter()
            .enumerate()
            .map(|(c, v)| {
                if c < text_cols || c + 1 == ncol {
                    format!("{v:<w$}", w = widths[c])
                } else {
                    format!("{v:>w$}", w = widths[c])
                }
            })
            .collect();
        out.push_str(cells.join("  ").trim_end());
        out.push('\n');
    }
    out
}

// ---------------------------------------------------------------------------------------------------------------
// jem eval

/// `auto`, 1, 2 or 4.
#[derive(Clone, Copy, Debug)]
struct ScaleArg(Option<u32>);

impl std::str::FromStr for ScaleArg {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "auto" => Ok(ScaleArg(None)),
            "1" => Ok(ScaleArg(Some(1))),
            "2" => Ok(ScaleArg(Some(2))),
            "4" => Ok(ScaleArg(Some(4))),
            _ => Err(format!("invalid scale {s:?} (expected auto, 1, 2 or 4)")),
        }
    }
}

/// Arguments of `jem eval` (the help text is on [`Command::Eval`]).
#[derive(Args, Debug, Clone)]
struct EvalArgs {
    /// Folder searched recursively for scene folders with disp0GT.pfm (e.g. MiddEval3/trainingQ, or one scene).
    #[arg(value_name = "DIR")]
    dir: PathBuf,
    /// Result to score: disp0NAME.pfm in each scene folder (repeatable).
    #[arg(long = "alg", required = true, value_name = "NAME")]
    algs: Vec<String>,
    /// Pixels to evaluate: nonocc (mask0nocc.png == 255) or all (mask > 0).
    #[arg(long, value_name = "nonocc|all", default_value = "nonocc")]
    mask: jem::eval::MaskMode,
    /// Factor to full-resolution pixels; auto reads it from the path (trainingQ/testQ = 4, *H = 2, *F = 1).
    #[arg(long, value_name = "auto|1|2|4", default_value = "auto")]
    scale: ScaleArg,
    /// Output format: table, csv, json or markdown.
    #[arg(long, value_name = "FORMAT", default_value = "table")]
    format: jem::eval::Format,
    /// Print the paper's avgErr from this column of paper-results.tsv beside ours (LCM, FCM, JEM_LRC, JEM_SPS,
    /// JEM_ALL, ...). Give it once for all --alg, or once per --alg in the same order.
    #[arg(long, value_name = "COLUMN")]
    paper: Vec<String>,
    /// The paper's numbers (default: $JEM_DATA/paper-results.tsv, else ../shared/middlebury/paper-results.tsv).
    #[arg(long, value_name = "PATH")]
    paper_file: Option<PathBuf>,
}

/// Where the paper's TSV is: --paper-file, else $JEM_DATA/paper-results.tsv, else ../shared/middlebury/.
fn paper_file(flag: Option<&Path>) -> PathBuf {
    if let Some(p) = flag {
        return p.to_path_buf();
    }
    match std::env::var_os("JEM_DATA") {
        Some(d) if !d.is_empty() => PathBuf::from(d).join("paper-results.tsv"),
        _ => PathBuf::from("../shared/middlebury/paper-results.tsv"),
    }
}

fn run_eval(args: &EvalArgs) -> Result<ExitCode> {
    use jem::eval::{PaperResults, evaluate_dir, render};
    for a in &args.algs {
        jem::batch::validate_alg_name(a)?;
    }
    let papers = if args.paper.is_empty() {
        Vec::new()
    } else {
        if args.paper.len() != 1 && args.paper.len() != args.algs.len() {
            return Err(Error::Input(format!(
                "{} --paper columns for {} --alg: give one for all, or one per --alg",
                args.paper.len(),
                args.algs.len()
            )));
        }
        let path = paper_file(args.paper_file.as_deref());
        if !path.is_file() {
            return Err(Error::Input(format!(
                "--paper needs the paper's numbers, but {} does not exist (use --paper-file or set JEM_DATA)",
                path.display()
            )));
        }
        let table = PaperResults::load(&path)?;
        let columns = args.algs.iter().enumerate().map(|(i, _)| &args.paper[if args.paper.len() == 1 { 0 } else { i }]);
        columns.map(|c| table.column(c).map(Some)).collect::<Result<Vec<_>>>()?
    };
    let reports = args
        .algs
        .iter()
        .map(|alg| evaluate_dir(&args.dir, alg, args.mask, args.scale.0))
        .collect::<Result<Vec<_>>>()?;
    print!("{}", render(&reports, &papers, args.format));
    let excluded = reports.iter().any(|r| r.excluded().next().is_some());
    Ok(if excluded { ExitCode::from(2) } else { ExitCode::SUCCESS })
}

// ---------------------------------------------------------------------------------------------------------------
// jem viz

/// Arguments of `jem viz` (the help text is on [`Command::Viz`]).
#[derive(Args, Debug, Clone)]
struct VizArgs {
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

fn run_viz(args: &VizArgs, global: &GlobalArgs) -> Result<ExitCode> {
    use jem::viz;
    let ext = args.output.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if ext.as_deref() != Some("png") {
        return Err(Error::Input(format!("{}: viz writes PNG (use a .png name)", args.output.display())));
    }
    if let Some(s) = args.scale {
        if ![1, 2, 4].contains(&s) {
            return Err(Error::param("--scale", s, "1, 2 or 4"));
        }
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
        let sheet = viz::contact_sheet(&args.input, alg, args.scale, args.panel_width)?;
        sheet.canvas.write_png(&args.output)?;
        for (dir, e) in &sheet.skipped {
            eprintln!("warning: {} left out: {e}", dir.display());
        }
        if !global.quiet {
            let names: Vec<String> = sheet.rows.iter().map(|s| jem::batch::scene_name(s)).collect();
            eprintln!("{}: {} rows ({})", args.output.display(), names.len(), names.join(", "));
        }
        return Ok(ExitCode::SUCCESS);
    }
    let disp = jem::io::read_disparity(&args.input)?;
    let calib = viz::calib_range(&args.input.parent().unwrap_or(Path::new(".")).join("calib.txt"));
    let data = viz::finite_range(&disp);
    let vmin = args.vmin.or(calib.map(|c| c.0)).or(data.map(|d| d.0)).unwrap_or(0.0);
    let vmax = args.vmax.or(calib.map(|c| c.1)).or(data.map(|d| d.1)).unwrap_or(1.0);
    let colour = viz::colorize(&disp, vmin, vmax);
    let picture = match &args.gt {
        None => colour,
        Some(gt_path) => {
            let (gt, mask) = viz::load_gt_for(&disp, gt_path)?;
            let scale = args.scale.or_else(|| viz::resolved_scale(gt_path)).unwrap_or(1);
            viz::hstack(&[colour, viz::error_map(&disp, &gt, mask.as_ref(), scale)], 4)
        }
    };
    picture.write_png(&args.output)?;
    if global.verbose && !global.quiet {
        eprintln!("{}: range {vmin}..{vmax}", args.output.display());
    }
    Ok(ExitCode::SUCCESS)
}
