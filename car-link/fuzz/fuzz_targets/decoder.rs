//! Fuzzes the streaming frame decoder and the payload decoders: no input may panic them, and every frame they
//! accept must re-encode to a frame that decodes to the same payload.

#![no_main]

use car_link::frame::{FrameDecoder, FrameEncoder};
use car_link::message::{Dialect, Reply, Request};
use car_link::firmware::FirmwareVersion;
use libfuzzer_sys::fuzz_target;

const VERSIONS: [FirmwareVersion; 4] = [
    FirmwareVersion::V10_1,
    FirmwareVersion::V11_0,
    FirmwareVersion::V12_0,
    FirmwareVersion::V12_3,
];

fuzz_target!(|data: &[u8]| {
    // The first byte chooses how the stream is cut into reads.
    let Some((&cut, stream)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(cut).max(1);
    for mut decoder in [FrameDecoder::host(), FrameDecoder::firmware()] {
        let mut frames = Vec::new();
        for piece in stream.chunks(chunk) {
            decoder.push(piece);
            frames.extend(std::iter::from_fn(|| decoder.next_frame()));
        }
        frames.extend(decoder.drain_stale());
        assert!(!decoder.has_pending());
        for frame in frames.into_iter().flatten() {
            let again = FrameEncoder::pc_side(1 << 20)
                .encode_to_bytes(&frame.payload)
                .expect("a decoded payload frames");
            let mut check = FrameDecoder::host();
            check.push(&again);
            let back = check
                .next_frame()
                .and_then(Result::ok)
                .expect("re-encoded frame decodes");
            assert_eq!(back.payload, frame.payload);
            for version in VERSIONS {
                if let Ok((car, request)) = Request::decode(&frame.payload, version) {
                    let _ = request.encode(car, Dialect::host(version));
                }
                if let Ok((car, reply)) = Reply::decode(&frame.payload, version) {
                    let _ = reply.encode(car, Dialect::firmware(version));
                }
            }
        }
    }
});
