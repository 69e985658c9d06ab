//! `drivecheck run` end to end on the embedded simulated car in virtual time: the exit status
//! says whether every test passed, and the run directory holds the campaign and its cases.

use crate::common;

use common::{campaign, drivecheck, path, text};

use std::process::{Command, Output};

fn run(args: &[&str], out: &std::path::Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .arg("run")
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .expect("the drivecheck binary runs")
}

#[test]
fn a_campaign_with_faults_that_finds_a_failure_exits_one() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["--seed", "1", "--tests", "3"], dir.path());
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("| failed |"));
    for file in [
        "campaign.json",
        "case-000.json",
        "case-001.json",
        "case-002.json",
    ] {
        assert!(dir.path().join(file).is_file(), "{file} missing");
    }
}

#[test]
fn the_same_campaign_without_faults_passes_and_exits_zero() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["--seed", "1", "--tests", "3", "--no-faults"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(String::from_utf8_lossy(&out.stderr).contains("seed 1"));
}

#[test]
fn an_unknown_car_address_is_an_error_with_exit_two() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["--car", "carrier-pigeon://7"], dir.path());
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
}

#[test]
fn continuing_after_a_failure_drives_and_records_every_segment() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(
        &["--seed", "1", "--tests", "4", "--on-failure", "continue"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let record = std::fs::read_to_string(dir.path().join("campaign.json")).unwrap();
    assert!(record.contains("\"failure_policy\": \"continue_and_record\""));
    let failed: Vec<campaign::files::Case> = (0..4)
        .map(|i| {
            let text =
                std::fs::read_to_string(dir.path().join(format!("case-{i:03}.json"))).unwrap();
            campaign::files::Case::from_json(&text).unwrap()
        })
        .filter(|c| c.verdict == Some(campaign::oracle::Verdict::Failed))
        .collect();
    assert!(!failed.is_empty());
    for case in failed {
        let segments = case
            .commands
            .iter()
            .filter(|c| matches!(c, campaign::files::CommandRecord::RunSegments { .. }))
            .count();
        // Every segment was driven and judged, not only those up to the first failure.
        assert_eq!(case.segments.len(), segments, "{:?}", case.reason);
    }
}

#[test]
fn a_stale_limit_beyond_the_watchdog_is_refused_and_a_valid_one_is_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["--stale-after", "3s"], dir.path());
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    // The limit in the unit the user typed (it said "at most 1s 900ms").
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("--stale-after 3s: must be above 0 and at most 1.9 s")
            && said.contains("brakes after 2 s without commands"),
        "{said}"
    );
    let out = run(&["--stale-after", "2500ms"], dir.path());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("at most 1900 ms"),
        "{}",
        text(&out)
    );
    let out = run(
        &[
            "--seed",
            "2",
            "--tests",
            "1",
            "--no-faults",
            "--stale-after",
            "400ms",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let record = std::fs::read_to_string(dir.path().join("campaign.json")).unwrap();
    assert!(record.contains("\"stale_after\": 400"), "{record}");
}

#[test]
fn a_run_directory_is_never_reused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let first = run(&["--seed", "3", "--tests", "1", "--no-faults"], &out);
    assert_eq!(first.status.code(), Some(0), "{}", text(&first));
    let record = std::fs::read(out.join("campaign.json")).unwrap();
    let files = std::fs::read_dir(&out).unwrap().count();
    // A second campaign into the same directory is refused before anything is written.
    let second = run(&["--seed", "4", "--tests", "2"], &out);
    assert_eq!(second.status.code(), Some(2), "{}", text(&second));
    assert!(
        text(&second).contains("exists and is not empty"),
        "{}",
        text(&second)
    );
    assert_eq!(std::fs::read(out.join("campaign.json")).unwrap(), record);
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), files);
    // So is a replay into it.
    let case = out.join("case-000.json");
    let replay = Command::new(env!("CARGO_BIN_EXE_drivecheck"))
        .args(["replay", case.to_str().unwrap(), "--times", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(replay.status.code(), Some(2), "{}", text(&replay));
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), files);
    // An empty directory is fine.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let fresh = run(&["--seed", "3", "--tests", "1", "--no-faults"], &empty);
    assert_eq!(fresh.status.code(), Some(0), "{}", text(&fresh));
}

#[test]
fn a_simulated_campaign_records_the_simulators_debug_channels() {
    use recording::{Recording, Topic};
    let dir = tempfile::tempdir().unwrap();
    let run = campaign(dir.path(), 2, 2, &[], 0);
    let recording = Recording::read(&run.join("campaign.mcap")).unwrap();
    // Every simulated range, and (seed 2 has faults) every fault application inside the car.
    assert!(
        recording.count(Topic::SimRanges) > 100,
        "{}",
        recording.count(Topic::SimRanges)
    );
    assert!(recording.count(Topic::SimFaults) > 0);
    assert!(recording.count(Topic::SimTruth) > 100);
}

#[test]
fn a_scenario_without_anchors_runs_only_when_allowed_and_says_uwb_was_not_tested() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("refused");
    let refused = drivecheck(&[
        "run",
        "--scenario",
        "courtyard",
        "--tests",
        "1",
        "--out",
        path(&out),
    ]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    assert!(text(&refused).contains("--allow-no-anchors"));
    assert!(!out.exists(), "nothing written");
    let run = campaign(
        dir.path(),
        1,
        1,
        &["--scenario", "courtyard", "--allow-no-anchors"],
        0,
    );
    let record = campaign::files::CampaignRecord::from_json(
        &std::fs::read_to_string(run.join("campaign.json")).unwrap(),
    )
    .unwrap();
    let why = record.summary.unwrap().uwb_not_tested.expect("said");
    assert!(why.contains("no anchors"), "{why}");
}

/// A real area whose recovery route ends 3.77 m from the start route (the straight step may be
/// 3 m): it loads with a warning, and every reset drives a planned join onto the start route, so
/// the tests run as in the full area. Before, the scenario was refused at load.
#[test]
fn a_recovery_route_ending_far_from_the_start_route_is_joined_by_a_planned_route() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/short-recovery.toml"
    );
    let out = run(
        &[
            "--scenario",
            scenario,
            "--seed",
            "1",
            "--tests",
            "2",
            "--no-faults",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("the recovery route ends 3.77 m from start_route[0]")
            && stderr.contains("the reset plans a route between them")
            && stderr.contains("every reset drives a planned join of"),
        "{}",
        text(&out)
    );
}

/// What a campaign covered is in `campaign.json`, in `runs show --coverage` and in the report: the
/// share of the area driven, headings and speeds, fault types per probe, segments per test.
#[test]
fn a_campaign_records_and_shows_what_it_covered() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["--seed", "1", "--tests", "3"], dir.path());
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let record = campaign::files::CampaignRecord::from_json(
        &std::fs::read_to_string(dir.path().join("campaign.json")).unwrap(),
    )
    .unwrap();
    let coverage = record.summary.unwrap().coverage.unwrap();
    assert_eq!(coverage.tests, 3);
    assert!(
        coverage.area_share > 0.1 && coverage.area_share <= 1.0,
        "{coverage:?}"
    );
    assert!(coverage.heading_m.iter().sum::<f64>() > 10.0);
    assert!(!coverage.faults.is_empty());
    assert!(
        coverage
            .faults
            .iter()
            .all(|f| f.acted <= f.confirmed && f.confirmed <= f.planned)
    );
    assert_eq!(coverage.segments_per_test.iter().sum::<usize>(), 3);
    let shown = drivecheck(&["runs", "show", path(dir.path()), "--coverage"]);
    assert_eq!(shown.status.code(), Some(0), "{}", text(&shown));
    let shown = String::from_utf8_lossy(&shown.stdout);
    assert!(
        shown.contains("coverage of 3 tests:") && shown.contains("| uwb_"),
        "{shown}"
    );
    let report = drivecheck(&["report", path(dir.path())]);
    assert_eq!(report.status.code(), Some(0), "{}", text(&report));
    let page = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(page.contains("<section id=\"coverage\">"));
}

/// An error before the first test (a car that cannot be reached, a bad setting) leaves no run
/// directory behind — neither `run`'s nor `replay`'s — and an existing empty `--out` stays.
#[test]
fn an_error_before_the_first_test_leaves_no_run_directory() {
    let dir = tempfile::tempdir().unwrap();
    // A port nothing listens on: bound, then released.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let car = format!("tcp://127.0.0.1:{port}");
    let out = dir.path().join("run");
    let refused = drivecheck(&["run", "--car", &car, "--tests", "1", "--out", path(&out)]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    assert!(!out.exists(), "{}", text(&refused));
    let stale = drivecheck(&["run", "--stale-after", "0s", "--out", path(&out)]);
    assert_eq!(stale.status.code(), Some(2), "{}", text(&stale));
    assert!(!out.exists());
    let case = campaign(dir.path(), 3, 1, &[], 0).join("case-000.json");
    let replay = dir.path().join("replay");
    let refused = drivecheck(&["replay", path(&case), "--car", &car, "--out", path(&replay)]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    assert!(!replay.exists(), "{}", text(&refused));
    let mine = dir.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    let refused = drivecheck(&["run", "--car", &car, "--out", path(&mine)]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    assert!(mine.is_dir(), "a directory the user made stays");
    let once = text(&refused);
    assert_eq!(
        once.matches("Connection refused").count(),
        1,
        "the cause once: {once}"
    );
}

/// `--junit` is checked before anything is driven: a missing directory, or a path inside the run
/// directory (where it would replace `campaign.json`), is an error that names the flag.
#[test]
fn a_junit_path_is_checked_before_the_campaign() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let missing = dir.path().join("no/such/dir/junit.xml");
    let refused = drivecheck(&[
        "run",
        "--tests",
        "1",
        "--out",
        path(&out),
        "--junit",
        path(&missing),
    ]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    assert!(text(&refused).contains("--junit"), "{}", text(&refused));
    assert!(!out.exists(), "nothing was driven: {}", text(&refused));
    let inside = out.join("campaign.json");
    let refused = drivecheck(&[
        "run",
        "--tests",
        "1",
        "--out",
        path(&out),
        "--junit",
        path(&inside),
    ]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    assert!(
        text(&refused).contains("inside the run directory"),
        "{}",
        text(&refused)
    );
    assert!(!out.exists());
}

#[test]
fn of_two_campaigns_given_the_same_out_at_once_one_is_refused_and_nothing_is_mixed() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("R");
    for attempt in 0..3 {
        let _ = std::fs::remove_dir_all(&out);
        let spawn = |seed: &str| {
            Command::new(env!("CARGO_BIN_EXE_drivecheck"))
                .args(["run", "-q", "--tests", "2", "--seed", seed, "--out"])
                .arg(&out)
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .expect("the drivecheck binary runs")
        };
        let (a, b) = (spawn("11"), spawn("12"));
        let outputs = [a.wait_with_output().unwrap(), b.wait_with_output().unwrap()];
        let refused: Vec<&Output> = outputs
            .iter()
            .filter(|o| o.status.code() == Some(2))
            .collect();
        assert_eq!(refused.len(), 1, "attempt {attempt}: {outputs:?}");
        let said = text(refused[0]);
        assert!(
            said.contains("another drivecheck process is writing it")
                || said.contains("exists and is not empty"),
            "{said}"
        );
        // The winner's campaign and every case in the directory are of one seed.
        let record: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("campaign.json")).unwrap())
                .unwrap();
        let seed = &record["seed"];
        for case in ["case-000.json", "case-001.json"] {
            let case: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(out.join(case)).unwrap()).unwrap();
            assert_eq!(&case["campaign_seed"], seed, "attempt {attempt}");
        }
        assert!(!out.join(".drivecheck-writing").exists());
    }
}

/// A claim file left by a process that died (a SIGTERM before the signal handler, a kill -9
/// during `run --report`) does not block the directory for ever: `run -o DIR` takes it over and
/// says so; the claim of a live process (this test's) is still refused.
#[test]
fn a_stale_claim_is_taken_over_and_a_live_one_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("R");
    std::fs::create_dir(&out).unwrap();
    let claim = out.join(".drivecheck-writing");
    // A pid above any pid_max (4194304) is no process.
    std::fs::write(&claim, "pid 4294967295 since 2026-12-02T10:00:00Z\n").unwrap();
    let taken = run(&["--seed", "3", "--tests", "1", "--no-faults"], &out);
    assert_eq!(taken.status.code(), Some(0), "{}", text(&taken));
    assert!(
        text(&taken).contains(&format!(
            "{}: took over a stale claim (pid 4294967295 since 2026-12-02T10:00:00Z): that \
             process no longer runs",
            out.display()
        )),
        "{}",
        text(&taken)
    );
    assert!(out.join("campaign.json").is_file());
    assert!(!claim.exists(), "the run gave its own claim back");
    // A live process's claim, on an empty directory.
    let live = dir.path().join("live");
    std::fs::create_dir(&live).unwrap();
    let held = format!("pid {} since 2026-12-02T10:00:00Z\n", std::process::id());
    std::fs::write(live.join(".drivecheck-writing"), &held).unwrap();
    let refused = run(&["--seed", "3", "--tests", "1", "--no-faults"], &live);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused));
    assert!(
        text(&refused).contains(&format!(
            "another drivecheck process is writing it (pid {} since",
            std::process::id()
        )),
        "{}",
        text(&refused)
    );
    assert_eq!(
        std::fs::read_to_string(live.join(".drivecheck-writing")).unwrap(),
        held
    );
    assert_eq!(std::fs::read_dir(&live).unwrap().count(), 1);
}
