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

#[cfg(test)]
mod tests {
    use super::checksum;

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
