//! What a campaign covered — what QuickCheck's `classify` and `cover` report and proptest does
//! not: the share of the drivable area its tests drove (with the grid for a heat map), the
//! headings and speeds driven, the fault kinds on each probe injected, confirmed and acting, and
//! the segments per test. As text (what `runs show --coverage` prints and the report shows), the
//! statistics' `Display`.
//!
//! Everything comes from the case files: the segments a test drove (those the oracle judged) as
//! planned, from the end of the start route, and its fault commands with their places and
//! windows. The safety monitor keeps the car within its cross-track limit of the planned route,
//! so the planned route is where it drove to within that limit.

use trajgen::validation::CoverageGrid;
use trajgen::{Area, Point};

use crate::files::{Case, CommandRecord, CoverageRecord, FaultCoverageRecord};

/// Side of a coverage cell, metres.
pub const CELL_M: f64 = 0.5;
/// Width of a heading bin, degrees.
pub const HEADING_BIN_DEG: f64 = 30.0;
/// Width of a speed bin, km/h.
pub const SPEED_BIN_KMH: f64 = 2.0;

/// A campaign's coverage statistics (what `campaign.json` keeps, as a
/// [`CoverageRecord`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CoverageStats {
    /// Tests counted.
    pub tests: usize,
    /// Side of a cell, metres.
    pub cell_m: f64,
    /// Drivable cells of the area.
    pub drivable_cells: usize,
    /// Drivable cells a driven segment passed through.
    pub driven_cells: usize,
    /// `driven_cells / drivable_cells`.
    pub area_share: f64,
    /// Metres driven per heading bin: bin *k* holds headings from `k × 30°` (counter-clockwise
    /// from east) up to the next.
    pub heading_m: Vec<f64>,
    /// Metres driven per speed bin: bin *k* holds speeds from `k × 2 km/h` up to the next.
    pub speed_m: Vec<f64>,
    /// Per probe and fault type: how many fault commands the tests held, sent and confirmed by
    /// the car, and estimated to begin acting before their test ended.
    pub faults: Vec<FaultCoverage>,
    /// `segments_per_test[n]`: how many tests drove `n` segments.
    pub segments_per_test: Vec<usize>,
}

/// One probe and fault type of [`CoverageStats::faults`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FaultCoverage {
    /// The probe (`uwb_range_50`, `uwb_travel_dist`, `uwb_yaw`).
    pub probe: String,
    /// The fault type (`OFFSET`, `AMPLIFICATION`, `SET_TO`, `BITFLIP`).
    pub kind: String,
    /// Fault commands of that probe and type in the tests' plans.
    pub planned: usize,
    /// Sent and confirmed by the car.
    pub confirmed: usize,
    /// Estimated to begin acting before their test's drive ended.
    pub acted: usize,
}

impl From<CoverageStats> for CoverageRecord {
    fn from(c: CoverageStats) -> Self {
        Self {
            tests: c.tests,
            cell_m: c.cell_m,
            drivable_cells: c.drivable_cells,
            driven_cells: c.driven_cells,
            area_share: c.area_share,
            heading_m: c.heading_m,
            speed_m: c.speed_m,
            faults: c
                .faults
                .into_iter()
                .map(|f| FaultCoverageRecord {
                    probe: f.probe,
                    kind: f.kind,
                    planned: f.planned,
                    confirmed: f.confirmed,
                    acted: f.acted,
                })
                .collect(),
            segments_per_test: c.segments_per_test,
        }
    }
}

impl From<CoverageRecord> for CoverageStats {
    fn from(r: CoverageRecord) -> Self {
        Self {
            tests: r.tests,
            cell_m: r.cell_m,
            drivable_cells: r.drivable_cells,
            driven_cells: r.driven_cells,
            area_share: r.area_share,
            heading_m: r.heading_m,
            speed_m: r.speed_m,
            faults: r
                .faults
                .into_iter()
                .map(|f| FaultCoverage {
                    probe: f.probe,
                    kind: f.kind,
                    planned: f.planned,
                    confirmed: f.confirmed,
                    acted: f.acted,
                })
                .collect(),
            segments_per_test: r.segments_per_test,
        }
    }
}

/// The coverage statistics with the grid behind them.
#[derive(Debug, Clone, PartialEq)]
pub struct Coverage {
    /// The statistics.
    pub stats: CoverageStats,
    /// Visits per cell: how many driven segments passed through it.
    pub grid: CoverageGrid,
}

/// The coverage of `cases`, tests driven in `scenario` (from the end of its start route).
pub fn of_scenario(scenario: &scenarios::Scenario, cases: &[Case]) -> Coverage {
    let start_end = scenario
        .start_route
        .points
        .last()
        .map_or(Point::new(0.0, 0.0), |w| w.position);
    coverage(&scenario.area, start_end, cases)
}

/// The coverage of `cases`, tests driven in `area` from a start route ending at `start_end`.
pub fn coverage(area: &Area, start_end: Point, cases: &[Case]) -> Coverage {
    let mut builder = CoverageBuilder::new(area, start_end);
    for case in cases {
        builder.add(case);
    }
    builder.finish()
}

/// The coverage of tests added one at a time, so that a large campaign's cases need not be in
/// memory together (`drivecheck report` reads its case files one by one).
#[derive(Debug, Clone)]
pub struct CoverageBuilder {
    grid: CoverageGrid,
    start_end: Point,
    heading_m: Vec<f64>,
    speed_m: Vec<f64>,
    faults: Vec<FaultCoverage>,
    segments_per_test: Vec<usize>,
    tests: usize,
}

impl CoverageBuilder {
    /// No test yet, in `area` from a start route ending at `start_end`.
    pub fn new(area: &Area, start_end: Point) -> Self {
        let bins = |width: f64, full: f64| (full / width).ceil() as usize;
        Self {
            grid: CoverageGrid::new(area, CELL_M),
            start_end,
            heading_m: vec![0.0; bins(HEADING_BIN_DEG, 360.0)],
            speed_m: vec![0.0; bins(SPEED_BIN_KMH, 30.0)],
            faults: Vec::new(),
            segments_per_test: Vec::new(),
            tests: 0,
        }
    }

    /// No test yet, in `scenario` (from the end of its start route).
    pub fn of_scenario(scenario: &scenarios::Scenario) -> Self {
        let start_end = scenario
            .start_route
            .points
            .last()
            .map_or(Point::new(0.0, 0.0), |w| w.position);
        Self::new(&scenario.area, start_end)
    }

    /// Adds a test.
    pub fn add(&mut self, case: &Case) {
        let Self {
            grid,
            heading_m,
            speed_m,
            faults,
            segments_per_test,
            ..
        } = self;
        self.tests += 1;
        let driven = case.segments.len();
        let mut from = self.start_end;
        let mut segment = 0usize;
        for command in &case.commands {
            match command {
                CommandRecord::RunSegments { points, .. } => {
                    if segment < driven {
                        for p in points {
                            let to = Point::new(p.x, p.y);
                            let length = from.dist(to);
                            if length > 0.0 && to.is_finite() {
                                grid.visit_segment(from, to);
                                let heading = (to - from).heading().to_degrees().rem_euclid(360.0);
                                add(heading_m, heading / HEADING_BIN_DEG, length);
                                add(speed_m, p.speed * 3.6 / SPEED_BIN_KMH, length);
                            }
                            from = to;
                        }
                    }
                    segment += 1;
                }
                CommandRecord::AddFault { probe, kind, .. } => {
                    let (probe, kind) = (probe.to_string(), kind.to_string());
                    let index = match faults
                        .iter()
                        .position(|f| f.probe == probe && f.kind == kind)
                    {
                        Some(index) => index,
                        None => {
                            faults.push(FaultCoverage {
                                probe,
                                kind,
                                planned: 0,
                                confirmed: 0,
                                acted: 0,
                            });
                            faults.len() - 1
                        }
                    };
                    faults[index].planned += 1;
                }
            }
        }
        for place in &case.fault_places {
            if let Some(CommandRecord::AddFault {
                probe, kind, param, ..
            }) = case.commands.get(place.command_index)
            {
                // A neutral parameter (an offset of 0, an amplification of 1) leaves the probe's
                // value as it is: such a fault never acts.
                let changes = kind.spec().neutral != Some(*param);
                let (probe, kind) = (probe.to_string(), kind.to_string());
                if let Some(f) = faults
                    .iter_mut()
                    .find(|f| f.probe == probe && f.kind == kind)
                {
                    f.confirmed += 1;
                    let ended = case.timing.map_or(f64::INFINITY, |t| t.drive_s);
                    if changes && place.acts_from_s < ended {
                        f.acted += 1;
                    }
                }
            }
        }
        if segments_per_test.len() <= driven {
            segments_per_test.resize(driven + 1, 0);
        }
        segments_per_test[driven] += 1;
    }

    /// The coverage of the tests added.
    pub fn finish(self) -> Coverage {
        let Self {
            grid,
            heading_m,
            speed_m,
            mut faults,
            segments_per_test,
            tests,
            ..
        } = self;
        faults.sort_by(|a, b| (&a.probe, &a.kind).cmp(&(&b.probe, &b.kind)));
        let drivable_cells = grid.raster.drivable_cells();
        let driven_cells = grid.visited_cells();
        Coverage {
            stats: CoverageStats {
                tests,
                cell_m: CELL_M,
                drivable_cells,
                driven_cells,
                area_share: grid.coverage(),
                heading_m,
                speed_m,
                faults,
                segments_per_test,
            },
            grid,
        }
    }
}

/// Metres driven in one bin of headings (degrees) or speeds (km/h).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bin {
    /// Where the bin begins.
    pub from: f64,
    /// Where the next begins.
    pub to: f64,
    /// Metres driven in it.
    pub metres: f64,
}

impl CoverageStats {
    /// Metres driven in all (the planned route of the driven segments).
    pub fn driven_m(&self) -> f64 {
        self.heading_m.iter().sum()
    }

    /// The heading bins, degrees counter-clockwise from east, all of them.
    pub fn heading_bins(&self) -> Vec<Bin> {
        let width = 360.0 / self.heading_m.len().max(1) as f64;
        bins(&self.heading_m, width)
    }

    /// The speed bins, km/h, up to the last one driven.
    pub fn speed_bins(&self) -> Vec<Bin> {
        let last = self.speed_m.iter().rposition(|&m| m > 0.0).unwrap_or(0);
        let mut speeds = bins(&self.speed_m, SPEED_BIN_KMH);
        speeds.truncate(last + 1);
        speeds
    }

    /// (segments driven, tests that drove that many) for the counts some test drove.
    pub fn tests_by_segments(&self) -> Vec<(usize, usize)> {
        self.segments_per_test
            .iter()
            .copied()
            .enumerate()
            .filter(|&(_, n)| n > 0)
            .collect()
    }
}

/// Bins of `width` holding `metres`, from 0.
fn bins(metres: &[f64], width: f64) -> Vec<Bin> {
    metres
        .iter()
        .enumerate()
        .map(|(k, &m)| Bin {
            from: k as f64 * width,
            to: (k + 1) as f64 * width,
            metres: m,
        })
        .collect()
}

/// The statistics as text, as `runs show --coverage` prints them: the area driven, the metres
/// driven per heading and per speed bin (with bars), the fault table and the tests per number of
/// segments driven. The report shows the same figures as HTML tables.
impl std::fmt::Display for CoverageStats {
    fn fmt(&self, out: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = self;
        writeln!(
            out,
            "coverage of {} test{}: {:.1} % of the drivable area driven ({} of {} cells of {} m)",
            c.tests,
            if c.tests == 1 { "" } else { "s" },
            c.area_share * 100.0,
            c.driven_cells,
            c.drivable_cells,
            c.cell_m
        )?;
        // Markdown throughout, as the tables of tests and runs: a table per histogram, its bar
        // a column of its own.
        let total = c.driven_m();
        writeln!(
            out,
            "\nmetres driven by heading (counter-clockwise from east), {total:.0} m in all:\n\n\
             | heading | metres | share |\n|---|---|---|"
        )?;
        for b in c.heading_bins() {
            writeln!(
                out,
                "| {:.0}°–{:.0}° | {:.1} | {} |",
                b.from,
                b.to,
                b.metres,
                bar(b.metres, total)
            )?;
        }
        writeln!(
            out,
            "\nmetres driven by speed:\n\n| speed | metres | share |\n|---|---|---|"
        )?;
        for b in c.speed_bins() {
            writeln!(
                out,
                "| {:.0}–{:.0} km/h | {:.1} | {} |",
                b.from,
                b.to,
                b.metres,
                bar(b.metres, total)
            )?;
        }
        if c.faults.is_empty() {
            out.write_str("\nfaults: none planned\n")?;
        } else {
            out.write_str(
                "\nfaults:\n\n| probe | fault type | planned | confirmed | began acting in its test |\n\
                 |---|---|---|---|---|\n",
            )?;
            for f in &c.faults {
                writeln!(
                    out,
                    "| {} | {} | {} | {} | {} |",
                    f.probe, f.kind, f.planned, f.confirmed, f.acted
                )?;
            }
        }
        let counts: Vec<String> = c
            .tests_by_segments()
            .iter()
            .map(|(segments, n)| format!("{segments} segments: {n}"))
            .collect();
        writeln!(out, "\ntests by segments driven: {}", counts.join(", "))
    }
}

/// A bar of up to 30 characters for `part` of `total`.
fn bar(part: f64, total: f64) -> String {
    let n = if total > 0.0 {
        (30.0 * part / total).round() as usize
    } else {
        0
    };
    "#".repeat(n)
}

/// Adds `metres` to bin `⌊position⌋` (the last bin takes what lies beyond it).
fn add(bins: &mut [f64], position: f64, metres: f64) {
    if let Some(last) = bins.len().checked_sub(1) {
        let k = (position.max(0.0).floor() as usize).min(last);
        bins[k] += metres;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use trajgen::Polygon;

    fn square() -> Area {
        let fence = Polygon::new(vec![
            Point::new(0.0, 0.0),
            Point::new(10.0, 0.0),
            Point::new(10.0, 10.0),
            Point::new(0.0, 10.0),
        ])
        .unwrap();
        Area::new(fence, vec![]).unwrap()
    }

    /// A case of one segment through `points` (x, y, speed), judged `judged` times (0 or 1).
    fn case_driving(points: &[(f64, f64, f64)], judged: usize) -> Case {
        let points: Vec<serde_json::Value> = points
            .iter()
            .map(|&(x, y, speed)| serde_json::json!({"x": x, "y": y, "speed": speed}))
            .collect();
        let segments: Vec<serde_json::Value> = (0..judged)
            .map(|k| {
                serde_json::json!({
                    "segment_index": k, "command_index": 0, "faults_preceding": [],
                    "oracle": {"stats": null, "invalid_uwb_samples": 0, "unjudged_samples": 0,
                               "threshold_m": 1.0, "verdict": "passed"}
                })
            })
            .collect();
        let json = serde_json::json!({
            "format": "drivecheck-case", "schema_version": 2,
            "scenario": {"name": "square"}, "no_faults": false,
            "commands": [{"command": "run_segments", "points": points}],
            "return_route": [], "segments": segments
        });
        Case::from_json(&json.to_string()).unwrap()
    }

    #[test]
    fn a_straight_drive_covers_its_cells_its_heading_and_its_speed() {
        // From (1, 1.25) east to (9, 1.25) at 1 m/s (3.6 km/h): 16 cells of 0.5 m in one row.
        let case = case_driving(&[(5.0, 1.25, 1.0), (9.0, 1.25, 1.0)], 1);
        let c = coverage(&square(), Point::new(1.0, 1.25), &[case]);
        assert_eq!(c.stats.drivable_cells, 400);
        assert_eq!(c.stats.driven_cells, 17);
        assert!(
            (c.stats.heading_m[0] - 8.0).abs() < 1e-9,
            "{:?}",
            c.stats.heading_m
        );
        assert!(
            (c.stats.speed_m[1] - 8.0).abs() < 1e-9,
            "{:?}",
            c.stats.speed_m
        );
        assert_eq!(c.stats.segments_per_test, [0, 1]);
        // A segment the test did not drive (no verdict) covers nothing.
        let undriven = case_driving(&[(5.0, 1.25, 1.0)], 0);
        let none = coverage(&square(), Point::new(1.0, 1.25), &[undriven]);
        assert_eq!(none.stats.driven_cells, 0);
        assert_eq!(none.stats.segments_per_test, [1]);
    }

    #[test]
    fn a_fault_with_a_neutral_parameter_is_confirmed_but_never_acted() {
        use crate::files::{CommandRecord, FaultPlacementRecord, PlaceRuleRecord, TestTiming};
        use crate::model::Probe;
        let mut case = case_driving(&[(5.0, 1.25, 1.0), (9.0, 1.25, 1.0)], 1);
        for param in [0.0, 2.0] {
            case.commands.push(CommandRecord::AddFault {
                probe: Probe::UwbYaw,
                kind: crate::model::FaultKind::Offset,
                param,
                start: 0,
                duration: 10,
                at: None,
            });
            case.fault_places.push(FaultPlacementRecord {
                command_index: case.commands.len() - 1,
                rule: PlaceRuleRecord::EarlierTool,
                segment_index: 0,
                planned_along_m: 1.0,
                sent_s: 1.0,
                added_s: 1.0,
                actual_along_m: None,
                error_m: None,
                acts_from_s: 1.0,
                acts_to_s: 2.0,
            });
        }
        case.timing = Some(TestTiming {
            reset_s: 1.0,
            drive_s: 10.0,
        });
        let c = coverage(&square(), Point::new(1.0, 1.25), &[case]);
        let [fault] = &c.stats.faults[..] else {
            panic!("{:?}", c.stats.faults);
        };
        assert_eq!((fault.confirmed, fault.acted), (2, 1), "{fault:?}");
    }

    #[test]
    fn the_text_names_the_area_the_bins_driven_and_the_faults() {
        let case = case_driving(&[(5.0, 1.25, 1.0), (9.0, 1.25, 1.0)], 1);
        let text = coverage(&square(), Point::new(1.0, 1.25), &[case])
            .stats
            .to_string();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[0],
            "coverage of 1 test: 4.2 % of the drivable area driven (17 of 400 cells of 0.5 m)"
        );
        // Markdown: a table per histogram, the bar a column of its own.
        assert_eq!(
            lines[2],
            "metres driven by heading (counter-clockwise from east), 8 m in all:"
        );
        assert_eq!(
            lines[4..6],
            ["| heading | metres | share |", "|---|---|---|"]
        );
        // Twelve heading bins of 30°, the first full: a bar of 30 characters.
        assert_eq!(lines[6], format!("| 0°–30° | 8.0 | {} |", "#".repeat(30)));
        assert_eq!(lines[17], "| 330°–360° | 0.0 |  |");
        assert_eq!(lines[19], "metres driven by speed:");
        // Speed bins up to the last one driven (2–4 km/h).
        assert_eq!(lines[23], "| 0–2 km/h | 0.0 |  |");
        assert_eq!(
            lines[24],
            format!("| 2–4 km/h | 8.0 | {} |", "#".repeat(30))
        );
        assert_eq!(lines[26], "faults: none planned");
        assert_eq!(lines[28], "tests by segments driven: 1 segments: 1");
        assert_eq!(lines.len(), 29);
        assert!(text.ends_with('\n'));
    }
}
