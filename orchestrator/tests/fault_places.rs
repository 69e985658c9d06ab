//! Faults act at their places on the route: a replay sends each fault where its case places it,
//! and a case without places (hand-written, or of version 1) as the earlier tool sent faults,
//! once the car had 4 or fewer route points left of the fault's segment, with a warning.

mod common;

use std::path::{Path, PathBuf};

use campaign::case::{CampaignRecord, Case, CommandRecord};
use campaign::drive::PlaceRule;
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

fn read(file: &Path) -> Case {
    Case::from_json(&std::fs::read_to_string(file).unwrap()).unwrap()
}

fn replay(case: &Path, out: &Path) -> (Case, String) {
    let run = drivecheck(&["replay", path(case), "--times", "1", "--out", path(out)]);
    assert!(matches!(run.status.code(), Some(0 | 1)), "{}", text(&run));
    (read(&out.join("run-1").join("case-000.json")), text(&run))
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
        assert_eq!(p.rule, PlaceRule::Planned);
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
        assert_eq!(p.rule, PlaceRule::EarlierTool);
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
