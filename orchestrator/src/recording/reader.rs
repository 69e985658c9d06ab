//! Reading a recording back: its channels with their schemas, its metadata records, and its
//! messages per channel as typed records. A file cut short (a killed campaign) reads up to the
//! last complete chunk; [`Recording::cut_short`] says why it stopped.

use std::collections::BTreeMap;
use std::path::Path;

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
    /// Its messages, in file order.
    pub messages: Vec<super::Held>,
}

/// Reads a recording test by test, one test's messages in memory at a time: every
/// `drivecheck.test.<index>` metadata record closes the span of the messages before it (those
/// from its start on); messages after the last such record come as one span without a test.
pub struct Spans<'a> {
    records: Records<'a>,
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
}

impl<'a> Spans<'a> {
    /// The spans of the recording in `bytes`.
    pub fn new(bytes: &'a [u8]) -> Result<Self, RecordingError> {
        Ok(Self {
            records: Records::new(bytes),
            channels: BTreeMap::new(),
            pending: Vec::new(),
            done: false,
            error: None,
            spanned: false,
            metadata: BTreeMap::new(),
        })
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
            messages,
        })
    }
}

impl Iterator for Spans<'_> {
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
                    self.error = Some(RecordingError::NotMcap(e));
                    return match self.leftover() {
                        Some(span) => Some(Ok(span)),
                        None => self.error.take().map(Err),
                    };
                }
                Some(Ok(record)) => record,
            };
            match record {
                McapRecord::Channel(channel) => {
                    if let (Some(topic), Some(encoding)) = (
                        Topic::from_name(&channel.topic),
                        Encoding::from_name(&channel.message_encoding),
                    ) {
                        self.channels.insert(channel.id, (topic, encoding));
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
                        self.spanned = m.metadata.get("test_spans").is_some_and(|v| v == "true");
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
                    return Some(Ok(Span {
                        test_index: Some(test_index as usize),
                        start_ns,
                        end_ns,
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

/// The records of the MCAP file in `bytes`, chunks unpacked (mcap's `ChunkFlattener`), every CRC
/// the file has checked (each chunk's, the data section's, the summary's), with every length read from the file bounded by [`RECORD_LIMIT`]: a damaged
/// length is an error, never an allocation of its size.
struct Records<'a> {
    buf: &'a [u8],
    reader: mcap::sans_io::LinearReader,
}

impl<'a> Records<'a> {
    fn new(buf: &'a [u8]) -> Self {
        let options = mcap::sans_io::LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
            .with_record_length_limit(RECORD_LIMIT);
        Self {
            buf,
            reader: mcap::sans_io::LinearReader::new_with_options(options),
        }
    }
}

impl Iterator for Records<'_> {
    type Item = Result<McapRecord<'static>, mcap::McapError>;

    fn next(&mut self) -> Option<Self::Item> {
        while let Some(event) = self.reader.next_event() {
            match event {
                Ok(mcap::sans_io::LinearReadEvent::ReadRequest(need)) => {
                    let n = need.min(self.buf.len());
                    self.reader.insert(n).copy_from_slice(&self.buf[..n]);
                    self.reader.notify_read(n);
                    self.buf = &self.buf[n..];
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
