//! `compare.html`: the page of `drivecheck compare BASE NEW --report`, in the report's style: the
//! verdict, the statistics, the tests' table, a map of the paired segments coloured by how their
//! largest deviation changed (worse red, better blue, within the noise grey), a histogram of the
//! changes and the breakdowns.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use plotters::prelude::*;
use trajgen::Point;

use super::ReportError;
use super::data::{Sample, scenario_for};
use super::draw::{Colouring, MapLayers, TrackLayer, css, map_svg};
use super::html::{escape, fact, figure, foot, head, legend, swatch};
use campaign::compare::{BreakdownRow, Paired, PairedSegment, Report, Significance, p_words};
use campaign::files::ScenarioRef;
use serde::Serialize;

/// Where the noise came from.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "from", rename_all = "snake_case")]
pub enum NoiseSource {
    /// `DEFAULT_NOISE_M`.
    Default,
    /// `--noise M`.
    Given,
    /// `--noise-from DIR`: the 95th percentile of |change| between BASE and DIR.
    Rerun {
        /// The rerun's directory.
        dir: PathBuf,
        /// Its segments paired with BASE's and measured in both.
        segments: usize,
    },
}

/// Two runs compared: the pairs (for the page) and the comparison.
#[derive(Debug, Clone)]
pub struct Compared {
    /// BASE's run directory.
    pub base: PathBuf,
    /// The scenario BASE ran in (`campaign.json`), for the page's map.
    pub scenario: ScenarioRef,
    /// NEW's.
    pub new: PathBuf,
    /// Where the noise came from.
    pub noise_source: NoiseSource,
    /// The tests and segments of both, paired.
    pub paired: Paired,
    /// The comparison.
    pub report: Report,
}

/// A signed length in metres, or `–`.
pub fn signed(m: Option<f64>) -> String {
    m.map_or_else(|| "–".to_owned(), |m| format!("{m:+.3}"))
}

/// Where the noise came from, in words.
pub fn noise_words(compared: &Compared) -> String {
    let noise = compared.report.noise_m;
    match &compared.noise_source {
        NoiseSource::Default => format!("{noise:.3} m (the default: the replay rule's 0.2 m)"),
        NoiseSource::Given => format!("{noise:.3} m (--noise)"),
        NoiseSource::Rerun { dir, segments } => format!(
            "{noise:.3} m (95th percentile of |change| over {segments} segments of BASE and its \
             rerun {})",
            dir.display()
        ),
    }
}

/// Worse than the noise.
const WORSE: RGBColor = RGBColor(0xd7, 0x19, 0x1c);
/// Better than the noise.
const BETTER: RGBColor = RGBColor(0x2c, 0x7b, 0xb6);
/// Within the noise.
const SAME: RGBColor = RGBColor(0xb4, 0xb4, 0xb4);
/// The most segments drawn on the map: the largest changes first, so a page of 100,000
/// segments stays a few megabytes.
const MAX_MAP_SEGMENTS: usize = 4000;
/// The most rows of a breakdown table on the page.
const MAX_ROWS: usize = 40;
const HIST_WIDTH: u32 = 860;
const HIST_HEIGHT: u32 = 320;
const HIST_BINS: usize = 41;

fn draw_error(e: impl std::fmt::Display) -> ReportError {
    ReportError::Draw(e.to_string())
}

fn sans(px: f64) -> (&'static str, f64) {
    ("sans-serif", px * 1.24)
}

fn colour_of(change: f64, noise: f64) -> RGBColor {
    if change > noise {
        WORSE
    } else if change < -noise {
        BETTER
    } else {
        SAME
    }
}

/// Writes the page of `compared` to `out` (whole or not at all).
pub fn write(compared: &Compared, out: &Path) -> Result<(), ReportError> {
    let page = page(compared)?;
    runner::atomic::write(out, &page).map_err(|error| ReportError::Write {
        path: out.to_owned(),
        error,
    })
}

fn page(compared: &Compared) -> Result<String, ReportError> {
    let r = &compared.report;
    let mut out = String::new();
    head(&mut out, "drivecheck compare");
    let _ = writeln!(
        out,
        "<h1>NEW against BASE</h1>\n<p class=\"sub\">BASE <code>{}</code> · NEW <code>{}</code> · \
         scenario {}</p>",
        escape(&compared.base.display().to_string()),
        escape(&compared.new.display().to_string()),
        escape(&compared.scenario.name)
    );
    let (class, word) = match r.significance {
        Significance::Worse => ("failed", "worse"),
        Significance::Better => ("passed", "better"),
        Significance::Mixed => ("aborted", "mixed"),
        Significance::NoDifference => ("notrun", "no difference"),
    };
    let _ = writeln!(
        out,
        "<p><span class=\"verdict {class}\">{word}</span> {}</p>",
        escape(&r.verdict)
    );

    out.push_str("<h2>Statistics</h2>\n<div class=\"columns\">\n<table class=\"facts\">\n");
    let t = &r.tests;
    let s = &r.segments;
    fact(&mut out, "tests in both", &t.paired.to_string());
    fact(
        &mut out,
        "segments",
        &format!(
            "{} driven in both ({} measured); {} only in BASE, {} only in NEW",
            s.paired, s.measured, s.only_base, s.only_new
        ),
    );
    fact(&mut out, "noise", &escape(&noise_words(compared)));
    fact(
        &mut out,
        "worse than the noise",
        &format!("{} ({})", segments(s.worse), share(s.worse_share)),
    );
    fact(
        &mut out,
        "better than the noise",
        &format!("{} ({})", segments(s.better), share(s.better_share)),
    );
    fact(
        &mut out,
        "segment verdicts",
        &format!("{} regressed, {} fixed", s.regressed, s.fixed),
    );
    fact(
        &mut out,
        "McNemar (tests)",
        &format!(
            "{} regressed, {} fixed: two-sided p = {} (significant below α/2 = {})",
            r.mcnemar.regressed,
            r.mcnemar.fixed,
            p_words(r.mcnemar.p),
            r.alpha / 2.0
        ),
    );
    match &r.median_change {
        Some(m) => {
            fact(
                &mut out,
                "median change",
                &format!(
                    "{} m (95 % CI {} to {} m)",
                    signed(Some(m.median_m)),
                    signed(Some(m.ci95_m[0])),
                    signed(Some(m.ci95_m[1]))
                ),
            );
            fact(
                &mut out,
                "sign-flip test",
                &format!(
                    "p = {} (significant below α/2 = {}; {} sign assignments of {} tests; the \
                     interval from {} bootstrap resamples; seed {})",
                    p_words(m.p),
                    r.alpha / 2.0,
                    m.flips,
                    m.tests,
                    m.resamples,
                    m.seed
                ),
            );
        }
        None => fact(
            &mut out,
            "median change",
            "no segment measured in both runs",
        ),
    }
    out.push_str(
        "</table>\n<table>\n<tr><th>tests</th><th>NEW passed</th><th>NEW failed</th></tr>\n",
    );
    let _ = writeln!(
        out,
        "<tr><th>BASE passed</th><td class=\"num\">{}</td><td class=\"num\">{}</td></tr>\n\
         <tr><th>BASE failed</th><td class=\"num\">{}</td><td class=\"num\">{}</td></tr>\n\
         </table>\n</div>",
        t.both_passed, t.regressed, t.fixed, t.both_failed
    );
    out.push_str(
        "<p class=\"sub\">Failed includes aborted. NEW is significantly worse when McNemar's p \
         is below α/2 with more regressed than fixed tests, or the sign-flip test's p is below \
         α/2 with a median change above 0 (docs/compare.md).</p>\n",
    );

    let noise = r.noise_m;
    let _ = writeln!(out, "<h2>Where the segments changed</h2>");
    let (map, drawn) = change_map(compared)?;
    figure(
        &mut out,
        map,
        "no map: the scenario is not bundled and no segment has a route",
    );
    let measured = compared
        .paired
        .segments()
        .filter(|s| s.change_m().is_some())
        .count();
    legend(
        &mut out,
        &[
            swatch(
                &format!("background:{}", css(WORSE)),
                &format!("worse by more than {noise:.2} m"),
            ),
            swatch(
                &format!("background:{}", css(BETTER)),
                &format!("better by more than {noise:.2} m"),
            ),
            swatch(&format!("background:{}", css(SAME)), "within the noise"),
        ],
        Some(&format!(
            "Each segment driven in both runs, coloured by NEW − BASE of its largest deviation; \
             {drawn} of {measured} drawn{}.",
            if drawn < measured {
                " (the largest changes)"
            } else {
                ""
            }
        )),
    );
    let _ = writeln!(out, "<h2>Changes of a segment's largest deviation</h2>");
    figure(
        &mut out,
        histogram(compared)?,
        "no segment measured in both runs",
    );
    legend(
        &mut out,
        &[],
        Some(
            "Segments per bin of NEW − BASE (metres); the dashed lines are ± the noise, the \
             solid line the median change.",
        ),
    );

    out.push_str("<h2>Where the difference lives</h2>\n");
    for (title, rows) in [
        ("By active fault (probe and kind)", &r.breakdowns.by_fault),
        ("By commanded speed", &r.breakdowns.by_speed),
        ("By region (cells of the area)", &r.breakdowns.by_region),
    ] {
        breakdown_table(&mut out, title, rows);
    }
    foot(&mut out, &compared.new);
    Ok(out)
}

/// `n segments`, or `1 segment`.
fn segments(n: usize) -> String {
    if n == 1 {
        "1 segment".to_owned()
    } else {
        format!("{n} segments")
    }
}

fn share(value: f64) -> String {
    format!("{:.1} %", value * 100.0)
}

fn breakdown_table(out: &mut String, title: &str, rows: &[BreakdownRow]) {
    let _ = writeln!(out, "<h3>{}</h3>", escape(title));
    out.push_str(
        "<table>\n<tr><th></th><th>segments</th><th>median change</th><th>worse</th>\
         <th>better</th><th>regressed</th><th>fixed</th></tr>\n",
    );
    for r in rows.iter().take(MAX_ROWS) {
        let above = if r.regression_score() > 0 {
            " class=\"num above\""
        } else {
            " class=\"num\""
        };
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td class=\"num\">{}</td><td{above}>{}</td><td class=\"num\">{}</td>\
             <td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td></tr>",
            escape(&r.key),
            r.segments,
            r.median_change_m
                .map_or_else(|| "–".to_owned(), |m| format!("{m:+.3} m")),
            r.worse,
            r.better,
            r.regressed,
            r.fixed
        );
    }
    out.push_str("</table>\n");
    if rows.len() > MAX_ROWS {
        let _ = writeln!(
            out,
            "<p class=\"sub\">The first {MAX_ROWS} of {} rows (every row is in <code>--json</code>).</p>",
            rows.len()
        );
    }
}

/// The map of the paired segments, each a line in its change's colour, and how many were drawn.
fn change_map(compared: &Compared) -> Result<(Option<String>, usize), ReportError> {
    let noise = compared.report.noise_m;
    let mut measured: Vec<(&PairedSegment, f64)> = compared
        .paired
        .segments()
        .filter(|s| s.route.len() >= 2)
        .filter_map(|s| Some((s, s.change_m()?)))
        .collect();
    // The largest changes are kept; within the noise grey is drawn first, red and blue on top.
    measured.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    measured.truncate(MAX_MAP_SEGMENTS);
    measured.sort_by(|a, b| a.1.abs().total_cmp(&b.1.abs()));
    let tracks: Vec<(RGBColor, Vec<Sample>)> = measured
        .iter()
        .map(|(s, change)| {
            let samples = s
                .route
                .iter()
                .map(|&[x, y]| Sample {
                    t_s: 0.0,
                    rtk: Point::new(x, y),
                    uwb: Point::new(x, y),
                    deviation_m: None,
                })
                .collect();
            (colour_of(*change, noise), samples)
        })
        .collect();
    let layers = MapLayers {
        tracks: tracks
            .iter()
            .map(|(colour, samples)| TrackLayer {
                samples,
                colouring: Colouring::Run {
                    colour: *colour,
                    threshold: f64::INFINITY,
                },
                rtk: false,
            })
            .collect(),
        ..MapLayers::default()
    };
    let (scenario, _) = scenario_for(
        &compared.scenario.name,
        compared.scenario.hash.as_deref(),
        None,
        None,
    );
    Ok((map_svg(scenario.as_ref(), &layers)?, tracks.len()))
}

/// The histogram of the changes, `None` without one.
fn histogram(compared: &Compared) -> Result<Option<String>, ReportError> {
    let noise = compared.report.noise_m;
    let mut changes: Vec<f64> = compared
        .paired
        .segments()
        .filter_map(PairedSegment::change_m)
        .collect();
    if changes.is_empty() {
        return Ok(None);
    }
    changes.sort_by(f64::total_cmp);
    // Symmetric about 0, wide enough for 99 % of the changes and twice the noise.
    let p = |q: f64| {
        campaign::compare::nearest_rank(&changes, q)
            .unwrap_or(0.0)
            .abs()
    };
    let half = p(0.005).max(p(0.995)).max(2.0 * noise).max(0.05);
    let width = 2.0 * half / HIST_BINS as f64;
    let mut counts = vec![0usize; HIST_BINS];
    for &c in &changes {
        let k = ((c + half) / width)
            .floor()
            .clamp(0.0, (HIST_BINS - 1) as f64) as usize;
        counts[k] += 1;
    }
    let most = counts.iter().copied().max().unwrap_or(1).max(1) as f64;
    let median = compared.report.median_change.map(|m| m.median_m);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (HIST_WIDTH, HIST_HEIGHT)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(76)
            .build_cartesian_2d(-half..half, 0.0..most * 1.1)
            .map_err(draw_error)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .light_line_style(RGBColor(0xf0, 0xf0, 0xf0))
            .bold_line_style(RGBColor(0xdd, 0xdd, 0xdd))
            .x_desc("NEW − BASE of a segment's largest deviation")
            .y_desc("segments")
            .x_label_formatter(&|v| format!("{v:+.2} m"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style(sans(14.0))
            .axis_desc_style(sans(14.0))
            .draw()
            .map_err(draw_error)?;
        chart
            .draw_series(
                counts
                    .iter()
                    .enumerate()
                    .filter(|(_, n)| **n > 0)
                    .map(|(k, &n)| {
                        let from = -half + k as f64 * width;
                        let centre = from + width / 2.0;
                        Rectangle::new(
                            [(from, 0.0), (from + width, n as f64)],
                            colour_of(centre, noise).filled(),
                        )
                    }),
            )
            .map_err(draw_error)?;
        for x in [-noise, noise] {
            chart
                .draw_series(DashedLineSeries::new(
                    [(x, 0.0), (x, most * 1.1)],
                    5,
                    4,
                    RGBColor(0x55, 0x55, 0x55).stroke_width(1),
                ))
                .map_err(draw_error)?;
        }
        if let Some(m) = median.filter(|m| m.abs() <= half) {
            chart
                .draw_series([PathElement::new(
                    [(m, 0.0), (m, most * 1.1)],
                    BLACK.stroke_width(2),
                )])
                .map_err(draw_error)?;
        }
        root.present().map_err(draw_error)?;
    }
    Ok(Some(svg))
}
