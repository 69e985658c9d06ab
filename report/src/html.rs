//! The page: HTML with inline CSS and the SVG pictures inline, no script and no external
//! reference, so it opens from a file anywhere.

use std::fmt::Write;

use scenarios::Scenario;

use super::ReportError;
use super::data::{Origin, ReplayData, Row, Sample, ShrinkData, TestData, short};
use super::draw::{
    AMBER, BarPanel, Colouring, FAULT, FaultMark, GREEN, MAX_TRACK_POINTS, MapLayers, PlotInput,
    RED_ABOVE, RUN_COLOURS, TrackLayer, Window, bars_svg, css, decimate, deviation_svg, map_svg,
};
use super::explain::{ExplainOptions, explain_segments, fault_number};
use super::route::{boundaries, point_along, segments};
use campaign::case::CampaignRecord;
use campaign::case::{Case, CommandRecord};
use campaign::coverage::{Bin, Coverage, CoverageStats, FaultCoverage};
use campaign::explain::{SegmentExplanation, Source};
use campaign::oracle::{SegmentVerdict, Verdict};
use campaign::shrink::{Edit, FaultField, Outcome, RunResult, Step};
use runner::TestSummary;

const CSS: &str = r#"
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 0 auto;
  max-width: 1100px; padding: 16px 24px 48px; color: #1d1d1d; background: #fff; }
h1 { font-size: 1.6em; margin: 0.4em 0 0.1em; }
h2 { font-size: 1.25em; margin: 1.6em 0 0.4em; border-bottom: 1px solid #ddd; padding-bottom: 4px; }
h3 { font-size: 1.05em; margin: 1.2em 0 0.3em; }
.sub { color: #555; margin: 0 0 1em; }
table { border-collapse: collapse; margin: 0.4em 0 0.8em; font-size: 0.92em; }
th, td { border: 1px solid #d8d8d8; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #f3f3f3; font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
table.facts th { width: 13em; }
.verdict { display: inline-block; padding: 1px 8px; border-radius: 9px; color: #fff;
  font-size: 0.85em; font-weight: 600; }
.passed { background: #1a9850; } .failed { background: #d7191c; } .aborted { background: #e68a00; }
.notrun { background: #888; }
td.above { color: #d7191c; font-weight: 600; }
td.runs { white-space: nowrap; }
.figure { margin: 0.5em 0; overflow-x: auto; }
.figure svg { max-width: 100%; height: auto; border: 1px solid #e4e4e4; }
.legend { font-size: 0.9em; color: #444; margin: 0.2em 0 1em; line-height: 1.7; }
.legend .entry { display: inline-block; white-space: nowrap; margin-right: 1.2em; }
.legend p { margin: 0.1em 0; line-height: 1.4; }
.legend span.sw { display: inline-block; width: 22px; height: 4px; vertical-align: middle;
  margin: 0 5px 0 0; }
.legend span.dot { display: inline-block; width: 10px; height: 10px; border-radius: 5px;
  vertical-align: middle; margin: 0 5px 0 0; }
.legend b.n, td b.n { display: inline-block; min-width: 1em; padding: 0 3px; margin-right: 4px;
  border: 1px solid #7b3294; color: #7b3294; background: #fff; text-align: center; }
.columns { display: flex; flex-wrap: wrap; gap: 0 2.5em; align-items: flex-start; }
.notes { background: #fff8e1; border: 1px solid #f0d890; padding: 6px 12px 6px 28px; }
.test { border-top: 3px solid #eee; margin-top: 2em; }
a { color: #1f5fae; }
code { background: #f4f4f4; padding: 0 3px; }
footer { margin-top: 3em; color: #777; font-size: 0.85em; }
"#;

/// Escapes text for HTML.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

fn metres(value: Option<f64>) -> String {
    value.map_or_else(|| "–".to_owned(), |m| format!("{m:.2} m"))
}

fn seconds(value: f64) -> String {
    if value < 120.0 {
        format!("{value:.1} s")
    } else {
        format!("{:.0} min {:.0} s", (value / 60.0).floor(), value % 60.0)
    }
}

fn badge(verdict: Option<Verdict>) -> String {
    let (class, text) = match verdict {
        Some(Verdict::Passed) => ("passed", "passed"),
        Some(Verdict::Failed) => ("failed", "failed"),
        Some(Verdict::Aborted) => ("aborted", "aborted"),
        None => ("notrun", "not run"),
    };
    format!(r#"<span class="verdict {class}">{text}</span>"#)
}

pub fn head(out: &mut String, title: &str) {
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{}</title>\n<style>{CSS}</style>\n</head>\n<body>\n",
        escape(title)
    );
}

fn notes(out: &mut String, notes: &[String]) {
    if notes.is_empty() {
        return;
    }
    out.push_str("<ul class=\"notes\">\n");
    for note in notes {
        let _ = writeln!(out, "<li>{}</li>", escape(note));
    }
    out.push_str("</ul>\n");
}

pub fn foot(out: &mut String, dir: &std::path::Path) {
    let _ = write!(
        out,
        "<footer>Written by drivecheck {} from <code>{}</code>. Every picture is inline SVG; the \
         page needs no network and no script.</footer>\n</body>\n</html>\n",
        escape(campaign::case::tool_version()),
        escape(&dir.display().to_string())
    );
}

pub fn fact(out: &mut String, name: &str, value: &str) {
    let _ = writeln!(out, "<tr><th>{}</th><td>{value}</td></tr>", escape(name));
}

/// Seconds between two RFC 3339 times, when both parse.
fn wall_seconds(started: &str, ended: Option<&str>) -> Option<f64> {
    let start = humantime::parse_rfc3339_weak(started).ok()?;
    let end = humantime::parse_rfc3339_weak(ended?).ok()?;
    end.duration_since(start).ok().map(|d| d.as_secs_f64())
}

/// The fault command of a placement.
fn probe_of(case: &Case, command_index: usize) -> String {
    match case.commands.get(command_index) {
        Some(CommandRecord::AddFault { probe, .. }) => probe.to_string(),
        _ => format!("command {command_index}"),
    }
}

fn threshold_of(case: &Case, fallback: f64) -> f64 {
    case.segments
        .first()
        .map(|s| s.oracle.threshold_m)
        .or_else(|| case.settings.as_ref().map(|s| s.oracle_threshold_m))
        .unwrap_or(fallback)
}

/// The faults of a test on the map: the car's place when each was added, and the RTK track
/// while it acted; each labelled with its number in the key (see [`fault_key`]).
fn fault_marks(scenario: &Scenario, case: &Case, samples: &[Sample]) -> Vec<FaultMark> {
    let segs = segments(case);
    case.fault_places
        .iter()
        .enumerate()
        .filter_map(|(k, place)| {
            let along = place.actual_along_m.unwrap_or(place.planned_along_m);
            let at = point_along(scenario, &segs, place.segment_index, along)?;
            let window = samples
                .iter()
                .filter(|s| s.t_s >= place.acts_from_s && s.t_s <= place.acts_to_s)
                .map(|s| s.rtk)
                .collect();
            Some(FaultMark {
                at,
                label: (k + 1).to_string(),
                window,
            })
        })
        .collect()
}

/// How many segments the car drove: up to the last one judged.
fn driven(case: &Case) -> usize {
    case.segments
        .iter()
        .map(|s| s.segment_index + 1)
        .max()
        .unwrap_or(0)
}

/// The faults' windows on the plot, numbered as in the key.
fn windows(case: &Case) -> Vec<Window> {
    case.fault_places
        .iter()
        .enumerate()
        .map(|(k, p)| Window {
            from_s: p.acts_from_s,
            to_s: p.acts_to_s,
            label: (k + 1).to_string(),
        })
        .collect()
}

/// A fault command in few words: its probe, what it does and its parameter.
fn fault_brief(case: &Case, command_index: usize) -> String {
    match case.commands.get(command_index) {
        Some(CommandRecord::AddFault {
            probe, kind, param, ..
        }) => format!("{probe}: {} {param:.3}", kind.spec().name.replace('_', " ")),
        _ => format!("command {command_index}"),
    }
}

/// A fault's number as it is drawn on the map and the plot.
fn number_badge(number: usize) -> String {
    format!("<b class=\"n\">{number}</b>")
}

/// The key of a test's numbered faults (the map's markers, the plot's windows): each number,
/// its fault and when it acted.
fn fault_key(out: &mut String, case: &Case) {
    if case.fault_places.is_empty() {
        return;
    }
    out.push_str("<div class=\"legend\"><span class=\"entry\">Faults by number:</span>");
    for (k, p) in case.fault_places.iter().enumerate() {
        let _ = write!(
            out,
            " <span class=\"entry\">{}{}, acts from {} to {}</span>",
            number_badge(k + 1),
            escape(&fault_brief(case, p.command_index)),
            seconds(p.acts_from_s),
            seconds(p.acts_to_s)
        );
    }
    out.push_str("</div>\n");
}

/// A legend entry: a swatch of `style` and its `text` (HTML), kept on one line.
pub fn swatch(style: &str, text: &str) -> String {
    format!("<span class=\"entry\"><span class=\"sw\" style=\"{style}\"></span>{text}</span>")
}

/// A legend of `entries` (wrapping between entries, never inside one), then `note` (HTML) as
/// a paragraph when given.
pub fn legend(out: &mut String, entries: &[String], note: Option<&str>) {
    let _ = write!(out, "<div class=\"legend\">{}", entries.join(" "));
    if let Some(note) = note {
        let _ = write!(out, "<p>{note}</p>");
    }
    out.push_str("</div>\n");
}

fn map_legend(out: &mut String, deviation: bool) {
    let dashed = "background:repeating-linear-gradient(90deg,#4a7fc1 0 6px,transparent 6px 10px)";
    let mut entries = vec![
        swatch("background:#000", "fence"),
        swatch("background:#9a9a9a;height:10px", "cutout"),
        swatch("background:#b0b0b0", "start route"),
        swatch(dashed, "planned segments s0, s1, … (faint: not driven)"),
        swatch("background:#252525;height:1px", "RTK track"),
    ];
    if deviation {
        for (colour, text) in [
            (GREEN, "UWB track below half the threshold"),
            (AMBER, "UWB up to the threshold"),
            (RED_ABOVE, "UWB above the threshold"),
        ] {
            entries.push(swatch(&format!("background:{}", css(colour)), text));
        }
    }
    let f = css(FAULT);
    entries.push(format!(
        "<span class=\"entry\"><span class=\"dot\" style=\"border:2px solid {f};width:8px;\
         height:8px\"></span>where the car was when a fault was added</span> \
         <span class=\"entry\">{}a fault's number (the key below)</span>",
        number_badge(1)
    ));
    entries.push(swatch(
        &format!("background:{f};opacity:0.35;height:9px"),
        "where it drove while the fault acted",
    ));
    entries.push("<span class=\"entry\">▲ anchor</span>".to_owned());
    legend(out, &entries, None);
}

fn plot_legend(out: &mut String, origin: Origin) {
    let origin = match origin {
        Origin::Autopilot => {
            "Time 0 is when the car acknowledged the command that started the test's autopilot: \
             the runner's test clock."
        }
        Origin::StartEvent => {
            "Time 0 is the test's start event (the car's acknowledgement of the autopilot command \
             is not recorded): the samples may be drawn up to a few round trips late against the \
             fault windows."
        }
    };
    let entries = [
        "<span class=\"entry\">deviation per state sample, coloured as on the map</span>"
            .to_owned(),
        swatch(
            &format!(
                "background:repeating-linear-gradient(90deg,{} 0 8px,transparent 8px 13px)",
                css(RED_ABOVE)
            ),
            "threshold",
        ),
        swatch(
            "background:#888;width:2px;height:12px",
            "the car enters segment s0, s1, … (located on the route as the runner does) or ends",
        ),
        swatch(
            &format!("background:{};opacity:0.25;height:12px", css(FAULT)),
            "while a fault acts (estimated from its probe's call rate), numbered",
        ),
    ];
    legend(out, &entries, Some(origin));
}

fn segments_table(out: &mut String, case: &Case) {
    if case.segments.is_empty() {
        return;
    }
    out.push_str(
        "<table><tr><th>segment</th><th>command</th><th>samples</th><th>largest deviation</th>\
         <th>RMS</th><th>95th percentile</th><th>verdict</th><th>faults added before it</th></tr>\n",
    );
    for s in &case.segments {
        let o = &s.oracle;
        let (samples, max, rms, p95) = o.stats.map_or_else(
            || ("0".to_owned(), None, None, None),
            |st| {
                (
                    st.samples.to_string(),
                    Some(st.max_m),
                    Some(st.rms_m),
                    Some(st.p95_m),
                )
            },
        );
        let above = max.is_some_and(|m| m > o.threshold_m);
        let verdict = match o.verdict {
            SegmentVerdict::Passed => "passed",
            SegmentVerdict::Failed => "<strong>failed</strong>",
            SegmentVerdict::NoSamples => "no samples",
        };
        let faults: Vec<String> = s
            .faults_preceding
            .iter()
            .map(|&i| {
                let number = fault_number(case, i).map_or_else(String::new, number_badge);
                format!("{number}{}", escape(&probe_of(case, i)))
            })
            .collect();
        let _ = writeln!(
            out,
            "<tr><td class=\"num\">s{}</td><td class=\"num\">{}</td><td class=\"num\">{samples}</td>\
             <td class=\"num{}\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{verdict}</td><td>{}</td></tr>",
            s.segment_index,
            s.command_index,
            if above { " above" } else { "" },
            metres(max),
            metres(rms),
            metres(p95),
            faults.join(", ")
        );
    }
    out.push_str("</table>\n");
}

fn faults_table(out: &mut String, case: &Case) {
    if case.fault_places.is_empty() {
        return;
    }
    out.push_str(
        "<table><tr><th>fault</th><th>command</th><th>what it does</th><th>segment</th>\
         <th>planned place</th><th>where the car was</th><th>added at</th>\
         <th>acts (estimated)</th></tr>\n",
    );
    for (k, p) in case.fault_places.iter().enumerate() {
        let fault = match case.commands.get(p.command_index) {
            Some(CommandRecord::AddFault {
                start, duration, ..
            }) => format!(
                "{}; it starts {start} calls of its probe after it is added and lasts {duration} calls",
                fault_brief(case, p.command_index)
            ),
            _ => "?".to_owned(),
        };
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td class=\"num\">{}</td><td>{}</td><td class=\"num\">s{}</td>\
             <td class=\"num\">{:.2} m along it</td><td class=\"num\">{}</td>\
             <td class=\"num\">{:.2} s</td><td class=\"num\">from {:.2} s to {:.2} s</td></tr>",
            number_badge(k + 1),
            p.command_index,
            escape(&fault),
            p.segment_index,
            p.planned_along_m,
            p.actual_along_m
                .map_or_else(|| "–".to_owned(), |a| format!("{a:.2} m along it")),
            p.added_s,
            p.acts_from_s,
            p.acts_to_s
        );
    }
    out.push_str("</table>\n");
}

pub fn figure(out: &mut String, svg: Option<String>, missing: &str) {
    match svg {
        Some(svg) => {
            out.push_str("<div class=\"figure\">\n");
            out.push_str(&svg);
            out.push_str("</div>\n");
        }
        None => {
            let _ = writeln!(out, "<p class=\"sub\">{}</p>", escape(missing));
        }
    }
}

/// The causes of each failing segment's error growth (`drivecheck explain`), most first.
fn causes_table(out: &mut String, case: &Case, explained: &[SegmentExplanation]) {
    out.push_str(
        "<table>\n<tr><th>segment</th><th>|UWB − RTK|</th><th>cause</th><th>share</th>\
         <th>growth</th></tr>\n",
    );
    for segment in explained {
        let rows = segment.causes.len();
        for (k, cause) in segment.causes.iter().enumerate() {
            let first = if k == 0 {
                format!(
                    "<td rowspan=\"{rows}\">s{}</td><td rowspan=\"{rows}\">{:.2} → {:.2} m, \
                     {:.1}–{:.1} s{}</td>",
                    segment.segment_index,
                    segment.error_from_m,
                    segment.error_to_m,
                    segment.from_s,
                    segment.to_s,
                    if segment.carried_over {
                        " (carried over from before the segment)"
                    } else {
                        ""
                    }
                )
            } else {
                String::new()
            };
            let ambiguous = cause.ambiguous_with.map_or_else(String::new, |other| {
                format!(
                    " (cannot always be told apart from {})",
                    cause_words(&other, case)
                )
            });
            let _ = writeln!(
                out,
                "<tr>{first}<td>{}{}</td><td>{:.0} %</td><td>{:.2} m</td></tr>",
                escape(&cause_words(&cause.source, case)),
                escape(&ambiguous),
                cause.share * 100.0,
                cause.growth_m
            );
        }
    }
    out.push_str(
        "</table>\n<p class=\"sub\">Each step's change of UWB − RTK is credited to the \
         direction it follows: an anchor's line (its range), the heading (odometry) or across it \
         (yaw), and to the fault acting that way in its window (docs/explain.md).</p>\n",
    );
}

/// A cause in words, with its fault command's probe.
fn cause_words(source: &Source, case: &Case) -> String {
    match source {
        Source::Fault { command_index } => match fault_number(case, *command_index) {
            Some(number) => format!(
                "fault {number} (command {command_index}: {})",
                probe_of(case, *command_index)
            ),
            None => format!(
                "fault: command {command_index} ({})",
                probe_of(case, *command_index)
            ),
        },
        Source::Anchor { anchor_id } => format!("anchor {anchor_id}'s range"),
        Source::Odometry => "odometry".to_owned(),
        Source::Heading => "heading".to_owned(),
        Source::Unexplained => "unexplained".to_owned(),
    }
}

/// The section of one test (or one run of a replay): facts, map, plot, tables.
pub fn test_section(
    out: &mut String,
    id: &str,
    title: &str,
    test: &TestData,
    scenario: Option<&Scenario>,
    fallback_threshold: f64,
    draw_map: bool,
) -> Result<(), ReportError> {
    let case = &test.case;
    let summary = TestSummary::of(test.index, test.file.clone(), case);
    let _ = writeln!(
        out,
        "<section class=\"test\" id=\"{id}\">\n<h2>{} {}</h2>",
        escape(title),
        badge(case.verdict)
    );
    if let Some(reason) = &case.reason {
        let _ = writeln!(out, "<p><strong>{}</strong></p>", escape(reason));
    }
    let segments_count = segments(case).len();
    let faults = case
        .commands
        .iter()
        .filter(|c| matches!(c, CommandRecord::AddFault { .. }))
        .count();
    let timing = case.timing.map_or_else(String::new, |t| {
        format!(
            " · reset {}, drive {}",
            seconds(t.reset_s),
            seconds(t.drive_s)
        )
    });
    let _ = writeln!(
        out,
        "<p class=\"sub\"><code>{}</code> · {} commands, {segments_count} segments ({} driven), \
         {faults} faults · worst deviation {}{timing}</p>",
        escape(&test.file),
        case.commands.len(),
        case.segments.len(),
        metres(summary.worst_deviation_m)
    );
    let threshold = threshold_of(case, fallback_threshold);
    let samples = test
        .track
        .as_ref()
        .map(|t| decimate(&t.samples, MAX_TRACK_POINTS))
        .unwrap_or_default();
    if draw_map {
        let layers = MapLayers {
            heat: None,
            segments: segments(case),
            driven: driven(case),
            tracks: vec![TrackLayer {
                samples: &samples,
                colouring: Colouring::ByDeviation { threshold },
                rtk: true,
            }],
            faults: scenario.map_or_else(Vec::new, |s| fault_marks(s, case, &samples)),
        };
        out.push_str("<h3>Map</h3>\n");
        figure(
            out,
            map_svg(scenario, &layers)?,
            "No map: neither the scenario nor a track is known.",
        );
        map_legend(out, true);
        fault_key(out, case);
    }
    out.push_str("<h3>Deviation against time</h3>\n");
    let bounds = match scenario {
        Some(s) => boundaries(s, case, &samples),
        None => Vec::new(),
    };
    let windows = windows(case);
    let plot = deviation_svg(&PlotInput {
        samples: &samples,
        threshold,
        boundaries: &bounds,
        windows: &windows,
    })?;
    let has_plot = plot.is_some();
    figure(
        out,
        plot,
        "No plot: the recording has no state samples of this test.",
    );
    if has_plot && let Some(track) = &test.track {
        plot_legend(out, track.origin);
        fault_key(out, case);
    }
    if let Some(scenario) = scenario
        && case
            .segments
            .iter()
            .any(|s| s.oracle.verdict == SegmentVerdict::Failed)
    {
        out.push_str("<h3>Why it failed</h3>\n");
        match explain_segments(
            &test.case,
            test.track.as_ref(),
            scenario,
            &ExplainOptions::default(),
        ) {
            Ok(explained) => causes_table(out, case, &explained),
            Err(why) => {
                let _ = writeln!(
                    out,
                    "<p class=\"sub\">Not explained: {}.</p>",
                    escape(&why.to_string())
                );
            }
        }
    }
    out.push_str("<h3>Segments</h3>\n");
    segments_table(out, case);
    if !case.fault_places.is_empty() {
        out.push_str("<h3>Faults</h3>\n");
        faults_table(out, case);
    }
    out.push_str("</section>\n");
    Ok(())
}

/// What the top of a campaign's page shows: `campaign.json`, a row per test, `twin.json`.
pub struct CampaignTop<'a> {
    /// The run directory.
    pub dir: &'a std::path::Path,
    /// `campaign.json`.
    pub record: &'a CampaignRecord,
    /// A row per test.
    pub rows: &'a [Row],
    /// `twin.json`, when a twin check wrote one.
    pub twin: Option<&'a campaign::files::TwinCheck>,
    /// What the page should say about missing or unreadable parts.
    pub notes: &'a [String],
}

/// The title of a campaign's pages.
fn campaign_title(record: &CampaignRecord) -> String {
    format!(
        "drivecheck campaign seed {} on {}",
        record.seed, record.scenario.name
    )
}

/// The top of a campaign's page: the summary, the twin check and the tests table, each row
/// linking to `link(test index)` when the test has a section.
pub fn campaign_top(
    out: &mut String,
    top: &CampaignTop<'_>,
    link: impl Fn(usize) -> Option<String>,
) {
    let CampaignTop {
        dir,
        record,
        rows,
        twin,
        notes: page_notes,
    } = *top;
    head(out, &campaign_title(record));
    let _ = writeln!(
        out,
        "<h1>Campaign seed {} on {}</h1>\n<p class=\"sub\">Run directory <code>{}</code></p>",
        record.seed,
        escape(&record.scenario.name),
        escape(&dir.display().to_string())
    );
    notes(out, page_notes);
    out.push_str("<section id=\"summary\">\n<h2>Summary</h2>\n<table class=\"facts\">\n");
    fact(out, "seed", &record.seed.to_string());
    fact(
        out,
        "scenario",
        &format!(
            "{} (hash {})",
            escape(&record.scenario.name),
            record.scenario.hash.as_deref().map_or("–", short)
        ),
    );
    fact(out, "drivecheck", &escape(record.header.tool()));
    fact(
        out,
        "car",
        &format!(
            "{}, firmware {}",
            escape(&record.car),
            escape(record.car_firmware_version.as_deref().unwrap_or("unknown"))
        ),
    );
    // On several cars, each car: its tests, and why it left if it did.
    for car in &record.cars {
        fact(
            out,
            &match car.session {
                Some(session) => format!("car {} (session {session})", car.name),
                None => format!("car {}", car.name),
            },
            &format!(
                "{}, firmware {}: {} test{}{}",
                escape(&car.address),
                escape(car.firmware.as_deref().unwrap_or("unknown")),
                car.tests.len(),
                if car.tests.len() == 1 { "" } else { "s" },
                car.left
                    .as_deref()
                    .map(|why| format!("; <b>left the campaign</b>: {}", escape(why)))
                    .unwrap_or_default()
            ),
        );
    }
    if let Some(of) = &record.replay_of {
        fact(out, "replay of", &escape(&of.case));
    }
    if let Some(of) = &record.cases_from {
        fact(
            out,
            "cases of",
            &format!(
                "{} (campaign seed {}, {} tests)",
                escape(&of.run),
                of.campaign_seed,
                of.tests
            ),
        );
    }
    if record.no_faults {
        fact(out, "faults", "none (--no-faults)");
    }
    let counts = |v| rows.iter().filter(|r| r.verdict == Some(v)).count();
    let (tests, passed, failed, aborted) = match &record.summary {
        Some(s) => (s.tests, s.passed, s.failed, s.aborted),
        None => (
            rows.len(),
            counts(Verdict::Passed),
            counts(Verdict::Failed),
            counts(Verdict::Aborted),
        ),
    };
    fact(
        out,
        "tests",
        &format!(
            "<span id=\"count-tests\">{tests}</span>: \
             <span class=\"verdict passed\" id=\"count-passed\">{passed}</span> passed, \
             <span class=\"verdict failed\" id=\"count-failed\">{failed}</span> failed, \
             <span class=\"verdict aborted\" id=\"count-aborted\">{aborted}</span> aborted"
        ),
    );
    let worst = record
        .summary
        .as_ref()
        .and_then(|s| s.worst_deviation_m)
        .or_else(|| {
            rows.iter()
                .filter_map(|r| r.worst_deviation_m)
                .max_by(f64::total_cmp)
        });
    fact(
        out,
        "worst deviation",
        &format!(
            "<span id=\"worst-deviation\">{}</span> (threshold {:.2} m)",
            metres(worst),
            record.settings.oracle_threshold_m
        ),
    );
    fact(
        out,
        "started, ended",
        &format!(
            "{}, {}",
            escape(&record.started_at),
            escape(record.ended_at.as_deref().unwrap_or("– (did not end)"))
        ),
    );
    match wall_seconds(&record.started_at, record.ended_at.as_deref()) {
        Some(s) if s < 1.0 => fact(out, "wall time", "under a second"),
        Some(s) => fact(out, "wall time", &seconds(s)),
        None => fact(out, "wall time", "unknown"),
    }
    let timed: Vec<_> = rows.iter().filter_map(|r| r.timing).collect();
    if !timed.is_empty() {
        let drive: f64 = timed.iter().map(|t| t.drive_s).sum();
        let reset: f64 = timed.iter().map(|t| t.reset_s).sum();
        let clock = if record.car == "sim" {
            " (simulated time)"
        } else {
            ""
        };
        fact(
            out,
            "driven",
            &format!(
                "{} in tests, {} in resets{clock}{}",
                seconds(drive),
                seconds(reset),
                if timed.len() < rows.len() {
                    format!(", {} of {} tests timed", timed.len(), rows.len())
                } else {
                    String::new()
                }
            ),
        );
    }
    if let Some(profile) = &record.car_profile {
        fact(
            out,
            "car profile",
            &format!("{} (hash {})", escape(&profile.name), short(&profile.hash)),
        );
    }
    out.push_str("</table>\n</section>\n");
    if let Some(twin) = twin {
        twin_section(out, twin);
    }
    out.push_str(
        "<section id=\"tests\">\n<h2>Tests</h2>\n<table><tr><th>test</th><th>verdict</th>\
         <th>worst deviation</th><th>segments driven</th><th>faults</th><th>drive</th>\
         <th>failing segment or reason</th></tr>\n",
    );
    let threshold = record.settings.oracle_threshold_m;
    for r in rows {
        let above = r.worst_deviation_m.is_some_and(|w| w > threshold);
        let name = format!("test {:03}", r.index);
        let name = match link(r.index) {
            Some(href) => format!("<a href=\"{}\">{name}</a>", escape(&href)),
            None => name,
        };
        let _ = writeln!(
            out,
            "<tr><td>{name}</td><td>{}</td>\
             <td class=\"num{}\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>\
             <td class=\"num\">{}</td><td>{}</td></tr>",
            badge(r.verdict),
            if above { " above" } else { "" },
            metres(r.worst_deviation_m),
            r.segments,
            r.faults,
            r.timing
                .map_or_else(|| "–".to_owned(), |t| seconds(t.drive_s)),
            escape(r.reason.as_deref().unwrap_or("")),
        );
    }
    out.push_str("</table>\n</section>\n");
}

/// The head of a page of a campaign's test sections (`first` to `last`, page `page` of
/// `pages`), linking back to the `index` page and to the pages around it.
pub fn section_page_top(
    out: &mut String,
    record: &CampaignRecord,
    index: &str,
    page: (usize, usize),
    tests: (usize, usize),
    link: impl Fn(usize) -> String,
) {
    let (page, pages) = page;
    head(
        out,
        &format!(
            "{}, tests {:03}–{:03}",
            campaign_title(record),
            tests.0,
            tests.1
        ),
    );
    let _ = writeln!(
        out,
        "<h1>Campaign seed {} on {}: tests {:03} to {:03}</h1>",
        record.seed,
        escape(&record.scenario.name),
        tests.0,
        tests.1
    );
    page_nav(out, index, page, pages, link);
}

/// Links to the index page and to the previous and next pages of sections.
pub fn page_nav(
    out: &mut String,
    index: &str,
    page: usize,
    pages: usize,
    link: impl Fn(usize) -> String,
) {
    let _ = write!(
        out,
        "<p class=\"sub\">Page {page} of {pages} of the failing and aborted tests' sections · \
         <a href=\"{}\">the summary, coverage and every test</a>",
        escape(index)
    );
    if page > 1 {
        let _ = write!(
            out,
            " · <a href=\"{}\">previous page</a>",
            escape(&link(page - 1))
        );
    }
    if page < pages {
        let _ = write!(
            out,
            " · <a href=\"{}\">next page</a>",
            escape(&link(page + 1))
        );
    }
    out.push_str("</p>\n");
}

/// The index page's list of the pages of test sections: each page's link and its tests.
pub fn pages_section(out: &mut String, pages: &[(String, usize, usize, usize)]) {
    out.push_str(
        "<section id=\"pages\">\n<h2>Test sections</h2>\n<p>The failing and aborted tests' \
         maps, plots and tables are on pages of their own, linked from the tests table above:</p>\n<ul>\n",
    );
    for (href, first, last, count) in pages {
        let _ = writeln!(
            out,
            "<li><a href=\"{}\">tests {first:03} to {last:03}</a> ({count} tests)</li>",
            escape(href)
        );
    }
    out.push_str("</ul>\n</section>\n");
}

/// What the campaign covered: a heat map of the cells its tests drove, then the numbers
/// (`drivecheck runs show --coverage`).
/// `twin.json`: how far each simulated car reproduces this run (`drivecheck twin check`).
fn twin_section(out: &mut String, twin: &campaign::files::TwinCheck) {
    let _ = writeln!(
        out,
        "<section id=\"twin\">\n<h2>Twin check</h2>\n<p>The run's {} case(s) driven {} time(s) \
         again on simulated cars: how often their segment verdicts agree with the recording's, \
         and Δ, a segment's recorded largest deviation minus its simulated runs' median \
         (absolute). A twin is as trustworthy as its figures are near the car's own \
         repeatability.</p>\n<table><tr><th>simulated car</th><th>segments</th>\
         <th>verdicts agreed</th><th>median Δ</th><th>p90 Δ</th></tr>",
        twin.cases, twin.runs
    );
    let row = |out: &mut String, name: String, s: &campaign::files::TwinSummary| {
        let _ = writeln!(
            out,
            "<tr><td>{name}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            s.segments,
            s.verdicts_agreed
                .map_or_else(|| "–".to_owned(), |a| format!("{:.0} %", a * 100.0)),
            metres(s.median_abs_delta_m),
            metres(s.p90_abs_delta_m)
        );
    };
    for result in &twin.profiles {
        row(
            out,
            format!(
                "car profile {} (hash {})",
                escape(&result.profile.name),
                short(&result.profile.hash)
            ),
            &result.summary,
        );
    }
    if let Some(repeat) = &twin.repeatability {
        row(
            out,
            format!("the car again ({})", escape(&repeat.run)),
            &repeat.summary,
        );
    }
    out.push_str("</table>\n</section>\n");
}

pub fn coverage_section(
    out: &mut String,
    scenario: Option<&Scenario>,
    coverage: Option<&Coverage>,
) -> Result<(), ReportError> {
    let (Some(scenario), Some(coverage)) = (scenario, coverage) else {
        return Ok(());
    };
    out.push_str("<section id=\"coverage\">\n<h2>Coverage</h2>\n");
    let layers = MapLayers {
        heat: Some(&coverage.grid),
        segments: Vec::new(),
        driven: 0,
        tracks: Vec::new(),
        faults: Vec::new(),
    };
    figure(
        out,
        map_svg(Some(scenario), &layers)?,
        "No map of the area.",
    );
    let _ = writeln!(
        out,
        "<p class=\"sub\">Cells of {} m the tests' driven segments passed through, pale for \
         one to dark red for the most (logarithmic).</p>",
        coverage.stats.cell_m
    );
    coverage_figures(out, &coverage.stats)?;
    out.push_str("</section>\n");
    Ok(())
}

/// The coverage figures `runs show --coverage` prints (`CoverageStats`), as tables, with a
/// chart of the share of the metres driven per heading and per speed.
fn coverage_figures(out: &mut String, c: &CoverageStats) -> Result<(), ReportError> {
    let total = c.driven_m();
    out.push_str("<table class=\"facts\">\n");
    fact(out, "tests", &c.tests.to_string());
    fact(
        out,
        "drivable area driven",
        &format!(
            "{:.1} % ({} of {} cells of {} m)",
            c.area_share * 100.0,
            c.driven_cells,
            c.drivable_cells,
            c.cell_m
        ),
    );
    fact(out, "metres driven", &format!("{total:.0} m"));
    let by_segments: Vec<String> = c
        .tests_by_segments()
        .iter()
        .map(|(segments, n)| format!("{segments} segments: {n}"))
        .collect();
    fact(out, "tests by segments driven", &by_segments.join(", "));
    out.push_str("</table>\n");
    let share = |b: &Bin| if total > 0.0 { b.metres / total } else { 0.0 };
    let (headings, speeds) = (c.heading_bins(), c.speed_bins());
    let panels = [
        BarPanel {
            title: "heading, counter-clockwise from east",
            bars: headings
                .iter()
                .map(|b| (format!("{:.0}°", b.from), share(b)))
                .collect(),
        },
        BarPanel {
            title: "speed",
            bars: speeds
                .iter()
                .map(|b| (format!("{:.0}–{:.0} km/h", b.from, b.to), share(b)))
                .collect(),
        },
    ];
    if total > 0.0 {
        out.push_str("<h3>Share of the metres driven by heading and by speed</h3>\n");
        figure(out, bars_svg(&panels)?, "No chart.");
    }
    out.push_str("<div class=\"columns\">\n");
    bins_table(
        out,
        "heading (counter-clockwise from east)",
        &headings,
        total,
        "°",
    );
    bins_table(out, "speed", &speeds, total, " km/h");
    out.push_str("</div>\n");
    coverage_faults(out, &c.faults);
    Ok(())
}

/// A table of the metres driven per bin (`unit` after each bound).
fn bins_table(out: &mut String, what: &str, bins: &[Bin], total: f64, unit: &str) {
    let _ = writeln!(
        out,
        "<table><tr><th>{}</th><th>metres driven</th><th>share</th></tr>",
        escape(what)
    );
    for b in bins {
        let share = if total > 0.0 { b.metres / total } else { 0.0 };
        let _ = writeln!(
            out,
            "<tr><td class=\"num\">{:.0}–{:.0}{unit}</td><td class=\"num\">{:.1} m</td>\
             <td class=\"num\">{:.0} %</td></tr>",
            b.from,
            b.to,
            b.metres,
            share * 100.0
        );
    }
    out.push_str("</table>\n");
}

/// The fault kinds per probe the tests planned, the car confirmed and that began acting.
fn coverage_faults(out: &mut String, faults: &[FaultCoverage]) {
    if faults.is_empty() {
        out.push_str("<p>No faults planned.</p>\n");
        return;
    }
    out.push_str(
        "<table><tr><th>probe</th><th>fault type</th><th>planned</th><th>confirmed by the car</th>\
         <th>began acting in its test</th></tr>\n",
    );
    for f in faults {
        let _ = writeln!(
            out,
            "<tr><td><code>{}</code></td><td>{}</td><td class=\"num\">{}</td>\
             <td class=\"num\">{}</td><td class=\"num\">{}</td></tr>",
            escape(&f.probe),
            escape(&f.kind.to_lowercase().replace('_', " ")),
            f.planned,
            f.confirmed,
            f.acted
        );
    }
    out.push_str("</table>\n");
}

/// A replay's page: the runs on one map, the comparison, a plot per run.
pub fn replay_page(
    data: &ReplayData,
    scenario: Option<&Scenario>,
    mut page_notes: Vec<String>,
) -> Result<String, ReportError> {
    let c = &data.comparison;
    let mut out = String::new();
    let title = format!(
        "drivecheck replay of {} on {}",
        c.replay_of.case, c.scenario.name
    );
    head(&mut out, &title);
    let _ = writeln!(
        out,
        "<h1>Replay of <code>{}</code></h1>\n<p class=\"sub\">Replay directory <code>{}</code></p>",
        escape(&c.replay_of.case),
        escape(&data.dir.display().to_string())
    );
    page_notes.extend(data.notes.iter().cloned());
    for (_, run) in &data.runs {
        if let Some(run) = run {
            page_notes.extend(run.notes.iter().cloned());
        }
    }
    notes(&mut out, &page_notes);
    out.push_str("<section id=\"summary\">\n<h2>Summary</h2>\n<table class=\"facts\">\n");
    fact(
        &mut out,
        "scenario",
        &format!(
            "{} (hash {})",
            escape(&c.scenario.name),
            c.scenario.hash.as_deref().map_or("–", short)
        ),
    );
    let of = &c.replay_of;
    fact(
        &mut out,
        "case",
        &format!(
            "<code>{}</code>{}{}, recorded verdict {}",
            escape(&of.case),
            of.campaign_seed
                .map_or_else(String::new, |s| format!(", campaign seed {s}")),
            of.test_index
                .map_or_else(String::new, |i| format!(", test {i}")),
            of.verdict.map_or("–", Verdict::as_str)
        ),
    );
    if of.no_faults {
        fact(&mut out, "faults", "left out (--no-faults)");
    }
    let count = |v| c.runs.iter().filter(|r| r.verdict == Some(v)).count();
    fact(
        &mut out,
        "runs",
        &format!(
            "<span id=\"count-tests\">{}</span>: {} passed, {} failed, {} aborted",
            c.runs.len(),
            count(Verdict::Passed),
            count(Verdict::Failed),
            count(Verdict::Aborted)
        ),
    );
    fact(
        &mut out,
        "same verdict every run",
        yes_no(Some(c.same_verdict)),
    );
    fact(&mut out, "same as the case", yes_no(c.same_as_original));
    if c.failure_disappeared.is_some() {
        fact(
            &mut out,
            "failure disappeared without faults",
            yes_no(c.failure_disappeared),
        );
    }
    fact(
        &mut out,
        "largest difference from the mean",
        &metres(c.max_abs_diff_m),
    );
    out.push_str("</table>\n</section>\n");
    out.push_str(
        "<section id=\"runs\">\n<h2>Runs</h2>\n<table><tr><th>run</th><th>seed</th>\
         <th>verdict</th><th>worst deviation</th><th>reason</th></tr>\n",
    );
    for (run, data) in &data.runs {
        let worst = data
            .as_ref()
            .and_then(|d| d.tests.first())
            .and_then(|t| TestSummary::of(0, String::new(), &t.case).worst_deviation_m);
        let _ = writeln!(
            out,
            "<tr><td><a href=\"#{d}\">{d}</a></td><td class=\"num\">{}</td><td>{}</td>\
             <td class=\"num\">{}</td><td>{}</td></tr>",
            run.seed,
            badge(run.verdict),
            metres(worst),
            escape(run.reason.as_deref().unwrap_or("")),
            d = escape(&run.dir)
        );
    }
    out.push_str("</table>\n");
    comparison_table(&mut out, c);
    out.push_str("</section>\n");
    // The runs overlaid on one map.
    let threshold = data
        .runs
        .iter()
        .filter_map(|(_, d)| d.as_ref()?.tests.first())
        .map(|t| threshold_of(&t.case, 1.0))
        .next()
        .unwrap_or(1.0);
    let decimated: Vec<(usize, &TestData, Vec<Sample>)> = data
        .runs
        .iter()
        .enumerate()
        .filter_map(|(k, (_, d))| {
            let test = d.as_ref()?.tests.first()?;
            let samples = test
                .track
                .as_ref()
                .map(|t| decimate(&t.samples, MAX_TRACK_POINTS))
                .unwrap_or_default();
            Some((k, test, samples))
        })
        .collect();
    if let Some((_, first, _)) = decimated.first() {
        let layers = MapLayers {
            heat: None,
            segments: segments(&first.case),
            driven: decimated
                .iter()
                .map(|(_, t, _)| driven(&t.case))
                .max()
                .unwrap_or(0),
            tracks: decimated
                .iter()
                .map(|(k, _, samples)| TrackLayer {
                    samples,
                    colouring: Colouring::Run {
                        colour: RUN_COLOURS[k % RUN_COLOURS.len()],
                        threshold,
                    },
                    rtk: true,
                })
                .collect(),
            faults: scenario.map_or_else(Vec::new, |s| {
                decimated
                    .iter()
                    .flat_map(|(k, test, samples)| {
                        // The runs' places nearly coincide: the first run's are named.
                        let mut marks = fault_marks(s, &test.case, samples);
                        if *k > 0 {
                            marks.iter_mut().for_each(|m| m.label.clear());
                        }
                        marks
                    })
                    .collect()
            }),
        };
        out.push_str("<section id=\"map\">\n<h2>The runs on the map</h2>\n");
        figure(
            &mut out,
            map_svg(scenario, &layers)?,
            "No map: neither the scenario nor a track is known.",
        );
        map_legend(&mut out, false);
        let mut entries: Vec<String> = decimated
            .iter()
            .map(|(k, _, _)| {
                let colour = css(RUN_COLOURS[k % RUN_COLOURS.len()]);
                swatch(
                    &format!("background:{colour}"),
                    &format!("UWB track of run {}", k + 1),
                )
            })
            .collect();
        entries.push(format!(
            "<span class=\"entry\"><span class=\"dot\" style=\"background:{}\"></span>UWB above \
             the threshold</span>",
            css(RED_ABOVE)
        ));
        legend(
            &mut out,
            &entries,
            Some("The faults are numbered at run 1's places."),
        );
        fault_key(&mut out, &first.case);
        out.push_str("</section>\n");
    }
    for (k, test, _) in &decimated {
        let dir = &data.runs[*k].0.dir;
        test_section(
            &mut out,
            &escape(dir),
            &format!("Run {} ({dir}/{})", k + 1, test.file),
            test,
            scenario,
            threshold,
            false,
        )?;
    }
    foot(&mut out, &data.dir);
    Ok(out)
}

fn yes_no(value: Option<bool>) -> &'static str {
    match value {
        Some(true) => "yes",
        Some(false) => "no",
        None => "–",
    }
}

fn comparison_table(out: &mut String, c: &campaign::replay::Comparison) {
    out.push_str("<h3>Per segment: each run's largest deviation</h3>\n<table><tr><th>segment</th><th>case</th>");
    for run in &c.runs {
        let _ = write!(out, "<th>{}</th>", escape(&run.dir));
    }
    out.push_str("<th>mean</th>");
    for run in &c.runs {
        let _ = write!(out, "<th>{} − mean</th>", escape(&run.dir));
    }
    out.push_str("</tr>\n");
    for s in &c.segments {
        let _ = write!(
            out,
            "<tr><td class=\"num\">s{}</td><td class=\"num\">{}</td>",
            s.segment_index,
            metres(s.original_max_m)
        );
        for m in &s.max_m {
            let _ = write!(out, "<td class=\"num\">{}</td>", metres(*m));
        }
        let _ = write!(out, "<td class=\"num\">{}</td>", metres(s.mean_m));
        for d in &s.diff_from_mean_m {
            let text = d.map_or_else(|| "–".to_owned(), |d| format!("{d:+.2} m"));
            let _ = write!(out, "<td class=\"num\">{text}</td>");
        }
        out.push_str("</tr>\n");
    }
    out.push_str("</table>\n");
}

fn runs_cell(runs: &[RunResult]) -> String {
    runs.iter()
        .map(|r| {
            format!(
                "seed {}: {}{}{}",
                r.seed,
                r.verdict.map_or("–", Verdict::as_str),
                r.first_failing_segment
                    .map_or_else(String::new, |s| format!(" at s{s}")),
                r.max_deviation_m
                    .map_or_else(String::new, |m| format!(" ({m:.2} m)"))
            )
        })
        .collect::<Vec<_>>()
        .join("<br>")
}

/// A shrink's edit in words: the edits of a fault name the command and the value (the others'
/// descriptions are words already).
fn edit_words(step: &Step) -> String {
    match step.edit {
        Edit::DropFault { command_index } => format!("drop the fault of command {command_index}"),
        Edit::FaultValue {
            command_index,
            field,
            from,
            to,
        } => {
            let what = match field {
                FaultField::Param => "parameter",
                FaultField::Start => "start (probe calls after it is added)",
                FaultField::Duration => "duration (probe calls)",
            };
            let short = |v: f64| {
                let text = format!("{v:.3}");
                text.trim_end_matches('0').trim_end_matches('.').to_owned()
            };
            format!(
                "the fault of command {command_index}: {what} {} → {}",
                short(from),
                short(to)
            )
        }
        _ => step.description.clone(),
    }
}

/// How a shrink's step ended, in words: a barely failing run's margin in centimetres above
/// the `threshold` when it is known.
fn outcome_words(step: &Step, min_deviation_m: f64, threshold: Option<f64>) -> String {
    match step.outcome {
        Outcome::Kept => "kept: every run failed there".to_owned(),
        Outcome::Passed => "dropped: a run passed".to_owned(),
        Outcome::FailedElsewhere => "dropped: a run failed first at another segment".to_owned(),
        Outcome::FailedBarely => match threshold.filter(|t| *t > 0.0 && min_deviation_m > *t) {
            Some(t) => format!(
                "dropped: a run failed there by less than {:.0} cm above the threshold",
                (min_deviation_m - t) * 100.0
            ),
            None => format!(
                "dropped: a run failed there with a largest deviation under {min_deviation_m:.2} m"
            ),
        },
        Outcome::Aborted => "dropped: a run was aborted or ended without a verdict".to_owned(),
        Outcome::NotDrivable => match &step.not_drivable {
            Some(why) => format!("not drivable: {why}"),
            None => "not drivable".to_owned(),
        },
    }
}

/// A shrink's page: before and after, the steps; no maps (a shrink's runs are not recorded).
pub fn shrink_page(data: &ShrinkData, page_notes: Vec<String>) -> String {
    let r = &data.report;
    let mut out = String::new();
    head(&mut out, &format!("drivecheck shrink of {}", r.case));
    let _ = writeln!(
        out,
        "<h1>Shrink of <code>{}</code></h1>\n<p class=\"sub\">Shrink directory <code>{}</code></p>",
        escape(&r.case),
        escape(&data.dir.display().to_string())
    );
    let mut all = page_notes;
    all.extend(data.notes.iter().cloned());
    notes(&mut out, &all);
    let _ = writeln!(
        out,
        "<p>No maps or plots on this page: a shrink drives its candidates on the simulated car \
         without recording them (there is no MCAP). To see the minimal case's tracks, replay it: \
         <code>drivecheck replay {} --report</code>.</p>",
        escape(
            &data
                .dir
                .join(campaign::shrink::MINIMAL_FILE)
                .display()
                .to_string()
        )
    );
    out.push_str("<section id=\"summary\">\n<h2>Summary</h2>\n<table class=\"facts\">\n");
    fact(
        &mut out,
        "scenario",
        &format!(
            "{} (hash {})",
            escape(&r.scenario.name),
            r.scenario.hash.as_deref().map_or("–", short)
        ),
    );
    fact(&mut out, "drivecheck", &escape(r.header.tool()));
    fact(
        &mut out,
        "seed, runs per candidate",
        &format!("{}, {}", r.seed, r.runs_per_candidate),
    );
    fact(
        &mut out,
        "a candidate is kept when",
        &format!(
            "every run fails at its segment with a largest deviation of at least {:.2} m",
            r.min_deviation_m
        ),
    );
    fact(&mut out, "ended", r.ended.words());
    fact(
        &mut out,
        "simulator runs, wall time",
        &format!("{}, {}", r.simulator_runs, seconds(r.wall_s)),
    );
    if let Some(conf) = &r.confirmation {
        fact(
            &mut out,
            "confirmation",
            &format!(
                "{} of {} other seeds failed the same way{}; {}{}",
                conf.failed,
                conf.runs.len(),
                conf.case_failed
                    .map_or_else(String::new, |n| format!(" (the case itself: {n})")),
                if conf.confirmed {
                    "confirmed"
                } else {
                    "not confirmed"
                },
                if conf.stepped_back > 0 {
                    format!(", {} step(s) undone", conf.stepped_back)
                } else {
                    String::new()
                }
            ),
        );
    }
    fact(
        &mut out,
        "replay on the car",
        &format!("<code>{}</code>", escape(&r.replay_on_car)),
    );
    out.push_str("</table>\n</section>\n");
    out.push_str(
        "<section id=\"before-after\">\n<h2>Before and after</h2>\n<table><tr><th></th>\
         <th>before</th><th>after</th></tr>\n",
    );
    let (b, a) = (&r.before, &r.after);
    let rows = [
        ("commands", b.size.commands, a.size.commands),
        ("segments", b.size.segments, a.size.segments),
        ("faults", b.size.faults, a.size.faults),
        ("route points", b.size.points, a.size.points),
    ];
    for (name, before, after) in rows {
        let _ = writeln!(
            out,
            "<tr><th>{name}</th><td class=\"num\">{before}</td><td class=\"num\">{after}</td></tr>"
        );
    }
    let _ = writeln!(
        out,
        "<tr><th>failing segment</th><td>s{}</td><td>s{}</td></tr>\n\
         <tr><th>{}</th><td class=\"num\" id=\"median-before\">{}</td>\
         <td class=\"num\" id=\"median-after\">{}</td></tr>\n\
         <tr><th>runs</th><td class=\"runs\">{}</td><td class=\"runs\">{}</td></tr>",
        escape(&b.target.to_string()),
        escape(&a.target.to_string()),
        escape(campaign::shrink::MEDIAN_ROW),
        metres(b.median_deviation_m()),
        metres(a.median_deviation_m()),
        runs_cell(&b.runs),
        runs_cell(&a.runs)
    );
    if let Some(runs) = &r.without_faults {
        let _ = writeln!(
            out,
            "<tr><th>the minimal case without its faults</th><td></td><td class=\"runs\">{}</td></tr>",
            runs_cell(runs)
        );
    }
    out.push_str("</table>\n</section>\n");
    if let Some(minimal) = &data.minimal {
        out.push_str("<section id=\"minimal\">\n<h2>The minimal case's segments</h2>\n");
        let _ = writeln!(
            out,
            "<p class=\"sub\"><code>minimal.json</code>: {} commands, verdict {}{}. Its \
             figures are those of one run, {}; the median above is over all {} runs.</p>",
            minimal.commands.len(),
            minimal.verdict.map_or("–", Verdict::as_str),
            minimal
                .reason
                .as_deref()
                .map_or_else(String::new, |r| format!(" ({})", escape(r))),
            a.runs
                .first()
                .map_or_else(|| "the first".to_owned(), |r| format!("seed {}", r.seed)),
            a.runs.len()
        );
        segments_table(&mut out, minimal);
        faults_table(&mut out, minimal);
        out.push_str("</section>\n");
    }
    out.push_str(
        "<section id=\"steps\">\n<h2>Steps</h2>\n<table><tr><th>#</th><th>edit</th>\
         <th>outcome</th><th>commands</th><th>must fail at</th><th>runs</th></tr>\n",
    );
    let threshold = data.minimal.as_ref().map(|m| threshold_of(m, 0.0));
    for (i, step) in r.steps.iter().enumerate() {
        let outcome = outcome_words(step, r.min_deviation_m, threshold);
        let (class, outcome) = if step.outcome == Outcome::Kept {
            (
                " class=\"kept\"",
                format!("<strong>{}</strong>", escape(&outcome)),
            )
        } else {
            ("", escape(&outcome))
        };
        let _ = writeln!(
            out,
            "<tr{class}><td class=\"num\">{}</td><td>{}</td><td>{outcome}</td>\
             <td class=\"num\">{}</td><td>s{}</td><td class=\"runs\">{}</td></tr>",
            i + 1,
            escape(&edit_words(step)),
            step.commands,
            escape(&step.target.to_string()),
            runs_cell(&step.runs)
        );
    }
    out.push_str("</table>\n</section>\n");
    foot(&mut out, &data.dir);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_escaped() {
        assert_eq!(
            escape("<a href=\"x\">&'"),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
    }

    #[test]
    fn wall_time_needs_both_ends() {
        assert_eq!(
            wall_seconds("2026-11-22T10:55:21Z", Some("2026-11-22T10:56:02Z")),
            Some(41.0)
        );
        assert_eq!(wall_seconds("2026-11-22T10:55:21Z", None), None);
        assert_eq!(
            wall_seconds("yesterday", Some("2026-11-22T10:56:02Z")),
            None
        );
    }
}
