//! SIGTERM and SIGHUP stop a campaign as Ctrl-C does: the car is stopped safely, the running test
//! is recorded as aborted (`interrupted`), the run directory and the recording are complete, and
//! the exit status is 2. A second signal brakes at once and still writes the test in flight.

#![cfg(unix)]

use crate::common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use campaign::files::{CampaignRecord, Case};
use campaign::oracle::Verdict;
use common::path;
use recording::Recording;

fn stop_with(signal: &str) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    // The simulated car against the wall clock: the first reset alone takes seconds.
    let mut child = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args([
            "run",
            "--realtime",
            "--tests",
            "3",
            "--seed",
            "1",
            "--out",
            path(&out),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("drivecheck starts");
    std::thread::sleep(Duration::from_millis(2500));
    let killed = Command::new("kill")
        .args([&format!("-{signal}"), &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(killed.success());
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "drivecheck did not stop after SIG{signal}"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut stderr).unwrap();
    assert_eq!(status.code(), Some(2), "SIG{signal}: {stderr}");
    assert!(stderr.contains(&format!("SIG{signal}")), "{stderr}");
    // A complete run directory: the record has its end and summary, the interrupted test its case.
    let record =
        CampaignRecord::from_json(&std::fs::read_to_string(out.join("campaign.json")).unwrap())
            .unwrap();
    assert!(record.ended_at.is_some());
    let summary = record.summary.expect("a summary");
    assert!(summary.aborted >= 1, "{summary:?}");
    let last = summary.tests - 1;
    let case = Case::from_json(
        &std::fs::read_to_string(out.join(format!("case-{last:03}.json"))).unwrap(),
    )
    .unwrap();
    assert_eq!(case.verdict, Some(Verdict::Aborted));
    assert!(
        case.reason
            .as_deref()
            .is_some_and(|r| r.contains("interrupted")),
        "{:?}",
        case.reason
    );
    // The recording was finished.
    let recording = Recording::read(&out.join("campaign.mcap")).unwrap();
    assert!(recording.is_complete(), "{:?}", recording.cut_short());
}

#[test]
fn sigterm_stops_the_car_safely_and_completes_the_run_directory() {
    stop_with("TERM");
}

#[test]
fn sighup_stops_the_car_safely_and_completes_the_run_directory() {
    stop_with("HUP");
}

#[test]
fn after_kill_9_runs_show_says_how_to_read_the_unfinished_recording() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let mut child = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args([
            "run",
            "--realtime",
            "--tests",
            "2",
            "--seed",
            "1",
            "--out",
            path(&out),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("drivecheck starts");
    std::thread::sleep(Duration::from_millis(2500));
    child.kill().unwrap();
    child.wait().unwrap();
    // Every file drivecheck wrote is whole: campaign.json reads (without an end).
    let record =
        CampaignRecord::from_json(&std::fs::read_to_string(out.join("campaign.json")).unwrap())
            .unwrap();
    assert!(record.ended_at.is_none());
    let show = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(["runs", "show", path(&out)])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&show.stdout);
    assert!(text.contains("(did not end)"), "{text}");
    assert!(
        text.contains("unfinished") && text.contains("mcap recover"),
        "{text}"
    );
}

#[test]
fn a_second_signal_brakes_at_once_and_still_writes_the_test_in_flight() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    // Against the wall clock (in virtual time the safe stop ends before a second signal comes):
    // after the first reset, the first tests are driving.
    let mut child = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args([
            "run",
            "--realtime",
            "--tests",
            "2",
            "--seed",
            "1",
            "--out",
            path(&out),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("drivecheck starts");
    std::thread::sleep(Duration::from_millis(9000));
    for _ in 0..2 {
        let killed = Command::new("kill")
            .args(["-INT", &child.id().to_string()])
            .status()
            .expect("kill runs");
        assert!(killed.success());
        std::thread::sleep(Duration::from_millis(100));
    }
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        // Half a second of grace after the second signal, and the machine's noise.
        assert!(
            started.elapsed() < Duration::from_secs(3),
            "drivecheck did not exit after the second signal"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut stderr).unwrap();
    assert_eq!(status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("again: braking at once"), "{stderr}");
    // The run directory is complete, every test in the summary has its case, and the tests in
    // flight name the hard brake.
    let record =
        CampaignRecord::from_json(&std::fs::read_to_string(out.join("campaign.json")).unwrap())
            .unwrap();
    assert!(record.ended_at.is_some());
    let summary = record.summary.expect("a summary");
    assert!(summary.aborted >= 1, "{summary:?}");
    let mut hard = 0;
    for test in 0..summary.tests {
        let case = Case::from_json(
            &std::fs::read_to_string(out.join(format!("case-{test:03}.json"))).unwrap(),
        )
        .unwrap();
        if case.verdict == Some(Verdict::Aborted) {
            let reason = case.reason.unwrap_or_default();
            assert!(reason.contains("interrupted"), "{reason}");
            hard += usize::from(reason.contains(campaign::drive::BRAKED_AT_ONCE));
        }
    }
    assert!(hard >= 1, "no case names the hard brake");
    let recording = Recording::read(&out.join("campaign.mcap")).unwrap();
    assert!(recording.is_complete(), "{:?}", recording.cut_short());
}
