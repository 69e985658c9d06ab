//! Case files and campaign records: the versioned JSON a run directory holds.
//!
//! A [`Case`] is one test on record: where it came from (campaign seed, test index, scenario name
//! and hash, settings), the concrete command sequence (segment intents and points with speeds,
//! ahead margins, fault parameters), the return route driven before it, the oracle's result per
//! segment with the faults that preceded it, and the verdict with its reason. Replay consumes it
//! (planning a test from it is [`crate::replay`]'s);
//! a person reads it; a person can write one by hand (only `format`, `schema_version`, `scenario`
//! and `commands` are required). A [`CampaignRecord`] (`campaign.json`) describes the campaign.
//! The format is documented field by field in `docs/case-format.md`.
//!
//! Reading checks the format name and version and names the offending field on a parse error;
//! [`Case::check`] checks the values (finite coordinates, positive speeds, counts that agree)
//! and [`Case::check_route`] checks the geometry against a scenario (both in `check.rs`).

use scenarios::{CampaignSettings, Interval, Scenario};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use thiserror::Error;
use trajgen::{GenerationError, Point, Waypoint};

use crate::drive::FaultPlacement;
use crate::model::{
    Command, Fault, FaultKind, FaultPlace, ModelError, Probe, Segment, SegmentIntent, TestPlan,
};
use crate::oracle::{FailurePolicy, SegmentOutcome, Verdict};
use crate::safety::{Abort, SafetyConfig};
use crate::streaming::{Append, StreamingConfig};

mod check;

/// The `format` of a case file.
pub const CASE_FORMAT: &str = "drivecheck-case";
/// The `format` of a campaign record.
pub const CAMPAIGN_FORMAT: &str = "drivecheck-campaign";
/// The schema version of campaign records (`campaign.json`) and replay comparisons this build
/// writes and reads.
pub const SCHEMA_VERSION: u32 = 1;
/// The schema version of case files this build writes: 2 gives every fault its place on the
/// route. Version 1 is still read; its faults have no place.
pub const CASE_SCHEMA_VERSION: u32 = 2;

/// Why a case file or campaign record was refused.
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
        supported: &'static str,
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

/// The settings a campaign ran with: the scenario's campaign settings, the ahead margin and the
/// oracle's failure policy.
///
/// The case format's own spelling of the scenario's [`CampaignSettings`]: flat fault ranges with
/// the firmware's fault kind names, every field required, and what the scenario does not hold
/// (the ahead margin, the failure policy, the runtime constants). Its `{min, max}` ranges are the
/// scenario's [`Interval`]s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Tests in the campaign.
    pub tests: usize,
    /// Commands per test, growing over the campaign.
    pub test_size: Interval<usize>,
    /// Points per `run_segments`.
    pub points_per_segment: Interval<usize>,
    /// Speed of a segment, km/h.
    pub speed_kmh: Interval<f64>,
    /// Points of every segment's ahead margin.
    pub ahead_margin: usize,
    /// Largest allowed deviation of UWB from RTK, metres.
    pub oracle_threshold_m: f64,
    /// What happens after a failing segment.
    pub failure_policy: FailurePolicy,
    /// Command weights.
    pub weights: Weights,
    /// Fault parameter ranges.
    pub faults: FaultRanges,
    /// The safety monitor's limits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyConfig>,
    /// The streaming rule's constants.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub streaming: Option<StreamingConfig>,
}

/// Command weights in a record: the scenario's [`scenarios::CommandWeights`], but a case file
/// must give all four (a scenario file defaults the ones it leaves out).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Weights {
    /// `run_segments`.
    pub run_segments: u32,
    /// `add_fault` on an anchor's range.
    pub anchor_range_fault: u32,
    /// `add_fault` wheel slip.
    pub wheel_slip_fault: u32,
    /// `add_fault` yaw.
    pub yaw_fault: u32,
}

/// Fault parameter ranges in a record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultRanges {
    /// Fault kinds of anchor range faults.
    pub anchor_range_kinds: Vec<FaultKind>,
    /// Anchor range fault parameter.
    pub anchor_range_param: Interval<f64>,
    /// Anchor range fault start, probe iterations.
    pub anchor_range_start: Interval<u32>,
    /// Anchor range fault duration, probe iterations.
    pub anchor_range_duration: Interval<u32>,
    /// Wheel slip amplification.
    pub wheel_slip_amplification: Interval<f64>,
    /// Wheel slip start, probe iterations.
    pub wheel_slip_start: Interval<u32>,
    /// Wheel slip duration, probe iterations.
    pub wheel_slip_duration: Interval<u32>,
    /// Yaw offset, degrees.
    pub yaw_offset_deg: Interval<f64>,
    /// Yaw start, probe iterations.
    pub yaw_start: Interval<u32>,
    /// Yaw duration, probe iterations.
    pub yaw_duration: Interval<u32>,
}

impl Settings {
    /// The settings of a campaign in `scenario` with `tests` tests and `policy`.
    pub fn new(scenario: &Scenario, tests: usize, policy: FailurePolicy) -> Self {
        let c: &CampaignSettings = &scenario.campaign;
        let f = &c.faults;
        Self {
            tests,
            test_size: c.test_size,
            points_per_segment: c.points_per_segment,
            speed_kmh: c.speed_kmh,
            ahead_margin: scenario.generator.ahead_margin,
            oracle_threshold_m: c.oracle_threshold_m,
            failure_policy: policy,
            weights: Weights {
                run_segments: c.weights.run_segments,
                anchor_range_fault: c.weights.anchor_range_fault,
                wheel_slip_fault: c.weights.wheel_slip_fault,
                yaw_fault: c.weights.yaw_fault,
            },
            faults: FaultRanges {
                anchor_range_kinds: f.anchor_range.kinds.clone(),
                anchor_range_param: f.anchor_range.range(FaultKind::Offset),
                anchor_range_start: f.anchor_range.start,
                anchor_range_duration: f.anchor_range.duration,
                wheel_slip_amplification: f.wheel_slip.range(FaultKind::Amplification),
                wheel_slip_start: f.wheel_slip.start,
                wheel_slip_duration: f.wheel_slip.duration,
                yaw_offset_deg: f.yaw.range(FaultKind::Offset),
                yaw_start: f.yaw.start,
                yaw_duration: f.yaw.duration,
            },
            safety: None,
            streaming: None,
        }
    }

    /// These settings with the safety monitor's and the streaming rule's constants.
    pub fn with_runtime(self, safety: SafetyConfig, streaming: StreamingConfig) -> Self {
        Self {
            safety: Some(safety),
            streaming: Some(streaming),
            ..self
        }
    }
}

/// A point of a route with the speed the car drives towards it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RoutePointRecord {
    /// East, metres (local ENU).
    pub x: f64,
    /// North, metres.
    pub y: f64,
    /// Speed towards this point, m/s.
    pub speed: f64,
}

impl RoutePointRecord {
    /// The position.
    pub fn position(&self) -> Point {
        Point::new(self.x, self.y)
    }
}

impl From<Waypoint> for RoutePointRecord {
    fn from(w: Waypoint) -> Self {
        Self {
            x: w.position.x,
            y: w.position.y,
            speed: w.speed,
        }
    }
}

impl From<RoutePointRecord> for Waypoint {
    fn from(p: RoutePointRecord) -> Self {
        Waypoint::new(p.position(), p.speed)
    }
}

/// A position without a speed (ahead margin points are never driven).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PointRecord {
    /// East, metres.
    pub x: f64,
    /// North, metres.
    pub y: f64,
}

impl From<Point> for PointRecord {
    fn from(p: Point) -> Self {
        Self { x: p.x, y: p.y }
    }
}

impl From<PointRecord> for Point {
    fn from(p: PointRecord) -> Self {
        Point::new(p.x, p.y)
    }
}

/// What the generator was asked for (absent in hand-written cases).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct IntentRecord {
    /// The generator's seed.
    pub seed: u64,
    /// Points asked for.
    pub points: usize,
    /// Speed, m/s.
    pub speed_mps: f64,
}

/// One command of a case.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "command", rename_all = "snake_case", deny_unknown_fields)]
pub enum CommandRecord {
    /// Append these points to the car's route and drive them.
    RunSegments {
        /// What the generator was asked for; replay does not need it.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        intent: Option<IntentRecord>,
        /// The points sent to the car, with their speeds.
        points: Vec<RoutePointRecord>,
        /// The ahead margin generated after them (never sent); may be empty in a hand-written
        /// case.
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        margin: Vec<PointRecord>,
    },
    /// Inject a fault: `fi_add_fault probe kind param start duration`.
    AddFault {
        /// The probe id.
        probe: Probe,
        /// The fault type.
        kind: FaultKind,
        /// Its parameter.
        param: f64,
        /// Probe iterations before it applies.
        start: u32,
        /// Probe iterations it applies for.
        duration: u32,
        /// Where on the route it is sent; absent in version-1 cases and in hand-written cases
        /// that leave it to the earlier tool's rule.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        at: Option<PlaceRecord>,
    },
}

/// A fault's place on the route in a case file: `{"segment_index": k, "along_m": d}`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaceRecord {
    /// The segment (among the case's segments, from 0) on which the fault is sent.
    pub segment_index: usize,
    /// Metres along that segment from its start.
    pub along_m: f64,
}

impl From<FaultPlace> for PlaceRecord {
    fn from(p: FaultPlace) -> Self {
        Self {
            segment_index: p.segment_index,
            along_m: p.along_m,
        }
    }
}

impl From<PlaceRecord> for FaultPlace {
    fn from(p: PlaceRecord) -> Self {
        Self {
            segment_index: p.segment_index,
            along_m: p.along_m,
        }
    }
}

impl From<&Command> for CommandRecord {
    fn from(command: &Command) -> Self {
        match command {
            Command::RunSegments(segment) => segment_record(segment),
            Command::AddFault(f) => Self::AddFault {
                probe: f.probe,
                kind: f.kind,
                param: f.param,
                start: f.start,
                duration: f.duration,
                at: f.at.map(PlaceRecord::from),
            },
        }
    }
}

impl From<SegmentIntent> for IntentRecord {
    fn from(i: SegmentIntent) -> Self {
        Self {
            seed: i.seed,
            points: i.points,
            speed_mps: i.speed_mps,
        }
    }
}

impl From<IntentRecord> for SegmentIntent {
    fn from(i: IntentRecord) -> Self {
        Self {
            seed: i.seed,
            points: i.points,
            speed_mps: i.speed_mps,
        }
    }
}

fn segment_record(segment: &Segment) -> CommandRecord {
    CommandRecord::RunSegments {
        intent: segment.intent.map(IntentRecord::from),
        points: segment.waypoints().map(RoutePointRecord::from).collect(),
        margin: segment.margin.iter().map(|&p| p.into()).collect(),
    }
}

impl CommandRecord {
    /// The model's command for this record: a segment with its recorded points and speeds (and
    /// its intent and margin when recorded), or a fault.
    pub fn to_command(&self) -> Command {
        match self {
            Self::AddFault {
                probe,
                kind,
                param,
                start,
                duration,
                at,
            } => Command::AddFault(Fault {
                probe: *probe,
                kind: *kind,
                param: *param,
                start: *start,
                duration: *duration,
                at: at.map(FaultPlace::from),
            }),
            Self::RunSegments {
                intent,
                points,
                margin,
            } => Command::RunSegments(Segment {
                intent: intent.map(SegmentIntent::from),
                points: points.iter().map(RoutePointRecord::position).collect(),
                speeds: points.iter().map(|p| p.speed).collect(),
                margin: margin.iter().map(|&p| p.into()).collect(),
            }),
        }
    }
}

/// The oracle's result for one driven segment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SegmentResult {
    /// The segment's index among the test's segments (from 0).
    pub segment_index: usize,
    /// Its command's index in `commands`.
    pub command_index: usize,
    /// Indices (in `commands`) of the fault commands sent before it.
    pub faults_preceding: Vec<usize>,
    /// Indices of the faults estimated to be applying while it was driven (empty when not
    /// estimated).
    #[serde(default)]
    pub faults_active: Vec<usize>,
    /// The oracle's statistics and verdict.
    pub oracle: SegmentOutcome,
}

/// One test on record (see the module doc and `docs/case-format.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Case {
    /// Always `drivecheck-case`.
    pub format: String,
    /// The schema version (1).
    pub schema_version: u32,
    /// The drivecheck version that wrote it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool_version: Option<String>,
    /// The campaign's seed (absent when written by hand).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub campaign_seed: Option<u64>,
    /// The test's index in its campaign, from 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_index: Option<usize>,
    /// The scenario it ran in.
    pub scenario: ScenarioRef,
    /// The settings it was generated and judged with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settings: Option<Settings>,
    /// True when it ran without fault commands.
    #[serde(default)]
    pub no_faults: bool,
    /// The concrete command sequence.
    pub commands: Vec<CommandRecord>,
    /// The return route driven before the test (from the car's pose to the recovery route).
    #[serde(default)]
    pub return_route: Vec<RoutePointRecord>,
    /// The clearance from every edge the return route keeps, metres, when it is less than the
    /// scenario's `clearance_m` (the car stood inside the clearance band); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub return_clearance_m: Option<f64>,
    /// Per segment driven: the oracle's result.
    #[serde(default)]
    pub segments: Vec<SegmentResult>,
    /// The verdict; absent when the case has not been run (hand-written).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
    /// Why it failed or was aborted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// The stop the safety monitor (or the runner) demanded, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub abort: Option<Abort>,
    /// How the segments were streamed: every append and the starvation events.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub streaming: Option<StreamingRecord>,
    /// Where each fault the car added was meant to act and where it did (version 2).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fault_places: Vec<FaultPlacement>,
    /// How long the reset and the drive took on the runner's clock (simulated time for the
    /// embedded simulated car in virtual time).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timing: Option<TestTiming>,
    /// Why each failing segment failed (`drivecheck explain`, `docs/explain.md`): written by
    /// `drivecheck run` after the campaign, from the recording.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub explanation: Vec<crate::explain::SegmentExplanation>,
}

/// How long a test took, seconds on the runner's clock.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TestTiming {
    /// The reset: the return route and the start route driven.
    pub reset_s: f64,
    /// The test's drive, its safe stop included.
    pub drive_s: f64,
}

/// How a test's segments were streamed to the car.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StreamingRecord {
    /// Every append, in order (times in milliseconds since the test started).
    pub appends: Vec<Append>,
    /// When the car reached the end of its route during the test, milliseconds since the test
    /// started (should be empty).
    pub starvations_ms: Vec<u64>,
    /// The smallest margin left over the confirmed appends, seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub smallest_margin_s: Option<f64>,
}

impl Case {
    /// A not yet run case for `plan`: its commands, where it came from, no results.
    pub fn planned(
        plan: &TestPlan,
        scenario: &Scenario,
        campaign_seed: u64,
        no_faults: bool,
        settings: Settings,
    ) -> Self {
        Self {
            format: CASE_FORMAT.to_owned(),
            schema_version: CASE_SCHEMA_VERSION,
            tool_version: Some(tool_version().to_owned()),
            campaign_seed: Some(campaign_seed),
            test_index: Some(plan.test_index),
            scenario: ScenarioRef::of(scenario),
            settings: Some(settings),
            no_faults,
            commands: plan.commands.iter().map(CommandRecord::from).collect(),
            return_route: Vec::new(),
            return_clearance_m: None,
            segments: Vec::new(),
            verdict: None,
            reason: None,
            abort: None,
            streaming: None,
            fault_places: Vec::new(),
            timing: None,
            explanation: Vec::new(),
        }
    }

    /// Reads a case from JSON: shape, format name and version.
    pub fn from_json(text: &str) -> Result<Self, CaseError> {
        let case: Self = parse(text)?;
        check_header(&case.format, CASE_FORMAT, case.schema_version)?;
        Ok(case)
    }

    /// The case as pretty-printed JSON.
    pub fn to_json(&self) -> Result<String, CaseError> {
        serde_json::to_string_pretty(self).map_err(CaseError::Write)
    }
}

/// What a campaign's run directory says about it (`campaign.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CampaignRecord {
    /// Always `drivecheck-campaign`.
    pub format: String,
    /// The schema version (1).
    pub schema_version: u32,
    /// The drivecheck version that ran it.
    pub tool_version: String,
    /// The one seed every test derives from.
    pub seed: u64,
    /// True when it ran without fault commands.
    pub no_faults: bool,
    /// The scenario.
    pub scenario: ScenarioRef,
    /// The settings.
    pub settings: Settings,
    /// The car it drove (`sim`, `tcp://…`, `udp://…`, `serial://…`).
    pub car: String,
    /// The car's firmware version as it reported it (absent if unknown).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub car_firmware_version: Option<String>,
    /// When it started, RFC 3339 (for example `2026-11-22T10:55:21Z`).
    pub started_at: String,
    /// When it ended, RFC 3339; absent while running or if the process died.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ended_at: Option<String>,
    /// The outcome, once it ended.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub summary: Option<CampaignSummary>,
    /// For a replay (`drivecheck replay`): the case every test drove again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replay_of: Option<ReplayOf>,
    /// For one shard of a campaign (`drivecheck run --shard K/N`): which one. Its run directory
    /// holds the shard's tests only; `drivecheck runs merge` joins the shards.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<crate::shard::Shard>,
}

/// The case a replay drove again.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayOf {
    /// The case file as given on the command line.
    pub case: String,
    /// Its campaign's seed, if recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub campaign_seed: Option<u64>,
    /// Its test index, if recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_index: Option<usize>,
    /// Its verdict, if it was run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
    /// True when the replay left out its fault commands.
    pub no_faults: bool,
}

/// A campaign's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CampaignSummary {
    /// Tests run.
    pub tests: usize,
    /// Tests passed.
    pub passed: usize,
    /// Tests failed.
    pub failed: usize,
    /// Tests aborted.
    pub aborted: usize,
    /// Largest deviation seen in any segment, metres (absent without samples).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_deviation_m: Option<f64>,
    /// Case files of the failed and aborted tests, relative to the run directory.
    pub failing_cases: Vec<String>,
    /// Why the UWB positioning was not tested, when it was not (an area without anchors: the
    /// estimate is dead reckoning only, so a pass says nothing about UWB).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uwb_not_tested: Option<String>,
    /// What the tests covered: the share of the area driven, headings and speeds, fault kinds
    /// per probe (`campaign::coverage`); absent in records of older versions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage: Option<crate::coverage::CoverageStats>,
}

impl CampaignRecord {
    /// Reads a campaign record from JSON: shape, format name and version.
    pub fn from_json(text: &str) -> Result<Self, CaseError> {
        let record: Self = parse(text)?;
        check_header(&record.format, CAMPAIGN_FORMAT, record.schema_version)?;
        Ok(record)
    }

    /// The record as pretty-printed JSON.
    pub fn to_json(&self) -> Result<String, CaseError> {
        serde_json::to_string_pretty(self).map_err(CaseError::Write)
    }
}

/// The version of drivecheck recorded in every file it writes.
pub fn tool_version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

fn parse<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, CaseError> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| CaseError::Parse {
        path: e.path().to_string(),
        message: e.inner().to_string(),
    })
}

fn check_header(format: &str, expected: &'static str, version: u32) -> Result<(), CaseError> {
    if format != expected {
        return Err(CaseError::WrongFormat {
            found: format.to_owned(),
            expected,
        });
    }
    let (known, supported): (&[u32], _) = if expected == CASE_FORMAT {
        (&[1, CASE_SCHEMA_VERSION], "1 and 2")
    } else {
        (&[SCHEMA_VERSION], "1")
    };
    if !known.contains(&version) {
        return Err(CaseError::UnsupportedVersion {
            found: version,
            supported,
        });
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests;
