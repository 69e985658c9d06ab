//! `drivecheck run --cases-from DIR` end to end: an earlier run's cases driven again test for
//! test, with the same commands (routes, faults, fault places) whatever the seed, also as shards
//! merged; what cannot be driven is refused before anything is.

use crate::common;

use std::path::{Path, PathBuf};

use common::{cases, drivecheck, path, run_unrecorded, text};
use serde_json::Value;

fn json(text: &str) -> Value {
    serde_json::from_str(text).unwrap()
}

/// `campaign.json` of a run directory.
fn record(dir: &Path) -> Value {
    json(&std::fs::read_to_string(dir.join("campaign.json")).unwrap())
}

#[test]
fn a_forty_test_run_is_driven_again_command_for_command_also_sharded_and_merged() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("source");
    run_unrecorded(&["--seed", "7", "--tests", "40"], &source);
    let source_cases = cases(&source);
    assert_eq!(source_cases.len(), 40);

    // The same seed: the same tests on the same car, so the very same case files.
    let again = dir.path().join("again");
    run_unrecorded(&["--cases-from", path(&source)], &again);
    assert_eq!(cases(&again), source_cases);
    let of = &record(&again)["cases_from"];
    assert_eq!(of["run"], path(&source));
    assert_eq!(of["campaign_seed"], 7);
    assert_eq!(of["tests"], 40);

    // Another seed: other sensor noise and resets, the same commands in every test.
    let other = dir.path().join("other");
    run_unrecorded(&["--cases-from", path(&source), "--seed", "8"], &other);
    let other_cases = cases(&other);
    assert_eq!(other_cases.len(), 40);
    let mut verdicts_differ = 0;
    for (name, text) in &source_cases {
        let (a, b) = (json(text), json(&other_cases[name]));
        assert_eq!(a["commands"], b["commands"], "{name}: commands differ");
        assert_eq!(a["test_index"], b["test_index"], "{name}");
        assert_eq!(b["campaign_seed"], 8, "{name}");
        verdicts_differ += usize::from(a["segments"] != b["segments"]);
    }
    // The seed reaches the car: some segment's outcome differs.
    assert!(verdicts_differ > 0, "the seed changed no segment");
    assert_eq!(record(&other)["seed"], 8);

    // Sharded and merged: the unsharded run's case files.
    let shards: Vec<PathBuf> = (1..=2)
        .map(|k| dir.path().join(format!("shard-{k}")))
        .collect();
    for (k, shard) in shards.iter().enumerate() {
        let arg = format!("{}/2", k + 1);
        run_unrecorded(
            &[
                "--cases-from",
                path(&source),
                "--seed",
                "8",
                "--shard",
                &arg,
            ],
            shard,
        );
        assert_eq!(cases(shard).len(), 20);
    }
    let merged = dir.path().join("merged");
    let output = drivecheck(&[
        "runs",
        "merge",
        path(&shards[0]),
        path(&shards[1]),
        "--out",
        path(&merged),
    ]);
    assert!(output.status.success(), "{}", text(&output));
    assert_eq!(cases(&merged), other_cases);
    assert_eq!(record(&merged)["cases_from"], record(&other)["cases_from"]);

    // A shard of it is not a whole run: refused, saying what to do.
    let refused = drivecheck(&["run", "--cases-from", path(&shards[0])]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(
        said.contains("shard 1/2") && said.contains("runs merge"),
        "{said}"
    );
}

#[test]
fn a_run_with_a_missing_or_broken_case_is_refused_naming_it_before_driving() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("source");
    run_unrecorded(&["--seed", "3", "--tests", "6"], &source);

    std::fs::remove_file(source.join("case-002.json")).unwrap();
    let out = dir.path().join("gap");
    let refused = drivecheck(&["run", "--cases-from", path(&source), "--out", path(&out)]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(said.contains("no case file for test 2"), "{said}");
    assert!(!out.join("campaign.json").exists(), "nothing is written");

    // Test 2 back, test 4 broken: named by file and field.
    let three = std::fs::read_to_string(source.join("case-003.json")).unwrap();
    std::fs::write(
        source.join("case-002.json"),
        three.replace("\"test_index\": 3", "\"test_index\": 2"),
    )
    .unwrap();
    let four = std::fs::read_to_string(source.join("case-004.json")).unwrap();
    std::fs::write(
        source.join("case-004.json"),
        four.replacen("\"speed\": ", "\"speed\": -", 1),
    )
    .unwrap();
    let refused = drivecheck(&["run", "--cases-from", path(&source), "--out", path(&out)]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(said.contains("case-004.json"), "{said}");
    assert!(!out.join("campaign.json").exists(), "nothing is written");
}
