//! The `drivecheck` command: parses the command line and hands over to the orchestrator library.

use std::process::ExitCode;

use clap::Parser;
use orchestrator::cli::Cli;
use orchestrator::exit::Exit;

fn main() -> ExitCode {
    exit_quietly_when_stdout_closes();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        // `--help` and `--version` are not errors; a command line that does not parse is.
        Err(error) => {
            let _ = error.print();
            return if error.use_stderr() {
                Exit::Error
            } else {
                Exit::Success
            }
            .into();
        }
    };
    match orchestrator::commands::run(cli) {
        Ok(exit) => exit.into(),
        Err(error) => {
            eprintln!("error: {error:#}");
            Exit::Error.into()
        }
    }
}

/// `drivecheck runs | head`: when the reader of standard output goes away, ends the process as a
/// Unix tool ends then, quietly with status 141 ([`Exit::ClosedStdout`]), instead of with a panic
/// message. Rust ignores
/// SIGPIPE, so `println!` panics with "Broken pipe" instead. Nothing is cut short by exiting: the
/// commands write to standard output only after their work is done (a campaign prints its table
/// after the car has stopped and the run directory is complete).
fn exit_quietly_when_stdout_closes() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let message = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or_default();
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            Exit::ClosedStdout.exit();
        }
        default(info);
    }));
}
