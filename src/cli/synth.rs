//! `jem synth`: renders a synthetic scene with exact ground truth ([`jem::synth`]) and writes it in MiddEval3
//! layout.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use jem::Result;

use super::{GlobalArgs, ThreadsArg};

/// Arguments of `jem synth` (the help text is on [`Command::Synth`](super::Command::Synth)).
#[derive(Args, Debug, Clone)]
pub(super) struct SynthArgs {
    /// Folder to write the scene into (created if missing; one that already holds a scene is refused).
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
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
}

/// Renders and writes one scene.
pub(super) fn run(args: &SynthArgs, global: &GlobalArgs) -> Result<ExitCode> {
    let params = jem::synth::SynthParams { width: args.width, height: args.height, ndisp: args.ndisp, seed: args.seed };
    // Before rendering: a folder that holds a scene is refused.
    jem::synth::check_scene_folder(&args.outdir)?;
    let scene = jem::synth::render_scene(&params)?;
    jem::synth::write_scene(&args.outdir, &scene)?;
    if !global.quiet {
        note!(
            "wrote {}/{{im0.png,im1.png,calib.txt,disp0GT.pfm,mask0nocc.png}}: {}×{}, ndisp {}, disparities {}..{}, \
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
