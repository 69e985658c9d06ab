//! The process around a command: how `drivecheck` starts (standard output closing, the command
//! line parsed, the verbosity set, `RUST_LOG`) and ends (its status, an error printed). The
//! `drivecheck` binary is [`main`] and nothing else; the development tools (`drivecheck-dev exec`)
//! run a command through the same function.

use std::ffi::OsString;
use std::io::IsTerminal;

use crate::exit::Exit;

/// Runs the command line `args` (the program's name first) as the `drivecheck` binary does and
/// returns its exit status: a command line that does not parse prints clap's message (`--help`
/// and `--version` are not errors), an error prints `error: …` with its causes.
pub fn main<I, T>(args: I) -> Exit
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    exit_quietly_when_stdout_closes();
    let cli = match crate::cli::parse_from(args) {
        Ok(cli) => cli,
        Err(error) => {
            let _ = error.print();
            return if error.use_stderr() {
                Exit::Error
            } else {
                Exit::Success
            };
        }
    };
    crate::output::set(if cli.quiet {
        crate::output::Verbosity::Quiet
    } else if cli.verbose {
        crate::output::Verbosity::Verbose
    } else {
        crate::output::Verbosity::Normal
    });
    // After the verbosity: a `RUST_LOG` that cannot be read is a warning (not with `-q`).
    log_as_rust_log_says();
    // Before the command: a signal ends any command as `interrupted` says, or as it handles it.
    crate::commands::signals::listen_for_the_process();
    match crate::commands::run(cli) {
        Ok(exit) => exit,
        Err(error) => {
            eprintln!("error: {}", crate::output::describe(&error));
            Exit::Error
        }
    }
}

/// Ends the process for the signal `signal` (its name, `interrupted (SIGINT)`) while no command
/// handles signals (a command that reads and writes files: `report`, `runs merge`, `explain`, …;
/// `commands::signals`): its scratch files removed (`runner::scratch::remove_all`: what it was
/// writing is not left half written), `error: interrupted (SIGINT): …` said, status 2 as every
/// command interrupted by a signal ([`Exit::Error`]).
pub(crate) fn interrupted(signal: &str) -> ! {
    let _held = runner::scratch::remove_all();
    eprintln!("error: {signal}: stopped before its end; nothing it was writing was left behind");
    Exit::Error.exit()
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
            crate::output::warning(format_args!("{RUST_LOG} ignored: {error}"));
            return;
        }
        None => {
            crate::output::warning(format_args!("{RUST_LOG} ignored: it is not UTF-8"));
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
