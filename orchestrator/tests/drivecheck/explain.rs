//! `drivecheck explain` end to end: a campaign on the rock lot without faults (a rock hides anchor
//! 234 for part of the lot and a wall reflects its signal; the wide shadow of
//! `fixtures/rock-wide-shadow.toml`, across the cars' paths) is explained from its recording, scored
//! against the simulator's truth, and calibrated on; a case file alone is explained too.

use crate::common;

use common::{campaign, drivecheck, path, summary, text};

#[test]
fn the_rock_lots_failures_are_explained_by_anchor_234s_reflected_range() {
    let dir = tempfile::tempdir().unwrap();
    let run = common::rock_campaign(dir.path());
    let out = drivecheck(&["explain", path(&run), "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let segments: Vec<&serde_json::Value> = json["cases"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|c| c["segments"].as_array().unwrap())
        .collect();
    assert!(!segments.is_empty(), "{json}");
    let named_234 = segments
        .iter()
        .filter(|s| s["causes"][0]["source"] == "anchor" && s["causes"][0]["anchor_id"] == 234)
        .count();
    assert!(
        named_234 * 10 >= segments.len() * 9,
        "{named_234} of {} name anchor 234 first",
        segments.len()
    );
    assert!(segments.iter().all(|s| s["verdict"] == "failed"));
    // Scored against the truth the simulator recorded: a table and the share right.
    let scored = drivecheck(&["explain", path(&run), "--score"]);
    assert_eq!(scored.status.code(), Some(0), "{}", text(&scored));
    let table = String::from_utf8_lossy(&scored.stdout);
    assert!(
        table.contains("| reflection on 234 |") && table.contains("failing segments"),
        "{table}"
    );
    // One case file alone, as text.
    let case = json["cases"][0]["case"].as_str().unwrap().to_owned();
    let one = drivecheck(&["explain", &case]);
    assert_eq!(one.status.code(), Some(0), "{}", text(&one));
    assert!(
        String::from_utf8_lossy(&one.stdout).contains("anchor 234's range"),
        "{}",
        text(&one)
    );
    // Calibration wants a fault-free run: this one is.
    let calibrated = drivecheck(&["explain", path(&run), "--calibrate"]);
    assert_eq!(calibrated.status.code(), Some(0), "{}", text(&calibrated));
    assert!(String::from_utf8_lossy(&calibrated.stdout).contains("--nominal"));
}

#[test]
fn a_run_with_faults_is_explained_by_them_and_cannot_be_calibrated_on() {
    let dir = tempfile::tempdir().unwrap();
    let run = campaign(dir.path(), 1, 6, &["--on-failure", "continue"], 1);
    // `run` wrote each failed case's explanation into its case file.
    let explained: Vec<campaign::files::Case> = std::fs::read_dir(&run)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("case-")
        })
        .map(|p| campaign::files::Case::from_json(&std::fs::read_to_string(p).unwrap()).unwrap())
        .filter(|c| c.verdict == Some(campaign::oracle::Verdict::Failed))
        .collect();
    assert!(!explained.is_empty());
    assert!(explained.iter().all(|c| !c.explanation.is_empty()));
    // The workers explained each failed test from the messages it recorded, before writing
    // them: the very explanation `drivecheck explain` finds in the recording.
    let out = drivecheck(&["explain", path(&run), "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let from_recording: Vec<(usize, Vec<campaign::files::SegmentExplanationRecord>)> =
        json["cases"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|c| !c["segments"].as_array().unwrap().is_empty())
            .map(|c| {
                let segments: Vec<campaign::explain::SegmentExplanation> =
                    serde_json::from_value(c["segments"].clone()).unwrap();
                (
                    c["test_index"].as_u64().unwrap() as usize,
                    segments.iter().map(Into::into).collect(),
                )
            })
            .collect();
    let mut in_run: Vec<(usize, Vec<campaign::files::SegmentExplanationRecord>)> = explained
        .iter()
        .map(|c| (c.test_index.unwrap(), c.explanation.clone()))
        .collect();
    in_run.sort_by_key(|(index, _)| *index);
    assert_eq!(in_run, from_recording);
    let out = drivecheck(&["explain", path(&run), "--score", "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let scored = json["scored"].as_array().unwrap();
    assert!(!scored.is_empty(), "{json}");
    let right = scored.iter().filter(|s| s["right"] == true).count();
    assert!(
        right * 10 >= scored.len() * 8,
        "{right} of {} right",
        scored.len()
    );
    // Where two faults moved a failing segment's estimate, the case was driven again without
    // each, and the truth is the one whose absence lowered its deviation most.
    let settled: Vec<&serde_json::Value> = scored
        .iter()
        .filter(|s| s["moved"].as_array().is_some_and(|m| m.len() >= 2))
        .collect();
    assert!(!settled.is_empty(), "{json}");
    for s in &settled {
        let drops = s["counterfactual"].as_array().expect("a counterfactual");
        assert_eq!(drops.len(), s["moved"].as_array().unwrap().len(), "{s}");
        if drops[0]["metres"].as_f64().unwrap() >= 0.05 {
            assert_eq!(
                s["truth"]["command_index"], drops[0]["command_index"],
                "{s}"
            );
        }
    }
    let unsettled = drivecheck(&[
        "explain",
        path(&run),
        "--score",
        "--json",
        "--counterfactual-runs",
        "0",
    ]);
    assert_eq!(unsettled.status.code(), Some(0), "{}", text(&unsettled));
    let unsettled: serde_json::Value = serde_json::from_slice(&unsettled.stdout).unwrap();
    assert!(
        unsettled["scored"]
            .as_array()
            .unwrap()
            .iter()
            .all(|s| s.get("counterfactual").is_none())
    );
    let calibrated = drivecheck(&["explain", path(&run), "--calibrate"]);
    assert_eq!(calibrated.status.code(), Some(2), "{}", text(&calibrated));
    assert!(String::from_utf8_lossy(&calibrated.stderr).contains("fault-free"));
    let missing = drivecheck(&["explain", "no-such-dir"]);
    assert_eq!(missing.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("no-such-dir"));
}

/// A replay directory is explained run by run (`run-1/`, `run-2/`, …).
#[test]
fn a_replay_directory_is_explained_run_by_run() {
    let dir = tempfile::tempdir().unwrap();
    let run = campaign(dir.path(), 1, 6, &["--on-failure", "continue"], 1);
    let failed = std::fs::read_dir(&run)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| {
            std::fs::read_to_string(p).is_ok_and(|t| t.contains("\"verdict\": \"failed\""))
                && p.file_name()
                    .unwrap()
                    .to_string_lossy()
                    .starts_with("case-")
        })
        .expect("a failed case");
    let replay = dir.path().join("replay");
    let out = drivecheck(&[
        "replay",
        path(&failed),
        "--times",
        "2",
        "--out",
        path(&replay),
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let explained = drivecheck(&["explain", path(&replay), "--json"]);
    assert_eq!(explained.status.code(), Some(0), "{}", text(&explained));
    let json: serde_json::Value = serde_json::from_slice(&explained.stdout).unwrap();
    let cases: Vec<&str> = json["cases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["case"].as_str().unwrap())
        .collect();
    assert_eq!(cases.len(), 2, "{json}");
    assert!(
        cases[0].contains("run-1") && cases[1].contains("run-2"),
        "{cases:?}"
    );
}

/// A run recorded with `--record failing` has no samples of its passing tests: `explain` says
/// nothing of them, and `--all-segments` says it once, not a line per test.
#[test]
fn the_passing_tests_of_a_run_recorded_failing_need_no_note() {
    let dir = tempfile::tempdir().unwrap();
    let run = campaign(dir.path(), 1, 8, &["--record", "failing"], 1);
    let notes = |extra: &[&str]| {
        let mut args = vec!["explain", path(&run), "--json"];
        args.extend_from_slice(extra);
        let out = drivecheck(&args);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        json["notes"].as_array().cloned().unwrap_or_default()
    };
    assert!(notes(&[]).is_empty());
    let passing = summary(&run)["passed"].as_u64().unwrap();
    assert!(passing > 3, "{passing} passing tests");
    let all = notes(&["--all-segments"]);
    assert_eq!(all.len(), 1, "{all:?}");
    let note = all[0].as_str().unwrap();
    assert!(
        note.starts_with(&format!("{passing} tests have no samples in the recording")),
        "{note}"
    );
}
