//! A replay reproduces (#52): a case of a campaign on the embedded simulated car, replayed with
//! no options, drives the same test — the same simulated car from the same start — so every
//! segment's largest deviation is the case's to the last digit, and the summary says so;
//! `--vary-seed` drives other cars and reports their spread; more runs than one imply it; a
//! shrink's first run of the case is the case's own.

use crate::common;

use common::{campaign, drivecheck, path, text};

use std::path::Path;

use campaign::files::{CampaignRecord, Case};
use campaign::oracle::SegmentVerdict;
use campaign::replay::{Comparison, Drove};
use campaign::seed::{Purpose, derive};

fn read_case(file: &Path) -> Case {
    Case::from_json(&std::fs::read_to_string(file).unwrap()).unwrap()
}

fn read_comparison(dir: &Path) -> Comparison {
    Comparison::from_json(&std::fs::read_to_string(dir.join("replay.json")).unwrap()).unwrap()
}

/// The failing (and aborted) case files of a campaign of `tests` tests with `seed` in `dir`.
fn failing_cases(dir: &Path, seed: u64, tests: usize) -> Vec<std::path::PathBuf> {
    let out = dir.join(format!("seed-{seed}"));
    std::fs::create_dir_all(&out).unwrap();
    let run = campaign(&out, seed, tests, &["--record", "none"], 1);
    let record =
        CampaignRecord::from_json(&std::fs::read_to_string(run.join("campaign.json")).unwrap())
            .unwrap();
    let summary = record.summary.expect("the campaign ended");
    summary.failing_cases.iter().map(|f| run.join(f)).collect()
}

/// Every failing case of a 20-test campaign, for five seeds: `replay CASE` drives it again with
/// every segment's largest deviation exactly the case's, and says "reproduced".
#[test]
fn every_failing_case_of_a_campaign_replays_to_the_last_digit_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let mut reproduced = 0;
    for seed in 1..=5 {
        let cases = failing_cases(tmp.path(), seed, 20);
        assert!(!cases.is_empty(), "seed {seed} finds failures in 20 tests");
        for (k, case_file) in cases.iter().enumerate() {
            let original = read_case(case_file);
            let out = tmp.path().join(format!("replay-{seed}-{k}"));
            let run = drivecheck(&["replay", path(case_file), "--out", path(&out)]);
            assert_eq!(run.status.code(), Some(1), "{}", text(&run));
            let c = read_comparison(&out);
            let shown = format!("{}: {}", case_file.display(), c.table());
            assert_eq!(c.runs.len(), 1, "{shown}");
            assert_eq!(c.drove, Some(Drove::SameTest), "{shown}");
            let reproduction = c.reproduction.as_ref().expect("checked against the case");
            assert!(reproduction.identical, "{shown}");
            assert_eq!(c.runs[0].verdict, original.verdict, "{shown}");
            // Segment by segment, to the bit, against the case file itself.
            let index = original.test_index.unwrap();
            let replayed = read_case(&out.join("run-1").join(format!("case-{index:03}.json")));
            assert_eq!(replayed.segments.len(), original.segments.len(), "{shown}");
            for (a, b) in original.segments.iter().zip(&replayed.segments) {
                let max = |s: &campaign::files::SegmentResult| s.oracle.stats.map(|s| s.max_m);
                assert_eq!(
                    max(a).map(f64::to_bits),
                    max(b).map(f64::to_bits),
                    "{shown}"
                );
            }
            // The same car: the campaign's simulator seed of that test.
            assert_eq!(c.runs[0].seed, seed);
            assert_eq!(
                c.runs[0].simulator_seed,
                Some(derive(seed, Purpose::Simulator { test_index: index }))
            );
            let stdout = String::from_utf8_lossy(&run.stdout);
            assert!(
                stdout.contains("reproduced: every segment identical"),
                "{stdout}"
            );
            reproduced += 1;
        }
    }
    eprintln!("{reproduced} failing cases of 5 seeds × 20 tests reproduced exactly");
}

/// One failing case of the seed-11 campaign (#52's example: test 3 failed segment 0 at 1.006 m).
fn seed_11_case(dir: &Path) -> std::path::PathBuf {
    let cases = failing_cases(dir, 11, 6);
    cases
        .into_iter()
        .find(|c| read_case(c).test_index == Some(3))
        .expect("seed 11 fails test 3")
}

#[test]
fn vary_seed_drives_other_cars_of_the_same_test_and_reports_their_spread() {
    let tmp = tempfile::tempdir().unwrap();
    let case_file = seed_11_case(tmp.path());
    let out = tmp.path().join("varied");
    let run = drivecheck(&[
        "replay",
        path(&case_file),
        "--vary-seed",
        "--out",
        path(&out),
    ]);
    assert_eq!(run.status.code(), Some(1), "{}", text(&run));
    let c = read_comparison(&out);
    assert_eq!(c.drove, Some(Drove::OtherCars));
    assert_eq!(c.reproduction, None);
    assert_eq!(c.runs.len(), 3, "{}", c.table());
    let own = derive(11, Purpose::Simulator { test_index: 3 });
    let cars: Vec<u64> = c.runs.iter().map(|r| r.simulator_seed.unwrap()).collect();
    for (k, car) in cars.iter().enumerate() {
        assert_eq!(c.runs[k].seed, 11, "the campaign's reset and safe stop");
        assert_eq!(
            *car,
            derive(
                11,
                Purpose::Rerun {
                    test_index: 3,
                    run: k as u64 + 1
                }
            )
        );
        assert_ne!(*car, own);
    }
    let spread = c.max_abs_diff_m.expect("segments were driven");
    assert!(spread > 0.0, "{}", c.table());
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("other simulated cars") && stdout.contains("spread: largest difference"),
        "{stdout}"
    );

    // More than one run without --vary-seed is the same: said in the summary.
    let out = tmp.path().join("times");
    let run = drivecheck(&[
        "replay",
        path(&case_file),
        "--times",
        "2",
        "--out",
        path(&out),
    ]);
    assert_eq!(run.status.code(), Some(1), "{}", text(&run));
    let c = read_comparison(&out);
    assert_eq!(c.drove, Some(Drove::OtherCars));
    assert_eq!(c.runs.len(), 2);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains(
            "--times 2 on the embedded simulated car in virtual time implies --vary-seed"
        ),
        "{stdout}"
    );
}

#[test]
fn a_replay_that_does_not_reproduce_says_which_segments_differ() {
    let tmp = tempfile::tempdir().unwrap();
    let case_file = seed_11_case(tmp.path());
    let mut case = read_case(&case_file);
    // A case whose recorded figure is not what its test gives (as when it was driven on another
    // car): the summary must not call that reproduced.
    let recorded = case.segments[0].oracle.stats.as_mut().unwrap();
    let driven = recorded.max_m;
    recorded.max_m += 0.5;
    let edited = tmp.path().join("edited.json");
    std::fs::write(&edited, case.to_json().unwrap()).unwrap();
    let out = tmp.path().join("edited-replay");
    let run = drivecheck(&["replay", path(&edited), "--out", path(&out)]);
    assert_eq!(run.status.code(), Some(1), "{}", text(&run));
    let c = read_comparison(&out);
    let r = c.reproduction.expect("the same test is checked");
    assert!(!r.identical);
    assert_eq!(r.differing.len(), 1, "{:?}", r.differing);
    assert_eq!(r.differing[0].segment_index, 0);
    assert_eq!(r.differing[0].max_m, Some(driven));
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        stdout.contains("not reproduced: 1 segment(s) differ")
            && stdout.contains(&format!(
                "segment 0 case {:.3} m, run 1 {driven:.3} m",
                driven + 0.5
            )),
        "{stdout}"
    );
}

#[test]
fn a_shrinks_first_run_of_the_case_is_the_cases_own_test() {
    let tmp = tempfile::tempdir().unwrap();
    let cases = failing_cases(tmp.path(), 11, 6);
    let case_file = cases
        .into_iter()
        .find(|c| read_case(c).test_index == Some(2))
        .expect("seed 11 fails test 2");
    let original = read_case(&case_file);
    let out = tmp.path().join("shrunk");
    let run = drivecheck(&[
        "shrink",
        path(&case_file),
        "--budget",
        "1s",
        "--json",
        "--out",
        path(&out),
    ]);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("shrink.json")).unwrap()).unwrap();
    let first = &report["before"]["runs"][0];
    let failing = original
        .segments
        .iter()
        .find(|s| s.oracle.verdict == SegmentVerdict::Failed)
        .unwrap();
    assert_eq!(
        first["first_failing_segment"].as_u64(),
        Some(failing.segment_index as u64)
    );
    let worst = original
        .segments
        .iter()
        .filter_map(|s| s.oracle.stats.map(|s| s.max_m))
        .fold(f64::NEG_INFINITY, f64::max);
    assert_eq!(
        first["max_deviation_m"].as_f64().map(f64::to_bits),
        Some(worst.to_bits()),
        "{first}"
    );
    assert_eq!(
        first["seed"].as_u64(),
        Some(derive(11, Purpose::Simulator { test_index: 2 }))
    );
}
