//! Channels in Foxglove's well-known schemas, so that Foxglove shows a recording on a map in its
//! 3D panel without any set-up: the area (`/foxglove/area`, `foxglove.SceneUpdate`: the fence and
//! cutouts as line loops, the anchors as spheres with their ids), each test's planned route
//! (`/foxglove/route`, `foxglove.SceneUpdate`: a line strip per segment, cleared when a test
//! starts), the RTK and UWB poses of every state sample (`/foxglove/rtk`, `/foxglove/uwb`,
//! `foxglove.PoseInFrame`) and the events worth reading (`/foxglove/log`, `foxglove.Log`: faults
//! sent and confirmed, tests started and ended, safety stops).
//!
//! The poses are protobuf in Foxglove's own schema (`foxglove::messages::PoseInFrame`); the
//! rest are JSON, with JSON schemas derived from the types below (Foxglove knows the message
//! types by their schema names). Everything is in the frame `map`: x east, y north, in
//! metres, as the area's coordinates. The recorder writes them beside the records they come from
//! (see `Recorder`); `docs/foxglove-layout.json` is a layout with a 3D panel, a plot of the
//! deviation and the log.

use scenarios::Scenario;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::records::{CarStateRecord, FaultRecord, FaultStatus, PlannedSegment, SafetyRecord};
use super::records::{TestEvent, TestEventKind};
use super::topic::{Record, Topic};

/// The frame everything is drawn in.
pub const FRAME: &str = "map";

/// A time: seconds and nanoseconds (here, of the run's clock since the campaign started).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Time {
    /// Whole seconds.
    pub sec: u64,
    /// Nanoseconds.
    pub nsec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the origin.
    pub fn from_ns(ns: u64) -> Self {
        Self {
            sec: ns / 1_000_000_000,
            nsec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// A point or a size.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Vector3 {
    /// East, m.
    pub x: f64,
    /// North, m.
    pub y: f64,
    /// Up, m.
    pub z: f64,
}

/// An orientation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Quaternion {
    /// A rotation by `yaw` radians about the vertical (counter-clockwise from east).
    pub fn yaw(yaw: f64) -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: (yaw / 2.0).sin(),
            w: (yaw / 2.0).cos(),
        }
    }
}

/// A position and an orientation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Pose {
    /// Where.
    pub position: Vector3,
    /// Which way.
    pub orientation: Quaternion,
}

impl Pose {
    /// At (`x`, `y`) on the ground, heading `yaw` radians.
    pub fn at(x: f64, y: f64, yaw: f64) -> Self {
        Self {
            position: Vector3 { x, y, z: 0.0 },
            orientation: Quaternion::yaw(yaw),
        }
    }
}

/// A colour, each part 0–1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Color {
    /// Red.
    pub r: f64,
    /// Green.
    pub g: f64,
    /// Blue.
    pub b: f64,
    /// Opacity.
    pub a: f64,
}

const fn rgb(r: f64, g: f64, b: f64) -> Color {
    Color { r, g, b, a: 1.0 }
}

/// A polyline (`type` 0: strip, 1: loop).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LinePrimitive {
    /// 0 line strip, 1 line loop, 2 line list.
    #[serde(rename = "type")]
    pub kind: u8,
    /// Where its points are relative to.
    pub pose: Pose,
    /// Its width.
    pub thickness: f64,
    /// Whether `thickness` is in pixels (true) or metres.
    pub scale_invariant: bool,
    /// The points.
    pub points: Vec<Vector3>,
    /// Its colour.
    pub color: Color,
    /// Per-point colours (none).
    pub colors: Vec<Color>,
    /// Indices into `points` (none: in order).
    pub indices: Vec<u32>,
}

/// A sphere.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SpherePrimitive {
    /// Its centre.
    pub pose: Pose,
    /// Its diameters.
    pub size: Vector3,
    /// Its colour.
    pub color: Color,
}

/// A text label.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TextPrimitive {
    /// Where.
    pub pose: Pose,
    /// Always facing the camera.
    pub billboard: bool,
    /// Its size.
    pub font_size: f64,
    /// Whether `font_size` is in pixels.
    pub scale_invariant: bool,
    /// Its colour.
    pub color: Color,
    /// The text.
    pub text: String,
}

/// A thing in the 3D scene, made of primitives: lines, spheres and texts (the schema's other
/// kinds, arrows, cubes, cylinders, triangles and models, and its metadata are left out; Foxglove
/// reads a missing list as empty).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SceneEntity {
    /// When.
    pub timestamp: Time,
    /// Its frame ([`FRAME`]).
    pub frame_id: String,
    /// Its id: an entity replaces an earlier one of the same id on its topic.
    pub id: String,
    /// How long it shows (zero: until replaced or deleted).
    pub lifetime: Time,
    /// Whether it moves with its frame.
    pub frame_locked: bool,
    /// Spheres.
    pub spheres: Vec<SpherePrimitive>,
    /// Lines.
    pub lines: Vec<LinePrimitive>,
    /// Texts.
    pub texts: Vec<TextPrimitive>,
}

impl SceneEntity {
    fn new(at: Time, id: String) -> Self {
        Self {
            timestamp: at,
            frame_id: FRAME.to_owned(),
            id,
            lifetime: Time::from_ns(0),
            frame_locked: false,
            spheres: Vec::new(),
            lines: Vec::new(),
            texts: Vec::new(),
        }
    }
}

/// A deletion of entities (`type` 1: all on the topic).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SceneEntityDeletion {
    /// Entities older than this go.
    pub timestamp: Time,
    /// 0 the one with `id`, 1 all.
    #[serde(rename = "type")]
    pub kind: u8,
    /// The id (for `type` 0).
    pub id: String,
}

/// An update of the 3D scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SceneUpdate {
    /// What to remove first.
    pub deletions: Vec<SceneEntityDeletion>,
    /// What to add or replace.
    pub entities: Vec<SceneEntity>,
}

/// `/foxglove/area`: the area, once at the start.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(transparent)]
pub struct AreaScene(pub SceneUpdate);

impl Record for AreaScene {
    const TOPIC: Topic = Topic::FoxgloveArea;
}

/// `/foxglove/route`: a test's planned segments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(transparent)]
pub struct RouteScene(pub SceneUpdate);

impl Record for RouteScene {
    const TOPIC: Topic = Topic::FoxgloveRoute;
}

/// A pose in a frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct PoseInFrame {
    /// When.
    pub timestamp: Time,
    /// The frame ([`FRAME`]).
    #[serde(with = "frame")]
    #[schemars(with = "String")]
    pub frame_id: (),
    /// The pose.
    pub pose: Pose,
}

/// `frame_id` is always [`FRAME`].
mod frame {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(_: &(), s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(super::FRAME)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<(), D::Error> {
        String::deserialize(d).map(drop)
    }
}

/// `/foxglove/rtk`: the RTK (fused) pose of a state sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(transparent)]
pub struct RtkPose(pub PoseInFrame);

impl Record for RtkPose {
    const TOPIC: Topic = Topic::FoxgloveRtk;

    fn encode(&self) -> Result<Vec<u8>, super::RecordingError> {
        Ok(self.0.to_protobuf())
    }

    fn from_protobuf(data: &[u8]) -> Option<Result<Self, super::ProtobufError>> {
        Some(
            PoseInFrame::from_protobuf(data)
                .map(RtkPose)
                .map_err(Into::into),
        )
    }
}

/// `/foxglove/uwb`: the UWB pose of a state sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(transparent)]
pub struct UwbPose(pub PoseInFrame);

impl Record for UwbPose {
    const TOPIC: Topic = Topic::FoxgloveUwb;

    fn encode(&self) -> Result<Vec<u8>, super::RecordingError> {
        Ok(self.0.to_protobuf())
    }

    fn from_protobuf(data: &[u8]) -> Option<Result<Self, super::ProtobufError>> {
        Some(
            PoseInFrame::from_protobuf(data)
                .map(UwbPose)
                .map_err(Into::into),
        )
    }
}

impl PoseInFrame {
    /// The message in Foxglove's protobuf `foxglove.PoseInFrame` (recording version 3).
    fn to_protobuf(self) -> Vec<u8> {
        use ::foxglove::messages as fm;
        let p = self.pose.position;
        let o = self.pose.orientation;
        let message = fm::PoseInFrame {
            timestamp: Some(fm::Timestamp::new(
                u32::try_from(self.timestamp.sec).unwrap_or(u32::MAX),
                self.timestamp.nsec,
            )),
            frame_id: FRAME.to_owned(),
            pose: Some(fm::Pose {
                position: Some(fm::Vector3 {
                    x: p.x,
                    y: p.y,
                    z: p.z,
                }),
                orientation: Some(fm::Quaternion {
                    x: o.x,
                    y: o.y,
                    z: o.z,
                    w: o.w,
                }),
            }),
        };
        prost::Message::encode_to_vec(&message)
    }

    /// A `foxglove.PoseInFrame` in protobuf.
    fn from_protobuf(data: &[u8]) -> Result<Self, prost::DecodeError> {
        let message: ::foxglove::messages::PoseInFrame = prost::Message::decode(data)?;
        let time = message.timestamp.unwrap_or_default();
        let pose = message.pose.unwrap_or_default();
        let p = pose.position.unwrap_or_default();
        let o = pose.orientation.unwrap_or_default();
        Ok(PoseInFrame {
            timestamp: Time {
                sec: u64::from(time.sec()),
                nsec: time.nsec(),
            },
            frame_id: (),
            pose: Pose {
                position: Vector3 {
                    x: p.x,
                    y: p.y,
                    z: p.z,
                },
                orientation: Quaternion {
                    x: o.x,
                    y: o.y,
                    z: o.z,
                    w: o.w,
                },
            },
        })
    }
}

/// `/foxglove/log`: an event worth reading.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Log {
    /// When.
    pub timestamp: Time,
    /// 1 debug, 2 info, 3 warning, 4 error, 5 fatal.
    pub level: u8,
    /// The text.
    pub message: String,
    /// Who says it (`drivecheck`).
    pub name: String,
    /// Source file (empty).
    pub file: String,
    /// Source line (0).
    pub line: u32,
}

impl Record for Log {
    const TOPIC: Topic = Topic::FoxgloveLog;
}

impl Log {
    fn new(at: Time, level: u8, message: String) -> Self {
        Self {
            timestamp: at,
            level,
            message,
            name: "drivecheck".to_owned(),
            file: String::new(),
            line: 0,
        }
    }
}

const INFO: u8 = 2;
const WARNING: u8 = 3;
const ERROR: u8 = 4;

const FENCE: Color = rgb(0.1, 0.1, 0.1);
const CUTOUT: Color = rgb(0.45, 0.45, 0.45);
const ANCHOR: Color = rgb(0.1, 0.1, 0.55);
const ROUTE: Color = rgb(0.29, 0.5, 0.76);

fn ground(p: trajgen::Point) -> Vector3 {
    Vector3 {
        x: p.x,
        y: p.y,
        z: 0.0,
    }
}

fn line(kind: u8, points: Vec<Vector3>, thickness: f64, color: Color) -> LinePrimitive {
    LinePrimitive {
        kind,
        pose: Pose::at(0.0, 0.0, 0.0),
        thickness,
        scale_invariant: false,
        points,
        color,
        colors: Vec::new(),
        indices: Vec::new(),
    }
}

/// The area of `scenario`: fence and cutouts as line loops, anchors as spheres with labels.
pub fn area(scenario: &Scenario, at: Time) -> AreaScene {
    let mut fence = SceneEntity::new(at, "area".to_owned());
    let vertices = |p: &trajgen::Polygon| p.vertices().iter().copied().map(ground).collect();
    fence
        .lines
        .push(line(1, vertices(scenario.area.fence()), 0.08, FENCE));
    for cutout in scenario.area.cutouts() {
        fence.lines.push(line(1, vertices(cutout), 0.06, CUTOUT));
    }
    let mut anchors = SceneEntity::new(at, "anchors".to_owned());
    for a in &scenario.anchors {
        let centre = Pose::at(a.x, a.y, 0.0);
        anchors.spheres.push(SpherePrimitive {
            pose: Pose {
                position: Vector3 {
                    z: a.height,
                    ..centre.position
                },
                ..centre
            },
            size: Vector3 {
                x: 0.4,
                y: 0.4,
                z: 0.4,
            },
            color: ANCHOR,
        });
        anchors.texts.push(TextPrimitive {
            pose: Pose {
                position: Vector3 {
                    z: a.height + 0.5,
                    ..centre.position
                },
                ..centre
            },
            billboard: true,
            font_size: 14.0,
            scale_invariant: true,
            color: ANCHOR,
            text: format!("anchor {}", a.id),
        });
    }
    AreaScene(SceneUpdate {
        deletions: Vec::new(),
        entities: vec![fence, anchors],
    })
}

/// The derived messages of a record written on one of drivecheck's own channels.
pub(super) enum Derived {
    /// On `/foxglove/route`.
    Route(RouteScene),
    /// On `/foxglove/log`.
    Log(Log),
}

/// What `record` adds to the Foxglove channels, at `at`.
pub(super) fn derived<R: Record + 'static>(record: &R, at: Time) -> Option<Derived> {
    let any: &dyn std::any::Any = record;
    if let Some(segment) = any.downcast_ref::<PlannedSegment>() {
        let mut entity = SceneEntity::new(
            at,
            format!(
                "test {} segment {}",
                segment.test_index, segment.segment_index
            ),
        );
        entity.lines.push(line(
            0,
            segment
                .points
                .iter()
                .map(|p| Vector3 {
                    x: p.x,
                    y: p.y,
                    z: 0.0,
                })
                .collect(),
            0.05,
            ROUTE,
        ));
        return Some(Derived::Route(RouteScene(SceneUpdate {
            deletions: Vec::new(),
            entities: vec![entity],
        })));
    }
    if let Some(event) = any.downcast_ref::<TestEvent>() {
        let (level, text) = match &event.event {
            TestEventKind::Started { .. } => {
                // A new test: the planned route of the one before goes.
                let clear = RouteScene(SceneUpdate {
                    deletions: vec![SceneEntityDeletion {
                        timestamp: at,
                        kind: 1,
                        id: String::new(),
                    }],
                    entities: Vec::new(),
                });
                return Some(Derived::Route(clear));
            }
            TestEventKind::Ended { verdict, reason } => (
                match verdict {
                    campaign::oracle::Verdict::Passed => INFO,
                    campaign::oracle::Verdict::Failed => ERROR,
                    campaign::oracle::Verdict::Aborted => WARNING,
                },
                format!(
                    "test {} {}{}",
                    event.test_index,
                    verdict.as_str(),
                    reason
                        .as_deref()
                        .map_or_else(String::new, |r| format!(": {r}"))
                ),
            ),
        };
        return Some(Derived::Log(Log::new(at, level, text)));
    }
    if let Some(fault) = any.downcast_ref::<FaultRecord>() {
        let f = &fault.fault;
        let what = format!(
            "test {} command {}: {} {} {}",
            fault.test_index, fault.command_index, f.probe, f.kind, f.param
        );
        let (level, text) = match &fault.status {
            FaultStatus::Sent => (INFO, format!("{what} sent")),
            FaultStatus::Confirmed => (INFO, format!("{what} confirmed by the car")),
            FaultStatus::Refused { error } => (WARNING, format!("{what} not added: {error}")),
            FaultStatus::Placed { placement } => (
                INFO,
                format!(
                    "{what} acted from {:.2} s to {:.2} s (placed {} m off its place)",
                    placement.acts_from_s,
                    placement.acts_to_s,
                    placement
                        .error_m
                        .map_or_else(|| "?".to_owned(), |e| format!("{e:+.2}"))
                ),
            ),
        };
        return Some(Derived::Log(Log::new(at, level, text)));
    }
    if let Some(stop) = any.downcast_ref::<SafetyRecord>() {
        return Some(Derived::Log(Log::new(
            at,
            WARNING,
            format!("safety: {}", stop.message),
        )));
    }
    None
}

/// The RTK and UWB poses of a state sample, each where its position is finite (a pose without
/// one is not written: Foxglove would draw it at the origin; `/car/state` then holds the
/// position). The RTK pose heads the RTK yaw; the UWB estimate has no heading of its own, so its
/// pose has the identity orientation. These channels are where a version-3 recording keeps the
/// sample's RTK and UWB positions (`super::proto`).
pub(super) fn poses(state: &CarStateRecord, at: Time) -> (Option<RtkPose>, Option<UwbPose>) {
    // The firmware's yaw turns clockwise from east; a pose's counter-clockwise.
    let yaw = (-state.rtk.yaw_deg).to_radians();
    let pose = |x: f64, y: f64, yaw: f64| {
        has_pose(x, y).then(|| PoseInFrame {
            timestamp: at,
            frame_id: (),
            pose: Pose::at(x, y, if yaw.is_finite() { yaw } else { 0.0 }),
        })
    };
    (
        pose(state.rtk.x, state.rtk.y, yaw).map(RtkPose),
        pose(state.uwb.x, state.uwb.y, 0.0).map(UwbPose),
    )
}

/// Whether a position gets a pose on `/foxglove/rtk` or `/foxglove/uwb`: when it is finite.
pub(super) fn has_pose(x: f64, y: f64) -> bool {
    x.is_finite() && y.is_finite()
}
