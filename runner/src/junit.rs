//! JUnit XML for CI (`drivecheck run --junit FILE`, `drivecheck replay --junit FILE`, `drivecheck
//! runs merge --junit FILE`): one `<testsuite>` per campaign or replay, one `<testcase>` per test
//! or run.
//!
//! The shape is Jenkins' `junit-10.xsd`, the Surefire schema pytest and Jenkins write and CI
//! reporters read (GitLab, GitHub): `<testsuites>` with `name`, `tests`, `failures`, `errors`,
//! `time`; per `<testsuite>` `name`, `tests`, `failures`, `errors`, `skipped`, `time`, `timestamp`
//! and `<properties>`; per `<testcase>` `name` (`seed-7/test-003`), `classname`, `time`, a
//! `<failure>` (a failed test: the oracle's reason and every segment's largest deviation) or an
//! `<error>` (an aborted test: why), and `<system-out>` (the case file, the simulated time).
//! Times are wall-clock seconds; a test in the simulator's virtual time has no wall time of its
//! own (its `time` is left out) and says its simulated seconds in `<system-out>`, the suite its
//! total as the property `simulated_time_s`.

use std::io;

use quick_xml::Writer;
use quick_xml::events::{BytesDecl, BytesText, Event};

use campaign::files::{Case, TestTiming};
use campaign::oracle::{SegmentVerdict, Verdict};

/// Whose seconds a test's `timing` holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clock {
    /// The wall clock: a car, or the simulator against the wall clock.
    Wall,
    /// The simulator's virtual time.
    Simulated,
}

/// One test or run.
#[derive(Debug, Clone)]
pub struct TestCase {
    /// Its name, identifying the case (`seed-7/test-003`, `seed-7/test-003/run-2`).
    pub name: String,
    /// What the case it wrote says.
    pub case: Outcome,
    /// Where that case file is, as the user named the directory.
    pub file: String,
}

/// What a test's JUnit element says, taken from its case: a few values per segment, so that a
/// campaign of any size is written without its cases in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The test's verdict (`None`: not run).
    pub verdict: Option<Verdict>,
    /// Why it failed or was aborted.
    pub reason: Option<String>,
    /// Its reset and drive times.
    pub timing: Option<TestTiming>,
    /// Its judged segments.
    pub segments: Vec<SegmentOutcome>,
}

/// One judged segment of an [`Outcome`].
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentOutcome {
    /// The segment's index in its test.
    pub segment_index: usize,
    /// Its command's index.
    pub command_index: usize,
    /// The oracle's verdict.
    pub verdict: SegmentVerdict,
    /// Its largest deviation, metres (none without samples).
    pub max_m: Option<f64>,
    /// The oracle's threshold, metres.
    pub threshold_m: f64,
}

impl From<&Case> for Outcome {
    fn from(case: &Case) -> Self {
        Self {
            verdict: case.verdict,
            reason: case.reason.clone(),
            timing: case.timing,
            segments: case
                .segments
                .iter()
                .map(|s| SegmentOutcome {
                    segment_index: s.segment_index,
                    command_index: s.command_index,
                    verdict: s.oracle.verdict,
                    max_m: s.oracle.stats.as_ref().map(|st| st.max_m),
                    threshold_m: s.oracle.threshold_m,
                })
                .collect(),
        }
    }
}

/// A campaign or a replay.
#[derive(Debug, Clone)]
pub struct Suite {
    /// Its name (`campaign seed 7 on parking-lot-2anchors`).
    pub name: String,
    /// The test cases' class name (`drivecheck.<scenario>`).
    pub classname: String,
    /// When it started, RFC 3339.
    pub timestamp: String,
    /// Its properties (seed, scenario, car, firmware, tool version).
    pub properties: Vec<(String, String)>,
    /// Its tests.
    pub cases: Vec<TestCase>,
    /// Whose seconds the cases' `timing` holds.
    pub clock: Clock,
    /// How long it took on the wall clock, seconds (when known).
    pub wall_s: Option<f64>,
}

impl Suite {
    /// The suite's wall-clock time: measured, or the tests' own on the wall clock.
    fn wall_time(&self) -> Option<f64> {
        self.wall_s.or_else(|| {
            (self.clock == Clock::Wall).then(|| self.cases.iter().map(|c| time(&c.case)).sum())
        })
    }
}

fn time(case: &Outcome) -> f64 {
    case.timing.map_or(0.0, |t| t.reset_s + t.drive_s)
}

fn count(suite: &Suite, verdict: Verdict) -> usize {
    suite
        .cases
        .iter()
        .filter(|c| c.case.verdict == Some(verdict))
        .count()
}

/// What the failure's body says: the reason, each segment's largest deviation, the case file.
fn details(case: &TestCase) -> String {
    let mut text = String::new();
    if let Some(reason) = &case.case.reason {
        text.push_str(reason);
        text.push('\n');
    }
    for s in &case.case.segments {
        let verdict = match s.verdict {
            SegmentVerdict::Passed => "passed",
            SegmentVerdict::Failed => "FAILED",
            SegmentVerdict::NoSamples => "no samples",
        };
        let max = s
            .max_m
            .map_or_else(|| "-".to_owned(), |max| format!("{max:.2} m"));
        text.push_str(&format!(
            "segment {} (command {}): {verdict}, max deviation {max} (threshold {:.2} m)\n",
            s.segment_index, s.command_index, s.threshold_m
        ));
    }
    text.push_str(&format!("case file: {}\n", case.file));
    text
}

/// The JUnit XML document for `suites`.
pub fn to_xml(suites: &[Suite]) -> io::Result<String> {
    let mut w = Writer::new_with_indent(Vec::new(), b' ', 2);
    w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))?;
    let all = |verdict| suites.iter().map(|s| count(s, verdict)).sum::<usize>();
    let tests: usize = suites.iter().map(|s| s.cases.len()).sum();
    let total: Option<f64> = suites.iter().map(Suite::wall_time).sum();
    let mut attributes = vec![
        ("name", "drivecheck".to_owned()),
        ("tests", tests.to_string()),
        ("failures", all(Verdict::Failed).to_string()),
        ("errors", all(Verdict::Aborted).to_string()),
    ];
    if let Some(total) = total {
        attributes.push(("time", format!("{total:.3}")));
    }
    w.create_element("testsuites")
        .with_attributes(attributes.iter().map(|(k, v)| (*k, v.as_str())))
        .write_inner_content(|w| {
            for suite in suites {
                write_suite(w, suite)?;
            }
            Ok(())
        })?;
    String::from_utf8(w.into_inner()).map_err(io::Error::other)
}

fn write_suite(w: &mut Writer<Vec<u8>>, suite: &Suite) -> io::Result<()> {
    let mut attributes = vec![
        ("name", suite.name.clone()),
        ("tests", suite.cases.len().to_string()),
        ("failures", count(suite, Verdict::Failed).to_string()),
        ("errors", count(suite, Verdict::Aborted).to_string()),
        ("skipped", "0".to_owned()),
    ];
    if let Some(wall) = suite.wall_time() {
        attributes.push(("time", format!("{wall:.3}")));
    }
    attributes.push(("timestamp", suite.timestamp.clone()));
    let mut properties = suite.properties.clone();
    if suite.clock == Clock::Simulated {
        let simulated: f64 = suite.cases.iter().map(|c| time(&c.case)).sum();
        properties.push(("simulated_time_s".to_owned(), format!("{simulated:.3}")));
    }
    w.create_element("testsuite")
        .with_attributes(attributes.iter().map(|(k, v)| (*k, v.as_str())))
        .write_inner_content(|w| {
            w.create_element("properties").write_inner_content(|w| {
                for (name, value) in &properties {
                    w.create_element("property")
                        .with_attributes([("name", name.as_str()), ("value", value.as_str())])
                        .write_empty()?;
                }
                Ok(())
            })?;
            for case in &suite.cases {
                write_case(w, suite, case)?;
            }
            Ok(())
        })?;
    Ok(())
}

fn write_case(w: &mut Writer<Vec<u8>>, suite: &Suite, case: &TestCase) -> io::Result<()> {
    let mut attributes = vec![
        ("name", case.name.clone()),
        ("classname", suite.classname.clone()),
    ];
    // A test's duration on its own clock: wall-clock seconds on a car, the seconds it drove
    // in virtual time on the simulator (a dashboard shows how long each test drove; the
    // suite's `time` stays the campaign's wall time).
    attributes.push(("time", format!("{:.3}", time(&case.case))));
    let element = w
        .create_element("testcase")
        .with_attributes(attributes.iter().map(|(k, v)| (*k, v.as_str())));
    let problem = match case.case.verdict {
        Some(Verdict::Passed) => None,
        Some(Verdict::Failed) => Some(("failure", "failed")),
        Some(Verdict::Aborted) => Some(("error", "aborted")),
        None => Some(("error", "not run")),
    };
    let mut out = format!("case file: {}\n", case.file);
    if let (Clock::Simulated, Some(t)) = (suite.clock, case.case.timing) {
        out.push_str(&format!(
            "simulated time: reset {:.3} s, drive {:.3} s\n",
            t.reset_s, t.drive_s
        ));
    }
    element.write_inner_content(|w| {
        if let Some((tag, kind)) = problem {
            let message = case.case.reason.clone().unwrap_or_else(|| kind.to_owned());
            w.create_element(tag)
                .with_attributes([("message", message.as_str()), ("type", kind)])
                .write_text_content(BytesText::new(&details(case)))?;
        }
        w.create_element("system-out")
            .write_text_content(BytesText::new(&out))?;
        Ok(())
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn case(verdict: Option<Verdict>, reason: Option<&str>) -> Case {
        let mut case = Case::from_json(
            r#"{"format": "drivecheck-case", "schema_version": 2,
                "scenario": {"name": "s"}, "commands": []}"#,
        )
        .unwrap();
        case.verdict = verdict;
        case.reason = reason.map(str::to_owned);
        case.timing = Some(TestTiming {
            reset_s: 1.5,
            drive_s: 10.25,
        });
        case
    }

    fn suite(cases: &[&Case], clock: Clock, wall_s: Option<f64>) -> Suite {
        Suite {
            name: "campaign seed 7 on s".to_owned(),
            classname: "drivecheck.s".to_owned(),
            timestamp: "2026-11-24T10:00:00Z".to_owned(),
            properties: vec![("seed".to_owned(), "7".to_owned())],
            cases: cases
                .iter()
                .enumerate()
                .map(|(i, c)| TestCase {
                    name: format!("seed-7/test-{i:03}"),
                    case: Outcome::from(*c),
                    file: format!("runs/x/case-{i:03}.json"),
                })
                .collect(),
            clock,
            wall_s,
        }
    }

    #[test]
    fn counts_failures_and_errors_and_escapes_text() {
        let passed = case(Some(Verdict::Passed), None);
        let failed = case(
            Some(Verdict::Failed),
            Some("segment 2 (command 3): deviation 1.28 m > 1.00 m & <worse>"),
        );
        let aborted = case(Some(Verdict::Aborted), Some("link lost"));
        let xml = to_xml(&[suite(&[&passed, &failed, &aborted], Clock::Wall, None)]).unwrap();
        assert!(xml.starts_with("<?xml version=\"1.0\" encoding=\"UTF-8\"?>"));
        assert!(xml.contains(
            "<testsuites name=\"drivecheck\" tests=\"3\" failures=\"1\" errors=\"1\" time=\"35.250\">"
        ));
        assert!(xml.contains(
            "<testcase name=\"seed-7/test-000\" classname=\"drivecheck.s\" time=\"11.750\">"
        ));
        assert!(xml.contains("<system-out>case file: runs/x/case-000.json\n</system-out>"));
        assert!(xml.contains("<failure message=\"segment 2 (command 3): deviation 1.28 m &gt; 1.00 m &amp; &lt;worse&gt;\" type=\"failed\">"));
        assert!(xml.contains("<error message=\"link lost\" type=\"aborted\">"));
        assert!(xml.contains("<property name=\"seed\" value=\"7\"/>"));
        assert!(xml.contains("case file: runs/x/case-001.json"));
        assert!(
            !xml.contains("file=\""),
            "junit-10.xsd has no file attribute: {xml}"
        );
    }

    #[test]
    fn in_virtual_time_a_test_s_time_is_its_simulated_seconds() {
        let passed = case(Some(Verdict::Passed), None);
        let xml = to_xml(&[suite(&[&passed], Clock::Simulated, Some(0.7))]).unwrap();
        assert!(xml.contains("<testsuites name=\"drivecheck\" tests=\"1\" failures=\"0\" errors=\"0\" time=\"0.700\">"), "{xml}");
        assert!(
            xml.contains(
                "<testcase name=\"seed-7/test-000\" classname=\"drivecheck.s\" time=\"11.750\">"
            ),
            "{xml}"
        );
        assert!(
            xml.contains("simulated time: reset 1.500 s, drive 10.250 s"),
            "{xml}"
        );
        assert!(
            xml.contains("<property name=\"simulated_time_s\" value=\"11.750\"/>"),
            "{xml}"
        );
    }
}
