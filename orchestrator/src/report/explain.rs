//! The explanations of a run directory's tests (`drivecheck explain`): each test's samples from
//! the recording, its segments' times located on its route (as the report's plot finds them),
//! its faults' estimated windows and the scenario's anchors, handed to `campaign::explain`.

use std::path::{Path, PathBuf};

use scenarios::Scenario;
use serde::{Deserialize, Serialize};

use super::ReportError;
use super::data::{CampaignData, TestData, read_campaign, scenario_for};
use super::route::boundaries;
use campaign::case::{Case, CommandRecord};
use campaign::explain::{
    ExplainAnchor, ExplainConfig, ExplainFault, ExplainSample, ExplainSegment, SegmentExplanation,
    Source, explain_segment,
};
use campaign::oracle::SegmentVerdict;

/// Every explained case of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Explanations {
    /// The cases, in test order.
    pub cases: Vec<CaseExplanation>,
    /// What could not be explained, and why.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// One case's explained segments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseExplanation {
    /// The case file.
    pub case: PathBuf,
    /// Its test index.
    pub test_index: usize,
    /// The failing segments (every judged one with `all`), in order.
    pub segments: Vec<SegmentExplanation>,
}

/// Why a test's segments could not be explained (a note on the page or in the output, not an
/// error of the run: the other tests are explained).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum NotExplained {
    /// The recording holds no state samples of the test (`--record failing` or `none`, or a
    /// recording cut short).
    #[error("the recording has no samples of this test")]
    NoSamples,
}

/// What to explain.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ExplainOptions {
    /// Every judged segment, not only the failing ones.
    pub all_segments: bool,
    /// The method's settings (the threshold is the case's own).
    pub config: ExplainConfig,
}

/// Explains the tests of the run directory `dir`, or only the case file `case` in it.
pub fn explain_run(
    dir: &Path,
    only: Option<&Path>,
    scenario: Option<&Scenario>,
    options: &ExplainOptions,
) -> Result<Explanations, ReportError> {
    let data = read_campaign(dir)?;
    let (scenario, mut notes) = scenario_for(
        &data.record.scenario.name,
        data.record.scenario.hash.as_deref(),
        scenario,
        data.recorded_scenario.as_deref(),
    );
    notes.extend(data.notes.iter().cloned());
    let Some(scenario) = scenario else {
        notes.push("no scenario: the anchors and the route are unknown".to_owned());
        return Ok(Explanations {
            cases: Vec::new(),
            notes,
        });
    };
    let wanted = only.and_then(|p| p.file_name()).and_then(|n| n.to_str());
    let mut cases = Vec::new();
    for test in &data.tests {
        if wanted.is_some_and(|w| w != test.file) {
            continue;
        }
        match explain_test(&data, test, &scenario, options) {
            Ok(explained) => cases.push(explained),
            Err(why) => notes.push(format!("{}: {why}", test.file)),
        }
    }
    if let Some(w) = wanted
        && !data.tests.iter().any(|t| t.file == w)
    {
        notes.push(format!("{w} is not a case file of {}", dir.display()));
    }
    Ok(Explanations { cases, notes })
}

fn explain_test(
    data: &CampaignData,
    test: &TestData,
    scenario: &Scenario,
    options: &ExplainOptions,
) -> Result<CaseExplanation, NotExplained> {
    Ok(CaseExplanation {
        case: data.dir.join(&test.file),
        test_index: test.index,
        segments: explain_segments(test, scenario, options)?,
    })
}

/// The explained segments of one test (the failing ones; every judged one with
/// `options.all_segments`); an error when the recording has no samples of it.
pub(crate) fn explain_segments(
    test: &TestData,
    scenario: &Scenario,
    options: &ExplainOptions,
) -> Result<Vec<SegmentExplanation>, NotExplained> {
    let case = &test.case;
    let track = test.track.as_ref().ok_or(NotExplained::NoSamples)?;
    let samples: Vec<ExplainSample> = track
        .samples
        .iter()
        .map(|s| ExplainSample {
            t_s: s.t_s,
            rtk: s.rtk,
            uwb: s.uwb,
        })
        .collect();
    let bounds = boundaries(scenario, case, &track.samples);
    let anchors: Vec<ExplainAnchor> = scenario
        .anchors
        .iter()
        .map(|a| ExplainAnchor {
            id: u16::from(a.id),
            position: trajgen::Point::new(a.x, a.y),
        })
        .collect();
    let faults = faults_of(case);
    let mut segments = Vec::new();
    for result in &case.segments {
        let failed = result.oracle.verdict == SegmentVerdict::Failed;
        if !failed && !options.all_segments {
            continue;
        }
        let k = result.segment_index;
        let at = |label: &str| bounds.iter().find(|b| b.label == label).map(|b| b.t_s);
        let from_s = at(&format!("s{k}"));
        let to_s = at(&format!("s{}", k + 1))
            .or_else(|| at("end"))
            .or_else(|| samples.last().map(|s| s.t_s));
        let (Some(from_s), Some(to_s)) = (from_s, to_s) else {
            continue;
        };
        let segment = ExplainSegment {
            segment_index: k,
            from_s,
            to_s,
            failed,
        };
        let config = ExplainConfig {
            threshold_m: result.oracle.threshold_m,
            ..options.config
        };
        segments.extend(explain_segment(
            &segment, &samples, &anchors, &faults, &config,
        ));
    }
    Ok(segments)
}

/// The case's faults with their estimated windows (faults the car confirmed).
pub(crate) fn faults_of(case: &Case) -> Vec<ExplainFault> {
    case.fault_places
        .iter()
        .filter_map(|place| match case.commands.get(place.command_index) {
            Some(CommandRecord::AddFault {
                probe, kind, param, ..
            }) => Some(ExplainFault {
                command_index: place.command_index,
                probe: *probe,
                kind: *kind,
                param: *param,
                acts_from_s: place.acts_from_s,
                acts_to_s: place.acts_to_s,
            }),
            _ => None,
        })
        .collect()
}

/// A cause of test `test_index` in words (the campaign's `cases` give the fault's command).
pub(crate) fn describe_source(source: &Source, cases: &[Case], test_index: usize) -> String {
    let case = cases.iter().find(|c| c.test_index == Some(test_index));
    describe(source, case)
}

/// A cause in words: a fault with its command (what `drivecheck explain` and `run` print).
pub(crate) fn describe(source: &Source, case: Option<&Case>) -> String {
    match source {
        Source::Fault { command_index } => {
            let what = case
                .and_then(|c| c.commands.get(*command_index))
                .and_then(|c| match c {
                    CommandRecord::AddFault {
                        probe, kind, param, ..
                    } => Some(format!(" ({probe} {kind} {param:.2})")),
                    CommandRecord::RunSegments { .. } => None,
                });
            format!("fault: command {command_index}{}", what.unwrap_or_default())
        }
        Source::Anchor { anchor_id } => format!("anchor {anchor_id}'s range"),
        Source::Odometry => "odometry (travelled distance)".to_owned(),
        Source::Heading => "heading (yaw)".to_owned(),
        Source::Unexplained => "unexplained".to_owned(),
    }
}

/// What really made a failing segment's error grow, from a simulated run's hidden truth.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "truth")]
pub enum TrueCause {
    /// An injected fault applied during the growth (the one that moved the estimate most).
    Fault {
        /// Its command's index in the case.
        command_index: usize,
    },
    /// No fault applied, and this anchor's ranges came over a reflected path.
    Reflection {
        /// The anchor.
        anchor_id: u16,
    },
    /// Neither: dead reckoning's own drift and range noise.
    Nominal,
}

/// One failing segment: what the explanation named first, and the truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scored {
    /// The case file.
    pub case: PathBuf,
    /// The segment.
    pub segment_index: usize,
    /// The first cause named (`None`: only `unexplained`).
    pub named: Option<Source>,
    /// The truth.
    pub truth: TrueCause,
    /// The class of the truth, for the confusion matrix (`range offset`, `wheel slip`, …).
    pub truth_class: String,
    /// Whether the first cause named is the truth (a fault: that very command; a reflection:
    /// that anchor's range; nominal: no fault and no anchor).
    pub right: bool,
    /// The faults that moved the estimate by at least [`FAULT_MOVED_M`] during the growth
    /// interval and the [`TRUTH_SLACK_S`] before it, most first (metres: how far each pushed
    /// its probe's quantity, see [`score_run`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub moved: Vec<FaultEffect>,
    /// When several did and the case was driven again without each of them
    /// ([`settle_by_counterfactual`]): how much lower the segment's largest deviation came out
    /// without each (the median over the runs), most first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub counterfactual: Vec<FaultEffect>,
    /// Other faults whose absence lowered the deviation as much as the truth's, within
    /// [`COUNTERFACTUAL_TIE_M`]: each was needed as much (naming one of them is right).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tied_with: Vec<usize>,
}

/// A fault command and a length in metres (what it moved, or what its absence lowered).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FaultEffect {
    /// The fault's command index in the case.
    pub command_index: usize,
    /// Metres.
    pub metres: f64,
}

impl Scored {
    /// The faults a counterfactual should tell apart: two or more moved the estimate.
    pub fn needs_counterfactual(&self) -> bool {
        matches!(self.truth, TrueCause::Fault { .. }) && self.moved.len() >= 2
    }
}

/// Settles which of several faults that moved the estimate is the truth by what the segment's
/// largest deviation came to without each (`drops`: how much lower it was, per fault): the one
/// whose absence lowered it most. The push each fault gave its probe (what [`score_run`] ranks
/// by) is not how much of the error it caused: a push while the error pointed across the track,
/// or while the ranges pulled it back, grows the error little.
///
/// Faults whose absence lowered it as much, within [`COUNTERFACTUAL_TIE_M`], are each as much the
/// cause (often each alone was needed: without either the segment comes out the same), and naming
/// any of them is right. When no fault's absence lowered it by [`FAULT_MOVED_M`], none of them
/// alone made it fail and the truth stays the push's.
pub fn settle_by_counterfactual(scored: &mut Scored, case: &Case, mut drops: Vec<FaultEffect>) {
    drops.retain(|d| d.metres.is_finite());
    drops.sort_by(|a, b| b.metres.total_cmp(&a.metres));
    if let Some(first) = drops.first().filter(|d| d.metres >= FAULT_MOVED_M) {
        scored.truth = TrueCause::Fault {
            command_index: first.command_index,
        };
        scored.tied_with = drops[1..]
            .iter()
            .filter(|d| first.metres - d.metres <= COUNTERFACTUAL_TIE_M)
            .map(|d| d.command_index)
            .collect();
        scored.truth_class = truth_class(case, scored.truth);
        scored.right = is_right(scored.truth, scored.named)
            || scored.named.is_some_and(|named| {
                scored
                    .tied_with
                    .iter()
                    .any(|&command_index| named == Source::Fault { command_index })
            });
    }
    scored.counterfactual = drops;
}

/// Two faults whose absence lowers a segment's largest deviation by amounts this close are
/// equally its cause, metres: 2 % of the method's 1 m threshold, far below what decides a verdict.
pub const COUNTERFACTUAL_TIE_M: f64 = 0.02;

/// Whether `named` is `truth` (see [`Scored::right`]).
fn is_right(truth: TrueCause, named: Option<Source>) -> bool {
    use Source;
    match (truth, named) {
        (TrueCause::Fault { command_index }, Some(Source::Fault { command_index: n })) => {
            command_index == n
        }
        (TrueCause::Reflection { anchor_id }, Some(Source::Anchor { anchor_id: n })) => {
            anchor_id == n
        }
        (TrueCause::Nominal, named) => {
            !matches!(named, Some(Source::Fault { .. } | Source::Anchor { .. }))
        }
        _ => false,
    }
}

/// The truth of each failing segment of a simulated run, next to its explanation; and the
/// scenario the run was recorded in (its recording's copy, else the bundled one, else
/// `scenario`), in which its cases can be driven again.
pub fn score_run(
    dir: &Path,
    scenario: Option<&Scenario>,
    options: &ExplainOptions,
) -> Result<(Explanations, Vec<Scored>, Option<Scenario>), ReportError> {
    use crate::recording::{Recording, SimFault, SimRange, TruthRecord};
    let explanations = explain_run(dir, None, scenario, options)?;
    let data = read_campaign(dir)?;
    let path = dir.join(crate::runner::RECORDING_FILE);
    let recording = Recording::read(&path).map_err(|e| invalid(&path, e))?;
    let read = |e: crate::recording::RecordingError| invalid(&path, e);
    if recording
        .messages::<TruthRecord>()
        .map_err(read)?
        .is_empty()
    {
        return Err(invalid(
            &path,
            "the recording has no simulator truth (/sim/truth): only a simulated run can be \
             scored",
        ));
    }
    let faults = recording.messages::<SimFault>().map_err(read)?;
    let ranges = recording.messages::<SimRange>().map_err(read)?;
    let mut scored = Vec::new();
    for case in &explanations.cases {
        let Some(test) = data.tests.iter().find(|t| t.index == case.test_index) else {
            continue;
        };
        let Some(track) = &test.track else { continue };
        let t_of = |log_ns: u64| (log_ns as f64 - track.zero_ns as f64) / 1e9;
        for segment in case.segments.iter().filter(|s| s.verdict == "failed") {
            let (a, b) = (segment.from_s - TRUTH_SLACK_S, segment.to_s);
            let inside = |log_ns: u64| (a..=b).contains(&t_of(log_ns));
            // Faults: how far each (probe, slot) moved the estimate, metres.
            let mut moved: Vec<(usize, f64)> = Vec::new();
            for applied in faults.iter().filter(|f| inside(f.log_time_ns)) {
                let f = &applied.message;
                let delta = (f.after - f.before).abs();
                let metres = match f.probe.as_str() {
                    "uwb_travel_dist" => delta,
                    "uwb_yaw" => delta.to_radians() * YAW_LEVER_M,
                    _ => delta.min(MAX_CORRECTION_M),
                };
                for (command, part) in slot_shares(&test.case, f) {
                    match moved.iter_mut().find(|m| m.0 == command) {
                        Some(m) => m.1 += metres * part,
                        None => moved.push((command, metres * part)),
                    }
                }
            }
            moved.sort_by(|x, y| y.1.total_cmp(&x.1));
            let truth = match moved.first() {
                Some(&(command_index, metres)) if metres >= FAULT_MOVED_M => {
                    TrueCause::Fault { command_index }
                }
                _ => {
                    let mut reflected: Vec<(u16, f64)> = Vec::new();
                    for request in ranges.iter().filter(|r| inside(r.log_time_ns)) {
                        if let SimRange::Request {
                            anchor,
                            path: Some(p),
                            true_range_m: Some(truth),
                            range_m: Some(range),
                            ..
                        } = &request.message
                            && p.kind == crate::recording::RadioPathKind::Reflected
                        {
                            let excess = (range - truth).max(0.0);
                            let id = u16::from(*anchor);
                            match reflected.iter_mut().find(|r| r.0 == id) {
                                Some(r) => r.1 += excess,
                                None => reflected.push((id, excess)),
                            }
                        }
                    }
                    reflected.sort_by(|x, y| y.1.total_cmp(&x.1));
                    match reflected.first() {
                        Some(&(anchor_id, excess)) if excess >= REFLECTED_EXCESS_M => {
                            TrueCause::Reflection { anchor_id }
                        }
                        _ => TrueCause::Nominal,
                    }
                }
            };
            let named = segment.top().map(|c| c.source);
            let right = is_right(truth, named);
            scored.push(Scored {
                case: case.case.clone(),
                segment_index: segment.segment_index,
                named,
                truth,
                truth_class: truth_class(&test.case, truth),
                right,
                moved: moved
                    .iter()
                    .filter(|m| m.1 >= FAULT_MOVED_M)
                    .map(|&(command_index, metres)| FaultEffect {
                        command_index,
                        metres,
                    })
                    .collect(),
                counterfactual: Vec::new(),
                tied_with: Vec::new(),
            });
        }
    }
    let (scenario, _) = scenario_for(
        &data.record.scenario.name,
        data.record.scenario.hash.as_deref(),
        scenario,
        data.recorded_scenario.as_deref(),
    );
    Ok((explanations, scored, scenario))
}

/// The truth looks this far before the growth interval (a fault's last applications before
/// the error crossed the nominal level still count), seconds.
pub const TRUTH_SLACK_S: f64 = 0.5;
/// The firmware's largest correction per range, metres.
const MAX_CORRECTION_M: f64 = 0.2;
/// What a yaw error of one radian moves the estimate per odometry tick at about 2 m/s, metres.
const YAW_LEVER_M: f64 = 0.02;
/// A fault that moved the estimate less than this is not the truth, metres.
pub const FAULT_MOVED_M: f64 = 0.05;
/// Reflected ranges longer than the direct path by less than this in all are not the truth,
/// metres.
const REFLECTED_EXCESS_M: f64 = 0.3;

/// The command index of the fault in slot `slot` of `probe`: the car fills a probe's slots in
/// the order it adds faults, which is the order of the case's `fault_places`.
fn command_of_slot(case: &Case, probe: &str, slot: usize) -> Option<usize> {
    case.fault_places
        .iter()
        .filter(|place| {
            matches!(case.commands.get(place.command_index),
                Some(CommandRecord::AddFault { probe: p, .. }) if p.to_string() == probe)
        })
        .nth(slot)
        .map(|place| place.command_index)
}

/// The faults that applied in one probe call (`applied`), each with its share of the call's
/// change of the probe's value: the simulator applies them in slot order, so each slot's own
/// change is replayed from the value before. Equal shares when the changes cannot be told (the
/// value before is not finite, or no slot changed it).
fn slot_shares(case: &Case, applied: &crate::recording::SimFault) -> Vec<(usize, f64)> {
    use car_sim::fault::FaultEffect;
    let mut value = applied.before as f32;
    let mut changes: Vec<(usize, f64)> = Vec::new();
    for slot in (0..8).filter(|slot| applied.slots & (1 << slot) != 0) {
        let Some(command) = command_of_slot(case, &applied.probe, slot) else {
            continue;
        };
        let change = match case.commands.get(command) {
            Some(CommandRecord::AddFault { kind, param, .. }) => {
                let next = kind.apply(value, *param as f32);
                let change = f64::from((next - value).abs());
                value = next;
                change
            }
            _ => f64::NAN,
        };
        changes.push((command, change));
    }
    let total: f64 = changes.iter().map(|c| c.1).sum();
    let equal = 1.0 / changes.len().max(1) as f64;
    changes
        .into_iter()
        .map(|(command, change)| {
            let part = if total.is_finite() && total > 0.0 {
                change / total
            } else {
                equal
            };
            (command, part)
        })
        .collect()
}

/// The class of a truth, for the confusion matrix.
fn truth_class(case: &Case, truth: TrueCause) -> String {
    match truth {
        TrueCause::Fault { command_index } => match case.commands.get(command_index) {
            Some(CommandRecord::AddFault { probe, kind, .. }) => match probe {
                car_link::Probe::UwbRange(_) => {
                    format!("range {}", kind.to_string().to_lowercase())
                }
                car_link::Probe::UwbTravelDist => "wheel slip".to_owned(),
                car_link::Probe::UwbYaw => "yaw".to_owned(),
                car_link::Probe::Px => "px".to_owned(),
            },
            _ => "fault".to_owned(),
        },
        TrueCause::Reflection { anchor_id } => format!("reflection on {anchor_id}"),
        TrueCause::Nominal => "nominal".to_owned(),
    }
}

fn invalid(path: &Path, error: impl std::fmt::Display) -> ReportError {
    ReportError::Invalid {
        path: path.to_owned(),
        message: error.to_string(),
    }
}

/// Thresholds for `campaign::explain` from a fault-free run, at a false-alarm budget.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Samples of |UWB − RTK| read.
    pub samples: usize,
    /// Judged segments read.
    pub segments: usize,
    /// The budget: the share of fault-free samples above `nominal_m`, and of fault-free segments
    /// with a cause above `min_growth_m`.
    pub budget: f64,
    /// The error level `1 − budget` of the fault-free samples stay at or below, metres.
    pub nominal_m: f64,
    /// The growth a cause of `1 − budget` of the fault-free segments stays below (with that
    /// nominal level), metres.
    pub min_growth_m: f64,
}

/// Calibrates the nominal level and the least growth on the fault-free run `dir`: the
/// `1 − budget` quantile of its |UWB − RTK| samples, then of the largest growth any cause gets
/// in each of its judged segments with that nominal level and no least growth.
pub fn calibrate(
    dir: &Path,
    scenario: Option<&Scenario>,
    budget: f64,
) -> Result<Calibration, ReportError> {
    let data = read_campaign(dir)?;
    if data.tests.iter().any(|t| {
        t.case
            .commands
            .iter()
            .any(|c| matches!(c, CommandRecord::AddFault { .. }))
    }) {
        return Err(invalid(
            dir,
            "the run has fault commands: calibrate on a fault-free run (drivecheck run --no-faults)",
        ));
    }
    let mut errors: Vec<f64> = data
        .tests
        .iter()
        .filter_map(|t| t.track.as_ref())
        .flat_map(|track| track.samples.iter().filter_map(|s| s.deviation_m))
        .collect();
    if errors.is_empty() {
        return Err(invalid(dir, "the recording has no samples to calibrate on"));
    }
    errors.sort_by(f64::total_cmp);
    let nominal_m = quantile(&errors, 1.0 - budget);
    let options = ExplainOptions {
        all_segments: true,
        config: ExplainConfig {
            nominal_m,
            min_growth_m: 0.0,
            ..ExplainConfig::default()
        },
    };
    let explained = explain_run(dir, None, scenario, &options)?;
    let mut largest: Vec<f64> = explained
        .cases
        .iter()
        .flat_map(|c| c.segments.iter())
        .map(|s| {
            s.causes
                .iter()
                .filter(|c| c.source != Source::Unexplained)
                .map(|c| c.growth_m)
                .fold(0.0, f64::max)
        })
        .collect();
    largest.sort_by(f64::total_cmp);
    Ok(Calibration {
        samples: errors.len(),
        segments: largest.len(),
        budget,
        nominal_m,
        min_growth_m: if largest.is_empty() {
            0.0
        } else {
            quantile(&largest, 1.0 - budget)
        },
    })
}

/// The nearest-rank `q` quantile of sorted, non-empty `values`.
fn quantile(values: &[f64], q: f64) -> f64 {
    let rank = ((q * values.len() as f64).ceil() as usize).clamp(1, values.len());
    values[rank - 1]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::SimFault;

    /// A case with two wheel-slip faults, ×1.5 (slot 0) and ×3 (slot 1).
    fn two_slips() -> Case {
        let place = |command_index: usize| {
            serde_json::json!({
                "command_index": command_index, "rule": "planned", "segment_index": 0,
                "planned_along_m": 1.0, "sent_s": 1.0, "added_s": 1.0,
                "acts_from_s": 1.0, "acts_to_s": 2.0
            })
        };
        let fault = |param: f64| {
            serde_json::json!({
                "command": "add_fault", "probe": "uwb_travel_dist", "kind": "amplification",
                "param": param, "start": 0, "duration": 100
            })
        };
        let json = serde_json::json!({
            "format": "drivecheck-case", "schema_version": 2, "scenario": {"name": "s"},
            "commands": [fault(1.5), fault(3.0)],
            "fault_places": [place(0), place(1)]
        });
        Case::from_json(&json.to_string()).unwrap()
    }

    fn applied(slots: u8, before: f64) -> SimFault {
        SimFault {
            sim_ms: 0,
            probe: "uwb_travel_dist".to_owned(),
            slots,
            iteration: 0,
            before,
            after: f64::NAN,
        }
    }

    #[test]
    fn a_probe_call_is_shared_among_its_faults_by_each_ones_own_change() {
        let case = two_slips();
        // 10 mm: ×1.5 adds 5 mm, then ×3 adds 30 mm.
        let shares = slot_shares(&case, &applied(0b11, 0.01));
        assert_eq!(shares.len(), 2);
        assert_eq!(shares[0].0, 0);
        assert!((shares[0].1 - 1.0 / 7.0).abs() < 1e-6, "{shares:?}");
        assert!((shares[1].1 - 6.0 / 7.0).abs() < 1e-6, "{shares:?}");
        // One slot alone takes the whole call.
        assert_eq!(slot_shares(&case, &applied(0b10, 0.01)), vec![(1, 1.0)]);
        // Without the value before, the changes cannot be told: equal shares.
        assert_eq!(
            slot_shares(&case, &applied(0b11, f64::NAN)),
            vec![(0, 0.5), (1, 0.5)]
        );
    }

    fn scored(named: usize, truth: usize) -> Scored {
        Scored {
            case: PathBuf::from("case-000.json"),
            segment_index: 1,
            named: Some(Source::Fault {
                command_index: named,
            }),
            truth: TrueCause::Fault {
                command_index: truth,
            },
            truth_class: "wheel slip".to_owned(),
            right: named == truth,
            moved: vec![
                FaultEffect {
                    command_index: truth,
                    metres: 1.7,
                },
                FaultEffect {
                    command_index: named,
                    metres: 0.4,
                },
            ],
            counterfactual: Vec::new(),
            tied_with: Vec::new(),
        }
    }

    fn drops(pairs: &[(usize, f64)]) -> Vec<FaultEffect> {
        pairs
            .iter()
            .map(|&(command_index, metres)| FaultEffect {
                command_index,
                metres,
            })
            .collect()
    }

    #[test]
    fn the_fault_whose_absence_lowers_the_deviation_most_is_the_truth() {
        let case = two_slips();
        assert!(scored(1, 0).needs_counterfactual());
        // Fault 0 pushed more, but without fault 1 the segment came out 1.4 m lower.
        let mut s = scored(1, 0);
        settle_by_counterfactual(&mut s, &case, drops(&[(0, 0.9), (1, 1.4)]));
        assert_eq!(s.truth, TrueCause::Fault { command_index: 1 });
        assert!(s.right);
        assert_eq!(s.counterfactual[0].command_index, 1);
        assert!(s.tied_with.is_empty());
        // Without either it comes out the same: each was needed, naming either is right.
        let mut s = scored(1, 0);
        settle_by_counterfactual(&mut s, &case, drops(&[(0, 0.65), (1, 0.64)]));
        assert_eq!(s.truth, TrueCause::Fault { command_index: 0 });
        assert_eq!(s.tied_with, [1]);
        assert!(s.right);
        // Neither's absence changes it: not settled, the push's truth stays.
        let mut s = scored(1, 0);
        settle_by_counterfactual(&mut s, &case, drops(&[(0, 0.0), (1, 0.01)]));
        assert_eq!(s.truth, TrueCause::Fault { command_index: 0 });
        assert!(!s.right);
        assert_eq!(s.counterfactual.len(), 2);
    }
}
