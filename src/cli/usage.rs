//! What `jem` says when its command line cannot be parsed and clap's own message would mislead: a bare `jem` (the
//! usage and the list of commands, where clap names three "required arguments"), and a third path after the two
//! images (`jem L R disp.pfm`: clap reads it as an unknown subcommand; it is an output without its `-o`).

use std::ffi::OsString;

use clap::CommandFactory;

use super::Cli;

/// The extensions a stray path must have to be taken for a forgotten `-o`: those of a disparity map.
const OUTPUT_EXTENSIONS: [&str; 3] = ["pfm", "exr", "png"];

/// The positional arguments of a match command line (`jem …` or `jem match …`): every token that is not a flag or
/// a flag's value, in order. `None` when the line names another subcommand (its own parser speaks for it) or holds
/// a token that is not UTF-8.
fn match_positionals(args: &[OsString]) -> Option<Vec<String>> {
    let command = Cli::command();
    let takes_value = |token: &str| {
        command.get_arguments().any(|a| {
            let long = token.strip_prefix("--").is_some_and(|l| a.get_long() == Some(l));
            let short = token.strip_prefix('-').is_some_and(|s| s.len() == 1 && a.get_short() == s.chars().next());
            (long || short) && a.get_action().takes_values()
        })
    };
    let mut positionals = Vec::new();
    let mut tokens = args.iter().skip(1);
    while let Some(token) = tokens.next() {
        let token = token.to_str()?;
        if token.starts_with('-') && token.len() > 1 {
            if !token.contains('=') && takes_value(token) {
                tokens.next();
            }
            continue;
        }
        if positionals.is_empty() && command.get_subcommands().any(|c| c.get_name() == token) {
            if token != "match" {
                return None;
            }
            continue;
        }
        positionals.push(token.to_string());
    }
    Some(positionals)
}

/// The message for a path given where no third path is taken, when the line is a match with more than two
/// positional arguments: "did you mean -o PATH?" for one that looks like a disparity map and no `-o` given.
pub(super) fn stray_output(args: &[OsString]) -> Option<String> {
    let positionals = match_positionals(args)?;
    let stray = positionals.get(2)?;
    let has_output = args.iter().any(|a| a == "-o" || a == "--output" || a.to_string_lossy().starts_with("--output="));
    let extension = std::path::Path::new(stray).extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let looks_like_output = extension.is_some_and(|e| OUTPUT_EXTENSIONS.contains(&e.as_str()));
    Some(if looks_like_output && !has_output {
        format!("error: unexpected argument '{stray}' after the two images: did you mean -o {stray}?")
    } else {
        format!(
            "error: unexpected argument '{stray}': a match takes two images (LEFT RIGHT); every output is named by its \
             flag (-o, --confidence, --depth, --cloud, ...)"
        )
    })
}

/// Whether the line is a match with no image given at all (a bare `jem`, or `jem -v`): then the usage is what
/// helps, not the list of missing arguments.
pub(super) fn is_bare(args: &[OsString]) -> bool {
    match_positionals(args).is_some_and(|p| p.is_empty()) && !args.iter().skip(1).any(|a| a == "match")
}

/// The usage of `jem` and its commands, one line each (their help's first line).
pub(super) fn usage() -> String {
    let command = Cli::command();
    let commands: Vec<(String, String)> = command
        .get_subcommands()
        .map(|c| (c.get_name().to_string(), c.get_about().map(|a| a.to_string()).unwrap_or_default()))
        .collect();
    let width = commands.iter().map(|(n, _)| n.len()).max().unwrap_or(0);
    let mut text = String::from(
        "usage: jem LEFT RIGHT -o OUT [OPTIONS]    match a rectified pair, writing its disparity map\n       \
         jem COMMAND ...\n\ncommands:\n",
    );
    for (name, about) in commands {
        text.push_str(&format!("  {name:<width$}  {about}\n"));
    }
    text.push_str("\n`jem --help` and `jem COMMAND --help` list every flag.");
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(args: &[&str]) -> Vec<OsString> {
        std::iter::once("jem").chain(args.iter().copied()).map(OsString::from).collect()
    }

    #[test]
    fn a_third_path_that_looks_like_an_output_suggests_its_flag() {
        let message = stray_output(&line(&["l.png", "r.png", "disp.pfm"])).unwrap();
        assert!(message.contains("did you mean -o disp.pfm?"), "{message}");
        let message = stray_output(&line(&["match", "--ndisp", "64", "l.png", "r.png", "d.PNG", "-v"])).unwrap();
        assert!(message.contains("did you mean -o d.PNG?"), "{message}");
        // With -o given, or a path that is no disparity map, there is no output to suggest.
        let message = stray_output(&line(&["l.png", "r.png", "-o", "d.pfm", "c.pfm"])).unwrap();
        assert!(!message.contains("did you mean") && message.contains("named by its flag"), "{message}");
        assert!(!stray_output(&line(&["l.png", "r.png", "notes.txt"])).unwrap().contains("did you mean"));
        // Two paths, or another subcommand: nothing to say here.
        assert_eq!(stray_output(&line(&["l.png", "r.png", "--ndisp", "64"])), None);
        assert_eq!(stray_output(&line(&["eval", "a", "b", "c.pfm"])), None);
    }

    #[test]
    fn a_bare_jem_gets_the_usage_and_every_command() {
        assert!(is_bare(&line(&[])) && is_bare(&line(&["-v"])) && is_bare(&line(&["--ndisp", "64"])));
        assert!(!is_bare(&line(&["l.png"])) && !is_bare(&line(&["match"])) && !is_bare(&line(&["eval"])));
        let text = usage();
        assert!(text.starts_with("usage: jem LEFT RIGHT -o OUT"), "{text}");
        for command in Cli::command().get_subcommands() {
            assert!(text.contains(&format!("\n  {} ", command.get_name())), "{} missing: {text}", command.get_name());
        }
    }
}
