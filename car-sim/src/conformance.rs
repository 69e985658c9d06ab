//! Conformance of the protocol shell: the protocol's test-vector frames
//! (`docs/protocol.md#test-vectors`) over a raw TCP socket byte by byte, the `car-link` client
//! against the in-process simulator in virtual time, UDP, impairment and the one-client rule.

use std::net::SocketAddr;
use std::time::Duration;

use car_link::crc::checksum;
use car_link::message::{Anchor, EnuRef, Pose, RoutePoint as LinkPoint, SyncPoint};
use car_link::{Car as LinkCar, FaultKind, FirmwareVersion, LinkConfig, Probe};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpStream, UdpSocket};
use tokio::time::timeout;

use crate::{LinkImpairment, SimConfig, serve_tcp, serve_udp, spawn_in_process};

fn loopback() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}

fn frame(payload: &[u8]) -> Vec<u8> {
    let crc = checksum(payload);
    let mut f = vec![0x02, payload.len() as u8];
    f.extend_from_slice(payload);
    f.extend_from_slice(&crc.to_be_bytes());
    f.push(0x03);
    f
}

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).expect("hex"))
        .collect()
}

/// Reads whatever arrives within `wait`.
async fn read_for(stream: &mut TcpStream, wait: Duration) -> Vec<u8> {
    let mut out = Vec::new();
    let mut buf = [0u8; 2048];
    while let Ok(Ok(n)) = timeout(wait, stream.read(&mut buf)).await {
        if n == 0 {
            break;
        }
        out.extend_from_slice(&buf[..n]);
    }
    out
}

async fn exchange(stream: &mut TcpStream, bytes: &[u8]) -> Vec<u8> {
    stream.write_all(bytes).await.expect("write");
    read_for(stream, Duration::from_millis(100)).await
}

const ADD_POINTS_12X: &str = "02 32 01 37
   00 01 9A 28  FF FF 81 0C  00 00 00 00  00 26 25 A0  00 00 00 00  00 00 00 00
   00 01 D4 C0  FF FF BB A4  00 00 00 00  00 26 25 A0  00 00 00 00  00 00 00 00
3C B3 03";
const ADD_POINTS_10X: &str = "02 22 01 37
   00 01 9A 28  FF FF 81 0C  00 26 25 A0  00 00 00 00
   00 01 D4 C0  FF FF BB A4  00 26 25 A0  00 00 00 00
E9 E1 03";
const FI_ADD: &str =
    "02 2B 01 01 66 69 5F 61 64 64 5F 66 61 75 6C 74 20 75 77 62 5F 72 61 6E 67 65 5F 35
30 20 4F 46 46 53 45 54 20 32 2E 30 20 31 35 20 38 CE 59 03";
const FI_REPLY: &str =
    "02 4D 01 00 46 61 75 6C 74 20 4F 46 46 53 45 54 20 77 69 74 68 20 70 61 72 61 6D 65
74 65 72 20 32 2E 30 30 20 73 75 63 63 65 73 73 66 75 6C 6C 79 20 61 64 64 65 64 20
74 6F 20 70 72 6F 62 65 20 75 77 62 5F 72 61 6E 67 65 5F 35 30 2E 0A 79 E2 03";

#[tokio::test]
async fn the_section_13_frames_get_the_documented_replies_byte_by_byte() {
    for firmware in [FirmwareVersion::V10_1, FirmwareVersion::V12_3] {
        let sim = serve_tcp(
            loopback(),
            &SimConfig {
                firmware,
                ..SimConfig::default()
            },
        )
        .await
        .expect("bind");
        let mut s = TcpStream::connect(sim.local_addr().expect("bound"))
            .await
            .expect("connect");
        // GET_STATE → a 112-byte short frame from car 1 with the firmware's version.
        let state = exchange(&mut s, &hex("02 02 01 78 CC AE 03")).await;
        let FirmwareVersion { major, minor } = firmware;
        // The hand-written vectors below are those of the two simulated versions.
        let v12_3 = firmware == FirmwareVersion::V12_3;
        assert_eq!(state.len(), 112, "{firmware}");
        assert_eq!(&state[..6], &[0x02, 0x6B, 0x01, 0x78, major, minor]);
        let crc = checksum(&state[2..109]).to_be_bytes();
        assert_eq!(&state[109..], &[crc[0], crc[1], 0x03]);
        // AP_ADD_POINTS in the era's layout → the ack.
        let add = if v12_3 {
            ADD_POINTS_12X
        } else {
            ADD_POINTS_10X
        };
        assert_eq!(
            exchange(&mut s, &hex(add)).await,
            hex("02 02 01 37 75 85 03")
        );
        // TERMINAL_CMD fi_add_fault → the PRINTF, byte for byte.
        assert_eq!(exchange(&mut s, &hex(FI_ADD)).await, hex(FI_REPLY));
        // AP_SET_ACTIVE (two bytes for 12.3, one for 10.x) → the ack `01 3B`, CRC 0xB409.
        let active = if v12_3 {
            "02 04 01 3B 01 00 70 D1 03"
        } else {
            "02 03 01 3B 01 FE 7E 03"
        };
        assert_eq!(
            exchange(&mut s, &hex(active)).await,
            hex("02 02 01 3B B4 09 03")
        );
        // RC_CONTROL brake 50 A: no reply.
        let rc = "02 0B 01 79 03 00 07 A1 20 00 00 00 00 BA FA 03";
        assert!(exchange(&mut s, &hex(rc)).await.is_empty());
        // ADD_UWB_ANCHOR with the era's id → the ack with that id.
        let (anchor, ack) = if v12_3 {
            (
                "02 10 01 50 00 32 41 20 00 00 C0 B0 00 00 40 00 00 00 9E 4B 03",
                [0x01, 0x50],
            )
        } else {
            (
                "02 10 01 54 00 32 41 20 00 00 C0 B0 00 00 40 00 00 00 05 F9 03",
                [0x01, 0x54],
            )
        };
        assert_eq!(exchange(&mut s, &hex(anchor)).await, frame(&ack));
        // AP_GET_ROUTE_PART first 0, num 10 → route_len 2 and 10 points of the era's size.
        let part = exchange(&mut s, &hex("02 07 01 3A 00 00 00 00 0A B0 A5 03")).await;
        let point = firmware.route_point_size();
        assert_eq!(part.len(), 5 + 2 + 4 + 10 * point);
        assert_eq!(&part[2..8], &[0x01, 0x3A, 0, 0, 0, 2]);
        // Silence: a bad CRC, another car's id, EMERGENCY_STOP, HEARTBEAT (12.x), num > 20.
        let estop = if v12_3 { 76 } else { 80 };
        let mut silent = frame(&[0x07, 0x78]);
        silent.extend(frame(&[0x01, estop]));
        silent.extend(frame(&[0x01, 89]));
        silent.extend(frame(&[0x01, 0x3A, 0, 0, 0, 0, 21]));
        assert!(exchange(&mut s, &silent).await.is_empty(), "{firmware}");
        // A bad CRC gets no reply, and the next request is answered at once (no byte timeout).
        assert!(
            exchange(&mut s, &hex("02 02 01 78 CC AF 03"))
                .await
                .is_empty()
        );
        // Broadcast 255 is answered with the car's own id; 254 with 254, which the bridge does
        // not forward, except PRINTF (always stamped with the car's own id).
        assert_eq!(
            exchange(&mut s, &frame(&[0xFF, 0x39])).await,
            frame(&[0x01, 0x39])
        );
        assert!(exchange(&mut s, &frame(&[0xFE, 0x39])).await.is_empty());
        assert_eq!(
            exchange(&mut s, &frame(b"\xFE\x01ping")).await,
            frame(b"\x01\x00pong\n")
        );
        // Terminal texts.
        assert_eq!(
            exchange(&mut s, &frame(b"\x01\x01ping")).await,
            frame(b"\x01\x00pong\n")
        );
        assert_eq!(
            exchange(&mut s, &frame(b"\x01\x01")).await,
            frame(b"\x01\x00No command received\n")
        );
    }
}

#[tokio::test]
async fn a_second_tcp_client_is_accepted_and_closed_at_once() {
    let sim = serve_tcp(loopback(), &SimConfig::default())
        .await
        .expect("bind");
    let addr = sim.local_addr().expect("bound");
    let mut first = TcpStream::connect(addr).await.expect("connect");
    assert_eq!(
        exchange(&mut first, &frame(b"\x01\x01ping")).await,
        frame(b"\x01\x00pong\n")
    );
    let mut second = TcpStream::connect(addr).await.expect("connect");
    let mut buf = [0u8; 16];
    let n = timeout(Duration::from_secs(1), second.read(&mut buf)).await;
    assert!(matches!(n, Ok(Ok(0)) | Ok(Err(_))), "closed at once: {n:?}");
    assert_eq!(
        exchange(&mut first, &frame(b"\x01\x01ping")).await,
        frame(b"\x01\x00pong\n")
    );
    drop(first);
    tokio::time::sleep(Duration::from_millis(50)).await;
    let mut third = TcpStream::connect(addr).await.expect("connect");
    assert_eq!(
        exchange(&mut third, &frame(b"\x01\x01ping")).await,
        frame(b"\x01\x00pong\n")
    );
}

#[tokio::test]
async fn a_silent_tcp_client_is_disconnected_after_the_idle_timeout_and_frees_the_slot() {
    let config = SimConfig {
        idle_timeout: Some(Duration::from_millis(300)),
        ..SimConfig::default()
    };
    let sim = serve_tcp(loopback(), &config).await.expect("bind");
    let addr = sim.local_addr().expect("bound");
    // A client that connects and never speaks.
    let mut silent = TcpStream::connect(addr).await.expect("connect");
    let mut buf = [0u8; 16];
    let n = timeout(Duration::from_secs(3), silent.read(&mut buf)).await;
    assert!(matches!(n, Ok(Ok(0)) | Ok(Err(_))), "disconnected: {n:?}");
    // A client that trickles a byte every 100 ms, never a whole frame, is disconnected too.
    let mut trickling = TcpStream::connect(addr).await.expect("the slot is free");
    let started = tokio::time::Instant::now();
    let mut cut = false;
    for byte in std::iter::repeat_n(0x41u8, 40) {
        if trickling.write_all(&[byte]).await.is_err() {
            cut = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
        if let Ok(Ok(0)) = timeout(Duration::from_millis(1), trickling.read(&mut buf)).await {
            cut = true;
            break;
        }
    }
    assert!(cut, "still connected after {:?}", started.elapsed());
    assert!(
        started.elapsed() < Duration::from_secs(2),
        "{:?}",
        started.elapsed()
    );
    // A client that speaks now and then keeps its connection past the timeout.
    let mut next = TcpStream::connect(addr).await.expect("the slot is free");
    for _ in 0..4 {
        assert_eq!(
            exchange(&mut next, &frame(b"\x01\x01ping")).await,
            frame(b"\x01\x00pong\n")
        );
        tokio::time::sleep(Duration::from_millis(150)).await;
    }
}

#[tokio::test]
async fn udp_carries_one_bare_payload_per_datagram_and_replies_to_port_plus_one() {
    // Find a port p with p + 1 free for the client's listener.
    let (sim, client) = loop {
        let sim = serve_udp(loopback(), &SimConfig::default())
            .await
            .expect("bind");
        let port = sim.local_addr().expect("bound").port();
        if let Ok(c) = UdpSocket::bind(SocketAddr::from(([127, 0, 0, 1], port + 1))).await {
            break (sim, c);
        }
    };
    let sender = UdpSocket::bind(loopback()).await.expect("bind");
    sender
        .send_to(&[0x01, 0x78], sim.local_addr().expect("bound"))
        .await
        .expect("send");
    let mut buf = [0u8; 256];
    let (n, _) = timeout(Duration::from_secs(2), client.recv_from(&mut buf))
        .await
        .expect("a reply")
        .expect("recv");
    assert_eq!(n, 107);
    assert_eq!(&buf[..4], &[0x01, 0x78, 10, 1]);
}

#[tokio::test]
async fn car_links_udp_client_talks_to_the_simulated_bridge() {
    // The client binds port + 1 on loopback and accepts replies from the simulator's port only:
    // the simulator (like the bridge) replies from the port it serves.
    for _ in 0..20 {
        let sim = serve_udp(loopback(), &SimConfig::default())
            .await
            .expect("bind");
        let port = sim.local_addr().expect("bound").port();
        let address = format!("udp://127.0.0.1:{port}").parse().expect("address");
        let car = match LinkCar::connect(&address, link_config()).await {
            Ok(car) => car,
            // Port + 1 taken by another program: try another port.
            Err(car_link::CarError::Connect { .. }) => continue,
            Err(error) => panic!("{error}"),
        };
        assert!(car.state().await.is_ok());
        return;
    }
    panic!("no port p with p + 1 free");
}

fn link_config() -> LinkConfig {
    LinkConfig {
        car_id: 1,
        ..LinkConfig::default()
    }
}

#[tokio::test(start_paused = true)]
async fn every_command_through_the_car_link_client_in_virtual_time() {
    for firmware in [FirmwareVersion::V10_1, FirmwareVersion::V12_3] {
        let (stream, sim) = spawn_in_process(&SimConfig {
            firmware,
            ..SimConfig::default()
        });
        let car = LinkCar::over_stream(stream, link_config())
            .await
            .expect("handshake");
        assert_eq!(car.version(), firmware);
        let deviations = car.prepare_for_test_drive().await.expect("config");
        assert!(!deviations.is_empty(), "repeat is on at the factory");
        assert!(
            car.main_config()
                .await
                .expect("config")
                .test_drive_deviations()
                .expect("ok")
                .is_empty()
        );
        car.set_enu_ref(EnuRef {
            lat: 57.7,
            lon: 11.9,
            height: 10.0,
        })
        .await
        .expect("enu");
        let enu = car.enu_ref().await.expect("enu");
        assert!((enu.lat - 57.7).abs() < 1e-6 && (enu.height - 10.0).abs() < 1e-3);
        car.upload_anchors(&[Anchor {
            id: 50,
            px: 10.0,
            py: 0.0,
            height: 1.0,
        }])
        .await
        .expect("anchors");
        assert_eq!(car.terminal("ping").await.expect("ping"), "pong\n");
        car.set_fi_enabled(true).await.expect("fi");
        car.add_fault(&Probe::Px, FaultKind::Offset, 0.5, 0, 1)
            .await
            .expect("fault");
        car.add_fault(&Probe::UwbYaw, FaultKind::Amplification, -1.5, 20, 3)
            .await
            .expect("fault");
        let listed = car.list_faults().await.expect("list");
        let probes: Vec<&str> = listed.iter().map(|f| f.probe.as_str()).collect();
        assert_eq!(probes, ["px", "uwb_yaw"]);
        assert_eq!(
            (listed[1].kind.as_str(), listed[1].param, listed[1].duration),
            ("AMPLIFICATION", -1.5, 3)
        );
        car.clear_faults().await.expect("clear");
        assert!(car.list_faults().await.expect("list").is_empty());
        car.set_pos(Pose {
            x: 0.0,
            y: 0.0,
            yaw: 0.0,
        })
        .await
        .expect("set pos");
        car.reset_uwb_pos().await.expect("reset uwb");
        let route: Vec<LinkPoint> = (0..10)
            .map(|i| LinkPoint::at(f64::from(i), 0.0, 1.5))
            .collect();
        car.clear_route().await.expect("clear");
        car.add_points(&route[..5]).await.expect("add");
        car.add_points(&route[5..]).await.expect("add");
        car.remove_last_point().await.expect("remove");
        let part = car.route_part(0, 10).await.expect("part");
        assert_eq!(part.route_len, 9);
        assert_eq!(part.points[3].px, 3.0);
        car.sync_point(SyncPoint {
            point: 5,
            time_ms: 4000,
            min_diff_ms: 0,
        })
        .await
        .expect("sync");
        car.replace_route(&route[..5]).await.expect("replace");
        car.add_points(&route[5..]).await.expect("add");
        car.set_autopilot(true, false).await.expect("active");
        tokio::time::sleep(Duration::from_secs(3)).await;
        let s = car.state().await.expect("state").state;
        assert!(s.speed > 0.5 && s.px > 0.5, "{firmware}: driving {s:?}");
        assert!(sim.truth().x > 0.5);
        car.brake(50.0).await.expect("brake");
        tokio::time::sleep(Duration::from_secs(2)).await;
        assert!(car.state().await.expect("state").state.speed.abs() < 0.1);
    }
}

#[tokio::test(start_paused = true)]
async fn the_same_seed_gives_identical_replies_in_virtual_time() {
    async fn run(seed: u64) -> Vec<car_link::CarState> {
        let config = SimConfig {
            seed,
            ..SimConfig::default()
        };
        let (stream, _sim) = spawn_in_process(&config);
        let car = LinkCar::over_stream(stream, link_config())
            .await
            .expect("handshake");
        car.prepare_for_test_drive().await.expect("config");
        let route: Vec<LinkPoint> = (0..5)
            .map(|i| LinkPoint::at(f64::from(i) * 2.0, 0.0, 2.0))
            .collect();
        car.add_points(&route).await.expect("add");
        car.set_autopilot(true, false).await.expect("active");
        let mut states = Vec::new();
        for _ in 0..40 {
            tokio::time::sleep(Duration::from_millis(50)).await;
            states.push(car.state().await.expect("state").state);
        }
        states
    }
    let a = run(3).await;
    assert_eq!(a, run(3).await);
    assert_ne!(a, run(4).await);
}

#[tokio::test(start_paused = true)]
async fn link_impairment_delays_loses_and_disconnects() {
    use car_link::frame::{FrameDecoder, FrameEncoder};
    let config = SimConfig {
        link: LinkImpairment {
            latency: Duration::from_millis(150),
            jitter: Duration::from_millis(40),
            disconnect_after: Some(Duration::from_secs(5)),
            ..LinkImpairment::default()
        },
        ..SimConfig::default()
    };
    let (mut stream, _sim) = spawn_in_process(&config);
    let request = FrameEncoder::pc_side(1024)
        .encode_to_bytes(&[0x01, 0x78])
        .expect("frame");
    let start = tokio::time::Instant::now();
    stream.write_all(&request).await.expect("write");
    let mut buf = [0u8; 512];
    let n = stream.read(&mut buf).await.expect("read");
    let rtt = start.elapsed();
    assert!(
        rtt >= Duration::from_millis(300) && rtt <= Duration::from_millis(400),
        "{rtt:?}"
    );
    let mut decoder = FrameDecoder::host();
    decoder.push(&buf[..n]);
    assert!(matches!(decoder.next_frame(), Some(Ok(_))));
    // Scripted disconnect: the stream ends.
    tokio::time::sleep(Duration::from_secs(6)).await;
    assert_eq!(stream.read(&mut buf).await.expect("eof"), 0);

    let lossy = SimConfig {
        link: LinkImpairment {
            loss: 1.0,
            ..LinkImpairment::default()
        },
        ..SimConfig::default()
    };
    let (mut stream, _sim) = spawn_in_process(&lossy);
    stream.write_all(&request).await.expect("write");
    assert!(
        timeout(Duration::from_secs(2), stream.read(&mut buf))
            .await
            .is_err(),
        "all lost"
    );
}

#[tokio::test(start_paused = true)]
async fn in_process_is_like_usb_and_forwards_replies_to_254() {
    use car_link::frame::{FrameDecoder, FrameEncoder};
    let (mut stream, _sim) = spawn_in_process(&SimConfig::default());
    let request = FrameEncoder::to_firmware()
        .encode_to_bytes(&[0xFE, 0x39])
        .expect("frame");
    stream.write_all(&request).await.expect("write");
    let mut buf = [0u8; 64];
    let n = stream.read(&mut buf).await.expect("read");
    let mut decoder = FrameDecoder::host();
    decoder.push(&buf[..n]);
    let frame = decoder.next_frame().expect("a frame").expect("valid");
    assert_eq!(&frame.payload[..], &[0xFE, 0x39]);
}

#[tokio::test(start_paused = true)]
async fn the_handle_shows_the_truth_and_the_debug_events() {
    use crate::{DebugEvent, World, WorldAnchor};
    use scenarios::geometry::Point;
    let config = SimConfig {
        world: World {
            anchors: vec![
                WorldAnchor {
                    id: 1,
                    position: Point::new(5.0, 0.0),
                    height: 1.0,
                    range_bias_m: None,
                },
                WorldAnchor {
                    id: 2,
                    position: Point::new(0.0, 5.0),
                    height: 1.0,
                    range_bias_m: None,
                },
            ],
            ..World::default()
        },
        preload_anchors: true,
        record_events: true,
        ..SimConfig::default()
    };
    let (_stream, sim) = spawn_in_process(&config);
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert!(sim.truth().time_ms >= 2_900);
    let events = sim.take_events();
    assert!(events.iter().any(|e| matches!(e, DebugEvent::Range { .. })));
    assert!(
        events
            .iter()
            .any(|e| matches!(e, DebugEvent::WatchdogExpired { at_ms: 2_010 }))
    );
    assert!(sim.take_events().len() < events.len());
}

#[test]
fn a_scenario_gives_the_world_and_the_start_pose() {
    let scenario = scenarios::bundled::load("parking-lot-2anchors")
        .expect("bundled")
        .scenario;
    let config = SimConfig::from_scenario(&scenario);
    assert_eq!(config.world.anchors.len(), 2);
    let start = scenario.start_route.positions();
    let placement = config.placement.expect("a start pose");
    assert_eq!((placement.x, placement.y), (start[0].x, start[0].y));
    let heading = (start[1] - start[0]).heading();
    assert!((placement.heading - heading).abs() < 1e-12);
}

/// The simulation does not wake for every tick: it runs the ticks due when a payload comes in
/// or goes out, and at the latest every few ticks. Whoever reads the truth sees time go on
/// without any request, and a reply reaches the client only after every tick before it (a
/// recording's `/sim/truth`, read as each state sample arrives, is the car's at that moment).
#[tokio::test(start_paused = true)]
async fn the_truth_keeps_time_between_requests_and_is_current_at_every_reply() {
    use crate::car::TICK_MS;
    use crate::server::HEARTBEAT_TICKS;
    use tokio::time::Instant;

    let start = Instant::now();
    let (stream, sim) = spawn_in_process(&SimConfig::default());
    let car = LinkCar::over_stream(stream, link_config())
        .await
        .expect("handshake");
    let last_tick = || (start.elapsed().as_millis() as u64 / TICK_MS) * TICK_MS;
    for wait_ms in [1_000, 3, 17, 250, 1, 2_000] {
        tokio::time::sleep(Duration::from_millis(wait_ms)).await;
        let idle = sim.truth().time_ms;
        assert!(
            idle <= last_tick() && last_tick() - idle < u64::from(HEARTBEAT_TICKS) * TICK_MS,
            "{idle} ms simulated at {} ms",
            last_tick()
        );
        car.state().await.expect("state");
        assert_eq!(sim.truth().time_ms, last_tick(), "after {wait_ms} ms");
    }
}
