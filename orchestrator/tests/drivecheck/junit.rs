//! `run --junit` and `replay --junit`: JUnit XML of the common schema CI systems read, one
//! testcase per test or run, failures with the failing segment and the case file.

use crate::common;

use serde::Deserialize;

use common::{campaign, drivecheck, path, text};

// The elements and attributes of Jenkins' junit-10.xsd (the Surefire schema) that drivecheck
// writes; unknown ones are errors, so the test fails when the writer strays from the schema. Its
// rules on them: `name`, `tests`, `failures` and `errors` required on a testsuite, `name` on a
// testcase, `name` and `value` on a property; a testcase's attributes are only `name`, `time`,
// `classname` and `group`; times match SUREFIRE_TIME (digits, a decimal part).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Testsuites {
    #[serde(rename = "@name")]
    _name: String,
    #[serde(rename = "@tests")]
    tests: usize,
    #[serde(rename = "@failures")]
    failures: usize,
    #[serde(rename = "@errors")]
    errors: usize,
    #[serde(rename = "@time")]
    time: Option<String>,
    testsuite: Vec<Testsuite>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Testsuite {
    #[serde(rename = "@name")]
    name: String,
    #[serde(rename = "@tests")]
    tests: usize,
    #[serde(rename = "@failures")]
    failures: usize,
    #[serde(rename = "@errors")]
    errors: usize,
    #[serde(rename = "@skipped")]
    _skipped: usize,
    #[serde(rename = "@time")]
    time: Option<String>,
    #[serde(rename = "@timestamp")]
    timestamp: String,
    properties: Properties,
    testcase: Vec<Testcase>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Properties {
    property: Vec<Property>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Property {
    #[serde(rename = "@name")]
    name: String,
    #[serde(rename = "@value")]
    value: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Testcase {
    #[serde(rename = "@name")]
    name: String,
    #[serde(rename = "@classname")]
    classname: String,
    #[serde(rename = "@time")]
    time: Option<String>,
    failure: Option<Problem>,
    error: Option<Problem>,
    #[serde(rename = "system-out")]
    system_out: String,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Problem {
    #[serde(rename = "@message")]
    message: String,
    #[serde(rename = "@type")]
    kind: String,
    #[serde(rename = "$text")]
    text: String,
}

/// Whether `time` matches junit-10.xsd's SUREFIRE_TIME as drivecheck writes it (`12.345`).
fn surefire_time(time: &str) -> bool {
    let (whole, fraction) = time.split_once('.').unwrap_or((time, ""));
    !whole.is_empty()
        && whole.bytes().all(|b| b.is_ascii_digit())
        && fraction.bytes().all(|b| b.is_ascii_digit())
}

/// The case file a testcase names in its `<system-out>`.
fn case_file(case: &Testcase) -> &str {
    case.system_out
        .lines()
        .find_map(|l| l.strip_prefix("case file: "))
        .unwrap_or_else(|| panic!("no case file: {case:?}"))
}

fn read(file: &std::path::Path) -> Testsuites {
    let xml = std::fs::read_to_string(file).unwrap();
    assert!(xml.starts_with("<?xml version=\"1.0\" encoding=\"UTF-8\"?>"));
    let doc: Testsuites = quick_xml::de::from_str(&xml).unwrap_or_else(|e| panic!("{e}: {xml}"));
    let times = doc.time.iter().chain(doc.testsuite.iter().flat_map(|s| {
        s.time
            .iter()
            .chain(s.testcase.iter().flat_map(|c| c.time.iter()))
    }));
    for time in times {
        assert!(surefire_time(time), "time {time:?} in {xml}");
    }
    doc
}

#[test]
fn a_campaign_and_a_replay_write_junit_xml() {
    let dir = tempfile::tempdir().unwrap();
    let junit = dir.path().join("campaign.xml");
    let run = campaign(dir.path(), 2, 10, &["--junit", path(&junit)], 1);
    let doc = read(&junit);
    let record: campaign::files::CampaignRecord =
        serde_json::from_str(&std::fs::read_to_string(run.join("campaign.json")).unwrap()).unwrap();
    let summary = record.summary.unwrap();
    assert_eq!(doc.tests, 10);
    assert_eq!(
        (doc.failures, doc.errors),
        (summary.failed, summary.aborted)
    );
    let suite = &doc.testsuite[0];
    assert_eq!(suite.name, "campaign seed 2 on parking-lot-2anchors");
    assert_eq!(suite.tests, 10);
    assert_eq!(
        (suite.failures, suite.errors),
        (summary.failed, summary.aborted)
    );
    assert_eq!(suite.timestamp, record.started_at);
    assert!(
        suite
            .properties
            .property
            .iter()
            .any(|p| p.name == "seed" && p.value == "2")
    );
    // In virtual time a test's time is the seconds it drove there (its output says the same),
    // and the suite's time is the campaign's on the wall clock.
    assert!(suite.time.is_some());
    for (i, case) in suite.testcase.iter().enumerate() {
        assert_eq!(case.name, format!("seed-2/test-{i:03}"));
        assert_eq!(case.classname, "drivecheck.parking-lot-2anchors");
        let file = case_file(case);
        assert!(file.ends_with(&format!("case-{i:03}.json")), "{file}");
        assert!(std::path::Path::new(file).exists());
        let simulated: f64 = case
            .system_out
            .split("simulated time: reset ")
            .nth(1)
            .and_then(|rest| rest.lines().next())
            .map(|line| {
                line.split(|c: char| !(c.is_ascii_digit() || c == '.'))
                    .filter_map(|n| n.parse::<f64>().ok())
                    .sum()
            })
            .unwrap_or_else(|| panic!("no simulated time: {case:?}"));
        let time: f64 = case.time.as_deref().expect("a time").parse().unwrap();
        assert!(time > 0.0 && (time - simulated).abs() < 0.002, "{case:?}");
        let failing = &summary.failing_cases;
        let failed = case.failure.is_some() || case.error.is_some();
        assert_eq!(failed, failing.contains(&format!("case-{i:03}.json")));
        if let Some(failure) = &case.failure {
            assert_eq!(failure.kind, "failed");
            assert!(failure.message.contains("deviation"), "{failure:?}");
            assert!(failure.text.contains("FAILED"), "{failure:?}");
            assert!(failure.text.contains(file), "{failure:?}");
        }
    }
    assert!(
        suite
            .properties
            .property
            .iter()
            .any(|p| p.name == "simulated_time_s")
    );
    assert!(summary.failed > 0, "seed 2 has failing tests");

    // Replay the first failing case twice: one testcase per run.
    let case = run.join(&summary.failing_cases[0]);
    let junit = dir.path().join("replay.xml");
    let out = dir.path().join("replay");
    let replay = drivecheck(&[
        "replay",
        path(&case),
        "--times",
        "2",
        "--out",
        path(&out),
        "--junit",
        path(&junit),
    ]);
    assert_eq!(replay.status.code(), Some(1), "{}", text(&replay));
    let doc = read(&junit);
    let suite = &doc.testsuite[0];
    assert!(suite.name.starts_with("replay of "), "{}", suite.name);
    let names: Vec<&str> = suite.testcase.iter().map(|c| c.name.as_str()).collect();
    let test = summary.failing_cases[0]
        .trim_start_matches("case-")
        .trim_end_matches(".json")
        .to_owned();
    assert_eq!(
        names,
        [
            format!("seed-2/test-{test}/run-1"),
            format!("seed-2/test-{test}/run-2")
        ]
    );
    assert!(suite.testcase.iter().all(|c| c.failure.is_some()));
    assert!(case_file(&suite.testcase[1]).ends_with(&format!("run-2/case-{test}.json")));

    // The JUnit of merged shards is of the same schema.
    let shards: Vec<_> = (1..=2)
        .map(|k| {
            let out = dir.path().join(format!("shard-{k}"));
            let shard = format!("{k}/2");
            let run = drivecheck(&[
                "run",
                "--seed",
                "2",
                "--tests",
                "4",
                "--shard",
                &shard,
                "--out",
                path(&out),
            ]);
            assert!(matches!(run.status.code(), Some(0 | 1)), "{}", text(&run));
            out
        })
        .collect();
    let junit = dir.path().join("merged.xml");
    let merged = drivecheck(&[
        "runs",
        "merge",
        path(&shards[0]),
        path(&shards[1]),
        "--out",
        path(&dir.path().join("merged")),
        "--junit",
        path(&junit),
    ]);
    assert_eq!(merged.status.code(), Some(0), "{}", text(&merged));
    let doc = read(&junit);
    assert_eq!(doc.tests, 4);
    assert_eq!(doc.testsuite[0].testcase[3].name, "seed-2/test-003");
}
