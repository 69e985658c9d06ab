//! JUnit XML for CI (`drivecheck run --junit FILE`, `drivecheck replay --junit FILE`): one
//! `<testsuite>` per campaign or replay, one `<testcase>` per test or run.
//!
//! The shape is the common JUnit schema that CI systems read (Jenkins' `junit-10.xsd`, GitLab,
//! GitHub test reporters): `<testsuites>` with `tests`, `failures`, `errors`, `time`; per
//! `<testsuite>` `name`, `tests`, `failures`, `errors`, `skipped`, `time`, `timestamp` and
//! `<properties>`; per `<testcase>` `name`, `classname`, `time`, `file`, and a `<failure>`
//! (a failed test: the oracle's reason and every segment's largest deviation) or an `<error>`
//! (an aborted test: why). `time` is the test's reset and drive (simulated seconds for the
//! embedded simulated car in virtual time).

use std::io;

use quick_xml::Writer;
use quick_xml::events::{BytesDecl, BytesText, Event};

use campaign::files::Case;
use campaign::oracle::{SegmentVerdict, Verdict};

/// One test or run.
#[derive(Debug, Clone)]
pub struct TestCase<'a> {
    /// Its name (`test 003`, `run 2`).
    pub name: String,
    /// The case it wrote.
    pub case: &'a Case,
    /// Where that case file is, as the user named the directory.
    pub file: String,
}

/// A campaign or a replay.
#[derive(Debug, Clone)]
pub struct Suite<'a> {
    /// Its name (`campaign seed 7 on parking-lot-2anchors`).
    pub name: String,
    /// The test cases' class name (`drivecheck.<scenario>`).
    pub classname: String,
    /// When it started, RFC 3339.
    pub timestamp: String,
    /// Its properties (seed, scenario, car, firmware, tool version).
    pub properties: Vec<(String, String)>,
    /// Its tests.
    pub cases: Vec<TestCase<'a>>,
}

fn time(case: &Case) -> f64 {
    case.timing.map_or(0.0, |t| t.reset_s + t.drive_s)
}

fn count(suite: &Suite<'_>, verdict: Verdict) -> usize {
    suite
        .cases
        .iter()
        .filter(|c| c.case.verdict == Some(verdict))
        .count()
}

/// What the failure's body says: the reason, each segment's largest deviation, the case file.
fn details(case: &TestCase<'_>) -> String {
    let mut text = String::new();
    if let Some(reason) = &case.case.reason {
        text.push_str(reason);
        text.push('\n');
    }
    for s in &case.case.segments {
        let verdict = match s.oracle.verdict {
            SegmentVerdict::Passed => "passed",
            SegmentVerdict::Failed => "FAILED",
            SegmentVerdict::NoSamples => "no samples",
        };
        let max = s
            .oracle
            .stats
            .as_ref()
            .map_or_else(|| "-".to_owned(), |st| format!("{:.2} m", st.max_m));
        text.push_str(&format!(
            "segment {} (command {}): {verdict}, max deviation {max} (threshold {:.2} m)\n",
            s.segment_index, s.command_index, s.oracle.threshold_m
        ));
    }
    text.push_str(&format!("case file: {}\n", case.file));
    text
}

/// The JUnit XML document for `suites`.
pub fn to_xml(suites: &[Suite<'_>]) -> io::Result<String> {
    let mut w = Writer::new_with_indent(Vec::new(), b' ', 2);
    w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))?;
    let all = |verdict| suites.iter().map(|s| count(s, verdict)).sum::<usize>();
    let tests: usize = suites.iter().map(|s| s.cases.len()).sum();
    let total: f64 = suites
        .iter()
        .flat_map(|s| s.cases.iter().map(|c| time(c.case)))
        .sum();
    w.create_element("testsuites")
        .with_attributes([
            ("name", "drivecheck"),
            ("tests", tests.to_string().as_str()),
            ("failures", all(Verdict::Failed).to_string().as_str()),
            ("errors", all(Verdict::Aborted).to_string().as_str()),
            ("time", format!("{total:.3}").as_str()),
        ])
        .write_inner_content(|w| {
            for suite in suites {
                write_suite(w, suite)?;
            }
            Ok(())
        })?;
    String::from_utf8(w.into_inner()).map_err(io::Error::other)
}

fn write_suite(w: &mut Writer<Vec<u8>>, suite: &Suite<'_>) -> io::Result<()> {
    let time: f64 = suite.cases.iter().map(|c| time(c.case)).sum();
    w.create_element("testsuite")
        .with_attributes([
            ("name", suite.name.as_str()),
            ("tests", suite.cases.len().to_string().as_str()),
            (
                "failures",
                count(suite, Verdict::Failed).to_string().as_str(),
            ),
            (
                "errors",
                count(suite, Verdict::Aborted).to_string().as_str(),
            ),
            ("skipped", "0"),
            ("time", format!("{time:.3}").as_str()),
            ("timestamp", suite.timestamp.as_str()),
        ])
        .write_inner_content(|w| {
            w.create_element("properties").write_inner_content(|w| {
                for (name, value) in &suite.properties {
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

fn write_case(w: &mut Writer<Vec<u8>>, suite: &Suite<'_>, case: &TestCase<'_>) -> io::Result<()> {
    let element = w.create_element("testcase").with_attributes([
        ("name", case.name.as_str()),
        ("classname", suite.classname.as_str()),
        ("time", format!("{:.3}", time(case.case)).as_str()),
        ("file", case.file.as_str()),
    ]);
    let (tag, kind) = match case.case.verdict {
        Some(Verdict::Passed) => {
            element.write_empty()?;
            return Ok(());
        }
        Some(Verdict::Failed) => ("failure", "failed"),
        Some(Verdict::Aborted) => ("error", "aborted"),
        None => ("error", "not run"),
    };
    let message = case.case.reason.clone().unwrap_or_else(|| kind.to_owned());
    let body = details(case);
    element.write_inner_content(|w| {
        w.create_element(tag)
            .with_attributes([("message", message.as_str()), ("type", kind)])
            .write_text_content(BytesText::new(&body))?;
        Ok(())
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use campaign::files::TestTiming;

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

    #[test]
    fn counts_failures_and_errors_and_escapes_text() {
        let passed = case(Some(Verdict::Passed), None);
        let failed = case(
            Some(Verdict::Failed),
            Some("segment 2 (command 3): deviation 1.28 m > 1.00 m & <worse>"),
        );
        let aborted = case(Some(Verdict::Aborted), Some("link lost"));
        let suite = Suite {
            name: "campaign seed 7 on s".to_owned(),
            classname: "drivecheck.s".to_owned(),
            timestamp: "2026-11-24T10:00:00Z".to_owned(),
            properties: vec![("seed".to_owned(), "7".to_owned())],
            cases: [&passed, &failed, &aborted]
                .iter()
                .enumerate()
                .map(|(i, c)| TestCase {
                    name: format!("test {i:03}"),
                    case: c,
                    file: format!("runs/x/case-{i:03}.json"),
                })
                .collect(),
        };
        let xml = to_xml(&[suite]).unwrap();
        assert!(xml.starts_with("<?xml version=\"1.0\" encoding=\"UTF-8\"?>"));
        assert!(xml.contains(
            "<testsuites name=\"drivecheck\" tests=\"3\" failures=\"1\" errors=\"1\" time=\"35.250\">"
        ));
        assert!(xml.contains("<testcase name=\"test 000\" classname=\"drivecheck.s\" time=\"11.750\" file=\"runs/x/case-000.json\"/>"));
        assert!(xml.contains("<failure message=\"segment 2 (command 3): deviation 1.28 m &gt; 1.00 m &amp; &lt;worse&gt;\" type=\"failed\">"));
        assert!(xml.contains("<error message=\"link lost\" type=\"aborted\">"));
        assert!(xml.contains("<property name=\"seed\" value=\"7\"/>"));
        assert!(xml.contains("case file: runs/x/case-001.json"));
    }
}
