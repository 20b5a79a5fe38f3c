//! The `jem` command: parses arguments, calls the library, prints errors, picks the exit code.

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let raw = cli::global_flags_after_subcommand(std::env::args_os().collect());
    let args = match cli::Cli::try_parse_from(&raw) {
        Ok(args) => args,
        Err(e) => return cli::usage_error(e, &raw),
    };
    match cli::run(args) {
        Ok(code) => code,
        Err(err) => {
            cli::print_error(&err);
            ExitCode::from(2)
        }
    }
}
