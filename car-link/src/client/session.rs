//! The state behind a [`super::Car`]: the link's sender, the requests waiting for replies, the dispatcher that
//! matches replies to them by (car id, command), and the background tasks (link supervision with reconnection,
//! watchdog keepalive).
//!
//! GET_STATE is matched differently from every other command, because several GET_STATE requests may be in
//! flight at once (the pipelined state stream, the keepalive, single reads) and its reply carries no request id.
//! All GET_STATE requests are identical and idempotent, and the car answers in arrival order
//! (`docs/protocol.md#receiving-frames`, on an ordered link), so a reply answers the **oldest** GET_STATE request of
//! that car still waiting (first in, first out). A request whose reply has not come by its deadline counts as lost and
//! is never paired afterwards; a reply with no request waiting is stray. See [`Shared::dispatch_state`] for what this
//! means for the stamps.
//!
//! A reply whose payload does not decode, but whose header names the (car, command) of a waiting request (not
//! GET_STATE), is handed to that request: if no reply that decodes comes, the request fails with
//! [`CarError::UndecodableReply`] and its cause rather than a bare "no reply".

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use bytes::Bytes;
use tokio::sync::{broadcast, mpsc, oneshot, watch};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use super::{CarError, LinkConfig, LinkEvent, StateSample};
use crate::address::CarAddress;
use crate::firmware::FirmwareVersion;
use crate::health::{HealthRecorder, OtherCar};
use crate::message::{DecodeError, Dialect, ID_ALL, POINTS_PER_PACKET, Reply, Request, RoutePoint};
use crate::transport::{Incoming, Link, PC_BYTE_TIMEOUT};
use crate::version::CommandId;

use super::DUPLICATE_POINT_THRESHOLD;
#[derive(Debug, Clone, Copy)]
pub(super) struct Identity {
    pub(super) car_id: u8,
    pub(super) version: FirmwareVersion,
}

/// Waiting requests are keyed by (car id or any, wire command id).
type Key = (Option<u8>, u8);

/// A GET_STATE request waiting for its reply, in the order sent.
#[derive(Debug)]
pub(super) struct StateWaiter {
    /// The car it was sent to (`None`: broadcast, any car answers).
    car: Option<u8>,
    /// After this it counts as lost: a later reply answers a later request.
    deadline: Instant,
    tx: oneshot::Sender<Answer>,
}

/// The requester's side of a GET_STATE request in flight.
#[derive(Debug)]
pub(super) struct StateTicket {
    /// When the request was handed to the link.
    pub(super) sent_at: Instant,
    /// When it counts as lost.
    pub(super) deadline: Instant,
    rx: oneshot::Receiver<Answer>,
}

/// How a GET_STATE request ended.
#[derive(Debug)]
pub(super) enum StateOutcome {
    /// Its reply (the oldest waiting request takes the next reply).
    Answered(Box<Answer>),
    /// No reply by its deadline.
    Expired,
    /// The link went down while it waited.
    LinkLost,
}

impl StateTicket {
    /// Waits for the outcome. Cancel-safe: the ticket can be waited on again.
    pub(super) async fn outcome(&mut self) -> StateOutcome {
        match tokio::time::timeout_at(self.deadline, &mut self.rx).await {
            Ok(Ok(answer)) => StateOutcome::Answered(Box::new(answer)),
            // The dispatcher forgets a request past its deadline; before it, only a lost link drops it.
            Ok(Err(_)) if Instant::now() >= self.deadline => StateOutcome::Expired,
            Ok(Err(_)) => StateOutcome::LinkLost,
            Err(_) => StateOutcome::Expired,
        }
    }
}

/// A reply delivered to a waiting request.
#[derive(Debug)]
pub(super) struct Answer {
    pub(super) car: u8,
    pub(super) reply: Reply,
    pub(super) received_at: Instant,
}

#[derive(Debug, Default)]
pub(super) struct RouteMemory {
    /// First (x, y) of the previous accepted route packet; the firmware drops a packet starting there.
    pub(super) last_first: Option<(f64, f64)>,
    /// Whether the autopilot was last switched on by this client.
    pub(super) active: bool,
    /// Points sent since the route was last emptied by this client (clear, or replace while inactive):
    /// what the car's route length reads while the ring has not wrapped. `None` until then.
    pub(super) sent_since_empty: Option<usize>,
}

#[derive(Debug)]
pub(super) struct Shared {
    pub(super) config: LinkConfig,
    pub(super) identity: Mutex<Identity>,
    pub(super) outgoing: Mutex<Option<mpsc::Sender<Bytes>>>,
    pub(super) waiters: Mutex<HashMap<Key, oneshot::Sender<Answer>>>,
    /// For a waiting request, why the last payload with its header did not decode.
    pub(super) garbled: Mutex<HashMap<Key, DecodeError>>,
    /// GET_STATE requests in flight, oldest first.
    pub(super) state_waiters: Mutex<VecDeque<StateWaiter>>,
    pub(super) lanes: Mutex<HashMap<u8, Arc<tokio::sync::Mutex<()>>>>,
    /// Ordered lanes of terminal commands (the fault commands of one probe), by name: see
    /// [`Shared::terminal_lines_ordered`].
    pub(super) ordered_lanes: Mutex<HashMap<String, Arc<OrderedLane>>>,
    pub(super) printf: broadcast::Sender<String>,
    /// PRINTF lines sent on [`Shared::printf`] so far: the number of each line, for
    /// [`Shared::subscribe_printf`].
    pub(super) printf_sent: Mutex<u64>,
    pub(super) events: broadcast::Sender<LinkEvent>,
    pub(super) health: Mutex<HealthRecorder>,
    pub(super) last_feed: Mutex<Option<Instant>>,
    pub(super) keepalive_on: AtomicBool,
    pub(super) losses: AtomicU64,
    pub(super) route: Mutex<RouteMemory>,
    /// One route upload at a time, so that packets of two uploads never interleave.
    pub(super) uploads: tokio::sync::Mutex<()>,
    pub(super) latest: watch::Sender<Option<StateSample>>,
    /// The per-try timeout in force, ns: `config.request_timeout` until [`Shared::set_request_timeout`].
    pub(super) request_timeout_ns: AtomicU64,
    /// The tries of an acked request in force: `config.tries` until [`Shared::set_tries`].
    pub(super) tries: AtomicU32,
    /// `fi_add_fault` commands in flight now, and started so far: a command that ran alone
    /// knows that a success line naming another probe answered it (see `Car::add_fault`).
    pub(super) fault_adds: Mutex<FaultAdds>,
}

/// The `fi_add_fault` commands of a car: in flight now, started so far.
#[derive(Debug, Default)]
pub(super) struct FaultAdds {
    pub(super) in_flight: usize,
    pub(super) started: u64,
}

/// Locks a std mutex, ignoring poisoning (no code here panics while holding one).
pub(super) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Removes its waiter when the request finishes or is cancelled.
struct WaiterGuard<'a> {
    shared: &'a Shared,
    key: Key,
}

impl Drop for WaiterGuard<'_> {
    fn drop(&mut self) {
        lock(&self.shared.waiters).remove(&self.key);
    }
}

/// A lane of terminal commands in flight together, their replies taken in order (see
/// [`Shared::terminal_lines_ordered`]).
#[derive(Debug, Default)]
pub(super) struct OrderedLane {
    /// Held while a command is sent: what the last command sent will have taken (the number of the last
    /// PRINTF line of its reply), for the command after it.
    tail: tokio::sync::Mutex<Option<oneshot::Receiver<u64>>>,
}

/// A terminal command's reply being collected: the relevant lines by number, those after `after` taken.
struct TerminalReply {
    /// The number of the last line received.
    seen: u64,
    /// Relevant lines, by number.
    lines: Vec<(u64, String)>,
    /// Lines up to this number belong to earlier commands; `None` until known.
    after: Option<u64>,
    deadline: Instant,
    last_deadline: Instant,
    quiet: Duration,
}

impl TerminalReply {
    /// Collecting from now, subscribed after line `seen`.
    fn new(config: &LinkConfig, seen: u64) -> Self {
        let deadline = Instant::now() + config.terminal_timeout;
        TerminalReply {
            seen,
            lines: Vec::new(),
            after: None,
            deadline,
            // However often the car keeps printing, the reply ends here.
            last_deadline: deadline + config.terminal_timeout,
            quiet: config.terminal_quiet,
        }
    }

    fn line(&mut self, text: String, relevant: impl Fn(&str) -> bool) {
        self.seen += 1;
        if relevant(&text) {
            self.lines.push((self.seen, text));
            self.quieten();
        }
    }

    fn lagged(&mut self, skipped: u64) {
        self.seen += skipped;
    }

    /// The earlier commands' replies end at line `after`.
    fn after(&mut self, after: u64) {
        self.after = Some(after);
        self.quieten();
    }

    /// Once a line is taken, the reply ends when no further one comes within the quiet time.
    fn quieten(&mut self) {
        if self.after.is_some() && self.lines.iter().any(|(n, _)| Some(*n) > self.after) {
            self.deadline = (Instant::now() + self.quiet).min(self.last_deadline);
        }
    }

    /// The lines taken (those after the earlier commands' replies).
    fn taken(&self) -> Vec<String> {
        let after = self.after.unwrap_or(u64::MAX);
        self.lines
            .iter()
            .filter(|(n, _)| *n > after)
            .map(|(_, text)| text.clone())
            .collect()
    }

    fn complete(&self, done: impl Fn(&[String]) -> bool) -> bool {
        self.after.is_some() && done(&self.taken())
    }

    /// The number of the last line taken, else where the earlier commands' replies end: where the next
    /// command's reply starts.
    fn last_taken(&self) -> u64 {
        let after = self.after.unwrap_or(self.seen);
        self.lines
            .iter()
            .map(|(n, _)| *n)
            .filter(|&n| n > after)
            .max()
            .unwrap_or(after)
    }
}

impl Shared {
    pub(super) fn new(config: LinkConfig) -> Shared {
        Shared {
            identity: Mutex::new(Identity {
                car_id: config.car_id,
                version: FirmwareVersion::LATEST,
            }),
            keepalive_on: AtomicBool::new(config.keepalive.is_some()),
            outgoing: Mutex::new(None),
            waiters: Mutex::new(HashMap::new()),
            garbled: Mutex::new(HashMap::new()),
            state_waiters: Mutex::new(VecDeque::new()),
            lanes: Mutex::new(HashMap::new()),
            ordered_lanes: Mutex::new(HashMap::new()),
            printf: broadcast::channel(256).0,
            printf_sent: Mutex::new(0),
            events: broadcast::channel(64).0,
            health: Mutex::new(HealthRecorder::default()),
            last_feed: Mutex::new(None),
            losses: AtomicU64::new(0),
            route: Mutex::new(RouteMemory::default()),
            uploads: tokio::sync::Mutex::new(()),
            latest: watch::channel(None).0,
            request_timeout_ns: AtomicU64::new(duration_ns(config.request_timeout)),
            tries: AtomicU32::new(config.tries),
            fault_adds: Mutex::new(FaultAdds::default()),
            config,
        }
    }

    /// The per-try timeout of requests in force (see [`Car::set_request_timeout`](super::Car::set_request_timeout)).
    pub(super) fn request_timeout(&self) -> Duration {
        Duration::from_nanos(self.request_timeout_ns.load(Ordering::Relaxed))
    }

    /// The tries of an acked request in force.
    pub(super) fn tries(&self) -> u32 {
        self.tries.load(Ordering::Relaxed)
    }

    /// Sets the tries of acked requests from now on.
    pub(super) fn set_tries(&self, tries: u32) {
        self.tries.store(tries.max(1), Ordering::Relaxed);
    }

    /// Sets the per-try timeout of requests from now on.
    pub(super) fn set_request_timeout(&self, per_try: Duration) {
        self.request_timeout_ns
            .store(duration_ns(per_try), Ordering::Relaxed);
    }

    pub(super) fn identity(&self) -> Identity {
        *lock(&self.identity)
    }

    fn lane(&self, code: u8) -> Arc<tokio::sync::Mutex<()>> {
        lock(&self.lanes).entry(code).or_default().clone()
    }

    pub(super) fn link_up(&self, sender: mpsc::Sender<Bytes>) {
        *lock(&self.outgoing) = Some(sender);
        lock(&self.health).figures.link_up = true;
    }

    fn link_down(&self, reason: String) {
        *lock(&self.outgoing) = None;
        self.losses.fetch_add(1, Ordering::SeqCst);
        // Dropping the senders wakes every waiting request with LinkLost.
        lock(&self.waiters).clear();
        lock(&self.state_waiters).clear();
        lock(&self.health).figures.link_up = false;
        tracing::warn!(%reason, "link to the car lost");
        let _ = self.events.send(LinkEvent::Lost { reason });
    }

    fn dispatch(&self, payload: &Bytes) {
        let identity = self.identity();
        let (car, reply) = match Reply::decode(payload, identity.version) {
            Ok(decoded) => decoded,
            Err(error) => {
                tracing::debug!(%error, "undecodable payload from the car");
                lock(&self.health).figures.undecodable += 1;
                self.dispatch_undecodable(payload, error, identity.version);
                return;
            }
        };
        let ours = identity.car_id == ID_ALL || car == identity.car_id;
        if !ours && !matches!(reply, Reply::Printf(_)) {
            // PRINTF carries the car's own id even to a link of id 254: only the others name a car.
            let mut health = lock(&self.health);
            health.figures.other_car_replies += 1;
            health.figures.last_other_car = Some(OtherCar {
                car,
                expected: identity.car_id,
            });
        }
        if let Reply::Printf(text) = reply {
            if ours {
                let mut sent = lock(&self.printf_sent);
                let _ = self.printf.send(text);
                *sent += 1;
            }
            return;
        }
        // A decoded payload has its [id][cmd] header.
        let Some(&code) = payload.get(1) else {
            return;
        };
        let answer = Answer {
            car,
            reply,
            received_at: Instant::now(),
        };
        if Some(code) == CommandId::GetState.code(identity.version) {
            if !self.dispatch_state(answer) {
                tracing::debug!(car, "stray state reply ignored");
                lock(&self.health).figures.stray_replies += 1;
            }
            return;
        }
        let delivered = self
            .take_waiter(car, code)
            .is_some_and(|tx| tx.send(answer).is_ok());
        if !delivered {
            tracing::debug!(car, code, "stray reply ignored");
            lock(&self.health).figures.stray_replies += 1;
        }
    }

    /// The request waiting for a reply of car `car` to command `code`: one sent to that car, else a broadcast.
    fn take_waiter(&self, car: u8, code: u8) -> Option<oneshot::Sender<Answer>> {
        let mut waiters = lock(&self.waiters);
        let key = waiting_key(&waiters, car, code)?;
        waiters.remove(&key)
    }

    /// Notes why a payload with an `[id][cmd]` header did not decode, for the request waiting for that
    /// (car, command): it reports it ([`CarError::UndecodableReply`]) if no reply that decodes comes. The
    /// request keeps waiting (a link may echo requests, and the real reply may follow at once).
    ///
    /// GET_STATE is left out: its replies answer the oldest request first in first out, with nothing to tell
    /// a garbled reply from an echoed GET_STATE request (which does not decode either), so such a payload is
    /// only counted, and the request it may have answered expires as lost.
    fn dispatch_undecodable(&self, payload: &[u8], error: DecodeError, version: FirmwareVersion) {
        // An RTCM3 stream is no reply: its first byte, 0xD3, is no car id.
        if matches!(error, DecodeError::Rtcm) {
            return;
        }
        let [car, code, ..] = *payload else {
            return;
        };
        if Some(code) == CommandId::GetState.code(version) {
            return;
        }
        let key = waiting_key(&lock(&self.waiters), car, code);
        if let Some(key) = key {
            lock(&self.garbled).insert(key, error);
        }
    }

    /// Hands a GET_STATE reply to the oldest GET_STATE request of that car still waiting; `false` if there is
    /// none (a stray: a duplicate, another car's, or the late reply of a request already counted as lost).
    ///
    /// Requests past their deadline, and those nobody waits for any more, are forgotten first. Since requests
    /// are identical, a lost request or reply cannot be told from a slow one: until the lost request's deadline,
    /// later replies are each paired with the request before their own, so their round trip reads one period
    /// long (never more than the deadline allows: the error is bounded by the timeout, and always on the long
    /// side, the safe side for lead times). A reply later than its deadline shifts the pairing the other way
    /// until a loss or a quiet moment realigns it. The receive time of every sample is exact either way.
    fn dispatch_state(&self, answer: Answer) -> bool {
        let now = answer.received_at;
        let mut queue = lock(&self.state_waiters);
        queue.retain(|w| !w.tx.is_closed() && w.deadline > now);
        let Some(index) = queue
            .iter()
            .position(|w| w.car.is_none_or(|car| car == answer.car))
        else {
            return false;
        };
        queue
            .remove(index)
            .is_some_and(|waiter| waiter.tx.send(answer).is_ok())
    }

    /// Sends one GET_STATE request that counts as lost after `timeout`; the reply is taken with
    /// [`StateTicket::outcome`]. Never waits for a reply, so that several can be in flight.
    pub(super) async fn send_state_request(
        &self,
        timeout: Duration,
    ) -> Result<StateTicket, CarError> {
        let (payload, identity, command) = self.encode(&Request::GetState)?;
        let (tx, rx) = oneshot::channel();
        // Registered before sending, so that even an instant reply finds it.
        let deadline = Instant::now() + timeout;
        {
            let mut queue = lock(&self.state_waiters);
            // Requests nobody waits for any more go now, so that a silent car does not grow the queue.
            queue.retain(|w| !w.tx.is_closed());
            queue.push_back(StateWaiter {
                car: (identity.car_id != ID_ALL).then_some(identity.car_id),
                deadline,
                tx,
            });
        }
        let sent_at = self.send(payload, command).await?;
        // The same deadline as the waiter's: past it the dispatcher forgets the waiter, and the ticket must
        // then read "expired", not "link lost".
        Ok(StateTicket {
            sent_at,
            deadline,
            rx,
        })
    }

    /// Counts a try that got no reply in time and reports it as an event.
    pub(super) fn note_timeout(&self, command: CommandId) {
        lock(&self.health).figures.timeouts += 1;
        let _ = self.events.send(LinkEvent::Timeout { command });
    }

    /// Turns the answer to a GET_STATE request sent at `requested_at` into a sample: records the round trip,
    /// follows the reported firmware version and publishes the sample as the latest.
    pub(super) fn accept_state(
        &self,
        answer: Answer,
        requested_at: Instant,
    ) -> Result<StateSample, CarError> {
        lock(&self.health).record_rtt(answer.received_at.saturating_duration_since(requested_at));
        let Reply::State(state) = answer.reply else {
            let reply = format!("{:?}", answer.reply);
            return Err(CarError::UnexpectedReply {
                command: CommandId::GetState,
                reply,
            });
        };
        let sample = StateSample {
            state,
            car_id: answer.car,
            requested_at,
            received_at: answer.received_at,
        };
        self.follow_version(state.version);
        self.latest.send_replace(Some(sample));
        Ok(sample)
    }

    /// Sends a payload; notes the watchdog feed. Waits at most `request_timeout` for room in the send queue
    /// (full only when the link stopped taking bytes).
    async fn send(&self, payload: Bytes, command: Option<CommandId>) -> Result<Instant, CarError> {
        let sender = lock(&self.outgoing).clone().ok_or(CarError::LinkLost)?;
        let waited = self.config.request_timeout;
        match tokio::time::timeout(waited, sender.send(payload)).await {
            Ok(Ok(())) => {}
            Ok(Err(_)) => return Err(CarError::LinkLost),
            Err(_) => return Err(CarError::SendStalled { waited }),
        }
        let now = Instant::now();
        if command.is_some_and(CommandId::resets_watchdog) {
            *lock(&self.last_feed) = Some(now);
        }
        Ok(now)
    }

    fn encode(&self, request: &Request) -> Result<(Bytes, Identity, Option<CommandId>), CarError> {
        let identity = self.identity();
        let payload = request.encode(identity.car_id, Dialect::host(identity.version))?;
        Ok((payload, identity, request.command(identity.version)))
    }

    /// Sends a request without waiting for anything.
    pub(super) async fn fire(&self, request: &Request) -> Result<(), CarError> {
        let (payload, _, command) = self.encode(request)?;
        self.send(payload, command).await.map(|_| ())
    }

    /// Sends `request` and waits for the reply with the same (car, command), retrying on timeouts; returns
    /// the answer, when the answered try was sent, and how many tries were sent. A payload with that header
    /// that does not decode does not end a try (a link may echo requests), but when every try fails the
    /// error is [`CarError::UndecodableReply`] with the last such payload's cause rather than
    /// [`CarError::NoReply`]. Not for GET_STATE, whose replies go to the first-in-first-out queue: use
    /// [`Shared::state`].
    ///
    /// After a retry the answer may be the late reply to an earlier try of the same request, and the reply
    /// to the answered try may still come: a caller sending several requests of one command in a row (a
    /// route upload) must check the outcome another way (see `Car::add_points`).
    pub(super) async fn exchange(
        &self,
        request: &Request,
        per_try: Duration,
        tries: u32,
    ) -> Result<(Answer, Instant, u32), CarError> {
        let (payload, identity, command) = self.encode(request)?;
        let command = command.unwrap_or(CommandId::GetState);
        let code = payload[1];
        let lane = self.lane(code);
        let _one_at_a_time = lane.lock().await;
        let key = ((identity.car_id != ID_ALL).then_some(identity.car_id), code);
        lock(&self.garbled).remove(&key);
        for sent in 1..=tries.max(1) {
            let (tx, rx) = oneshot::channel();
            lock(&self.waiters).insert(key, tx);
            let _waiter = WaiterGuard { shared: self, key };
            let sent_at = self.send(payload.clone(), Some(command)).await?;
            match tokio::time::timeout(per_try, rx).await {
                Ok(Ok(answer)) => {
                    lock(&self.health)
                        .record_rtt(answer.received_at.saturating_duration_since(sent_at));
                    return Ok((answer, sent_at, sent));
                }
                Ok(Err(_)) => return Err(CarError::LinkLost),
                Err(_) => self.note_timeout(command),
            }
        }
        // Payloads with this header that did not decode (garbled, or echoes of the request on a link that
        // echoes) did not end a try; the last one's cause explains the failure.
        Err(match lock(&self.garbled).remove(&key) {
            Some(source) => CarError::UndecodableReply { command, source },
            None => CarError::NoReply {
                command,
                tries: tries.max(1),
                per_try,
            },
        })
    }

    pub(super) async fn acked(&self, request: &Request, per_try: Duration) -> Result<(), CarError> {
        self.acked_after(request, per_try).await.map(|_tries| ())
    }

    /// [`Shared::acked`], returning how many tries were sent.
    pub(super) async fn acked_after(
        &self,
        request: &Request,
        per_try: Duration,
    ) -> Result<u32, CarError> {
        let (answer, _, tries) = self.exchange(request, per_try, self.tries()).await?;
        let command = request.command(self.identity().version);
        match answer.reply {
            Reply::Ack(acked) if Some(acked) == command => Ok(tries),
            other => Err(CarError::UnexpectedReply {
                command: command.unwrap_or(CommandId::GetState),
                reply: format!("{other:?}"),
            }),
        }
    }

    /// Reads the state with up to `tries` GET_STATE requests of `request_timeout` each, one after another.
    ///
    /// Single reads (this one, the keepalive's) wait for each other, as every other command does, so that
    /// without a state stream running only one GET_STATE is in flight and its round trip is unambiguous (what
    /// a round-trip measurement needs); a stream's requests do not wait for them.
    pub(super) async fn state(&self, tries: u32) -> Result<StateSample, CarError> {
        self.state_with(tries, self.request_timeout()).await
    }

    /// [`Shared::state`] with its own per-try timeout.
    pub(super) async fn state_with(
        &self,
        tries: u32,
        per_try: Duration,
    ) -> Result<StateSample, CarError> {
        let lane = self.lane(
            CommandId::GetState
                .code(self.identity().version)
                .unwrap_or(120),
        );
        let _one_read_at_a_time = lane.lock().await;
        for _ in 0..tries.max(1) {
            let mut ticket = self.send_state_request(per_try).await?;
            match ticket.outcome().await {
                StateOutcome::Answered(answer) => {
                    return self.accept_state(*answer, ticket.sent_at);
                }
                StateOutcome::LinkLost => return Err(CarError::LinkLost),
                StateOutcome::Expired => self.note_timeout(CommandId::GetState),
            }
        }
        Err(CarError::NoReply {
            command: CommandId::GetState,
            tries: tries.max(1),
            per_try,
        })
    }

    /// Layouts and ids follow the version the car reports, also if it changes (a reflashed car behind the
    /// same bridge after a reconnection).
    fn follow_version(&self, reported: FirmwareVersion) {
        let mut identity = lock(&self.identity);
        if identity.version != reported {
            tracing::warn!(from = %identity.version, to = %reported, "the car reports another firmware version");
            identity.version = reported;
        }
    }

    /// Sends a terminal command and collects the PRINTF lines that `relevant` accepts, until `done` says the
    /// reply is complete, or the first line does not come within `terminal_timeout`, or no further line comes
    /// within `terminal_quiet`. One command per command code at a time.
    pub(super) async fn terminal_lines(
        &self,
        command: &str,
        relevant: impl Fn(&str) -> bool,
        done: impl Fn(&[String]) -> bool,
    ) -> Result<Vec<String>, CarError> {
        let request = Request::TerminalCmd(command.to_string());
        let (payload, _, cmd) = self.encode(&request)?;
        let lane = self.lane(payload[1]);
        let _one_at_a_time = lane.lock().await;
        let (printf, seen) = self.subscribe_printf();
        let losses = self.losses.load(Ordering::SeqCst);
        self.send(payload, cmd).await?;
        let reply = self.collect(printf, seen, None, relevant, done).await;
        self.reply_lines(&reply, losses)
    }

    /// [`Shared::terminal_lines`] in the ordered lane `lane`: a command is sent without waiting for the
    /// replies of the lane's earlier commands, and its reply is the lines `relevant` accepts after those its
    /// predecessor in the lane took. The car answers terminal commands in the order they arrive, so on a
    /// link that keeps order the replies of one lane come in the order of its commands. `relevant` must
    /// accept no line of other lanes' replies (fault commands name their probe).
    pub(super) async fn terminal_lines_ordered(
        &self,
        lane: &str,
        command: &str,
        relevant: impl Fn(&str) -> bool,
        done: impl Fn(&[String]) -> bool,
    ) -> Result<Vec<String>, CarError> {
        let request = Request::TerminalCmd(command.to_string());
        let (payload, _, cmd) = self.encode(&request)?;
        let lane = lock(&self.ordered_lanes)
            .entry(lane.to_owned())
            .or_default()
            .clone();
        let mut tail = lane.tail.lock().await;
        let (printf, seen) = self.subscribe_printf();
        let losses = self.losses.load(Ordering::SeqCst);
        self.send(payload, cmd).await?;
        // The next command of the lane waits for what this one takes.
        let (took, next) = oneshot::channel();
        let predecessor = tail.replace(next);
        drop(tail);
        let reply = self
            .collect(printf, seen, predecessor, relevant, done)
            .await;
        let _ = took.send(reply.last_taken());
        self.reply_lines(&reply, losses)
    }

    /// Collects a terminal command's reply from `printf` (subscribed after line `seen`): the lines `relevant`
    /// accepts after those the command's `predecessor` in its lane took (with none, every such line), until
    /// `done` says it is complete or its deadline passes.
    async fn collect(
        &self,
        mut printf: broadcast::Receiver<String>,
        seen: u64,
        mut predecessor: Option<oneshot::Receiver<u64>>,
        relevant: impl Fn(&str) -> bool,
        done: impl Fn(&[String]) -> bool,
    ) -> TerminalReply {
        let mut reply = TerminalReply::new(&self.config, seen);
        if predecessor.is_none() {
            reply.after(seen);
        }
        while !reply.complete(&done) {
            tokio::select! {
                after = async { predecessor.as_mut().expect("polled only while waiting").await },
                    if predecessor.is_some() =>
                {
                    // A predecessor that was cancelled took nothing it says.
                    reply.after(after.unwrap_or(seen));
                    predecessor = None;
                }
                line = tokio::time::timeout_at(reply.deadline, printf.recv()) => match line {
                    Ok(Ok(text)) => reply.line(text, &relevant),
                    Ok(Err(broadcast::error::RecvError::Lagged(n))) => reply.lagged(n),
                    Ok(Err(broadcast::error::RecvError::Closed)) | Err(_) => {
                        // The predecessor was sent first: its own deadline ends the wait.
                        if let Some(earlier) = predecessor.take() {
                            reply.after(earlier.await.unwrap_or(seen));
                        }
                        break;
                    }
                },
            }
        }
        reply
    }

    /// The lines of `reply`, unless the link was lost since `losses` was read.
    fn reply_lines(&self, reply: &TerminalReply, losses: u64) -> Result<Vec<String>, CarError> {
        if self.losses.load(Ordering::SeqCst) != losses {
            return Err(CarError::LinkLost);
        }
        Ok(reply.taken())
    }

    /// A receiver of the PRINTF lines from now on, and the number of lines sent before it: its k-th line is
    /// line number `seen + k` (from 1).
    fn subscribe_printf(&self) -> (broadcast::Receiver<String>, u64) {
        let sent = lock(&self.printf_sent);
        (self.printf.subscribe(), *sent)
    }

    /// Checks the duplicate-first-point rule for every packet of an upload before anything is sent: no packet
    /// may start at the (x, y) where the packet before it (or, for the first, the last accepted one) started.
    pub(super) fn check_packet_starts(&self, points: &[RoutePoint]) -> Result<(), CarError> {
        let mut previous = lock(&self.route).last_first;
        for (n, packet) in points.chunks(POINTS_PER_PACKET).enumerate() {
            let first = (packet[0].px, packet[0].py);
            if let Some((x, y)) = previous
                && (x - first.0).abs() < DUPLICATE_POINT_THRESHOLD
                && (y - first.1).abs() < DUPLICATE_POINT_THRESHOLD
            {
                return Err(CarError::DuplicateFirstPoint {
                    index: n * POINTS_PER_PACKET,
                });
            }
            previous = Some(first);
        }
        Ok(())
    }

    pub(super) fn remember_first_point(&self, first: &RoutePoint) {
        lock(&self.route).last_first = Some((first.px, first.py));
    }
}

/// The key of the request waiting for a reply of car `car` to command `code`: one sent to that car,
/// else a broadcast.
fn waiting_key<V>(waiters: &HashMap<Key, V>, car: u8, code: u8) -> Option<Key> {
    [(Some(car), code), (None, code)]
        .into_iter()
        .find(|key| waiters.contains_key(key))
}

/// Reads the link until it closes; reconnects if an address is known. Ends when cancelled.
pub(super) async fn supervise(
    shared: Arc<Shared>,
    mut link: Link,
    address: Option<CarAddress>,
    cancel: CancellationToken,
) {
    // Made once, not at every payload: each would take a waiter slot and give it back.
    let cancelled = cancel.cancelled();
    tokio::pin!(cancelled);
    loop {
        shared.link_up(link.sender());
        let reason = loop {
            let incoming = tokio::select! {
                () = &mut cancelled => return,
                incoming = link.recv() => incoming,
            };
            match incoming {
                Some(Incoming::Payload(payload)) => {
                    lock(&shared.health).last_heard = Some(Instant::now());
                    shared.dispatch(&payload);
                }
                Some(Incoming::Dropped(error)) => {
                    tracing::debug!(%error, "frame dropped");
                    lock(&shared.health).figures.dropped_frames += 1;
                }
                Some(Incoming::Closed(reason)) => break reason,
                None => break "link closed".to_string(),
            }
        };
        shared.link_down(reason);
        drop(link);
        let Some(address) = address.as_ref() else {
            return;
        };
        link = match reconnect(&shared, address, &cancel).await {
            Some(link) => link,
            None => return,
        };
        lock(&shared.health).figures.reconnects += 1;
        let _ = shared.events.send(LinkEvent::Reconnected);
    }
}

/// Retries with exponential backoff (250 ms to 5 s); `None` when cancelled.
async fn reconnect(
    shared: &Shared,
    address: &CarAddress,
    cancel: &CancellationToken,
) -> Option<Link> {
    let mut delay = Duration::from_millis(250);
    loop {
        tokio::select! {
            _ = cancel.cancelled() => return None,
            _ = tokio::time::sleep(delay) => {}
        }
        match Link::open(address, shared.config.connect_timeout).await {
            Ok(link) => {
                // The bridge's parser state survives a reconnect: wait past its 500 ms byte timeout.
                tokio::select! {
                    _ = cancel.cancelled() => return None,
                    _ = tokio::time::sleep(PC_BYTE_TIMEOUT + Duration::from_millis(100)) => {}
                }
                return Some(link);
            }
            Err(error) => {
                tracing::debug!(%error, %address, "reconnection failed");
                delay = (delay * 2).min(Duration::from_secs(5));
            }
        }
    }
}

/// Sends GET_STATE whenever nothing has fed the watchdog for `period`. Ends when cancelled.
pub(super) async fn keep_alive(shared: Arc<Shared>, period: Duration, cancel: CancellationToken) {
    loop {
        let last = *lock(&shared.last_feed);
        let due = last.map_or_else(Instant::now, |t| t + period);
        tokio::select! {
            _ = cancel.cancelled() => return,
            _ = tokio::time::sleep_until(due) => {}
        }
        let fed_recently = lock(&shared.last_feed).is_some_and(|t| t.elapsed() < period);
        if fed_recently {
            continue;
        }
        if !shared.keepalive_on.load(Ordering::SeqCst) {
            tokio::select! {
                _ = cancel.cancelled() => return,
                _ = tokio::time::sleep(period) => {}
            }
            continue;
        }
        // A failure is already counted in the health figures and reported as an event.
        if let Err(error) = shared.state(1).await {
            tracing::debug!(%error, "keepalive GET_STATE failed");
            if matches!(error, CarError::LinkLost) {
                tokio::select! {
                    _ = cancel.cancelled() => return,
                    _ = tokio::time::sleep(period) => {}
                }
            }
        }
    }
}

/// A duration in nanoseconds, saturating (about 584 years).
fn duration_ns(duration: Duration) -> u64 {
    u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX)
}
