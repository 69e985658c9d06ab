//! An append-only MCAP writer for the recording ([MCAP spec](https://mcap.dev/spec)): zstd
//! chunks with their message indexes, metadata records, and on completion the summary
//! (schemas, channels, statistics, chunk and metadata indexes), its offsets and the footer.
//!
//! Why not the `mcap` crate's writer (the crate still reads every recording): it writes each
//! message's header field by field through the chunk's CRC and a streaming zstd encoder, seven
//! calls per message, which was about 40 % of what recording a test cost (`docs/recording.md`,
//! *Size and speed*). Here a message is appended to the chunk's buffer in one piece, and a chunk
//! is compressed in one call when it closes. The file only grows by whole records: schemas and
//! channels first, then chunks (each followed by its message indexes) and metadata records; a
//! process killed before [`McapOut::finish`] leaves a file without summary that readers still
//! read to its last complete record.

use std::io::{self, Write};

// The magic and the opcodes are the `mcap` crate's (it reads the files).
use mcap::MAGIC;
use mcap::records::op;

/// A message record's header: opcode, length, channel, sequence, log and publish time.
const MESSAGE_HEADER_LEN: usize = 1 + 8 + 2 + 4 + 8 + 8;

/// The content of one record, built in memory (all MCAP integers are little-endian).
#[derive(Debug, Default)]
struct Content(Vec<u8>);

impl Content {
    fn u8(mut self, v: u8) -> Self {
        self.0.push(v);
        self
    }
    fn u16(mut self, v: u16) -> Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn u32(mut self, v: u32) -> Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn u64(mut self, v: u64) -> Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// A string or `uint32`-prefixed byte array.
    fn bytes32(self, v: &[u8]) -> Self {
        let mut this = self.u32(len32(v.len()));
        this.0.extend_from_slice(v);
        this
    }
    fn str(self, v: &str) -> Self {
        self.bytes32(v.as_bytes())
    }
    /// A `Map<string, string>`: its byte length, then the pairs.
    fn string_map<'a>(self, pairs: impl IntoIterator<Item = (&'a str, &'a str)>) -> Self {
        let inner = pairs
            .into_iter()
            .fold(Content::default(), |c, (k, v)| c.str(k).str(v));
        self.bytes32(&inner.0)
    }
    /// A `Map<uint16, uint64>`.
    fn id_map(self, pairs: impl IntoIterator<Item = (u16, u64)>) -> Self {
        let inner = pairs
            .into_iter()
            .fold(Content::default(), |c, (k, v)| c.u16(k).u64(v));
        self.bytes32(&inner.0)
    }
}

/// A length as MCAP's `uint32` (every length written here is far below 4 GiB: a chunk's is
/// `uint64`, and a metadata value or schema that large is refused by the caller's memory first).
fn len32(len: usize) -> u32 {
    u32::try_from(len).unwrap_or(u32::MAX)
}

/// The file, with the offset written so far and the CRC of the section being written.
struct Out<W: Write> {
    inner: W,
    position: u64,
    crc: crc32fast::Hasher,
}

impl<W: Write> Out<W> {
    fn raw(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.inner.write_all(bytes)?;
        self.crc.update(bytes);
        self.position += bytes.len() as u64;
        Ok(())
    }

    /// Writes a record; returns its offset and its whole length.
    fn record(&mut self, opcode: u8, content: &Content) -> io::Result<(u64, u64)> {
        let start = self.position;
        let mut head = [0u8; 9];
        head[0] = opcode;
        head[1..].copy_from_slice(&(content.0.len() as u64).to_le_bytes());
        self.raw(&head)?;
        self.raw(&content.0)?;
        Ok((start, self.position - start))
    }
}

/// A chunk's index in the summary.
#[derive(Debug, Clone)]
struct ChunkIndex {
    start_time: u64,
    end_time: u64,
    offset: u64,
    length: u64,
    message_index_offsets: Vec<(u16, u64)>,
    message_index_length: u64,
    compressed_size: u64,
    uncompressed_size: u64,
}

/// What a finished file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Written {
    /// Messages on all channels.
    pub messages: u64,
    /// Chunks.
    pub chunks: u32,
}

/// An MCAP file being written (see the module doc).
pub(super) struct McapOut<W: Write> {
    out: Out<W>,
    /// Schema records' contents, for the summary.
    schemas: Vec<Content>,
    /// Channel records' contents, for the summary.
    channels: Vec<Content>,
    /// The open chunk's uncompressed records.
    chunk: Vec<u8>,
    /// The open chunk's log-time bounds.
    chunk_times: Option<(u64, u64)>,
    /// The open chunk's message index entries (log time, offset in `chunk`), by channel id − 1.
    chunk_index: Vec<Vec<(u64, u64)>>,
    /// Close a chunk once its records reach this many bytes.
    chunk_bytes: usize,
    compressor: zstd::bulk::Compressor<'static>,
    chunk_indexes: Vec<ChunkIndex>,
    /// Metadata records: offset, length, name.
    metadata_indexes: Vec<(u64, u64, String)>,
    /// Messages per channel id − 1.
    message_counts: Vec<u64>,
    /// Log-time bounds of every message.
    times: Option<(u64, u64)>,
    /// A write failed: the file is incomplete and nothing more is written.
    failed: bool,
}

impl<W: Write> McapOut<W> {
    /// Starts a file on `inner`: the magic and the header record naming `library`.
    pub fn new(inner: W, library: &str, chunk_bytes: usize, level: i32) -> io::Result<Self> {
        let mut out = Out {
            inner,
            position: 0,
            crc: crc32fast::Hasher::new(),
        };
        out.raw(MAGIC)?;
        out.record(op::HEADER, &Content::default().str("").str(library))?;
        Ok(Self {
            out,
            schemas: Vec::new(),
            channels: Vec::new(),
            chunk: Vec::with_capacity(chunk_bytes + chunk_bytes / 4),
            chunk_times: None,
            chunk_index: Vec::new(),
            chunk_bytes,
            compressor: zstd::bulk::Compressor::new(level)?,
            chunk_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
            message_counts: Vec::new(),
            times: None,
            failed: false,
        })
    }

    fn guard<T>(&mut self, result: io::Result<T>) -> io::Result<T> {
        if result.is_err() {
            self.failed = true;
        }
        result
    }

    fn check(&self) -> io::Result<()> {
        if self.failed {
            return Err(io::Error::other("an earlier write to the recording failed"));
        }
        Ok(())
    }

    /// Writes a schema record; returns its id (from 1).
    pub fn add_schema(&mut self, name: &str, encoding: &str, data: &[u8]) -> io::Result<u16> {
        self.check()?;
        let id = u16::try_from(self.schemas.len() + 1).map_err(io::Error::other)?;
        let content = Content::default()
            .u16(id)
            .str(name)
            .str(encoding)
            .bytes32(data);
        let written = self.out.record(op::SCHEMA, &content);
        self.guard(written)?;
        self.schemas.push(content);
        Ok(id)
    }

    /// Writes a channel record (no metadata); returns its id (from 1).
    pub fn add_channel(
        &mut self,
        schema_id: u16,
        topic: &str,
        message_encoding: &str,
    ) -> io::Result<u16> {
        self.check()?;
        let id = u16::try_from(self.channels.len() + 1).map_err(io::Error::other)?;
        let content = Content::default()
            .u16(id)
            .u16(schema_id)
            .str(topic)
            .str(message_encoding)
            .string_map([]);
        let written = self.out.record(op::CHANNEL, &content);
        self.guard(written)?;
        self.channels.push(content);
        self.chunk_index.push(Vec::new());
        self.message_counts.push(0);
        Ok(id)
    }

    /// Appends a message on channel `channel_id` (an id [`McapOut::add_channel`] returned) to
    /// the open chunk, which is written when it reaches its size.
    pub fn write_message(
        &mut self,
        channel_id: u16,
        sequence: u32,
        log_time: u64,
        data: &[u8],
    ) -> io::Result<()> {
        self.check()?;
        let slot = usize::from(channel_id).wrapping_sub(1);
        let (Some(entries), Some(count)) = (
            self.chunk_index.get_mut(slot),
            self.message_counts.get_mut(slot),
        ) else {
            return Err(io::Error::other(format!("no channel {channel_id}")));
        };
        entries.push((log_time, self.chunk.len() as u64));
        *count += 1;
        let mut head = [0u8; MESSAGE_HEADER_LEN];
        head[0] = op::MESSAGE;
        let len = (MESSAGE_HEADER_LEN - 9 + data.len()) as u64;
        head[1..9].copy_from_slice(&len.to_le_bytes());
        head[9..11].copy_from_slice(&channel_id.to_le_bytes());
        head[11..15].copy_from_slice(&sequence.to_le_bytes());
        head[15..23].copy_from_slice(&log_time.to_le_bytes());
        head[23..31].copy_from_slice(&log_time.to_le_bytes());
        self.chunk.extend_from_slice(&head);
        self.chunk.extend_from_slice(data);
        self.chunk_times = Some(widen(self.chunk_times, log_time));
        self.times = Some(widen(self.times, log_time));
        if self.chunk.len() >= self.chunk_bytes {
            self.close_chunk()?;
        }
        Ok(())
    }

    /// Writes the open chunk (compressed) and its message indexes, if it holds anything.
    pub fn close_chunk(&mut self) -> io::Result<()> {
        self.check()?;
        let Some((start_time, end_time)) = self.chunk_times.take() else {
            return Ok(());
        };
        let written = self.write_chunk(start_time, end_time);
        self.chunk.clear();
        self.chunk_index.iter_mut().for_each(Vec::clear);
        self.guard(written)
    }

    fn write_chunk(&mut self, start_time: u64, end_time: u64) -> io::Result<()> {
        let compressed = self.compressor.compress(&self.chunk)?;
        let mut content = Content::default()
            .u64(start_time)
            .u64(end_time)
            .u64(self.chunk.len() as u64)
            .u32(crc32fast::hash(&self.chunk))
            .str("zstd")
            .u64(compressed.len() as u64);
        content.0.extend_from_slice(&compressed);
        let (offset, length) = self.out.record(op::CHUNK, &content)?;
        let indexes_start = self.out.position;
        let mut message_index_offsets = Vec::new();
        for (slot, entries) in self.chunk_index.iter().enumerate() {
            if entries.is_empty() {
                continue;
            }
            let channel_id = u16::try_from(slot + 1).map_err(io::Error::other)?;
            let mut index = Content(Vec::with_capacity(6 + 16 * entries.len()))
                .u16(channel_id)
                .u32(len32(16 * entries.len()));
            for &(log_time, at) in entries {
                index = index.u64(log_time).u64(at);
            }
            let (at, _) = self.out.record(op::MESSAGE_INDEX, &index)?;
            message_index_offsets.push((channel_id, at));
        }
        self.chunk_indexes.push(ChunkIndex {
            start_time,
            end_time,
            offset,
            length,
            message_index_offsets,
            message_index_length: self.out.position - indexes_start,
            compressed_size: compressed.len() as u64,
            uncompressed_size: self.chunk.len() as u64,
        });
        Ok(())
    }

    /// Closes the open chunk and writes a metadata record.
    pub fn write_metadata(&mut self, name: &str, entries: &[(&str, String)]) -> io::Result<()> {
        self.close_chunk()?;
        let content = Content::default()
            .str(name)
            .string_map(entries.iter().map(|(k, v)| (*k, v.as_str())));
        let written = self.out.record(op::METADATA, &content);
        let (offset, length) = self.guard(written)?;
        self.metadata_indexes
            .push((offset, length, name.to_owned()));
        Ok(())
    }

    /// Closes the open chunk and flushes the file to the operating system.
    pub fn flush(&mut self) -> io::Result<()> {
        self.close_chunk()?;
        let flushed = self.out.inner.flush();
        self.guard(flushed)
    }

    /// Completes the file: the last chunk, the data end, the summary and its offsets, the
    /// footer and the magic. Returns the file's writer, flushed.
    pub fn finish(mut self) -> io::Result<(W, Written)> {
        self.close_chunk()?;
        let data_crc = std::mem::take(&mut self.out.crc).finalize();
        self.out
            .record(op::DATA_END, &Content::default().u32(data_crc))?;
        // The summary's CRC starts after the data end.
        self.out.crc = crc32fast::Hasher::new();
        let summary_start = self.out.position;
        let mut groups = Vec::new();
        let start = self.out.position;
        for schema in &self.schemas {
            self.out.record(op::SCHEMA, schema)?;
        }
        groups.push((op::SCHEMA, start));
        let start = self.out.position;
        for channel in &self.channels {
            self.out.record(op::CHANNEL, channel)?;
        }
        groups.push((op::CHANNEL, start));
        let start = self.out.position;
        let (first, last) = self.times.unwrap_or((0, 0));
        let statistics = Content::default()
            .u64(self.message_counts.iter().sum())
            .u16(u16::try_from(self.schemas.len()).unwrap_or(u16::MAX))
            .u32(len32(self.channels.len()))
            .u32(0)
            .u32(len32(self.metadata_indexes.len()))
            .u32(len32(self.chunk_indexes.len()))
            .u64(first)
            .u64(last)
            .id_map(
                self.message_counts
                    .iter()
                    .enumerate()
                    .filter(|&(_, &n)| n > 0)
                    .map(|(slot, &n)| (u16::try_from(slot + 1).unwrap_or(u16::MAX), n)),
            );
        self.out.record(op::STATISTICS, &statistics)?;
        groups.push((op::STATISTICS, start));
        let start = self.out.position;
        for chunk in &self.chunk_indexes {
            let content = Content::default()
                .u64(chunk.start_time)
                .u64(chunk.end_time)
                .u64(chunk.offset)
                .u64(chunk.length)
                .id_map(chunk.message_index_offsets.iter().copied())
                .u64(chunk.message_index_length)
                .str("zstd")
                .u64(chunk.compressed_size)
                .u64(chunk.uncompressed_size);
            self.out.record(op::CHUNK_INDEX, &content)?;
        }
        groups.push((op::CHUNK_INDEX, start));
        let start = self.out.position;
        for (offset, length, name) in &self.metadata_indexes {
            let content = Content::default().u64(*offset).u64(*length).str(name);
            self.out.record(op::METADATA_INDEX, &content)?;
        }
        groups.push((op::METADATA_INDEX, start));
        groups.push((0, self.out.position));
        let summary_offset_start = self.out.position;
        for pair in groups.windows(2) {
            let ((opcode, start), (_, end)) = (pair[0], pair[1]);
            if end > start {
                let content = Content::default().u8(opcode).u64(start).u64(end - start);
                self.out.record(op::SUMMARY_OFFSET, &content)?;
            }
        }
        // The footer's CRC covers the summary up to and including its own second field.
        let footer_head = Content::default()
            .u8(op::FOOTER)
            .u64(8 + 8 + 4)
            .u64(summary_start)
            .u64(summary_offset_start);
        self.out.raw(&footer_head.0)?;
        let summary_crc = std::mem::take(&mut self.out.crc).finalize();
        self.out.raw(&summary_crc.to_le_bytes())?;
        self.out.raw(MAGIC)?;
        self.out.inner.flush()?;
        let written = Written {
            messages: self.message_counts.iter().sum(),
            chunks: len32(self.chunk_indexes.len()),
        };
        Ok((self.out.inner, written))
    }
}

fn widen(bounds: Option<(u64, u64)>, t: u64) -> (u64, u64) {
    bounds.map_or((t, t), |(lo, hi)| (lo.min(t), hi.max(t)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use mcap::records::Record;
    use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
    use proptest::prelude::*;

    /// Every record of `bytes`, read with every CRC checked (chunks, data section, summary).
    fn records(bytes: &[u8], options: LinearReaderOptions) -> Vec<Record<'static>> {
        let mut reader = LinearReader::new_with_options(options);
        let mut input = bytes;
        let mut out = Vec::new();
        while let Some(event) = reader.next_event() {
            match event.unwrap() {
                LinearReadEvent::ReadRequest(need) => {
                    let n = need.min(input.len());
                    reader.insert(n).copy_from_slice(&input[..n]);
                    reader.notify_read(n);
                    input = &input[n..];
                }
                LinearReadEvent::Record { data, opcode } => {
                    out.push(mcap::parse_record(opcode, data).unwrap().into_owned());
                }
            }
        }
        out
    }

    fn checked() -> LinearReaderOptions {
        LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_validate_data_section_crc(true)
            .with_validate_summary_section_crc(true)
    }

    /// Message `i`: on channel 1 or 2, a few bytes that tell it apart.
    fn message(i: u32) -> (u16, u64, Vec<u8>) {
        let channel = 1 + u16::from(i.is_multiple_of(3));
        let data = format!("message {i} {}", "x".repeat((i % 17) as usize)).into_bytes();
        (channel, 1_000 * u64::from(i), data)
    }

    fn written(messages: u32, flush_after: Option<u32>, finish: bool) -> Vec<u8> {
        let mut bytes = Vec::new();
        let mut out = McapOut::new(&mut bytes, "test", 512, 1).unwrap();
        let schema = out.add_schema("s", "jsonschema", b"{}").unwrap();
        assert_eq!(out.add_channel(schema, "/a", "json").unwrap(), 1);
        assert_eq!(out.add_channel(schema, "/b", "json").unwrap(), 2);
        out.write_metadata("first", &[("k", "v".to_owned())])
            .unwrap();
        let mut sequences = [0u32; 2];
        for i in 0..messages {
            let (channel, log_time, data) = message(i);
            sequences[usize::from(channel - 1)] += 1;
            let sequence = sequences[usize::from(channel - 1)];
            out.write_message(channel, sequence, log_time, &data)
                .unwrap();
            if flush_after == Some(i) {
                out.flush().unwrap();
            }
        }
        if finish {
            out.finish().unwrap();
        } else {
            drop(out);
        }
        bytes
    }

    #[test]
    fn a_finished_file_reads_back_whole_with_its_crcs_summary_and_indexes() {
        let bytes = written(400, Some(100), true);
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let stats = summary.stats.clone().unwrap();
        assert_eq!(stats.message_count, 400);
        assert_eq!(stats.metadata_count, 1);
        assert_eq!(stats.schema_count, 1);
        assert_eq!(stats.channel_count, 2);
        assert_eq!(
            (stats.message_start_time, stats.message_end_time),
            (0, 399_000)
        );
        assert_eq!(stats.channel_message_counts[&1], 266);
        assert_eq!(stats.channel_message_counts[&2], 134);
        assert!(summary.chunk_indexes.len() > 10);
        assert_eq!(stats.chunk_count as usize, summary.chunk_indexes.len());
        assert_eq!(summary.metadata_indexes.len(), 1);
        // Every message found through the message indexes is the one written.
        let mut found = 0;
        for chunk in &summary.chunk_indexes {
            for (channel, entries) in summary.read_message_indexes(&bytes, chunk).unwrap() {
                for entry in entries {
                    let read = summary.seek_message(&bytes, chunk, &entry).unwrap();
                    let i = u32::try_from(read.log_time / 1_000).unwrap();
                    let (expected_channel, _, data) = message(i);
                    assert_eq!((channel.id, &*read.data), (expected_channel, &data[..]));
                    found += 1;
                }
            }
        }
        assert_eq!(found, 400);
        // Read front to back with every CRC checked: the messages in order, then the summary.
        let records = records(&bytes, checked());
        let messages = records
            .iter()
            .filter(|r| matches!(r, Record::Message { .. }))
            .count();
        assert_eq!(messages, 400);
        assert!(matches!(records.last(), Some(Record::Footer(_))));
        let stream: Vec<_> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .collect();
        assert_eq!(stream.len(), 400);
        for (i, m) in stream.iter().enumerate() {
            let (channel, log_time, data) = message(u32::try_from(i).unwrap());
            assert_eq!(
                (m.channel.id, m.log_time, m.publish_time, &*m.data),
                (channel, log_time, log_time, &data[..])
            );
        }
        assert_eq!(stream[3].sequence, 2, "channel 2's second message");
    }

    /// A step of a file being written: a message, a flush, or a metadata record.
    #[derive(Debug, Clone)]
    enum Step {
        Message {
            channel: u16,
            log_time: u64,
            data: Vec<u8>,
        },
        Flush,
        Metadata(String),
    }

    fn step() -> impl Strategy<Value = Step> {
        prop_oneof![
            8 => (1u16..=3, any::<u64>(), proptest::collection::vec(any::<u8>(), 0..64))
                .prop_map(|(channel, log_time, data)| Step::Message { channel, log_time, data }),
            1 => Just(Step::Flush),
            1 => "[a-z.]{1,12}".prop_map(Step::Metadata),
        ]
    }

    proptest! {
        /// Whatever is written, in whatever log-time order and chunk size, reads back the same
        /// with every CRC checked, and the summary and message indexes account for every message.
        #[test]
        fn any_file_reads_back_as_written(
            steps in proptest::collection::vec(step(), 0..200),
            chunk_bytes in 1usize..4096,
        ) {
            let mut bytes = Vec::new();
            let mut out = McapOut::new(&mut bytes, "test", chunk_bytes, 1).unwrap();
            let schema = out.add_schema("s", "jsonschema", b"{}").unwrap();
            for topic in ["/a", "/b", "/c"] {
                out.add_channel(schema, topic, "json").unwrap();
            }
            let mut sequences = [0u32; 3];
            let mut written = Vec::new();
            let mut metadata = 0;
            for step in &steps {
                match step {
                    Step::Message { channel, log_time, data } => {
                        let sequence = &mut sequences[usize::from(*channel - 1)];
                        *sequence += 1;
                        out.write_message(*channel, *sequence, *log_time, data).unwrap();
                        written.push((*channel, *sequence, *log_time, data.clone()));
                    }
                    Step::Flush => out.flush().unwrap(),
                    Step::Metadata(name) => {
                        out.write_metadata(name, &[("k", name.clone())]).unwrap();
                        metadata += 1;
                    }
                }
            }
            out.finish().unwrap();
            let read: Vec<_> = records(&bytes, checked())
                .into_iter()
                .filter_map(|r| match r {
                    Record::Message { header, data } => {
                        Some((header.channel_id, header.sequence, header.log_time, data.into_owned()))
                    }
                    _ => None,
                })
                .collect();
            prop_assert_eq!(&read, &written);
            let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
            let stats = summary.stats.clone().unwrap();
            prop_assert_eq!(stats.message_count, written.len() as u64);
            prop_assert_eq!(stats.metadata_count as usize, metadata);
            let times = written.iter().map(|w| w.2);
            prop_assert_eq!(
                (stats.message_start_time, stats.message_end_time),
                (times.clone().min().unwrap_or(0), times.max().unwrap_or(0))
            );
            let mut indexed = 0;
            for chunk in &summary.chunk_indexes {
                for (_, entries) in summary.read_message_indexes(&bytes, chunk).unwrap() {
                    for entry in entries {
                        let message = summary.seek_message(&bytes, chunk, &entry).unwrap();
                        prop_assert_eq!(message.log_time, entry.log_time);
                        indexed += 1;
                    }
                }
            }
            prop_assert_eq!(indexed, written.len());
        }
    }

    #[test]
    fn a_file_cut_before_its_end_holds_every_chunk_written() {
        let bytes = written(150, Some(100), false);
        let options = LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_skip_end_magic(true);
        let records = records(&bytes, options);
        let metadata = records
            .iter()
            .filter(|r| matches!(r, Record::Metadata(_)))
            .count();
        assert_eq!(metadata, 1);
        // Chunks of 512 bytes closed as they filled, and the flush after message 100: every
        // message up to 100 is there, and none of the open chunk's is.
        let messages = records
            .iter()
            .filter(|r| matches!(r, Record::Message { .. }))
            .count();
        assert!((101..150).contains(&messages), "{messages}");
    }
}
