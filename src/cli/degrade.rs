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
    /// The new folder to write (must not exist, or be empty; never inside SRC). With --frames: a folder that
    /// holds no scene or sequence yet.
    out: PathBuf,
    /// What to do: noise:SIGMA, lowlight:GAIN:READ_SIGMA, exposure:GAIN:GAMMA (right view), blur:SIGMA,
    /// misalign:SHIFT:DEGREES (right view), jpeg:QUALITY, or several joined by `+` (each explained in --help);
    /// none leaves the images as they are.
    #[arg(long, value_name = "RECIPE")]
    recipe: Recipe,
    /// Random seed: the same seed gives byte-identical files.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Write a stereo sequence of N frames instead (SRC: one scene folder): each frame degraded with its own
    /// seed (fresh noise), OUT laid out as `jem sequence` reads it (left/, right/, gt/, mask/, calib.txt).
    #[arg(long, value_name = "N")]
    frames: Option<usize>,
    /// With --frames: the view moves PX columns right per frame (a window of the pair sliding across it: a
    /// panning camera with exact ground truth); 0 = a static camera.
    #[arg(long, value_name = "PX", default_value_t = 0, requires = "frames")]
    pan: usize,
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
}

/// Degrades the tree and says what was written.
pub(super) fn run(args: &DegradeArgs, global: &GlobalArgs) -> Result<ExitCode> {
    if let Some(frames) = args.frames {
        let how = jem::sequence::FromScene { frames, recipe: args.recipe.clone(), seed: args.seed, pan_px: args.pan };
        let n = jem::sequence::sequence_from_scene(&args.src, &args.out, &how)?;
        if !global.quiet {
            let pan = if args.pan > 0 { format!(", panning {} px per frame", args.pan) } else { String::new() };
            note!(
                "wrote a sequence of {n} frames to {} ({}, seed {}{pan})",
                args.out.display(),
                args.recipe,
                args.seed
            );
        }
        return Ok(ExitCode::SUCCESS);
    }
    let scenes = jem::degrade::degrade_tree(&args.src, &args.out, &args.recipe, args.seed)?;
    if !global.quiet {
        note!("wrote {} scene(s) under {} ({}, seed {})", scenes.len(), args.out.display(), args.recipe, args.seed);
    }
    Ok(ExitCode::SUCCESS)
}
