//! `drivecheck-dev`: drivecheck's development tools, kept out of the `drivecheck` binary a user
//! installs. `bench …` measures drivecheck's own speed and its simulated car's fidelity (run it
//! with `cargo run --release -p drivecheck-dev -- bench …`); `exec …` runs a `drivecheck`
//! command in this process, exactly as the `drivecheck` binary would, and can record the
//! process's peak memory (`bench scale` measures every step so).

mod bench;
mod cli;

use std::process::ExitCode;

use clap::Parser;
use orchestrator::exit::Exit;

use cli::{BenchCommand, Command, DevCli};

/// The allocator of the `drivecheck` binary, so that what is measured here is what it does.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    let cli = match DevCli::try_parse() {
        Ok(cli) => cli,
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
    let exit = match cli.command {
        Command::Exec(args) => {
            let exit = orchestrator::process::main(
                std::iter::once(std::ffi::OsString::from("drivecheck")).chain(args.args),
            );
            bench::scale::record_peak_memory();
            return exit.into();
        }
        Command::Bench(command) => bench(command),
    };
    match exit {
        Ok(exit) => exit,
        Err(error) => {
            eprintln!("error: {}", orchestrator::output::describe(&error));
            Exit::Error
        }
    }
    .into()
}

fn bench(command: BenchCommand) -> anyhow::Result<Exit> {
    match command {
        BenchCommand::Generator(args) => bench::generator::generator(&args),
        BenchCommand::Recovery(args) => bench::recovery::run(&args),
        BenchCommand::Fidelity(args) => bench::fidelity::run(&args),
        BenchCommand::Placement(args) => bench::placement::run(&args),
        BenchCommand::Scale(args) => bench::scale::run(&args),
        BenchCommand::Compare(args) => bench::compare::run(&args),
        BenchCommand::KillResume(args) => bench::kill_resume::run(&args),
        BenchCommand::Agreement(args) => bench::agreement::run(&args),
        BenchCommand::TwinReach(args) => bench::twin_reach::run(&args),
    }
}
