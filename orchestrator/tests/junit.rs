//! `run --junit` and `replay --junit`: JUnit XML of the common schema CI systems read, one
//! testcase per test or run, failures with the failing segment and the case file.

mod common;

use serde::Deserialize;

use common::{campaign, drivecheck, path, text};

// The JUnit schema's elements and attributes drivecheck writes (Jenkins' junit-10.xsd); unknown
// ones are errors, so the test fails when the writer strays from the schema.
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
    _time: f64,
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
    time: f64,
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
    time: f64,
    #[serde(rename = "@file")]
    file: String,
    failure: Option<Problem>,
    error: Option<Problem>,
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

fn read(file: &std::path::Path) -> Testsuites {
    let xml = std::fs::read_to_string(file).unwrap();
    assert!(xml.starts_with("<?xml version=\"1.0\" encoding=\"UTF-8\"?>"));
    quick_xml::de::from_str(&xml).unwrap_or_else(|e| panic!("{e}: {xml}"))
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
    let mut time = 0.0;
    for (i, case) in suite.testcase.iter().enumerate() {
        assert_eq!(case.name, format!("test {i:03}"));
        assert_eq!(case.classname, "drivecheck.parking-lot-2anchors");
        assert!(
            case.file.ends_with(&format!("case-{i:03}.json")),
            "{}",
            case.file
        );
        assert!(std::path::Path::new(&case.file).exists());
        assert!(case.time > 1.0, "a test takes simulated seconds: {case:?}");
        time += case.time;
        let file = &summary.failing_cases;
        let failed = case.failure.is_some() || case.error.is_some();
        assert_eq!(failed, file.contains(&format!("case-{i:03}.json")));
        if let Some(failure) = &case.failure {
            assert_eq!(failure.kind, "failed");
            assert!(failure.message.contains("deviation"), "{failure:?}");
            assert!(failure.text.contains("FAILED"), "{failure:?}");
            assert!(failure.text.contains(&case.file), "{failure:?}");
        }
    }
    assert!((suite.time - time).abs() < 0.01 * suite.testcase.len() as f64);
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
    assert_eq!(names, ["run 1", "run 2"]);
    assert!(suite.testcase.iter().all(|c| c.failure.is_some()));
    assert!(suite.testcase[1].file.ends_with("run-2/case-000.json"));
}
