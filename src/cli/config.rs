//! `jem config`, and the configuration flags that `jem match` and `jem batch` share ([`ConfigArgs`]): the
//! defaults, `--config FILE`, `--set KEY=VALUE` and `--downscale N` merged, in that order, into one validated
//! [`Params`].

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use jem::{Error, Params, Result};

/// Which parameters to use.
#[derive(Args, Debug, Clone, Default)]
pub(super) struct ConfigArgs {
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
    /// The defaults, overridden by the --config file, then each --set, then --downscale; validated.
    pub(super) fn params(&self) -> Result<Params> {
        let mut overrides = self.overrides.clone();
        if let Some(text) = &self.downscale {
            overrides.push(format!("downscale={}", parse_downscale(text)?));
        }
        Params::load(self.config.as_deref(), &overrides)
    }
}

impl ConfigArgs {
    /// What the configuration is made of: `built-in defaults ← fast.toml ← 2 --set ← --downscale 2`.
    fn describe(&self) -> String {
        let mut parts = vec!["built-in defaults".to_string()];
        if let Some(c) = &self.config {
            parts.push(c.display().to_string());
        }
        match self.overrides.len() {
            0 => {}
            1 => parts.push("1 --set".into()),
            n => parts.push(format!("{n} --set")),
        }
        if let Some(d) = &self.downscale {
            parts.push(format!("--downscale {}", d.trim()));
        }
        parts.join(" ← ")
    }
}

/// The `--downscale` value: an integer ≥ 1 (parsed here rather than by clap, for a one-line error).
fn parse_downscale(text: &str) -> Result<usize> {
    match text.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(Error::param("--downscale", format!("{text:?}"), "an integer >= 1; 1 = full resolution")),
    }
}

/// Prints the effective configuration as TOML (stdout), then what it was made of (stderr).
pub(super) fn run(args: &ConfigArgs, global: &super::GlobalArgs) -> Result<ExitCode> {
    out!("{}", args.params()?.to_toml());
    if !global.quiet {
        note!("printed the effective configuration: {}", args.describe());
    }
    Ok(ExitCode::SUCCESS)
}
