//! The frame checksum: CRC-16/XMODEM over the payload bytes only (`docs/protocol.md#crc`).

use crc::{CRC_16_XMODEM, Crc};

/// CRC-16/XMODEM: polynomial `0x1021`, init 0, no reflection, no final xor; check value `0x31C3`.
const XMODEM: Crc<u16> = Crc::<u16>::new(&CRC_16_XMODEM);

/// The checksum a frame carries for `payload` (sent high byte first).
///
/// ```
/// assert_eq!(car_link::crc::checksum(b"123456789"), 0x31C3);
/// ```
pub fn checksum(payload: &[u8]) -> u16 {
    XMODEM.checksum(payload)
}

/// The running checksum after one more byte (CRC-16/XMODEM, not reflected).
pub(crate) fn update(crc: u16, byte: u8) -> u16 {
    (crc << 8) ^ BYTE_TABLE[usize::from((crc >> 8) as u8 ^ byte)]
}

/// The checksum of a stream's bytes `[from, to)` from the running checksums `at_from` and `at_to`
/// of the stream up to those offsets (both started anywhere before `from`, with 0): the decoder's
/// way to check a candidate in a constant number of steps instead of one per payload byte.
///
/// With init 0 and no final xor the checksum is linear: `crc(A ‖ B) = crc(A)·x^(8|B|) ⊕ crc(B)`,
/// so `crc(B) = at_to ⊕ shift(at_from, |B|)`, and the shift takes one table step per set bit of
/// `|B|`.
pub(crate) fn range(at_from: u16, at_to: u16, len: usize) -> u16 {
    at_to ^ shift(at_from, len)
}

/// `crc · x^(8·bytes) mod G`: the running checksum after `bytes` more zero bytes.
fn shift(mut crc: u16, bytes: usize) -> u16 {
    let tables = shift_tables();
    let mut rest = bytes;
    for level in tables.iter() {
        if rest == 0 {
            return crc;
        }
        if rest & 1 == 1 {
            crc = level.apply(crc);
        }
        rest >>= 1;
    }
    // Beyond the tables (never for a frame): one zero byte at a time.
    let remaining = (bytes >> SHIFT_LEVELS) << SHIFT_LEVELS;
    (0..remaining).fold(crc, |c, _| update(c, 0))
}

/// Shift tables cover `bytes` below `2^SHIFT_LEVELS` (4 MiB, above every payload limit).
const SHIFT_LEVELS: usize = 22;

/// The linear map "shift by 2^level zero bytes", as the images of a checksum's high and low
/// bytes.
struct ShiftTable {
    hi: [u16; 256],
    lo: [u16; 256],
}

impl ShiftTable {
    fn apply(&self, crc: u16) -> u16 {
        self.hi[usize::from((crc >> 8) as u8)] ^ self.lo[usize::from(crc as u8)]
    }
}

fn shift_tables() -> &'static [ShiftTable; SHIFT_LEVELS] {
    static TABLES: std::sync::OnceLock<Box<[ShiftTable; SHIFT_LEVELS]>> =
        std::sync::OnceLock::new();
    TABLES.get_or_init(|| {
        // Level 0: one zero byte. Level k + 1: level k applied twice.
        let mut levels: Vec<ShiftTable> = Vec::with_capacity(SHIFT_LEVELS);
        let one = |crc: u16| update(crc, 0);
        let mut first = ShiftTable {
            hi: [0; 256],
            lo: [0; 256],
        };
        for b in 0..=255u8 {
            first.hi[usize::from(b)] = one(u16::from(b) << 8);
            first.lo[usize::from(b)] = one(u16::from(b));
        }
        levels.push(first);
        while levels.len() < SHIFT_LEVELS {
            let last = levels.last().expect("level 0 is there");
            let mut next = ShiftTable {
                hi: [0; 256],
                lo: [0; 256],
            };
            for b in 0..=255u8 {
                next.hi[usize::from(b)] = last.apply(last.apply(u16::from(b) << 8));
                next.lo[usize::from(b)] = last.apply(last.apply(u16::from(b)));
            }
            levels.push(next);
        }
        match levels.try_into() {
            Ok(levels) => Box::new(levels),
            Err(_) => unreachable!("SHIFT_LEVELS levels were built"),
        }
    })
}

/// The byte table of CRC-16/XMODEM (polynomial `0x1021`, not reflected).
const BYTE_TABLE: [u16; 256] = byte_table();

const fn byte_table() -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::{checksum, range, update};

    proptest! {
        /// The checksum of any stretch of a stream, from the running checksums at its ends,
        /// equals the checksum computed over its bytes.
        #[test]
        fn a_range_checksum_equals_the_direct_one(
            bytes in proptest::collection::vec(any::<u8>(), 0..3000),
            a in 0usize..3000,
            b in 0usize..3000,
        ) {
            let (from, to) = (a.min(b).min(bytes.len()), a.max(b).min(bytes.len()));
            let mut running = vec![0u16];
            for &byte in &bytes {
                running.push(update(*running.last().unwrap(), byte));
            }
            prop_assert_eq!(running[bytes.len()], checksum(&bytes));
            prop_assert_eq!(
                range(running[from], running[to], to - from),
                checksum(&bytes[from..to])
            );
        }
    }

    // The CRC test vectors (`docs/protocol.md#test-vectors`).
    #[test]
    fn check_value() {
        assert_eq!(checksum(b"123456789"), 0x31C3);
    }

    #[test]
    fn get_state_to_car_1() {
        assert_eq!(checksum(&[0x01, 0x78]), 0xCCAE);
    }

    #[test]
    fn terminal_ping_to_car_1() {
        assert_eq!(checksum(&[0x01, 0x01, 0x70, 0x69, 0x6E, 0x67]), 0x9C1A);
    }

    #[test]
    fn set_active_ack_from_car_1() {
        assert_eq!(checksum(&[0x01, 0x3B]), 0xB409);
    }
}
