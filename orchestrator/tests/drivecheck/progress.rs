//! What a campaign prints where nobody watches a terminal (the tests' standard error is a pipe,
//! as in CI or behind `| tee`): a line per test, status lines above 100 tests, and with `-q` only
//! the summary.

use crate::common;

use common::{drivecheck, path, text};

fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn stdout(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn a_small_campaign_prints_a_line_per_test_and_no_bundled_warnings() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("run");
    let out = drivecheck(&[
        "run",
        "--seed",
        "3",
        "--tests",
        "3",
        "--out",
        path(&out_dir),
    ]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    let err = stderr(&out);
    for k in 0..3 {
        assert!(err.contains(&format!("test {k}: ")), "{err}");
    }
    assert!(err.contains("(3/3 done, "), "{err}");
    assert!(
        !err.contains("warning:"),
        "a bundled scenario's drawing warnings are for -v and scenario check: {err}"
    );
    assert!(
        !err.contains("preflight:"),
        "the simulator's factory configuration is the same on every run: {err}"
    );
    assert!(
        stdout(&out).contains("| test | verdict |"),
        "{}",
        text(&out)
    );
}

#[test]
fn quiet_prints_only_the_summary_and_verbose_the_warnings_too() {
    let dir = tempfile::tempdir().unwrap();
    let quiet = drivecheck(&[
        "run",
        "-q",
        "--seed",
        "3",
        "--tests",
        "3",
        "--out",
        path(&dir.path().join("q")),
    ]);
    assert!(
        matches!(quiet.status.code(), Some(0 | 1)),
        "{}",
        text(&quiet)
    );
    assert_eq!(stderr(&quiet), "", "{}", text(&quiet));
    let summary = stdout(&quiet);
    assert!(summary.starts_with("tests 3, passed "), "{summary}");
    assert!(
        !summary.contains("| test |") && !summary.contains("why test"),
        "{summary}"
    );
    assert!(summary.contains("run directory: "), "{summary}");
    let verbose = drivecheck(&[
        "run",
        "--verbose",
        "--seed",
        "3",
        "--tests",
        "3",
        "--out",
        path(&dir.path().join("v")),
    ]);
    assert!(
        stderr(&verbose).contains("warning: bundled:"),
        "{}",
        text(&verbose)
    );
    assert!(
        stderr(&verbose).contains("preflight: switched off ApRepeatRoutes (was 1)"),
        "{}",
        text(&verbose)
    );
    let both = drivecheck(&["run", "-q", "-v", "--tests", "1"]);
    assert_eq!(both.status.code(), Some(2), "{}", text(&both));
}

#[test]
fn a_large_campaign_prints_status_lines_and_the_tests_that_did_not_pass() {
    let dir = tempfile::tempdir().unwrap();
    let out = drivecheck(&[
        "run",
        "--seed",
        "3",
        "--tests",
        "120",
        "--record",
        "none",
        "--out",
        path(&dir.path().join("run")),
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let err = stderr(&out);
    let status: Vec<&str> = err.lines().filter(|l| l.contains(" tests (")).collect();
    assert!(
        status.len() >= 2 && status.len() <= 101,
        "a status line at every 1 % or 10 s: {err}"
    );
    assert!(
        status.last().unwrap().starts_with("120/120 tests (100 %)"),
        "{err}"
    );
    assert!(
        err.contains(": failed"),
        "every failing test is named: {err}"
    );
    assert!(
        !err.contains(": passed"),
        "no line for a passing test: {err}"
    );
    let table = stdout(&out);
    assert!(
        table.contains("passing tests not listed: -v lists every test"),
        "{table}"
    );
    assert!(!table.contains("| passed |"), "{table}");
}
