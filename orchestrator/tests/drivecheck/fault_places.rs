//! Faults act at their places on the route: a replay sends each fault where its case places it,
//! and a case without places (hand-written, or of version 1) as the earlier tool sent faults,
//! once the car had 4 or fewer route points left of the fault's segment, with a warning.

use crate::common;

use std::path::{Path, PathBuf};

use campaign::files::PlaceRuleRecord;
use campaign::files::{CampaignRecord, Case, CommandRecord};
use common::{campaign, drivecheck, path, text};

/// A failing case of a 10-test campaign with seed 2.
fn failing_case(dir: &Path) -> PathBuf {
    let campaign = campaign(dir, 2, 10, &[], 1);
    let record = CampaignRecord::from_json(
        &std::fs::read_to_string(campaign.join("campaign.json")).unwrap(),
    )
    .unwrap();
    campaign.join(&record.summary.unwrap().failing_cases[0])
}

/// The one case file of a replay's run directory (`case-NNN.json` of the test it replays).
fn replayed_case(run: &Path) -> PathBuf {
    let names = common::cases(run);
    assert_eq!(names.len(), 1, "{names:?}");
    run.join(names.keys().next().unwrap())
}

fn read(file: &Path) -> Case {
    Case::from_json(&std::fs::read_to_string(file).unwrap()).unwrap()
}

fn replay(case: &Path, out: &Path) -> (Case, String) {
    let run = drivecheck(&["replay", path(case), "--times", "1", "--out", path(out)]);
    assert!(matches!(run.status.code(), Some(0 | 1)), "{}", text(&run));
    (read(&replayed_case(&out.join("run-1"))), text(&run))
}

#[test]
fn a_replay_sends_each_fault_at_its_place_or_by_the_earlier_tools_rule() {
    let dir = tempfile::tempdir().unwrap();
    let file = failing_case(dir.path());
    let case = read(&file);
    let places: Vec<(usize, f64)> = case
        .commands
        .iter()
        .filter_map(|c| match c {
            CommandRecord::AddFault { at: Some(at), .. } => Some((at.segment_index, at.along_m)),
            _ => None,
        })
        .collect();
    assert!(!places.is_empty(), "a failing case of seed 2 has faults");

    let (placed, log) = replay(&file, &dir.path().join("placed"));
    assert!(!log.contains("without a place"), "{log}");
    assert!(!placed.fault_places.is_empty());
    for p in &placed.fault_places {
        assert_eq!(p.rule, PlaceRuleRecord::Planned);
        assert!(
            places.contains(&(p.segment_index, p.planned_along_m)),
            "{p:?}"
        );
        assert!(p.error_m.unwrap().abs() < 0.1, "{p:?}");
    }

    // The same case without places: the earlier tool's rule, with a warning.
    let mut unplaced = case.clone();
    for command in &mut unplaced.commands {
        if let CommandRecord::AddFault { at, .. } = command {
            *at = None;
        }
    }
    let unplaced_file = dir.path().join("unplaced.json");
    std::fs::write(&unplaced_file, unplaced.to_json().unwrap()).unwrap();
    let (earlier, log) = replay(&unplaced_file, &dir.path().join("earlier"));
    assert!(log.contains("without a place"), "{log}");
    assert!(!earlier.fault_places.is_empty());
    for p in &earlier.fault_places {
        assert_eq!(p.rule, PlaceRuleRecord::EarlierTool);
        assert!(p.error_m.unwrap().abs() < 0.1, "{p:?}");
    }
    // The earlier tool's place is where 4 points are left of the segment: the segment's fourth
    // point from its end, which differs from the planned places.
    let earlier_places: Vec<(usize, f64)> = earlier
        .fault_places
        .iter()
        .map(|p| (p.segment_index, p.planned_along_m))
        .collect();
    assert_ne!(
        earlier_places,
        places[..earlier_places.len().min(places.len())]
    );
}

/// The first failing segment of a run's case, if any.
fn first_failing(case: &Case) -> Option<usize> {
    case.segments
        .iter()
        .find(|s| s.oracle.verdict == campaign::oracle::SegmentVerdict::Failed)
        .map(|s| s.segment_index)
}

/// Replays `case` three times with seeds 1, 2, 3: the case of every run.
fn replay_three(case: &Path, out: &Path) -> (Vec<Case>, String) {
    let run = drivecheck(&[
        "replay",
        path(case),
        "--times",
        "3",
        "--vary-seed",
        "--seed",
        "1",
        "--out",
        path(out),
    ]);
    assert_eq!(run.status.code(), Some(1), "{}", text(&run));
    let cases = (1..=3)
        .map(|k| read(&replayed_case(&out.join(format!("run-{k}")))))
        .collect();
    (cases, text(&run))
}

#[test]
fn a_case_without_places_keeps_the_earlier_tools_timing_and_its_failing_segment() {
    // A hand-written case (no ahead margins, no places): six segments on the two-anchor lot and,
    // after segment 3 (7 points, 6.8 m at 0.88 m/s), a strong reflection on anchor 234 that
    // starts 20 range calls (about 4 s) after it is added. The earlier tool added it with 4
    // points left of segment 3, so it acts after segment 3, in segment 4 or 5; placed at the
    // start of segment 3 it acts inside segment 3.
    let fixture =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/earlier-vs-placed.json");
    let case = read(&fixture);
    let fault = case
        .commands
        .iter()
        .position(|c| matches!(c, CommandRecord::AddFault { at: None, .. }))
        .expect("the fixture has an unplaced fault");
    let dir = tempfile::tempdir().unwrap();

    let (earlier, log) = replay_three(&fixture, &dir.path().join("earlier"));
    assert!(log.contains("1 fault(s) without a place"), "{log}");
    for run in &earlier {
        let [placement] = run.fault_places.as_slice() else {
            panic!("one fault: {:?}", run.fault_places)
        };
        assert_eq!(placement.rule, PlaceRuleRecord::EarlierTool);
        assert_eq!(placement.segment_index, 3);
        assert!(placement.planned_along_m > 3.0, "{placement:?}");
        let failing = first_failing(run);
        assert!(
            matches!(failing, Some(4 | 5)),
            "{failing:?}: {:?}",
            run.segments
        );
    }

    let mut placed = case.clone();
    if let CommandRecord::AddFault { at, .. } = &mut placed.commands[fault] {
        *at = Some(campaign::files::PlaceRecord {
            segment_index: 3,
            along_m: 0.0,
        });
    }
    let placed_file = dir.path().join("placed.json");
    std::fs::write(&placed_file, placed.to_json().unwrap()).unwrap();
    let (placed, log) = replay_three(&placed_file, &dir.path().join("placed"));
    assert!(!log.contains("without a place"), "{log}");
    for run in &placed {
        assert_eq!(run.fault_places[0].rule, PlaceRuleRecord::Planned);
        assert_eq!(first_failing(run), Some(3), "{:?}", run.segments);
    }
}
