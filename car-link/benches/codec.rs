//! Codec throughput: framing plus typed encoding and decoding of GET_STATE replies (the telemetry stream) and
//! AP_ADD_POINTS packets (route upload). Run with `cargo bench -p car-link --bench codec`.

use std::hint::black_box;
use std::time::Duration;

use car_link::frame::{FrameDecoder, FrameEncoder};
use car_link::message::{CarState, Dialect, Reply, Request, RoutePoint};
use car_link::version::FirmwareVersion;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

const VERSION: FirmwareVersion = FirmwareVersion::V12_3;
const FRAMES: usize = 1000;

fn state() -> CarState {
    CarState {
        version: VERSION,
        roll: 0.5,
        pitch: -0.25,
        yaw: 45.0,
        accel: [0.01, -0.02, 1.0],
        gyro: [0.0, 0.0, 0.1],
        mag: [10.0, -20.0, 30.0],
        px: 12.3456,
        py: -7.5,
        speed: 1.5,
        v_in: 39.0,
        temp_mos: 25.0,
        mc_fault: 0,
        px_gps: 12.34,
        py_gps: -7.49,
        ap_goal_px: 13.0,
        ap_goal_py: -6.8,
        ap_rad: 0.8,
        ms_today: 45_296_789,
        ap_route_left: 7,
        px_uwb: 12.2,
        py_uwb: -7.6,
    }
}

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
    let reply = Reply::State(state());
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

criterion_group! {
    name = codec;
    config = Criterion::default().warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(2));
    targets = get_state_reply, add_points
}
criterion_main!(codec);
