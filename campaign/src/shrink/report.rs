//! `shrink.json`: what a shrink tried and what it kept.

use serde::{Deserialize, Serialize};

use super::{RunResult, Size, Step, Target};
use crate::files::{
    CaseError, Header, SHRINK_FORMAT, SHRINK_READABLE, ScenarioRef, check_header, parse,
};
/// Its file name in the shrink directory.
pub const SHRINK_FILE: &str = "shrink.json";
/// The minimal case's file name in the shrink directory.
pub const MINIMAL_FILE: &str = "minimal.json";

/// The row of the before/after table that holds [`CaseSummary::median_deviation_m`].
pub const MEDIAN_ROW: &str = "its largest deviation (median of the runs)";

/// Why a shrink stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Ended {
    /// No edit was left that kept the failure: the case is minimal for the shrink's edits.
    Minimal,
    /// The time budget ran out (the case is the smallest found so far).
    Budget,
    /// The user interrupted it (the case is the smallest found so far).
    Interrupted,
}

impl Ended {
    /// Why the shrink stopped, in words (the command's summary and the report say it).
    pub fn words(self) -> &'static str {
        match self {
            Self::Minimal => "no simpler case fails the same way",
            Self::Budget => "stopped by the time budget (--budget)",
            Self::Interrupted => "interrupted",
        }
    }
}

/// A case as the shrink saw it: its size, its failing segment and the runs that confirmed it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaseSummary {
    /// Its size.
    pub size: Size,
    /// The segment(s) that fail first.
    pub target: Target,
    /// The runs that showed it (all failed there).
    pub runs: Vec<RunResult>,
}

impl CaseSummary {
    /// The median over [`CaseSummary::runs`] of each run's largest deviation in its failing
    /// segment: the nearest-rank median (`trajgen::stats`), the middle run of an odd number and
    /// the lower of the two middle ones of an even number. `None` without a measured run. The
    /// command's table and the report both show this.
    pub fn median_deviation_m(&self) -> Option<f64> {
        let mut values: Vec<f64> = self
            .runs
            .iter()
            .filter_map(|r| r.max_deviation_m)
            .filter(|m| m.is_finite())
            .collect();
        values.sort_by(f64::total_cmp);
        trajgen::stats::nearest_rank(&values, 0.5)
    }
}

/// The minimal case driven again with other seeds (those after the candidates' seeds).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Confirmation {
    /// The runs.
    pub runs: Vec<RunResult>,
    /// How many of them failed the same way.
    pub failed: usize,
    /// How many the case itself failed with the same seeds (driven only when the minimal case
    /// did not fail in all of them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub case_failed: Option<usize>,
    /// The minimal case is as robust as the case: it failed in every run, or in at least as many
    /// as the case itself. False only when the shrink stepped back to the case itself and it is
    /// less robust than its own first runs showed.
    pub confirmed: bool,
    /// Kept steps undone because the case they gave did not fail the same way with these seeds
    /// (a candidate that only just fails can be kept because its runs happened to fail).
    pub stepped_back: usize,
}

/// `shrink.json` (see `docs/case-format.md#shrinking-a-case`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShrinkReport {
    /// `drivecheck-shrink` ([`crate::files::SHRINK_FORMAT`]), its schema version and the
    /// drivecheck version that shrank it.
    #[serde(flatten)]
    pub header: Header,
    /// The case file shrunk, as given.
    pub case: String,
    /// The scenario it was driven in.
    pub scenario: ScenarioRef,
    /// The seed: run k of every candidate has seed + k.
    pub seed: u64,
    /// Runs per candidate; a candidate is kept only when all of them fail the same way.
    pub runs_per_candidate: u32,
    /// The largest deviation every run of a kept candidate reached in its failing segment: the
    /// threshold plus the margin, or the case's own least clear failure if that is less.
    pub min_deviation_m: f64,
    /// Why it stopped.
    pub ended: Ended,
    /// The case shrunk.
    pub before: CaseSummary,
    /// The minimal case (`minimal.json`).
    pub after: CaseSummary,
    /// The minimal case driven without its faults (absent when it has none): does the failure
    /// need them?
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub without_faults: Option<Vec<RunResult>>,
    /// The minimal case confirmed with other seeds (absent when the shrink was interrupted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confirmation: Option<Confirmation>,
    /// Every edit tried, in order.
    pub steps: Vec<Step>,
    /// Simulator runs in all (the confirmations of the case and of the minimal one included).
    pub simulator_runs: usize,
    /// Wall time, seconds.
    pub wall_s: f64,
    /// The command that replays the minimal case on a real car.
    pub replay_on_car: String,
}

impl ShrinkReport {
    /// Reads a shrink report from JSON: shape, format name and version.
    pub fn from_json(text: &str) -> Result<Self, CaseError> {
        let report: Self = parse(text)?;
        check_header(&report.header, SHRINK_FORMAT, SHRINK_READABLE)?;
        Ok(report)
    }

    /// The report as pretty-printed JSON.
    pub fn to_json(&self) -> Result<String, CaseError> {
        crate::files::to_json(self)
    }

    /// The before/after table the command prints.
    pub fn table(&self) -> String {
        let median = |summary: &CaseSummary| {
            summary
                .median_deviation_m()
                .map_or_else(|| "-".to_owned(), |v| format!("{v:.2} m"))
        };
        let (b, a) = (&self.before, &self.after);
        let mut out = String::from("| | before | after |\n|---|---|---|\n");
        let rows = [
            (
                "commands",
                b.size.commands.to_string(),
                a.size.commands.to_string(),
            ),
            (
                "segments",
                b.size.segments.to_string(),
                a.size.segments.to_string(),
            ),
            (
                "faults",
                b.size.faults.to_string(),
                a.size.faults.to_string(),
            ),
            (
                "route points",
                b.size.points.to_string(),
                a.size.points.to_string(),
            ),
            (
                "failing segment",
                b.target.to_string(),
                a.target.to_string(),
            ),
            (MEDIAN_ROW, median(b), median(a)),
        ];
        for (name, before, after) in rows {
            out.push_str(&format!("| {name} | {before} | {after} |\n"));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn summary(deviations: &[Option<f64>]) -> CaseSummary {
        CaseSummary {
            size: Size {
                commands: 3,
                segments: 2,
                faults: 1,
                points: 10,
            },
            target: Target::segment(1),
            runs: deviations
                .iter()
                .enumerate()
                .map(|(k, &max_deviation_m)| RunResult {
                    seed: k as u64,
                    verdict: Some(crate::oracle::Verdict::Failed),
                    first_failing_segment: Some(1),
                    max_deviation_m,
                })
                .collect(),
        }
    }

    #[test]
    fn the_median_is_the_nearest_rank_one_of_the_measured_runs() {
        // The middle run of three, in any order.
        let three = summary(&[Some(1.21), Some(1.15), Some(1.19)]);
        assert_eq!(three.median_deviation_m(), Some(1.19));
        // The lower middle of four; an unmeasured run does not count.
        let four = summary(&[Some(1.2), None, Some(1.1), Some(1.3), Some(1.15)]);
        assert_eq!(four.median_deviation_m(), Some(1.15));
        assert_eq!(summary(&[None]).median_deviation_m(), None);
    }
}
