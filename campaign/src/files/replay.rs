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
    /// The seed it ran with (the simulator's and the reset's).
    pub seed: u64,
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
