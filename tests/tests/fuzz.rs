//! Fuzzing without a nightly toolchain: the frame decoder, the scenario parser and the case parser
//! fed mutated and random input, deterministically from a seed. Each must return an error (or a
//! value) and never panic; a delivered frame must be one that was sent or a chance frame with a
//! valid checksum and end byte.
//!
//! The default run is small (it is part of `cargo test`); the long runs are ignored tests:
//!
//! ```sh
//! DRIVECHECK_FUZZ_INPUTS=10000000 cargo test --release -p drivecheck-tests --test fuzz -- --ignored --nocapture
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
    let doc = include_str!("../../docs/case-format.md");
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
    let (inputs, frames) = no_panic("the frame decoder", 1, || fuzz_frames(20_000, 1));
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
