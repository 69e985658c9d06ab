//! Resynchronisation without timeouts: after a corrupted frame, the next intact frame comes out of the decoder as
//! soon as its last byte has been pushed, with no call to `expire` or `drain_stale`.

use car_link::frame::{FrameDecoder, FrameEncoder};
use proptest::prelude::*;
use proptest::sample::Index;

/// How a frame is damaged on the wire.
#[derive(Debug, Clone)]
enum Damage {
    /// One byte (start byte, length, payload, CRC or end byte) is XORed with a non-zero mask.
    Flip { at: Index, mask: u8 },
    /// The frame is cut short (the link dropped its tail).
    Truncate { keep: Index },
    /// A burst of noise (never empty) replaces the tail of the frame from `at` on.
    Noise { at: Index, noise: Vec<u8> },
}

impl Damage {
    fn apply(&self, frame: &mut Vec<u8>) {
        match self {
            Damage::Flip { at, mask } => {
                let at = at.index(frame.len());
                frame[at] ^= mask;
            }
            Damage::Truncate { keep } => frame.truncate(keep.index(frame.len())),
            Damage::Noise { at, noise } => {
                let at = at.index(frame.len());
                let first_differs = frame[at] != noise[0];
                frame.truncate(at);
                frame.extend_from_slice(noise);
                if !first_differs {
                    // Noise that repeats the byte it replaces does not damage it.
                    frame[at] ^= 0xFF;
                }
            }
        }
    }
}

fn damage() -> impl Strategy<Value = Damage> {
    // Noise rich in start and end bytes is the hard case.
    let noise_byte = prop_oneof![
        proptest::sample::select(vec![0x02u8, 0x03, 0x04]),
        any::<u8>()
    ];
    prop_oneof![
        (any::<Index>(), 1u8..=255).prop_map(|(at, mask)| Damage::Flip { at, mask }),
        any::<Index>().prop_map(|keep| Damage::Truncate { keep }),
        (any::<Index>(), proptest::collection::vec(noise_byte, 1..12))
            .prop_map(|(at, noise)| Damage::Noise { at, noise }),
    ]
}

/// A frame on the wire: its payload and, if it was damaged, how.
fn entry() -> impl Strategy<Value = (Vec<u8>, Option<Damage>)> {
    let payload = prop_oneof![
        4 => proptest::collection::vec(any::<u8>(), 1..40),
        1 => proptest::collection::vec(any::<u8>(), 250..300),
    ];
    (payload, proptest::option::weighted(0.4, damage()))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn every_intact_frame_comes_out_as_soon_as_it_has_arrived(
        entries in proptest::collection::vec(entry(), 1..10),
        cut in any::<Index>(),
    ) {
        let encoder = FrameEncoder::to_firmware();
        let mut decoder = FrameDecoder::host();
        let mut expected = Vec::new();
        let mut delivered = Vec::new();
        for (payload, damage) in &entries {
            let mut bytes = encoder
                .encode_to_bytes(payload)
                .map_err(|e| TestCaseError::fail(e.to_string()))?
                .to_vec();
            match damage {
                Some(damage) => damage.apply(&mut bytes),
                None => expected.push(payload.clone()),
            }
            // Each frame arrives in two reads.
            let (a, b) = bytes.split_at(cut.index(bytes.len() + 1).min(bytes.len()));
            for read in [a, b] {
                decoder.push(read);
                delivered.extend(
                    std::iter::from_fn(|| decoder.next_frame())
                        .filter_map(Result::ok)
                        .map(|f| f.payload.to_vec()),
                );
            }
            // No decoder can tell a real frame from bytes that happen to form one: a damaged frame can still
            // be valid by chance (a flipped length byte, noise that completes a frame: 2^-24 and less), and such
            // a frame may overlap the next one. Such cases say nothing about resynchronisation.
            prop_assume!(
                delivered.iter().all(|f| expected.contains(f)),
                "a chance frame in the damage"
            );
            // Delivered now, without any timeout: every intact frame so far, in order.
            prop_assert_eq!(&delivered, &expected);
        }
    }

    #[test]
    fn intact_frames_come_out_in_order_whatever_the_reads(
        entries in proptest::collection::vec(entry(), 1..10),
        read_size in 1usize..64,
    ) {
        let encoder = FrameEncoder::to_firmware();
        let mut stream = Vec::new();
        let mut expected = Vec::new();
        for (payload, damage) in &entries {
            let mut bytes = encoder
                .encode_to_bytes(payload)
                .map_err(|e| TestCaseError::fail(e.to_string()))?
                .to_vec();
            match damage {
                Some(damage) => damage.apply(&mut bytes),
                None => expected.push(payload.clone()),
            }
            stream.extend_from_slice(&bytes);
        }
        let mut decoder = FrameDecoder::firmware();
        let mut delivered = Vec::new();
        for read in stream.chunks(read_size) {
            decoder.push(read);
            delivered.extend(
                std::iter::from_fn(|| decoder.next_frame())
                    .filter_map(Result::ok)
                    .map(|f| f.payload.to_vec()),
            );
        }
        prop_assume!(
            delivered.iter().all(|f| expected.contains(f)),
            "a chance frame in the damage"
        );
        prop_assert_eq!(delivered, expected);
        // What is left is only damage: a timeout reports it and finds no further frame.
        let stale = decoder.drain_stale();
        prop_assert!(stale.iter().all(Result::is_err), "{:?}", stale);
        prop_assert!(!decoder.has_pending());
    }
}
