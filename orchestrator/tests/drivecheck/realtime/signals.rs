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

/// Starts `drivecheck ARGS` with `DRIVECHECK_PAUSE=pause`, waits (at most 3 minutes) until it
/// says it paused there, sends it SIG`signal` and waits (at most 30 s) for it to end: its exit
/// status and standard error.
fn interrupt_when_paused(args: &[&str], pause: &str, signal: &str) -> (Option<i32>, String, u32) {
    use std::io::BufRead;
    let mut child = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(args)
        .env("DRIVECHECK_PAUSE", pause)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("drivecheck starts");
    let pid = child.id();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        for line in std::io::BufReader::new(stderr).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut said = String::new();
    let started = Instant::now();
    loop {
        let remaining = Duration::from_secs(180).saturating_sub(started.elapsed());
        match rx.recv_timeout(remaining) {
            Ok(line) => {
                said.push_str(&line);
                said.push('\n');
                if line.starts_with("drivecheck: paused in") {
                    break;
                }
            }
            Err(_) => {
                let _ = child.kill();
                panic!("drivecheck did not pause at {pause}: {said}");
            }
        }
    }
    let killed = Command::new("kill")
        .args([&format!("-{signal}"), &pid.to_string()])
        .status()
        .expect("kill runs");
    assert!(killed.success());
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if started.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            panic!("drivecheck did not end after SIG{signal}: {said}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    reader.join().unwrap();
    said.extend(rx.try_iter().map(|line| line + "\n"));
    (status.code(), said, pid)
}

/// The scratch files in `dir` (`.NAME.tmp-PID`, `.NAME.sections-PID`, `.NAME.staging-PID`).
fn scratch_in(dir: &std::path::Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| runner::scratch::scratch_of(n).is_some())
        .collect()
}

/// A recorded campaign of `tests` tests with seed 1 in `dir/run`.
fn recorded_run(dir: &std::path::Path, tests: &str, extra: &[&str]) -> std::path::PathBuf {
    let run = dir.join("run");
    let mut args = vec!["-q", "run", "--seed", "1", "--tests", tests];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", path(&run)]);
    let out = common::drivecheck(&args);
    assert!(
        matches!(out.status.code(), Some(0 | 1)),
        "{}",
        common::text(&out)
    );
    run
}

/// `report` interrupted by SIGINT half way (#51 item 11): it used to die of the signal (130)
/// and leave its sections (`.report.html.sections-PID`, megabytes); now it exits 2, as every
/// interrupted command, and leaves no scratch file and no page.
#[test]
fn a_report_interrupted_by_sigint_exits_2_and_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let run = recorded_run(dir.path(), "3", &[]);
    let (code, said, _) =
        interrupt_when_paused(&["report", path(&run), "--all-tests"], "report:1", "INT");
    assert_eq!(code, Some(2), "{said}");
    assert!(said.contains("error: interrupted (SIGINT)"), "{said}");
    assert_eq!(scratch_in(&run), Vec::<String>::new(), "{said}");
    assert!(!run.join("report.html").exists(), "{said}");
}

/// `runs merge` interrupted by SIGTERM half way (#51 item 11): exit 2, its staging directory
/// (`.OUT.staging-PID`) removed, nothing at the output.
#[test]
fn runs_merge_interrupted_by_sigterm_exits_2_and_leaves_no_staging_directory() {
    let dir = tempfile::tempdir().unwrap();
    let shard = |k: &str| dir.path().join(format!("shard{}", &k[..1]));
    for k in ["1/2", "2/2"] {
        let out = common::drivecheck(&[
            "-q",
            "run",
            "--seed",
            "7",
            "--tests",
            "4",
            "--shard",
            k,
            "--out",
            path(&shard(k)),
        ]);
        assert!(
            matches!(out.status.code(), Some(0 | 1)),
            "{}",
            common::text(&out)
        );
    }
    let merged = dir.path().join("merged");
    let (code, said, _) = interrupt_when_paused(
        &[
            "runs",
            "merge",
            path(&shard("1/2")),
            path(&shard("2/2")),
            "--out",
            path(&merged),
        ],
        "merge:1",
        "TERM",
    );
    assert_eq!(code, Some(2), "{said}");
    assert!(said.contains("error: terminated (SIGTERM)"), "{said}");
    assert_eq!(scratch_in(dir.path()), Vec::<String>::new(), "{said}");
    assert!(!merged.exists(), "{said}");
}

/// `explain --score` interrupted by SIGINT in its counterfactual runs (#51 item 11): exit 2,
/// saying it was interrupted, no score printed from runs the signal cut off, and its scratch
/// directory removed.
#[test]
fn explain_score_interrupted_in_its_counterfactual_runs_says_so_and_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let run = recorded_run(dir.path(), "6", &["--on-failure", "continue"]);
    let (code, said, pid) = interrupt_when_paused(
        &["explain", path(&run), "--score"],
        "counterfactual:0",
        "INT",
    );
    assert_eq!(code, Some(2), "{said}");
    assert!(said.contains("interrupted by a signal"), "{said}");
    let scratch = std::env::temp_dir().join(format!("drivecheck-counterfactual-{pid}"));
    assert!(!scratch.exists(), "{said}");
}

/// `twin check` interrupted by SIGINT (#51 item 12 d): it said the case "cannot be driven
/// again"; now it says it was interrupted and exits 2, writing no `twin.json`.
#[test]
fn an_interrupted_twin_check_says_interrupted_and_does_not_blame_the_case() {
    let dir = tempfile::tempdir().unwrap();
    let run = recorded_run(dir.path(), "2", &[]);
    let (code, said, _) = interrupt_when_paused(
        &["twin", "check", path(&run), "--runs", "1"],
        "twin:0",
        "INT",
    );
    assert_eq!(code, Some(2), "{said}");
    assert!(said.contains("interrupted by a signal"), "{said}");
    assert!(!said.contains("cannot be driven again"), "{said}");
    assert!(!run.join("twin.json").exists(), "{said}");
}

/// Under `nohup` (SIGHUP ignored when drivecheck starts) a hangup is ignored, as `nohup` asks;
/// SIGINT still interrupts.
#[test]
fn under_nohup_a_hangup_is_ignored_and_sigint_still_interrupts() {
    use std::io::BufRead;
    let dir = tempfile::tempdir().unwrap();
    let run = recorded_run(dir.path(), "3", &[]);
    let mut child = Command::new("nohup")
        .arg(env!("CARGO_BIN_EXE_drivecheck"))
        .args(["report", path(&run), "--all-tests"])
        .env("DRIVECHECK_PAUSE", "report:1")
        .current_dir(dir.path())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("nohup drivecheck starts");
    let mut stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut said = String::new();
    while !said.contains("drivecheck: paused in report") {
        let mut line = String::new();
        assert!(stderr.read_line(&mut line).unwrap() > 0, "{said}");
        said.push_str(&line);
    }
    let pid = child.id().to_string();
    let send = |signal: &str| {
        let sent = Command::new("kill").args([signal, &pid]).status().unwrap();
        assert!(sent.success());
    };
    send("-HUP");
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "a hangup ended it: {said}"
    );
    send("-INT");
    let status = child.wait().unwrap();
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut stderr, &mut rest).unwrap();
    assert_eq!(status.code(), Some(2), "{said}{rest}");
    assert!(rest.contains("error: interrupted (SIGINT)"), "{said}{rest}");
}

/// `explain --score` interrupted by SIGTERM while it reads the recording (#51 item 11): it died
/// of the signal (143); now it exits 2 saying so.
#[test]
fn explain_score_interrupted_while_it_reads_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let run = recorded_run(dir.path(), "3", &["--on-failure", "continue"]);
    let (code, said, _) = interrupt_when_paused(
        &[
            "explain",
            path(&run),
            "--score",
            "--counterfactual-runs",
            "0",
        ],
        "score:1",
        "TERM",
    );
    assert_eq!(code, Some(2), "{said}");
    assert!(said.contains("error: terminated (SIGTERM)"), "{said}");
}
