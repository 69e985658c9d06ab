//! `drivecheck completions SHELL` and `drivecheck man`: what a shell and `man` need, generated
//! from the command line's own definition ([`crate::cli::Cli`]), so they never disagree with it.

use std::io::Write;
use std::path::Path;

use crate::cli::{CompletionsArgs, ManArgs};
use crate::exit::Exit;
use anyhow::{Context, Result};

/// Prints the completion script of `args.shell` on standard output.
pub fn completions(args: &CompletionsArgs) -> Result<Exit> {
    let mut command = crate::cli::command();
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut command, "drivecheck", &mut script);
    write_stdout(&script)?;
    Ok(Exit::Success)
}

/// Writes the manual pages into `args.out` (every command's), or the main page on standard
/// output.
pub fn man(args: &ManArgs) -> Result<Exit> {
    let command = crate::cli::command();
    match &args.out {
        None => {
            let mut page = Vec::new();
            clap_mangen::Man::new(command).render(&mut page)?;
            write_stdout(&page)?;
        }
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
    let mut page = Vec::new();
    clap_mangen::Man::new(command.clone()).render(&mut page)?;
    let file = dir.join(format!("{name}.1"));
    runner::atomic::write(&file, page)
        .with_context(|| format!("cannot write {}", file.display()))?;
    let mut written = 1;
    for sub in command.get_subcommands().filter(|s| s.get_name() != "help") {
        written += write_pages(sub, &format!("{name}-{}", sub.get_name()), dir)?;
    }
    Ok(written)
}

/// Writes `bytes` to standard output.
fn write_stdout(bytes: &[u8]) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    stdout.write_all(bytes)?;
    stdout.flush()?;
    Ok(())
}
