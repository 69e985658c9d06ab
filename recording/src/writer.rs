//! The [`Recorder`]: writes a campaign's MCAP file append-only as things happen.
//!
//! Messages go into an in-memory chunk (compressed with zstd) that is written whole and flushed to the
//! operating system when its messages span the chunk interval of log time, at [`Recorder::flush`]
//! and before each metadata record. The file therefore only ever grows by whole records: a killed
//! process leaves every chunk written before the kill, and loses the open one.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;
use std::time::Duration;

use car_link::StateSample;
use car_sim::{DebugEvent, Truth};
use scenarios::Scenario;
use tokio::time::Instant;

use super::live::LiveView;
use super::mcap_out::McapOut;
use super::records::{
    AckOutcome, CarCommand, CarStateRecord, CommandAck, CommandSent, SimRecord, TruthRecord,
    nanos_since,
};
use super::topic::{Encoding, Record, Topic};
use super::{RECORDING_FORMAT, RECORDING_VERSION, RecordingError, foxglove, schema};
use campaign::files::{CampaignRecord, tool_version};

/// The default [`RecordingStart::chunk_interval`]: at most one second of messages is lost when the
/// process is killed while messages flow.
pub const DEFAULT_CHUNK_INTERVAL: Duration = Duration::from_secs(1);

/// The name of a test's span metadata record, before the test's index ([`Recorder::test_span`]).
pub const TEST_SPAN_PREFIX: &str = "drivecheck.test.";

/// Chunks are also closed when they reach this many bytes.
const CHUNK_BYTES: usize = 256 * 1024;

/// The chunks' zstd level (`docs/recording.md`, *Size and speed*).
const ZSTD_LEVEL: i32 = 1;

type Sink = BufWriter<File>;

/// The name of the metadata record that holds a simulated car's profile (the simulator's truth,
/// like the `/sim/*` channels: `drivecheck calibrate` never reads it).
pub const SIM_PROFILE_METADATA: &str = "drivecheck.sim.profile";

/// What a recording starts with.
#[derive(Debug, Clone)]
pub struct RecordingStart<'a> {
    /// The campaign (`campaign.json` as written at its start): a metadata record.
    pub campaign: &'a CampaignRecord,
    /// The scenario: its canonical TOML and hash in a metadata record.
    pub scenario: &'a Scenario,
    /// The instant the campaign started on the run's tokio clock: log time 0.
    pub origin: Instant,
    /// A simulated run: the `/sim/*` channels are registered.
    pub simulated: bool,
    /// The longest span of log time one chunk holds ([`DEFAULT_CHUNK_INTERVAL`]).
    pub chunk_interval: Duration,
    /// Where every message is also served as it is written (`run --live`).
    pub live: Option<&'a LiveView>,
    /// Every test's messages are followed by a `drivecheck.test.<index>` record of their span
    /// (a campaign on fresh simulated cars; see [`Recorder::test_span`]).
    pub test_spans: bool,
    /// The simulated car's profile, the simulator's truth: a `drivecheck.sim.profile` metadata
    /// record (its name, hash and canonical TOML).
    pub sim_profile: Option<&'a crate::LoadedProfile>,
}

/// What [`Recorder::finish`] wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FinishedRecording {
    /// Messages on all channels.
    pub messages: u64,
    /// Chunks.
    pub chunks: u32,
}

/// The topics a recording has: all but the simulator's in a run on a real car.
pub(super) fn recorded_topics(simulated: bool) -> impl Iterator<Item = Topic> {
    Topic::ALL
        .into_iter()
        .filter(move |t| simulated || !t.is_simulator_only())
}

/// The live view's channel of every recorded topic (none without a live view).
fn live_channels(
    simulated: bool,
    live: Option<&LiveView>,
) -> HashMap<Topic, super::live::LiveChannel> {
    let Some(view) = live else {
        return HashMap::new();
    };
    recorded_topics(simulated)
        .filter_map(|topic| Some((topic, view.channel(topic, &schema::channel_schema(topic))?)))
        .collect()
}

/// A message encoded but not written yet: what a test's recording holds until its verdict
/// decides whether it is kept (`run --record failing`), or what a test run on a fresh simulated
/// car in a worker thread hands to the campaign's recording (`run --jobs`).
#[derive(Debug, Clone, PartialEq)]
pub struct Held {
    topic: Topic,
    /// How `data` is encoded.
    encoding: Encoding,
    /// Log time, ns since the origin of the recorder that encoded it.
    log_time: u64,
    data: Vec<u8>,
}

impl Held {
    /// A message on `topic` at `log_time` with its bytes, encoded as this build encodes the
    /// topic ([`Topic::encoding`]).
    pub fn new(topic: Topic, log_time: u64, data: Vec<u8>) -> Self {
        Self::encoded_as(topic, topic.encoding(), log_time, data)
    }

    /// A message on `topic` at `log_time` with its bytes in `encoding` (read from a recording,
    /// perhaps of another version).
    pub fn encoded_as(topic: Topic, encoding: Encoding, log_time: u64, data: Vec<u8>) -> Self {
        Self {
            topic,
            encoding,
            log_time,
            data,
        }
    }

    /// How its bytes are encoded.
    pub fn encoding(&self) -> Encoding {
        self.encoding
    }

    /// Its log time (ns since the origin of the recorder that encoded it).
    pub fn log_time(&self) -> u64 {
        self.log_time
    }

    /// Its channel's topic.
    pub fn topic(&self) -> Topic {
        self.topic
    }

    /// Its encoded bytes.
    pub fn data(&self) -> &[u8] {
        &self.data
    }

    /// Its encoded bytes, taken.
    pub fn into_data(self) -> Vec<u8> {
        self.data
    }
}

/// A record kept as it is until it is known to be written: encoding is most of what recording
/// costs, and `run --record failing` drops the messages of every test that passed.
trait Deferred: Send {
    fn encode_now(&self) -> Result<Vec<u8>, RecordingError>;
}

impl<R: Record> Deferred for R {
    fn encode_now(&self) -> Result<Vec<u8>, RecordingError> {
        Record::encode(self)
    }
}

/// A message held: encoded already (it was served live), or not yet.
enum Pending {
    Encoded(Held),
    Deferred {
        topic: Topic,
        log_time: u64,
        record: Box<dyn Deferred>,
    },
}

impl Pending {
    fn encoded(self) -> Result<Held, RecordingError> {
        match self {
            Pending::Encoded(held) => Ok(held),
            Pending::Deferred {
                topic,
                log_time,
                record,
            } => Ok(Held::new(topic, log_time, record.encode_now()?)),
        }
    }
}

/// A campaign's recording being written (see the module doc), or a test's recording held in
/// memory ([`Recorder::in_memory`]).
///
/// Every write is synchronous and small (a JSON encoding into memory; a chunk write to the OS
/// page cache once per chunk interval). Dropping a recorder without [`Recorder::finish`]
/// completes the file as well, ignoring errors.
pub struct Recorder {
    /// The file; `None` for a recorder in memory.
    writer: Option<McapOut<Sink>>,
    channels: HashMap<Topic, u16>,
    /// Messages recorded while held ([`Recorder::hold`]), or always for a recorder in memory;
    /// encoded when written or taken.
    held: Option<Vec<Pending>>,
    /// A recording of a simulated car: the `/sim/*` channels are recorded.
    simulated: bool,
    sequences: HashMap<Topic, u32>,
    origin: Instant,
    chunk_interval: u64,
    chunk_opened_at: Option<u64>,
    next_command: u64,
    pending_commands: BTreeMap<u64, (u64, &'static str)>,
    sim_offset_ns: Option<i128>,
    /// The live view's channels (`run --live`), by topic.
    live: HashMap<Topic, super::live::LiveChannel>,
}

impl Drop for Recorder {
    /// Completes the file (see [`Recorder`]); an error is ignored, as the file is then cut
    /// short, which readers say.
    fn drop(&mut self) {
        if let Some(writer) = self.writer.take() {
            let _ = writer.finish();
        }
    }
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("channels", &self.channels)
            .field("origin", &self.origin)
            .finish_non_exhaustive()
    }
}

impl Recorder {
    /// Creates the file at `path` (replacing one there), registers the channels with their
    /// schemas, writes the metadata records and flushes: the file is readable from here on.
    pub fn create(path: &Path, start: &RecordingStart<'_>) -> Result<Self, RecordingError> {
        let file = File::create(path).map_err(|source| RecordingError::Create {
            path: path.to_owned(),
            source,
        })?;
        let writer = McapOut::new(
            BufWriter::with_capacity(1 << 16, file),
            &format!("drivecheck {}", tool_version()),
            CHUNK_BYTES,
            ZSTD_LEVEL,
        )
        .map_err(RecordingError::Write)?;
        let mut recorder = Self {
            writer: Some(writer),
            channels: HashMap::new(),
            held: None,
            simulated: start.simulated,
            sequences: HashMap::new(),
            origin: start.origin,
            chunk_interval: u64::try_from(start.chunk_interval.as_nanos()).unwrap_or(u64::MAX),
            chunk_opened_at: None,
            next_command: 1,
            pending_commands: BTreeMap::new(),
            sim_offset_ns: None,
            live: live_channels(start.simulated, start.live),
        };
        recorder.register_channels(start.simulated)?;
        recorder.write_start_metadata(start)?;
        recorder.write_at_ns(
            0,
            &foxglove::area(start.scenario, foxglove::Time::from_ns(0)),
        )?;
        recorder.flush()?;
        Ok(recorder)
    }

    /// A recorder that keeps every message in memory (see [`Held`]), with log times from
    /// `origin` and command ids from `first_command`: a test run in a worker thread records
    /// through it, and the campaign's recorder writes what it kept ([`Recorder::write_held`]).
    /// `live` serves every message as it is encoded.
    pub fn in_memory(
        origin: Instant,
        simulated: bool,
        first_command: u64,
        live: Option<&LiveView>,
    ) -> Self {
        Self {
            writer: None,
            channels: HashMap::new(),
            held: Some(Vec::new()),
            simulated,
            sequences: HashMap::new(),
            origin,
            chunk_interval: u64::MAX,
            chunk_opened_at: None,
            next_command: first_command,
            pending_commands: BTreeMap::new(),
            sim_offset_ns: None,
            live: live_channels(simulated, live),
        }
    }

    /// A recorder that keeps nothing and only serves every message live (`run --live --record
    /// none`), with log times from `origin` and command ids from `first_command`; `scenario`,
    /// when given, goes out first as the area (which the live view latches for late joiners).
    pub fn live_only(
        origin: Instant,
        simulated: bool,
        first_command: u64,
        live: &LiveView,
        scenario: Option<&Scenario>,
    ) -> Result<Self, RecordingError> {
        let mut recorder = Self::in_memory(origin, simulated, first_command, Some(live));
        recorder.held = None;
        if let Some(scenario) = scenario {
            recorder.write_at_ns(0, &foxglove::area(scenario, foxglove::Time::from_ns(0)))?;
        }
        Ok(recorder)
    }

    /// From now on, messages are held in memory instead of written, until [`Recorder::release`].
    pub fn hold(&mut self) {
        self.held.get_or_insert_with(Vec::new);
    }

    /// Ends holding: writes the held messages when `keep` (in order, with their log times),
    /// drops them otherwise. A recorder in memory keeps holding; nothing is written.
    pub fn release(&mut self, keep: bool) -> Result<(), RecordingError> {
        if self.writer.is_none() {
            return Ok(());
        }
        let held = self.held.take().unwrap_or_default();
        if keep {
            for pending in held {
                let held = pending.encoded()?;
                self.write_to_chunk(held.topic, held.log_time, &held.data)?;
            }
        }
        Ok(())
    }

    /// Takes the messages held so far, encoded.
    pub fn take_held(&mut self) -> Result<Vec<Held>, RecordingError> {
        let pending = self.held.as_mut().map(std::mem::take).unwrap_or_default();
        pending.into_iter().map(Pending::encoded).collect()
    }

    /// Drops the messages held so far without encoding them.
    pub fn drop_held(&mut self) {
        if let Some(held) = &mut self.held {
            held.clear();
        }
    }

    /// Writes messages another recorder held, their log times shifted by `offset_ns`; they are
    /// not served live again. A recorder in memory holds them.
    pub fn write_held(&mut self, held: Vec<Held>, offset_ns: u64) -> Result<(), RecordingError> {
        for message in held {
            if message.encoding != message.topic.encoding() {
                return Err(RecordingError::MixedEncoding {
                    topic: message.topic.name(),
                    found: message.encoding.name(),
                    expected: message.topic.encoding().name(),
                    version: RECORDING_VERSION,
                });
            }
            let log_time = message.log_time.wrapping_add(offset_ns);
            if self.held.is_some() {
                self.write_data(message.topic, log_time, message.data)?;
            } else {
                self.write_to_chunk(message.topic, log_time, &message.data)?;
            }
        }
        Ok(())
    }

    fn register_channels(&mut self, simulated: bool) -> Result<(), RecordingError> {
        let Some(writer) = &mut self.writer else {
            return Ok(());
        };
        for topic in recorded_topics(simulated) {
            let schema = schema::channel_schema(topic);
            let schema_id = writer
                .add_schema(topic.schema_name(), schema.encoding, &schema.data)
                .map_err(RecordingError::Write)?;
            let channel = writer
                .add_channel(schema_id, topic.name(), topic.encoding().name())
                .map_err(RecordingError::Write)?;
            self.channels.insert(topic, channel);
        }
        Ok(())
    }

    fn write_start_metadata(&mut self, start: &RecordingStart<'_>) -> Result<(), RecordingError> {
        let recording = [
            ("format", RECORDING_FORMAT.to_owned()),
            ("schema_version", RECORDING_VERSION.to_string()),
            ("tool_version", tool_version().to_owned()),
            (
                "log_time",
                "ns of the run's tokio clock since the campaign started".to_owned(),
            ),
            ("simulated", start.simulated.to_string()),
            ("test_spans", start.test_spans.to_string()),
        ];
        self.metadata("drivecheck.recording", &recording)?;
        let s = start.scenario;
        let scenario = [
            ("name", s.name.clone()),
            ("hash", s.hash()),
            ("toml", s.to_toml()),
        ];
        self.metadata("drivecheck.scenario", &scenario)?;
        if let Some(profile) = start.sim_profile {
            let entries = [
                ("name", profile.name.clone()),
                ("hash", profile.profile.hash()),
                ("toml", profile.profile.to_toml()),
            ];
            self.metadata(SIM_PROFILE_METADATA, &entries)?;
        }
        self.campaign_metadata("drivecheck.campaign", start.campaign)
    }

    /// Writes `campaign` (as it stands at the end, with its summary) as the
    /// `drivecheck.campaign_end` metadata record. Call it before [`Recorder::finish`].
    pub fn campaign_ended(&mut self, campaign: &CampaignRecord) -> Result<(), RecordingError> {
        self.campaign_metadata("drivecheck.campaign_end", campaign)
    }

    fn campaign_metadata(
        &mut self,
        name: &str,
        campaign: &CampaignRecord,
    ) -> Result<(), RecordingError> {
        let json = campaign.to_json().map_err(RecordingError::Campaign)?;
        let entries = [
            ("seed", campaign.seed.to_string()),
            ("car", campaign.car.clone()),
            ("started_at", campaign.started_at.clone()),
            ("no_faults", campaign.no_faults.to_string()),
            ("json", json),
        ];
        self.metadata(name, &entries)
    }

    /// Records that test `test_index`'s messages span `start_ns..=end_ns` of log time (a
    /// `drivecheck.test.<index>` metadata record): how `drivecheck runs merge` finds each test's
    /// messages in a shard's recording. On several cars, `car` names the car that drove it
    /// (a `car` entry).
    pub fn test_span(
        &mut self,
        test_index: usize,
        start_ns: u64,
        end_ns: u64,
        car: Option<&str>,
    ) -> Result<(), RecordingError> {
        let mut entries = vec![
            ("test_index", test_index.to_string()),
            ("start_ns", start_ns.to_string()),
            ("end_ns", end_ns.to_string()),
        ];
        if let Some(car) = car {
            entries.push(("car", car.to_owned()));
        }
        self.metadata(&format!("{TEST_SPAN_PREFIX}{test_index}"), &entries)
    }

    /// Copies a span another recording holds (`Spans`) into this one, its log times shifted by
    /// `shift_ns`: its messages, then its test's span record (moved by the same shift), or, for
    /// messages no test claims, a flush. The one way a recording is copied into another (a
    /// resumed campaign's earlier sessions, `runs merge`'s shards).
    pub fn copy_span(&mut self, span: crate::Span, shift_ns: u64) -> Result<(), RecordingError> {
        let start_ns = span.start_ns.wrapping_add(shift_ns);
        let end_ns = span.end_ns.wrapping_add(shift_ns);
        self.write_held(span.messages, shift_ns)?;
        match span.test_index {
            Some(test_index) => self.test_span(test_index, start_ns, end_ns, span.car.as_deref()),
            None => self.flush(),
        }
    }

    /// Writes a metadata record (which closes the open chunk) and flushes.
    fn metadata(&mut self, name: &str, entries: &[(&str, String)]) -> Result<(), RecordingError> {
        if let Some(writer) = &mut self.writer {
            writer
                .write_metadata(name, entries)
                .map_err(RecordingError::Write)?;
        }
        self.flush()
    }

    /// Moves the origin `ns` earlier, so that every message recorded from now on has a log time
    /// after `ns` (a resumed campaign's, after the sessions before: `run --resume`). The tokio
    /// clock cannot go before its start; the origin then moves as far as it can.
    pub fn continue_after(&mut self, ns: u64) {
        let mut back = Duration::from_nanos(ns);
        while !back.is_zero() {
            if let Some(origin) = self.origin.checked_sub(back) {
                self.origin = origin;
                return;
            }
            back /= 2;
        }
    }

    /// The log time of now: ns of the tokio clock since the origin.
    pub fn now_ns(&self) -> u64 {
        nanos_since(self.origin, Instant::now())
    }

    /// Records `message` on its channel at the current tokio time.
    pub fn write<R: Record>(&mut self, message: &R) -> Result<(), RecordingError> {
        self.write_at_ns(self.now_ns(), message)
    }

    /// Records `message` on its channel at `at` on the tokio clock.
    pub fn write_at<R: Record>(&mut self, at: Instant, message: &R) -> Result<(), RecordingError> {
        self.write_at_ns(nanos_since(self.origin, at), message)
    }

    /// Records `message` with log time `log_time` (ns since the origin). A message for a channel
    /// that is not registered (`/sim/*` in a run on a real car) is ignored.
    fn write_at_ns<R: Record>(&mut self, log_time: u64, message: &R) -> Result<(), RecordingError> {
        self.write_one(log_time, message)?;
        match foxglove::derived(message, foxglove::Time::from_ns(log_time)) {
            Some(foxglove::Derived::Route(route)) => self.write_one(log_time, &route),
            Some(foxglove::Derived::Log(log)) => self.write_one(log_time, &log),
            None => Ok(()),
        }
    }

    /// Records `message` alone (nothing derived from it).
    fn write_one<R: Record>(&mut self, log_time: u64, message: &R) -> Result<(), RecordingError> {
        if R::TOPIC.is_simulator_only() && !self.simulated {
            return Ok(());
        }
        let live = self.live.get(&R::TOPIC);
        if let (Some(held), None) = (&mut self.held, live) {
            held.push(Pending::Deferred {
                topic: R::TOPIC,
                log_time,
                record: Box::new(message.clone()),
            });
            return Ok(());
        }
        let data = message.encode()?;
        if let Some(channel) = live {
            channel.log(&data);
            if R::TOPIC == Topic::Tests {
                // A test starts or ends: the area and the route again, for a viewer that lost
                // them.
                channel.repeat_latched();
            }
        }
        self.write_data(R::TOPIC, log_time, data)
    }

    /// Writes (or holds) one encoded message.
    fn write_data(
        &mut self,
        topic: Topic,
        log_time: u64,
        data: Vec<u8>,
    ) -> Result<(), RecordingError> {
        if let Some(held) = &mut self.held {
            held.push(Pending::Encoded(Held::new(topic, log_time, data)));
            return Ok(());
        }
        self.close_chunk_if_due(log_time)?;
        self.write_to_chunk(topic, log_time, &data)
    }

    /// Writes one encoded message into the open chunk, whatever log time it spans: a test
    /// written whole at once (held, or recorded in a worker thread) is as safe in one chunk as
    /// in many, and compresses better (the chunk then closes at [`CHUNK_BYTES`] or at the
    /// test's end).
    fn write_to_chunk(
        &mut self,
        topic: Topic,
        log_time: u64,
        data: &[u8],
    ) -> Result<(), RecordingError> {
        let Some(&channel_id) = self.channels.get(&topic) else {
            return Ok(());
        };
        let sequence = self.sequences.entry(topic).or_insert(0);
        *sequence = sequence.wrapping_add(1);
        if let Some(writer) = &mut self.writer {
            writer
                .write_message(channel_id, *sequence, log_time, data)
                .map_err(RecordingError::Write)?;
        }
        self.chunk_opened_at.get_or_insert(log_time);
        Ok(())
    }

    fn close_chunk_if_due(&mut self, log_time: u64) -> Result<(), RecordingError> {
        match self.chunk_opened_at {
            Some(opened) if log_time.saturating_sub(opened) >= self.chunk_interval => self.flush(),
            _ => Ok(()),
        }
    }

    /// Writes the open chunk and flushes the file to the operating system: everything recorded
    /// so far survives a kill from here on. Call it at the end of each test.
    pub fn flush(&mut self) -> Result<(), RecordingError> {
        self.chunk_opened_at = None;
        match &mut self.writer {
            Some(writer) => writer.flush().map_err(RecordingError::Write),
            None => Ok(()),
        }
    }

    /// Records a state sample at the time it was received.
    pub fn car_state(&mut self, sample: &StateSample) -> Result<(), RecordingError> {
        let record = CarStateRecord::new(sample, self.origin);
        self.write_at(sample.received_at, &record)?;
        let at = nanos_since(self.origin, sample.received_at);
        let (rtk, uwb) = foxglove::poses(&record, foxglove::Time::from_ns(at));
        if let Some(rtk) = rtk {
            self.write_one(at, &rtk)?;
        }
        match uwb {
            Some(uwb) => self.write_one(at, &uwb),
            None => Ok(()),
        }
    }

    /// Records a command about to be sent during test `test_index` (if any) and returns its id
    /// for [`Recorder::command_answered`].
    pub fn command_sent(
        &mut self,
        test_index: Option<usize>,
        command: CarCommand,
    ) -> Result<u64, RecordingError> {
        let id = self.next_command;
        self.next_command += 1;
        let name = command.name();
        let now = self.now_ns();
        self.write_at_ns(
            now,
            &CommandSent {
                id,
                test_index,
                command,
            },
        )?;
        self.pending_commands.insert(id, (now, name));
        Ok(id)
    }

    /// Records the car's answer to command `id` (the car-link call's result), with the round
    /// trip since [`Recorder::command_sent`].
    pub fn command_answered<T, E: std::fmt::Display>(
        &mut self,
        id: u64,
        result: &Result<T, E>,
    ) -> Result<(), RecordingError> {
        let now = self.now_ns();
        let sent = self.pending_commands.remove(&id);
        let ack = CommandAck {
            id,
            command: sent.map_or("unknown", |(_, name)| name).to_owned(),
            outcome: AckOutcome::of(result),
            round_trip_ms: sent.map(|(at, _)| now.saturating_sub(at) as f64 / 1e6),
        };
        self.write_at_ns(now, &ack)
    }

    /// Records the simulator's truth now, and remembers how its clock maps to log time for
    /// [`Recorder::sim_events`].
    pub fn sim_truth(&mut self, truth: &Truth) -> Result<(), RecordingError> {
        let now = self.now_ns();
        self.sim_offset_ns = Some(i128::from(now) - i128::from(truth.time_ms) * 1_000_000);
        self.write_at_ns(now, &TruthRecord::from(truth))
    }

    /// Records the simulator's debug events on `/sim/ranges`, `/sim/faults` and `/sim/events`.
    /// Their log time is their simulation time mapped through the last [`Recorder::sim_truth`]
    /// (the time of this call before any truth).
    pub fn sim_events(&mut self, events: &[DebugEvent]) -> Result<(), RecordingError> {
        for event in events {
            let record = SimRecord::from(event);
            let log_time = self.sim_log_time(record.sim_ms());
            match &record {
                SimRecord::Range(r) => self.write_at_ns(log_time, r)?,
                SimRecord::Fault(f) => self.write_at_ns(log_time, f)?,
                SimRecord::Event(e) => self.write_at_ns(log_time, e)?,
            }
        }
        Ok(())
    }

    fn sim_log_time(&self, sim_ms: u64) -> u64 {
        match self.sim_offset_ns {
            Some(offset) => {
                let ns = offset + i128::from(sim_ms) * 1_000_000;
                u64::try_from(ns.max(0)).unwrap_or(u64::MAX)
            }
            None => self.now_ns(),
        }
    }

    /// Completes the file (the last chunk, the summary with indexes and statistics, the footer)
    /// and syncs it to disk.
    pub fn finish(mut self) -> Result<FinishedRecording, RecordingError> {
        self.release(true)?;
        let Some(writer) = self.writer.take() else {
            return Ok(FinishedRecording {
                messages: 0,
                chunks: 0,
            });
        };
        let (file, written) = writer.finish().map_err(RecordingError::Write)?;
        let file = file
            .into_inner()
            .map_err(|e| RecordingError::Complete(e.into_error()))?;
        file.sync_all().map_err(RecordingError::Complete)?;
        Ok(FinishedRecording {
            messages: written.messages,
            chunks: written.chunks,
        })
    }
}
