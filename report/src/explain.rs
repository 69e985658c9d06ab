//! The explanations of a run directory's tests (`drivecheck explain`): each test's samples from
//! the recording, its segments' times located on its route (as the report's plot finds them),
//! its faults' estimated windows and the scenario's anchors, handed to `campaign::explain`. For
//! `--score` and `--calibrate` it reads what the policies in `campaign::explain::score` and
//! `campaign::explain::calibrate` need (the simulator's truth, the deviations) and hands it to
//! them.

use std::path::{Path, PathBuf};

use scenarios::Scenario;
use serde::{Deserialize, Serialize};

use super::ReportError;
use super::data::{
    TRACK_TOPICS, TestData, Track, Tracks, each_test, read_campaign, read_record, scenario_for,
};
use super::route::boundaries;
use campaign::case::{Case, CommandRecord, SegmentResult};
use campaign::explain::calibrate::{Calibration, CalibrationError};
use campaign::explain::score::{
    AppliedFault, RangeTruth, SegmentScore, SimTruth, TRUTH_SLACK_S, score_segments,
};
use campaign::explain::{
    ExplainAnchor, ExplainConfig, ExplainFault, ExplainSample, ExplainSegment, SegmentExplanation,
    Source, explain_segment,
};
use campaign::files::SegmentExplanationRecord;
use campaign::oracle::SegmentVerdict;
use recording::{Held, Recording};

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
    let wanted = only.and_then(|p| p.file_name()).and_then(|n| n.to_str());
    let mut cases = Vec::new();
    let mut not_explained: Vec<(usize, String, NotExplained)> = Vec::new();
    let mut found = false;
    // A test at a time: its case and samples are dropped once it is explained.
    let read = each_test(
        dir,
        scenario,
        |_, file| wanted.is_none_or(|w| w == file),
        |test, scenario| {
            found = true;
            let Some(scenario) = scenario else {
                return Ok(());
            };
            match explain_test(dir, &test, scenario, options) {
                Ok(explained) => cases.push(explained),
                Err(why) => not_explained.push((test.index, test.file.clone(), why)),
            }
            Ok(())
        },
    )?;
    let mut notes = read.notes;
    if read.scenario.is_none() {
        notes.push("no scenario: the anchors and the route are unknown".to_owned());
        return Ok(Explanations {
            cases: Vec::new(),
            notes,
        });
    }
    cases.sort_by_key(|c| c.test_index);
    not_explained.sort_by_key(|(index, _, _)| *index);
    notes.extend(not_explained_notes(&not_explained));
    if let Some(w) = wanted
        && !found
    {
        notes.push(format!("{w} is not a case file of {}", dir.display()));
    }
    Ok(Explanations { cases, notes })
}

/// Most tests named in a note before the rest are counted.
const NAMED_TESTS: usize = 3;

/// A note per test that could not be explained; one for all the tests without samples when
/// there are more than [`NAMED_TESTS`] (`explain --all` on a run recorded with `--record failing`
/// would otherwise print a line per passing test).
fn not_explained_notes(not_explained: &[(usize, String, NotExplained)]) -> Vec<String> {
    let no_samples: Vec<&str> = not_explained
        .iter()
        .filter(|(_, _, why)| *why == NotExplained::NoSamples)
        .map(|(_, file, _)| file.as_str())
        .collect();
    let summed = no_samples.len() > NAMED_TESTS;
    let mut notes: Vec<String> = not_explained
        .iter()
        .filter(|(_, _, why)| !(summed && *why == NotExplained::NoSamples))
        .map(|(_, file, why)| format!("{file}: {why}"))
        .collect();
    if summed {
        let named = no_samples[..NAMED_TESTS].join(", ");
        let more = no_samples.len() - NAMED_TESTS;
        notes.push(format!(
            "{} tests have no samples in the recording (recorded with --record failing or none, \
             or cut short): {named} and {more} more",
            no_samples.len()
        ));
    }
    notes
}

fn explain_test(
    dir: &Path,
    test: &TestData,
    scenario: &Scenario,
    options: &ExplainOptions,
) -> Result<CaseExplanation, NotExplained> {
    Ok(CaseExplanation {
        case: dir.join(&test.file),
        test_index: test.index,
        segments: explain_segments(&test.case, test.track.as_ref(), scenario, options)?,
    })
}

/// The failing segments of test `test_index` (`case`) explained from its messages as the worker
/// that ran it holds them (`held`, before they are written to the recording), as its case file
/// keeps them: what `drivecheck explain` finds in the recording, without reading it back (`run`
/// gives it to the runner, [`runner::ExplainHeld`]). `None` when the messages hold no
/// samples of the test.
pub fn explain_held(
    held: &[Held],
    test_index: usize,
    case: &Case,
    scenario: &Scenario,
) -> Option<Vec<SegmentExplanationRecord>> {
    // Only what the track is made of: a test's other messages (the simulator's truth and
    // ranges, …) are most of them.
    let recording = Recording::from_held(
        held.iter()
            .filter(|m| TRACK_TOPICS.contains(&m.topic()))
            .cloned()
            .collect(),
    );
    let track = Tracks::split(&recording).ok()?.track(test_index);
    let segments =
        explain_segments(case, track.as_ref(), scenario, &ExplainOptions::default()).ok()?;
    Some(segments.iter().map(Into::into).collect())
}

/// The explained segments of one test (the failing ones; every judged one with
/// `options.all_segments`); an error when the recording has no samples of it.
pub fn explain_segments(
    case: &Case,
    track: Option<&Track>,
    scenario: &Scenario,
    options: &ExplainOptions,
) -> Result<Vec<SegmentExplanation>, NotExplained> {
    let wanted = |result: &&SegmentResult| {
        options.all_segments || result.oracle.verdict == SegmentVerdict::Failed
    };
    // A test with nothing to explain needs no samples: `--record failing` records none of a
    // passing test.
    if !case.segments.iter().any(|r| wanted(&r)) {
        return Ok(Vec::new());
    }
    let track = track.ok_or(NotExplained::NoSamples)?;
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
    for result in case.segments.iter().filter(wanted) {
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
            failed: result.oracle.verdict == SegmentVerdict::Failed,
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

/// One test of a run as `calibrate` compares it: its case, its UWB − RTK error samples (from the
/// recording's state samples: what a car reports) and the time spans of its start route and its
/// judged segments.
#[derive(Debug, Clone)]
pub struct TestErrors {
    /// The case.
    pub case: Case,
    /// The case file's name.
    pub file: String,
    /// The error samples.
    pub samples: Vec<campaign::calibrate::ErrorSample>,
    /// The judged segments' spans.
    pub spans: Vec<campaign::calibrate::SegmentSpan>,
}

/// The tests of run directory `dir` in `scenario` with their error samples and segment spans
/// (tests the recording has no samples of are left out). Reads the case files and the
/// recording's `/tests`, `/commands`, `/acks` and `/car/state`, never the simulator's truth.
pub fn error_series(dir: &Path, scenario: &Scenario) -> Result<Vec<TestErrors>, ReportError> {
    let data = read_campaign(dir)?;
    let mut tests = Vec::new();
    for test in data.tests {
        let Some(track) = &test.track else {
            continue;
        };
        let bounds = boundaries(scenario, &test.case, &track.samples);
        let at = |label: &str| bounds.iter().find(|b| b.label == label).map(|b| b.t_s);
        // The start route (from the first sample to the first segment), then every judged
        // segment.
        let start_route = track
            .samples
            .iter()
            .find(|s| s.t_s >= 0.0)
            .zip(at("s0"))
            .map(|(first, to_s)| campaign::calibrate::SegmentSpan {
                segment_index: campaign::calibrate::START_ROUTE,
                from_s: first.t_s,
                to_s,
            });
        let spans = start_route
            .into_iter()
            .chain(
                test.case
                    .segments
                    .iter()
                    .filter(|s| s.oracle.verdict != SegmentVerdict::NoSamples)
                    .filter_map(|s| {
                        let k = s.segment_index;
                        let from_s = at(&format!("s{k}"))?;
                        let to_s = at(&format!("s{}", k + 1)).or_else(|| at("end"))?;
                        Some(campaign::calibrate::SegmentSpan {
                            segment_index: k,
                            from_s,
                            to_s,
                        })
                    }),
            )
            .collect();
        // Where no fault acts yet: the car's own errors, undisturbed. (With every stretch after
        // a fault too, on car F of `drivecheck-dev bench twin-reach` the car's own profile's rms
        // misfit rose from 0.10 to 0.16-0.17 m and the fit put the odometry scale and the yaw
        // bias far from the truth and called them identified; docs/twin.md.)
        let first_fault_s = test
            .case
            .fault_places
            .iter()
            .map(|p| p.acts_from_s)
            .fold(f64::INFINITY, f64::min);
        let samples = track
            .samples
            .iter()
            .filter(|s| s.t_s < first_fault_s)
            .map(|s| campaign::calibrate::ErrorSample {
                t_s: s.t_s,
                east_m: s.uwb.x - s.rtk.x,
                north_m: s.uwb.y - s.rtk.y,
            })
            .collect();
        tests.push(TestErrors {
            case: test.case,
            file: test.file,
            samples,
            spans,
        });
    }
    Ok(tests)
}

/// The case's faults with their estimated windows (faults the car confirmed).
pub fn faults_of(case: &Case) -> Vec<ExplainFault> {
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

/// The number of the fault of command `command_index` in its test (1, 2, …, in the order of
/// the faults' places): the number the report's map, plot and fault key give it, and every
/// cause in words.
pub fn fault_number(case: &Case, command_index: usize) -> Option<usize> {
    case.fault_places
        .iter()
        .position(|p| p.command_index == command_index)
        .map(|k| k + 1)
}

/// A cause in words: a fault with its command (what `drivecheck explain` and `run` print).
pub fn describe(source: &Source, case: Option<&Case>) -> String {
    match source {
        Source::Fault { command_index } => {
            let what = case
                .and_then(|c| c.commands.get(*command_index))
                .and_then(|c| match c {
                    CommandRecord::AddFault {
                        probe, kind, param, ..
                    } => Some(format!("{probe} {kind} {param:.2}")),
                    CommandRecord::RunSegments { .. } => None,
                });
            // Numbered as the report's map, plot and fault key number it (1, 2, … in the
            // order of the faults' places); the command index is the case file's.
            match (case.and_then(|c| fault_number(c, *command_index)), what) {
                (Some(number), Some(what)) => {
                    format!("fault {number} (command {command_index}: {what})")
                }
                (Some(number), None) => format!("fault {number} (command {command_index})"),
                (None, Some(what)) => format!("fault: command {command_index} ({what})"),
                (None, None) => format!("fault: command {command_index}"),
            }
        }
        Source::Anchor { anchor_id } => format!("anchor {anchor_id}'s range"),
        Source::Odometry => "odometry (travelled distance)".to_owned(),
        Source::Heading => "heading (yaw)".to_owned(),
        Source::Unexplained => "unexplained".to_owned(),
    }
}

/// One failing segment of a case file, scored ([`SegmentScore`]: what the explanation named
/// first, the truth, whether it is right).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scored {
    /// The case file.
    pub case: PathBuf,
    /// The score.
    #[serde(flatten)]
    pub score: SegmentScore,
}

/// The truth of each failing segment of a simulated run, next to its explanation
/// ([`campaign::explain::score`], from the recording's `/sim/faults` and `/sim/ranges` and the
/// simulated car's fault model); and the scenario the run was recorded in (its recording's copy,
/// else the bundled one, else `scenario`), in which its cases can be driven again.
///
/// The recording is read a test at a time ([`Spans`](recording::Spans)): a test's truth
/// is its span's, with what the spans before it recorded in the last [`TRUTH_SLACK_S`] before
/// its start (a segment's truth is looked for from that long before the segment, and a test's
/// segments start in its span). A recording without test spans is one span, every test's.
pub fn score_run(
    dir: &Path,
    scenario: Option<&Scenario>,
    options: &ExplainOptions,
) -> Result<(Explanations, Vec<Scored>, Option<Scenario>), ReportError> {
    use recording::{Recording, SimFault, SimRange, Spans, Stamped, TruthRecord};
    let explanations = explain_run(dir, None, scenario, options)?;
    let record = read_record(dir)?;
    crate::data::check_recording(dir)?;
    let path = dir.join(runner::RECORDING_FILE);
    let read = |e: recording::RecordingError| invalid(&path, e);
    let slack_ns = (TRUTH_SLACK_S * 1e9) as u64;
    // Each case's scores, in the order of `explanations.cases`.
    let mut scores: Vec<Option<Vec<Scored>>> = vec![None; explanations.cases.len()];
    let mut truth = false;
    let mut faults: Vec<Stamped<SimFault>> = Vec::new();
    let mut ranges: Vec<Stamped<SimRange>> = Vec::new();
    let mut read_any = false;
    let mut spans = Spans::open(&path).map_err(read)?;
    for span in spans.by_ref() {
        let span = match span {
            Ok(span) => span,
            // A recording cut short is scored up to the damage, as far as it holds tests.
            Err(_) if read_any => break,
            Err(e) => return Err(read(e)),
        };
        read_any = true;
        // What the spans before recorded within the slack of this one's start stays.
        let from_ns = span.start_ns.saturating_sub(slack_ns);
        faults.retain(|f| f.log_time_ns >= from_ns);
        ranges.retain(|r| r.log_time_ns >= from_ns);
        let test_index = span.test_index;
        if let Some(test) = test_index {
            runner::pause_at("score", test);
        }
        let recording = Recording::from_held(span.messages);
        truth |= !recording
            .messages::<TruthRecord>()
            .map_err(read)?
            .is_empty();
        faults.extend(recording.messages::<SimFault>().map_err(read)?);
        ranges.extend(recording.messages::<SimRange>().map_err(read)?);
        let mut tracks = None;
        for (case, scored) in explanations.cases.iter().zip(scores.iter_mut()) {
            if scored.is_some() || test_index.is_some_and(|t| t != case.test_index) {
                continue;
            }
            let tracks = match &mut tracks {
                Some(tracks) => tracks,
                None => tracks.insert(Tracks::split(&recording).map_err(read)?),
            };
            let Some(track) = tracks.track(case.test_index) else {
                continue;
            };
            // The case is read when its span comes, and dropped with it.
            let text = std::fs::read_to_string(&case.case).map_err(|error| ReportError::Read {
                path: case.case.clone(),
                error,
            })?;
            let on_disk = Case::from_json(&text).map_err(|e| invalid(&case.case, e))?;
            *scored = Some(score_case(case, &on_disk, &track, &faults, &ranges));
        }
    }
    let recorded_scenario = spans
        .metadata("drivecheck.scenario")
        .and_then(|m| m.get("toml"))
        .cloned();
    if !truth {
        return Err(invalid(
            &path,
            "the recording has no simulator truth (/sim/truth): only a simulated run can be \
             scored",
        ));
    }
    let scored = scores.into_iter().flatten().flatten().collect();
    let (scenario, _) = scenario_for(
        &record.scenario.name,
        record.scenario.hash.as_deref(),
        scenario,
        recorded_scenario.as_deref(),
    );
    Ok((explanations, scored, scenario))
}

/// The scores of `case`'s failing segments against the simulator's `faults` and `ranges`
/// around its test (see [`score_run`]).
fn score_case(
    case: &CaseExplanation,
    on_disk: &Case,
    track: &Track,
    faults: &[recording::Stamped<recording::SimFault>],
    ranges: &[recording::Stamped<recording::SimRange>],
) -> Vec<Scored> {
    use recording::{RadioPathKind, SimRange};
    // The simulator's truth on the test's clock.
    let t_of = |log_ns: u64| (log_ns as f64 - track.zero_ns as f64) / 1e9;
    let applied: Vec<AppliedFault<'_>> = faults
        .iter()
        .map(|f| AppliedFault {
            t_s: t_of(f.log_time_ns),
            probe: &f.message.probe,
            slots: f.message.slots,
            before: f.message.before,
            after: f.message.after,
        })
        .collect();
    let ranged: Vec<RangeTruth> = ranges
        .iter()
        .filter_map(|r| match &r.message {
            SimRange::Request {
                anchor,
                path: Some(p),
                true_range_m: Some(true_range_m),
                range_m: Some(range_m),
                ..
            } => Some(RangeTruth {
                t_s: t_of(r.log_time_ns),
                anchor_id: u16::from(*anchor),
                reflected: p.kind == RadioPathKind::Reflected,
                range_m: *range_m,
                true_range_m: *true_range_m,
            }),
            _ => None,
        })
        .collect();
    let truth = SimTruth {
        faults: &applied,
        ranges: &ranged,
    };
    score_segments(&case.segments, on_disk, &truth)
        .into_iter()
        .map(|score| Scored {
            case: case.case.clone(),
            score,
        })
        .collect()
}

fn invalid(path: &Path, error: impl std::fmt::Display) -> ReportError {
    ReportError::Invalid {
        path: path.to_owned(),
        message: error.to_string(),
    }
}

/// Calibrates the nominal level and the least growth on the fault-free run `dir`
/// ([`campaign::explain::calibrate`]): its samples' deviations, and its judged segments explained
/// with the configuration the calibration asks for.
pub fn calibrate(
    dir: &Path,
    scenario: Option<&Scenario>,
    budget: f64,
) -> Result<Calibration, ReportError> {
    let data = read_campaign(dir)?;
    let deviations = data
        .tests
        .iter()
        .filter_map(|t| t.track.as_ref())
        .flat_map(|track| track.samples.iter().filter_map(|s| s.deviation_m));
    let explain = |config: &ExplainConfig| {
        let options = ExplainOptions {
            all_segments: true,
            config: *config,
        };
        let explained = explain_run(dir, None, scenario, &options)?;
        Ok::<_, ReportError>(
            explained
                .cases
                .into_iter()
                .flat_map(|c| c.segments)
                .collect(),
        )
    };
    campaign::explain::calibrate::calibrate(
        data.tests.iter().map(|t| &t.case),
        deviations,
        budget,
        explain,
    )
    .map_err(|error| match error {
        CalibrationError::Explain(error) => error,
        refused => invalid(dir, refused),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn missing(indices: std::ops::Range<usize>) -> Vec<(usize, String, NotExplained)> {
        indices
            .map(|i| (i, format!("case-{i:03}.json"), NotExplained::NoSamples))
            .collect()
    }

    #[test]
    fn a_few_tests_without_samples_get_a_note_each_and_many_one_note() {
        assert_eq!(
            not_explained_notes(&missing(1..3)),
            [
                "case-001.json: the recording has no samples of this test",
                "case-002.json: the recording has no samples of this test"
            ]
        );
        assert_eq!(
            not_explained_notes(&missing(0..582)),
            [
                "582 tests have no samples in the recording (recorded with --record failing or \
              none, or cut short): case-000.json, case-001.json, case-002.json and 579 more"
            ]
        );
        assert!(not_explained_notes(&[]).is_empty());
    }
}
