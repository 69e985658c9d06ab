//! What the tests of `drivecheck-dev` share: running it and showing its output.

use std::path::Path;
use std::process::{Command, Output};

/// Runs `drivecheck-dev ARGS` (a `bench …` command) and waits for it.
pub fn drivecheck(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_drivecheck-dev"))
        .args(args)
        .output()
        .expect("the drivecheck-dev binary runs")
}

/// The run's standard output and error, for an assertion's message.
pub fn text(output: &Output) -> String {
    format!(
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// A temporary path as a command-line argument.
pub fn path(p: &Path) -> &str {
    p.to_str().expect("temporary paths are UTF-8")
}
