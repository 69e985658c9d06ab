//! The `drivecheck` command: parses the command line and hands over to the orchestrator library.

use std::process::ExitCode;

use clap::Parser;
use orchestrator::cli::Cli;

fn main() -> ExitCode {
    exit_quietly_when_stdout_closes();
    let cli = Cli::parse();
    match orchestrator::commands::run(cli) {
        Ok(code) => code,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::from(2)
        }
    }
}

/// The status of a Unix tool killed by SIGPIPE (128 + 13), which is what `drivecheck … | head`
/// reports when `head` has read enough.
const CLOSED_STDOUT_STATUS: i32 = 141;

/// `drivecheck runs | head`: when the reader of standard output goes away, ends the process as a
/// Unix tool ends then, quietly with status 141, instead of with a panic message. Rust ignores
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
            std::process::exit(CLOSED_STDOUT_STATUS);
        }
        default(info);
    }));
}
