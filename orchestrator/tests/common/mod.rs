//! What the end-to-end tests of the `drivecheck` binary share: running it and showing its output.

#![allow(dead_code)] // each test file uses its own part

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the `drivecheck` binary with `args` and waits for it.
pub fn drivecheck(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(args)
        .output()
        .expect("the drivecheck binary runs")
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

/// Runs a campaign (`drivecheck run --seed SEED --tests TESTS [extra] --out DIR/campaign`),
/// expects exit status `code`, and returns the run directory.
pub fn campaign(dir: &Path, seed: u64, tests: usize, extra: &[&str], code: i32) -> PathBuf {
    let out_dir = dir.join("campaign");
    let (seed, tests) = (seed.to_string(), tests.to_string());
    let mut args = vec!["run", "--seed", &seed, "--tests", &tests];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", path(&out_dir)]);
    let out = drivecheck(&args);
    assert_eq!(out.status.code(), Some(code), "{}", text(&out));
    out_dir
}
