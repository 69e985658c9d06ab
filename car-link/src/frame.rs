//! Framing (`docs/protocol.md#framing`): start byte, length, payload, CRC-16/XMODEM, end byte; and a streaming decoder
//! that resynchronises after garbage without ever waiting on a bogus candidate.
//!
//! | Form | Bytes |
//! |---|---|
//! | short | `02 LEN payload CRC_HI CRC_LO 03` |
//! | long | `03 LEN_HI LEN_LO payload CRC_HI CRC_LO 03` |
//! | extra-long (PC side only) | `04 LEN(24 bit) payload CRC_HI CRC_LO 03` |
//!
//! # How the decoder resynchronises
//!
//! The reference receivers parse one candidate at a time: a stray start byte in noise swallows the real frame
//! after it, and a candidate that announces more bytes than ever arrive blocks the receiver until its byte timeout.
//! [`FrameDecoder`] instead follows every candidate in parallel. Every start byte that is not inside a delivered
//! frame opens a candidate, and each candidate is settled on its own as soon as its bytes allow:
//!
//! - a candidate whose length, CRC or end byte is wrong is dropped (reported as a [`FrameError`]); the candidates
//!   that start inside it are followed anyway, so a real frame that a stray start byte swallowed is recovered;
//! - a candidate that is still incomplete *waits without holding anything up*: the bytes after its start byte are
//!   scanned on, and a valid frame among them is delivered the moment its end byte arrives;
//! - a valid frame is delivered and consumed whole, with every candidate that starts inside it, so a payload that
//!   happens to contain frame-like bytes is never split up.
//!
//! When several candidates can be settled with the bytes at hand, the one that starts first wins. Frames therefore
//! come out in the order in which their end bytes arrive, which is stream order. A frame that follows a bad one is
//! delivered as soon as its last byte arrives: the bad frame's trailing `0x03`, taken for the start of a long frame,
//! simply waits in the background until its announced length has arrived (and fails its CRC) or until
//! [`FrameDecoder::expire`], which a reader calls after its byte timeout (500 ms in the reference PC tools) or at the
//! end of the stream. Apart from the chance frames below, garbage of any kind never delays or loses a valid frame
//! that follows it.
//!
//! The price is that no decoder can tell a real frame from bytes that happen to form one. Besides the chance
//! frames in garbage that every resynchronising receiver shares, this decoder can deliver a chance frame inside a
//! real frame's payload when that real frame is still arriving; the real frame is delivered too, after it. For
//! random payload bytes a chance frame needs a start byte, a fitting length, the matching CRC and the end byte,
//! about 2⁻³⁰ per payload byte. Waiting candidates keep their bytes buffered, at most one frame of the largest
//! accepted length.

use std::collections::VecDeque;

use bytes::{Buf, BufMut, Bytes, BytesMut};
use thiserror::Error;

use crate::crc::{self, checksum};

/// Start byte of the short form (1-byte length).
pub const START_SHORT: u8 = 0x02;
/// Start byte of the long form (16-bit length).
pub const START_LONG: u8 = 0x03;
/// Start byte of the extra-long form (24-bit length; PC side only, never sent to the firmware).
pub const START_EXTRA_LONG: u8 = 0x04;
/// The byte that closes every frame.
pub const END: u8 = 0x03;
/// The largest payload the firmware sends or accepts.
pub const FIRMWARE_MAX_PAYLOAD: usize = 1024;
/// The largest payload the 12.x control station accepts.
pub const PC_MAX_PAYLOAD: usize = 2_000_000;

/// Which of the three frame layouts a frame uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FrameForm {
    /// `0x02` and a 1-byte length.
    Short,
    /// `0x03` and a 16-bit length.
    Long,
    /// `0x04` and a 24-bit length (PC side only).
    ExtraLong,
}

impl FrameForm {
    /// The start byte of this form.
    pub fn start_byte(self) -> u8 {
        match self {
            FrameForm::Short => START_SHORT,
            FrameForm::Long => START_LONG,
            FrameForm::ExtraLong => START_EXTRA_LONG,
        }
    }

    /// Bytes before the payload: the start byte and the length.
    pub fn header_len(self) -> usize {
        match self {
            FrameForm::Short => 2,
            FrameForm::Long => 3,
            FrameForm::ExtraLong => 4,
        }
    }

    fn from_start_byte(byte: u8) -> Option<FrameForm> {
        match byte {
            START_SHORT => Some(FrameForm::Short),
            START_LONG => Some(FrameForm::Long),
            START_EXTRA_LONG => Some(FrameForm::ExtraLong),
            _ => None,
        }
    }
}

/// A frame whose length, CRC and end byte were all valid.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// The payload: `[id][cmd][data…]`.
    pub payload: Bytes,
    /// The layout it arrived in.
    pub form: FrameForm,
}

/// Why a payload cannot be framed.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FrameEncodeError {
    /// A zero-length payload: every receiver drops it.
    #[error("empty payload: receivers drop frames of length 0")]
    EmptyPayload,
    /// Longer than the receiver accepts (1024 bytes for the firmware).
    #[error("payload of {len} bytes exceeds the limit of {max} bytes")]
    PayloadTooLong {
        /// The payload length.
        len: usize,
        /// The limit in force.
        max: usize,
    },
}

/// A candidate frame that was dropped. Offsets count every byte fed to the decoder since it was created.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FrameError {
    /// The length field is 0 or above the limit (the firmware's 256-byte short-form bug shows up as length 0).
    #[error("frame at byte {offset}: length {len} is outside 1..={max}")]
    BadLength {
        /// Stream offset of the start byte.
        offset: u64,
        /// The announced length.
        len: usize,
        /// The decoder's payload limit.
        max: usize,
    },
    /// The CRC does not match the payload.
    #[error("frame at byte {offset}: CRC {received:#06x} received, {computed:#06x} computed")]
    Checksum {
        /// Stream offset of the start byte.
        offset: u64,
        /// CRC carried by the frame.
        received: u16,
        /// CRC computed over the payload.
        computed: u16,
    },
    /// The byte after the CRC is not `0x03`.
    #[error("frame at byte {offset}: end byte {found:#04x} at byte {end_offset}, expected 0x03")]
    EndByte {
        /// Stream offset of the start byte.
        offset: u64,
        /// Stream offset of the bad end byte.
        end_offset: u64,
        /// The byte found there.
        found: u8,
    },
    /// The stream went quiet (or ended) in the middle of a candidate frame.
    #[error("frame at byte {offset}: abandoned after {have} of {need} bytes")]
    Incomplete {
        /// Stream offset of the start byte.
        offset: u64,
        /// Bytes of the candidate received.
        have: usize,
        /// Bytes the candidate announced (header, payload, CRC and end byte), if the header was complete.
        need: usize,
    },
}

/// Frames payloads: short form up to `short_form_max`, then long form, then (if allowed) the extra-long form.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameEncoder {
    short_form_max: usize,
    max_payload: usize,
    extra_long: bool,
}

impl Default for FrameEncoder {
    fn default() -> Self {
        FrameEncoder::to_firmware()
    }
}

impl FrameEncoder {
    /// What a host sends to the firmware (and what a well-behaved simulator sends back): short form up to 255
    /// bytes, long form up to the firmware limit of 1024 bytes, never the extra-long form.
    pub fn to_firmware() -> Self {
        FrameEncoder {
            short_form_max: 255,
            max_payload: FIRMWARE_MAX_PAYLOAD,
            extra_long: false,
        }
    }

    /// The 12.x PC tools: short ≤ 255, long ≤ 65535, extra-long above, up to `max_payload`.
    pub fn pc_side(max_payload: usize) -> Self {
        FrameEncoder {
            short_form_max: 255,
            max_payload: max_payload.min(0xFF_FFFF),
            extra_long: true,
        }
    }

    /// Reproduces the firmware's short-form bug: a 256-byte payload is sent with length byte `0x00`, which every
    /// receiver drops (`docs/protocol.md#frame-forms`). For simulators that want to be faithful.
    pub fn with_firmware_short_form_bug(self) -> Self {
        FrameEncoder {
            short_form_max: 256,
            ..self
        }
    }

    /// The largest payload this encoder frames.
    pub fn max_payload(&self) -> usize {
        self.max_payload
    }

    /// The form a payload of `len` bytes gets.
    pub fn form_for(&self, len: usize) -> Result<FrameForm, FrameEncodeError> {
        if len == 0 {
            return Err(FrameEncodeError::EmptyPayload);
        }
        if len > self.max_payload {
            return Err(FrameEncodeError::PayloadTooLong {
                len,
                max: self.max_payload,
            });
        }
        if len <= self.short_form_max {
            Ok(FrameForm::Short)
        } else if len <= 0xFFFF {
            Ok(FrameForm::Long)
        } else if self.extra_long {
            Ok(FrameForm::ExtraLong)
        } else {
            Err(FrameEncodeError::PayloadTooLong { len, max: 0xFFFF })
        }
    }

    /// Appends the frame of `payload` to `dst`.
    pub fn encode(
        &self,
        payload: &[u8],
        dst: &mut BytesMut,
    ) -> Result<FrameForm, FrameEncodeError> {
        let form = self.form_for(payload.len())?;
        let len = payload.len();
        dst.reserve(len + form.header_len() + 3);
        dst.put_u8(form.start_byte());
        match form {
            // The 256-byte bug: the length byte wraps to 0.
            FrameForm::Short => dst.put_u8(len as u8),
            FrameForm::Long => dst.put_u16(len as u16),
            FrameForm::ExtraLong => dst.put_uint(len as u64, 3),
        }
        dst.put_slice(payload);
        dst.put_u16(checksum(payload));
        dst.put_u8(END);
        Ok(form)
    }

    /// The frame of `payload` as a new buffer.
    pub fn encode_to_bytes(&self, payload: &[u8]) -> Result<Bytes, FrameEncodeError> {
        let mut dst = BytesMut::new();
        self.encode(payload, &mut dst)?;
        Ok(dst.freeze())
    }
}

/// What a decoder accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DecoderLimits {
    /// The largest payload accepted; longer lengths drop the candidate.
    pub max_payload: usize,
    /// Whether `0x04` starts an extra-long frame (PC receivers) or is garbage (the firmware).
    pub accept_extra_long: bool,
}

impl DecoderLimits {
    /// A host receiving from the car: the 1024-byte firmware limit (nothing the car sends is longer, and a small
    /// limit drops bogus candidates sooner) and the extra-long form accepted.
    pub fn host() -> Self {
        DecoderLimits {
            max_payload: FIRMWARE_MAX_PAYLOAD,
            accept_extra_long: true,
        }
    }

    /// The firmware's receiver: 1..=1024 bytes, no extra-long form. What a simulator of the car should use.
    pub fn firmware() -> Self {
        DecoderLimits {
            max_payload: FIRMWARE_MAX_PAYLOAD,
            accept_extra_long: false,
        }
    }
}

impl Default for DecoderLimits {
    fn default() -> Self {
        DecoderLimits::host()
    }
}

/// Scanning state shared by [`FrameDecoder`] and [`FrameCodec`]. Positions are stream offsets: `offset` is the
/// offset of the first buffered byte, `scan` the first byte not yet looked at as a possible start byte.
#[derive(Debug, Clone, Default)]
struct Scanner {
    limits: DecoderLimits,
    offset: u64,
    scan: u64,
    /// Candidates waiting for more bytes, oldest first; all start before `scan`.
    pending: VecDeque<Pending>,
    /// Delivered frames whose bytes are still buffered (an older waiting candidate holds them), oldest first: the
    /// bytes that are not garbage when they are let go of.
    delivered: VecDeque<(u64, u64)>,
    skipped: u64,
    /// The running checksum at each buffered offset: entry `k` is the checksum of the bytes from some earlier
    /// origin up to stream offset `offset + k`, so a candidate's checksum takes a constant number of steps
    /// ([`crc::range`]) however long its payload: garbage crafted so that every byte opens a long candidate
    /// costs about as much as random bytes.
    running: VecDeque<u16>,
}

/// A candidate frame waiting for more bytes.
#[derive(Debug, Clone, Copy)]
struct Pending {
    /// Stream offset of its start byte.
    start: u64,
    /// Stream offset just past its end byte, once its length is known.
    end: Option<u64>,
}

enum Candidate {
    /// Not enough bytes yet; the total frame length once the header is complete.
    Wait(Option<usize>),
    /// A complete, valid frame: its form, header length and payload length.
    Valid {
        form: FrameForm,
        header: usize,
        len: usize,
    },
    /// Not a frame.
    Invalid(FrameError),
}

impl Scanner {
    fn new(limits: DecoderLimits) -> Self {
        Scanner {
            limits,
            ..Scanner::default()
        }
    }

    fn is_start(&self, byte: u8) -> bool {
        match FrameForm::from_start_byte(byte) {
            Some(FrameForm::ExtraLong) => self.limits.accept_extra_long,
            Some(_) => true,
            None => false,
        }
    }

    /// Stream offset just past the last buffered byte.
    fn buffered_end(&self, buf: &[u8]) -> u64 {
        self.offset + buf.len() as u64
    }

    /// Index into the buffer of stream offset `at` (which is never before `offset`).
    fn index(&self, at: u64) -> usize {
        usize::try_from(at.saturating_sub(self.offset)).unwrap_or(usize::MAX)
    }

    /// The candidate starting at stream offset `start`.
    fn examine(&self, buf: &[u8], start: u64) -> Candidate {
        let bytes = buf.get(self.index(start)..).unwrap_or_default();
        let Some(form) = bytes.first().copied().and_then(FrameForm::from_start_byte) else {
            return Candidate::Wait(None);
        };
        let header = form.header_len();
        let Some(length) = bytes.get(1..header) else {
            return Candidate::Wait(None);
        };
        let len = length
            .iter()
            .fold(0usize, |acc, &b| (acc << 8) | usize::from(b));
        let max = self.limits.max_payload;
        if len == 0 || len > max {
            return Candidate::Invalid(FrameError::BadLength {
                offset: start,
                len,
                max,
            });
        }
        let total = header + len + 3;
        let Some(frame) = bytes.get(..total) else {
            return Candidate::Wait(Some(total));
        };
        let received = u16::from_be_bytes([frame[total - 3], frame[total - 2]]);
        let from = self.index(start) + header;
        let computed = match (self.running.get(from), self.running.get(from + len)) {
            (Some(&at_from), Some(&at_to)) => crc::range(at_from, at_to, len),
            _ => checksum(&frame[header..header + len]),
        };
        if received != computed {
            return Candidate::Invalid(FrameError::Checksum {
                offset: start,
                received,
                computed,
            });
        }
        let found = frame[total - 1];
        if found != END {
            return Candidate::Invalid(FrameError::EndByte {
                offset: start,
                end_offset: start + (total - 1) as u64,
                found,
            });
        }
        Candidate::Valid { form, header, len }
    }

    /// The next valid frame or dropped candidate in `buf`; `None` when more bytes are needed.
    fn next(&mut self, buf: &mut BytesMut) -> Option<Result<Frame, FrameError>> {
        self.check_buffer(buf);
        self.extend_running(buf);
        let item = self.resolve_pending(buf).or_else(|| self.scan_new(buf));
        self.release(buf);
        item
    }

    /// Re-examines the waiting candidates that may have completed, oldest first, and settles the first that did.
    fn resolve_pending(&mut self, buf: &mut BytesMut) -> Option<Result<Frame, FrameError>> {
        let available = self.buffered_end(buf);
        for i in 0..self.pending.len() {
            let Pending { start, end } = self.pending[i];
            if end.is_some_and(|end| end > available) {
                continue;
            }
            match self.examine(buf, start) {
                Candidate::Wait(total) => self.pending[i].end = total.map(|t| start + t as u64),
                Candidate::Invalid(error) => {
                    self.pending.remove(i);
                    return Some(Err(error));
                }
                Candidate::Valid { form, header, len } => {
                    return Some(Ok(self.deliver(buf, start, form, header, len)));
                }
            }
        }
        None
    }

    /// Looks at the bytes not scanned yet: skips those that cannot start a frame, settles complete candidates and
    /// leaves incomplete ones waiting without letting them hold up the bytes after them.
    fn scan_new(&mut self, buf: &mut BytesMut) -> Option<Result<Frame, FrameError>> {
        loop {
            let from = self.index(self.scan);
            let found = buf
                .get(from..)
                .and_then(|rest| rest.iter().position(|&b| self.is_start(b)));
            let Some(at) = found else {
                self.scan = self.buffered_end(buf);
                return None;
            };
            let start = self.scan + at as u64;
            self.scan = start + 1;
            match self.examine(buf, start) {
                Candidate::Wait(total) => self.pending.push_back(Pending {
                    start,
                    end: total.map(|t| start + t as u64),
                }),
                Candidate::Invalid(error) => return Some(Err(error)),
                Candidate::Valid { form, header, len } => {
                    return Some(Ok(self.deliver(buf, start, form, header, len)));
                }
            }
        }
    }

    /// Hands out the valid frame at `start`. Candidates that start inside it are dropped with it; older waiting
    /// candidates keep their bytes, and so the payload is copied out only while one exists.
    fn deliver(
        &mut self,
        buf: &mut BytesMut,
        start: u64,
        form: FrameForm,
        header: usize,
        len: usize,
    ) -> Frame {
        let end = start + (header + len + 3) as u64;
        self.pending.retain(|p| p.start < start);
        while self.delivered.back().is_some_and(|&(s, _)| s >= start) {
            self.delivered.pop_back();
        }
        self.scan = self.scan.max(end);
        self.delivered.push_back((start, end));
        let payload = if self.pending.is_empty() {
            self.release_to(buf, start + header as u64);
            let payload = buf.split_to(len.min(buf.len())).freeze();
            self.offset += payload.len() as u64;
            self.drop_running(payload.len());
            payload
        } else {
            let from = self.index(start) + header;
            buf.get(from..from + len)
                .map(Bytes::copy_from_slice)
                .unwrap_or_default()
        };
        Frame { payload, form }
    }

    /// Drops the bytes no candidate needs any more: everything before the oldest waiting candidate and the scan
    /// position.
    fn release(&mut self, buf: &mut BytesMut) {
        let keep = self
            .pending
            .front()
            .map_or(self.scan, |p| p.start.min(self.scan));
        self.release_to(buf, keep);
    }

    /// Drops the bytes before stream offset `to`, counting those outside delivered frames as skipped garbage.
    fn release_to(&mut self, buf: &mut BytesMut, to: u64) {
        let to = to.clamp(self.offset, self.buffered_end(buf));
        let mut garbage = to - self.offset;
        while let Some(&(start, end)) = self.delivered.front() {
            if start >= to {
                break;
            }
            let covered_end = end.min(to);
            garbage = garbage.saturating_sub(covered_end.saturating_sub(start.max(self.offset)));
            if end > to {
                break;
            }
            self.delivered.pop_front();
        }
        self.skipped += garbage;
        let dropped = self.index(to);
        buf.advance(dropped);
        self.offset = to;
        self.drop_running(dropped);
    }

    /// Extends the running checksums to the end of the buffer.
    fn extend_running(&mut self, buf: &[u8]) {
        if self.running.is_empty() {
            self.running.push_back(0);
        }
        while let Some(&byte) = buf.get(self.running.len() - 1) {
            let last = self.running.back().copied().unwrap_or_default();
            self.running.push_back(crc::update(last, byte));
        }
    }

    /// Forgets the running checksums of the first `bytes` buffered bytes (they left the buffer).
    fn drop_running(&mut self, bytes: usize) {
        if bytes >= self.running.len() {
            self.running.clear();
        } else {
            self.running.drain(..bytes);
        }
    }

    /// Abandons the oldest waiting candidate; the bytes after its start byte have been scanned already.
    fn expire(&mut self, buf: &mut BytesMut) -> Option<FrameError> {
        self.check_buffer(buf);
        let Pending { start, end } = self.pending.pop_front()?;
        let available = self.buffered_end(buf);
        let error = FrameError::Incomplete {
            offset: start,
            have: usize::try_from(available.saturating_sub(start)).unwrap_or(usize::MAX),
            need: end.map_or(0, |end| usize::try_from(end - start).unwrap_or(usize::MAX)),
        };
        self.release(buf);
        Some(error)
    }

    /// Keeps the state consistent with a buffer that someone else shortened (a codec's buffer can be replaced):
    /// positions past its end are forgotten. Never happens with [`FrameDecoder`].
    fn check_buffer(&mut self, buf: &BytesMut) {
        let available = self.buffered_end(buf);
        if self.scan > available {
            self.scan = available;
            self.pending.retain(|p| p.start < available);
            self.delivered.clear();
        }
        // Entry k covers offset + k: a shortened buffer has fewer.
        self.running.truncate(buf.len() + 1);
    }
}

/// A streaming frame decoder: feed it bytes as they arrive, take frames (or dropped candidates) out.
///
/// It never panics, whatever it is fed, and after any garbage it delivers the next valid frame as soon as that
/// frame's last byte arrives (see the [module documentation](self)).
///
/// ```
/// use car_link::frame::FrameDecoder;
/// let mut decoder = FrameDecoder::host();
/// decoder.push(&[0xAA, 0x55]); // noise
/// decoder.push(&[0x02, 0x02, 0x01, 0x78, 0xCC, 0xAE, 0x03]);
/// let frame = decoder.next_frame().and_then(Result::ok).expect("one frame");
/// assert_eq!(&frame.payload[..], &[0x01, 0x78]);
/// ```
#[derive(Debug, Default)]
pub struct FrameDecoder {
    scanner: Scanner,
    buf: BytesMut,
}

impl FrameDecoder {
    /// A decoder with the given limits.
    pub fn new(limits: DecoderLimits) -> Self {
        FrameDecoder {
            scanner: Scanner::new(limits),
            buf: BytesMut::new(),
        }
    }

    /// A decoder for a host receiving from the car ([`DecoderLimits::host`]).
    pub fn host() -> Self {
        FrameDecoder::new(DecoderLimits::host())
    }

    /// A decoder for the car side receiving from a host ([`DecoderLimits::firmware`]).
    pub fn firmware() -> Self {
        FrameDecoder::new(DecoderLimits::firmware())
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// The next valid frame, or the next dropped candidate; `None` when more bytes are needed.
    pub fn next_frame(&mut self) -> Option<Result<Frame, FrameError>> {
        self.scanner.next(&mut self.buf)
    }

    /// Abandons the oldest candidate frame that is waiting for more bytes (the bytes after its start byte have
    /// been scanned for frames already, so nothing is lost). Call it when the byte timeout elapses or the stream
    /// ends, after draining [`Self::next_frame`]; repeat until it returns `None`. Waiting candidates never hold up
    /// a valid frame, so this only reports them and frees their bytes.
    pub fn expire(&mut self) -> Option<FrameError> {
        self.scanner.expire(&mut self.buf)
    }

    /// Everything still decodable at the end of a stream (or after a byte timeout): frames and dropped candidates,
    /// in stream order. Leaves the decoder empty.
    pub fn drain_stale(&mut self) -> Vec<Result<Frame, FrameError>> {
        let mut out = Vec::new();
        loop {
            while let Some(item) = self.next_frame() {
                out.push(item);
            }
            match self.expire() {
                Some(error) => out.push(Err(error)),
                None => return out,
            }
        }
    }

    /// Whether bytes are buffered: a candidate frame waiting for more bytes, or bytes not looked at yet.
    pub fn has_pending(&self) -> bool {
        !self.buf.is_empty()
    }

    /// Bytes discarded as garbage so far: every byte let go of that was not part of a delivered frame.
    pub fn skipped_bytes(&self) -> u64 {
        self.scanner.skipped
    }
}

/// A [`tokio_util::codec`] codec: encodes payloads into frames and decodes frames, yielding dropped candidates as
/// `Err` items so that a [`tokio_util::codec::FramedRead`] keeps going after garbage.
#[cfg(feature = "client")]
#[derive(Debug, Default)]
pub struct FrameCodec {
    encoder: FrameEncoder,
    scanner: Scanner,
}

#[cfg(feature = "client")]
impl FrameCodec {
    /// A codec with the given encoder and decoder limits.
    pub fn new(encoder: FrameEncoder, limits: DecoderLimits) -> Self {
        FrameCodec {
            encoder,
            scanner: Scanner::new(limits),
        }
    }

    /// The host side: frames to the firmware, decodes with [`DecoderLimits::host`].
    pub fn host() -> Self {
        FrameCodec::new(FrameEncoder::to_firmware(), DecoderLimits::host())
    }

    /// The car side (a simulator): short form ≤ 255, long form ≤ 1024, decodes like the firmware.
    pub fn car() -> Self {
        FrameCodec::new(FrameEncoder::to_firmware(), DecoderLimits::firmware())
    }
}

#[cfg(feature = "client")]
impl tokio_util::codec::Decoder for FrameCodec {
    type Item = Result<Frame, FrameError>;
    type Error = std::io::Error;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<Self::Item>, Self::Error> {
        Ok(self.scanner.next(src))
    }

    fn decode_eof(&mut self, src: &mut BytesMut) -> Result<Option<Self::Item>, Self::Error> {
        if let Some(item) = self.scanner.next(src) {
            return Ok(Some(item));
        }
        Ok(self.scanner.expire(src).map(Err))
    }
}

#[cfg(feature = "client")]
impl<T: AsRef<[u8]>> tokio_util::codec::Encoder<T> for FrameCodec {
    type Error = std::io::Error;

    fn encode(&mut self, payload: T, dst: &mut BytesMut) -> Result<(), Self::Error> {
        self.encoder
            .encode(payload.as_ref(), dst)
            .map(|_| ())
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode_all(bytes: &[u8]) -> Vec<Result<Frame, FrameError>> {
        let mut decoder = FrameDecoder::host();
        decoder.push(bytes);
        decoder.drain_stale()
    }

    fn frames(bytes: &[u8]) -> Vec<Bytes> {
        decode_all(bytes)
            .into_iter()
            .filter_map(Result::ok)
            .map(|f| f.payload)
            .collect()
    }

    const GET_STATE_TO_1: [u8; 7] = [0x02, 0x02, 0x01, 0x78, 0xCC, 0xAE, 0x03];

    #[test]
    fn encodes_the_get_state_request_vector() {
        let frame = FrameEncoder::to_firmware().encode_to_bytes(&[0x01, 0x78]);
        assert_eq!(frame.as_deref().ok(), Some(&GET_STATE_TO_1[..]));
    }

    #[test]
    fn decodes_after_garbage() {
        let mut bytes = vec![0x00, 0xFF, 0x41, 0x42];
        bytes.extend_from_slice(&GET_STATE_TO_1);
        assert_eq!(frames(&bytes), vec![Bytes::from_static(&[0x01, 0x78])]);
    }

    #[test]
    fn recovers_a_frame_swallowed_by_a_stray_start_byte() {
        // A stray 0x02 announcing 9 bytes would, in the reference, eat the real frame.
        let mut bytes = vec![0x02, 0x09];
        bytes.extend_from_slice(&GET_STATE_TO_1);
        bytes.extend_from_slice(&[0x00, 0x00, 0x00, 0x00]);
        assert_eq!(frames(&bytes), vec![Bytes::from_static(&[0x01, 0x78])]);
    }

    #[test]
    fn a_bogus_candidate_neither_holds_up_the_next_frame_nor_outlives_the_timeout() {
        let mut decoder = FrameDecoder::host();
        decoder.push(&[0x03, 0x03, 0xFF]); // long form, 1023 bytes announced
        decoder.push(&GET_STATE_TO_1);
        let items: Vec<_> = std::iter::from_fn(|| decoder.next_frame()).collect();
        // The second 0x03 announces 0xFF02 bytes: dropped at once; then the frame, without a timeout.
        assert!(matches!(
            &items[..],
            [Err(FrameError::BadLength { offset: 1, .. }), Ok(frame)]
                if frame.payload[..] == [0x01, 0x78]
        ));
        assert!(decoder.has_pending());
        assert_eq!(
            decoder.expire(),
            Some(FrameError::Incomplete {
                offset: 0,
                have: 10,
                need: 1029,
            })
        );
        assert_eq!(decoder.next_frame(), None);
        assert_eq!(decoder.expire(), None);
        assert!(!decoder.has_pending());
        assert_eq!(decoder.skipped_bytes(), 3);
    }

    #[test]
    fn a_good_frame_right_after_a_bad_crc_is_delivered_at_once() {
        let mut decoder = FrameDecoder::host();
        decoder.push(&[0x02, 0x02, 0x01, 0x78, 0xCC, 0xAF, 0x03]);
        let dropped: Vec<_> = std::iter::from_fn(|| decoder.next_frame()).collect();
        assert!(!dropped.is_empty() && dropped.iter().all(Result::is_err));
        // The request/reply link is quiet now; the reply arrives and must come out without any timeout.
        decoder.push(&GET_STATE_TO_1);
        assert!(
            matches!(decoder.next_frame(), Some(Ok(frame)) if frame.payload[..] == [0x01, 0x78])
        );
        assert_eq!(decoder.next_frame(), None);
        // The bad frame's end byte, read as a long-form start announcing 0x0202 bytes, waits in the background.
        assert!(matches!(
            decoder.expire(),
            Some(FrameError::Incomplete {
                offset: 6,
                need: 520,
                ..
            })
        ));
    }

    #[test]
    fn a_frame_swallowed_by_a_stray_start_byte_comes_out_before_the_timeout() {
        let mut decoder = FrameDecoder::host();
        decoder.push(&[0x02, 0x09]);
        decoder.push(&GET_STATE_TO_1);
        assert!(matches!(decoder.next_frame(), Some(Ok(_))));
        assert_eq!(decoder.next_frame(), None);
        // The stray candidate completes with the next bytes, fails its CRC and frees the buffer.
        decoder.push(&[0x00, 0x00, 0x00, 0x00, 0x00]);
        let rest: Vec<_> = std::iter::from_fn(|| decoder.next_frame()).collect();
        assert!(rest.iter().all(Result::is_err), "{rest:?}");
        assert!(!decoder.has_pending());
        assert_eq!(decoder.skipped_bytes(), 7);
    }

    #[test]
    fn a_valid_frame_is_consumed_whole_even_while_an_older_candidate_waits() {
        // The payload holds a complete frame of its own; it must not come out as a frame.
        let inner = [0x02, 0x02, 0x01, 0x78, 0xCC, 0xAE, 0x03];
        let mut payload = vec![0x01, 0x00];
        payload.extend_from_slice(&inner);
        let outer = FrameEncoder::to_firmware()
            .encode_to_bytes(&payload)
            .unwrap_or_default();
        let mut decoder = FrameDecoder::host();
        decoder.push(&outer);
        assert!(matches!(decoder.next_frame(), Some(Ok(frame)) if frame.payload == payload));
        assert_eq!(decoder.next_frame(), None);
        assert!(!decoder.has_pending());
        assert_eq!(decoder.skipped_bytes(), 0);
    }

    #[test]
    fn bad_crc_is_reported_with_its_offset() {
        let mut bytes = vec![0xEE];
        bytes.extend_from_slice(&[0x02, 0x02, 0x01, 0x78, 0xCC, 0xAF, 0x03]);
        let result = decode_all(&bytes);
        assert_eq!(
            result.first(),
            Some(&Err(FrameError::Checksum {
                offset: 1,
                received: 0xCCAF,
                computed: 0xCCAE
            }))
        );
    }

    #[test]
    fn bad_end_byte_is_reported() {
        let result = decode_all(&[0x02, 0x02, 0x01, 0x78, 0xCC, 0xAE, 0x04]);
        assert_eq!(
            result.first(),
            Some(&Err(FrameError::EndByte {
                offset: 0,
                end_offset: 6,
                found: 0x04
            }))
        );
    }

    #[test]
    fn length_zero_and_over_the_limit_are_dropped() {
        assert!(matches!(
            decode_all(&[0x02, 0x00, 0x01])[0],
            Err(FrameError::BadLength { len: 0, .. })
        ));
        assert!(matches!(
            decode_all(&[0x03, 0x04, 0x01, 0x00])[0],
            Err(FrameError::BadLength {
                len: 1025,
                max: 1024,
                ..
            })
        ));
    }

    #[test]
    fn short_form_up_to_255_then_long_form() {
        let encoder = FrameEncoder::to_firmware();
        assert_eq!(encoder.form_for(255), Ok(FrameForm::Short));
        assert_eq!(encoder.form_for(256), Ok(FrameForm::Long));
        assert_eq!(encoder.form_for(1024), Ok(FrameForm::Long));
        assert_eq!(
            encoder.form_for(1025),
            Err(FrameEncodeError::PayloadTooLong {
                len: 1025,
                max: 1024
            })
        );
        assert_eq!(encoder.form_for(0), Err(FrameEncodeError::EmptyPayload));
    }

    #[test]
    fn the_firmware_256_byte_bug_produces_a_frame_every_receiver_drops() {
        let payload = vec![0x01; 256];
        let frame = FrameEncoder::to_firmware()
            .with_firmware_short_form_bug()
            .encode_to_bytes(&payload);
        let frame = frame.unwrap_or_default();
        assert_eq!(&frame[..2], &[0x02, 0x00]);
        assert!(frames(&frame).is_empty());
        // The correct encoder uses the long form for it, and it decodes.
        let good = FrameEncoder::to_firmware()
            .encode_to_bytes(&payload)
            .unwrap_or_default();
        assert_eq!(&good[..3], &[0x03, 0x01, 0x00]);
        assert_eq!(frames(&good), vec![Bytes::from(payload)]);
    }

    #[test]
    fn the_extra_long_form_is_accepted_by_hosts_only() {
        let payload = vec![0x01, 0x00, b'h', b'i'];
        let mut frame = vec![0x04, 0x00, 0x00, 0x04];
        frame.extend_from_slice(&payload);
        frame.extend_from_slice(&checksum(&payload).to_be_bytes());
        frame.push(END);
        assert_eq!(frames(&frame), vec![Bytes::from(payload)]);
        let mut firmware = FrameDecoder::firmware();
        firmware.push(&frame);
        assert!(firmware.drain_stale().into_iter().all(|r| r.is_err()));
        let encoded = FrameEncoder::pc_side(PC_MAX_PAYLOAD)
            .encode_to_bytes(&vec![7u8; 70_000])
            .unwrap_or_default();
        assert_eq!(&encoded[..4], &[0x04, 0x01, 0x11, 0x70]);
    }

    #[test]
    fn frames_split_across_pushes_decode() {
        let mut decoder = FrameDecoder::host();
        for byte in GET_STATE_TO_1 {
            assert_eq!(decoder.next_frame(), None);
            decoder.push(&[byte]);
        }
        assert!(matches!(decoder.next_frame(), Some(Ok(_))));
    }
}
