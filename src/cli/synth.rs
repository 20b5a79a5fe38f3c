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
    /// Render a stereo sequence of N frames instead, laid out as `jem sequence` reads it (left/, right/,
    /// gt/<stem>.pfm, mask/<stem>.png, calib.txt, truth.txt), into a folder that holds no scene or sequence yet.
    #[arg(long, value_name = "N", help_heading = "Sequences")]
    frames: Option<usize>,
    /// With --frames, what moves: static, pan (the camera sideways, 0.1 baseline per frame), dolly (the camera
    /// forward), object (one object, 2 px per frame), cut (another scene from frame N/2).
    #[arg(long, value_name = "MOTION", default_value = "static", requires = "frames", help_heading = "Sequences")]
    motion: jem::synth::Motion,
    /// With --frames, Gaussian sensor noise of σ S grey levels, fresh in each frame and view.
    #[arg(long, value_name = "S", default_value_t = 0.0, requires = "frames", help_heading = "Sequences")]
    noise: f64,
    /// With --frames, each frame's gain drawn within ±P % of 1 (both views alike, seeded): an auto-exposure's
    /// jitter.
    #[arg(long, value_name = "P", default_value_t = 0.0, requires = "frames", help_heading = "Sequences")]
    gain_jitter: f64,
    /// With --frames, the gain × (1 + P/100) from frame K on: an exposure step.
    #[arg(long, value_name = "K:P", requires = "frames", value_parser = parse_step, help_heading = "Sequences")]
    exposure_step: Option<(usize, f64)>,
    #[command(flatten)]
    pub(super) threads: ThreadsArg,
}

/// `K:P` of `--exposure-step`: a frame index and a percentage.
fn parse_step(s: &str) -> std::result::Result<(usize, f64), String> {
    let bad = || format!("{s:?}: expected FRAME:PERCENT, e.g. 4:10");
    let (k, p) = s.split_once(':').ok_or_else(bad)?;
    Ok((k.parse().map_err(|_| bad())?, p.parse().map_err(|_| bad())?))
}

/// Renders and writes one scene.
pub(super) fn run(args: &SynthArgs, global: &GlobalArgs) -> Result<ExitCode> {
    let params = jem::synth::SynthParams { width: args.width, height: args.height, ndisp: args.ndisp, seed: args.seed };
    if let Some(frames) = args.frames {
        let (step_at, step) = args.exposure_step.map_or((0, 0.0), |(k, p)| (k, p / 100.0));
        let gain = jem::synth::GainChange { jitter: args.gain_jitter / 100.0, step, step_at };
        let seq =
            jem::synth::SequenceParams { scene: params, frames, motion: args.motion, noise_sigma: args.noise, gain };
        let stems = jem::synth::write_synth_sequence(&args.outdir, &seq)?;
        if !global.quiet {
            let noise = if args.noise > 0.0 { format!(", noise σ {}", args.noise) } else { String::new() };
            note!(
                "wrote a sequence of {} frames ({}) to {}: {}×{}, ndisp {}{noise}, seed {}",
                stems.len(),
                args.motion.name(),
                args.outdir.display(),
                args.width,
                args.height,
                args.ndisp,
                args.seed
            );
        }
        return Ok(ExitCode::SUCCESS);
    }
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
