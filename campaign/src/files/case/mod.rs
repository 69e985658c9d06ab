//! Case files (`case-NNN.json`, a shrink's `minimal.json`): one test on record.
//!
//! A [`Case`] is one test on record: where it came from (campaign seed, test index, scenario name
//! and hash, settings), the concrete command sequence (segment intents and points with speeds,
//! ahead margins, fault parameters), the return route driven before it, the oracle's result per
//! segment with the faults that preceded it, and the verdict with its reason. Replay consumes it
//! (planning a test from it is [`crate::replay`]'s);
//! a person reads it; a person can write one by hand (only `format`, `schema_version`, `scenario`
//! and `commands` are required). The format is documented field by field in
//! `docs/case-format.md`.
//!
//! Reading checks the format name and version and names the offending field on a parse error;
//! [`Case::check`] checks the values (finite coordinates, positive speeds, counts that agree)
//! and [`Case::check_route`] checks the geometry against a scenario (both in `check.rs`).

use scenarios::Scenario;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use trajgen::{Point, Waypoint};

use super::{
    CASE_FAULT_SECTIONS_SINCE, CASE_FORMAT, CASE_READABLE, CASE_SCHEMA_VERSION, CaseError, Header,
    ScenarioRef, Settings, check_header, parse, settings::millis,
};
use crate::model::{
    Command, Fault, FaultKind, FaultPlace, Probe, Segment, SegmentIntent, TestPlan,
};
use crate::oracle::{SegmentOutcome, Verdict};
use crate::safety::Abort;
use crate::streaming::Append;

mod check;

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
    /// `drivecheck-case`, its schema version and the drivecheck version that wrote it (absent
    /// when written by hand).
    #[serde(flatten)]
    pub header: Header,
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
    /// The car profile of the simulated car it was driven on (absent on a real car and in a
    /// case not yet run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub car_profile: Option<super::CarProfileRef>,
    /// The name of the car that drove it, in a campaign on several cars (`run --car A --car
    /// B`); absent with one car.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub car: Option<String>,
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
    pub fault_places: Vec<FaultPlacementRecord>,
    /// How long the reset and the drive took on the runner's clock (simulated time for the
    /// embedded simulated car in virtual time).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timing: Option<TestTiming>,
    /// Why each failing segment failed (`drivecheck explain`, `docs/explain.md`): written by
    /// `drivecheck run` after the campaign, from the recording.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub explanation: Vec<super::SegmentExplanationRecord>,
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
    pub appends: Vec<AppendRecord>,
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
            header: Header::current(CASE_FORMAT, CASE_SCHEMA_VERSION),
            campaign_seed: Some(campaign_seed),
            test_index: Some(plan.test_index),
            scenario: ScenarioRef::of(scenario),
            settings: Some(settings),
            car_profile: None,
            car: None,
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
        check_header(&case.header, CASE_FORMAT, CASE_READABLE)?;
        if let Some(settings) = &case.settings {
            let version = case.header.schema_version;
            settings
                .faults
                .check_form(version >= CASE_FAULT_SECTIONS_SINCE, version)?;
        }
        Ok(case)
    }

    /// The case as pretty-printed JSON.
    pub fn to_json(&self) -> Result<String, CaseError> {
        super::to_json(self)
    }
}

/// One append of a segment, as a case records it (`streaming.appends`): times in milliseconds
/// since the test started (`crate::streaming::Append` on record).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AppendRecord {
    /// When it was decided, milliseconds.
    pub decided_at: u64,
    /// Time the car still needed then, milliseconds.
    pub time_to_end: u64,
    /// The lead time then, milliseconds.
    pub lead: u64,
    /// Delay from the decision to the car's confirmation, milliseconds; absent until confirmed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confirmed_after: Option<u64>,
}

impl AppendRecord {
    /// The margin left when the car had the points: `time_to_end − confirmed_after`, seconds
    /// (negative: the car would have reached its stopping point first). `None` until confirmed.
    pub fn margin_left_s(&self) -> Option<f64> {
        self.confirmed_after
            .map(|delay| secs(self.time_to_end) - secs(delay))
    }
}

impl From<Append> for AppendRecord {
    fn from(a: Append) -> Self {
        Self {
            decided_at: millis(a.decided_at),
            time_to_end: millis(a.time_to_end),
            lead: millis(a.lead),
            confirmed_after: a.confirmed_after.map(millis),
        }
    }
}

/// Milliseconds as seconds, as the streaming rule counts them.
fn secs(ms: u64) -> f64 {
    std::time::Duration::from_millis(ms).as_secs_f64()
}

/// Which rule placed a fault, as a case records it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlaceRuleRecord {
    /// The case gave the place.
    Planned,
    /// The case gave none: the earlier tool's rule (4 or fewer route points left).
    EarlierTool,
}

/// Where a fault was meant to act and where it did (`fault_places`; the placer's
/// `crate::drive::FaultPlacement` on record).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultPlacementRecord {
    /// The fault command's index in the plan.
    pub command_index: usize,
    /// The rule that placed it.
    pub rule: PlaceRuleRecord,
    /// The segment it is placed on (among the test's segments, from 0).
    pub segment_index: usize,
    /// The place: metres along that segment from its start.
    pub planned_along_m: f64,
    /// When the command was sent, seconds since the test began.
    pub sent_s: f64,
    /// When the car added the fault (estimated), seconds since the test began.
    pub added_s: f64,
    /// Where the car was then: metres along the segment (absent when no sample came after).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub actual_along_m: Option<f64>,
    /// `actual_along_m − planned_along_m`: positive when the fault was added past its place.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_m: Option<f64>,
    /// The estimated window in which the fault acted, seconds since the test began (from the
    /// probe's call rate: `start` and `duration` calls after it was added).
    pub acts_from_s: f64,
    /// The window's end.
    pub acts_to_s: f64,
}

#[cfg(test)]
pub(crate) mod tests;
