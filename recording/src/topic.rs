//! The channels of a recording: their topic names and which record type each carries.

use std::fmt;

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::{Recording, RecordingError, Stamped};

/// A channel of a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Topic {
    /// `/car/state`: every state sample the car answered ([`super::CarStateRecord`]).
    CarState,
    /// `/commands`: every command sent to the car, fault commands aside ([`super::CommandSent`]).
    Commands,
    /// `/acks`: the car's answer to each command ([`super::CommandAck`]).
    Acks,
    /// `/tests`: a test started or ended ([`super::TestEvent`]).
    Tests,
    /// `/plan/segments`: each segment as planned ([`super::PlannedSegment`]).
    PlanSegments,
    /// `/plan/return_route`: each return route as planned ([`super::PlannedReturnRoute`]).
    PlanReturnRoute,
    /// `/faults`: fault commands and their confirmation ([`super::FaultRecord`]).
    Faults,
    /// `/oracle/segments`: the oracle's result per driven segment ([`super::OracleRecord`]).
    OracleSegments,
    /// `/safety/events`: the stops the safety monitor demanded ([`super::SafetyRecord`]).
    SafetyEvents,
    /// `/sim/truth`: the simulated car's true pose and estimates ([`super::TruthRecord`]).
    SimTruth,
    /// `/sim/ranges`: every simulated UWB range and its fate ([`super::SimRange`]).
    SimRanges,
    /// `/sim/faults`: each fault application inside the simulator ([`super::SimFault`]).
    SimFaults,
    /// `/sim/events`: the simulated firmware's watchdog and quirk events ([`super::SimEvent`]).
    SimEvents,
    /// `/foxglove/area`: the area in Foxglove's `SceneUpdate` ([`super::foxglove::AreaScene`]).
    FoxgloveArea,
    /// `/foxglove/route`: each test's planned segments in `SceneUpdate`.
    FoxgloveRoute,
    /// `/foxglove/rtk`: the RTK pose of every state sample in `PoseInFrame`.
    FoxgloveRtk,
    /// `/foxglove/uwb`: the UWB pose of every state sample in `PoseInFrame`.
    FoxgloveUwb,
    /// `/foxglove/log`: faults, tests and safety stops in Foxglove's `Log`.
    FoxgloveLog,
}

impl Topic {
    /// Every channel, in registration order.
    pub const ALL: [Topic; 18] = [
        Topic::CarState,
        Topic::Commands,
        Topic::Acks,
        Topic::Tests,
        Topic::PlanSegments,
        Topic::PlanReturnRoute,
        Topic::Faults,
        Topic::OracleSegments,
        Topic::SafetyEvents,
        Topic::SimTruth,
        Topic::SimRanges,
        Topic::SimFaults,
        Topic::SimEvents,
        Topic::FoxgloveArea,
        Topic::FoxgloveRoute,
        Topic::FoxgloveRtk,
        Topic::FoxgloveUwb,
        Topic::FoxgloveLog,
    ];

    /// Whether a live viewer that joins late gets the topic's last message: the area and the
    /// route, which are made once a campaign (the area) or a test (a route); the live view sends
    /// them again as each test starts and ends.
    pub fn is_latched(self) -> bool {
        matches!(self, Topic::FoxgloveArea | Topic::FoxgloveRoute)
    }

    /// The topic name (`/car/state`, …).
    pub fn name(self) -> &'static str {
        match self {
            Topic::CarState => "/car/state",
            Topic::Commands => "/commands",
            Topic::Acks => "/acks",
            Topic::Tests => "/tests",
            Topic::PlanSegments => "/plan/segments",
            Topic::PlanReturnRoute => "/plan/return_route",
            Topic::Faults => "/faults",
            Topic::OracleSegments => "/oracle/segments",
            Topic::SafetyEvents => "/safety/events",
            Topic::SimTruth => "/sim/truth",
            Topic::SimRanges => "/sim/ranges",
            Topic::SimFaults => "/sim/faults",
            Topic::SimEvents => "/sim/events",
            Topic::FoxgloveArea => "/foxglove/area",
            Topic::FoxgloveRoute => "/foxglove/route",
            Topic::FoxgloveRtk => "/foxglove/rtk",
            Topic::FoxgloveUwb => "/foxglove/uwb",
            Topic::FoxgloveLog => "/foxglove/log",
        }
    }

    /// The channel's schema name (`drivecheck.CarState`, …; Foxglove's well-known names for the
    /// `/foxglove/*` channels).
    pub fn schema_name(self) -> &'static str {
        match self {
            Topic::CarState => "drivecheck.CarState",
            Topic::Commands => "drivecheck.CommandSent",
            Topic::Acks => "drivecheck.CommandAck",
            Topic::Tests => "drivecheck.TestEvent",
            Topic::PlanSegments => "drivecheck.PlannedSegment",
            Topic::PlanReturnRoute => "drivecheck.PlannedReturnRoute",
            Topic::Faults => "drivecheck.Fault",
            Topic::OracleSegments => "drivecheck.OracleSegment",
            Topic::SafetyEvents => "drivecheck.SafetyEvent",
            Topic::SimTruth => "drivecheck.SimTruth",
            Topic::SimRanges => "drivecheck.SimRange",
            Topic::SimFaults => "drivecheck.SimFault",
            Topic::SimEvents => "drivecheck.SimEvent",
            Topic::FoxgloveArea | Topic::FoxgloveRoute => "foxglove.SceneUpdate",
            Topic::FoxgloveRtk | Topic::FoxgloveUwb => "foxglove.PoseInFrame",
            Topic::FoxgloveLog => "foxglove.Log",
        }
    }

    /// The channel for `name`, if it is one of ours.
    pub fn from_name(name: &str) -> Option<Topic> {
        Topic::ALL.into_iter().find(|t| t.name() == name)
    }

    /// How this build encodes the channel's messages: protobuf for the channels written at every
    /// state sample and for every simulated range (`docs/recording.md`, *The encodings*), JSON
    /// for the rest.
    pub fn encoding(self) -> Encoding {
        match self {
            Topic::CarState
            | Topic::SimTruth
            | Topic::SimRanges
            | Topic::FoxgloveRtk
            | Topic::FoxgloveUwb => Encoding::Protobuf,
            _ => Encoding::Json,
        }
    }

    /// Whether only a simulated run records this channel.
    pub fn is_simulator_only(self) -> bool {
        matches!(
            self,
            Topic::SimTruth | Topic::SimRanges | Topic::SimFaults | Topic::SimEvents
        )
    }
}

impl fmt::Display for Topic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A channel's message encoding (MCAP's `message_encoding`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Encoding {
    /// `json`, with a JSON schema (`jsonschema`).
    Json,
    /// `protobuf`, with a `FileDescriptorSet` schema (`protobuf`).
    Protobuf,
}

impl Encoding {
    /// The name MCAP gives it (`json`, `protobuf`).
    pub fn name(self) -> &'static str {
        match self {
            Encoding::Json => "json",
            Encoding::Protobuf => "protobuf",
        }
    }

    /// The encoding named `name`, if it is one drivecheck writes.
    pub fn from_name(name: &str) -> Option<Self> {
        [Encoding::Json, Encoding::Protobuf]
            .into_iter()
            .find(|e| e.name() == name)
    }
}

/// A message type of a recording: the record one channel carries. Every record is JSON in
/// recordings of version 1 and 2; the channels [`Topic::encoding`] names protobuf are
/// protobuf from version 3 on.
pub trait Record: Serialize + DeserializeOwned + Clone + Send + 'static {
    /// Its channel.
    const TOPIC: Topic;

    /// The message in its channel's encoding ([`Topic::encoding`]).
    fn encode(&self) -> Result<Vec<u8>, RecordingError> {
        serde_json::to_vec(self).map_err(|source| RecordingError::Encode {
            topic: Self::TOPIC.name(),
            source,
        })
    }

    /// The record of a protobuf message; `None` for a record that is never protobuf.
    fn from_protobuf(_data: &[u8]) -> Option<Result<Self, super::ProtobufError>> {
        None
    }

    /// Every message of the channel in `recording`, decoded (the state samples join the pose
    /// channels here).
    fn read_all(recording: &Recording) -> Result<Vec<Stamped<Self>>, RecordingError> {
        recording.decode_each::<Self>()
    }
}
