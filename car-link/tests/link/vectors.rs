//! Every test vector of the protocol (`docs/protocol.md#test-vectors`), encoded and decoded with the crate's own types.

use car_link::crc::checksum;
use car_link::firmware::FirmwareVersion;
use car_link::frame::{FrameDecoder, FrameEncoder};
use car_link::message::{Anchor, CarState, Dialect, RcControl, RcMode, Reply, Request, RoutePoint};
use car_link::version::CommandId;

use crate::support;

use support::sample_state;

fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace()
        .filter(|t| !t.ends_with(':'))
        .map(|t| u8::from_str_radix(t, 16).unwrap_or_else(|_| panic!("bad hex {t}")))
        .collect()
}

fn frame(payload: &[u8]) -> Vec<u8> {
    FrameEncoder::to_firmware()
        .encode_to_bytes(payload)
        .map(|b| b.to_vec())
        .unwrap_or_default()
}

/// Decodes exactly one frame out of `bytes` and returns its payload.
fn unframe(bytes: &[u8]) -> Vec<u8> {
    let mut decoder = FrameDecoder::host();
    decoder.push(bytes);
    let results = decoder.drain_stale();
    assert_eq!(results.len(), 1, "{results:?}");
    results
        .into_iter()
        .next()
        .and_then(Result::ok)
        .map(|f| f.payload.to_vec())
        .unwrap_or_default()
}

fn request_frame(request: &Request, version: FirmwareVersion) -> Vec<u8> {
    for dialect in [Dialect::host(version), Dialect::firmware(version)] {
        assert!(request.encode(1, dialect).is_ok(), "{request:?}");
    }
    frame(
        &request
            .encode(1, Dialect::host(version))
            .unwrap_or_default(),
    )
}

const V10: FirmwareVersion = FirmwareVersion::V10_1;
const V12: FirmwareVersion = FirmwareVersion::V12_3;

#[test]
fn crc_vectors_13_1() {
    assert_eq!(checksum(b"123456789"), 0x31C3);
    assert_eq!(checksum(&hex("01 78")), 0xCCAE);
    assert_eq!(checksum(&hex("01 01 70 69 6E 67")), 0x9C1A);
    assert_eq!(checksum(&hex("01 3B")), 0xB409);
}

#[test]
fn get_state_request_13_2() {
    let wire = hex("02 02 01 78 CC AE 03");
    assert_eq!(request_frame(&Request::GetState, V12), wire);
    assert_eq!(
        Request::decode(&unframe(&wire), V12),
        Ok((1, Request::GetState))
    );
}

fn two_points() -> Vec<RoutePoint> {
    vec![
        RoutePoint::at(10.5, -3.25, 2.5),
        RoutePoint::at(12.0, -1.75, 2.5),
    ]
}

#[test]
fn add_points_12x_13_3() {
    let wire = hex("02 32 01 37
         00 01 9A 28  FF FF 81 0C  00 00 00 00  00 26 25 A0  00 00 00 00  00 00 00 00
         00 01 D4 C0  FF FF BB A4  00 00 00 00  00 26 25 A0  00 00 00 00  00 00 00 00
         3C B3 03");
    let request = Request::AddPoints(two_points());
    assert_eq!(request_frame(&request, V12), wire);
    assert_eq!(Request::decode(&unframe(&wire), V12), Ok((1, request)));
    assert_eq!(checksum(&unframe(&wire)), 0x3CB3);
}

#[test]
fn add_points_10x_13_3() {
    let wire = hex("02 22 01 37
         00 01 9A 28  FF FF 81 0C  00 26 25 A0  00 00 00 00
         00 01 D4 C0  FF FF BB A4  00 26 25 A0  00 00 00 00
         E9 E1 03");
    let request = Request::AddPoints(two_points());
    assert_eq!(request_frame(&request, V10), wire);
    assert_eq!(request_frame(&request, FirmwareVersion::V11_0), wire);
    assert_eq!(Request::decode(&unframe(&wire), V10), Ok((1, request)));
}

#[test]
fn add_points_ack_13_3() {
    let wire = hex("02 02 01 37 75 85 03");
    for version in [V10, V12] {
        let reply = Reply::Ack(CommandId::ApAddPoints);
        assert_eq!(
            frame(
                &reply
                    .encode(1, Dialect::firmware(version))
                    .unwrap_or_default()
            ),
            wire
        );
        assert_eq!(Reply::decode(&unframe(&wire), version), Ok((1, reply)));
    }
}

const FAULT_COMMAND: &str = "fi_add_fault uwb_range_50 OFFSET 2.0 15 8";
const FAULT_REPLY: &str =
    "Fault OFFSET with parameter 2.00 successfully added to probe uwb_range_50.\n";

#[test]
fn terminal_command_13_4() {
    let wire = hex(
        "02 2B 01 01 66 69 5F 61 64 64 5F 66 61 75 6C 74 20 75 77 62 5F 72 61 6E 67 65 5F 35
         30 20 4F 46 46 53 45 54 20 32 2E 30 20 31 35 20 38 CE 59 03",
    );
    assert_eq!(FAULT_COMMAND.len(), 41);
    let request = Request::TerminalCmd(FAULT_COMMAND.into());
    assert_eq!(request_frame(&request, V12), wire);
    assert_eq!(Request::decode(&unframe(&wire), V12), Ok((1, request)));
}

#[test]
fn printf_reply_13_4() {
    let wire = hex(
        "02 4D 01 00 46 61 75 6C 74 20 4F 46 46 53 45 54 20 77 69 74 68 20 70 61 72 61 6D 65
         74 65 72 20 32 2E 30 30 20 73 75 63 63 65 73 73 66 75 6C 6C 79 20 61 64 64 65 64 20
         74 6F 20 70 72 6F 62 65 20 75 77 62 5F 72 61 6E 67 65 5F 35 30 2E 0A 79 E2 03",
    );
    let reply = Reply::Printf(FAULT_REPLY.into());
    assert_eq!(
        frame(&reply.encode(1, Dialect::firmware(V12)).unwrap_or_default()),
        wire
    );
    assert_eq!(Reply::decode(&unframe(&wire), V12), Ok((1, reply)));
}

const STATE_FRAME: &str = "
000: 02 6B 01 78 0C 03 00 07 A1 20 FF FC 2F 70 02 AE
016: A5 40 00 00 27 10 FF FF B1 E0 00 0F 42 40 00 00
032: 00 00 00 00 00 00 00 01 86 A0 00 98 96 80 FE CE
048: D3 00 01 C9 C3 80 00 01 E2 40 FF FE DB 08 00 16
064: E3 60 02 53 17 C0 01 7D 78 40 00 00 01 E2 08 FF
080: FE DB 6C 00 01 FB D0 FF FE F6 60 00 0C 35 00 02
096: B3 2C 95 00 07 00 01 DC 90 FF FE D7 20 BB 97 03";

#[test]
fn get_state_reply_13_5() {
    let wire = hex(STATE_FRAME);
    assert_eq!(wire.len(), 112);
    let payload = unframe(&wire);
    assert_eq!(payload.len(), 107);
    assert_eq!(checksum(&payload), 0xBB97);
    assert_eq!(&payload[52..56], &[0x00, 0x01, 0xE2, 0x40]);
    assert_eq!(&payload[93..97], &[0x02, 0xB3, 0x2C, 0x95]);
    assert_eq!(&payload[97..99], &[0x00, 0x07]);
    assert_eq!(&payload[99..103], &[0x00, 0x01, 0xDC, 0x90]);

    let state = sample_state(V12);
    assert_eq!(Reply::decode(&payload, V12), Ok((1, Reply::State(state))));
    // The truncating firmware encoder and the rounding control-station encoder agree on these values.
    for dialect in [Dialect::firmware(V12), Dialect::host(V12)] {
        assert_eq!(
            frame(&Reply::State(state).encode(1, dialect).unwrap_or_default()),
            wire,
            "{dialect:?}"
        );
    }
}

#[test]
fn get_state_reply_from_10_1_13_5() {
    let state = sample_state(FirmwareVersion::V10_1);
    let payload = Reply::State(state)
        .encode(1, Dialect::firmware(V10))
        .unwrap_or_default();
    assert_eq!(&payload[2..4], &[0x0A, 0x01]);
    assert_eq!(checksum(&payload), 0xAE8F);
    let (_, decoded) = Reply::decode(&payload, V12).unwrap_or((0, Reply::Printf(String::new())));
    assert_eq!(decoded, Reply::State(state));
}

#[test]
fn inactive_autopilot_radius_13_5() {
    let state = CarState {
        ap_rad: -1.0,
        ..sample_state(V12)
    };
    let payload = Reply::State(state)
        .encode(1, Dialect::firmware(V12))
        .unwrap_or_default();
    assert_eq!(&payload[89..93], &[0xFF, 0xF0, 0xBD, 0xC0]);
}

#[test]
fn set_active_12_3_13_6() {
    let wire = hex("02 04 01 3B 01 00 70 D1 03");
    let request = Request::SetActive {
        active: true,
        reset: false,
    };
    assert_eq!(request_frame(&request, V12), wire);
    assert_eq!(Request::decode(&unframe(&wire), V12), Ok((1, request)));
}

#[test]
fn set_active_10x_13_6() {
    let wire = hex("02 03 01 3B 01 FE 7E 03");
    let request = Request::SetActive {
        active: true,
        reset: false,
    };
    assert_eq!(request_frame(&request, V10), wire);
    assert_eq!(request_frame(&request, FirmwareVersion::new(12, 2)), wire);
    assert_eq!(Request::decode(&unframe(&wire), V10), Ok((1, request)));
}

#[test]
fn rc_control_brake_13_6() {
    let wire = hex("02 0B 01 79 03 00 07 A1 20 00 00 00 00 BA FA 03");
    let request = Request::RcControl(RcControl {
        mode: RcMode::CurrentBrake,
        throttle: 50.0,
        steering: 0.0,
    });
    assert_eq!(request_frame(&request, V12), wire);
    assert_eq!(Request::decode(&unframe(&wire), V12), Ok((1, request)));
}

#[test]
fn add_uwb_anchor_both_numberings_13_6() {
    let anchor = Request::AddUwbAnchor(Anchor {
        id: 50,
        px: 10.0,
        py: -5.5,
        height: 2.0,
    });
    let new = hex("02 10 01 50 00 32 41 20 00 00 C0 B0 00 00 40 00 00 00 9E 4B 03");
    let old = hex("02 10 01 54 00 32 41 20 00 00 C0 B0 00 00 40 00 00 00 05 F9 03");
    assert_eq!(request_frame(&anchor, FirmwareVersion::V12_1), new);
    assert_eq!(request_frame(&anchor, FirmwareVersion::V12_0), old);
    assert_eq!(
        Request::decode(&unframe(&new), FirmwareVersion::V12_1),
        Ok((1, anchor.clone()))
    );
    assert_eq!(Request::decode(&unframe(&old), V10), Ok((1, anchor)));
}

#[test]
fn get_route_part_13_6() {
    let wire = hex("02 07 01 3A 00 00 00 00 0A B0 A5 03");
    let request = Request::GetRoutePart { first: 0, num: 10 };
    assert_eq!(request_frame(&request, V12), wire);
    assert_eq!(Request::decode(&unframe(&wire), V12), Ok((1, request)));
}

#[test]
fn set_active_reset_is_refused_before_12_3() {
    let request = Request::SetActive {
        active: true,
        reset: true,
    };
    assert!(
        request
            .encode(1, Dialect::host(FirmwareVersion::new(12, 2)))
            .is_err()
    );
    assert!(request.encode(1, Dialect::host(V12)).is_ok());
}

#[test]
fn attributes_are_refused_before_12_0() {
    let point = RoutePoint {
        attributes: 2,
        ..RoutePoint::at(1.0, 2.0, 1.0)
    };
    assert!(
        Request::AddPoints(vec![point])
            .encode(1, Dialect::host(V10))
            .is_err()
    );
    assert!(
        Request::AddPoints(vec![point])
            .encode(1, Dialect::host(V12))
            .is_ok()
    );
}

#[test]
fn car_id_211_is_refused_and_rtcm_payloads_are_not_commands() {
    assert!(Request::GetState.encode(211, Dialect::host(V12)).is_err());
    assert!(Request::decode(&[0xD3, 0x00, 0x13], V12).is_err());
}

#[test]
fn an_echoed_get_state_request_is_not_a_state() {
    assert!(Reply::decode(&[0x01, 0x78], V12).is_err());
}
