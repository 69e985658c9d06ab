//! The client against a minimal responder, over the in-process pipe (in virtual time) and over loopback TCP.

use crate::support;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use car_link::client::{Car, CarError, LinkConfig, LinkEvent};
use car_link::fault::{FaultError, FaultKind, FaultRejection, Probe};
use car_link::firmware::FirmwareVersion;
use car_link::message::{Anchor, DecodeError, EnuRef, Request, RoutePoint};
use car_link::transport::sim_pipe;
use car_link::version::CommandId;
use futures::StreamExt;
use support::{Behaviour, Log, sample_state, serve};

/// A car behind the in-process pipe, served by the fake car.
async fn pipe_car(
    behaviour: Behaviour,
    config: LinkConfig,
) -> (Result<Car, CarError>, Arc<Mutex<Log>>) {
    let pipe = sim_pipe();
    let log = Arc::new(Mutex::new(Log::default()));
    tokio::spawn(serve(pipe.car, behaviour, log.clone()));
    (Car::over_stream(pipe.host, config).await, log)
}

fn requests(log: &Arc<Mutex<Log>>) -> Vec<Request> {
    log.lock().map(|l| l.requests.clone()).unwrap_or_default()
}

fn no_keepalive() -> LinkConfig {
    LinkConfig {
        keepalive: None,
        ..LinkConfig::default()
    }
}

#[tokio::test(start_paused = true)]
async fn the_handshake_learns_the_version_and_the_car_id() {
    let behaviour = Behaviour {
        id: 3,
        version: FirmwareVersion::V10_1,
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    assert_eq!(car.version(), FirmwareVersion::V10_1);
    assert_eq!(car.car_id(), 3);
    let sample = car.state().await.expect("a state");
    assert_eq!(sample.state, sample_state(FirmwareVersion::V10_1));
    assert_eq!(sample.ms_today(), 45_296_789);
    assert!(sample.received_at >= sample.requested_at);
}

#[tokio::test(start_paused = true)]
async fn a_lost_link_is_an_error_never_a_zero_state() {
    let behaviour = Behaviour {
        hang_up_after: Some(2),
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    let mut events = car.events();
    assert!(car.state().await.is_ok());
    // The car hangs up on the next request.
    let lost = car.state().await;
    assert!(matches!(lost, Err(CarError::LinkLost)), "{lost:?}");
    assert!(matches!(events.recv().await, Ok(LinkEvent::Lost { .. })));
    assert!(matches!(car.state().await, Err(CarError::LinkLost)));
    assert!(matches!(
        car.terminal("ping").await,
        Err(CarError::LinkLost)
    ));
    assert!(!car.health().link_up);
    let mut stream = Box::pin(car.state_stream(Duration::from_millis(50)));
    for _ in 0..3 {
        assert!(matches!(stream.next().await, Some(Err(CarError::LinkLost))));
    }
}

#[tokio::test(start_paused = true)]
async fn a_silent_car_times_out_instead_of_answering_zeros() {
    let behaviour = Behaviour {
        silent_after: Some(1),
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    let result = car.state().await;
    assert!(
        matches!(result, Err(CarError::NoReply { tries: 1, .. })),
        "{result:?}"
    );
    let result = car.clear_route().await;
    assert!(
        matches!(result, Err(CarError::NoReply { tries: 5, .. })),
        "{result:?}"
    );
    assert_eq!(car.health().timeouts, 6);
    // Nothing came since the handshake's reply: one state try and five clear tries ago.
    let silent = car.health().silent_for.expect("heard once");
    assert!(silent >= Duration::from_millis(1500), "{silent:?}");
}

#[tokio::test(start_paused = true)]
async fn a_link_that_stops_taking_bytes_stalls_the_call_instead_of_blocking_it() {
    let behaviour = Behaviour {
        stop_reading_after: Some(1),
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    // Commands without a reply fill the pipe, then the send queue; then one waits its request timeout.
    let mut sent = 0;
    let error = loop {
        match car.brake(50.0).await {
            Ok(()) => sent += 1,
            Err(error) => break error,
        }
        assert!(sent < 100_000, "the link never backed up");
    };
    assert!(
        matches!(error, CarError::SendStalled { waited } if waited == Duration::from_millis(250)),
        "{error:?} after {sent} commands"
    );
}

#[tokio::test(start_paused = true)]
async fn a_car_that_never_stops_printing_ends_the_terminal_reply_at_twice_the_timeout() {
    let behaviour = Behaviour {
        chatty_terminal: Some(200),
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    let started = tokio::time::Instant::now();
    let text = car.terminal("ping").await.expect("a reply");
    // Lines come every 50 ms for 10 s; the reply ends after 2 s with about 40 of them.
    assert!(
        started.elapsed() <= Duration::from_millis(2001),
        "{:?}",
        started.elapsed()
    );
    assert!(text.lines().count() >= 30, "{text}");
}

#[tokio::test(start_paused = true)]
async fn stray_and_duplicate_replies_are_not_taken_for_answers() {
    let behaviour = Behaviour {
        stray_replies: true,
        duplicate_replies: true,
        ..Behaviour::default()
    };
    // With another car on the same link, the handshake must name the car: a broadcast would take any answer.
    let config = LinkConfig {
        car_id: 1,
        ..no_keepalive()
    };
    let (car, _) = pipe_car(behaviour, config).await;
    let car = car.expect("handshake");
    for _ in 0..5 {
        let sample = car.state().await.expect("a state");
        assert_eq!(sample.car_id, 1);
        assert_eq!(sample.state, sample_state(FirmwareVersion::V12_3));
    }
    // An ack of AP_ADD_POINTS arrives before every state: it must not complete this upload's first packet
    // before the car saw it. The upload still succeeds on the real acks.
    car.add_points(&[RoutePoint::at(1.0, 2.0, 1.0)])
        .await
        .expect("points acked");
    let health = car.health();
    assert!(health.stray_replies >= 10, "{health:?}");
}

/// A proxy that changes the car id of the replies: the handshake and the health name the id the
/// replies came from and the one expected.
#[tokio::test(start_paused = true)]
async fn replies_from_another_car_id_are_named_in_the_error_and_the_health() {
    let config = LinkConfig {
        car_id: 1,
        ..no_keepalive()
    };
    let renumbered = |kept| Behaviour {
        renumber_after: Some((kept, 9)),
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(renumbered(0), config.clone()).await;
    let error = car.expect_err("no reply is the car's own").to_string();
    assert!(
        error.starts_with("version handshake failed: no reply to GetState from the car, but a reply came from car id 9, expected 1"),
        "{error}"
    );
    let (car, _) = pipe_car(renumbered(1), config).await;
    let car = car.expect("the handshake's reply is the car's own");
    assert_eq!(car.health().last_other_car, None);
    car.state().await.expect_err("no reply is the car's own");
    let health = car.health();
    assert_eq!(
        health.last_other_car,
        Some(car_link::health::OtherCar {
            car: 9,
            expected: 1
        }),
        "{health:?}"
    );
    assert_eq!(health.other_car_replies, 1, "{health:?}");
}

#[tokio::test(start_paused = true)]
async fn a_request_answered_only_by_undecodable_replies_fails_with_their_cause() {
    let garbling = |command| Behaviour {
        garble_reply_to: Some(command),
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(garbling(CommandId::GetEnuRef), no_keepalive()).await;
    let car = car.expect("handshake");
    let error = car.enu_ref().await.expect_err("a garbled reply");
    assert!(
        matches!(
            error,
            CarError::UndecodableReply {
                command: CommandId::GetEnuRef,
                source: DecodeError::Length { found: 10, .. },
            }
        ),
        "{error:?}"
    );
    assert_eq!(
        error.to_string(),
        "no reply that decodes to GetEnuRef: GetEnuRef: 10 data bytes, expected 20"
    );
    // A truncated main-configuration record, and an ack with a stray byte.
    let (car, _) = pipe_car(garbling(CommandId::GetMainConfig), no_keepalive()).await;
    let car = car.expect("handshake");
    let result = car.main_config().await;
    assert!(
        matches!(
            result,
            Err(CarError::UndecodableReply {
                command: CommandId::GetMainConfig,
                source: DecodeError::Config { .. },
            })
        ),
        "{result:?}"
    );
    let (car, _) = pipe_car(garbling(CommandId::ApClearPoints), no_keepalive()).await;
    let car = car.expect("handshake");
    let result = car.clear_route().await;
    assert!(
        matches!(
            result,
            Err(CarError::UndecodableReply {
                command: CommandId::ApClearPoints,
                ..
            })
        ),
        "{result:?}"
    );
    // Every try got its garbled answer and then timed out waiting for one that decodes.
    let health = car.health();
    assert_eq!((health.undecodable, health.timeouts), (5, 5), "{health:?}");
    // The link carries on.
    assert!(car.state().await.is_ok());
}

#[tokio::test(start_paused = true)]
async fn an_undecodable_payload_before_the_reply_does_not_end_the_try() {
    // As on a link that echoes requests: the echo has the request's header and does not decode as a reply.
    let behaviour = Behaviour {
        garble_then_answer: true,
        garble_reply_to: Some(CommandId::GetEnuRef),
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    let started = tokio::time::Instant::now();
    car.enu_ref()
        .await
        .expect("the reply after the garbled payload");
    assert!(started.elapsed() < LinkConfig::default().request_timeout);
    assert_eq!(car.health().undecodable, 1);
}

#[tokio::test(start_paused = true)]
async fn add_points_retries_when_an_ack_is_dropped() {
    let behaviour = Behaviour {
        drop_add_point_acks: 2,
        ..Behaviour::default()
    };
    let (car, log) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    let points: Vec<RoutePoint> = (0..12)
        .map(|i| RoutePoint::at(f64::from(i), 0.0, 1.0))
        .collect();
    let started = tokio::time::Instant::now();
    car.add_points(&points).await.expect("acked after retries");
    // Two lost acks cost two 250 ms timeouts.
    assert!(started.elapsed() >= Duration::from_millis(500));
    let sent: Vec<usize> = requests(&log)
        .iter()
        .filter_map(|r| match r {
            Request::AddPoints(p) => Some(p.len()),
            _ => None,
        })
        .collect();
    // 12 points in packets of 5: the first packet three times (two lost acks), then 5 and 2.
    assert_eq!(sent, vec![5, 5, 5, 5, 2]);
    assert_eq!(car.health().timeouts, 2);
    // After the retries the upload was read back: the route's length, then its last 12 points.
    let read_back: Vec<(i32, u8)> = requests(&log)
        .iter()
        .filter_map(|r| match r {
            Request::GetRoutePart { first, num } => Some((*first, *num)),
            _ => None,
        })
        .collect();
    assert_eq!(read_back, vec![(0, 0), (0, 12)]);
}

#[tokio::test(start_paused = true)]
async fn an_upload_without_retries_is_not_read_back() {
    let (car, log) = pipe_car(Behaviour::default(), no_keepalive()).await;
    let car = car.expect("handshake");
    let points: Vec<RoutePoint> = (0..12)
        .map(|i| RoutePoint::at(f64::from(i), 0.0, 1.0))
        .collect();
    car.add_points(&points).await.expect("acked");
    let reads = requests(&log)
        .iter()
        .filter(|r| matches!(r, Request::GetRoutePart { .. }))
        .count();
    assert_eq!(reads, 0);
}

#[tokio::test(start_paused = true)]
async fn a_late_ack_taken_for_a_lost_packet_is_caught_by_reading_the_route_back() {
    let behaviour = Behaviour {
        late_ack_then_lost_packet: true,
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    car.clear_route().await.expect("cleared");
    let points: Vec<RoutePoint> = (0..12)
        .map(|i| RoutePoint::at(f64::from(i), 0.0, 1.0))
        .collect();
    // The first packet's retry is answered, then the late ack of its first try answers the second
    // packet, which the car never got: every packet looks acked, but points 5–9 are missing.
    let result = car.add_points(&points).await;
    assert!(
        matches!(result, Err(CarError::RouteLength { held: 7, sent: 12 })),
        "{result:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn add_points_gives_up_after_five_tries() {
    let behaviour = Behaviour {
        drop_add_point_acks: 100,
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    let result = car.add_points(&[RoutePoint::at(1.0, 1.0, 1.0)]).await;
    assert!(
        matches!(result, Err(CarError::NoReply { tries: 5, .. })),
        "{result:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn a_packet_starting_where_the_previous_one_started_is_refused() {
    let (car, log) = pipe_car(Behaviour::default(), no_keepalive()).await;
    let car = car.expect("handshake");
    car.add_points(&[RoutePoint::at(1.0, 1.0, 1.0), RoutePoint::at(2.0, 1.0, 1.0)])
        .await
        .expect("acked");
    // The car would drop this whole packet silently.
    let again = car.add_points(&[RoutePoint::at(1.0, 1.0, 2.0)]).await;
    assert!(
        matches!(again, Err(CarError::DuplicateFirstPoint { index: 0 })),
        "{again:?}"
    );
    // A loop back to the start five points later would hit the same rule.
    let square = [
        (0.0, 0.0),
        (4.0, 0.0),
        (4.0, 4.0),
        (0.0, 4.0),
        (0.0, 2.0),
        (0.0, 0.0),
        (4.0, 0.0),
    ];
    car.clear_route().await.expect("cleared");
    let route: Vec<RoutePoint> = square
        .iter()
        .map(|&(x, y)| RoutePoint::at(x, y, 1.0))
        .collect();
    let sent_before = requests(&log).len();
    let result = car.add_points(&route).await;
    assert!(
        matches!(result, Err(CarError::DuplicateFirstPoint { index: 5 })),
        "{result:?}"
    );
    // Refused before anything was sent: no half-uploaded route.
    assert_eq!(requests(&log).len(), sent_before);
    // After a clear the memory is gone.
    car.clear_route().await.expect("cleared");
    car.add_points(&[RoutePoint::at(1.0, 1.0, 1.0)])
        .await
        .expect("acked");
    let replaces = requests(&log)
        .iter()
        .filter(|r| matches!(r, Request::ClearPoints))
        .count();
    assert_eq!(replaces, 2);
}

#[tokio::test(start_paused = true)]
async fn replace_route_sends_one_replace_then_add_packets() {
    let (car, log) = pipe_car(Behaviour::default(), no_keepalive()).await;
    let car = car.expect("handshake");
    let route: Vec<RoutePoint> = (0..7)
        .map(|i| RoutePoint::at(f64::from(i), 1.0, 1.0))
        .collect();
    car.replace_route(&route).await.expect("replaced");
    // Replacing with the same route while inactive is fine: the car clears its duplicate memory.
    car.replace_route(&route).await.expect("replaced again");
    let kinds: Vec<&str> = requests(&log)
        .iter()
        .filter_map(|r| match r {
            Request::ReplaceRoute(_) => Some("replace"),
            Request::AddPoints(_) => Some("add"),
            _ => None,
        })
        .collect();
    assert_eq!(kinds, vec!["replace", "add", "replace", "add"]);
}

#[tokio::test(start_paused = true)]
async fn autopilot_anchors_enu_pose_and_brake_reach_the_car() {
    let (car, log) = pipe_car(Behaviour::default(), no_keepalive()).await;
    let car = car.expect("handshake");
    car.set_autopilot(true, true).await.expect("acked");
    let anchors = [
        Anchor {
            id: 50,
            px: 10.0,
            py: -5.5,
            height: 2.0,
        },
        Anchor {
            id: 51,
            px: 0.0,
            py: 0.0,
            height: 2.0,
        },
    ];
    car.upload_anchors(&anchors).await.expect("acked");
    let reference = EnuRef {
        lat: 57.7,
        lon: 12.0,
        height: 10.0,
    };
    car.set_enu_ref(reference).await.expect("acked");
    assert_eq!(car.enu_ref().await.expect("read back"), reference);
    car.set_pos(car_link::message::Pose {
        x: 1.0,
        y: 2.0,
        yaw: 90.0,
    })
    .await
    .expect("acked");
    assert_eq!(
        car.route_part(0, 3)
            .await
            .expect("three points")
            .points
            .len(),
        3
    );
    assert!(matches!(
        car.route_part(0, 21).await,
        Err(CarError::InvalidArgument(_))
    ));
    car.brake(50.0).await.expect("sent");
    tokio::time::sleep(Duration::from_millis(10)).await;
    let log = requests(&log);
    assert!(log.contains(&Request::SetActive {
        active: true,
        reset: true
    }));
    assert_eq!(
        log.iter()
            .filter(|r| matches!(r, Request::AddUwbAnchor(_)))
            .count(),
        2
    );
    assert!(
        log.iter()
            .any(|r| matches!(r, Request::RcControl(rc) if rc.throttle == 50.0))
    );
}

#[tokio::test(start_paused = true)]
async fn reset_is_refused_for_firmware_before_12_3() {
    let behaviour = Behaviour {
        version: FirmwareVersion::new(12, 2),
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    assert!(matches!(
        car.set_autopilot(true, true).await,
        Err(CarError::Encode(_))
    ));
    car.set_autopilot(true, false).await.expect("acked");
}

#[tokio::test(start_paused = true)]
async fn fault_replies_are_parsed_into_typed_results() {
    let behaviour = Behaviour {
        debug_noise: true,
        ..Behaviour::default()
    };
    let (car, _) = pipe_car(behaviour, no_keepalive()).await;
    let car = car.expect("handshake");
    car.clear_faults().await.expect("cleared");
    car.set_fi_enabled(true).await.expect("enabled");
    car.reset_uwb_pos().await.expect("reset");
    let probe = Probe::UwbRange(50);
    for _ in 0..5 {
        car.add_fault(&probe, FaultKind::Offset, 2.0, 15, 8)
            .await
            .expect("added");
    }
    let full = car.add_fault(&probe, FaultKind::Offset, 2.0, 15, 8).await;
    assert!(
        matches!(&full, Err(CarError::Fault(FaultError::Rejected(r))) if r == &[FaultRejection::TooManyFaults]),
        "{full:?}"
    );
    for anchor in 1..=4 {
        car.add_fault(&Probe::UwbRange(anchor), FaultKind::SetTo, 0.0, 0, 0)
            .await
            .expect("added");
    }
    let probes = car
        .add_fault(&Probe::Px, FaultKind::Bitflip, 30.0, 0, 1)
        .await;
    assert!(
        matches!(&probes, Err(CarError::Fault(FaultError::Rejected(r))) if r == &[FaultRejection::TooManyProbes]),
        "{probes:?}"
    );
    car.clear_faults().await.expect("cleared");
    car.add_fault(&Probe::Px, FaultKind::Bitflip, 30.0, 0, 1)
        .await
        .expect("room again");
}

#[tokio::test(start_paused = true)]
async fn terminal_returns_the_reply_text() {
    let (car, _) = pipe_car(Behaviour::default(), no_keepalive()).await;
    let car = car.expect("handshake");
    assert_eq!(car.terminal("ping").await.expect("pong"), "pong\n");
    let unknown = car.terminal("fi_clear_faults\n").await.expect("a reply");
    assert!(
        unknown.starts_with("Invalid command: fi_clear_faults\n"),
        "{unknown:?}"
    );
    let invalid = car
        .terminal("fi_add_fault px offset 1 0 0")
        .await
        .expect("a reply");
    assert_eq!(invalid, "Invalid fault type offset\n");
}

#[tokio::test(start_paused = true)]
async fn the_keepalive_feeds_the_watchdog_while_the_car_is_alive() {
    let (car, log) = pipe_car(Behaviour::default(), LinkConfig::default()).await;
    let car = car.expect("handshake");
    let count = || {
        requests(&log)
            .iter()
            .filter(|r| matches!(r, Request::GetState))
            .count()
    };
    let before = count();
    tokio::time::sleep(Duration::from_secs(10)).await;
    let fed = count() - before;
    // Every 250 ms: about 40 in 10 s; the watchdog (2 s) needs at least 5.
    assert!((36..=44).contains(&fed), "{fed} keepalives in 10 s");
    // Commands that feed the watchdog make the keepalive unnecessary.
    let before = count();
    for _ in 0..20 {
        car.set_autopilot(true, false).await.expect("acked");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(
        count() - before <= 2,
        "{} keepalives while commands fed it",
        count() - before
    );
    // Once the handle is gone, the keepalive stops and the watchdog may fire.
    drop(car);
    tokio::time::sleep(Duration::from_millis(50)).await;
    let before = count();
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert_eq!(count(), before);
}

#[tokio::test(start_paused = true)]
async fn the_state_stream_polls_at_the_chosen_rate() {
    let (car, _) = pipe_car(Behaviour::default(), no_keepalive()).await;
    let car = car.expect("handshake");
    let stream = car.state_stream(Duration::from_millis(50));
    let samples: Vec<_> = stream.take(20).collect().await;
    assert!(samples.iter().all(Result::is_ok));
    let times: Vec<_> = samples
        .iter()
        .filter_map(|s| s.as_ref().ok())
        .map(|s| s.requested_at)
        .collect();
    let span = times[19].duration_since(times[0]);
    assert_eq!(span, Duration::from_millis(950));
}

#[tokio::test]
async fn over_loopback_tcp_with_reconnection() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let port = listener.local_addr().expect("address").port();
    let log = Arc::new(Mutex::new(Log::default()));
    let server_log = log.clone();
    tokio::spawn(async move {
        // The first connection hangs up after 3 answers; the second behaves.
        let mut hang_up = Some(3);
        while let Ok((stream, _)) = listener.accept().await {
            let behaviour = Behaviour {
                hang_up_after: hang_up.take(),
                ..Behaviour::default()
            };
            tokio::spawn(serve(stream, behaviour, server_log.clone()));
        }
    });
    let address = format!("tcp://127.0.0.1:{port}").parse().expect("address");
    let car = Car::connect(&address, no_keepalive())
        .await
        .expect("connected");
    let mut events = car.events();
    assert!(car.state().await.is_ok());
    assert!(car.state().await.is_ok());
    assert!(matches!(car.state().await, Err(CarError::LinkLost)));
    assert!(matches!(events.recv().await, Ok(LinkEvent::Lost { .. })));
    assert!(matches!(events.recv().await, Ok(LinkEvent::Reconnected)));
    let sample = car.state().await.expect("a state after reconnecting");
    assert_eq!(sample.state.version, FirmwareVersion::V12_3);
    let health = car.health();
    assert_eq!(health.reconnects, 1);
    assert!(health.link_up);
    assert!(health.rtt_p50.is_some());
}

#[tokio::test]
async fn over_udp_replies_come_back_to_port_plus_one() {
    // A fake bridge: datagrams in, replies to the sender's IP at port + 1.
    let bridge = tokio::net::UdpSocket::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let port = bridge.local_addr().expect("address").port();
    tokio::spawn(async move {
        let mut buf = vec![0u8; 2048];
        let dialect = car_link::message::Dialect::firmware(FirmwareVersion::V12_3);
        while let Ok((n, from)) = bridge.recv_from(&mut buf).await {
            let Ok((_, request)) = Request::decode(&buf[..n], FirmwareVersion::V12_3) else {
                continue;
            };
            let reply = match request {
                Request::GetState => car_link::Reply::State(sample_state(FirmwareVersion::V12_3)),
                _ => continue,
            };
            let payload = reply.encode(1, dialect).unwrap_or_default();
            let _ = bridge.send_to(&payload, (from.ip(), port + 1)).await;
        }
    });
    let address = format!("udp://127.0.0.1:{port}").parse().expect("address");
    let car = Car::connect(&address, no_keepalive())
        .await
        .expect("handshake over UDP");
    assert_eq!(car.car_id(), 1);
    assert!(car.state().await.is_ok());
}

#[tokio::test]
async fn over_udp_replies_from_anyone_but_the_bridges_port_are_ignored() {
    // A bridge that never answers, and a spoofer on the same host (loopback) that keeps sending
    // valid replies to the client's reply port from a port of its own.
    let bridge = tokio::net::UdpSocket::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let port = bridge.local_addr().expect("address").port();
    let spoofer = tokio::net::UdpSocket::bind("127.0.0.1:0")
        .await
        .expect("bind");
    assert_ne!(spoofer.local_addr().expect("address").port(), port);
    let dialect = car_link::message::Dialect::firmware(FirmwareVersion::V12_3);
    let reply = car_link::Reply::State(sample_state(FirmwareVersion::V12_3))
        .encode(1, dialect)
        .expect("a reply");
    let spoofing = tokio::spawn(async move {
        loop {
            let _ = spoofer.send_to(&reply, ("127.0.0.1", port + 1)).await;
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    });
    let address = format!("udp://127.0.0.1:{port}").parse().expect("address");
    let config = LinkConfig {
        reconnect: false,
        ..no_keepalive()
    };
    let result = Car::connect(&address, config).await;
    spoofing.abort();
    match result {
        Ok(car) => panic!("connected to a spoofer: firmware {}", car.version()),
        Err(error) => assert!(
            matches!(&error, CarError::Handshake(inner) if matches!(**inner, CarError::NoReply { .. })),
            "{error}"
        ),
    }
    drop(bridge);
}

#[tokio::test]
async fn the_sim_address_is_left_to_the_orchestrator() {
    let result = Car::connect(&car_link::CarAddress::Sim, no_keepalive()).await;
    assert!(matches!(result, Err(CarError::Connect { .. })));
}

#[tokio::test]
async fn a_missing_serial_device_is_a_connect_error() {
    let address = "serial:///dev/does-not-exist-car-link"
        .parse()
        .expect("address");
    let result = Car::connect(&address, no_keepalive()).await;
    assert!(
        matches!(result, Err(CarError::Connect { .. })),
        "{result:?}"
    );
}

#[tokio::test(start_paused = true)]
async fn preparing_for_a_test_drive_switches_repeat_off_once() {
    let (car, log) = pipe_car(Behaviour::default(), no_keepalive()).await;
    let car = car.expect("handshake");
    let changed = car.prepare_for_test_drive().await.expect("prepared");
    assert_eq!(
        changed,
        vec![(car_link::config::ConfigField::ApRepeatRoutes, 1)]
    );
    let config = car.main_config().await.expect("read back");
    assert_eq!(
        config.get_u8(car_link::config::ConfigField::ApRepeatRoutes),
        Ok(0)
    );
    assert_eq!(
        car.prepare_for_test_drive().await.expect("prepared"),
        vec![]
    );
    let writes = requests(&log)
        .iter()
        .filter(|r| matches!(r, Request::SetMainConfig(_)))
        .count();
    assert_eq!(writes, 1);
}
