//! The `drivecheck` command: hands its command line over to the orchestrator library
//! ([`orchestrator::process::main`]).

use std::process::ExitCode;

/// mimalloc, not the system's allocator: with `--jobs`, what a test's thread allocates (its
/// recorded messages) is freed on the campaign's thread, where glibc's malloc contends; measured
/// in docs/scaling.md.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> ExitCode {
    orchestrator::process::main(std::env::args_os()).into()
}
