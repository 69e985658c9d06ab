//! A campaign's telemetry recording: an MCAP file written as things happen, readable in Foxglove,
//! the `mcap` CLI or any MCAP library.
//!
//! A [`Recorder`] opens the file at campaign start, writes one message per event on the
//! channel of its [`Topic`] (car state samples, commands and acks, planned segments and return
//! routes, faults and their confirmation, oracle results, safety events, test starts and ends, and
//! in a simulated run the simulator's hidden truth), and is finished at campaign end. The scenario
//! and the campaign are MCAP metadata records. The channels written at every state sample
//! (`/car/state`, `/sim/truth`, `/foxglove/rtk`, `/foxglove/uwb`) are protobuf with a
//! `FileDescriptorSet` schema (`proto`; nothing is written on two of them); every other channel
//! carries a JSON schema (`jsonschema` encoding) and JSON messages (`json` encoding).
//!
//! Log time: nanoseconds of the run's tokio clock since the campaign started (the `origin` the
//! recorder is created with). In a virtual-time run the recording is therefore deterministic.
//!
//! Crash safety: messages collect in an in-memory chunk which is written and flushed whole when
//! it spans [`RecordingStart::chunk_interval`] of log time, at [`Recorder::flush`] and before
//! every metadata record. A killed process leaves a file that [`Recording`] (and `mcap`'s
//! readers) read up to the last chunk written; dropping a recorder without [`Recorder::finish`]
//! still completes the file.
//!
//! [`Recording`] reads a file back whole (also a cut-short one) for tests and small files;
//! [`Spans`] reads it from the file a test at a time and [`Summary`] learns what it holds without
//! keeping its messages, so that a command's memory does not grow with the campaign. The format
//! is documented channel by channel in `docs/recording.md`.
//!
//! Not here: deciding what to record when (the campaign runner), replay.

pub mod foxglove;
pub mod live;
mod mcap_out;
mod profile;
mod proto;
mod reader;
mod records;
mod schema;
#[cfg(test)]
mod stream_tests;
#[cfg(test)]
mod tests;
mod topic;
mod writer;

use std::path::PathBuf;

use thiserror::Error;

pub use profile::{DEFAULT_PROFILE, LoadedProfile, LoadedProfileError};
pub use reader::{
    Recording, RecordingChannel, Span, Spans, Stamped, Summary, recorded_scenario, recorded_seed,
};
pub use records::{
    AckOutcome, CarCommand, CarStateRecord, CommandAck, CommandSent, FaultRecord, FaultSpec,
    FaultStatus, OracleRecord, PlannedReturnRoute, PlannedSegment, Pose, Position, RadioPathKind,
    RadioPathRecord, RangeOutcome, SafetyRecord, SimEvent, SimEventKind, SimFault, SimRange,
    TestEvent, TestEventKind, TruthRecord,
};
pub use topic::{Encoding, Record, Topic};
pub use writer::{
    DEFAULT_CHUNK_INTERVAL, FinishedRecording, Held, Recorder, RecordingStart,
    SIM_PROFILE_METADATA, TEST_SPAN_PREFIX,
};

/// The `format` in a recording's `drivecheck.recording` metadata record.
pub const RECORDING_FORMAT: &str = "drivecheck-recording";
/// The recording format version this build writes.
///
/// Version 2 leaves a value out where version 1 wrote `null` (a number that was not finite, an
/// absent option), so that every field has one type in the channels' schemas. Version 3 writes
/// the channels of every state sample in protobuf, each value once (`proto`); version 4 also
/// `/sim/ranges` (every simulated range). Each channel names its encoding, so a reader takes
/// every version's channels as they are.
pub const RECORDING_VERSION: u32 = 4;
/// The recording format versions this build reads (a version-1 `null` is read as before).
pub const READABLE_RECORDING_VERSIONS: [u32; 4] = [1, 2, 3, 4];

/// Why a protobuf message is not its channel's record.
#[derive(Debug, Error)]
pub enum ProtobufError {
    /// Not a protobuf message of the channel's type (what prost said).
    #[error(transparent)]
    Decode(#[from] prost::DecodeError),
    /// A field holds a number that stands for none of its record's values.
    #[error("field {field}: {value} stands for no value")]
    Value {
        /// The field.
        field: &'static str,
        /// The number.
        value: u64,
    },
}

/// Why a recording could not be written or read.
#[derive(Debug, Error)]
pub enum RecordingError {
    /// The file could not be created.
    #[error("cannot create {path}: {source}")]
    Create {
        /// The file.
        path: PathBuf,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
    /// Writing failed (disk full, closed file, …); the recorder refuses further writes.
    #[error("cannot write the recording: {0}")]
    Write(#[source] std::io::Error),
    /// The final flush or sync of the file failed.
    #[error("cannot complete the recording: {0}")]
    Complete(#[source] std::io::Error),
    /// A message could not be encoded as JSON.
    #[error("cannot encode a {topic} message: {source}")]
    Encode {
        /// The channel.
        topic: &'static str,
        /// What serde said.
        #[source]
        source: serde_json::Error,
    },
    /// The campaign record could not be written as JSON.
    #[error("cannot encode the campaign record: {0}")]
    Campaign(#[source] campaign::files::CaseError),
    /// The bytes do not start like an MCAP file.
    #[error("not an MCAP file: {0}")]
    NotMcap(#[source] mcap::McapError),
    /// The file is not a drivecheck recording this build reads (its `drivecheck.recording`
    /// metadata record is absent or names another format or version).
    #[error(
        "not a drivecheck recording of version 1, 2, 3 or 4 \
         (format {format:?}, schema_version {version:?})"
    )]
    UnsupportedFormat {
        /// The `format` found.
        format: Option<String>,
        /// The `schema_version` found.
        version: Option<String>,
    },
    /// A message does not decode as its channel's record.
    #[error("{topic} message {index}: {source}")]
    Decode {
        /// The channel.
        topic: &'static str,
        /// The message's position among the channel's messages, from 0.
        index: usize,
        /// What serde said.
        #[source]
        source: serde_json::Error,
    },
    /// A protobuf message does not decode as its channel's record.
    #[error("{topic} message {index}: {source}")]
    DecodeProtobuf {
        /// The channel.
        topic: &'static str,
        /// The message's position among the channel's messages, from 0.
        index: usize,
        /// What is wrong with it.
        #[source]
        source: ProtobufError,
    },
    /// A channel's messages are in an encoding this build does not read for it.
    #[error("{topic}: messages in {encoding:?}, which drivecheck does not read on this channel")]
    UnknownEncoding {
        /// The channel.
        topic: &'static str,
        /// The channel's `message_encoding`.
        encoding: String,
    },
    /// Messages recorded in another encoding than this build writes (a recording of another
    /// version), which cannot go into a recording this build writes (`runs merge`).
    #[error(
        "{topic}: a message in {found} cannot go into a recording of version {version}, which \
         writes {expected}: the shards were recorded by another drivecheck version"
    )]
    MixedEncoding {
        /// The channel.
        topic: &'static str,
        /// The message's encoding.
        found: &'static str,
        /// The channel's encoding in this version.
        expected: &'static str,
        /// This build's recording version.
        version: u32,
    },
}
