//! Shrinking a failing case (`docs/method.md#replay-and-shrinking`): from a failing test to the
//! smallest test that still fails the same way, every time.
//!
//! A [`Shrinker`] holds the smallest case found so far and proposes simpler candidates, one at a
//! time ([`Shrinker::next_candidate`]); each candidate is driven several times in the simulator,
//! with varied seeds, and its runs are reported ([`Shrinker::record`]). [`shrink`] is the whole
//! policy around it (which runs, the margin, when to stop, the confirmation with other seeds and
//! stepping back), given the driving as a [`Drive`]: the orchestrator drives fresh simulators. A candidate is
//! kept only when **every** run failed the same way (Erlang QuickCheck's `?ALWAYS`), so the
//! minimal case is robust, not lucky.
//!
//! **The same failure.** A case fails at its *target*: its first failing segment (the segment
//! the oracle judged above the threshold first), or, for a case whose first failing segment
//! moves with the sensor noise between two neighbours, those two ([`Target`]). A run shows the
//! same failure when its verdict is `failed` (not aborted), its first failing segment is in the
//! target, as edits move it (dropping earlier segments moves it forward), and it failed there by
//! the required margin. A candidate that fails earlier, later or not at all is a different test
//! and is not kept.
//!
//! **The edits**, tried in this order on the current case, greedily: the first that keeps the
//! failure is kept and the list is made again for the simpler case; an edit that did not keep it
//! is not tried again on the same case. The shrink ends when no edit is left ([`Edit`]):
//! 1. cut the segments after the target, with the faults placed on them;
//! 2. drop every fault, then each fault (last first);
//! 3. drop the segments before the target, all at once, then one at a time (last first): the
//!    route before them is joined to the segment after them by the return-route planner
//!    (`recovery`: turn and segment limits, clearance), and every candidate's route is checked
//!    with its ahead margin before it is driven;
//! 4. move each fault's values toward neutral: parameter (offset → 0, amplification → 1), start
//!    → 0, duration → 1; first all the way, then half and a quarter of the way;
//! 5. drive each segment up to the target slower (toward the scenario's lowest speed);
//! 6. drop the failing segment's last points (half, then one).
//!
//! A candidate whose route is not drivable (the join or the trimmed segment leaves no ahead
//! margin, for example) is recorded as such and never driven. Every step is deterministic given
//! the seed; pure: no clock, no I/O.

use std::collections::HashSet;

use scenarios::Scenario;
use serde::{Deserialize, Serialize};
use thiserror::Error;
use trajgen::{Generator, Strategy};

use crate::files::{Case, CaseError, CommandRecord};
use crate::oracle::{SegmentVerdict, Verdict};

mod edit;
mod policy;
mod report;
#[cfg(test)]
mod tests;

pub use crate::files::SHRINK_FORMAT;
pub use edit::{Edit, EditError, FaultField};
pub use policy::{Drive, Progress, Settings, ShrinkFailure, Shrunk, shrink};
pub use report::{
    CaseSummary, Confirmation, Ended, MEDIAN_ROW, MINIMAL_FILE, SHRINK_FILE, ShrinkReport,
};

use edit::{Joins, neutral, part_way, segment_commands};

/// After moving a value all the way to neutral failed, how far of the way it is moved instead.
const PART_WAY: [f64; 2] = [0.5, 0.25];

/// Why a shrink cannot start.
#[derive(Debug, Error)]
pub enum ShrinkError {
    /// The case cannot be replayed in the scenario.
    #[error(transparent)]
    Case(#[from] CaseError),
    /// The scenario's generator settings are unusable.
    #[error("the scenario's generator settings: {0}")]
    Generator(#[source] trajgen::GenerationError),
    /// The target segment is not among the case's segments.
    #[error("segment {target} is not among the case's {segments} segments")]
    NoSuchSegment {
        /// The target's last segment.
        target: usize,
        /// Segments in the case.
        segments: usize,
    },
}

/// Why a candidate is not drivable (a step's `not_drivable`, in words).
#[derive(Debug, Error)]
enum NotDrivable {
    /// The edit gives no case.
    #[error(transparent)]
    Edit(EditError),
    /// The case it gives is refused (route, margins, faults).
    #[error(transparent)]
    Case(CaseError),
}

/// What one run of a candidate showed: what the shrink judges by.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunResult {
    /// The run's seed.
    pub seed: u64,
    /// Its verdict (absent when it did not get to one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
    /// Its first failing segment.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first_failing_segment: Option<usize>,
    /// The largest deviation of that segment (or of the run, when none failed), metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_deviation_m: Option<f64>,
}

impl RunResult {
    /// The result of a run that wrote `case`.
    pub fn of(seed: u64, case: &Case) -> Self {
        let failing = case
            .segments
            .iter()
            .find(|s| s.oracle.verdict == SegmentVerdict::Failed);
        let max = |s: &crate::files::SegmentResult| s.oracle.stats.as_ref().map(|st| st.max_m);
        Self {
            seed,
            verdict: case.verdict,
            first_failing_segment: failing.map(|s| s.segment_index),
            max_deviation_m: match failing {
                Some(s) => max(s),
                None => case.segments.iter().filter_map(max).reduce(f64::max),
            },
        }
    }

    /// True when the run failed with its first failing segment in `target`.
    pub fn fails_at(&self, target: Target) -> bool {
        self.verdict == Some(Verdict::Failed)
            && self
                .first_failing_segment
                .is_some_and(|s| target.contains(s))
    }

    /// True when the run failed with its first failing segment in `target` and a largest
    /// deviation there of at least `min_deviation_m`.
    pub fn fails_clearly(&self, target: Target, min_deviation_m: f64) -> bool {
        self.fails_at(target)
            && (min_deviation_m <= 0.0
                || self.max_deviation_m.is_some_and(|m| m >= min_deviation_m))
    }
}

/// The segments where a case fails first: one, or two neighbours when the first failing segment
/// moves with the sensor noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    /// The first segment of the target.
    pub first: usize,
    /// Its last (equal to `first` for one segment).
    pub last: usize,
}

impl Target {
    /// One segment.
    pub fn segment(segment: usize) -> Self {
        Self {
            first: segment,
            last: segment,
        }
    }

    /// The target of runs' first failing segments: the segments from the smallest to the
    /// largest, when every run failed and they are at most one apart.
    pub fn of_runs(runs: &[RunResult]) -> Option<Self> {
        let mut segments = runs.iter().map(|r| match r.verdict {
            Some(Verdict::Failed) => r.first_failing_segment,
            _ => None,
        });
        let first = segments.next()??;
        let (mut lo, mut hi) = (first, first);
        for s in segments {
            let s = s?;
            lo = lo.min(s);
            hi = hi.max(s);
        }
        (hi - lo <= 1).then_some(Self {
            first: lo,
            last: hi,
        })
    }

    /// True when `segment` is in the target.
    pub fn contains(self, segment: usize) -> bool {
        (self.first..=self.last).contains(&segment)
    }

    /// The target after `n` segments before it were removed.
    pub fn moved_back(self, n: usize) -> Self {
        Self {
            first: self.first - n,
            last: self.last - n,
        }
    }
}

impl std::fmt::Display for Target {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.first == self.last {
            write!(f, "{}", self.first)
        } else {
            write!(f, "{}–{}", self.first, self.last)
        }
    }
}

/// How a tried edit ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// Every run failed the same way: the candidate is the new current case.
    Kept,
    /// A run passed.
    Passed,
    /// A run failed at another segment first.
    FailedElsewhere,
    /// Every run failed there, but a run by less than the margin above the threshold.
    FailedBarely,
    /// A run was aborted (or ended without a verdict).
    Aborted,
    /// The candidate's route is not drivable (never driven).
    NotDrivable,
}

impl Outcome {
    /// The outcome of `runs` for a failure at `target` by at least `min_deviation_m`.
    pub fn of(runs: &[RunResult], target: Target, min_deviation_m: f64) -> Self {
        for run in runs {
            match run.verdict {
                Some(Verdict::Passed) => return Self::Passed,
                Some(Verdict::Failed) if !run.fails_at(target) => return Self::FailedElsewhere,
                Some(Verdict::Failed) if !run.fails_clearly(target, min_deviation_m) => {
                    return Self::FailedBarely;
                }
                Some(Verdict::Failed) => {}
                Some(Verdict::Aborted) | None => return Self::Aborted,
            }
        }
        if runs.is_empty() {
            Self::Aborted
        } else {
            Self::Kept
        }
    }

    /// As written in `shrink.json` and the table.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Kept => "kept",
            Self::Passed => "passed",
            Self::FailedElsewhere => "failed elsewhere",
            Self::FailedBarely => "failed barely",
            Self::Aborted => "aborted",
            Self::NotDrivable => "not drivable",
        }
    }
}

/// One edit tried.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Step {
    /// What was changed.
    pub edit: Edit,
    /// The same in words.
    pub description: String,
    /// How it ended.
    pub outcome: Outcome,
    /// Why the candidate was not drivable.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub not_drivable: Option<String>,
    /// The runs (they stop at the first that does not fail the same way).
    #[serde(default)]
    pub runs: Vec<RunResult>,
    /// Commands of the candidate.
    pub commands: usize,
    /// The candidate's failing segment(s).
    pub target: Target,
}

/// A candidate to drive: a simpler case and where it must fail.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// The edit that made it.
    pub edit: Edit,
    /// The case (no results; every segment with its ahead margin).
    pub case: Case,
    /// The segment(s) that must fail first.
    pub target: Target,
}

/// Sizes of a case, for the before/after table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Size {
    /// Commands.
    pub commands: usize,
    /// `run_segments` commands.
    pub segments: usize,
    /// `add_fault` commands.
    pub faults: usize,
    /// Route points of all segments.
    pub points: usize,
}

impl Size {
    /// The size of `case`.
    pub fn of(case: &Case) -> Self {
        let mut size = Self {
            commands: case.commands.len(),
            segments: 0,
            faults: 0,
            points: 0,
        };
        for command in &case.commands {
            match command {
                CommandRecord::RunSegments { points, .. } => {
                    size.segments += 1;
                    size.points += points.len();
                }
                CommandRecord::AddFault { .. } => size.faults += 1,
            }
        }
        size
    }
}

/// A shrink in progress (see the module doc).
#[derive(Debug)]
pub struct Shrinker<'a> {
    scenario: &'a Scenario,
    generator: Generator,
    seed: u64,
    current: Case,
    target: Target,
    /// Edits (in words) that did not keep the failure on the current case.
    rejected: HashSet<String>,
    steps: Vec<Step>,
    joins: Joins,
    /// The largest deviation every run must reach in the target segment.
    min_deviation_m: f64,
}

impl<'a> Shrinker<'a> {
    /// A shrink of `case`, which fails first at `target`, in `scenario`; `seed` seeds the
    /// joining routes and the generated ahead margins.
    pub fn new(
        case: &Case,
        scenario: &'a Scenario,
        target: Target,
        seed: u64,
    ) -> Result<Self, ShrinkError> {
        let generator = Generator::new(scenario.generator.generator_config(Strategy::Wedge))
            .map_err(ShrinkError::Generator)?;
        let segments = segment_commands(case).len();
        if target.last >= segments || target.first > target.last {
            return Err(ShrinkError::NoSuchSegment {
                target: target.last,
                segments,
            });
        }
        let current = prepared(case, scenario, &generator, seed)?;
        Ok(Self {
            scenario,
            generator,
            seed,
            current,
            target,
            rejected: HashSet::new(),
            steps: Vec::new(),
            joins: Joins::default(),
            min_deviation_m: 0.0,
        })
    }

    /// Keeps a candidate only when every run's largest deviation in the target segment is at
    /// least `metres` (the threshold plus a margin: a case that only just fails is kept by luck
    /// and passes with other noise).
    pub fn with_min_deviation(mut self, metres: f64) -> Self {
        self.min_deviation_m = metres;
        self
    }

    /// The smallest case that kept the failure so far (no results).
    pub fn current(&self) -> &Case {
        &self.current
    }

    /// Its failing segment(s).
    pub fn target(&self) -> Target {
        self.target
    }

    /// Every edit tried, in order.
    pub fn steps(&self) -> &[Step] {
        &self.steps
    }

    /// The next candidate to drive, or `None` when no edit is left (the case is minimal).
    /// Candidates that are not drivable are recorded as steps and skipped.
    pub fn next_candidate(&mut self) -> Option<Candidate> {
        for edit in self.edits() {
            let key = edit.to_string();
            if self.rejected.contains(&key) {
                continue;
            }
            let applied = edit
                .apply(
                    &self.current,
                    self.target,
                    self.scenario,
                    self.seed,
                    &mut self.joins,
                )
                .map_err(NotDrivable::Edit)
                .and_then(|(case, target)| {
                    prepared(&case, self.scenario, &self.generator, self.seed)
                        .map(|case| (case, target))
                        .map_err(NotDrivable::Case)
                });
            match applied {
                Ok((case, target)) => return Some(Candidate { edit, case, target }),
                Err(reason) => {
                    self.steps.push(Step {
                        description: key.clone(),
                        edit,
                        outcome: Outcome::NotDrivable,
                        not_drivable: Some(reason.to_string()),
                        runs: Vec::new(),
                        commands: 0,
                        target: self.target,
                    });
                    self.rejected.insert(key);
                }
            }
        }
        None
    }

    /// Records the runs of `candidate`; true when it was kept (it became the current case).
    pub fn record(&mut self, candidate: Candidate, runs: Vec<RunResult>) -> bool {
        let outcome = Outcome::of(&runs, candidate.target, self.min_deviation_m);
        let description = candidate.edit.to_string();
        self.steps.push(Step {
            edit: candidate.edit,
            description: description.clone(),
            outcome,
            not_drivable: None,
            runs,
            commands: candidate.case.commands.len(),
            target: candidate.target,
        });
        if outcome == Outcome::Kept {
            self.current = candidate.case;
            self.target = candidate.target;
            self.rejected.clear();
            true
        } else {
            self.rejected.insert(description);
            false
        }
    }

    /// The edits of the current case, in the order they are tried (see the module doc).
    fn edits(&self) -> Vec<Edit> {
        let case = &self.current;
        let target = self.target;
        let segments = segment_commands(case);
        let faults: Vec<usize> = case
            .commands
            .iter()
            .enumerate()
            .filter(|(_, c)| matches!(c, CommandRecord::AddFault { .. }))
            .map(|(i, _)| i)
            .collect();
        let mut edits = Vec::new();
        if segments.len() > target.last + 1 {
            edits.push(Edit::CutTail {
                after_segment: target.last,
                segments_removed: segments.len() - target.last - 1,
            });
        }
        if faults.len() > 1 {
            edits.push(Edit::DropAllFaults {
                faults: faults.len(),
            });
        }
        edits.extend(
            faults
                .iter()
                .rev()
                .map(|&command_index| Edit::DropFault { command_index }),
        );
        if target.first > 1 {
            edits.push(Edit::DropSegments {
                first: 0,
                last: target.first - 1,
            });
        }
        edits.extend(
            (0..target.first)
                .rev()
                .map(|k| Edit::DropSegments { first: k, last: k }),
        );
        for &command_index in &faults {
            let CommandRecord::AddFault {
                kind,
                param,
                start,
                duration,
                ..
            } = case.commands[command_index]
            else {
                continue;
            };
            let values = [
                (FaultField::Param, param, 0.1),
                (FaultField::Start, f64::from(start), 1.0),
                (FaultField::Duration, f64::from(duration), 1.0),
            ];
            for (field, from, step) in values {
                let Some(to) = neutral(kind, field) else {
                    continue;
                };
                if (from - to).abs() < step / 2.0 {
                    continue;
                }
                edits.push(Edit::FaultValue {
                    command_index,
                    field,
                    from,
                    to,
                });
                for fraction in PART_WAY {
                    if let Some(to) = part_way(from, to, fraction, step) {
                        edits.push(Edit::FaultValue {
                            command_index,
                            field,
                            from,
                            to,
                        });
                    }
                }
            }
        }
        let slowest = self.scenario.campaign.speed_kmh.min / 3.6;
        for (segment_index, &command) in segments.iter().enumerate().take(target.last + 1) {
            let CommandRecord::RunSegments { points, .. } = &case.commands[command] else {
                continue;
            };
            let from_mps = points[0].speed;
            if from_mps - slowest < 0.05 {
                continue;
            }
            edits.push(Edit::SlowSegment {
                segment_index,
                from_mps,
                to_mps: slowest,
            });
            for fraction in PART_WAY {
                if let Some(to_mps) = part_way(from_mps, slowest, fraction, 0.1) {
                    edits.push(Edit::SlowSegment {
                        segment_index,
                        from_mps,
                        to_mps,
                    });
                }
            }
        }
        if target.last + 1 == segments.len()
            && let CommandRecord::RunSegments { points, .. } = &case.commands[segments[target.last]]
        {
            let n = points.len();
            for to_points in [n.div_ceil(2), n - 1] {
                if to_points >= 1 && to_points < n {
                    edits.push(Edit::TrimSegment {
                        segment_index: target.last,
                        from_points: n,
                        to_points,
                    });
                }
            }
        }
        edits
    }
}

/// `case` as a candidate: its commands with an ahead margin for every segment, checked in the
/// scenario (values, route with margins, faults that can act), without the results of a run.
fn prepared(
    case: &Case,
    scenario: &Scenario,
    generator: &Generator,
    seed: u64,
) -> Result<Case, CaseError> {
    let mut case = case.clone();
    case.return_route.clear();
    case.return_clearance_m = None;
    case.segments.clear();
    case.verdict = None;
    case.reason = None;
    case.abort = None;
    case.streaming = None;
    case.fault_places.clear();
    // The minimal case has places for its faults (version 2 on) and keeps the case's settings,
    // whose form its version names.
    case.header.schema_version = case
        .header
        .schema_version
        .max(crate::files::CASE_FAULT_PLACES_SINCE);
    case.check()?;
    case.check_route(scenario)?;
    case.check_faults_act(scenario)?;
    let case = case.with_margins(scenario, generator, seed)?;
    case.check_route(scenario)?;
    Ok(case)
}
