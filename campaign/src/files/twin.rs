//! Twin checks (`twin.json`): how far simulated cars of given profiles reproduce a recorded run
//! (computed by `crate::twin`; `docs/twin.md`).

use serde::{Deserialize, Serialize};

use super::{
    CarProfileRef, CaseError, Header, ScenarioRef, TWIN_FORMAT, TWIN_READABLE, check_header, parse,
};

/// One recorded segment against the same segment driven on a simulated car.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TwinSegment {
    /// The case's test index.
    pub test_index: usize,
    /// The segment's index among the test's segments.
    pub segment_index: usize,
    /// The recording's largest deviation, metres.
    pub recorded_max_m: f64,
    /// Whether the recording failed it.
    pub recorded_failed: bool,
    /// Each simulated run's largest deviation, metres (the runs that drove it).
    pub simulated_max_m: Vec<f64>,
    /// Their median, metres.
    pub simulated_median_m: f64,
    /// The runs whose verdict is the recording's.
    pub runs_agreeing: usize,
}

/// The agreement of a simulated car with a recording.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TwinSummary {
    /// Segments compared (judged in the recording and in at least one run).
    pub segments: usize,
    /// (Segment, run) pairs compared.
    pub segment_runs: usize,
    /// The share of those pairs whose verdict is the recording's.
    pub verdicts_agreed: Option<f64>,
    /// Median over segments of |recorded − simulated median| largest deviation, metres.
    pub median_abs_delta_m: Option<f64>,
    /// Its 90th percentile (nearest rank), metres.
    pub p90_abs_delta_m: Option<f64>,
}

/// One profile's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TwinProfileResult {
    /// The profile the cases were driven on.
    pub profile: CarProfileRef,
    /// Its agreement.
    pub summary: TwinSummary,
    /// Per segment.
    pub segments: Vec<TwinSegment>,
}

/// A twin check of a run directory (`twin.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TwinCheck {
    /// `drivecheck-twin`, its schema version, the drivecheck version.
    #[serde(flatten)]
    pub header: Header,
    /// The run directory checked, as given.
    pub run: String,
    /// The car it was recorded on (`campaign.json`'s `car`).
    pub car: String,
    /// Its scenario.
    pub scenario: ScenarioRef,
    /// Cases driven again.
    pub cases: usize,
    /// Simulated runs per case.
    pub runs: u32,
    /// The profile checked first, then the default car for comparison (when it is another).
    pub profiles: Vec<TwinProfileResult>,
    /// The car's own repeatability: the same cases driven again on the car (`--repeat`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeatability: Option<TwinRepeat>,
}

/// The recording against another recording of the same cases on the car.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TwinRepeat {
    /// The other run directory, as given.
    pub run: String,
    /// The agreement of the two recordings (one "run" per segment).
    pub summary: TwinSummary,
}

impl TwinCheck {
    /// The check as pretty-printed JSON.
    pub fn to_json(&self) -> Result<String, CaseError> {
        super::to_json(self)
    }

    /// Reads a check from JSON: shape, format name and version.
    pub fn from_json(text: &str) -> Result<Self, CaseError> {
        let check: Self = parse(text)?;
        check_header(&check.header, TWIN_FORMAT, TWIN_READABLE)?;
        Ok(check)
    }
}
