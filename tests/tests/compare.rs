//! `drivecheck compare` end to end on the embedded simulated car in virtual time: campaigns run
//! and compared through the command line's own parser and dispatcher (`orchestrator::commands`),
//! the comparison read through `orchestrator::commands::compare::compare_dirs`.

use std::path::Path;

use campaign::compare::{PairError, Significance};
use clap::Parser;
use orchestrator::cli::Cli;
use orchestrator::commands::compare::compare_dirs;
use orchestrator::exit::Exit;

/// Runs `drivecheck args` in this process; its exit status.
fn drivecheck(args: &[&str]) -> Exit {
    let cli = Cli::try_parse_from(std::iter::once("drivecheck").chain(args.iter().copied()))
        .expect("the command line parses");
    orchestrator::commands::run(cli).unwrap_or_else(|e| panic!("drivecheck {args:?}: {e:#}"))
}

fn path(p: &Path) -> &str {
    p.to_str().expect("a UTF-8 path")
}

/// A campaign of `tests` tests with `seed`, on the default car or the car `profile`.
fn campaign(out: &Path, seed: &str, tests: &str, profile: Option<&Path>) {
    let mut args = vec![
        "-q",
        "run",
        "--seed",
        seed,
        "--tests",
        tests,
        "--out",
        path(out),
    ];
    if let Some(p) = profile {
        args.extend(["--profile", path(p)]);
    }
    let exit = drivecheck(&args);
    assert!(matches!(exit, Exit::Success | Exit::Found), "{exit:?}");
}

#[test]
fn the_same_seed_twice_is_no_difference_even_when_failing_on_regression() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    campaign(&a, "11", "20", None);
    campaign(&b, "11", "20", None);
    let compared = compare_dirs(&a, &b, None, None, 0.05, 0).unwrap();
    let r = &compared.report;
    assert_eq!(r.significance, Significance::NoDifference, "{}", r.verdict);
    assert_eq!(
        (r.tests.paired, r.tests.fixed, r.tests.regressed),
        (20, 0, 0)
    );
    assert_eq!(r.segments.worse + r.segments.better, 0);
    assert_eq!(r.median_change.unwrap().median_m, 0.0);
    assert_eq!(r.mcnemar.p, 1.0);
    let report = dir.path().join("cmp.html");
    let report_arg = format!("--report={}", path(&report));
    assert_eq!(
        drivecheck(&[
            "-q",
            "compare",
            path(&a),
            path(&b),
            "--json",
            "--fail-on",
            "regression",
            &report_arg,
        ]),
        Exit::Success
    );
    let page = std::fs::read_to_string(&report).unwrap();
    assert!(page.contains("no significant difference at 0.05"));
    assert!(page.contains("<svg"));
}

#[test]
fn a_car_with_noisier_ranging_is_a_significant_regression() {
    let dir = tempfile::tempdir().unwrap();
    let profile = dir.path().join("noisy.toml");
    // The default car ranges with σ = 0.1 m per exchange (docs/twin.md); this one with 0.3 m.
    std::fs::write(
        &profile,
        "format = \"drivecheck-car-profile\"\nversion = 1\n\n[radio]\nrange_sigma_m = 0.3\n",
    )
    .unwrap();
    let (base, new) = (dir.path().join("base"), dir.path().join("new"));
    campaign(&base, "5", "60", None);
    campaign(&new, "5", "60", Some(&profile));
    let compared = compare_dirs(&base, &new, None, None, 0.05, 0).unwrap();
    let r = &compared.report;
    assert_eq!(r.significance, Significance::Worse, "{}", r.verdict);
    assert!(r.evidence.deviation_worse, "{:?}", r.evidence);
    let m = r.median_change.unwrap();
    assert!(m.decision_ci_m[0] > 0.0, "{m:?}");
    assert!(r.tests.regressed >= r.tests.fixed);
    // Every ranged segment is noisier, under a range fault or not: the rows of the range
    // probes' faults got worse too.
    let range_rows: Vec<_> = r
        .breakdowns
        .by_fault
        .iter()
        .filter(|row| row.key.starts_with("uwb_range_"))
        .collect();
    assert!(!range_rows.is_empty(), "{:#?}", r.breakdowns.by_fault);
    assert!(
        range_rows
            .iter()
            .all(|row| row.median_change_m.is_none_or(|c| c > -0.05)),
        "{range_rows:#?}"
    );
    // The rows are sorted by what they explain of the regression.
    let scores: Vec<i64> = r
        .breakdowns
        .by_fault
        .iter()
        .map(|row| row.regression_score())
        .collect();
    assert!(scores.windows(2).all(|w| w[0] >= w[1]), "{scores:?}");
    assert_eq!(
        drivecheck(&[
            "-q",
            "compare",
            path(&base),
            path(&new),
            "--fail-on",
            "regression",
        ]),
        Exit::Found
    );
    // Without --fail-on a regression is reported, not a failure.
    assert_eq!(
        drivecheck(&["-q", "compare", path(&base), path(&new), "--json"]),
        Exit::Success
    );
    // The other way round NEW is better.
    let back = compare_dirs(&new, &base, None, None, 0.05, 0).unwrap();
    assert_eq!(back.report.significance, Significance::Better);
}

#[test]
fn runs_of_other_seeds_are_refused_at_the_first_differing_command() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    campaign(&a, "1", "3", None);
    campaign(&b, "2", "3", None);
    let error = compare_dirs(&a, &b, None, None, 0.05, 0).unwrap_err();
    let pair = error
        .downcast_ref::<PairError>()
        .unwrap_or_else(|| panic!("{error:#}"));
    assert!(
        matches!(pair, PairError::Command { test_index: 0, .. }),
        "{pair:?}"
    );
    assert!(
        format!("{error:#}").contains("are not runs of the same tests: test 0, command"),
        "{error:#}"
    );
    // A run with fewer tests: the first test it lacks.
    let c = dir.path().join("c");
    campaign(&c, "1", "2", None);
    let error = compare_dirs(&a, &c, None, None, 0.05, 0).unwrap_err();
    assert_eq!(
        error.downcast_ref::<PairError>(),
        Some(&PairError::Missing {
            test_index: 2,
            present: campaign::compare::Run::Base,
            missing: campaign::compare::Run::New,
        })
    );
}
