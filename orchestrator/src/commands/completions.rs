//! `drivecheck completions SHELL` and `drivecheck man`: what a shell and `man` need, generated
//! from the command line's own definition ([`crate::cli::Cli`]), so they never disagree with it.

use std::io::Write;
use std::path::Path;

use crate::cli::{CompletionsArgs, ManArgs};
use crate::exit::Exit;
use anyhow::{Context, Result};
use clap_complete::Shell;

/// Prints the completion script of `args.shell` on standard output: every command and option,
/// and for a scenario (`--scenario`, `area validate SCENARIO`, …) the bundled scenarios' names as
/// well as files (bash and fish; zsh offers the names, and a path is typed as it is).
pub fn completions(args: &CompletionsArgs) -> Result<Exit> {
    let names = scenarios::bundled::names();
    let mut command = offer_bundled(crate::cli::command(), names);
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut command, "drivecheck", &mut script);
    let script = String::from_utf8(script)?;
    // clap_complete offers either the possible values or files; a scenario is either.
    let listed = names.join(" ");
    let script = match args.shell {
        Shell::Bash => script.replace(
            &format!("COMPREPLY=($(compgen -W \"{listed}\" -- \"${{cur}}\"))"),
            &format!(
                "COMPREPLY=($(compgen -W \"{listed}\" -- \"${{cur}}\") $(compgen -f -- \"${{cur}}\"))"
            ),
        ),
        // fish lists the values a line each (`-a "courtyard\t''⏎cutouts-four…"`); -F adds files.
        Shell::Fish => match names.first() {
            Some(first) => script.replace(
                &format!("-r -f -a \"{first}\\t"),
                &format!("-r -F -a \"{first}\\t"),
            ),
            None => script,
        },
        _ => script,
    };
    write_stdout(script.as_bytes())?;
    Ok(Exit::Success)
}

/// `command` with the bundled scenarios' `names` as the possible values of every scenario
/// argument (`scenario`, or the value name `SCENARIO`), for the completion scripts only: the command line itself
/// takes a file as well.
fn offer_bundled(mut command: clap::Command, names: &[&'static str]) -> clap::Command {
    let scenario_args: Vec<String> = command
        .get_arguments()
        .filter(|a| {
            a.get_id() == "scenario"
                || a.get_value_names()
                    .is_some_and(|v| v.iter().any(|n| n.as_str() == "SCENARIO"))
        })
        .map(|a| a.get_id().to_string())
        .collect();
    for id in scenario_args {
        let names = names.to_vec();
        command = command.mut_arg(id, |a| {
            a.value_parser(clap::builder::PossibleValuesParser::new(names))
        });
    }
    let subcommands: Vec<String> = command
        .get_subcommands()
        .map(|s| s.get_name().to_owned())
        .collect();
    for name in subcommands {
        command = command.mut_subcommand(name, |s| offer_bundled(s, names));
    }
    command
}

/// Writes the manual pages into `args.out` (every command's), or the main page on standard
/// output.
pub fn man(args: &ManArgs) -> Result<Exit> {
    let command = crate::cli::command();
    match &args.out {
        None => write_stdout(&page(&command, true)?)?,
        Some(dir) => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            let written = write_pages(&command, "drivecheck", dir)?;
            crate::output::note(format_args!("{written} manual pages in {}", dir.display()));
        }
    }
    Ok(Exit::Success)
}

/// Writes the page of `command` (named `name`, as `man` knows it) and of each of its
/// subcommands into `dir`; returns how many pages were written.
fn write_pages(command: &clap::Command, name: &str, dir: &Path) -> Result<usize> {
    // The page's title and name (`drivecheck-run`) and its synopsis (`drivecheck run …`).
    let command = command
        .clone()
        .display_name(name.to_owned())
        .bin_name(name.replace('-', " "));
    let file = dir.join(format!("{name}.1"));
    runner::atomic::write(&file, page(&command, name == "drivecheck")?)
        .with_context(|| format!("cannot write {}", file.display()))?;
    let mut written = 1;
    for sub in command.get_subcommands().filter(|s| s.get_name() != "help") {
        written += write_pages(sub, &format!("{name}-{}", sub.get_name()), dir)?;
    }
    Ok(written)
}

/// What the environment changes, for the main page's ENVIRONMENT section.
const ENVIRONMENT: [(&str, &str); 3] = [
    (
        "DRIVECHECK_RUNS_DIR",
        "Where run directories go when no --out is given (default: runs).",
    ),
    (
        "DRIVECHECK_SITL_CACHE",
        "Where firmware trees built for the host are kept (default: \
         $XDG_CACHE_HOME/drivecheck/sitl, else ~/.cache/drivecheck/sitl).",
    ),
    (
        "RUST_LOG",
        "Diagnostics on standard error, as tracing's targets select them (RUST_LOG=debug, \
         RUST_LOG=car_link=info); without it nothing is logged.",
    ),
];

/// The manual page of `command`: clap_mangen's sections without its `help` subcommand (there is
/// no drivecheck-help page) or its EXTRA section, and for the main page (`main`) the exit
/// statuses and the environment in sections of their own.
fn page(command: &clap::Command, main: bool) -> Result<Vec<u8>> {
    let command = command
        .clone()
        .disable_help_subcommand(true)
        .after_help(None::<&str>);
    let man = clap_mangen::Man::new(command.clone());
    let mut page = Vec::new();
    man.render_title(&mut page)?;
    man.render_name_section(&mut page)?;
    man.render_synopsis_section(&mut page)?;
    man.render_description_section(&mut page)?;
    if command.get_arguments().any(|a| !a.is_hide_set()) {
        man.render_options_section(&mut page)?;
    }
    if command.get_subcommands().any(|s| !s.is_hide_set()) {
        man.render_subcommands_section(&mut page)?;
    }
    if main {
        use roff::{Roff, bold, roman};
        let mut sections = Roff::new();
        sections.control("SH", ["EXIT STATUS"]);
        for exit in Exit::ALL {
            sections.control("TP", []);
            sections.text([bold(exit.code().to_string())]);
            sections.text([roman(exit.meaning())]);
        }
        sections.control("SH", ["ENVIRONMENT"]);
        for (name, what) in ENVIRONMENT {
            sections.control("TP", []);
            sections.text([bold(name)]);
            sections.text([roman(what)]);
        }
        sections.to_writer(&mut page)?;
    }
    if command.get_version().is_some() || command.get_long_version().is_some() {
        man.render_version_section(&mut page)?;
    }
    Ok(page)
}

/// Writes `bytes` to standard output; when its reader went away (`drivecheck man | head`), ends
/// quietly with status 141 as `println!` does (`crate::process`).
fn write_stdout(bytes: &[u8]) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    match stdout.write_all(bytes).and_then(|()| stdout.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Exit::ClosedStdout.exit(),
        written => Ok(written?),
    }
}
