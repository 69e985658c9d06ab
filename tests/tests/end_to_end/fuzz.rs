//! Fuzzing without a nightly toolchain: the frame decoder, the scenario parser and the case parser
//! fed mutated and random input, deterministically from a seed. Each must return an error (or a
//! value) and never panic; a delivered frame must be one that was sent or a chance frame with a
//! valid checksum and end byte.
//!
//! The default run is small (it is part of `cargo test`); the long runs are ignored tests:
//!
//! ```sh
//! DRIVECHECK_FUZZ_INPUTS=10000000 cargo test --release -p drivecheck-tests --test end_to_end fuzz -- --ignored --nocapture
//! ```

use std::panic::{AssertUnwindSafe, catch_unwind};

use car_link::crc::checksum;
use car_link::frame::{FrameDecoder, FrameEncoder};
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// Inputs of a long run: `DRIVECHECK_FUZZ_INPUTS`, or `default`.
fn inputs(default: u64) -> u64 {
    std::env::var("DRIVECHECK_FUZZ_INPUTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Mutates `bytes` a few times: flips, overwrites with protocol-significant bytes, inserts,
/// deletes, duplicates a stretch, truncates.
fn mutate(rng: &mut Pcg64Mcg, bytes: &mut Vec<u8>) {
    const SPECIAL: [u8; 8] = [0x02, 0x03, 0x04, 0x00, 0xFF, 0x0A, b'"', b'='];
    for _ in 0..rng.random_range(1..6) {
        let len = bytes.len();
        match rng.random_range(0..6) {
            0 if len > 0 => {
                let i = rng.random_range(0..len);
                bytes[i] ^= 1 << rng.random_range(0..8);
            }
            1 if len > 0 => {
                let i = rng.random_range(0..len);
                bytes[i] = SPECIAL[rng.random_range(0..SPECIAL.len())];
            }
            2 => {
                let i = rng.random_range(0..=len);
                bytes.insert(i, rng.random());
            }
            3 if len > 0 => {
                let i = rng.random_range(0..len);
                let n = rng.random_range(1..=(len - i).min(16));
                bytes.drain(i..i + n);
            }
            4 if len > 0 => {
                let i = rng.random_range(0..len);
                let n = rng.random_range(1..=(len - i).min(64));
                let stretch = bytes[i..i + n].to_vec();
                let at = rng.random_range(0..=len);
                bytes.splice(at..at, stretch);
            }
            5 if len > 0 => bytes.truncate(rng.random_range(0..len)),
            _ => {}
        }
    }
}

/// One input for the frame decoder: valid frames, random bytes and crafted headers, mutated.
fn frame_input(rng: &mut Pcg64Mcg, encoder: &FrameEncoder) -> Vec<u8> {
    let mut bytes = Vec::new();
    for _ in 0..rng.random_range(1..5) {
        match rng.random_range(0..4) {
            0 | 1 => {
                let len = rng.random_range(1..300);
                let payload: Vec<u8> = (0..len).map(|_| rng.random()).collect();
                if let Ok(frame) = encoder.encode_to_bytes(&payload) {
                    bytes.extend_from_slice(&frame);
                }
            }
            2 => bytes.extend((0..rng.random_range(0..200)).map(|_| rng.random::<u8>())),
            _ => {
                // A header announcing a long payload, then a little of it.
                let start = [0x02, 0x03, 0x04][rng.random_range(0..3)];
                bytes.push(start);
                bytes.extend((0..3).map(|_| rng.random::<u8>()));
                bytes.extend((0..rng.random_range(0..40)).map(|_| rng.random::<u8>()));
            }
        }
    }
    if rng.random_bool(0.7) {
        mutate(rng, &mut bytes);
    }
    bytes
}

/// Feeds `bytes` in random chunks to both decoders; checks every delivered frame. The frames
/// delivered.
fn decode(rng: &mut Pcg64Mcg, bytes: &[u8]) -> usize {
    let mut delivered = 0;
    for mut decoder in [FrameDecoder::host(), FrameDecoder::firmware()] {
        let mut rest = bytes;
        while !rest.is_empty() {
            let n = rng.random_range(1..=rest.len().min(64));
            decoder.push(&rest[..n]);
            rest = &rest[n..];
            while let Some(item) = decoder.next_frame() {
                if let Ok(frame) = item {
                    // A delivered frame is in the input, checksum and end byte included.
                    let crc = checksum(&frame.payload).to_be_bytes();
                    let tail = [crc[0], crc[1], 0x03];
                    let mut whole = frame.payload.to_vec();
                    whole.extend_from_slice(&tail);
                    assert!(
                        bytes.windows(whole.len()).any(|w| w == whole.as_slice()),
                        "a delivered frame is not in the input"
                    );
                    delivered += 1;
                }
            }
        }
        while decoder.expire().is_some() {}
        assert!(!decoder.has_pending());
    }
    delivered
}

fn fuzz_frames(inputs: u64, seed: u64) -> (u64, usize) {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let encoder = FrameEncoder::to_firmware();
    let mut frames = 0;
    for _ in 0..inputs {
        let bytes = frame_input(&mut rng, &encoder);
        frames += decode(&mut rng, &bytes);
    }
    (inputs, frames)
}

/// The texts the parsers start from: the bundled scenarios and the case examples of the docs.
fn scenario_texts() -> Vec<&'static str> {
    scenarios::bundled::names()
        .iter()
        .filter_map(|name| scenarios::bundled::text(name))
        .collect()
}

fn case_texts() -> Vec<&'static str> {
    let doc = include_str!("../../../docs/case-format.md");
    doc.split("```json\n")
        .skip(1)
        .filter_map(|block| block.split("\n```").next())
        .collect()
}

/// Mutated scenarios and cases through their parsers and checks: the inputs, how many parsed.
fn fuzz_parsers(inputs: u64, seed: u64) -> (u64, u64, u64) {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let scenarios_in = scenario_texts();
    let cases_in = case_texts();
    let scenario = scenarios::bundled::load("parking-lot-2anchors")
        .expect("the bundled scenario loads")
        .scenario;
    let (mut scenarios_ok, mut cases_ok) = (0, 0);
    for i in 0..inputs {
        let (source, is_case) = if i % 2 == 0 {
            (scenarios_in[rng.random_range(0..scenarios_in.len())], false)
        } else {
            (cases_in[rng.random_range(0..cases_in.len())], true)
        };
        let mut bytes = source.as_bytes().to_vec();
        mutate(&mut rng, &mut bytes);
        let text = String::from_utf8_lossy(&bytes);
        if is_case {
            if let Ok(case) = campaign::files::Case::from_json(&text) {
                cases_ok += 1;
                let _ = case.check();
                let _ = case.check_route(&scenario);
                let _ = case.check_faults_act(&scenario);
            }
        } else if scenarios::from_toml_str(&text, "fuzz.toml").is_ok() {
            scenarios_ok += 1;
        }
    }
    (inputs, scenarios_ok, cases_ok)
}

/// Runs `f`, turning a panic into a failure that names the seed.
fn no_panic<T>(what: &str, seed: u64, f: impl FnOnce() -> T) -> T {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(value) => value,
        Err(_) => panic!("{what} panicked (seed {seed})"),
    }
}

#[test]
fn the_frame_decoder_takes_any_bytes() {
    let (inputs, frames) = no_panic("the frame decoder", 1, || fuzz_frames(100_000, 1));
    assert!(
        frames > inputs as usize / 2,
        "{frames} frames in {inputs} inputs"
    );
}

#[test]
fn the_scenario_and_case_parsers_take_any_text() {
    let (inputs, scenarios_ok, cases_ok) = no_panic("the parsers", 2, || fuzz_parsers(2_000, 2));
    // Some mutations leave valid files: the parsers did get past the first byte.
    assert!(
        scenarios_ok > 0 && cases_ok > 0,
        "{inputs} inputs: {scenarios_ok} {cases_ok}"
    );
}

#[test]
#[ignore = "long: DRIVECHECK_FUZZ_INPUTS inputs (default 10 million)"]
fn fuzz_the_frame_decoder_long() {
    let seed = 0x0D15_C0DE;
    let started = std::time::Instant::now();
    let (inputs, frames) = no_panic("the frame decoder", seed, || {
        fuzz_frames(inputs(10_000_000), seed)
    });
    println!(
        "frame decoder: {inputs} inputs, {frames} frames delivered, 0 panics, {:.0} s",
        started.elapsed().as_secs_f64()
    );
}

#[test]
#[ignore = "long: DRIVECHECK_FUZZ_INPUTS inputs (default 1 million)"]
fn fuzz_the_parsers_long() {
    let seed = 0xCA5E;
    let started = std::time::Instant::now();
    let (inputs, scenarios_ok, cases_ok) = no_panic("the parsers", seed, || {
        fuzz_parsers(inputs(1_000_000), seed)
    });
    println!(
        "parsers: {inputs} inputs ({scenarios_ok} scenarios and {cases_ok} cases parsed), 0 \
         panics, {:.0} s",
        started.elapsed().as_secs_f64()
    );
}

/// A request of every command the simulated car handles, with ordinary values: the templates the
/// structured fuzzer fills with hostile ones.
fn command_templates(
    version: car_link::firmware::FirmwareVersion,
) -> Vec<car_link::message::Request> {
    use car_link::config::MainConfig;
    use car_link::message::{
        Anchor, EnuRef, Pose, RcControl, RcMode, Request, RoutePoint, SyncPoint,
    };
    let route: Vec<RoutePoint> = (0..4)
        .map(|k| RoutePoint {
            time_ms: 1000 * k,
            ..RoutePoint::at(f64::from(k), 0.5 * f64::from(k), 1.0)
        })
        .collect();
    let pose = Pose {
        x: 1.0,
        y: 2.0,
        yaw: 30.0,
    };
    let mut requests = vec![
        Request::GetState,
        Request::SetPos(pose),
        Request::SetPosAck(pose),
        Request::SetEnuRef(EnuRef {
            lat: 57.7,
            lon: 11.9,
            height: 10.0,
        }),
        Request::GetEnuRef,
        Request::AddPoints(route.clone()),
        Request::ReplaceRoute(route),
        Request::RemoveLastPoint,
        Request::ClearPoints,
        Request::GetRoutePart { first: 0, num: 4 },
        Request::SetActive {
            active: true,
            reset: version >= car_link::firmware::FirmwareVersion::V12_3,
        },
        Request::SyncPoint(SyncPoint {
            point: 1,
            time_ms: 500,
            min_diff_ms: 100,
        }),
        Request::SetServoDirect(0.5),
        Request::SetYawOffset(10.0),
        Request::SetYawOffsetAck(10.0),
        Request::SetMsToday(1000),
        Request::AddUwbAnchor(Anchor {
            id: 50,
            px: 3.0,
            py: 4.0,
            height: 1.0,
        }),
        Request::ClearUwbAnchors,
        Request::SetMainConfig(MainConfig::factory_default(version, 1)),
        Request::GetMainConfig,
        Request::GetMainConfigDefault,
    ];
    for mode in [
        RcMode::Current,
        RcMode::Duty,
        RcMode::Pid,
        RcMode::CurrentBrake,
    ] {
        requests.push(Request::RcControl(RcControl {
            mode,
            throttle: 0.5,
            steering: 0.1,
        }));
    }
    for text in [
        "fi_set_enabled 1",
        "fi_add_fault uwb_range_50 OFFSET 4.0 0 8",
        "fi_add_fault uwb_travel_dist AMPLIFICATION 3 50 10",
        "fi_add_fault px OFFSET 10 0 0",
        "fi_clear_faults",
        "pos_uwb_reset_pos",
    ] {
        requests.push(Request::TerminalCmd(text.to_owned()));
    }
    requests
}

/// Values a field can hold that no sane host sends: NaN and infinities as IEEE floats, the
/// extremes and signs of the wire's integers, zeros.
const HOSTILE: [[u8; 4]; 12] = [
    [0x7F, 0xC0, 0x00, 0x00], // f32 NaN
    [0xFF, 0xC0, 0x00, 0x01], // f32 negative NaN with payload
    [0x7F, 0x80, 0x00, 0x00], // f32 +inf
    [0xFF, 0x80, 0x00, 0x00], // f32 −inf
    [0x7F, 0x7F, 0xFF, 0xFF], // f32::MAX, i32 large
    [0x00, 0x00, 0x00, 0x01], // subnormal, i32 1
    [0x80, 0x00, 0x00, 0x00], // −0.0, i32::MIN
    [0x7F, 0xFF, 0xFF, 0xFF], // NaN, i32::MAX
    [0x00, 0x00, 0x00, 0x00],
    [0xFF, 0xFF, 0xFF, 0xFF], // −1, NaN
    [0xBF, 0x80, 0x00, 0x00], // −1.0
    [0x4E, 0x6E, 0x6B, 0x28], // 1e9
];

/// Hostile words for terminal commands' arguments.
const HOSTILE_WORDS: [&str; 12] = [
    "nan",
    "inf",
    "-inf",
    "1e39",
    "-1e39",
    "0",
    "-0",
    "1e-45",
    "2147483648",
    "-2147483649",
    "99999999999999999999",
    "",
];

/// One valid frame's payload of a command with hostile values: a template's encoding with windows
/// of its data overwritten by [`HOSTILE`] patterns or random bytes, its length and command kept
/// (a terminal command gets hostile arguments instead).
fn hostile_payload(
    rng: &mut Pcg64Mcg,
    templates: &[car_link::message::Request],
    dialect: car_link::message::Dialect,
) -> Vec<u8> {
    use car_link::message::Request;
    let template = &templates[rng.random_range(0..templates.len())];
    let request = match template {
        Request::TerminalCmd(text) => {
            let mut words: Vec<String> = text.split(' ').map(str::to_owned).collect();
            for word in words.iter_mut().skip(2) {
                if rng.random_bool(0.6) {
                    *word = HOSTILE_WORDS[rng.random_range(0..HOSTILE_WORDS.len())].to_owned();
                }
            }
            Request::TerminalCmd(words.join(" "))
        }
        other => other.clone(),
    };
    let mut payload = request
        .encode(1, dialect)
        .unwrap_or_else(|e| panic!("{request:?} does not encode: {e}"))
        .to_vec();
    if payload.len() > 2 {
        for _ in 0..rng.random_range(1..4) {
            let at = rng.random_range(2..payload.len());
            let window = &mut payload[at..];
            let n = window.len().min(4);
            if rng.random_bool(0.8) {
                let pattern = HOSTILE[rng.random_range(0..HOSTILE.len())];
                window[..n].copy_from_slice(&pattern[..n]);
            } else {
                window[..n].iter_mut().for_each(|b| *b = rng.random());
            }
        }
    }
    payload
}

/// Feeds a simulated board `frames` hostile commands (every command, each firmware generation
/// the simulator has), stepping its clock between them and asking its state every 50 frames: the
/// board must never panic and always answer. Returns the frames sent, those that decode as their
/// command (the rest test the decoder's refusal) and the states answered.
fn fuzz_car_commands(frames: u64, seed: u64) -> (u64, u64, u64) {
    use car_link::firmware::FirmwareVersion;
    use car_link::message::{Dialect, Request};
    use car_sim::{Board, CarOptions, SimCar};
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut sent = 0;
    let mut answered = 0;
    let mut decoded = 0;
    let boards = 1 + frames / 20_000;
    for b in 0..boards {
        let version = FirmwareVersion::SIMULATED[(b % 2) as usize];
        let dialect = Dialect::host(version);
        let templates = command_templates(version);
        let get_state = Request::GetState
            .encode(1, dialect)
            .expect("GET_STATE encodes");
        let mut board = Board::new(SimCar::new(CarOptions {
            firmware: version,
            seed: seed ^ b,
            ..CarOptions::default()
        }));
        let share = frames / boards + u64::from(b < frames % boards);
        for k in 0..share {
            let payload = hostile_payload(&mut rng, &templates, dialect);
            decoded += u64::from(Request::decode(&payload, version).is_ok());
            let step = || board.handle(&payload);
            if catch_unwind(AssertUnwindSafe(step)).is_err() {
                panic!(
                    "the simulated car ({version}) panicked on the payload {payload:02x?} (seed \
                     {seed}, board {b}, frame {k})"
                );
            }
            for _ in 0..rng.random_range(0..4) {
                if catch_unwind(AssertUnwindSafe(|| board.car_mut().step())).is_err() {
                    panic!(
                        "the simulated car ({version}) panicked stepping after {payload:02x?} \
                         (seed {seed}, board {b}, frame {k})"
                    );
                }
            }
            sent += 1;
            if k % 50 == 49 {
                let replies = board.handle(&get_state);
                assert_eq!(
                    replies.len(),
                    1,
                    "the simulated car ({version}) did not answer GET_STATE (seed {seed}, board \
                     {b}, frame {k})"
                );
                answered += 1;
            }
        }
    }
    (sent, decoded, answered)
}

#[test]
fn the_simulated_car_takes_hostile_values_in_every_command() {
    let (sent, decoded, answered) = fuzz_car_commands(200_000, 3);
    // A GET_STATE every 50 frames of each board's share.
    assert_eq!(sent, 200_000);
    assert!(answered > sent / 51, "{answered} states answered");
    assert!(decoded > sent / 2, "{decoded} of {sent} decoded");
}

#[test]
#[ignore = "long: DRIVECHECK_FUZZ_INPUTS frames (default 1 million)"]
fn fuzz_the_simulated_car_long() {
    let seed = 0xCA12;
    let started = std::time::Instant::now();
    let (sent, decoded, answered) = fuzz_car_commands(inputs(1_000_000), seed);
    println!(
        "simulated car: {sent} hostile frames ({decoded} decoded as their command), {answered} \
         states answered, 0 panics, {:.0} s",
        started.elapsed().as_secs_f64()
    );
}

/// The simulated car's server, fed hostile frames and random bytes over its stream for a minute
/// of virtual time, still answers GET_STATE: no task died, nothing deafened it.
#[tokio::test(start_paused = true)]
async fn the_simulated_car_server_answers_after_hostile_frames_and_random_bytes() {
    use car_link::firmware::FirmwareVersion;
    use car_link::message::{Dialect, Reply, Request};
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    for version in FirmwareVersion::SIMULATED {
        let config = car_sim::SimConfig {
            firmware: version,
            ..car_sim::SimConfig::default()
        };
        let (stream, _sim) = car_sim::spawn_in_process(&config);
        let (mut reader, mut writer) = tokio::io::split(stream);
        let states = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let counted = states.clone();
        tokio::spawn(async move {
            let mut decoder = FrameDecoder::host();
            let mut buf = [0u8; 4096];
            while let Ok(n) = reader.read(&mut buf).await {
                if n == 0 {
                    break;
                }
                decoder.push(&buf[..n]);
                while let Some(frame) = decoder.next_frame() {
                    if let Ok(frame) = frame
                        && matches!(
                            Reply::decode(&frame.payload, version),
                            Ok((_, Reply::State(_)))
                        )
                    {
                        counted.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    }
                }
            }
        });
        let mut rng = Pcg64Mcg::seed_from_u64(4);
        let encoder = FrameEncoder::to_firmware();
        let dialect = Dialect::host(version);
        let templates = command_templates(version);
        for _ in 0..3000 {
            let bytes: Vec<u8> = if rng.random_bool(0.8) {
                let payload = hostile_payload(&mut rng, &templates, dialect);
                encoder.encode_to_bytes(&payload).unwrap().to_vec()
            } else {
                (0..rng.random_range(1..64)).map(|_| rng.random()).collect()
            };
            writer.write_all(&bytes).await.unwrap();
            tokio::time::sleep(std::time::Duration::from_millis(rng.random_range(1..40))).await;
        }
        // Past the parser's byte timeout, then ask.
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
        let before = states.load(std::sync::atomic::Ordering::Relaxed);
        let get_state = Request::GetState.encode(1, dialect).unwrap();
        for _ in 0..3 {
            writer
                .write_all(&encoder.encode_to_bytes(&get_state).unwrap())
                .await
                .unwrap();
            tokio::time::sleep(std::time::Duration::from_millis(100)).await;
        }
        let after = states.load(std::sync::atomic::Ordering::Relaxed);
        assert_eq!(after - before, 3, "{version}: the server stopped answering");
    }
}
