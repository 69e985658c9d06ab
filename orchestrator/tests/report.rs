//! `drivecheck report`, `run --report` and `replay --report`: a self-contained `report.html`
//! with a section, a map and a plot per test (per run for a replay) whose summary matches the
//! run directory's records; rendered by a real browser when one is installed.

mod common;

use std::path::Path;
use std::process::Command;

use campaign::files::CampaignRecord;
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

/// The text of the element with `id` (`<span id="count-passed">7</span>` → `7`).
fn by_id<'a>(html: &'a str, id: &str) -> &'a str {
    let marker = format!("id=\"{id}\">");
    let start = html.find(&marker).unwrap_or_else(|| panic!("no #{id}")) + marker.len();
    let end = start + html[start..].find('<').unwrap();
    &html[start..end]
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

    // One section per test, linked from the table, with a map and a plot.
    let tests = sections(&html, "test-");
    let ids: Vec<&str> = tests.iter().map(|(id, _)| *id).collect();
    assert_eq!(ids, ["test-000", "test-001", "test-002"]);
    for (id, section) in &tests {
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
