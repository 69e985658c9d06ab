//! A minimal responder: a fake car that answers the client over any byte stream, with knobs to misbehave.
//! The full simulator is another crate; this one only answers what the client tests need.

#![allow(dead_code)] // each test binary uses part of it

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use car_link::config::MainConfig;
use car_link::firmware::FirmwareVersion;
use car_link::frame::FrameCodec;
use car_link::message::{CarState, Dialect, EnuRef, Reply, Request, RoutePart, RoutePoint};
use car_link::version::CommandId;
use futures::{SinkExt, StreamExt};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, DuplexStream};
use tokio::sync::mpsc;
use tokio::time::{Duration, Instant};
use tokio_util::codec::Framed;

/// How the fake car behaves.
#[derive(Debug, Clone)]
pub struct Behaviour {
    /// The car's own id.
    pub id: u8,
    /// The firmware version it reports.
    pub version: FirmwareVersion,
    /// Acks of AP_ADD_POINTS to swallow before answering normally.
    pub drop_add_point_acks: usize,
    /// Send every reply twice.
    pub duplicate_replies: bool,
    /// Before each GET_STATE reply, send a stray ack and a state from another car.
    pub stray_replies: bool,
    /// Answer this many requests, then go silent (keep the stream open, answer nothing).
    pub silent_after: Option<usize>,
    /// Answer this many requests, then close the stream.
    pub hang_up_after: Option<usize>,
    /// Before each terminal reply, send an unrelated debug PRINTF.
    pub debug_noise: bool,
    /// Lose the reply to every n-th GET_STATE (the handshake's is the first).
    pub lose_every_nth_state: Option<usize>,
    /// Store the first AP_ADD_POINTS but hold its ack; ack the client's retry; then lose the next packet
    /// and send the held ack instead: a late ack that arrives while the next packet is waiting.
    pub late_ack_then_lost_packet: bool,
    /// Answer this many requests, then stop reading the stream (keep it open): the host's writes back up.
    pub stop_reading_after: Option<usize>,
    /// Answer a terminal command with this many lines, 50 ms apart (a car printing without pause).
    pub chatty_terminal: Option<usize>,
    /// Answer this command with its reply's header and a garbled body that does not decode: the first half of
    /// the data, or a stray byte after a bare ack.
    pub garble_reply_to: Option<CommandId>,
    /// With `garble_reply_to`: send the garbled payload, then the real reply.
    pub garble_then_answer: bool,
    /// After answering this many requests, stamp every reply with this car id (a proxy that
    /// changes the id).
    pub renumber_after: Option<(usize, u8)>,
}

impl Default for Behaviour {
    fn default() -> Self {
        Behaviour {
            id: 1,
            version: FirmwareVersion::V12_3,
            drop_add_point_acks: 0,
            duplicate_replies: false,
            stray_replies: false,
            silent_after: None,
            hang_up_after: None,
            debug_noise: false,
            lose_every_nth_state: None,
            late_ack_then_lost_packet: false,
            stop_reading_after: None,
            chatty_terminal: None,
            garble_reply_to: None,
            garble_then_answer: false,
            renumber_after: None,
        }
    }
}

/// What the fake car saw.
#[derive(Debug, Default)]
pub struct Log {
    /// Every request decoded, in order.
    pub requests: Vec<Request>,
}

/// The firmware's fault-injection bookkeeping: 5 probes of 5 slots.
#[derive(Debug, Default)]
struct Faults {
    enabled: bool,
    probes: HashMap<String, usize>,
}

impl Faults {
    fn command(&mut self, text: &str) -> Vec<String> {
        let tokens: Vec<&str> = text.split(' ').collect();
        match tokens[0] {
            "fi_add_fault" => self.add(&tokens),
            "fi_clear_faults" => {
                self.probes.clear();
                vec!["Faults cleared\n".into()]
            }
            "fi_set_enabled" if tokens.len() != 2 => vec!["Wrong number of arguments\n".into()],
            "fi_set_enabled" => match tokens[1] {
                "0" | "1" => {
                    self.enabled = tokens[1] == "1";
                    let state = if self.enabled { "enabled" } else { "disabled" };
                    vec![format!("Fault Injection {state}\n")]
                }
                other => vec![format!("Invalid argument {other}\n")],
            },
            "pos_uwb_reset_pos" => vec!["UWB Position Reset\n".into()],
            "ping" => vec!["pong\n".into()],
            "" => vec!["No command received\n".into()],
            other => vec![format!(
                "Invalid command: {other}\ntype help to list all available commands\n"
            )],
        }
    }

    fn add(&mut self, tokens: &[&str]) -> Vec<String> {
        if tokens.len() != 6 {
            return vec!["Wrong number of arguments\n".into()];
        }
        let (id, kind) = (tokens[1], tokens[2]);
        let mut errors = Vec::new();
        if id.len() > 20 {
            errors.push("Too long ID. Maximum length is 20\n".to_string());
        }
        let valid = ["BITFLIP", "OFFSET", "AMPLIFICATION", "SET_TO"].contains(&kind)
            || kind.eq_ignore_ascii_case("none");
        if !valid {
            errors.push(format!("Invalid fault type {kind}\n"));
        }
        if !errors.is_empty() {
            return errors;
        }
        if !self.probes.contains_key(id) && self.probes.len() == 5 {
            return vec!["Too many probes in use, fault not added.\n".into()];
        }
        let used = self.probes.entry(id.to_string()).or_default();
        if *used == 5 {
            return vec!["Too many faults on this probe, fault not added.\n".into()];
        }
        *used += 1;
        let param: f32 = tokens[3].parse().unwrap_or(0.0);
        vec![format!(
            "Fault {kind} with parameter {param:.2} successfully added to probe {id}.\n"
        )]
    }
}

/// A plausible state, with the values of the GET_STATE reply test vector (`docs/protocol.md#test-vectors`).
pub fn sample_state(version: FirmwareVersion) -> CarState {
    CarState {
        version,
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

/// The stored route, with the firmware's duplicate-packet rule (autopilot inactive throughout).
#[derive(Debug, Default)]
struct Route {
    points: Vec<RoutePoint>,
    last_first: Option<(f64, f64)>,
}

impl Route {
    fn add(&mut self, packet: &[RoutePoint]) {
        let Some(first) = packet.first() else { return };
        let duplicate = self
            .last_first
            .is_some_and(|(x, y)| (x - first.px).abs() < 1e-4 && (y - first.py).abs() < 1e-4);
        if !duplicate {
            self.last_first = Some((first.px, first.py));
            self.points.extend_from_slice(packet);
        }
    }

    fn part(&self, first: i32, num: u8) -> RoutePart {
        let points = (0..i64::from(num))
            .map(|k| {
                usize::try_from(i64::from(first) + k)
                    .ok()
                    .and_then(|i| self.points.get(i).copied())
                    .unwrap_or_default()
            })
            .collect();
        RoutePart {
            route_len: i32::try_from(self.points.len()).unwrap_or(i32::MAX),
            points,
        }
    }
}

/// Serves one stream until it closes (or the behaviour says to hang up).
pub async fn serve<S>(stream: S, behaviour: Behaviour, log: Arc<Mutex<Log>>)
where
    S: AsyncRead + AsyncWrite + Unpin,
{
    let dialect = Dialect::firmware(behaviour.version);
    let mut framed = Framed::new(stream, FrameCodec::car());
    let mut faults = Faults::default();
    let mut enu = EnuRef::default();
    let mut config = MainConfig::factory_default(behaviour.version, behaviour.id);
    let mut dropped_acks = 0;
    let mut route = Route::default();
    let mut add_points_seen = 0usize;
    let mut answered = 0usize;
    let mut states = 0usize;
    while let Some(Ok(item)) = framed.next().await {
        let Ok(frame) = item else { continue };
        let Ok((id, request)) = Request::decode(&frame.payload, behaviour.version) else {
            continue;
        };
        if id != behaviour.id && id != 255 && id != 254 {
            continue;
        }
        if let Ok(mut log) = log.lock() {
            log.requests.push(request.clone());
        }
        if behaviour.hang_up_after.is_some_and(|n| answered >= n) {
            return;
        }
        if behaviour.silent_after.is_some_and(|n| answered >= n) {
            continue;
        }
        if behaviour.stop_reading_after.is_some_and(|n| answered >= n) {
            std::future::pending::<()>().await;
        }
        answered += 1;
        let reply_id = match behaviour.renumber_after {
            Some((kept, other)) if answered > kept => other,
            _ if id == 254 => 254,
            _ => behaviour.id,
        };
        let replies: Vec<Reply> = match &request {
            Request::GetState => {
                states += 1;
                let mut replies = Vec::new();
                if behaviour
                    .lose_every_nth_state
                    .is_some_and(|n| states.is_multiple_of(n))
                {
                    continue;
                }
                if behaviour.stray_replies {
                    replies.push(Reply::Ack(CommandId::ApAddPoints));
                }
                replies.push(Reply::State(sample_state(behaviour.version)));
                replies
            }
            Request::TerminalCmd(_) if behaviour.chatty_terminal.is_some() => {
                for k in 0..behaviour.chatty_terminal.unwrap_or(0) {
                    let line = Reply::Printf(format!("debug line {k}\n"));
                    let Ok(payload) = line.encode(reply_id, dialect) else {
                        continue;
                    };
                    if framed.send(payload).await.is_err() {
                        return;
                    }
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
                Vec::new()
            }
            Request::TerminalCmd(text) => {
                let mut lines = Vec::new();
                if behaviour.debug_noise {
                    lines.push("debug: uwb range 12.3\n".to_string());
                }
                lines.extend(faults.command(text));
                lines.into_iter().map(Reply::Printf).collect()
            }
            Request::AddPoints(points) => {
                add_points_seen += 1;
                let late = behaviour.late_ack_then_lost_packet;
                if late && add_points_seen == 3 {
                    // This packet is lost; the ack held from the first try arrives now.
                    vec![Reply::Ack(CommandId::ApAddPoints)]
                } else {
                    route.add(points);
                    if late && add_points_seen == 1 {
                        Vec::new()
                    } else if dropped_acks < behaviour.drop_add_point_acks {
                        dropped_acks += 1;
                        Vec::new()
                    } else {
                        vec![Reply::Ack(CommandId::ApAddPoints)]
                    }
                }
            }
            Request::ReplaceRoute(points) => {
                route = Route::default();
                route.add(points);
                vec![Reply::Ack(CommandId::ApReplaceRoute)]
            }
            Request::ClearPoints => {
                route = Route::default();
                vec![Reply::Ack(CommandId::ApClearPoints)]
            }
            Request::SetEnuRef(reference) => {
                enu = *reference;
                vec![Reply::Ack(CommandId::SetEnuRef)]
            }
            Request::GetEnuRef => vec![Reply::EnuRef(enu)],
            Request::GetMainConfig => vec![Reply::MainConfig {
                default: false,
                config: config.clone(),
            }],
            Request::SetMainConfig(record) => {
                config = record.clone();
                vec![Reply::Ack(CommandId::SetMainConfig)]
            }
            Request::GetRoutePart { first, num } if *num <= 20 => {
                vec![Reply::RoutePart(route.part(*first, *num))]
            }
            other => match other.command(behaviour.version) {
                Some(command) if car_link::message::is_acked(command) => vec![Reply::Ack(command)],
                _ => Vec::new(),
            },
        };
        let garble = behaviour.garble_reply_to.is_some()
            && request.command(behaviour.version) == behaviour.garble_reply_to;
        for reply in replies {
            if garble {
                let Ok(payload) = reply.encode(reply_id, dialect) else {
                    continue;
                };
                if framed.send(garbled(&payload)).await.is_err() {
                    return;
                }
                if !behaviour.garble_then_answer {
                    continue;
                }
            }
            let copies = if behaviour.duplicate_replies { 2 } else { 1 };
            for _ in 0..copies {
                if behaviour.stray_replies && matches!(reply, Reply::State(_)) {
                    let other_car = reply.encode(7, dialect).unwrap_or_default();
                    let _ = framed.send(other_car).await;
                }
                let Ok(payload) = reply.encode(reply_id, dialect) else {
                    continue;
                };
                if framed.send(payload).await.is_err() {
                    return;
                }
            }
        }
    }
}

/// `[id][cmd]` followed by the first half of the data, or by one byte where there is no data.
fn garbled(payload: &[u8]) -> Vec<u8> {
    let (header, data) = payload.split_at(2.min(payload.len()));
    let mut out = header.to_vec();
    if data.is_empty() {
        out.push(0xFF);
    } else {
        out.extend_from_slice(&data[..data.len() / 2]);
    }
    out
}

/// A long link in process: two pipes joined by relays that hold every chunk of bytes for `one_way` in each
/// direction (order kept, nothing lost), so that a round trip takes `2 × one_way`. Works in virtual time.
/// Returns the host end (for the client) and the car end (for [`serve`]).
pub fn slow_pipe(one_way: Duration) -> (DuplexStream, DuplexStream) {
    let near = car_link::transport::sim_pipe();
    let far = car_link::transport::sim_pipe();
    let (near_read, near_write) = tokio::io::split(near.car);
    let (far_read, far_write) = tokio::io::split(far.host);
    tokio::spawn(relay(near_read, far_write, one_way));
    tokio::spawn(relay(far_read, near_write, one_way));
    (near.host, far.car)
}

/// Copies `from` to `to`, each chunk `delay` after it was read.
async fn relay<R, W>(mut from: R, mut to: W, delay: Duration)
where
    R: AsyncRead + Unpin + Send + 'static,
    W: AsyncWrite + Unpin + Send + 'static,
{
    let (tx, mut rx) = mpsc::unbounded_channel::<(Instant, Vec<u8>)>();
    let writer = tokio::spawn(async move {
        while let Some((due, bytes)) = rx.recv().await {
            tokio::time::sleep_until(due).await;
            if to.write_all(&bytes).await.is_err() {
                return;
            }
        }
    });
    let mut buffer = vec![0u8; 4096];
    while let Ok(n) = from.read(&mut buffer).await {
        if n == 0
            || tx
                .send((Instant::now() + delay, buffer[..n].to_vec()))
                .is_err()
        {
            break;
        }
    }
    drop(tx);
    let _ = writer.await;
}
