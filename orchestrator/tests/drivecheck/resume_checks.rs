//! `drivecheck run --resume` trusts no case file of the run directory (#51 item 1): a case of
//! another campaign copied in, a case copied under another test's name and a case whose verdict
//! was edited are each refused, naming the file, before anything is driven (item 1); so are
//! another campaign's `campaign.json`, `campaign.mcap` and a stray `campaign.mcap.resumed`
//! (item 3), and the real recording is left where it was.

use crate::common;

use std::path::{Path, PathBuf};

use common::{drivecheck, path, run_unrecorded, text};

/// A run directory of 3 tests with seed 7 whose last case is gone (so that a resume has a test
/// to drive), and beside it a campaign of seed 8.
fn resumable(tmp: &Path) -> (PathBuf, PathBuf) {
    let (seven, eight) = (tmp.join("seven"), tmp.join("eight"));
    run_unrecorded(&["--seed", "7", "--tests", "3"], &seven);
    run_unrecorded(&["--seed", "8", "--tests", "3"], &eight);
    std::fs::remove_file(seven.join("case-002.json")).unwrap();
    (seven, eight)
}

/// Runs `--resume dir` and expects it refused with a message naming `file` and saying `why`.
fn assert_refused(dir: &Path, file: &str, why: &str) {
    let out = drivecheck(&["run", "--resume", path(dir), "--record", "none"]);
    let said = text(&out);
    assert_eq!(out.status.code(), Some(2), "{said}");
    assert!(said.contains(file), "names {file}: {said}");
    assert!(said.contains(why), "says {why:?}: {said}");
    assert!(
        !dir.join("case-002.json").exists(),
        "nothing was driven: {said}"
    );
}

#[test]
fn resume_refuses_another_campaigns_case() {
    let tmp = tempfile::tempdir().unwrap();
    let (seven, eight) = resumable(tmp.path());
    std::fs::copy(eight.join("case-001.json"), seven.join("case-001.json")).unwrap();
    assert_refused(
        &seven,
        "case-001.json",
        "campaign seed 8, the campaign's is 7",
    );
}

#[test]
fn resume_refuses_a_case_copied_under_another_tests_name() {
    let tmp = tempfile::tempdir().unwrap();
    let (seven, _) = resumable(tmp.path());
    std::fs::copy(seven.join("case-000.json"), seven.join("case-001.json")).unwrap();
    assert_refused(&seven, "case-001.json", "holds test 0, not test 1");
}

#[test]
fn resume_refuses_an_edited_verdict() {
    let tmp = tempfile::tempdir().unwrap();
    let (seven, _) = resumable(tmp.path());
    // A passed test written as failed, or one that did not pass written as passed.
    let file = seven.join("case-000.json");
    let mut case: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    let edited = if case["verdict"] == "passed" {
        "failed"
    } else {
        "passed"
    };
    case["verdict"] = serde_json::Value::from(edited);
    std::fs::write(&file, serde_json::to_string_pretty(&case).unwrap()).unwrap();
    assert_refused(&seven, "case-000.json", "verdict");
}

/// [`resumable`] with recordings.
fn recorded(tmp: &Path) -> (PathBuf, PathBuf) {
    let (seven, eight) = (tmp.join("seven"), tmp.join("eight"));
    for (seed, dir) in [("7", &seven), ("8", &eight)] {
        let out = drivecheck(&[
            "-q",
            "run",
            "--seed",
            seed,
            "--tests",
            "3",
            "--out",
            path(dir),
        ]);
        assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    }
    std::fs::remove_file(seven.join("case-002.json")).unwrap();
    (seven, eight)
}

#[test]
fn resume_refuses_another_campaigns_campaign_json() {
    let tmp = tempfile::tempdir().unwrap();
    let (seven, eight) = resumable(tmp.path());
    std::fs::copy(eight.join("campaign.json"), seven.join("campaign.json")).unwrap();
    assert_refused(&seven, "case-000.json", "campaign of campaign.json");
}

#[test]
fn resume_refuses_another_campaigns_recording() {
    let tmp = tempfile::tempdir().unwrap();
    let (seven, eight) = recorded(tmp.path());
    std::fs::copy(eight.join("campaign.mcap"), seven.join("campaign.mcap")).unwrap();
    assert_refused(&seven, "campaign.mcap", "seed 8");
}

#[test]
fn resume_refuses_a_stray_resumed_recording_and_keeps_the_real_one() {
    let tmp = tempfile::tempdir().unwrap();
    let (seven, eight) = recorded(tmp.path());
    let real = std::fs::read(seven.join("campaign.mcap")).unwrap();
    std::fs::copy(
        eight.join("campaign.mcap"),
        seven.join("campaign.mcap.resumed"),
    )
    .unwrap();
    assert_refused(&seven, "campaign.mcap.resumed", "seed 8");
    assert_eq!(
        std::fs::read(seven.join("campaign.mcap")).unwrap(),
        real,
        "the campaign's own recording is left as it was"
    );
}

/// `report`, `explain` (and `explain --score`) and `calibrate` read the recording beside the
/// case files only when it is of their campaign: another campaign's `campaign.mcap` is refused,
/// naming it and both seeds, and nothing is written (#51 item 3, the readers).
#[test]
fn the_readers_refuse_another_campaigns_recording_beside_the_cases() {
    let tmp = tempfile::tempdir().unwrap();
    let (seven, eight) = recorded(tmp.path());
    std::fs::copy(eight.join("campaign.mcap"), seven.join("campaign.mcap")).unwrap();
    let page = tmp.path().join("page.html");
    let profile = tmp.path().join("fitted.toml");
    let commands: [Vec<&str>; 4] = [
        vec!["report", path(&seven), "--out", path(&page)],
        vec!["explain", path(&seven)],
        vec!["explain", path(&seven), "--score"],
        vec!["calibrate", path(&seven), "--out", path(&profile)],
    ];
    for command in commands {
        let out = drivecheck(&command);
        let said = text(&out);
        assert_eq!(out.status.code(), Some(2), "{command:?}: {said}");
        assert!(
            said.contains("campaign.mcap") && said.contains("seed 8") && said.contains("seed 7"),
            "{command:?}: {said}"
        );
    }
    assert!(!page.exists() && !profile.exists());
}

/// A partial case (`case-NNN.partial-K.json`, the kept case of a test cut off) is a record of
/// what happened, never read back as a result: one tampered with (another campaign's, or not
/// JSON at all) changes nothing the resume drives or counts, and is left as it was.
#[test]
fn a_tampered_partial_changes_nothing_the_resume_drives_or_counts() {
    let tmp = tempfile::tempdir().unwrap();
    let (seven, eight) = resumable(tmp.path());
    let whole = tmp.path().join("whole");
    run_unrecorded(&["--seed", "7", "--tests", "3"], &whole);
    std::fs::copy(
        eight.join("case-002.json"),
        seven.join("case-002.partial-1.json"),
    )
    .unwrap();
    std::fs::write(seven.join("case-001.partial-1.json"), "not a case {").unwrap();
    let out = drivecheck(&["run", "--resume", path(&seven), "--record", "none"]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    let whole_cases = |dir: &Path| -> Vec<(String, String)> {
        common::cases(dir)
            .into_iter()
            .filter(|(name, _)| !name.contains(".partial-"))
            .collect()
    };
    assert_eq!(whole_cases(&whole), whole_cases(&seven));
    assert_eq!(common::summary(&whole), common::summary(&seven));
    assert_eq!(
        std::fs::read_to_string(seven.join("case-001.partial-1.json")).unwrap(),
        "not a case {"
    );
}

/// A campaign killed with `kill -9` as it wrote a case file leaves its temporary file
/// (`.case-002.json.tmp-PID`, #51 item 11): the resume removes it, saying so, and drives the test.
#[test]
fn resume_removes_the_temporary_file_of_a_killed_process() {
    let tmp = tempfile::tempdir().unwrap();
    let (seven, _) = resumable(tmp.path());
    // A pid above any pid_max (4194304): no process has it.
    let left = seven.join(".case-002.json.tmp-4294967295");
    std::fs::write(&left, "{\"half\": ").unwrap();
    let out = drivecheck(&["run", "--resume", path(&seven), "--record", "none"]);
    let said = text(&out);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{said}");
    assert!(!left.exists(), "{said}");
    assert!(
        said.contains(&format!("removed {}", left.display()))
            && said.contains("left by process 4294967295, which no longer runs"),
        "{said}"
    );
    assert!(seven.join("case-002.json").is_file(), "{said}");
}

/// A campaign driven on a scenario file that bears a bundled scenario's name is not resumed on
/// the bundled one (what `--resume` loads when no `--scenario` is given): the refusal says
/// which scenario the campaign drove and to give its file, and the resume with the file drives
/// the missing test.
#[test]
fn a_campaign_on_a_file_named_like_a_bundled_scenario_is_resumed_with_its_file() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = common::short_tests(tmp.path());
    let run = tmp.path().join("run");
    run_unrecorded(
        &["--scenario", path(&scenario), "--seed", "7", "--tests", "2"],
        &run,
    );
    std::fs::remove_file(run.join("case-001.json")).unwrap();
    let out = drivecheck(&["run", "--resume", path(&run), "--record", "none"]);
    let said = text(&out);
    assert_eq!(out.status.code(), Some(2), "{said}");
    assert!(
        said.contains("the campaign drove scenario `parking-lot-2anchors` (hash ")
            && said.contains("not the bundled `parking-lot-2anchors`")
            && said.contains("give the file it drove with --scenario")
            && !said.contains("leave --scenario out"),
        "{said}"
    );
    assert!(!run.join("case-001.json").exists(), "{said}");
    let out = drivecheck(&[
        "run",
        "--resume",
        path(&run),
        "--scenario",
        path(&scenario),
        "--record",
        "none",
    ]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    assert!(run.join("case-001.json").is_file(), "{}", text(&out));
}

/// A campaign goes on on the kind of car it drove: one that drove a car behind a link is not
/// finished on the embedded simulated car (`--car`'s default, so forgetting `--car` would do
/// it), and a simulated campaign is not finished on a car; both refused before anything drives.
#[test]
fn resume_refuses_another_kind_of_car() {
    let tmp = tempfile::tempdir().unwrap();
    let (seven, _) = resumable(tmp.path());
    let out = drivecheck(&[
        "run",
        "--resume",
        path(&seven),
        "--record",
        "none",
        "--car",
        "tcp://127.0.0.1:9",
    ]);
    let said = text(&out);
    assert_eq!(out.status.code(), Some(2), "{said}");
    assert!(
        said.contains("the campaign drove the embedded simulated car (sim)")
            && said.contains("is a car behind a link"),
        "{said}"
    );
    let file = seven.join("campaign.json");
    let record = std::fs::read_to_string(&file).unwrap();
    std::fs::write(
        &file,
        record.replace("\"car\": \"sim\"", "\"car\": \"tcp://127.0.0.1:9\""),
    )
    .unwrap();
    let out = drivecheck(&["run", "--resume", path(&seven), "--record", "none"]);
    let said = text(&out);
    assert_eq!(out.status.code(), Some(2), "{said}");
    assert!(
        said.contains("the campaign drove a car behind a link (tcp://127.0.0.1:9)")
            && said.contains("--car sim is the embedded simulated car"),
        "{said}"
    );
    assert!(!seven.join("case-002.json").exists(), "{said}");
}

/// A campaign that fills its disk (#51 item 2) ends with the error that stopped it, and its
/// session's end is in `campaign.json` — not left for the resume to take for a session that
/// died: the space the run directory kept back (`.drivecheck-reserve`) is given back for it.
/// Moved to a disk with room, the resume then ends with the uninterrupted run's cases. The full
/// disk is a 1 MiB tmpfs in a mount namespace of the test's own (`unshare`).
#[test]
fn a_campaign_that_fills_its_disk_records_its_end_and_is_resumed() {
    let tmp = tempfile::tempdir().unwrap();
    let (full, moved, whole) = (
        tmp.path().join("full"),
        tmp.path().join("moved"),
        tmp.path().join("whole"),
    );
    std::fs::create_dir(&full).unwrap();
    // One shell in its own mount namespace: the tmpfs is gone when it ends, so the run
    // directory is copied out first.
    let script = format!(
        "mount -t tmpfs -o size=1m tmpfs '{full}' || exit 99; \
         '{bin}' run --seed 3 --tests 10 --out '{full}/run' 2>&1; echo \"exit $?\"; \
         cp -a '{full}/run' '{moved}'",
        full = path(&full),
        moved = path(&moved),
        bin = env!("CARGO_BIN_EXE_drivecheck"),
    );
    let out = std::process::Command::new("unshare")
        .args(["--map-root-user", "--mount", "sh", "-c", &script])
        .output();
    let out = match out {
        Ok(out) if out.status.code() != Some(99) && out.status.success() => out,
        Ok(out) => {
            return common::skipped(
                "tmpfs",
                &format!("no tmpfs in a mount namespace of its own: {}", text(&out)),
            );
        }
        Err(e) => return common::skipped("tmpfs", &format!("no unshare: {e}")),
    };
    let said = text(&out);
    assert!(said.contains("exit 2"), "a full disk is an error: {said}");
    assert!(said.contains("No space left on device"), "{said}");
    assert!(
        !said.contains("campaign.json: No space"),
        "the campaign's end was written: {said}"
    );
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(moved.join("campaign.json")).unwrap())
            .unwrap();
    assert!(record["ended_at"].is_string(), "{record:#}");
    assert!(
        !moved.join(".drivecheck-reserve").exists(),
        "the reserve was given back"
    );

    let resumed = drivecheck(&["run", "--resume", path(&moved)]);
    assert!(
        matches!(resumed.status.code(), Some(0 | 1)),
        "{}",
        text(&resumed)
    );
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(moved.join("campaign.json")).unwrap())
            .unwrap();
    assert_eq!(record["sessions"][0]["end"], "interrupted", "{record:#}");
    assert_eq!(record["sessions"][1]["end"], "completed", "{record:#}");
    assert!(!moved.join(".drivecheck-reserve").exists());

    let uninterrupted = drivecheck(&[
        "-q",
        "run",
        "--seed",
        "3",
        "--tests",
        "10",
        "--out",
        path(&whole),
    ]);
    assert!(matches!(uninterrupted.status.code(), Some(0 | 1)));
    // A test the full disk cut off is kept as a partial case beside the one driven again.
    let mut cases = common::cases(&moved);
    cases.retain(|name, _| !name.contains(".partial-"));
    assert_eq!(cases, common::cases(&whole));
}
