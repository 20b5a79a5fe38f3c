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
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Match one pair (the same as `jem LEFT RIGHT -o OUT`).
    Match(MatchArgs),
    /// Print the effective configuration (defaults ← --config ← --set) as TOML.
    Config(ConfigArgs),
    /// Render a synthetic scene with exact ground truth in MiddEval3 layout.
    Synth(SynthArgs),
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
}

impl ConfigArgs {
    fn params(&self) -> Result<Params> {
        Params::load(self.config.as_deref(), &self.overrides)
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
    let (l, r) = rayon::join(|| jem::io::png::load_rgb(left), || jem::io::png::load_rgb(right));
    let (l, r) = (l?, r?);
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
