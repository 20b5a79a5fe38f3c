//! `jem degrade`: a seeded, degraded copy of a MiddEval3-style tree ([`jem::degrade`]), the measuring stick for
//! robustness.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use jem::Result;
use jem::degrade::Recipe;

use super::{GlobalArgs, ThreadsArg};

/// Arguments of `jem degrade` (the help text is on [`Command::Degrade`](super::Command::Degrade)).
#[derive(Args, Debug, Clone)]
pub(super) struct DegradeArgs {
    /// A scene folder or a tree of scenes (each with im0.png, im1.png, calib.txt).
    src: PathBuf,
    /// The new folder to write (must not exist, or be empty; never inside SRC).
    out: PathBuf,
    /// What to do: noise:SIGMA, lowlight:GAIN:READ_SIGMA, exposure:GAIN:GAMMA (right view), blur:SIGMA,
    /// misalign:SHIFT:DEGREES (right view), jpeg:QUALITY, or several joined by `+` (each explained in --help).
    #[arg(long, value_name = "RECIPE")]
    recipe: Recipe,
    /// Random seed: the same seed gives byte-identical files.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
}

/// Degrades the tree and says what was written.
pub(super) fn run(args: &DegradeArgs, global: &GlobalArgs) -> Result<ExitCode> {
    let scenes = jem::degrade::degrade_tree(&args.src, &args.out, &args.recipe, args.seed)?;
    if !global.quiet {
        note!("wrote {} scene(s) under {} ({}, seed {})", scenes.len(), args.out.display(), args.recipe, args.seed);
    }
    Ok(ExitCode::SUCCESS)
}
