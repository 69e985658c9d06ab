//! Codec throughput: framing plus typed encoding and decoding of GET_STATE replies (the telemetry stream) and
//! AP_ADD_POINTS packets (route upload). Run with `cargo bench -p drivecheck-benches --bench codec`.

use std::hint::black_box;
use std::time::Duration;

use car_link::firmware::FirmwareVersion;
use car_link::frame::{FrameDecoder, FrameEncoder};
use car_link::message::{Dialect, Reply, Request, RoutePoint};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

#[path = "../../../car-link/tests/link/support/mod.rs"]
mod support;

use support::sample_state;

const VERSION: FirmwareVersion = FirmwareVersion::V12_3;
const FRAMES: usize = 1000;

fn points() -> Vec<RoutePoint> {
    (0..5)
        .map(|i| RoutePoint::at(10.5 + f64::from(i), -3.25, 2.5))
        .collect()
}

/// `FRAMES` copies of a frame, back to back, as they would arrive on the link.
fn stream_of(payload: &[u8]) -> Vec<u8> {
    let frame = FrameEncoder::to_firmware()
        .encode_to_bytes(payload)
        .expect("frames");
    frame
        .iter()
        .copied()
        .cycle()
        .take(frame.len() * FRAMES)
        .collect()
}

fn get_state_reply(c: &mut Criterion) {
    let reply = Reply::State(sample_state(VERSION));
    let dialect = Dialect::firmware(VERSION);
    let encoder = FrameEncoder::to_firmware();
    let payload = reply.encode(1, dialect).expect("encodes");
    let stream = stream_of(&payload);
    let mut group = c.benchmark_group("get_state_reply");
    group.throughput(Throughput::Bytes(stream.len() as u64));
    group.bench_function("encode_1000_frames", |b| {
        let mut out = bytes::BytesMut::with_capacity(stream.len());
        b.iter(|| {
            out.clear();
            for _ in 0..FRAMES {
                let payload = black_box(&reply).encode(1, dialect).expect("encodes");
                encoder.encode(&payload, &mut out).expect("frames");
            }
            black_box(out.len())
        })
    });
    group.bench_function("decode_1000_frames", |b| {
        b.iter(|| {
            let mut decoder = FrameDecoder::host();
            decoder.push(black_box(&stream));
            let mut states = 0;
            while let Some(Ok(frame)) = decoder.next_frame() {
                if let Ok((_, Reply::State(_))) = Reply::decode(&frame.payload, VERSION) {
                    states += 1;
                }
            }
            assert_eq!(states, FRAMES);
        })
    });
    group.finish();
}

fn add_points(c: &mut Criterion) {
    let request = Request::AddPoints(points());
    let dialect = Dialect::host(VERSION);
    let encoder = FrameEncoder::to_firmware();
    let payload = request.encode(1, dialect).expect("encodes");
    let stream = stream_of(&payload);
    let mut group = c.benchmark_group("ap_add_points_5");
    group.throughput(Throughput::Bytes(stream.len() as u64));
    group.bench_function("encode_1000_frames", |b| {
        let mut out = bytes::BytesMut::with_capacity(stream.len());
        b.iter(|| {
            out.clear();
            for _ in 0..FRAMES {
                let payload = black_box(&request).encode(1, dialect).expect("encodes");
                encoder.encode(&payload, &mut out).expect("frames");
            }
            black_box(out.len())
        })
    });
    group.bench_function("decode_1000_frames", |b| {
        b.iter(|| {
            let mut decoder = FrameDecoder::firmware();
            decoder.push(black_box(&stream));
            let mut packets = 0;
            while let Some(Ok(frame)) = decoder.next_frame() {
                if let Ok((_, Request::AddPoints(_))) = Request::decode(&frame.payload, VERSION) {
                    packets += 1;
                }
            }
            assert_eq!(packets, FRAMES);
        })
    });
    group.finish();
}

/// Garbage of 64 KiB decoded by the host's decoder: random bytes, and bytes crafted so that every
/// byte opens a long-form candidate with a valid length and end byte (all `0x03`: length 771, end
/// byte `0x03`), which makes the decoder check a checksum for every byte. The ratio of the two is
/// what `issues #13` bounds (crafted within 10× of random).
fn garbage(c: &mut Criterion) {
    const LEN: usize = 64 * 1024;
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let random: Vec<u8> = (0..LEN)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 24) as u8
        })
        .collect();
    let crafted = vec![0x03u8; LEN];
    let mut group = c.benchmark_group("decode_garbage_64k");
    group.throughput(Throughput::Bytes(LEN as u64));
    for (name, bytes) in [("random", &random), ("all_0x03", &crafted)] {
        group.bench_function(name, |b| {
            b.iter(|| {
                let mut decoder = FrameDecoder::host();
                let mut items = 0usize;
                for chunk in bytes.chunks(256) {
                    decoder.push(black_box(chunk));
                    while let Some(item) = decoder.next_frame() {
                        items += usize::from(item.is_err());
                    }
                }
                while decoder.expire().is_some() {}
                black_box(items)
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = codec;
    config = Criterion::default().warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(2));
    targets = get_state_reply, add_points, garbage
}
criterion_main!(codec);
