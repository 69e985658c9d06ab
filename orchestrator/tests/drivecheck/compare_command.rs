//! `drivecheck compare` end to end on the embedded simulated car in virtual time: the same cases
//! driven again (`run --cases-from`) on the same car with another seed, on a car with noisier
//! ranging, and runs of other tests refused; what the command prints, exits with and writes.

use crate::common;

use std::path::{Path, PathBuf};

use common::{drivecheck, path, run_unrecorded, text};
use serde_json::Value;

/// `drivecheck compare BASE NEW --json [extra]`: the comparison, and the exit status.
fn compare(base: &Path, new: &Path, extra: &[&str]) -> (Value, Option<i32>) {
    let mut args = vec!["compare", path(base), path(new), "--json"];
    args.extend_from_slice(extra);
    let output = drivecheck(&args);
    let json: Value = serde_json::from_slice(&output.stdout)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", text(&output)));
    (json["comparison"].clone(), output.status.code())
}

/// `TESTS` tests of seed 5 in `dir/base`, and the same cases (`--cases-from`, seed 6) on the
/// car of the profile `body` in `dir/new`.
fn base_and_degraded(dir: &Path, tests: &str, body: &str) -> (PathBuf, PathBuf) {
    let profile = dir.join("degraded.toml");
    std::fs::write(
        &profile,
        format!("format = \"drivecheck-car-profile\"\nversion = 1\n\n{body}"),
    )
    .unwrap();
    let (base, new) = (dir.join("base"), dir.join("new"));
    run_unrecorded(&["--seed", "5", "--tests", tests], &base);
    let args = [
        "--cases-from",
        path(&base),
        "--seed",
        "6",
        "--profile",
        path(&profile),
    ];
    run_unrecorded(&args, &new);
    (base, new)
}

#[test]
fn the_same_cases_on_the_same_car_with_another_seed_are_no_difference() {
    let dir = tempfile::tempdir().unwrap();
    let (base, again) = (dir.path().join("base"), dir.path().join("again"));
    run_unrecorded(&["--seed", "11", "--tests", "40"], &base);
    run_unrecorded(&["--cases-from", path(&base), "--seed", "12"], &again);
    let (c, code) = compare(&base, &again, &["--fail-on", "regression"]);
    assert_eq!(c["significance"], "no_difference", "{}", c["verdict"]);
    assert_eq!(code, Some(0));
    assert_eq!(c["tests"]["paired"], 40);
    // The seed reached the car: the deviations moved, within the noise.
    assert!(c["median_change"]["median_m"].is_number());

    // The very same run: nothing changed at all; the page says so and draws its map.
    let report = dir.path().join("same.html");
    let report_arg = format!("--report={}", path(&report));
    let (c, code) = compare(&base, &base, &["--fail-on", "regression", &report_arg]);
    assert_eq!(code, Some(0));
    assert_eq!(c["tests"]["fixed"], 0);
    assert_eq!(c["tests"]["regressed"], 0);
    assert_eq!(c["median_change"]["median_m"], 0.0);
    assert_eq!(c["mcnemar"]["p"], 1.0);
    let page = std::fs::read_to_string(&report).unwrap();
    assert!(page.contains("no significant difference at 0.05"), "{page}");
    assert!(page.contains("<svg"));

    // The text a person reads names both runs and the verdict first.
    let output = drivecheck(&["compare", path(&base), path(&again)]);
    assert_eq!(output.status.code(), Some(0), "{}", text(&output));
    let said = String::from_utf8_lossy(&output.stdout);
    assert!(
        said.starts_with("no significant difference at 0.05"),
        "{said}"
    );
    assert!(said.contains(&format!("BASE  {}", path(&base))), "{said}");
}

#[test]
fn a_car_with_noisier_ranging_is_a_significant_regression_and_fails_the_gate() {
    let dir = tempfile::tempdir().unwrap();
    // The default car ranges with σ = 0.1 m per exchange (docs/twin.md); this one with 0.3 m.
    let (base, new) = base_and_degraded(dir.path(), "60", "[radio]\nrange_sigma_m = 0.3\n");
    let (c, code) = compare(&base, &new, &["--fail-on", "regression"]);
    assert_eq!(c["significance"], "worse", "{}", c["verdict"]);
    assert_eq!(code, Some(1), "--fail-on regression fails the gate");
    assert!(c["median_change"]["ci95_m"][0].as_f64().unwrap() > 0.0);
    assert!(c["median_change"]["p"].as_f64().unwrap() < 0.025);
    let verdict = c["verdict"].as_str().unwrap();
    assert!(
        verdict.starts_with("NEW is significantly worse at 0.05"),
        "{verdict}"
    );
    // Noisier ranging moves every ranged segment: the range probes' rows got worse too.
    let by_fault = c["breakdowns"]["by_fault"].as_array().unwrap();
    let range_rows: Vec<&Value> = by_fault
        .iter()
        .filter(|row| row["key"].as_str().unwrap().starts_with("uwb_range_"))
        .collect();
    assert!(!range_rows.is_empty(), "{by_fault:#?}");
    for row in range_rows {
        assert!(
            row["median_change_m"].as_f64().is_none_or(|m| m > -0.05),
            "{row}"
        );
    }
    // Without --fail-on a regression is reported, not a failure; the other way round NEW is
    // better.
    assert_eq!(compare(&base, &new, &[]).1, Some(0));
    assert_eq!(compare(&new, &base, &[]).0["significance"], "better");
}

#[test]
fn a_firmware_build_with_a_looser_correction_clamp_is_blamed_on_the_range_probes() {
    // A build whose UWB estimator corrects up to 0.5 m per range instead of 0.2 m lets a faulty
    // range pull the position further; without a fault, or with an odometry or yaw fault, the
    // corrections are small anyway. The breakdown must say so: the range probes' rows first.
    // (`bench compare` finds this build worse in 10 of 20 pairs of 50 tests, 20 of 20 of 100.)
    let dir = tempfile::tempdir().unwrap();
    let (base, new) = base_and_degraded(
        dir.path(),
        "100",
        "[estimator]\nuwb_correction_clamp_m = 0.5\n",
    );
    let (c, _) = compare(&base, &new, &[]);
    assert_eq!(c["significance"], "worse", "{}", c["verdict"]);
    let by_fault = c["breakdowns"]["by_fault"].as_array().unwrap();
    let is_range = |row: &Value| row["key"].as_str().unwrap().starts_with("uwb_range_");
    assert!(is_range(&by_fault[0]), "{by_fault:#?}");
    let median = |row: &Value| row["median_change_m"].as_f64().unwrap_or(0.0);
    let least_range = by_fault
        .iter()
        .filter(|r| is_range(r))
        .map(median)
        .fold(f64::INFINITY, f64::min);
    for row in by_fault.iter().filter(|r| !is_range(r)) {
        assert!(
            median(row) < 0.05 && median(row) < least_range,
            "{by_fault:#?}"
        );
    }
}

#[test]
fn runs_of_other_tests_are_refused_naming_the_first_difference() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        dir.path().join("a"),
        dir.path().join("b"),
        dir.path().join("c"),
    );
    run_unrecorded(&["--seed", "1", "--tests", "3"], &a);
    run_unrecorded(&["--seed", "2", "--tests", "3"], &b);
    // The same run without its last test.
    std::fs::create_dir(&c).unwrap();
    for file in ["campaign.json", "case-000.json", "case-001.json"] {
        std::fs::copy(a.join(file), c.join(file)).unwrap();
    }
    let refused = drivecheck(&["compare", path(&a), path(&b)]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(
        said.contains("are not runs of the same tests: test 0, command"),
        "{said}"
    );
    let refused = drivecheck(&["compare", path(&a), path(&c)]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(said.contains("test 2"), "{said}");
}

/// Edits `new`'s `case-000.json` with `edit` and expects `compare base new` refused with exit
/// status 2, naming the file and saying `why`.
fn assert_edited_case_refused(edit: impl Fn(&mut Value), why: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let (base, new) = (tmp.path().join("base"), tmp.path().join("new"));
    run_unrecorded(&["--seed", "5", "--tests", "2"], &base);
    run_unrecorded(&["--cases-from", path(&base), "--seed", "6"], &new);
    let file = new.join("case-000.json");
    let mut case: Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    edit(&mut case);
    std::fs::write(&file, serde_json::to_string_pretty(&case).unwrap()).unwrap();
    let output = drivecheck(&["compare", path(&base), path(&new)]);
    let said = text(&output);
    assert_eq!(output.status.code(), Some(2), "{said}");
    assert!(said.contains("case-000.json"), "names the file: {said}");
    assert!(said.contains(why), "says {why:?}: {said}");
}

#[test]
fn compare_refuses_an_edited_verdict() {
    assert_edited_case_refused(
        |case| {
            let edited = if case["verdict"] == "passed" {
                "failed"
            } else {
                "passed"
            };
            case["verdict"] = Value::from(edited);
        },
        "verdict",
    );
}

#[test]
fn compare_refuses_deviations_no_samples_give() {
    for (max, why) in [(1e308, "max_m"), (-5.0, "max_m")] {
        assert_edited_case_refused(
            move |case| {
                let stats = &mut case["segments"][0]["oracle"]["stats"];
                stats["max_m"] = Value::from(max);
            },
            why,
        );
    }
}

#[test]
fn compare_refuses_a_segment_repeated() {
    assert_edited_case_refused(
        |case| {
            let first = case["segments"][0].clone();
            case["segments"] = Value::Array(vec![first; 50]);
        },
        "segments[1].command_index",
    );
}
