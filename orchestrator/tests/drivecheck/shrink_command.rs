//! `drivecheck shrink`: a failing case shrinks to a smaller one that fails the same way in every
//! run, deterministically given the seed; a case that does not fail the same way every time is
//! refused.

use crate::common;

use std::path::{Path, PathBuf};

use campaign::files::{Case, CommandRecord};
use campaign::shrink::{MEDIAN_ROW, Outcome, ShrinkReport, Target};
use common::{drivecheck, path, text};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// The text of the element with `id` (`<td id="median-after">1.15 m</td>` → `1.15 m`).
fn by_id<'a>(html: &'a str, id: &str) -> &'a str {
    let marker = format!("id=\"{id}\">");
    let start = html.find(&marker).unwrap_or_else(|| panic!("no #{id}")) + marker.len();
    let end = start + html[start..].find('<').unwrap();
    &html[start..end]
}

fn shrink(case: &Path, out: &Path) -> (Case, ShrinkReport, String) {
    let run = drivecheck(&["shrink", path(case), "--seed", "1", "--out", path(out)]);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run));
    let minimal =
        Case::from_json(&std::fs::read_to_string(out.join("minimal.json")).unwrap()).unwrap();
    let report: ShrinkReport =
        serde_json::from_str(&std::fs::read_to_string(out.join("shrink.json")).unwrap()).unwrap();
    (minimal, report, text(&run))
}

#[test]
fn a_failing_case_shrinks_to_a_smaller_one_that_fails_every_time() {
    // Six segments and a strong reflection on anchor 234 placed at the start of segment 3,
    // which fails segment 3 in every run.
    let case = fixture("placed-reflection.json");
    let dir = tempfile::tempdir().unwrap();
    let (minimal, report, log) = shrink(&case, &dir.path().join("a"));
    assert!(log.contains("| commands | 7 |"), "{log}");
    assert!(log.contains("drivecheck replay"), "{log}");
    assert_eq!(report.before.target, Target::segment(3));
    assert!(
        report.after.size.commands < report.before.size.commands,
        "{:?}",
        report.after
    );
    assert!(report.after.size.segments < 6);
    assert_eq!(minimal.commands.len(), report.after.size.commands);
    // The reflection is what makes it fail: it is kept, and without it the minimal case passes.
    assert_eq!(report.after.size.faults, 1, "{log}");
    let without = report
        .without_faults
        .as_ref()
        .expect("driven without faults");
    assert!(without.iter().all(|r| !r.fails_at(report.after.target)));
    // Every kept step failed the same way in all 3 runs, by the margin above the threshold;
    // every other step has a run that did not (or was not drivable).
    assert!(
        (1.0..=1.1).contains(&report.min_deviation_m),
        "{}",
        report.min_deviation_m
    );
    for step in &report.steps {
        let all = step.runs.len() == 3
            && step
                .runs
                .iter()
                .all(|r| r.fails_clearly(step.target, report.min_deviation_m));
        assert_eq!(step.outcome == Outcome::Kept, all, "{step:?}");
    }
    assert!(report.steps.iter().any(|s| s.outcome == Outcome::Kept));
    // Confirmed with six other seeds.
    let confirmation = report.confirmation.as_ref().expect("confirmed");
    assert!(confirmation.confirmed);
    assert_eq!(confirmation.runs.len(), 6);
    assert!(confirmation.runs.iter().all(|r| r.seed >= 4));

    // The report of the shrink directory shows the medians the command printed.
    let shrunk = dir.path().join("a");
    let out = drivecheck(&["report", path(&shrunk)]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let page = std::fs::read_to_string(shrunk.join("report.html")).unwrap();
    let row = format!("| {MEDIAN_ROW} | ");
    let printed: Vec<&str> = log
        .lines()
        .find_map(|l| l.strip_prefix(&row))
        .unwrap_or_else(|| panic!("no median row in {log}"))
        .trim_end_matches(" |")
        .split(" | ")
        .collect();
    let shown = [by_id(&page, "median-before"), by_id(&page, "median-after")];
    assert_eq!(printed, shown, "{log}");
    let after = report
        .after
        .median_deviation_m()
        .expect("the runs measured");
    assert_eq!(shown[1], format!("{after:.2} m"));

    // Deterministic given the seed.
    let (again, again_report, _) = shrink(&case, &dir.path().join("b"));
    assert_eq!(again.commands, minimal.commands);
    assert_eq!(again_report.steps, report.steps);

    // The minimal case is a case file replay takes, and it fails where the shrink said, in
    // three runs with other seeds.
    let minimal_file = dir.path().join("a/minimal.json");
    let out = dir.path().join("replay");
    let run = drivecheck(&[
        "replay",
        path(&minimal_file),
        "--times",
        "3",
        "--vary-seed",
        "--seed",
        "11",
        "--out",
        path(&out),
    ]);
    assert_eq!(run.status.code(), Some(1), "{}", text(&run));
    for k in 1..=3 {
        let file = out.join(format!("run-{k}/case-000.json"));
        let case = Case::from_json(&std::fs::read_to_string(file).unwrap()).unwrap();
        let first_failing = case
            .segments
            .iter()
            .find(|s| s.oracle.verdict == campaign::oracle::SegmentVerdict::Failed)
            .map(|s| s.segment_index);
        assert!(
            first_failing.is_some_and(|s| report.after.target.contains(s)),
            "run {k}"
        );
    }
    assert!(
        minimal
            .commands
            .iter()
            .any(|c| matches!(c, CommandRecord::AddFault { .. }))
    );
}

#[test]
fn a_failure_that_moves_between_neighbouring_segments_shrinks_and_one_that_passes_does_not() {
    // Without its place the reflection fails segment 4 in some runs and segment 5 in others:
    // the target is both.
    let dir = tempfile::tempdir().unwrap();
    let (minimal, report, _) = shrink(&fixture("earlier-vs-placed.json"), &dir.path().join("a"));
    assert_eq!(report.before.target, Target { first: 4, last: 5 });
    assert!(minimal.commands.len() < 7, "{:?}", report.after);

    // The same case without its fault passes: nothing to shrink, a finding about the case (exit
    // status 1), not an error.
    let mut case =
        Case::from_json(&std::fs::read_to_string(fixture("earlier-vs-placed.json")).unwrap())
            .unwrap();
    case.commands
        .retain(|c| matches!(c, CommandRecord::RunSegments { .. }));
    let file = dir.path().join("passing.json");
    std::fs::write(&file, case.to_json().unwrap()).unwrap();
    let out = dir.path().join("b");
    let run = drivecheck(&["shrink", path(&file), "--seed", "1", "--out", path(&out)]);
    assert_eq!(run.status.code(), Some(1), "{}", text(&run));
    let log = text(&run);
    assert!(!log.contains("error:"), "{log}");
    assert!(
        log.contains("does not fail in every run at one segment"),
        "{log}"
    );
    assert!(log.contains("seed 1: passed"), "{log}");
    // Nothing was shrunk: the directory the shrink made is gone, not left empty.
    assert!(!out.exists(), "{log}");

    // `drivecheck runs` lists the shrink directory of the first case (and only it).
    let listed = drivecheck(&["runs", "--dir", path(dir.path())]);
    let table = text(&listed);
    assert_eq!(listed.status.code(), Some(0), "{table}");
    let row = table
        .lines()
        .find(|l| l.starts_with("| a |"))
        .unwrap_or_else(|| panic!("no row for the shrink directory a: {table}"));
    assert!(
        row.contains("shrink of") && row.contains("earlier-vs-placed.json"),
        "{row}"
    );
    assert!(table.contains("1 run directory in"), "{table}");
}
