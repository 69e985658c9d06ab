//! The table of a campaign's tests and its summary, as `run`, `runs show` and a failed campaign
//! print them (and `--json`'s document of them).

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Result;

use super::progress::{every_test, listed_at_most};

use campaign::oracle::Verdict;
use runner::{CampaignReport, RunError};

/// A campaign that did not run to its end, with where its record is.
#[derive(Debug, thiserror::Error)]
#[error("{error} (run directory {})", dir.display())]
pub(super) struct CampaignFailed {
    error: RunError,
    dir: PathBuf,
}

impl CampaignFailed {
    pub(super) fn new(error: RunError, dir: &Path) -> Self {
        Self {
            error,
            dir: dir.to_owned(),
        }
    }
}

/// Prints a campaign's table of tests and its summary (with the wall time when known). Above
/// [`EVERY_TEST_UP_TO`] tests the table lists the tests that did not pass (every test with `-v`);
/// with `-q` only the summary is printed.
pub(super) fn print_report(report: &CampaignReport, wall: Option<Duration>) {
    use crate::output::{Verbosity, verbosity};
    let every = every_test(report.tests.len());
    let listed: Vec<_> = report
        .tests
        .iter()
        .filter(|t| every || t.verdict != Some(Verdict::Passed))
        .collect();
    if verbosity() > Verbosity::Quiet {
        print_table(&listed);
        if listed.len() < report.tests.len() {
            println!(
                "({} passing tests not listed: -v lists every test)",
                report.tests.len() - listed.len()
            );
        }
    }
    print_summary(report, wall);
}

/// A campaign's result as `--json` prints it (docs/json.md): the run directory, the wall time
/// when known, `campaign.json`'s record and every test's row of the table.
#[derive(serde::Serialize)]
pub(super) struct CampaignJson<'a> {
    /// The run directory.
    dir: &'a Path,
    /// The campaign's wall time, seconds (when this command ran it).
    wall_time_s: Option<f64>,
    /// `campaign.json`: the settings and the summary.
    campaign: &'a campaign::files::CampaignRecord,
    /// Every test, in order.
    tests: &'a [runner::TestSummary],
}

/// Prints a campaign's result as one JSON document (`document`: of the command that printed it).
pub(super) fn print_report_json(
    document: crate::output::json::Document,
    report: &CampaignReport,
    wall: Option<Duration>,
) -> Result<()> {
    crate::output::print_json(
        document,
        &CampaignJson {
            dir: &report.dir,
            wall_time_s: wall.map(|w| w.as_secs_f64()),
            campaign: &report.record,
            tests: &report.tests,
        },
    )
}

/// The table of `tests`.
fn print_table(tests: &[&runner::TestSummary]) {
    // On several cars, which car drove each test.
    let cars = tests.iter().any(|t| t.car.is_some());
    let (car_head, car_rule) = if cars { (" car |", "---|") } else { ("", "") };
    println!(
        "| test |{car_head} verdict | worst deviation | starvations | smallest margin | reason |"
    );
    println!("|---|{car_rule}---|---|---|---|---|");
    for t in tests {
        let car = if cars {
            format!(" {} |", t.car.as_deref().unwrap_or("-"))
        } else {
            String::new()
        };
        println!(
            "| {} |{car} {} | {} | {} | {} | {} |",
            t.test_index,
            t.verdict.map_or("not run", Verdict::as_str),
            metres(t.worst_deviation_m),
            t.starvations,
            t.smallest_margin_s
                .map_or_else(|| "-".to_owned(), |m| format!("{m:.2} s")),
            t.reason.as_deref().unwrap_or("")
        );
    }
}

/// A campaign's summary: its counts, the failing cases and the run directory.
fn print_summary(report: &CampaignReport, wall: Option<Duration>) {
    let Some(s) = &report.record.summary else {
        return;
    };
    if crate::output::verbosity() >= crate::output::Verbosity::Normal {
        println!();
    }
    println!(
        "tests {}, passed {}, failed {}, aborted {}, worst deviation {}{}",
        s.tests,
        s.passed,
        s.failed,
        s.aborted,
        metres(s.worst_deviation_m),
        wall.map_or_else(String::new, |w| format!(
            "; {:.1} s wall time",
            w.as_secs_f64()
        ))
    );
    if let Some(why) = &s.uwb_not_tested {
        println!("UWB NOT TESTED: {why}");
    }
    // This session's cars (a resumed campaign's earlier ones are in `runs show`).
    let last = report.record.cars.last().and_then(|c| c.session);
    let cars: Vec<_> = report
        .record
        .cars
        .iter()
        .filter(|c| c.session == last)
        .cloned()
        .collect();
    for line in cars_lines(&cars) {
        println!("{line}");
    }
    let shown = listed_at_most();
    for file in s.failing_cases.iter().take(shown) {
        println!("  {}", report.dir.join(file).display());
    }
    if s.failing_cases.len() > shown {
        // `-q` and `-v` do not go together: under `-q` the way to them is the run directory.
        let hint = if crate::output::verbosity() == crate::output::Verbosity::Quiet {
            "runs show -v lists them all"
        } else {
            "-v lists them all"
        };
        println!(
            "  … and {} more failing cases in the run directory ({hint})",
            s.failing_cases.len() - shown
        );
    }
    println!("run directory: {}", report.dir.display());
}

/// A line per car of a campaign on several cars: `car A (tcp://…): 12 tests`, or for a car that
/// left, `car B (tcp://…): LEFT after 3 tests: <why>`.
pub(super) fn cars_lines(cars: &[campaign::files::CarRun]) -> Vec<String> {
    cars.iter()
        .map(|car| {
            let tests = match car.tests.len() {
                1 => "1 test".to_owned(),
                n => format!("{n} tests"),
            };
            let line = match &car.left {
                Some(why) => format!(
                    "car {} ({}): LEFT the campaign after {tests}: {why}",
                    car.name, car.address
                ),
                None => format!("car {} ({}): {tests}", car.name, car.address),
            };
            match car.session {
                Some(session) => format!("session {session}: {line}"),
                None => line,
            }
        })
        .collect()
}

/// Metres with two decimals, or `-`.
pub(super) fn metres(value: Option<f64>) -> String {
    value.map_or_else(|| "-".to_owned(), |m| format!("{m:.2} m"))
}
