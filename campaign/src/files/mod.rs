//! The files drivecheck writes as JSON, in one place: every format's name, schema version and
//! record types, the one [`Header`] they start with and the one check of it.
//!
//! | file | `format` | record type | written | read | bump when |
//! |---|---|---|---|---|---|
//! | `case-NNN.json`, `minimal.json` | `drivecheck-case` | [`Case`] | [`CASE_SCHEMA_VERSION`] 3 | 1, 2, 3 | a field of a case or of its settings is removed, renamed or changes meaning |
//! | `campaign.json` | `drivecheck-campaign` | [`CampaignRecord`] | [`CAMPAIGN_SCHEMA_VERSION`] 2 | 1, 2 | a field of the record, its settings or its summary is removed, renamed or changes meaning |
//! | `replay.json` | `drivecheck-replay` | [`Comparison`] | [`REPLAY_SCHEMA_VERSION`] 1 | 1 | a field of the comparison changes |
//! | `shrink.json` | `drivecheck-shrink` | [`crate::shrink::ShrinkReport`] | [`SHRINK_SCHEMA_VERSION`] 1 | 1 | a field of the report changes |
//! | `twin.json` | `drivecheck-twin` | [`TwinCheck`] | [`TWIN_SCHEMA_VERSION`] 1 | 1 | a field of the check changes |
//! | `sweep.json` | `drivecheck-sweep` | [`crate::sweep::SweepReport`] | [`SWEEP_SCHEMA_VERSION`] 1 | not read back | a field of the report changes |
//!
//! (The recording, `campaign.mcap`, is the orchestrator's: `orchestrator::recording`.)
//!
//! **The records are the file formats.** They hold plain data and types of the files' own
//! vocabulary (the firmware's probe and fault kind names, the scenario's `{min, max}` ranges, the
//! oracle's outcome and the verdict, the safety monitor's abort), never a configuration type of
//! the core: the safety monitor's and the streaming rule's constants, a fault's placement, a
//! streaming append and the coverage statistics are converted at this edge
//! ([`SafetyConfigRecord`], [`StreamingConfigRecord`], [`FaultPlacementRecord`],
//! [`AppendRecord`], [`CoverageRecord`], [`SegmentExplanationRecord`]), so changing an internal type does not change a file.
//! The modules that compute from cases (`drive`, `coverage`, `explain`, `replay`, `shrink`, `sweep`) use
//! this module; it uses none of them (the conversions from their types are beside them).
//!
//! Every record begins with the [`Header`], flattened: `format`, `schema_version`,
//! `tool_version`. Reading ([`parse`] then [`check_header`]) names the offending field on a parse
//! error, refuses another format and a version this build does not read. Bump a format's schema
//! version when a field is removed, renamed or changes meaning, or when a reader of the old
//! version would misread the new file; an added optional field does not need one. Keep reading
//! the old version (list it in the format's readable versions).
//!
//! Versions: case 2 gave every fault its place on the route; case 3 and campaign record 2 give
//! every fault section of the settings whole ([`FaultRanges`]) where the older versions kept
//! flat ranges ([`FlatFaultRanges`]: the offset range of anchor faults only, no set_to or bitflip
//! range). [`FaultRangesForm`] reads both, and a file's form must be its version's.
//!
//! The case format is documented field by field in `docs/case-format.md`.

use scenarios::Scenario;
use serde::{Deserialize, Serialize};
use thiserror::Error;
use trajgen::GenerationError;

use crate::model::ModelError;

mod campaign;
mod case;
mod explanation;
mod replay;
mod settings;
mod twin;

pub use campaign::{
    CampaignRecord, CampaignSummary, CarRun, CasesFrom, CoverageRecord, FaultCoverageRecord,
    ReplayOf, Session,
};
pub use case::{
    AppendRecord, Case, CommandRecord, FaultPlacementRecord, IntentRecord, PlaceRecord,
    PlaceRuleRecord, PointRecord, RoutePointRecord, SegmentResult, StreamingRecord, TestTiming,
};
pub use explanation::{CauseRecord, SegmentExplanationRecord, SourceRecord};
pub use replay::{
    Comparison, Drove, ReplayRun, Reproduction, SegmentComparison, SegmentDifference,
};
pub use settings::{
    FaultRanges, FaultRangesForm, FlatFaultRanges, ProbeFaultsRecord, SafetyConfigRecord, Settings,
    StreamingConfigRecord, Weights,
};
pub use twin::{TwinCheck, TwinProfileResult, TwinRepeat, TwinSegment, TwinSummary};

#[cfg(test)]
pub(crate) use case::tests;

/// The `format` of a case file.
pub const CASE_FORMAT: &str = "drivecheck-case";
/// The schema version of case files this build writes: 3 records every fault section of the
/// settings whole. Versions 1 and 2 are still read (their settings hold the flat fault ranges;
/// version 1's faults have no place).
pub const CASE_SCHEMA_VERSION: u32 = 3;
/// The case schema versions this build reads.
pub const CASE_READABLE: &[u32] = &[1, 2, 3];
/// The first case schema version whose faults have a place on the route.
pub const CASE_FAULT_PLACES_SINCE: u32 = 2;
/// The first case schema version whose settings hold the fault sections whole.
pub const CASE_FAULT_SECTIONS_SINCE: u32 = 3;

/// The `format` of a campaign record (`campaign.json`).
pub const CAMPAIGN_FORMAT: &str = "drivecheck-campaign";
/// The schema version of campaign records this build writes: 2 records every fault section of
/// the settings whole. Version 1 (the flat fault ranges) is still read.
pub const CAMPAIGN_SCHEMA_VERSION: u32 = 2;
/// The campaign record schema versions this build reads.
pub const CAMPAIGN_READABLE: &[u32] = &[1, 2];
/// The first campaign record schema version whose settings hold the fault sections whole.
pub const CAMPAIGN_FAULT_SECTIONS_SINCE: u32 = 2;

/// The `format` of a replay comparison (`replay.json`).
pub const REPLAY_FORMAT: &str = "drivecheck-replay";
/// The schema version of replay comparisons this build writes.
pub const REPLAY_SCHEMA_VERSION: u32 = 1;
/// The replay comparison schema versions this build reads.
pub const REPLAY_READABLE: &[u32] = &[1];

/// The `format` of a twin check (`twin.json`).
pub const TWIN_FORMAT: &str = "drivecheck-twin";
/// The schema version of twin checks this build writes.
pub const TWIN_SCHEMA_VERSION: u32 = 1;
/// The twin check schema versions this build reads.
pub const TWIN_READABLE: &[u32] = &[1];

/// The `format` of a shrink report (`shrink.json`).
pub const SHRINK_FORMAT: &str = "drivecheck-shrink";
/// The schema version of shrink reports this build writes.
pub const SHRINK_SCHEMA_VERSION: u32 = 1;
/// The shrink report schema versions this build reads (the report reads `shrink.json`).
pub const SHRINK_READABLE: &[u32] = &[1];

/// The `format` of a sweep result (`sweep.json`).
pub const SWEEP_FORMAT: &str = "drivecheck-sweep";
/// The schema version of sweep results this build writes.
pub const SWEEP_SCHEMA_VERSION: u32 = 1;

/// What every file begins with, flattened into its record: which format, which version of it,
/// and which drivecheck wrote it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    /// The format's name (`drivecheck-case`, …).
    pub format: String,
    /// The format's schema version.
    pub schema_version: u32,
    /// The drivecheck version that wrote it (absent in a hand-written case and in a replay
    /// comparison).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool_version: Option<String>,
}

impl Header {
    /// The header this build writes for `format` at `schema_version`, with its tool version.
    pub fn current(format: &str, schema_version: u32) -> Self {
        Self {
            format: format.to_owned(),
            schema_version,
            tool_version: Some(tool_version().to_owned()),
        }
    }

    /// The header for `format` at `schema_version` without a tool version.
    pub fn untooled(format: &str, schema_version: u32) -> Self {
        Self {
            format: format.to_owned(),
            schema_version,
            tool_version: None,
        }
    }

    /// The tool version, or `unknown` when the file does not say.
    pub fn tool(&self) -> &str {
        self.tool_version.as_deref().unwrap_or("unknown")
    }
}

/// Why a file (a case, a campaign record, a comparison) was refused.
#[derive(Debug, Error)]
pub enum CaseError {
    /// Not JSON of the expected shape; `path` names the field.
    #[error("{path}: {message}")]
    Parse {
        /// Where in the document (for example `commands[3].points[0].speed`).
        path: String,
        /// What serde said.
        message: String,
    },
    /// The `format` field names another kind of file.
    #[error("format is `{found}`, expected `{expected}`")]
    WrongFormat {
        /// What the file says.
        found: String,
        /// What was expected.
        expected: &'static str,
    },
    /// Written by a newer drivecheck (or an unknown version).
    #[error("schema_version {found} is not supported (this drivecheck reads {supported})")]
    UnsupportedVersion {
        /// What the file says.
        found: u32,
        /// What this build reads, in words.
        supported: String,
    },
    /// A value is unusable; `path` names it.
    #[error("{path}: {message}")]
    Invalid {
        /// Where in the document.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// A segment does not continue the route drivably in the scenario.
    #[error("commands[{command}]: not drivable in the scenario: {violation}")]
    NotDrivable {
        /// The command's index.
        command: usize,
        /// The first violation `trajgen::check_route` found.
        violation: trajgen::Violation,
    },
    /// No ahead margin can follow a segment that has none: the car could not be stopped safely
    /// inside the area after it.
    #[error(
        "commands[{command}]: no ahead margin can follow this segment, so the car could not be \
         stopped safely inside the area after it: {error}"
    )]
    NoAheadMargin {
        /// The command's index.
        command: usize,
        /// Why the generator failed.
        error: GenerationError,
    },
    /// The scenario's start route, where a case's first segment starts, cannot be continued
    /// ([`crate::model::start_tail`]'s error).
    #[error("scenario.start_route: {0}")]
    StartRoute(#[source] Box<ModelError>),
    /// Writing JSON failed.
    #[error("cannot write JSON: {0}")]
    Write(#[source] serde_json::Error),
}

/// The start tail's error ([`crate::model::start_tail`]), the one model error a case meets.
impl From<ModelError> for CaseError {
    fn from(error: ModelError) -> Self {
        Self::StartRoute(Box::new(error))
    }
}

pub(crate) fn invalid(path: impl Into<String>, message: impl Into<String>) -> CaseError {
    CaseError::Invalid {
        path: path.into(),
        message: message.into(),
    }
}

/// The scenario a case or campaign ran in.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioRef {
    /// The scenario's name.
    pub name: String,
    /// Its content hash (`Scenario::hash`, lowercase hex SHA-256 of the canonical TOML); absent
    /// in a hand-written case, which replay then runs only when told to.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hash: Option<String>,
}

impl ScenarioRef {
    /// The reference to `scenario`, with its hash.
    pub fn of(scenario: &Scenario) -> Self {
        Self {
            name: scenario.name.clone(),
            hash: Some(scenario.hash()),
        }
    }
}

/// The car profile a simulated car was (`--profile`, `docs/twin.md`): what a campaign, and
/// each of its cases, was driven on when the car was the embedded simulator.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CarProfileRef {
    /// `default` (the bundled car) or the profile file as given.
    pub name: String,
    /// Its content hash (`car_sim::CarProfile::hash`: lowercase hex SHA-256 of the canonical
    /// TOML).
    pub hash: String,
}

/// The version of drivecheck recorded in every file it writes.
pub fn tool_version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

/// Reads a record of type `T` from JSON, naming the offending field on an error.
pub fn parse<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, CaseError> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| CaseError::Parse {
        path: e.path().to_string(),
        message: e.inner().to_string(),
    })
}

/// Checks a file's header: its format is `expected` and its version one of `readable`.
pub fn check_header(
    header: &Header,
    expected: &'static str,
    readable: &[u32],
) -> Result<(), CaseError> {
    if header.format != expected {
        return Err(CaseError::WrongFormat {
            found: header.format.clone(),
            expected,
        });
    }
    if !readable.contains(&header.schema_version) {
        let words: Vec<String> = readable.iter().map(u32::to_string).collect();
        let supported = match words.split_last() {
            Some((last, [])) => last.clone(),
            Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
            None => "none".to_owned(),
        };
        return Err(CaseError::UnsupportedVersion {
            found: header.schema_version,
            supported,
        });
    }
    Ok(())
}

/// A record as pretty-printed JSON (how every file is written).
pub fn to_json<T: Serialize>(record: &T) -> Result<String, CaseError> {
    serde_json::to_string_pretty(record).map_err(CaseError::Write)
}
