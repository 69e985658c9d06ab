//! The `drivecheck` command: parses the command line and hands over to the orchestrator library.

use std::io::IsTerminal;
use std::process::ExitCode;

use clap::Parser;
use orchestrator::cli::Cli;
use orchestrator::exit::Exit;

/// mimalloc, not the system's allocator: with `--jobs`, what a test's thread allocates (its
/// recorded messages) is freed on the campaign's thread, where glibc's malloc contends; measured
/// in docs/scaling.md.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    exit_quietly_when_stdout_closes();
    log_as_rust_log_says();
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
    orchestrator::output::set(if cli.quiet {
        orchestrator::output::Verbosity::Quiet
    } else if cli.verbose {
        orchestrator::output::Verbosity::Verbose
    } else {
        orchestrator::output::Verbosity::Normal
    });
    let exit = match orchestrator::commands::run(cli) {
        Ok(exit) => exit,
        Err(error) => {
            eprintln!("error: {}", orchestrator::output::describe(&error));
            Exit::Error
        }
    };
    orchestrator::commands::bench_scale::record_peak_memory();
    exit.into()
}

/// Diagnostics (`tracing`: the car link's events, the runner's steps) go to standard error as
/// `RUST_LOG` selects them (`RUST_LOG=debug`, `RUST_LOG=orchestrator=debug,car_link=info`). Without
/// it nothing is logged, so what drivecheck prints is what its commands print.
fn log_as_rust_log_says() {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    const RUST_LOG: &str = "RUST_LOG";
    let Some(value) = std::env::var_os(RUST_LOG).filter(|v| !v.is_empty()) else {
        return;
    };
    let filter = match value
        .to_str()
        .map(str::parse::<tracing_subscriber::filter::Targets>)
    {
        Some(Ok(filter)) => filter,
        Some(Err(error)) => {
            eprintln!("warning: {RUST_LOG} ignored: {error}");
            return;
        }
        None => {
            eprintln!("warning: {RUST_LOG} ignored: it is not UTF-8");
            return;
        }
    };
    let format = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal());
    // The only subscriber of the process, set before anything logs: this cannot fail.
    let _ = tracing_subscriber::registry()
        .with(format)
        .with(filter)
        .try_init();
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
