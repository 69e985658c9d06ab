//! The `drivecheck` command: parses the command line and hands over to the orchestrator library.

use std::process::ExitCode;

use clap::Parser;
use orchestrator::cli::Cli;

fn main() -> ExitCode {
    let cli = Cli::parse();
    match orchestrator::commands::run(cli) {
        Ok(code) => code,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::from(2)
        }
    }
}
