//! `RUST_LOG` turns on the `tracing` diagnostics on standard error; without it drivecheck prints
//! only what its commands print.

use std::path::Path;
use std::process::{Command, Output};

/// `drivecheck run --seed 1 --tests 1 --out OUT`, with `RUST_LOG` as given (unset for `None`).
fn run(out: &Path, rust_log: Option<&str>) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_drivecheck"));
    command
        .args(["run", "--seed", "1", "--tests", "1", "--out"])
        .arg(out);
    match rust_log {
        Some(filter) => command.env("RUST_LOG", filter),
        None => command.env_remove("RUST_LOG"),
    };
    let output = command.output().expect("the drivecheck binary runs");
    assert!(
        matches!(output.status.code(), Some(0 | 1)),
        "stderr: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// A line of tracing-subscriber's formatter: a timestamp, then the level.
fn is_log_line(line: &str) -> bool {
    line.split_whitespace()
        .nth(1)
        .is_some_and(|level| ["TRACE", "DEBUG", "INFO", "WARN", "ERROR"].contains(&level))
}

/// Standard error's lines that are not log lines, with the run directory named alike.
fn messages(output: &Output, out: &Path) -> Vec<String> {
    String::from_utf8_lossy(&output.stderr)
        .lines()
        .filter(|line| !is_log_line(line))
        .map(|line| line.replace(out.to_str().expect("UTF-8 path"), "OUT"))
        .collect()
}

/// Standard output without the summary's wall time (which differs from run to run), with the
/// run directory named alike.
fn without_wall_time(stdout: &[u8], out: &Path) -> Vec<String> {
    String::from_utf8_lossy(stdout)
        .lines()
        .map(|line| match line.rsplit_once("; ") {
            Some((summary, wall)) if wall.ends_with("wall time") => summary.to_owned(),
            _ => line.to_owned(),
        })
        .map(|line| line.replace(out.to_str().expect("UTF-8 path"), "OUT"))
        .collect()
}

#[test]
fn rust_log_debug_prints_the_runners_and_the_links_diagnostics_and_nothing_else_changes() {
    let dir = tempfile::tempdir().unwrap();
    let (quiet_dir, debug_dir) = (dir.path().join("quiet"), dir.path().join("debug"));

    let quiet = run(&quiet_dir, None);
    let stderr = String::from_utf8_lossy(&quiet.stderr);
    assert!(
        !stderr.lines().any(is_log_line),
        "no diagnostics without RUST_LOG: {stderr}"
    );

    let debug = run(&debug_dir, Some("debug"));
    let stderr = String::from_utf8_lossy(&debug.stderr);
    let logged: Vec<&str> = stderr.lines().filter(|l| is_log_line(l)).collect();
    for expected in [
        "test planned",
        "car reset",
        "test driven",
        "connected to the car",
    ] {
        assert!(
            logged.iter().any(|l| l.contains(expected)),
            "a DEBUG/INFO line with {expected:?}: {stderr}"
        );
    }
    assert_eq!(debug.status.code(), quiet.status.code());
    assert_eq!(
        without_wall_time(&debug.stdout, &debug_dir),
        without_wall_time(&quiet.stdout, &quiet_dir),
        "standard output is the same"
    );
    assert_eq!(
        messages(&debug, &debug_dir),
        messages(&quiet, &quiet_dir),
        "the command's own messages are the same"
    );
}

#[test]
fn a_bad_rust_log_is_reported_and_ignored() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let output = run(&out, Some("orchestrator=notalevel"));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("warning: RUST_LOG ignored"), "{stderr}");
    assert!(!stderr.lines().any(is_log_line), "{stderr}");
}
