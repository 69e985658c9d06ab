//! The simulated car behaves as the firmware would for any fault value: a blown-up UWB estimate
//! (a bitflip in a value's exponent, a huge `set_to`) is reported, clamped as the firmware's
//! conversion clamps it, and the oracle fails the test. The car never falls silent, so such a test
//! is failed, not aborted for stale telemetry.

use crate::common;

use common::{campaign, drivecheck, path, text};

use std::path::Path;

use campaign::files::{Case, CommandRecord};
use campaign::model::{FaultKind, Probe};
use campaign::oracle::Verdict;

/// A passing case without faults (seed 1, test 0), with `fault` added after its first segment.
fn case_with(dir: &Path, fault: CommandRecord) -> std::path::PathBuf {
    let campaign = campaign(dir, 1, 1, &["--no-faults"], 0);
    let text = std::fs::read_to_string(campaign.join("case-000.json")).unwrap();
    let mut case = Case::from_json(&text).unwrap();
    let first = case
        .commands
        .iter()
        .position(|c| matches!(c, CommandRecord::RunSegments { .. }))
        .expect("a segment");
    case.commands.insert(first + 1, fault);
    case.segments.clear();
    case.verdict = None;
    case.reason = None;
    case.streaming = None;
    let file = dir.join("blown-up.json");
    std::fs::write(&file, case.to_json().unwrap()).unwrap();
    file
}

/// Replays a passing case with the fault added; returns the run's case (never aborted: the car
/// kept answering).
fn replay(probe: Probe, kind: FaultKind, param: f64) -> Case {
    let dir = tempfile::tempdir().unwrap();
    let fault = CommandRecord::AddFault {
        probe,
        kind,
        param,
        start: 0,
        duration: 20,
        at: None,
    };
    let file = case_with(dir.path(), fault);
    let out_dir = dir.path().join("replay");
    let out = drivecheck(&[
        "replay",
        path(&file),
        "--times",
        "1",
        "--ignore-scenario-hash",
        "--out",
        path(&out_dir),
    ]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    let run = Case::from_json(
        &std::fs::read_to_string(out_dir.join("run-1").join("case-000.json")).unwrap(),
    )
    .unwrap();
    assert_ne!(run.verdict, Some(Verdict::Aborted), "{}", text(&out));
    assert!(run.verdict.is_some(), "{}", text(&out));
    run
}

fn worst(run: &Case) -> f64 {
    run.segments
        .iter()
        .filter_map(|s| s.oracle.stats.map(|st| st.max_m))
        .fold(0.0, f64::max)
}

#[test]
fn a_bitflip_in_the_exponent_of_the_odometry_step_fails_the_test() {
    // Bit 30 of a 1-3 cm step makes it about 10^36 m: the estimate is thrown far away.
    let run = replay(Probe::UwbTravelDist, FaultKind::Bitflip, 30.0);
    assert_eq!(run.verdict, Some(Verdict::Failed));
    assert!(worst(&run) > 1000.0, "{}", worst(&run));
}

#[test]
fn a_huge_yaw_or_range_is_judged_not_aborted() {
    // A bitflip in the exponent makes the yaw and a range huge as the car runs: the yaw is
    // wrapped as the firmware wraps it (no endless loop); a range far beyond any anchor moves
    // the estimate by at most the 0.2 m correction limit per measurement.
    replay(Probe::UwbYaw, FaultKind::Bitflip, 30.0);
    replay(Probe::UwbRange(50), FaultKind::Bitflip, 30.0);
}

#[test]
fn a_fault_value_beyond_the_firmwares_ranges_is_refused_before_driving() {
    // A case file may not ask for a value no scenario can draw (#51): refused, naming the field.
    for (probe, kind, param) in [
        (Probe::UwbYaw, FaultKind::SetTo, 1.0e30),
        (Probe::UwbYaw, FaultKind::Amplification, f64::from(f32::MAX)),
        (Probe::UwbRange(50), FaultKind::SetTo, 1.0e38),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let fault = CommandRecord::AddFault {
            probe,
            kind,
            param,
            start: 0,
            duration: 20,
            at: None,
        };
        let file = case_with(dir.path(), fault);
        let out = drivecheck(&[
            "replay",
            path(&file),
            "--times",
            "1",
            "--ignore-scenario-hash",
        ]);
        assert_eq!(out.status.code(), Some(2), "{}", text(&out));
        assert!(text(&out).contains("commands[1].param"), "{}", text(&out));
    }
}
