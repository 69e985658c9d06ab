//! `drivecheck replay` and `drivecheck runs` end to end on the embedded simulated car in virtual
//! time: a failing case from a campaign fails the same way on every replay (identically with one
//! seed, closely with varied seeds), passes without its faults, is refused in another scenario
//! unless told, and a hand-written case replays; the run directories list and show.

use crate::common;

use common::{campaign, drivecheck, path, text};

use std::path::{Path, PathBuf};

use campaign::files::{CampaignRecord, Case};
use campaign::oracle::Verdict;
use campaign::replay::Comparison;

/// Runs a 4-test campaign with seed 1 in `dir` and returns its first failing case file.
fn failing_case(dir: &Path) -> PathBuf {
    let campaign = campaign(dir, 1, 4, &[], 1);
    let record: CampaignRecord = CampaignRecord::from_json(
        &std::fs::read_to_string(campaign.join("campaign.json")).unwrap(),
    )
    .unwrap();
    let summary = record.summary.expect("the campaign ended");
    summary
        .failing_cases
        .iter()
        .map(|f| campaign.join(f))
        .find(|f| read_case(f).verdict == Some(Verdict::Failed))
        .expect("seed 1 finds a failure within 4 tests")
}

fn read_case(file: &Path) -> Case {
    Case::from_json(&std::fs::read_to_string(file).unwrap()).unwrap()
}

fn read_comparison(dir: &Path) -> Comparison {
    Comparison::from_json(&std::fs::read_to_string(dir.join("replay.json")).unwrap()).unwrap()
}

#[test]
fn a_failing_case_replays_the_same_way_and_passes_without_its_faults() {
    let tmp = tempfile::tempdir().unwrap();
    let case_file = failing_case(tmp.path());
    let original = read_case(&case_file);

    // The case's own test, once: identical to the case (`replay_reproduces` checks it in full).
    let same = tmp.path().join("same");
    let out = drivecheck(&["replay", path(&case_file), "--out", path(&same)]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let c = read_comparison(&same);
    assert_eq!(c.runs.len(), 1);
    assert!(
        c.runs.iter().all(|r| r.verdict == Some(Verdict::Failed)),
        "{c:?}"
    );
    assert!(c.same_verdict);
    assert_eq!(c.same_as_original, Some(true));
    assert!(!c.segments.is_empty());
    assert_eq!(c.max_abs_diff_m, Some(0.0), "{}", c.table());
    assert!(String::from_utf8_lossy(&out.stdout).contains("reproduced: every segment identical"));
    let index = original.test_index.unwrap();
    {
        let run = same.join("run-1");
        let record =
            CampaignRecord::from_json(&std::fs::read_to_string(run.join("campaign.json")).unwrap())
                .unwrap();
        let of = record.replay_of.expect("a replay run names its case");
        assert_eq!(of.case, path(&case_file));
        assert!(run.join("campaign.mcap").is_file());
        // The very same segment points were driven again.
        let replayed = read_case(&run.join(format!("case-{index:03}.json")));
        assert_eq!(replayed.commands, original.commands);
    }

    // Varied seeds: the same failure, small differences.
    let varied = tmp.path().join("varied");
    let out = drivecheck(&[
        "replay",
        path(&case_file),
        "--times",
        "3",
        "--vary-seed",
        "--out",
        path(&varied),
    ]);
    assert!(out.status.code() == Some(1), "{}", text(&out));
    let c = read_comparison(&varied);
    let cars: std::collections::BTreeSet<u64> =
        c.runs.iter().filter_map(|r| r.simulator_seed).collect();
    assert_eq!(cars.len(), 3, "{c:?}");
    let diff = c.max_abs_diff_m.expect("segments were driven");
    assert!(diff > 0.0 && diff < 0.5, "{}", c.table());

    // Without its faults the failure disappears.
    let clean = tmp.path().join("clean");
    let out = drivecheck(&[
        "replay",
        path(&case_file),
        "--times",
        "1",
        "--no-faults",
        "--out",
        path(&clean),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let c = read_comparison(&clean);
    assert_eq!(c.failure_disappeared, Some(true), "{}", c.table());
    let replayed = read_case(&clean.join("run-1").join(format!("case-{index:03}.json")));
    assert!(replayed.no_faults);
    assert!(
        replayed
            .commands
            .iter()
            .all(|c| matches!(c, campaign::files::CommandRecord::RunSegments { .. }))
    );

    // `runs` lists the campaign and the replays; `runs show` shows each kind.
    let out = drivecheck(&["runs", "--dir", path(tmp.path())]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let listing = String::from_utf8_lossy(&out.stdout);
    assert!(
        listing.contains("| campaign | campaign | parking-lot-2anchors | 1 |"),
        "{listing}"
    );
    assert!(listing.contains("| same | replay ×1 of"), "{listing}");
    assert!(listing.contains("4 run directories"), "{listing}");
    let out = drivecheck(&["runs", "--dir", path(tmp.path()), "show", "same"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("run-1: seed"));
    let out = drivecheck(&["runs", "show", path(&tmp.path().join("campaign"))]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let shown = String::from_utf8_lossy(&out.stdout);
    assert!(
        shown.contains("seed 1") && shown.contains("| failed |"),
        "{shown}"
    );
}

#[test]
fn a_case_from_another_scenario_is_refused_unless_told() {
    let tmp = tempfile::tempdir().unwrap();
    let case_file = failing_case(tmp.path());
    let mut case = read_case(&case_file);
    case.scenario.hash = Some("0".repeat(64));
    let edited = tmp.path().join("edited.json");
    std::fs::write(&edited, case.to_json().unwrap()).unwrap();
    let out = drivecheck(&[
        "replay",
        path(&edited),
        "--times",
        "1",
        "--out",
        path(&tmp.path().join("refused")),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("hash 000000000000"), "{stderr}");
    assert!(stderr.contains("--ignore-scenario-hash"), "{stderr}");
    assert!(!tmp.path().join("refused").exists());
    let out = drivecheck(&[
        "replay",
        path(&edited),
        "--times",
        "1",
        "--ignore-scenario-hash",
        "--out",
        path(&tmp.path().join("told")),
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
}

#[test]
fn a_case_of_a_scenario_file_replays_from_the_scenario_its_recording_holds() {
    // A scenario file's campaign: its name is not bundled, so `replay` reads the scenario from
    // the recording beside the case, as `report` does; without the recording it asks for it.
    let tmp = tempfile::tempdir().unwrap();
    let run = common::rock_campaign(tmp.path());
    let case_file = run.join("case-000.json");
    let out = drivecheck(&[
        "replay",
        path(&case_file),
        "--out",
        path(&tmp.path().join("r")),
    ]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("reproduced: every segment identical"),
        "{}",
        text(&out)
    );
    std::fs::remove_file(run.join("campaign.mcap")).unwrap();
    let out = drivecheck(&[
        "replay",
        path(&case_file),
        "--out",
        path(&tmp.path().join("s")),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("is not a bundled scenario and no recording beside the case holds it"),
        "{stderr}"
    );
}

/// The first JSON example of docs/case-format.md: a case written by hand.
fn hand_written_example() -> &'static str {
    include_str!("../../../docs/case-format.md")
        .split("```json\n")
        .nth(1)
        .and_then(|block| block.split("\n```").next())
        .expect("the page has a hand-written example")
}

/// The hand-written example of docs/case-format.md, replayed in its scenario.
#[test]
fn the_documented_hand_written_case_replays() {
    let example = hand_written_example();
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("hand.json");
    std::fs::write(&file, example).unwrap();
    let out_dir = tmp.path().join("replay");
    let out = drivecheck(&[
        "replay",
        path(&file),
        "--times",
        "1",
        "--seed",
        "3",
        "--ignore-scenario-hash",
        "--out",
        path(&out_dir),
    ]);
    let c = read_comparison(&out_dir);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    let case = read_case(&out_dir.join("run-1").join("case-000.json"));
    assert!(case.verdict.is_some(), "{}", text(&out));
    assert_ne!(case.verdict, Some(Verdict::Aborted), "{:?}", case.reason);
    assert_eq!(c.segments.len(), 3, "{}", c.table());
}

#[test]
fn a_case_that_leaves_the_area_is_refused_before_driving() {
    let example = hand_written_example();
    let mut case = Case::from_json(example).unwrap();
    if let campaign::files::CommandRecord::RunSegments { points, .. } = &mut case.commands[3] {
        points[3].x = 500.0;
    }
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("outside.json");
    std::fs::write(&file, case.to_json().unwrap()).unwrap();
    let out = drivecheck(&[
        "replay",
        path(&file),
        "--ignore-scenario-hash",
        "--out",
        path(&tmp.path().join("r")),
    ]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("commands[3]: not drivable"), "{stderr}");
}

#[test]
fn a_fifo_as_a_case_or_scenario_file_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("case.json");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo runs");
    assert!(made.success());
    // Nothing ever writes to the FIFO: a reader that opened it would wait for ever, and this
    // test would time out instead of failing.
    for args in [
        vec!["replay", path(&fifo)],
        vec!["scenario", "check", path(&fifo)],
    ] {
        let out = drivecheck(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", text(&out));
        assert!(
            text(&out).contains("not a regular file (a directory, FIFO or device)"),
            "{args:?}: {}",
            text(&out)
        );
    }
}
