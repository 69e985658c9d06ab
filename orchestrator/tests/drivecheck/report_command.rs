//! `drivecheck report`, `run --report` and `replay --report`: a self-contained `report.html`
//! with a section, a map and a plot per test (per run for a replay) whose summary matches the
//! run directory's records; rendered by a real browser when one is installed.

use crate::common;

use std::path::Path;
use std::process::Command;

use campaign::files::{CampaignRecord, Case};
use campaign::oracle::Verdict;
use common::{drivecheck, path, text};

/// The page's sections with the given id prefix, each as its text up to `</section>`.
fn sections<'a>(html: &'a str, prefix: &str) -> Vec<(&'a str, &'a str)> {
    let marker = format!("<section class=\"test\" id=\"{prefix}");
    html.match_indices(&marker)
        .map(|(at, _)| {
            let rest = &html[at..];
            let id_start = "<section class=\"test\" id=\"".len();
            let id_end = id_start + rest[id_start..].find('"').unwrap();
            let end = rest.find("</section>").unwrap();
            (&rest[id_start..id_end], &rest[..end])
        })
        .collect()
}

/// No reference leaves the page: no address but the SVG namespace, no script, no fetched
/// resource.
fn assert_self_contained(html: &str) {
    let addresses = html.matches("http://").count() + html.matches("https://").count();
    let namespaces = html.matches("http://www.w3.org/2000/svg").count();
    assert_eq!(addresses, namespaces, "an address other than the SVG xmlns");
    for forbidden in ["<script", " src=", "<link", "@import", "url(", "<iframe"] {
        assert!(!html.contains(forbidden), "the page holds {forbidden}");
    }
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(html.trim_end().ends_with("</html>"));
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The verdict in the case file `path`.
fn verdict(path: &Path) -> Option<Verdict> {
    Case::from_json(&read(path)).unwrap().verdict
}

/// The text of the element with `id` (`<span id="count-passed">7</span>` → `7`).
fn by_id<'a>(html: &'a str, id: &str) -> &'a str {
    let marker = format!("id=\"{id}\">");
    let start = html.find(&marker).unwrap_or_else(|| panic!("no #{id}")) + marker.len();
    let end = start + html[start..].find('<').unwrap();
    &html[start..end]
}

/// Each of the sections `ids` of `html` is linked from the tests table and has a map (with the
/// anchors and tracks) and a plot (with the threshold), timed on the test's clock.
fn assert_all_drawn(html: &str, ids: &[impl AsRef<str>]) {
    let tests = sections(html, "test-");
    for id in ids {
        let id = id.as_ref();
        let (_, section) = tests
            .iter()
            .find(|(i, _)| *i == id)
            .unwrap_or_else(|| panic!("no section {id}"));
        assert!(html.contains(&format!("href=\"#{id}\"")), "no link to {id}");
        assert_eq!(section.matches("<svg").count(), 2, "{id}: a map and a plot");
        assert!(
            section.contains("anchor 50"),
            "{id}: the map shows the anchors"
        );
        assert!(
            section.contains("threshold 1.00 m"),
            "{id}: the plot's threshold"
        );
        assert!(section.contains("<polyline"), "{id}: tracks are drawn");
        assert!(
            section.contains("acknowledged the command that started the test's autopilot"),
            "{id}: the samples are timed on the test's clock"
        );
    }
}

#[test]
fn a_campaign_and_its_replay_get_a_self_contained_report() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("campaign");
    let out = drivecheck(&[
        "run",
        "--seed",
        "2",
        "--tests",
        "3",
        "--report",
        "--out",
        path(&run),
    ]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("report.html"), "{stderr}");
    let html = read(&run.join("report.html"));
    assert_self_contained(&html);
    let size = html.len();
    assert!(size < 2_000_000, "a 3-test report is {size} bytes");

    // The summary says what campaign.json says.
    let record = CampaignRecord::from_json(&read(&run.join("campaign.json"))).unwrap();
    let summary = record.summary.unwrap();
    assert_eq!(by_id(&html, "count-tests"), summary.tests.to_string());
    assert_eq!(by_id(&html, "count-passed"), summary.passed.to_string());
    assert_eq!(by_id(&html, "count-failed"), summary.failed.to_string());
    assert_eq!(by_id(&html, "count-aborted"), summary.aborted.to_string());
    let worst = summary.worst_deviation_m.unwrap();
    assert_eq!(by_id(&html, "worst-deviation"), format!("{worst:.2} m"));
    assert!(html.contains(&format!("<tr><th>seed</th><td>{}</td></tr>", record.seed)));
    let hash = record.scenario.hash.unwrap();
    assert!(html.contains(&format!("hash {}", &hash[..12])));

    // A section per failing or aborted test, linked from the table, with a map and a plot;
    // the passing tests are rows of the table only.
    let not_passed: Vec<String> = (0..3)
        .filter(|i| verdict(&run.join(format!("case-{i:03}.json"))) != Some(Verdict::Passed))
        .map(|i| format!("test-{i:03}"))
        .collect();
    let tests = sections(&html, "test-");
    let ids: Vec<&str> = tests.iter().map(|(id, _)| *id).collect();
    assert_eq!(
        ids, not_passed,
        "sections of the tests that did not pass only"
    );
    for i in 0..3 {
        let id = format!("test-{i:03}");
        assert_eq!(
            html.contains(&format!("href=\"#{id}\"")),
            not_passed.contains(&id),
            "a link to {id} when it has a section"
        );
    }
    assert_all_drawn(&html, &not_passed);

    // `--all-tests`: every test's section.
    let all = dir.path().join("all.html");
    let out = drivecheck(&["report", path(&run), "--all-tests", "--out", path(&all)]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let all = read(&all);
    assert_self_contained(&all);
    let ids: Vec<&str> = sections(&all, "test-").iter().map(|(id, _)| *id).collect();
    assert_eq!(ids, ["test-000", "test-001", "test-002"]);
    assert_all_drawn(&all, &["test-000", "test-001", "test-002"]);

    // `drivecheck report` writes the same page from the directory alone (the scenario from the
    // recording).
    let again = dir.path().join("again.html");
    let out = drivecheck(&["report", path(&run), "--out", path(&again)]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert_eq!(read(&again), html);

    // A replay directory: the runs on one map, a plot per run, the comparison.
    let replay = dir.path().join("replay");
    let out = drivecheck(&[
        "replay",
        path(&run.join("case-001.json")),
        "--times",
        "2",
        "--vary-seed",
        "--report",
        "--out",
        path(&replay),
    ]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    let html = read(&replay.join("report.html"));
    assert_self_contained(&html);
    assert!(html.contains("The runs on the map"));
    assert!(html.contains("Per segment: each run's largest deviation"));
    let runs = sections(&html, "run-");
    let ids: Vec<&str> = runs.iter().map(|(id, _)| *id).collect();
    assert_eq!(ids, ["run-1", "run-2"]);
    for (id, section) in &runs {
        assert_eq!(section.matches("<svg").count(), 1, "{id}: a plot");
    }
    assert_eq!(html.matches("<svg").count(), 3, "one map and two plots");
    assert_eq!(by_id(&html, "count-tests"), "2");
}

#[test]
fn a_directory_without_a_campaign_record_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = drivecheck(&["report", path(dir.path())]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(path(dir.path())) && stderr.contains("campaign.json"),
        "{stderr}"
    );
    assert!(!dir.path().join("report.html").exists());

    // A campaign record that is not one names the file.
    std::fs::write(dir.path().join("campaign.json"), "{}").unwrap();
    let out = drivecheck(&["report", path(dir.path())]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("campaign.json:"), "{stderr}");
}

const CHROMIUM: &str = "/usr/bin/chromium";

/// Renders `page` to a PNG with headless Chromium; its size in bytes.
fn screenshot(page: &Path, png: &Path) -> u64 {
    let out = Command::new(CHROMIUM)
        .args([
            "--headless",
            "--disable-gpu",
            "--no-sandbox",
            &format!("--screenshot={}", path(png)),
            "--window-size=1200,2400",
            &format!("file://{}", path(page)),
        ])
        .output()
        .expect("chromium runs");
    assert!(out.status.success(), "{}", text(&out));
    std::fs::metadata(png).map(|m| m.len()).unwrap_or(0)
}

#[test]
fn the_report_renders_in_a_browser() {
    if !Path::new(CHROMIUM).exists() {
        eprintln!("skipped: {CHROMIUM} is not installed (apt-get install chromium)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("campaign");
    let out = drivecheck(&[
        "run",
        "--seed",
        "7",
        "--tests",
        "2",
        "--report",
        "--out",
        path(&run),
    ]);
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", text(&out));
    // A blank page of the same size compresses to almost nothing; the report's maps, plots and
    // tables do not.
    let blank = dir.path().join("blank.html");
    std::fs::write(&blank, "<!DOCTYPE html><html><body></body></html>").unwrap();
    let blank_size = screenshot(&blank, &dir.path().join("blank.png"));
    let report_size = screenshot(&run.join("report.html"), &dir.path().join("report.png"));
    assert!(blank_size > 0, "chromium wrote no PNG");
    assert!(
        report_size > 10 * blank_size && report_size > 50_000,
        "the rendered report looks blank: {report_size} bytes against {blank_size} for a blank page"
    );
}

/// A copy of the run directory `run` at `to` with `extra` more tests: copies of its first test
/// with verdict `verdict`, numbered from 100 (their case files only: the recording has no track
/// of them).
fn with_copies(run: &Path, to: &Path, verdict: Verdict, extra: usize) -> std::path::PathBuf {
    std::fs::create_dir_all(to).unwrap();
    let mut model = None;
    let mut names: Vec<String> = std::fs::read_dir(run)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    for name in names {
        if name == "report.html" {
            continue;
        }
        std::fs::copy(run.join(&name), to.join(&name)).unwrap();
        if name.starts_with("case-") && model.is_none() {
            let case = Case::from_json(&read(&run.join(&name))).unwrap();
            if case.verdict == Some(verdict) {
                model = Some(case);
            }
        }
    }
    let mut case = model.unwrap_or_else(|| panic!("no {verdict:?} test in {}", run.display()));
    for k in 0..extra {
        let index = 100 + k;
        case.test_index = Some(index);
        std::fs::write(
            to.join(format!("case-{index:03}.json")),
            case.to_json().unwrap(),
        )
        .unwrap();
    }
    to.to_owned()
}

/// Writes the report of `dir` (with `extra` arguments); the page.
fn report_of(dir: &Path, extra: &[&str]) -> String {
    let mut args = vec!["report", path(dir)];
    args.extend_from_slice(extra);
    let out = drivecheck(&args);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    read(&dir.join("report.html"))
}

#[test]
fn passing_tests_are_rows_and_the_page_does_not_grow_with_them() {
    let dir = tempfile::tempdir().unwrap();
    // Seed 1: one test passes, two fail.
    let run = common::campaign(dir.path(), 1, 3, &[], 1);
    let small = with_copies(&run, &dir.path().join("small"), Verdict::Passed, 20);
    let large = with_copies(&run, &dir.path().join("large"), Verdict::Passed, 40);
    let (small_html, large_html) = (report_of(&small, &[]), report_of(&large, &[]));
    assert_self_contained(&large_html);
    assert_eq!(
        by_id(&large_html, "count-tests"),
        "3",
        "campaign.json's summary"
    );
    for html in [&small_html, &large_html] {
        let ids: Vec<&str> = sections(html, "test-").iter().map(|(id, _)| *id).collect();
        assert_eq!(ids, ["test-001", "test-002"], "the failing tests' sections");
        assert_all_drawn(html, &ids);
        // The coverage map and chart, a map and a plot per failing test.
        assert_eq!(html.matches("<svg").count(), 2 + 2 * 2);
    }
    // Twenty more passing tests are twenty more rows, a few hundred bytes each.
    let rows = |html: &str| {
        html.matches("<tr><td>test ").count() + html.matches("<tr><td><a href=\"#test-").count()
    };
    assert_eq!(rows(&small_html), 23);
    assert_eq!(rows(&large_html), 43);
    let grown = large_html.len() as i64 - small_html.len() as i64;
    assert!(
        (0..20 * 600).contains(&grown),
        "20 more passing tests grew the page by {grown} bytes"
    );

    // `--all-tests` draws every test.
    let all = report_of(&large, &["--all-tests"]);
    assert_eq!(sections(&all, "test-").len(), 43);
    // The three recorded tests with a map and a plot, the copies (no track) with a map.
    assert_eq!(all.matches("<svg").count(), 2 + 3 * 2 + 40);
}

#[test]
fn more_failing_tests_than_a_page_holds_get_pages_of_their_own() {
    let dir = tempfile::tempdir().unwrap();
    let run = common::campaign(dir.path(), 1, 3, &[], 1);
    // Two failing tests and 120 copies of one: 122 sections, two pages of at most 100.
    let many = with_copies(&run, &dir.path().join("many"), Verdict::Failed, 120);
    let index = report_of(&many, &[]);
    assert_self_contained(&index);
    assert!(
        sections(&index, "test-").is_empty(),
        "no section on the index"
    );
    assert!(index.contains("<section id=\"pages\">"));
    let pages_dir = many.join("report");
    let mut pages: Vec<String> = std::fs::read_dir(&pages_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    pages.sort();
    assert_eq!(pages, ["tests-0001.html", "tests-0002.html"]);
    let mut seen = Vec::new();
    for (k, page) in pages.iter().enumerate() {
        let html = read(&pages_dir.join(page));
        assert_self_contained(&html);
        assert!(
            html.contains("href=\"../report.html\""),
            "{page} links back"
        );
        let ids: Vec<String> = sections(&html, "test-")
            .iter()
            .map(|(id, _)| (*id).to_owned())
            .collect();
        assert_eq!(ids.len(), [100, 22][k], "{page}");
        for id in &ids {
            assert!(
                index.contains(&format!("href=\"report/{page}#{id}\"")),
                "the index links {id} to {page}"
            );
        }
        seen.extend(ids);
    }
    let mut expected = vec!["test-001".to_owned(), "test-002".to_owned()];
    expected.extend((100..220).map(|i| format!("test-{i:03}")));
    assert_eq!(seen, expected, "every failing test once, in order");

    // Fewer failing tests again: one page, and the old pages are gone.
    for i in 130..220 {
        std::fs::remove_file(many.join(format!("case-{i:03}.json"))).unwrap();
    }
    let index = report_of(&many, &[]);
    assert_eq!(sections(&index, "test-").len(), 32);
    assert!(
        !pages_dir.exists(),
        "the earlier report's pages are removed"
    );
}

/// A pid above any `pid_max` (4194304): no process has it.
const DEAD_PID: u32 = 4_294_967_295;

/// What a report or a campaign killed with `kill -9` left in a run directory (#51 item 11: the
/// sections a report put aside, a case file's temporary file) is removed by the next report
/// there, with a note; a scratch file of a live process (this test's) is not.
#[test]
fn a_report_removes_what_a_killed_process_left_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let ran = drivecheck(&[
        "-q",
        "run",
        "--seed",
        "1",
        "--tests",
        "2",
        "--out",
        path(&run),
    ]);
    assert!(matches!(ran.status.code(), Some(0 | 1)), "{}", text(&ran));
    let left = [
        format!(".report.html.sections-{DEAD_PID}"),
        format!(".case-001.json.tmp-{DEAD_PID}"),
    ];
    for name in &left {
        std::fs::write(run.join(name), "half a file").unwrap();
    }
    let live = format!(".case-000.json.tmp-{}", std::process::id());
    std::fs::write(run.join(&live), "being written").unwrap();
    let out = drivecheck(&["report", path(&run)]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let said = String::from_utf8_lossy(&out.stderr);
    for name in &left {
        assert!(!run.join(name).exists(), "{name} is left: {said}");
        assert!(
            said.contains(&format!("removed {}", run.join(name).display()))
                && said.contains(&format!("left by process {DEAD_PID}, which no longer runs")),
            "{said}"
        );
    }
    assert!(run.join(&live).exists(), "a live process's file is kept");
    assert!(run.join("report.html").is_file());
}
