//! Reading a recording back: its channels with their schemas, its metadata records, and its
//! messages per channel as typed records. A file cut short (a killed campaign) reads up to the
//! last complete chunk; [`Recording::cut_short`] says why it stopped.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use mcap::records::Record as McapRecord;

use super::topic::{Encoding, Record, Topic};
use super::{READABLE_RECORDING_VERSIONS, RECORDING_FORMAT, RecordingError};

/// A channel of a recording, as the file declares it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordingChannel {
    /// The topic name.
    pub topic: String,
    /// The message encoding (`json`).
    pub message_encoding: String,
    /// The schema's name (`drivecheck.CarState`, …); empty without a schema.
    pub schema_name: String,
    /// The schema's encoding (`jsonschema`); empty without a schema.
    pub schema_encoding: String,
    /// The schema's bytes.
    pub schema: Vec<u8>,
}

/// A message read back, with its MCAP header fields.
#[derive(Debug, Clone, PartialEq)]
pub struct Stamped<R> {
    /// Log time: ns of the run's clock since the campaign started.
    pub log_time_ns: u64,
    /// The message's number on its channel, from 1.
    pub sequence: u32,
    /// The record.
    pub message: R,
}

#[derive(Debug, Clone)]
struct RawMessage {
    channel_id: u16,
    sequence: u32,
    log_time: u64,
    data: Vec<u8>,
}

/// A recording read into memory (see the module doc).
#[derive(Debug, Clone, Default)]
pub struct Recording {
    channels: BTreeMap<u16, RecordingChannel>,
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    messages: Vec<RawMessage>,
    complete: bool,
    cut_short: Option<String>,
}

#[derive(Debug, Clone)]
struct SchemaRecord {
    name: String,
    encoding: String,
    data: Vec<u8>,
}

impl Recording {
    /// Reads the recording at `path`.
    pub fn read(path: &Path) -> Result<Self, RecordingError> {
        let bytes = std::fs::read(path).map_err(|source| RecordingError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::from_bytes(&bytes)
    }

    /// Reads a recording from its bytes. Only bytes that do not start like an MCAP file are an
    /// error; damage further on ends the reading there (see [`Recording::cut_short`]).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, RecordingError> {
        let mut recording = Recording::default();
        let mut schemas = BTreeMap::new();
        let mut started = false;
        for record in Records::new(bytes) {
            match record {
                Ok(McapRecord::Header(_)) => started = true,
                Ok(record) => recording.take(record, &mut schemas),
                Err(e) if !started => return Err(RecordingError::NotMcap(e)),
                Err(e) => {
                    recording.cut_short = Some(e.to_string());
                    break;
                }
            }
        }
        if !started {
            return Err(RecordingError::NotMcap(mcap::McapError::UnexpectedEof));
        }
        Ok(recording)
    }

    fn take(&mut self, record: McapRecord<'_>, schemas: &mut BTreeMap<u16, SchemaRecord>) {
        match record {
            McapRecord::Schema { header, data } => {
                let schema = SchemaRecord {
                    name: header.name,
                    encoding: header.encoding,
                    data: data.into_owned(),
                };
                schemas.insert(header.id, schema);
            }
            McapRecord::Channel(channel) => {
                let schema = schemas.get(&channel.schema_id);
                let entry = RecordingChannel {
                    topic: channel.topic,
                    message_encoding: channel.message_encoding,
                    schema_name: schema.map(|s| s.name.clone()).unwrap_or_default(),
                    schema_encoding: schema.map(|s| s.encoding.clone()).unwrap_or_default(),
                    schema: schema.map(|s| s.data.clone()).unwrap_or_default(),
                };
                self.channels.insert(channel.id, entry);
            }
            McapRecord::Message { header, data } => self.messages.push(RawMessage {
                channel_id: header.channel_id,
                sequence: header.sequence,
                log_time: header.log_time,
                data: data.into_owned(),
            }),
            McapRecord::Metadata(m) => {
                self.metadata.insert(m.name, m.metadata);
            }
            McapRecord::Footer(_) => self.complete = true,
            _ => {}
        }
    }

    /// A recording of `held` messages alone (a test's span, see [`Spans`]): its channels are their
    /// topics, without schemas; no metadata.
    pub fn from_held(held: Vec<super::Held>) -> Self {
        let mut recording = Recording {
            complete: true,
            ..Recording::default()
        };
        for message in held {
            let topic = message.topic();
            let id = topic as u16;
            recording
                .channels
                .entry(id)
                .or_insert_with(|| RecordingChannel {
                    topic: topic.name().to_owned(),
                    message_encoding: message.encoding().name().to_owned(),
                    schema_name: String::new(),
                    schema_encoding: String::new(),
                    schema: Vec::new(),
                });
            recording.messages.push(RawMessage {
                channel_id: id,
                sequence: 0,
                log_time: message.log_time(),
                data: message.into_data(),
            });
        }
        recording
    }

    /// Checks that the file is a drivecheck recording of a version this build reads (its
    /// `drivecheck.recording` metadata record, written first, so a cut-short file has it too).
    pub fn check_format(&self) -> Result<(), RecordingError> {
        let header = self.metadata("drivecheck.recording");
        let format = header.and_then(|h| h.get("format")).cloned();
        let version = header.and_then(|h| h.get("schema_version")).cloned();
        let readable = version
            .as_deref()
            .and_then(|v| v.parse::<u32>().ok())
            .is_some_and(|v| READABLE_RECORDING_VERSIONS.contains(&v));
        if format.as_deref() == Some(RECORDING_FORMAT) && readable {
            return Ok(());
        }
        Err(RecordingError::UnsupportedFormat { format, version })
    }

    /// Whether the file was finished (it ends with its summary and footer).
    pub fn is_complete(&self) -> bool {
        self.complete && self.cut_short.is_none()
    }

    /// Why reading stopped before the end of a complete file (a truncated or damaged file), if
    /// it did.
    pub fn cut_short(&self) -> Option<&str> {
        self.cut_short.as_deref()
    }

    /// The channels, in id order.
    pub fn channels(&self) -> impl Iterator<Item = &RecordingChannel> {
        self.channels.values()
    }

    /// The channel of `topic`, if the file declares it.
    pub fn channel(&self, topic: Topic) -> Option<&RecordingChannel> {
        self.channels.values().find(|c| c.topic == topic.name())
    }

    /// The metadata record `name` (`drivecheck.recording`, `drivecheck.scenario`,
    /// `drivecheck.campaign`, `drivecheck.campaign_end`).
    /// The names of the metadata records.
    pub fn metadata_names(&self) -> impl Iterator<Item = &str> {
        self.metadata.keys().map(String::as_str)
    }

    /// Every message of a known topic in file order, as written (for `drivecheck runs merge`).
    pub fn held(&self) -> Vec<super::Held> {
        self.messages
            .iter()
            .filter_map(|m| {
                let channel = self.channels.get(&m.channel_id)?;
                let topic = Topic::from_name(&channel.topic)?;
                let encoding = Encoding::from_name(&channel.message_encoding)?;
                Some(super::Held::encoded_as(
                    topic,
                    encoding,
                    m.log_time,
                    m.data.clone(),
                ))
            })
            .collect()
    }

    /// A metadata record by name.
    pub fn metadata(&self, name: &str) -> Option<&BTreeMap<String, String>> {
        self.metadata.get(name)
    }

    /// Messages on all channels.
    pub fn message_count(&self) -> usize {
        self.messages.len()
    }

    /// Messages on `topic`'s channel.
    pub fn count(&self, topic: Topic) -> usize {
        self.raw(topic).count()
    }

    /// The messages of `R`'s channel in file order, decoded (a state sample of a version-3
    /// recording joined with its poses: [`Record::read_all`]).
    pub fn messages<R: Record>(&self) -> Result<Vec<Stamped<R>>, RecordingError> {
        R::read_all(self)
    }

    /// The encoding of `topic`'s channel, if the file declares the channel in an encoding
    /// drivecheck writes.
    pub fn encoding(&self, topic: Topic) -> Option<Encoding> {
        Encoding::from_name(&self.channel(topic)?.message_encoding)
    }

    /// The messages of `R`'s channel in file order, each decoded alone in its channel's
    /// encoding.
    pub fn decode_each<R: Record>(&self) -> Result<Vec<Stamped<R>>, RecordingError> {
        let topic = R::TOPIC.name();
        let encoding = match self.channel(R::TOPIC) {
            None => return Ok(Vec::new()),
            Some(channel) => Encoding::from_name(&channel.message_encoding).ok_or_else(|| {
                RecordingError::UnknownEncoding {
                    topic,
                    encoding: channel.message_encoding.clone(),
                }
            })?,
        };
        self.raw_messages(R::TOPIC)
            .enumerate()
            .map(|(index, (log_time_ns, sequence, data))| {
                let message = match encoding {
                    Encoding::Json => {
                        serde_json::from_slice(data).map_err(|source| RecordingError::Decode {
                            topic,
                            index,
                            source,
                        })?
                    }
                    Encoding::Protobuf => R::from_protobuf(data)
                        .ok_or_else(|| RecordingError::UnknownEncoding {
                            topic,
                            encoding: encoding.name().to_owned(),
                        })?
                        .map_err(|source| RecordingError::DecodeProtobuf {
                            topic,
                            index,
                            source,
                        })?,
                };
                Ok(Stamped {
                    log_time_ns,
                    sequence,
                    message,
                })
            })
            .collect()
    }

    /// `topic`'s messages in file order, undecoded: log time, sequence and bytes.
    pub fn raw_messages(&self, topic: Topic) -> impl Iterator<Item = (u64, u32, &[u8])> {
        self.raw(topic)
            .map(|m| (m.log_time, m.sequence, m.data.as_slice()))
    }

    /// The payloads of `topic`'s messages in file order, undecoded.
    pub fn payloads(&self, topic: Topic) -> impl Iterator<Item = &[u8]> {
        self.raw(topic).map(|m| m.data.as_slice())
    }

    fn raw(&self, topic: Topic) -> impl Iterator<Item = &RawMessage> {
        let ids: Vec<u16> = self
            .channels
            .iter()
            .filter(|(_, c)| c.topic == topic.name())
            .map(|(&id, _)| id)
            .collect();
        self.messages
            .iter()
            .filter(move |m| ids.contains(&m.channel_id))
    }
}

/// What a recording holds, learnt without keeping its messages: whether it was finished, how
/// many messages it has, why reading stopped early (`drivecheck runs show`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Summary {
    /// Whether the file was finished (it ends with its summary and footer) and read without
    /// damage.
    pub complete: bool,
    /// Messages on all channels (up to the damage or the end of an unfinished file).
    pub messages: u64,
    /// Why reading stopped before the end of a complete file, if it did.
    pub cut_short: Option<String>,
}

/// The footer record and the end magic that close a finished MCAP file: opcode, length, summary
/// start, summary offset start, summary CRC, magic.
const FOOTER_AND_MAGIC: u64 = 1 + 8 + 8 + 8 + 4 + 8;
/// The data end record, just before the summary section: opcode, length, data section CRC.
const DATA_END: u64 = 1 + 8 + 4;

/// The records of a finished file's summary section, from its data end record on (its CRC
/// checked); `None` when the file has no summary section or its footer does not say where it is.
/// The records come as the file is read: an error of the section is one of them.
fn summary_section(
    file: &mut File,
) -> std::io::Result<Option<Records<BufReader<std::io::Take<&mut File>>>>> {
    let length = file.metadata()?.len();
    if length < mcap::MAGIC.len() as u64 + DATA_END + FOOTER_AND_MAGIC {
        return Ok(None);
    }
    file.seek(SeekFrom::Start(0))?;
    let mut magic = [0; 8];
    file.read_exact(&mut magic)?;
    if magic.as_slice() != mcap::MAGIC {
        return Ok(None);
    }
    let footer_at = length - FOOTER_AND_MAGIC;
    file.seek(SeekFrom::Start(footer_at))?;
    let mut footer = [0; FOOTER_AND_MAGIC as usize];
    file.read_exact(&mut footer)?;
    let field = |at: usize| u64::from_le_bytes(footer[at..at + 8].try_into().unwrap_or([0; 8]));
    let summary_start = field(9);
    if footer[0] != mcap::records::op::FOOTER
        || field(1) != 20
        || &footer[29..] != mcap::MAGIC
        || summary_start < mcap::MAGIC.len() as u64 + DATA_END
        || summary_start > footer_at
    {
        return Ok(None);
    }
    // From the data end record on: the reader checks the summary's CRC from there.
    let from = summary_start - DATA_END;
    file.seek(SeekFrom::Start(from))?;
    let input = BufReader::new(Read::take(file, length - from));
    let mut records = Records::summary(input);
    if !matches!(records.next(), Some(Ok(McapRecord::DataEnd(_)))) {
        return Ok(None);
    }
    Ok(Some(records))
}

impl Summary {
    /// The summary of the recording at `path`. A finished file's is read from its summary section
    /// (its statistics record, the summary's CRC checked), a few kilobytes at its end, not from
    /// its messages: the chunks are not read, so damage inside them shows only to a reader of
    /// the messages. A file without a readable summary (unfinished, damaged at its end) is
    /// [scanned](Summary::scan).
    pub fn read(path: &Path) -> Result<Self, RecordingError> {
        let read_error = |source| RecordingError::Read {
            path: path.to_owned(),
            source,
        };
        let mut file = File::open(path).map_err(read_error)?;
        match Self::from_summary_section(&mut file).map_err(read_error)? {
            Some(summary) => Ok(summary),
            None => Self::scan(path),
        }
    }

    /// The summary of the recording at `path`, every record read (every CRC checked) and its
    /// messages counted, one chunk in memory at a time. Only a file that does not start like an
    /// MCAP file is an error; damage further on ends the reading there (see
    /// [`Summary::cut_short`]), as [`Recording::read`] does.
    pub fn scan(path: &Path) -> Result<Self, RecordingError> {
        let file = File::open(path).map_err(|source| RecordingError::Read {
            path: path.to_owned(),
            source,
        })?;
        let mut summary = Summary {
            complete: false,
            messages: 0,
            cut_short: None,
        };
        let mut started = false;
        for record in Records::new(BufReader::new(file)) {
            match record {
                Ok(McapRecord::Header(_)) => started = true,
                Ok(McapRecord::Message { .. }) => summary.messages += 1,
                Ok(McapRecord::Footer(_)) => summary.complete = true,
                Ok(_) => {}
                Err(mcap::McapError::Io(source)) => {
                    return Err(RecordingError::Read {
                        path: path.to_owned(),
                        source,
                    });
                }
                Err(e) if !started => return Err(RecordingError::NotMcap(e)),
                Err(e) => {
                    summary.cut_short = Some(e.to_string());
                    break;
                }
            }
        }
        if !started {
            return Err(RecordingError::NotMcap(mcap::McapError::UnexpectedEof));
        }
        summary.complete &= summary.cut_short.is_none();
        Ok(summary)
    }

    /// The summary from the statistics record of a finished file's summary section; `None` when
    /// the file has no such section, or it does not read whole with its CRC.
    fn from_summary_section(file: &mut File) -> std::io::Result<Option<Self>> {
        let Some(records) = summary_section(file)? else {
            return Ok(None);
        };
        let mut messages = None;
        let mut footer_read = false;
        for record in records {
            match record {
                Ok(McapRecord::Statistics(statistics)) => {
                    messages = Some(statistics.message_count);
                }
                Ok(McapRecord::Footer(_)) => footer_read = true,
                Ok(_) => {}
                Err(mcap::McapError::Io(e)) => return Err(e),
                Err(_) => return Ok(None),
            }
        }
        Ok(match (messages, footer_read) {
            (Some(messages), true) => Some(Summary {
                complete: true,
                messages,
                cut_short: None,
            }),
            _ => None,
        })
    }

    /// Whether the file was finished and read without damage.
    pub fn is_complete(&self) -> bool {
        self.complete
    }

    /// Why reading stopped before the end of a complete file, if it did.
    pub fn cut_short(&self) -> Option<&str> {
        self.cut_short.as_deref()
    }
}

/// The messages of one test in a recording, as [`Spans`] reads them.
#[derive(Debug, Clone, PartialEq)]
pub struct Span {
    /// The test (`None`: messages no `drivecheck.test.*` record claims, such as all of a
    /// recording made on one car for the whole campaign).
    pub test_index: Option<usize>,
    /// Log time of the span's start, ns.
    pub start_ns: u64,
    /// Log time of its last message, ns.
    pub end_ns: u64,
    /// The car that drove it, in a campaign on several cars.
    pub car: Option<String>,
    /// Its messages, in file order.
    pub messages: Vec<super::Held>,
}

/// Reads a recording test by test, one test's messages in memory at a time: every
/// `drivecheck.test.<index>` metadata record closes the span of the messages before it (those
/// from its start on); messages after the last such record come as one span without a test.
///
/// The input is read as the spans are taken ([`Spans::open`] reads the file through a
/// [`BufReader`]), so that what is in memory is one test's messages and one chunk, whatever
/// the size of the file.
pub struct Spans<R> {
    records: Records<R>,
    /// The file read, to name it in an error of the system.
    path: Option<PathBuf>,
    channels: BTreeMap<u16, (Topic, Encoding)>,
    pending: Vec<super::Held>,
    done: bool,
    /// Where the file is damaged or cut short: given after what was read before it.
    error: Option<RecordingError>,
    /// The recording says every test's messages have a span: what no span claims is the
    /// campaign's own (the area), not a test's.
    spanned: bool,
    /// The metadata records read so far, but the spans'.
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// The test whose span is the last read ([`Spans::open_test`]).
    until: Option<usize>,
}

impl<'a> Spans<&'a [u8]> {
    /// The spans of the recording in `bytes`.
    pub fn new(bytes: &'a [u8]) -> Result<Self, RecordingError> {
        Ok(Self::from_reader(bytes))
    }
}

impl Spans<BufReader<File>> {
    /// The spans of the recording at `path`, read from the file as they are taken.
    pub fn open(path: &Path) -> Result<Self, RecordingError> {
        let file = File::open(path).map_err(|source| RecordingError::Read {
            path: path.to_owned(),
            source,
        })?;
        let mut spans = Self::from_reader(BufReader::new(file));
        spans.path = Some(path.to_owned());
        Ok(spans)
    }

    /// The span of test `test_index` alone, found by the summary section's metadata index
    /// (seek and read): the file is read from the end of the span record before it to its own,
    /// so one test of a large recording costs its own chunks, not the file's. The channels
    /// come from the summary section and the campaign's metadata records from their places.
    /// `None` (read the file from its start then) when the file has no summary section (a
    /// campaign that did not finish), no span record of the test, or none before it.
    pub fn open_test(path: &Path, test_index: usize) -> Result<Option<Self>, RecordingError> {
        let read = |source| RecordingError::Read {
            path: path.to_owned(),
            source,
        };
        let mut file = File::open(path).map_err(read)?;
        let Some(records) = summary_section(&mut file).map_err(read)? else {
            return Ok(None);
        };
        let mut channels = BTreeMap::new();
        let mut places: Vec<(u64, u64, String)> = Vec::new();
        for record in records {
            match record {
                Ok(McapRecord::Channel(channel)) => {
                    if let Some(known) = known_channel(&channel) {
                        channels.insert(channel.id, known);
                    }
                }
                Ok(McapRecord::MetadataIndex(index)) => {
                    places.push((index.offset, index.length, index.name));
                }
                Ok(_) => {}
                Err(mcap::McapError::Io(source)) => return Err(read(source)),
                Err(_) => return Ok(None),
            }
        }
        let is_span = |name: &str| name.starts_with(super::TEST_SPAN_PREFIX);
        let name = format!("{}{test_index}", super::TEST_SPAN_PREFIX);
        let Some(&(end, _, _)) = places.iter().find(|(_, _, n)| *n == name) else {
            return Ok(None);
        };
        let Some((before, before_length)) = places
            .iter()
            .filter(|(offset, _, n)| is_span(n) && *offset < end)
            .map(|&(offset, length, _)| (offset, length))
            .max()
        else {
            return Ok(None);
        };
        let mut metadata = BTreeMap::new();
        for (offset, length, _) in places.iter().filter(|(_, _, n)| !is_span(n)) {
            match metadata_at(&mut file, *offset, *length).map_err(read)? {
                Some(m) => metadata.insert(m.name, m.metadata),
                None => return Ok(None),
            };
        }
        let spanned = metadata
            .get("drivecheck.recording")
            .is_some_and(says_test_spans);
        file.seek(SeekFrom::Start(before.saturating_add(before_length)))
            .map_err(read)?;
        // From inside the data section: its CRC cannot be checked, every chunk's is.
        let options = mcap::sans_io::LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(RECORD_LIMIT);
        Ok(Some(Self {
            records: Records::with_options(BufReader::new(file), options),
            path: Some(path.to_owned()),
            channels,
            pending: Vec::new(),
            done: false,
            error: None,
            spanned,
            metadata,
            until: Some(test_index),
        }))
    }
}

/// The topic and encoding of a channel record, when drivecheck knows both.
fn known_channel(channel: &mcap::records::Channel) -> Option<(Topic, Encoding)> {
    Some((
        Topic::from_name(&channel.topic)?,
        Encoding::from_name(&channel.message_encoding)?,
    ))
}

/// Whether the `drivecheck.recording` metadata says every test's messages have a span.
fn says_test_spans(recording: &BTreeMap<String, String>) -> bool {
    recording.get("test_spans").is_some_and(|v| v == "true")
}

/// The metadata record of `length` bytes (opcode and length included, as a metadata index
/// gives it) at `offset` in `file`; `None` when it is not one.
fn metadata_at(
    file: &mut File,
    offset: u64,
    length: u64,
) -> std::io::Result<Option<mcap::records::Metadata>> {
    const HEAD: usize = 1 + 8;
    let Some(length) = usize::try_from(length)
        .ok()
        .filter(|&l| (HEAD..=RECORD_LIMIT).contains(&l))
    else {
        return Ok(None);
    };
    file.seek(SeekFrom::Start(offset))?;
    let mut bytes = vec![0; length];
    file.read_exact(&mut bytes)?;
    let declared = u64::from_le_bytes(bytes[1..HEAD].try_into().unwrap_or([0; 8]));
    if declared != (length - HEAD) as u64 {
        return Ok(None);
    }
    Ok(match mcap::parse_record(bytes[0], &bytes[HEAD..]) {
        Ok(McapRecord::Metadata(m)) => Some(m),
        _ => None,
    })
}

/// The campaign seed the recording at `path` names in its `drivecheck.campaign` metadata, read
/// from the file's start up to that record (written before any message, so only the first few
/// records are read, whatever the file's size). `None` when the file has no such record before
/// its first message or its damage.
pub fn recorded_seed(path: &Path) -> Result<Option<String>, RecordingError> {
    Ok(leading_metadata(path, "drivecheck.campaign")?.and_then(|m| m.get("seed").cloned()))
}

/// The canonical TOML of the scenario the recording at `path` was made in (its
/// `drivecheck.scenario` metadata), read as [`recorded_seed`] reads the seed. `None` when the file
/// has no such record before its first message or its damage.
pub fn recorded_scenario(path: &Path) -> Result<Option<String>, RecordingError> {
    Ok(leading_metadata(path, "drivecheck.scenario")?.and_then(|m| m.get("toml").cloned()))
}

/// The metadata record `name` among the records before the recording's first message.
fn leading_metadata(
    path: &Path,
    name: &str,
) -> Result<Option<BTreeMap<String, String>>, RecordingError> {
    let file = File::open(path).map_err(|source| RecordingError::Read {
        path: path.to_owned(),
        source,
    })?;
    for record in Records::new(BufReader::new(file)) {
        match record {
            Ok(McapRecord::Metadata(m)) if m.name == name => return Ok(Some(m.metadata)),
            Ok(McapRecord::Message { .. }) | Err(_) => break,
            Ok(_) => {}
        }
    }
    Ok(None)
}

impl<R: Read> Spans<R> {
    /// The spans of the recording `input` holds, read from it as they are taken.
    pub fn from_reader(input: R) -> Self {
        Self {
            records: Records::new(input),
            path: None,
            channels: BTreeMap::new(),
            pending: Vec::new(),
            done: false,
            error: None,
            spanned: false,
            metadata: BTreeMap::new(),
            until: None,
        }
    }

    /// An error of the reading: of the system (a file that cannot be read on) or of the file's
    /// content (damage, an end before the footer).
    fn failure(&self, error: mcap::McapError) -> RecordingError {
        match (error, &self.path) {
            (mcap::McapError::Io(source), Some(path)) => RecordingError::Read {
                path: path.clone(),
                source,
            },
            (error, _) => RecordingError::NotMcap(error),
        }
    }

    /// A metadata record read so far (not a span's), by name.
    pub fn metadata(&self, name: &str) -> Option<&BTreeMap<String, String>> {
        self.metadata.get(name)
    }

    fn leftover(&mut self) -> Option<Span> {
        let messages = std::mem::take(&mut self.pending);
        if self.spanned {
            return None;
        }
        let start_ns = messages.iter().map(super::Held::log_time).min()?;
        let end_ns = messages.iter().map(super::Held::log_time).max()?;
        Some(Span {
            test_index: None,
            start_ns,
            end_ns,
            car: None,
            messages,
        })
    }
}

impl<R: Read> Iterator for Spans<R> {
    type Item = Result<Span, RecordingError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return self.error.take().map(Err);
        }
        loop {
            let record = match self.records.next() {
                None => {
                    self.done = true;
                    return self.leftover().map(Ok);
                }
                Some(Err(e)) => {
                    // What was read before the damage first, then the damage.
                    self.done = true;
                    self.error = Some(self.failure(e));
                    return match self.leftover() {
                        Some(span) => Some(Ok(span)),
                        None => self.error.take().map(Err),
                    };
                }
                Some(Ok(record)) => record,
            };
            match record {
                McapRecord::Channel(channel) => {
                    if let Some(known) = known_channel(&channel) {
                        self.channels.insert(channel.id, known);
                    }
                }
                McapRecord::Message { header, data } => {
                    if let Some(&(topic, encoding)) = self.channels.get(&header.channel_id) {
                        self.pending.push(super::Held::encoded_as(
                            topic,
                            encoding,
                            header.log_time,
                            data.into_owned(),
                        ));
                    }
                }
                McapRecord::Metadata(m) if !m.name.starts_with(super::TEST_SPAN_PREFIX) => {
                    if m.name == "drivecheck.recording" {
                        self.spanned = says_test_spans(&m.metadata);
                    }
                    self.metadata.insert(m.name, m.metadata);
                }
                McapRecord::Metadata(m) if m.name.starts_with(super::TEST_SPAN_PREFIX) => {
                    let field = |name: &str| m.metadata.get(name).and_then(|v| v.parse().ok());
                    let (Some(test_index), Some(start_ns), Some(end_ns)) =
                        (field("test_index"), field("start_ns"), field("end_ns"))
                    else {
                        continue;
                    };
                    // What came before the span's start is the campaign's, not the test's (the
                    // area at log time 0).
                    let mut messages = std::mem::take(&mut self.pending);
                    messages.retain(|m| m.log_time() >= start_ns);
                    if self.until == Some(test_index as usize) {
                        self.done = true;
                    }
                    return Some(Ok(Span {
                        test_index: Some(test_index as usize),
                        start_ns,
                        end_ns,
                        car: m.metadata.get("car").cloned(),
                        messages,
                    }));
                }
                _ => {}
            }
        }
    }
}

/// The largest record or chunk (uncompressed) a drivecheck recording holds: the writer closes
/// chunks at 256 KiB, and no message comes near this. A larger length read from a file is damage.
pub const RECORD_LIMIT: usize = 64 * 1024 * 1024;

/// The records of the MCAP file `input` holds, read from it as the sans-io reader asks for bytes,
/// chunks unpacked (mcap's `ChunkFlattener`), every CRC the file has checked (each chunk's, the
/// data section's, the summary's), with every length read from the file bounded by
/// [`RECORD_LIMIT`]: a damaged length is an error, never an allocation of its size. An error of
/// the input ends the records.
struct Records<R> {
    input: R,
    reader: mcap::sans_io::LinearReader,
    failed: bool,
}

impl<R: Read> Records<R> {
    fn new(input: R) -> Self {
        let options = mcap::sans_io::LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_record_length_limit(RECORD_LIMIT);
        Self::with_options(input, options)
    }

    /// The records of a summary section, `input` placed at its data end record (the record
    /// before the summary, where the summary's CRC starts): the summary's CRC is checked, not the
    /// data section's (it is not read).
    fn summary(input: R) -> Self {
        let options = mcap::sans_io::LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_validate_summary_section_crc(true)
            .with_record_length_limit(RECORD_LIMIT);
        Self::with_options(input, options)
    }

    fn with_options(input: R, options: mcap::sans_io::LinearReaderOptions) -> Self {
        Self {
            input,
            reader: mcap::sans_io::LinearReader::new_with_options(options),
            failed: false,
        }
    }
}

impl<R: Read> Iterator for Records<R> {
    type Item = Result<McapRecord<'static>, mcap::McapError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        while let Some(event) = self.reader.next_event() {
            match event {
                Ok(mcap::sans_io::LinearReadEvent::ReadRequest(need)) => {
                    // As many of the `need` bytes as the input has: fewer only at its end.
                    let buf = self.reader.insert(need);
                    let mut filled = 0;
                    while filled < buf.len() {
                        match self.input.read(&mut buf[filled..]) {
                            Ok(0) => break,
                            Ok(n) => filled += n,
                            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                            Err(e) => {
                                self.failed = true;
                                return Some(Err(mcap::McapError::Io(e)));
                            }
                        }
                    }
                    self.reader.notify_read(filled);
                }
                Ok(mcap::sans_io::LinearReadEvent::Record { data, opcode }) => {
                    return Some(mcap::parse_record(opcode, data).map(McapRecord::into_owned));
                }
                Err(e) => return Some(Err(e)),
            }
        }
        None
    }
}
