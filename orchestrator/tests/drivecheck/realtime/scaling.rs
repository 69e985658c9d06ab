//! Large campaigns end to end (`docs/scaling.md`): a campaign run serially, with `--jobs 2`, and
//! as shards merged with `runs merge` gives the same case files and summary; the merged recording
//! holds the same messages as the unsharded one; the Kubernetes and Slurm examples' shard commands
//! run as plain shell and merge; merge refuses what is not one campaign.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{
    assert_same_campaign, assert_same_messages, cases, documented, drivecheck, messages, path,
    summary, text,
};
use recording::Recording;

/// `drivecheck run --seed SEED --tests TESTS [extra] --out DIR`; its exit status must be 0 or 1.
fn run(seed: u64, tests: usize, extra: &[&str], out: &Path) {
    let (seed, tests) = (seed.to_string(), tests.to_string());
    let mut args = vec!["run", "--seed", &seed, "--tests", &tests];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--out", path(out)]);
    let output = drivecheck(&args);
    assert!(
        matches!(output.status.code(), Some(0 | 1)),
        "{}",
        text(&output)
    );
}

#[test]
fn two_jobs_and_two_merged_shards_give_the_serial_runs_case_files() {
    let dir = tempfile::tempdir().unwrap();
    let (serial, jobs, merged) = (
        dir.path().join("serial"),
        dir.path().join("jobs"),
        dir.path().join("merged"),
    );
    let none = ["--record", "none"];
    run(3, 200, &[&["--jobs", "1"], &none[..]].concat(), &serial);
    run(3, 200, &[&["--jobs", "2"], &none[..]].concat(), &jobs);
    let shards: Vec<PathBuf> = (1..=2)
        .map(|k| dir.path().join(format!("shard-{k}")))
        .collect();
    for (k, shard) in shards.iter().enumerate() {
        let arg = format!("{}/2", k + 1);
        run(3, 200, &[&["--shard", &arg], &none[..]].concat(), shard);
        assert_eq!(cases(shard).len(), 100);
    }
    let junit = dir.path().join("merged.xml");
    let out = drivecheck(&[
        "runs",
        "merge",
        path(&shards[1]),
        path(&shards[0]),
        "--out",
        path(&merged),
        "--junit",
        path(&junit),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let xml = std::fs::read_to_string(&junit).unwrap();
    assert_eq!(xml.matches("<testcase ").count(), 200, "{xml}");
    assert_eq!(cases(&serial).len(), 200);
    assert_same_campaign(&serial, &jobs);
    assert_same_campaign(&serial, &merged);
    assert!(summary(&serial)["failed"].as_u64().unwrap() > 0);
}

#[test]
fn a_merged_recording_holds_the_unsharded_runs_messages_and_failing_keeps_the_failed_tests() {
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole");
    run(5, 12, &["--jobs", "2"], &whole);
    let shards: Vec<PathBuf> = (1..=3)
        .map(|k| dir.path().join(format!("shard-{k}")))
        .collect();
    for (k, shard) in shards.iter().enumerate() {
        run(5, 12, &["--shard", &format!("{}/3", k + 1)], shard);
    }
    let merged = dir.path().join("merged");
    let mut args = vec!["runs", "merge"];
    args.extend(shards.iter().map(|s| path(s)));
    args.extend(["--out", path(&merged)]);
    let out = drivecheck(&args);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert_same_campaign(&whole, &merged);
    let a = messages(&whole);
    assert!(a.len() > 1000, "{}", a.len());
    assert_same_messages(&whole, &merged);
    // `explain` reads the merged recording as the whole one.
    let explained = |dir: &Path| {
        let out = drivecheck(&["explain", path(dir), "--json"]);
        String::from_utf8_lossy(&out.stdout).replace(path(dir), "RUN")
    };
    assert_eq!(explained(&whole), explained(&merged));

    // --record failing keeps the failing tests' messages only: each test's span is kept whole.
    let failing = dir.path().join("failing");
    run(5, 12, &["--record", "failing"], &failing);
    assert_same_campaign(&whole, &failing);
    let recording = Recording::read(&failing.join("campaign.mcap")).unwrap();
    let kept: Vec<usize> = recording
        .metadata_names()
        .filter_map(|n| n.strip_prefix("drivecheck.test.")?.parse().ok())
        .collect();
    let failed: Vec<usize> = cases(&failing)
        .values()
        .map(|text| serde_json::from_str::<serde_json::Value>(text).unwrap())
        .filter(|case| case["verdict"] != "passed")
        .map(|case| case["test_index"].as_u64().unwrap() as usize)
        .collect();
    let mut kept_sorted = kept.clone();
    kept_sorted.sort_unstable();
    let mut failed_sorted = failed.clone();
    failed_sorted.sort_unstable();
    assert!(!failed.is_empty() && failed.len() < 12, "{failed:?}");
    assert_eq!(kept_sorted, failed_sorted);
    assert!(messages(&failing).len() < a.len());
}

#[test]
fn merge_refuses_other_campaigns_and_names_the_missing_shards() {
    let dir = tempfile::tempdir().unwrap();
    let shard = |seed: u64, k: usize, n: usize| {
        let out = dir.path().join(format!("s{seed}-{k}of{n}"));
        run(
            seed,
            4,
            &["--shard", &format!("{k}/{n}"), "--record", "none"],
            &out,
        );
        out
    };
    let merge = |dirs: &[&Path], out: &str| {
        let out = dir.path().join(out);
        let mut args = vec!["runs", "merge"];
        args.extend(dirs.iter().map(|d| path(d)));
        args.extend(["--out", path(&out)]);
        drivecheck(&args)
    };
    let (a1, a3, b2) = (shard(1, 1, 3), shard(1, 3, 3), shard(2, 2, 3));
    let shown = drivecheck(&["runs", "show", path(&a1)]);
    assert!(
        String::from_utf8_lossy(&shown.stdout).contains("shard 1/3 of a 4-test campaign"),
        "{}",
        text(&shown)
    );
    let missing = merge(&[&a1, &a3], "m1");
    assert_eq!(missing.status.code(), Some(2), "{}", text(&missing));
    assert!(
        String::from_utf8_lossy(&missing.stderr).contains("shards missing: 2/3"),
        "{}",
        text(&missing)
    );
    let other = merge(&[&a1, &b2, &a3], "m2");
    assert_eq!(other.status.code(), Some(2), "{}", text(&other));
    assert!(
        String::from_utf8_lossy(&other.stderr).contains("seed 1 and 2"),
        "{}",
        text(&other)
    );
    let twice = merge(&[&a1, &a1, &a3], "m3");
    assert!(
        String::from_utf8_lossy(&twice.stderr).contains("given twice"),
        "{}",
        text(&twice)
    );
    // More shards than tests: shard 6/6 of 4 tests holds none, ends well, and merges.
    let empty = dir.path().join("empty");
    let out = drivecheck(&[
        "run",
        "--seed",
        "1",
        "--tests",
        "4",
        "--shard",
        "6/6",
        "--out",
        path(&empty),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(cases(&empty).is_empty());
    let whole = dir.path().join("whole");
    run(1, 4, &["--record", "none"], &whole);
    let not_a_shard = merge(&[&whole], "m4");
    assert!(
        String::from_utf8_lossy(&not_a_shard.stderr).contains("not a shard"),
        "{}",
        text(&not_a_shard)
    );
    assert!(!dir.path().join("m1").exists() && !dir.path().join("m2").exists());
}

#[test]
fn a_shard_with_a_damaged_recording_leaves_nothing_where_the_merge_was_to_go() {
    let dir = tempfile::tempdir().unwrap();
    let shards: Vec<_> = (1..=2)
        .map(|k| {
            let out = dir.path().join(format!("s{k}"));
            run(5, 4, &["--shard", &format!("{k}/2")], &out);
            out
        })
        .collect();
    // The second shard's recording cut in half, as a copy interrupted would leave it.
    let mcap = shards[1].join("campaign.mcap");
    let bytes = std::fs::read(&mcap).unwrap();
    std::fs::write(&mcap, &bytes[..bytes.len() / 2]).unwrap();
    let out = dir.path().join("merged");
    let merged = drivecheck(&[
        "runs",
        "merge",
        path(&shards[0]),
        path(&shards[1]),
        "--out",
        path(&out),
    ]);
    assert_eq!(merged.status.code(), Some(2), "{}", text(&merged));
    assert!(!out.exists(), "{}", text(&merged));
    // Nothing staged is left beside it either, and `runs` lists only the two shards.
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left.len(), 2, "{left:?}");
}

/// Runs `command` with `sh -c` in `dir`, the `drivecheck` under test first on the path.
fn shell(command: &str, dir: &Path, env: &[(&str, String)]) {
    let path_var = common::path_with_drivecheck();
    let output = Command::new("sh")
        .arg("-c")
        .arg(command)
        .current_dir(dir)
        .env("PATH", path_var)
        .envs(env.iter().map(|(k, v)| (*k, v.as_str())))
        .output()
        .unwrap();
    assert!(
        matches!(output.status.code(), Some(0 | 1)),
        "{command}: {}",
        text(&output)
    );
}

#[test]
fn the_kubernetes_and_slurm_examples_run_as_shell_and_merge() {
    let dir = tempfile::tempdir().unwrap();
    let serial = dir.path().join("serial");
    run(9, 6, &["--record", "failing"], &serial);
    let common = |extra: Vec<(&'static str, String)>| {
        let mut env = vec![
            ("SEED", "9".to_owned()),
            ("TESTS", "6".to_owned()),
            ("SHARDS", "3".to_owned()),
        ];
        env.extend(extra);
        env
    };
    for engine in ["kubernetes", "slurm"] {
        let work = dir.path().join(engine);
        std::fs::create_dir(&work).unwrap();
        let command = documented(engine);
        for index in 0..3 {
            let env = match engine {
                "kubernetes" => common(vec![("JOB_COMPLETION_INDEX", index.to_string())]),
                _ => common(vec![
                    ("SLURM_ARRAY_TASK_ID", (index + 1).to_string()),
                    ("SLURM_ARRAY_TASK_COUNT", "3".to_owned()),
                ]),
            };
            shell(&command, &work, &env);
        }
        shell(&documented("merge"), &work, &[]);
        assert_same_campaign(&serial, &work.join("merged"));
        assert_same_messages(&serial, &work.join("merged"));
    }
}

#[test]
fn two_simulated_cars_on_one_machine_take_a_free_port_each_and_say_which() {
    let dir = tempfile::tempdir().unwrap();
    let (mut a, addr_a) = common::start_sim(dir.path(), "a");
    let (mut b, addr_b) = common::start_sim(dir.path(), "b");
    let _ = (a.kill(), b.kill(), a.wait(), b.wait());
    assert!(addr_a.starts_with("tcp://127.0.0.1:"), "{addr_a}");
    assert!(addr_b.starts_with("tcp://127.0.0.1:"), "{addr_b}");
    assert_ne!(addr_a, addr_b);
    assert!(!addr_a.ends_with(":0"));
}

/// Copies the files of directory `from` into a new directory `to`.
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
    }
}

#[test]
fn a_hundred_damaged_shards_are_each_refused_and_leave_no_run_directory() {
    let dir = tempfile::tempdir().unwrap();
    // Two campaigns of two shards each, recorded: seed 7 to merge, seed 8 to take files from.
    let pristine = |seed: u64, k: usize| dir.path().join(format!("pristine-{seed}-{k}"));
    for seed in [7, 8] {
        for k in 1..=2 {
            run(seed, 4, &["--shard", &format!("{k}/2")], &pristine(seed, k));
        }
    }
    // A fixed sequence of damages (a small LCG: the test is the same every time).
    let mut state: u64 = 0x5EED;
    let mut next = |bound: usize| {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((state >> 33) as usize) % bound
    };
    let mut kinds = [0usize; 7];
    for trial in 0..100 {
        let trial_dir = dir.path().join(format!("trial-{trial}"));
        let shards: Vec<_> = (1..=2)
            .map(|k| {
                let to = trial_dir.join(format!("s{k}"));
                copy_dir(&pristine(7, k), &to);
                to
            })
            .collect();
        let k = next(2);
        let shard = &shards[k];
        let kind = next(7);
        kinds[kind] += 1;
        let mut case_files: Vec<_> = std::fs::read_dir(shard)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.to_string_lossy().ends_with(".json") && !p.ends_with("campaign.json"))
            .collect();
        case_files.sort();
        let case = case_files[next(case_files.len())].clone();
        let mcap = shard.join("campaign.mcap");
        match kind {
            // Bytes flipped in the recording.
            0 => {
                let mut bytes = std::fs::read(&mcap).unwrap();
                for _ in 0..1 + next(64) {
                    let at = next(bytes.len());
                    bytes[at] ^= 1 << next(8);
                }
                std::fs::write(&mcap, bytes).unwrap();
            }
            // The recording cut short (or emptied).
            1 => {
                let bytes = std::fs::read(&mcap).unwrap();
                std::fs::write(&mcap, &bytes[..next(bytes.len())]).unwrap();
            }
            // The other campaign's recording of the same shard.
            2 => {
                std::fs::copy(pristine(8, k + 1).join("campaign.mcap"), &mcap).unwrap();
            }
            // The other campaign's case of the same test.
            3 => {
                let name = case.file_name().unwrap();
                std::fs::copy(pristine(8, k + 1).join(name), &case).unwrap();
            }
            // A verdict edited to a pass (the test's and every segment's).
            4 => {
                let text = std::fs::read_to_string(&case).unwrap();
                // Failed and aborted become passed, passed becomes failed.
                let edited = text
                    .replace("\"verdict\": \"passed\"", "\"verdict\": \"PASSED\"")
                    .replace("\"verdict\": \"failed\"", "\"verdict\": \"passed\"")
                    .replace("\"verdict\": \"aborted\"", "\"verdict\": \"passed\"")
                    .replace("\"verdict\": \"PASSED\"", "\"verdict\": \"failed\"");
                assert_ne!(edited, text);
                std::fs::write(&case, edited).unwrap();
            }
            // A case file cut short.
            5 => {
                let bytes = std::fs::read(&case).unwrap();
                std::fs::write(&case, &bytes[..next(bytes.len())]).unwrap();
            }
            // campaign.json cut short.
            _ => {
                let record = shard.join("campaign.json");
                let bytes = std::fs::read(&record).unwrap();
                std::fs::write(&record, &bytes[..next(bytes.len())]).unwrap();
            }
        }
        let out = trial_dir.join("merged");
        let merged = drivecheck(&[
            "runs",
            "merge",
            path(&shards[0]),
            path(&shards[1]),
            "--out",
            path(&out),
        ]);
        let said = String::from_utf8_lossy(&merged.stderr);
        assert_eq!(
            merged.status.code(),
            Some(2),
            "trial {trial} (damage {kind}): {}",
            text(&merged)
        );
        assert!(said.starts_with("error: "), "trial {trial}: {said}");
        assert!(!out.exists(), "trial {trial} (damage {kind}) left {out:?}");
        assert_eq!(
            std::fs::read_dir(&trial_dir).unwrap().count(),
            2,
            "trial {trial}: something beside the shards"
        );
        std::fs::remove_dir_all(&trial_dir).unwrap();
    }
    // Every kind of damage was tried.
    assert!(kinds.iter().all(|&n| n >= 5), "{kinds:?}");
}

/// Shards driven on several cars (`run --shard K/N --car A=… --car B=…`) merge into one list
/// of cars: each car once with every test it drove in any shard, and why it left a shard named
/// by the shard. (The shards here ran on the embedded car; their `cars` are written in as a lab
/// campaign writes them.)
#[test]
fn merged_shards_keep_every_cars_tests_and_why_it_left() {
    let dir = tempfile::tempdir().unwrap();
    let shards: Vec<PathBuf> = (1..=2)
        .map(|k| {
            let out = dir.path().join(format!("shard-{k}"));
            run(
                5,
                6,
                &["--shard", &format!("{k}/2"), "--record", "none"],
                &out,
            );
            out
        })
        .collect();
    let car = |name: &str, tests: &[usize], left: Option<&str>| {
        let mut car = serde_json::json!({
            "name": name,
            "address": format!("tcp://{name}:8300"),
            "firmware": "12.3",
            "tests": tests,
        });
        if let Some(why) = left {
            car["left"] = why.into();
        }
        car
    };
    for (shard, cars) in shards.iter().zip([
        vec![
            car("A", &[0, 4], None),
            car("B", &[2], Some("the link was lost")),
        ],
        vec![car("A", &[1, 3, 5], None)],
    ]) {
        let file = shard.join("campaign.json");
        let mut record: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
        record["cars"] = cars.into();
        std::fs::write(&file, record.to_string()).unwrap();
    }
    let merged = dir.path().join("merged");
    let out = drivecheck(&[
        "runs",
        "merge",
        path(&shards[0]),
        path(&shards[1]),
        "--out",
        path(&merged),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(merged.join("campaign.json")).unwrap())
            .unwrap();
    assert_eq!(
        record["cars"],
        serde_json::json!([
            {"name": "A", "address": "tcp://A:8300", "firmware": "12.3", "tests": [0, 1, 3, 4, 5]},
            {"name": "B", "address": "tcp://B:8300", "firmware": "12.3", "tests": [2],
             "left": "shard 1/2: the link was lost"},
        ]),
        "{record:#}"
    );
    let shown = drivecheck(&["runs", "show", path(&merged)]);
    assert!(
        String::from_utf8_lossy(&shown.stdout).contains("shard 1/2: the link was lost"),
        "{}",
        text(&shown)
    );
}
