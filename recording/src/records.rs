//! The records of a recording, one type per channel, with constructors from what the runner
//! holds (car-link's [`StateSample`], the model's segments and faults, car-sim's [`Truth`] and
//! [`DebugEvent`]).
//!
//! Numbers that may not be finite (estimates and probe values of a faulted car) are left out
//! when they are not (JSON has no NaN; version 1 wrote `null`) and read back as NaN; an absent
//! optional value is left out too, so no record holds a `null` and every field has one type, as
//! Foxglove's JSON-schema reader requires. Positions use metres in the local ENU frame.

use car_link::StateSample;
use car_sim::{DebugEvent, FwPose, RadioPath, RangeResult, Truth};
use schemars::JsonSchema;
use serde::{Deserialize, Deserializer, Serialize};
use tokio::time::Instant;

use prost::Message;

use super::foxglove::{RtkPose, UwbPose, has_pose};
use super::proto::{CarStatePb, TruthPb};
use super::topic::{Encoding, Record, Topic};
use super::{Recording, Stamped};
use campaign::drive::FaultPlacement;
use campaign::files::{IntentRecord, PointRecord, RoutePointRecord, SegmentResult};
use campaign::model::{Fault, FaultKind, Probe, Segment};
use campaign::oracle::{Verdict, deviation};
use campaign::safety::Abort;

/// Reads `null` as NaN: recordings of version 1 wrote a number that was not finite as `null`
/// (version 2 leaves it out, which [`nan`] reads as NaN).
fn nan_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// NaN: a number absent from a record (it was not finite when written).
fn nan() -> f64 {
    f64::NAN
}

/// Whether `x` is left out of a record: a JSON number must be finite.
fn not_finite(x: &f64) -> bool {
    !x.is_finite()
}

/// `Some(x)` when `x` is finite.
fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

/// Nanoseconds from `origin` to `at` (0 before it, saturating far after it).
pub(super) fn nanos_since(origin: Instant, at: Instant) -> u64 {
    let elapsed = at.saturating_duration_since(origin).as_nanos();
    u64::try_from(elapsed).unwrap_or(u64::MAX)
}

/// A position, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Position {
    /// East (absent when not finite).
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub x: f64,
    /// North (absent when not finite).
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub y: f64,
}

impl Position {
    fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    fn point(self) -> trajgen::Point {
        trajgen::Point::new(self.x, self.y)
    }
}

/// A pose: a position and a yaw.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Pose {
    /// East, metres (absent when not finite).
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub x: f64,
    /// North, metres (absent when not finite).
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub y: f64,
    /// Yaw, degrees clockwise from east, as the firmware holds it (absent when not finite).
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub yaw_deg: f64,
}

impl From<FwPose> for Pose {
    fn from(p: FwPose) -> Self {
        Self {
            x: f64::from(p.x),
            y: f64::from(p.y),
            yaw_deg: f64::from(p.yaw),
        }
    }
}

/// `/car/state`: one state sample of the car.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CarStateRecord {
    /// The car id that answered.
    pub car_id: u8,
    /// When the request was sent, ns of the run's clock since the campaign started.
    pub requested_at_ns: u64,
    /// When the reply arrived, ns since the campaign started (also the message's log time).
    pub received_at_ns: u64,
    /// The car's clock: ms since UTC midnight, −1 until known.
    pub ms_today: i32,
    /// The fused (RTK) pose: the oracle's reference.
    pub rtk: Pose,
    /// The UWB position under test.
    pub uwb: Position,
    /// The last GNSS fix.
    pub gnss: Position,
    /// |UWB − RTK|, metres; absent when either position is not finite.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deviation_m: Option<f64>,
    /// Speed from motor RPM, m/s, signed.
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub speed_mps: f64,
    /// Points left on the route (stale while the autopilot is inactive).
    pub route_left: i16,
    /// The pursuit goal.
    pub goal: Position,
    /// Look-ahead radius, metres; −1 when inactive or at the route end.
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub look_ahead_radius_m: f64,
    /// Input voltage, V.
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub input_voltage_v: f64,
    /// Motor-controller fault code, 0 = none.
    pub mc_fault: u8,
}

impl CarStateRecord {
    /// The record of `sample`, its times measured from `origin` (the campaign start).
    pub fn new(sample: &StateSample, origin: Instant) -> Self {
        let s = &sample.state;
        let rtk = Position::new(s.px, s.py);
        let uwb = Position::new(s.px_uwb, s.py_uwb);
        Self {
            car_id: sample.car_id,
            requested_at_ns: nanos_since(origin, sample.requested_at),
            received_at_ns: nanos_since(origin, sample.received_at),
            ms_today: s.ms_today,
            rtk: Pose {
                x: s.px,
                y: s.py,
                yaw_deg: s.yaw,
            },
            uwb,
            gnss: Position::new(s.px_gps, s.py_gps),
            deviation_m: deviation(uwb.point(), rtk.point()).and_then(finite),
            speed_mps: s.speed,
            route_left: s.ap_route_left,
            goal: Position::new(s.ap_goal_px, s.ap_goal_py),
            look_ahead_radius_m: s.ap_rad,
            input_voltage_v: s.v_in,
            mc_fault: s.mc_fault,
        }
    }
}

impl Record for CarStateRecord {
    const TOPIC: Topic = Topic::CarState;

    /// `drivecheck.CarState` (`super::proto`): the RTK and UWB positions only where the pose
    /// channels have no pose for them.
    fn encode(&self) -> Result<Vec<u8>, super::RecordingError> {
        let rtk = (!has_pose(self.rtk.x, self.rtk.y)).then_some(self.rtk);
        let uwb = (!has_pose(self.uwb.x, self.uwb.y)).then_some(self.uwb);
        let message = CarStatePb {
            car_id: u32::from(self.car_id),
            requested_at_ns: self.requested_at_ns,
            received_at_ns: self.received_at_ns,
            ms_today: self.ms_today,
            deviation_m: self.deviation_m.map_or(f32::NAN, |d| d as f32),
            gnss_x: self.gnss.x,
            gnss_y: self.gnss.y,
            speed_mps: self.speed_mps,
            route_left: i32::from(self.route_left),
            goal_x: self.goal.x,
            goal_y: self.goal.y,
            look_ahead_radius_m: self.look_ahead_radius_m,
            input_voltage_v: self.input_voltage_v,
            mc_fault: u32::from(self.mc_fault),
            rtk_x: rtk.map(|p| p.x),
            rtk_y: rtk.map(|p| p.y),
            rtk_yaw_deg: self.rtk.yaw_deg,
            uwb_x: uwb.map(|p| p.x),
            uwb_y: uwb.map(|p| p.y),
        };
        Ok(message.encode_to_vec())
    }

    /// A state alone, its positions NaN where the pose channels hold them ([`Record::read_all`]
    /// joins them).
    fn from_protobuf(data: &[u8]) -> Option<Result<Self, super::ProtobufError>> {
        Some(
            CarStatePb::decode(data)
                .map(|pb| CarStateRecord::from_pb(&pb, None, None))
                .map_err(Into::into),
        )
    }

    /// The states, each joined with its RTK and UWB poses (version 3; the poses follow their
    /// state in file order, one for each position the state does not hold).
    fn read_all(recording: &Recording) -> Result<Vec<Stamped<Self>>, super::RecordingError> {
        if recording.encoding(Topic::CarState) != Some(Encoding::Protobuf) {
            return recording.decode_each::<Self>();
        }
        let rtk_poses = recording.messages::<RtkPose>()?;
        let uwb_poses = recording.messages::<UwbPose>()?;
        let position = |p: &super::foxglove::PoseInFrame| (p.pose.position.x, p.pose.position.y);
        let mut rtk = rtk_poses.iter().map(|p| position(&p.message.0));
        let mut uwb = uwb_poses.iter().map(|p| position(&p.message.0));
        recording
            .raw_messages(Topic::CarState)
            .enumerate()
            .map(|(index, (log_time_ns, sequence, data))| {
                let pb = CarStatePb::decode(data).map_err(|source| {
                    super::RecordingError::DecodeProtobuf {
                        topic: Topic::CarState.name(),
                        index,
                        source: source.into(),
                    }
                })?;
                // A pose missing at the end of a cut-short file leaves the position unknown.
                let lost = (f64::NAN, f64::NAN);
                let rtk = match (pb.rtk_x, pb.rtk_y) {
                    (Some(x), Some(y)) => (x, y),
                    _ => rtk.next().unwrap_or(lost),
                };
                let uwb = match (pb.uwb_x, pb.uwb_y) {
                    (Some(x), Some(y)) => (x, y),
                    _ => uwb.next().unwrap_or(lost),
                };
                Ok(Stamped {
                    log_time_ns,
                    sequence,
                    message: CarStateRecord::from_pb(&pb, Some(rtk), Some(uwb)),
                })
            })
            .collect()
    }
}

impl CarStateRecord {
    /// The record of a `drivecheck.CarState` with its RTK and UWB positions (NaN when `None`);
    /// the deviation computed from them as when it was recorded.
    fn from_pb(pb: &CarStatePb, rtk: Option<(f64, f64)>, uwb: Option<(f64, f64)>) -> Self {
        let (rx, ry) = rtk.unwrap_or((f64::NAN, f64::NAN));
        let (ux, uy) = uwb.unwrap_or((f64::NAN, f64::NAN));
        let rtk_position = Position::new(rx, ry);
        let uwb = Position::new(ux, uy);
        Self {
            car_id: u8::try_from(pb.car_id).unwrap_or(u8::MAX),
            requested_at_ns: pb.requested_at_ns,
            received_at_ns: pb.received_at_ns,
            ms_today: pb.ms_today,
            rtk: Pose {
                x: rx,
                y: ry,
                yaw_deg: pb.rtk_yaw_deg,
            },
            uwb,
            gnss: Position::new(pb.gnss_x, pb.gnss_y),
            deviation_m: deviation(uwb.point(), rtk_position.point()).and_then(finite),
            speed_mps: pb.speed_mps,
            route_left: i16::try_from(pb.route_left).unwrap_or(i16::MAX),
            goal: Position::new(pb.goal_x, pb.goal_y),
            look_ahead_radius_m: pb.look_ahead_radius_m,
            input_voltage_v: pb.input_voltage_v,
            mc_fault: u8::try_from(pb.mc_fault).unwrap_or(u8::MAX),
        }
    }
}

/// A command to the car (fault commands go to `/faults` instead).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "command", rename_all = "snake_case", deny_unknown_fields)]
pub enum CarCommand {
    /// AP_ADD_POINTS: append to the route.
    AddPoints {
        /// The points.
        points: Vec<RoutePointRecord>,
    },
    /// AP_REPLACE_ROUTE: replace the route.
    ReplaceRoute {
        /// The points.
        points: Vec<RoutePointRecord>,
    },
    /// AP_CLEAR_POINTS.
    ClearRoute,
    /// AP_REMOVE_LAST_POINT.
    RemoveLastPoint,
    /// AP_SET_ACTIVE.
    SetAutopilot {
        /// Activate or deactivate.
        active: bool,
        /// Reset the route progress (12.3).
        reset: bool,
    },
    /// A brake with this motor current.
    Brake {
        /// Brake current, A.
        current_a: f64,
    },
    /// SET_POS: set the fused pose.
    SetPos {
        /// The pose.
        pose: Pose,
    },
    /// `fi_clear_faults`.
    ClearFaults,
    /// `fi_set_enabled`.
    SetFaultInjection {
        /// On or off.
        enabled: bool,
    },
    /// `pos_uwb_reset_pos`: reset the UWB position to the fused one.
    ResetUwbPos,
    /// Any other terminal command.
    Terminal {
        /// The text sent.
        text: String,
    },
}

impl CarCommand {
    /// The name of the command (its `command` tag).
    pub fn name(&self) -> &'static str {
        match self {
            CarCommand::AddPoints { .. } => "add_points",
            CarCommand::ReplaceRoute { .. } => "replace_route",
            CarCommand::ClearRoute => "clear_route",
            CarCommand::RemoveLastPoint => "remove_last_point",
            CarCommand::SetAutopilot { .. } => "set_autopilot",
            CarCommand::Brake { .. } => "brake",
            CarCommand::SetPos { .. } => "set_pos",
            CarCommand::ClearFaults => "clear_faults",
            CarCommand::SetFaultInjection { .. } => "set_fault_injection",
            CarCommand::ResetUwbPos => "reset_uwb_pos",
            CarCommand::Terminal { .. } => "terminal",
        }
    }

    /// AP_ADD_POINTS with car-link's points.
    pub fn add_points(points: &[car_link::RoutePoint]) -> Self {
        CarCommand::AddPoints {
            points: route_points(points),
        }
    }

    /// AP_REPLACE_ROUTE with car-link's points.
    pub fn replace_route(points: &[car_link::RoutePoint]) -> Self {
        CarCommand::ReplaceRoute {
            points: route_points(points),
        }
    }
}

fn route_points(points: &[car_link::RoutePoint]) -> Vec<RoutePointRecord> {
    points
        .iter()
        .map(|p| RoutePointRecord {
            x: p.px,
            y: p.py,
            speed: p.speed,
        })
        .collect()
}

/// `/commands`: a command as it was sent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CommandSent {
    /// The command's number in the recording (from 1), which its ack repeats.
    pub id: u64,
    /// The test it belongs to; absent between tests (resets, return routes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_index: Option<usize>,
    /// The command.
    pub command: CarCommand,
}

impl Record for CommandSent {
    const TOPIC: Topic = Topic::Commands;
}

/// How the car answered a command.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "status", rename_all = "snake_case", deny_unknown_fields)]
pub enum AckOutcome {
    /// Acknowledged (or, for commands without an ack, sent without error).
    Acked,
    /// Refused, timed out or the link failed.
    Failed {
        /// The error.
        error: String,
    },
}

impl AckOutcome {
    /// The outcome of a car-link call.
    pub fn of<T, E: std::fmt::Display>(result: &Result<T, E>) -> Self {
        match result {
            Ok(_) => AckOutcome::Acked,
            Err(e) => AckOutcome::Failed {
                error: e.to_string(),
            },
        }
    }
}

/// `/acks`: the answer to a command.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CommandAck {
    /// The command's `id` on `/commands`.
    pub id: u64,
    /// The command's name.
    pub command: String,
    /// The answer.
    pub outcome: AckOutcome,
    /// From sending to the answer, ms (absent when the send was not recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub round_trip_ms: Option<f64>,
}

impl Record for CommandAck {
    const TOPIC: Topic = Topic::Acks;
}

/// What happened to a test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "event", rename_all = "snake_case", deny_unknown_fields)]
pub enum TestEventKind {
    /// The test starts (after its reset and return route).
    Started {
        /// Commands in its plan.
        commands: usize,
    },
    /// The test ended.
    Ended {
        /// Its verdict.
        verdict: Verdict,
        /// Why it failed or was aborted.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        reason: Option<String>,
    },
}

/// `/tests`: a test started or ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TestEvent {
    /// The test's index in the campaign.
    pub test_index: usize,
    /// What happened.
    pub event: TestEventKind,
}

impl Record for TestEvent {
    const TOPIC: Topic = Topic::Tests;
}

/// `/plan/segments`: a segment as planned, before it is streamed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PlannedSegment {
    /// The test.
    pub test_index: usize,
    /// The command's index in the test.
    pub command_index: usize,
    /// The segment's index among the test's segments.
    pub segment_index: usize,
    /// What the generator was asked for (absent for a segment written by hand).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intent: Option<IntentRecord>,
    /// The points the car drives, with their speeds.
    pub points: Vec<RoutePointRecord>,
    /// The ahead margin generated after them (never sent).
    pub margin: Vec<PointRecord>,
}

impl PlannedSegment {
    /// The record of `segment`, command `command_index` and segment `segment_index` of test
    /// `test_index`.
    pub fn new(
        test_index: usize,
        command_index: usize,
        segment_index: usize,
        segment: &Segment,
    ) -> Self {
        Self {
            test_index,
            command_index,
            segment_index,
            intent: segment.intent.map(IntentRecord::from),
            points: segment.waypoints().map(RoutePointRecord::from).collect(),
            margin: segment.margin.iter().map(|&p| p.into()).collect(),
        }
    }
}

impl Record for PlannedSegment {
    const TOPIC: Topic = Topic::PlanSegments;
}

/// `/plan/return_route`: the route planned from the car's pose back to the recovery route.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PlannedReturnRoute {
    /// The test it prepares.
    pub test_index: usize,
    /// The points, with their speeds.
    pub points: Vec<RoutePointRecord>,
}

impl Record for PlannedReturnRoute {
    const TOPIC: Topic = Topic::PlanReturnRoute;
}

/// A fault as commanded: `fi_add_fault probe kind param start duration`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FaultSpec {
    /// The probe id.
    pub probe: Probe,
    /// The fault type.
    pub kind: FaultKind,
    /// Its parameter.
    pub param: f64,
    /// Probe iterations before it applies.
    pub start: u32,
    /// Probe iterations it applies for.
    pub duration: u32,
}

impl From<&Fault> for FaultSpec {
    fn from(f: &Fault) -> Self {
        Self {
            probe: f.probe,
            kind: f.kind,
            param: f.param,
            start: f.start,
            duration: f.duration,
        }
    }
}

/// Where a fault command stands.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "status", rename_all = "snake_case", deny_unknown_fields)]
pub enum FaultStatus {
    /// Sent to the car.
    Sent,
    /// The car confirmed it ("successfully added to probe …").
    Confirmed,
    /// The car refused it, or no answer came.
    Refused {
        /// The error.
        error: String,
    },
    /// Where it was meant to act and where the car added it, and the estimated window in which
    /// it acted (written when its test ends).
    Placed {
        /// The placement, as in the case file's `fault_places`.
        placement: FaultPlacement,
    },
}

/// `/faults`: a fault command sent, then its confirmation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FaultRecord {
    /// The test.
    pub test_index: usize,
    /// The command's index in the test.
    pub command_index: usize,
    /// The fault.
    pub fault: FaultSpec,
    /// Sent, confirmed or refused.
    pub status: FaultStatus,
}

impl FaultRecord {
    /// `fault` (command `command_index` of test `test_index`) has been sent.
    pub fn sent(test_index: usize, command_index: usize, fault: &Fault) -> Self {
        Self {
            test_index,
            command_index,
            fault: fault.into(),
            status: FaultStatus::Sent,
        }
    }

    /// The car answered `fault` with `result` (car-link's `add_fault`).
    pub fn answered<T, E: std::fmt::Display>(
        test_index: usize,
        command_index: usize,
        fault: &Fault,
        result: &Result<T, E>,
    ) -> Self {
        let status = match result {
            Ok(_) => FaultStatus::Confirmed,
            Err(e) => FaultStatus::Refused {
                error: e.to_string(),
            },
        };
        Self {
            status,
            ..Self::sent(test_index, command_index, fault)
        }
    }
}

impl FaultRecord {
    /// Where `fault` (command `command_index` of test `test_index`) was meant to act and did.
    pub fn placed(test_index: usize, fault: &Fault, placement: FaultPlacement) -> Self {
        Self {
            status: FaultStatus::Placed { placement },
            ..Self::sent(test_index, placement.command_index, fault)
        }
    }
}

impl Record for FaultRecord {
    const TOPIC: Topic = Topic::Faults;
}

/// `/oracle/segments`: the oracle's result for one driven segment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OracleRecord {
    /// The test.
    pub test_index: usize,
    /// The result, as in the case file's `segments`.
    pub result: SegmentResult,
}

impl Record for OracleRecord {
    const TOPIC: Topic = Topic::OracleSegments;
}

/// `/safety/events`: a stop the safety monitor (or the runner) demanded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SafetyRecord {
    /// The test it stopped; absent between tests.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_index: Option<usize>,
    /// The stop, as in the case file's `abort`.
    pub abort: Abort,
    /// The reason in words.
    pub message: String,
}

impl SafetyRecord {
    /// The record of `abort` during test `test_index`.
    pub fn new(test_index: Option<usize>, abort: Abort) -> Self {
        Self {
            test_index,
            abort,
            message: abort.reason.to_string(),
        }
    }
}

impl Record for SafetyRecord {
    const TOPIC: Topic = Topic::SafetyEvents;
}

/// `/sim/truth`: the simulated car's true state and its estimates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TruthRecord {
    /// Simulation time since boot, ms.
    pub sim_ms: u64,
    /// True position (rear axle centre).
    pub position: Position,
    /// True heading, radians counter-clockwise from east.
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub heading_rad: f64,
    /// True speed, m/s, signed.
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub speed_mps: f64,
    /// True steering angle, rad (positive left).
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub steering_rad: f64,
    /// The fused (RTK) estimate.
    pub fused: Pose,
    /// The UWB estimate.
    pub uwb: Pose,
    /// Distance of the fused estimate from the true position, metres (absent if not finite).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fused_error_m: Option<f64>,
    /// Distance of the UWB estimate from the true position, metres (absent if not finite).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uwb_error_m: Option<f64>,
}

impl From<&Truth> for TruthRecord {
    fn from(t: &Truth) -> Self {
        let fused = Pose::from(t.fused);
        let uwb = Pose::from(t.uwb);
        let error = |p: Pose| finite((p.x - t.x).hypot(p.y - t.y));
        Self {
            sim_ms: t.time_ms,
            position: Position::new(t.x, t.y),
            heading_rad: t.heading,
            speed_mps: t.speed,
            steering_rad: t.steering_angle,
            fused,
            uwb,
            fused_error_m: error(fused),
            uwb_error_m: error(uwb),
        }
    }
}

impl Record for TruthRecord {
    const TOPIC: Topic = Topic::SimTruth;

    /// `drivecheck.SimTruth` (`super::proto`): the estimates as the firmware holds them (`f32`),
    /// their errors left to the reader.
    fn encode(&self) -> Result<Vec<u8>, super::RecordingError> {
        let message = TruthPb {
            sim_ms: self.sim_ms,
            x: self.position.x,
            y: self.position.y,
            heading_rad: self.heading_rad,
            speed_mps: self.speed_mps,
            steering_rad: self.steering_rad,
            fused_x: self.fused.x as f32,
            fused_y: self.fused.y as f32,
            fused_yaw_deg: self.fused.yaw_deg as f32,
            uwb_x: self.uwb.x as f32,
            uwb_y: self.uwb.y as f32,
            uwb_yaw_deg: self.uwb.yaw_deg as f32,
        };
        Ok(message.encode_to_vec())
    }

    fn from_protobuf(data: &[u8]) -> Option<Result<Self, super::ProtobufError>> {
        Some(TruthPb::decode(data).map_err(Into::into).map(|pb| {
            let estimate = |x: f32, y: f32, yaw: f32| Pose {
                x: f64::from(x),
                y: f64::from(y),
                yaw_deg: f64::from(yaw),
            };
            let fused = estimate(pb.fused_x, pb.fused_y, pb.fused_yaw_deg);
            let uwb = estimate(pb.uwb_x, pb.uwb_y, pb.uwb_yaw_deg);
            let error = |p: Pose| finite((p.x - pb.x).hypot(p.y - pb.y));
            TruthRecord {
                sim_ms: pb.sim_ms,
                position: Position::new(pb.x, pb.y),
                heading_rad: pb.heading_rad,
                speed_mps: pb.speed_mps,
                steering_rad: pb.steering_rad,
                fused,
                uwb,
                fused_error_m: error(fused),
                uwb_error_m: error(uwb),
            }
        }))
    }
}

/// The radio path of a simulated range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum RadioPathKind {
    /// Line of sight.
    LineOfSight,
    /// Not line of sight: the direct path is blocked, a wall reflects.
    Reflected,
    /// Blocked, no reflection.
    Blocked,
}

/// A simulated range's radio path.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RadioPathRecord {
    /// Line of sight, reflected (NLOS) or blocked.
    pub kind: RadioPathKind,
    /// Planar length travelled, metres (absent when blocked).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length_m: Option<f64>,
    /// The reflecting wall's index in the world (reflected only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall: Option<usize>,
    /// Planar length of the blocked direct path, metres (reflected only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direct_m: Option<f64>,
}

impl From<&RadioPath> for RadioPathRecord {
    fn from(path: &RadioPath) -> Self {
        let (kind, wall, direct_m) = match *path {
            RadioPath::LineOfSight { .. } => (RadioPathKind::LineOfSight, None, None),
            RadioPath::Reflected { wall, direct, .. } => {
                (RadioPathKind::Reflected, Some(wall), Some(direct))
            }
            RadioPath::Blocked => (RadioPathKind::Blocked, None, None),
        };
        Self {
            kind,
            length_m: path.length(),
            wall,
            direct_m,
        }
    }
}

/// What a simulated UWB module returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum RangeOutcome {
    /// A range (in `range_m`).
    Measured,
    /// Blocked and no reflection: nothing returned.
    Blocked,
    /// An exchange failed: nothing returned.
    Dropped,
    /// No anchor answers to that address.
    NoResponder,
}

/// `/sim/ranges`: a simulated range request, or a range reaching the estimator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "event", rename_all = "snake_case", deny_unknown_fields)]
pub enum SimRange {
    /// A range request and its fate.
    Request {
        /// When, simulation ms since boot.
        sim_ms: u64,
        /// The address (anchor id low byte).
        anchor: u8,
        /// The radio path, when an anchor answers.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        path: Option<RadioPathRecord>,
        /// The true direct slant range, metres.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        true_range_m: Option<f64>,
        /// What the module returned.
        outcome: RangeOutcome,
        /// The measured range, metres (when measured).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        range_m: Option<f64>,
    },
    /// A range reply reached the estimator (after the `uwb_range_<id>` probe).
    Fused {
        /// When, simulation ms since boot.
        sim_ms: u64,
        /// The address.
        anchor: u8,
        /// The range after the probe, metres (absent when not finite).
        #[serde(
            default = "nan",
            deserialize_with = "nan_if_null",
            skip_serializing_if = "not_finite"
        )]
        range_m: f64,
        /// Whether the estimate moved.
        moved: bool,
    },
}

impl Record for SimRange {
    const TOPIC: Topic = Topic::SimRanges;

    /// `drivecheck.SimRange` (`super::proto`), from recording version 4.
    fn encode(&self) -> Result<Vec<u8>, super::RecordingError> {
        use super::proto::SimRangePb;
        // The simulator's ranges are the firmware's `f32`s: `float` keeps them exactly.
        let message = match *self {
            SimRange::Request {
                sim_ms,
                anchor,
                path,
                true_range_m,
                outcome,
                range_m,
            } => SimRangePb {
                event: 0,
                sim_ms,
                anchor: u32::from(anchor),
                path_kind: path.map(|p| match p.kind {
                    RadioPathKind::LineOfSight => 0,
                    RadioPathKind::Reflected => 1,
                    RadioPathKind::Blocked => 2,
                }),
                path_length_m: path.and_then(|p| p.length_m),
                path_wall: path.and_then(|p| p.wall).map(|w| w as u64),
                path_direct_m: path.and_then(|p| p.direct_m),
                true_range_m,
                outcome: match outcome {
                    RangeOutcome::Measured => 0,
                    RangeOutcome::Blocked => 1,
                    RangeOutcome::Dropped => 2,
                    RangeOutcome::NoResponder => 3,
                },
                range_m: range_m.map(|r| r as f32),
                moved: false,
            },
            SimRange::Fused {
                sim_ms,
                anchor,
                range_m,
                moved,
            } => SimRangePb {
                event: 1,
                sim_ms,
                anchor: u32::from(anchor),
                range_m: finite(range_m).map(|r| r as f32),
                moved,
                ..SimRangePb::default()
            },
        };
        Ok(message.encode_to_vec())
    }

    fn from_protobuf(data: &[u8]) -> Option<Result<Self, super::ProtobufError>> {
        use super::proto::SimRangePb;
        let decoded = SimRangePb::decode(data)
            .map_err(super::ProtobufError::from)
            .and_then(|pb| {
                let invalid =
                    |field: &'static str, value: u64| super::ProtobufError::Value { field, value };
                let anchor =
                    u8::try_from(pb.anchor).map_err(|_| invalid("anchor", pb.anchor.into()))?;
                let range_m = pb.range_m.map(f64::from);
                Ok(match pb.event {
                    0 => SimRange::Request {
                        sim_ms: pb.sim_ms,
                        anchor,
                        path: match pb.path_kind {
                            None => None,
                            Some(kind) => Some(RadioPathRecord {
                                kind: match kind {
                                    0 => RadioPathKind::LineOfSight,
                                    1 => RadioPathKind::Reflected,
                                    2 => RadioPathKind::Blocked,
                                    other => return Err(invalid("path_kind", other.into())),
                                },
                                length_m: pb.path_length_m,
                                wall: pb.path_wall.map(|w| w as usize),
                                direct_m: pb.path_direct_m,
                            }),
                        },
                        true_range_m: pb.true_range_m,
                        outcome: match pb.outcome {
                            0 => RangeOutcome::Measured,
                            1 => RangeOutcome::Blocked,
                            2 => RangeOutcome::Dropped,
                            3 => RangeOutcome::NoResponder,
                            other => return Err(invalid("outcome", other.into())),
                        },
                        range_m,
                    },
                    1 => SimRange::Fused {
                        sim_ms: pb.sim_ms,
                        anchor,
                        range_m: range_m.unwrap_or(f64::NAN),
                        moved: pb.moved,
                    },
                    other => return Err(invalid("event", other.into())),
                })
            });
        Some(decoded)
    }
}

fn range_outcome(result: &RangeResult) -> (RangeOutcome, Option<f64>) {
    match *result {
        RangeResult::Measured(r) => (RangeOutcome::Measured, finite(f64::from(r))),
        RangeResult::Blocked => (RangeOutcome::Blocked, None),
        RangeResult::Dropped => (RangeOutcome::Dropped, None),
        RangeResult::NoResponder => (RangeOutcome::NoResponder, None),
    }
}

/// `/sim/faults`: a fault applied at a probe inside the simulator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SimFault {
    /// When, simulation ms since boot.
    pub sim_ms: u64,
    /// The probe id.
    pub probe: String,
    /// Bit mask of the fault slots that applied.
    pub slots: u8,
    /// The probe's iteration.
    pub iteration: i32,
    /// The value before (absent when not finite).
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub before: f64,
    /// The value after (absent when not finite).
    #[serde(
        default = "nan",
        deserialize_with = "nan_if_null",
        skip_serializing_if = "not_finite"
    )]
    pub after: f64,
}

impl Record for SimFault {
    const TOPIC: Topic = Topic::SimFaults;
}

/// A simulated firmware event.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SimEventKind {
    /// The communication watchdog expired.
    WatchdogExpired,
    /// The anchor walk would hang here (`docs/firmware.md#ranging-schedule`; the round is skipped).
    AnchorWalkWouldHang,
    /// The autopilot window held a zero-length segment (`docs/firmware.md#uploading-points`).
    ZeroLengthSegment,
    /// The route ring overflowed (`docs/firmware.md#route-ring-and-points-left`).
    RouteRingOverflow,
    /// A route packet repeating the previous packet's first point was dropped
    /// (`docs/firmware.md#uploading-points`).
    DuplicatePacketDropped,
}

/// `/sim/events`: a watchdog or quirk event inside the simulated firmware.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SimEvent {
    /// When, simulation ms since boot.
    pub sim_ms: u64,
    /// What happened.
    pub event: SimEventKind,
}

impl Record for SimEvent {
    const TOPIC: Topic = Topic::SimEvents;
}

/// A simulator debug event as the record of its channel.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum SimRecord {
    /// For `/sim/ranges`.
    Range(SimRange),
    /// For `/sim/faults`.
    Fault(SimFault),
    /// For `/sim/events`.
    Event(SimEvent),
}

impl SimRecord {
    /// The simulation time of the event, ms since boot.
    pub(super) fn sim_ms(&self) -> u64 {
        match self {
            SimRecord::Range(SimRange::Request { sim_ms, .. })
            | SimRecord::Range(SimRange::Fused { sim_ms, .. })
            | SimRecord::Fault(SimFault { sim_ms, .. })
            | SimRecord::Event(SimEvent { sim_ms, .. }) => *sim_ms,
        }
    }
}

impl From<&DebugEvent> for SimRecord {
    fn from(event: &DebugEvent) -> Self {
        let firmware = |sim_ms: u64, event| SimRecord::Event(SimEvent { sim_ms, event });
        match event {
            DebugEvent::Range {
                at_ms,
                anchor,
                path,
                true_range,
                result,
            } => {
                let (outcome, range_m) = range_outcome(result);
                SimRecord::Range(SimRange::Request {
                    sim_ms: *at_ms,
                    anchor: *anchor,
                    path: path.as_ref().map(RadioPathRecord::from),
                    true_range_m: *true_range,
                    outcome,
                    range_m,
                })
            }
            DebugEvent::RangeFused {
                at_ms,
                anchor,
                range,
                moved,
            } => SimRecord::Range(SimRange::Fused {
                sim_ms: *at_ms,
                anchor: *anchor,
                range_m: f64::from(*range),
                moved: *moved,
            }),
            DebugEvent::Fault {
                at_ms,
                probe,
                slots,
                iteration,
                before,
                after,
            } => SimRecord::Fault(SimFault {
                sim_ms: *at_ms,
                probe: probe.clone(),
                slots: *slots,
                iteration: *iteration,
                before: f64::from(*before),
                after: f64::from(*after),
            }),
            DebugEvent::WatchdogExpired { at_ms } => {
                firmware(*at_ms, SimEventKind::WatchdogExpired)
            }
            DebugEvent::AnchorWalkWouldHang { at_ms } => {
                firmware(*at_ms, SimEventKind::AnchorWalkWouldHang)
            }
            DebugEvent::ZeroLengthSegment { at_ms } => {
                firmware(*at_ms, SimEventKind::ZeroLengthSegment)
            }
            DebugEvent::RouteRingOverflow { at_ms } => {
                firmware(*at_ms, SimEventKind::RouteRingOverflow)
            }
            DebugEvent::DuplicatePacketDropped { at_ms } => {
                firmware(*at_ms, SimEventKind::DuplicatePacketDropped)
            }
        }
    }
}
