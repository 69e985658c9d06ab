//! A run directory written by an earlier build still reads: `fixtures/recording-v2/` is one test
//! (seed 1, `--record all`) written by main 54162a8, whose recording is version 2 (every channel
//! JSON, the positions in `/car/state`). `runs show`, `report` and `explain` read it through the
//! streaming readers, and the errors `explain` finds in its samples are the ones the oracle of
//! that build computed as it ran.

use crate::common;

use std::path::Path;

use common::{drivecheck, path, text};

const FIXTURE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/recording-v2");

fn copy_of_fixture(to: &Path) {
    for name in ["campaign.json", "campaign.mcap", "case-000.json"] {
        std::fs::copy(Path::new(FIXTURE).join(name), to.join(name)).unwrap();
    }
}

#[test]
fn a_version_2_run_is_shown_reported_and_explained() {
    let dir = tempfile::tempdir().unwrap();
    copy_of_fixture(dir.path());
    let run = dir.path();
    let mcap = std::fs::read(run.join("campaign.mcap")).unwrap();
    let summary = mcap::Summary::read(&mcap).unwrap().unwrap();
    let version = summary
        .metadata_indexes
        .iter()
        .find(|m| m.name == "drivecheck.recording")
        .map(|m| mcap::read::metadata(&mcap, m).unwrap())
        .unwrap();
    assert_eq!(version.metadata["schema_version"], "2");

    let shown = drivecheck(&["runs", "show", path(run)]);
    assert_eq!(shown.status.code(), Some(0), "{}", text(&shown));
    assert!(
        String::from_utf8_lossy(&shown.stdout).contains("tests 1, passed 1"),
        "{}",
        text(&shown)
    );

    let report = drivecheck(&["report", path(run), "--all-tests"]);
    assert_eq!(report.status.code(), Some(0), "{}", text(&report));
    assert!(
        text(&report).contains("1 tests, 1 drawn"),
        "{}",
        text(&report)
    );

    let explained = drivecheck(&["explain", path(run), "--all-segments", "--json"]);
    assert_eq!(explained.status.code(), Some(0), "{}", text(&explained));
    let json: serde_json::Value = serde_json::from_slice(&explained.stdout).unwrap();
    assert!(json.get("notes").is_none(), "{json}");
    let segments = json["cases"][0]["segments"].as_array().unwrap();
    let case: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("case-000.json")).unwrap()).unwrap();
    let judged = case["segments"].as_array().unwrap();
    assert_eq!(segments.len(), judged.len());
    for (explained, judged) in segments.iter().zip(judged) {
        // The largest |UWB − RTK| of the segment's samples, read back from the JSON of version
        // 2, is the oracle's maximum of that run.
        assert_eq!(
            explained["error_to_m"].as_f64(),
            judged["oracle"]["stats"]["max_m"].as_f64(),
            "segment {}",
            judged["segment_index"]
        );
    }
}
