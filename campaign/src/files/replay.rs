//! Replay comparisons (`replay.json`): a recorded case driven again N times, per segment each
//! run's maximum deviation (computed by `crate::replay`).

use serde::{Deserialize, Serialize};

use super::{
    CaseError, Header, REPLAY_FORMAT, REPLAY_READABLE, ReplayOf, ScenarioRef, check_header, parse,
};
use crate::oracle::Verdict;

/// One run of a replay.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayRun {
    /// Its run directory, relative to the replay directory (`run-1`, …).
    pub dir: String,
    /// The campaign seed it ran with: its reset's and safe stop's (and, without
    /// `simulator_seed`, the simulated car's).
    pub seed: u64,
    /// The simulated car's seed, when it is not `seed` (a case driven as its own test: the
    /// seed map's [`crate::seed::Purpose::Rerun`] of its test; absent on a real car).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulator_seed: Option<u64>,
    /// Its verdict (`None` when it never ran).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
    /// Why it failed or was aborted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// One segment across the runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentComparison {
    /// The segment's index among the test's segments.
    pub segment_index: usize,
    /// The recorded case's maximum deviation for it, metres (when it was driven).
    pub original_max_m: Option<f64>,
    /// Each run's maximum deviation, metres (`None`: not driven or no samples).
    pub max_m: Vec<Option<f64>>,
    /// Mean of the runs' maxima that exist, metres.
    pub mean_m: Option<f64>,
    /// Each run's maximum minus the mean, metres.
    pub diff_from_mean_m: Vec<Option<f64>>,
}

/// What the runs of a replay drove, and so what they can be expected to reproduce.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Drove {
    /// The case's own test: the same simulated car (the seed map's streams of that test of
    /// that campaign seed, the same car profile) from the same start, in virtual time. Every
    /// segment's largest deviation should be the case's to the last digit.
    SameTest,
    /// The case's test on other simulated cars (`--vary-seed`): the spread.
    OtherCars,
    /// The case's test with something changed (`--no-faults`, another `--seed` or car
    /// profile): its figures need not be the case's.
    Altered,
    /// The same simulated car against the wall clock (`--realtime`): the timing differs.
    WallClock,
    /// A real car: the same commands, faults at the same places and the same seeds of the reset
    /// and the safe stop, but not the same sensors, start or link timing.
    RealCar,
    /// A case that names no campaign (written by hand): each run a campaign of its own.
    OwnCampaign,
}

/// A segment whose largest deviation in a run is not the case's (with [`Drove::SameTest`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentDifference {
    /// The segment's index among the test's segments.
    pub segment_index: usize,
    /// The run, from 1 (`run-1`, …).
    pub run: usize,
    /// The case's largest deviation in it, metres (`None`: not driven, or no samples).
    pub original_max_m: Option<f64>,
    /// The run's, metres (`None`: not driven, or no samples).
    pub max_m: Option<f64>,
}

/// Whether runs of the case's own test reproduced it (with [`Drove::SameTest`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Reproduction {
    /// Every run's largest deviation of every segment equals the case's, and its verdict too.
    pub identical: bool,
    /// Every segment of a run whose largest deviation differs from the case's, in order.
    pub differing: Vec<SegmentDifference>,
}

/// The comparison written to `replay.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Comparison {
    /// `drivecheck-replay` and its schema version (no tool version).
    #[serde(flatten)]
    pub header: Header,
    /// The case replayed.
    pub replay_of: ReplayOf,
    /// The scenario it was replayed in.
    pub scenario: ScenarioRef,
    /// Every run, in order.
    pub runs: Vec<ReplayRun>,
    /// Every segment driven by the case or by any run, by index.
    pub segments: Vec<SegmentComparison>,
    /// The largest |difference from the mean| over all segments and runs, metres.
    pub max_abs_diff_m: Option<f64>,
    /// True when every run ended with the same verdict.
    pub same_verdict: bool,
    /// True when every run's verdict equals the recorded case's (`None` for a case never run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub same_as_original: Option<bool>,
    /// For a replay without faults of a case that failed: true when every run passed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failure_disappeared: Option<bool>,
    /// What the runs drove (absent in a file of an earlier drivecheck).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drove: Option<Drove>,
    /// With `drove` [`Drove::SameTest`] and a case that was run: whether the runs reproduced
    /// it, segment by segment.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reproduction: Option<Reproduction>,
}

impl Comparison {
    /// The comparison as pretty-printed JSON.
    pub fn to_json(&self) -> Result<String, CaseError> {
        super::to_json(self)
    }

    /// Reads a comparison from JSON: shape, format name and version.
    pub fn from_json(text: &str) -> Result<Self, CaseError> {
        let comparison: Self = parse(text)?;
        check_header(&comparison.header, REPLAY_FORMAT, REPLAY_READABLE)?;
        Ok(comparison)
    }
}
