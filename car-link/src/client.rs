//! The async client: a [`Car`] handle over any [`Link`].
//!
//! On start it performs the version handshake (GET_STATE, then every layout and id from the reported firmware
//! version), starts a dispatcher that matches replies to requests by (car id, command) — GET_STATE, which may have
//! several requests in flight, first in first out — and a keepalive that feeds the car's 2 s communication
//! watchdog. Every timer is tokio's, so the client runs in virtual time too. A reply with the (car id, command)
//! of a waiting request whose payload does not decode is kept as that request's cause of failure: if no reply
//! that decodes comes within its tries, it fails with [`CarError::UndecodableReply`] rather than
//! [`CarError::NoReply`] (GET_STATE excepted: such a reply is only counted in [`LinkHealth::undecodable`]).
//!
//! Invariant: a lost link is an error ([`CarError::LinkLost`], [`LinkEvent::Lost`]), never a zero state.

mod session;

use std::collections::VecDeque;
use std::io;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use futures::Stream;
use thiserror::Error;
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::sync::broadcast;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use crate::address::CarAddress;
use crate::config::{ConfigError, ConfigField, MainConfig};
use crate::fault::{self, FaultError, FaultKind, MAX_PROBE_ID, Probe};
use crate::firmware::FirmwareVersion;
use crate::health::LinkHealth;
use crate::message::{
    Anchor, CarState, DecodeError, EncodeError, EnuRef, ID_ALL, ID_CAR_CLIENT, MAX_ROUTE_PART,
    POINTS_PER_PACKET, Pose, RcControl, RcMode, Reply, Request, RoutePart, RoutePoint, SyncPoint,
};
use crate::transport::{Link, PC_BYTE_TIMEOUT};
use crate::version::CommandId;
use session::{RouteMemory, Shared, StateOutcome, StateTicket, keep_alive, lock, supervise};

/// One `fi_add_fault` in flight, counted in [`Shared::fault_adds`] until it is dropped (also when
/// the command is cancelled).
struct FaultAdding<'a> {
    shared: &'a Shared,
    /// The count of commands started when this one started, if no other was in flight then.
    alone_from: Option<u64>,
}

impl<'a> FaultAdding<'a> {
    fn start(shared: &'a Shared) -> Self {
        let mut adds = lock(&shared.fault_adds);
        adds.in_flight += 1;
        adds.started += 1;
        let alone_from = (adds.in_flight == 1).then_some(adds.started);
        drop(adds);
        Self { shared, alone_from }
    }

    /// Whether no other `fi_add_fault` was in flight from this one's start until now: then no
    /// other fault command's reply was due meanwhile.
    fn ran_alone(&self) -> bool {
        let adds = lock(&self.shared.fault_adds);
        self.alone_from == Some(adds.started) && adds.in_flight == 1
    }
}

impl Drop for FaultAdding<'_> {
    fn drop(&mut self) {
        lock(&self.shared.fault_adds).in_flight -= 1;
    }
}

/// How closely a point read back from the car must match the point sent, metres: far above the
/// float32_auto rounding of the wire (under 0.1 mm at a kilometre), far below any real difference.
const STORED_POINT_TOLERANCE_M: f64 = 1e-3;

/// Two route packets whose first points are closer than this (in x and y) count as one for the firmware.
pub const DUPLICATE_POINT_THRESHOLD: f64 = 1e-4;
use crate::firmware::WATCHDOG;

/// How a [`Car`] talks to the car. Built with [`LinkConfig::default`] and changed field by field.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkConfig {
    /// The id requests are sent to before the handshake; 255 (broadcast) learns the car's own id from its reply.
    pub car_id: u8,
    /// Time allowed for each try of a request (MAVLink mission style: about 250 ms per item). It also bounds
    /// the wait for room in the send queue, which is full only when the link stopped taking bytes: such a
    /// call ends with [`CarError::SendStalled`] after at most this long on top of its documented timeout.
    pub request_timeout: Duration,
    /// Tries of an acked request before giving up (5).
    pub tries: u32,
    /// Time allowed for each try of SET_MAIN_CONFIG, which acks after a flash write (500 ms).
    pub main_config_timeout: Duration,
    /// How long a terminal command waits for its first PRINTF line (1 s).
    pub terminal_timeout: Duration,
    /// After a PRINTF line, how long without another one ends the reply (100 ms); a reply ends at twice
    /// `terminal_timeout` however long it is.
    pub terminal_quiet: Duration,
    /// The keepalive sends GET_STATE whenever nothing that feeds the watchdog was sent for this long (250 ms;
    /// the protocol asks for at least every 500 ms; longer periods are refused). `None` disables the keepalive
    /// task.
    pub keepalive: Option<Duration>,
    /// TCP connection timeout (2 s).
    pub connect_timeout: Duration,
    /// Reconnect after a lost link, when the link came from an address (not from a stream).
    pub reconnect: bool,
    /// Abandon a partly received frame after this long without a byte (500 ms, as the reference tools).
    pub byte_timeout: Duration,
}

impl Default for LinkConfig {
    fn default() -> Self {
        LinkConfig {
            car_id: ID_ALL,
            request_timeout: Duration::from_millis(250),
            tries: 5,
            main_config_timeout: Duration::from_millis(500),
            terminal_timeout: Duration::from_secs(1),
            terminal_quiet: Duration::from_millis(100),
            keepalive: Some(Duration::from_millis(250)),
            connect_timeout: Duration::from_secs(2),
            reconnect: true,
            byte_timeout: PC_BYTE_TIMEOUT,
        }
    }
}

/// Something that happened to the link.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkEvent {
    /// The link went down; requests fail with [`CarError::LinkLost`] until it is back.
    Lost {
        /// Why.
        reason: String,
    },
    /// The link is back after a reconnection.
    Reconnected,
    /// A try of a request got no reply in time.
    Timeout {
        /// The request's command.
        command: CommandId,
    },
}

/// What can go wrong talking to the car.
#[derive(Debug, Error)]
pub enum CarError {
    /// The link could not be opened.
    #[error("cannot open {address}")]
    Connect {
        /// The address.
        address: String,
        /// The cause.
        source: io::Error,
    },
    /// The link is down (or went down while waiting).
    #[error("the link to the car is lost")]
    LinkLost,
    /// Every try timed out.
    #[error("no reply to {command:?} after {tries} tries of {per_try:?}")]
    NoReply {
        /// The command.
        command: CommandId,
        /// Tries made.
        tries: u32,
        /// Time allowed per try.
        per_try: Duration,
    },
    /// A reply with the right (car, command) but the wrong content.
    #[error("unexpected reply to {command:?}: {reply}")]
    UnexpectedReply {
        /// The command.
        command: CommandId,
        /// The reply, as debug text.
        reply: String,
    },
    /// Every try of a request ended without a reply that decodes, but a payload with the right (car, command)
    /// came that does not (another record layout, a truncated or garbled body): the last one's cause.
    #[error("no reply that decodes to {command:?}: {source}")]
    UndecodableReply {
        /// The command.
        command: CommandId,
        /// Why the payload does not decode.
        source: DecodeError,
    },
    /// The request cannot be encoded for this firmware.
    #[error(transparent)]
    Encode(#[from] EncodeError),
    /// The version handshake failed.
    #[error("version handshake failed: {0}")]
    Handshake(Box<CarError>),
    /// No reply from the link's car, but replies from another car id came: another car on the
    /// link, or a bridge or proxy that changes the id.
    #[error(
        "no reply to {command:?} from the car, but {other} (another car on the link, or a bridge \
         that changes the id)"
    )]
    OtherCar {
        /// The command.
        command: CommandId,
        /// The last reply from another car id.
        other: crate::health::OtherCar,
    },
    /// A packet would start at the same (x, y) as the previous packet, and the firmware would silently drop it.
    #[error(
        "route point {index} would start a packet at the same (x, y) as the previous packet: the car drops it"
    )]
    DuplicateFirstPoint {
        /// Index of the point in the list passed in.
        index: usize,
    },
    /// A fault-injection command failed.
    #[error(transparent)]
    Fault(#[from] FaultError),
    /// A main-configuration record problem.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// An argument the car would not answer or would misread.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// Read back after an upload with retries, the car's route does not end with the points sent: a late
    /// ack was taken for the answer to a later packet, which the car never got.
    #[error(
        "the car did not store route point {index} as sent: ({sent_x:.3}, {sent_y:.3}) sent, \
         ({stored_x:.3}, {stored_y:.3}) stored"
    )]
    RouteNotStored {
        /// Index of the point in the list passed in (of the last upload).
        index: usize,
        /// The point sent, m.
        sent_x: f64,
        /// The point sent, m.
        sent_y: f64,
        /// What the car holds in its place, m.
        stored_x: f64,
        /// What the car holds in its place, m.
        stored_y: f64,
    },
    /// The link's send queue stayed full: the transport stopped taking bytes (a stalled connection).
    #[error("the link took no bytes for {waited:?}: the send queue is full")]
    SendStalled {
        /// How long the request waited for room.
        waited: Duration,
    },
    /// Read back after an upload with retries, the car holds another number of route points than were sent
    /// since the route was last emptied: a packet was lost although an ack seemed to answer it.
    #[error("the car holds {held} route points, but {sent} were sent since the route was emptied")]
    RouteLength {
        /// Points the car reports (its route length).
        held: usize,
        /// Points sent since the route was emptied.
        sent: usize,
    },
}

/// One GET_STATE answer, stamped with host monotonic time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateSample {
    /// The state.
    pub state: CarState,
    /// The car id that answered.
    pub car_id: u8,
    /// When the request was sent (tokio clock). With several GET_STATE requests in flight, the request this
    /// reply was paired with: the oldest one waiting (see [`Car::poll_states`]).
    pub requested_at: Instant,
    /// When the reply arrived (tokio clock).
    pub received_at: Instant,
}

impl StateSample {
    /// The round trip of this sample.
    pub fn rtt(&self) -> Duration {
        self.received_at
            .saturating_duration_since(self.requested_at)
    }

    /// The car's clock: ms since UTC midnight, −1 until known.
    pub fn ms_today(&self) -> i32 {
        self.state.ms_today
    }
}

/// The shortest polling period [`Car::poll_states`] uses (a shorter one is raised to it).
pub const MIN_STATE_PERIOD: Duration = Duration::from_millis(1);
/// The most GET_STATE requests [`StatePolling::new`] lets be in flight (the link queues 64 payloads).
pub const MAX_STATES_IN_FLIGHT: usize = 32;

/// How [`Car::poll_states`] polls GET_STATE.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StatePolling {
    /// Time between requests (at least [`MIN_STATE_PERIOD`]).
    pub period: Duration,
    /// How long a request waits for its reply before it counts as lost.
    pub timeout: Duration,
    /// Requests in flight at most (at least 1); at the cap the next request waits until the oldest is answered
    /// or lost.
    pub max_in_flight: usize,
}

impl StatePolling {
    /// A request every `period`, each lost after `timeout`, with as many in flight as the timeout needs:
    /// `ceil(timeout / period)`, between 1 and [`MAX_STATES_IN_FLIGHT`]. So a sample comes every `period` on
    /// any link whose round trip stays below `timeout`.
    pub fn new(period: Duration, timeout: Duration) -> Self {
        let period = period.max(MIN_STATE_PERIOD);
        let needed = timeout.as_nanos().div_ceil(period.as_nanos());
        let max_in_flight = usize::try_from(needed)
            .unwrap_or(usize::MAX)
            .clamp(1, MAX_STATES_IN_FLIGHT);
        StatePolling {
            period,
            timeout,
            max_in_flight,
        }
    }
}

/// The state behind [`Car::poll_states`]: the ticker and the requests in flight, oldest first.
struct StatePoller {
    car: Car,
    polling: StatePolling,
    ticker: tokio::time::Interval,
    in_flight: VecDeque<StateTicket>,
}

/// What woke the poller.
enum PollStep {
    /// Time to send the next request.
    Tick,
    /// The oldest request in flight ended.
    Oldest(StateOutcome),
}

impl StatePoller {
    /// The next item: sends requests on every tick meanwhile.
    async fn next(&mut self) -> Result<StateSample, CarError> {
        loop {
            let room = self.in_flight.len() < self.polling.max_in_flight.max(1);
            let oldest = self.in_flight.front_mut();
            let step = tokio::select! {
                biased;
                _ = self.ticker.tick(), if room => PollStep::Tick,
                outcome = async {
                    match oldest {
                        Some(ticket) => ticket.outcome().await,
                        None => std::future::pending().await,
                    }
                } => PollStep::Oldest(outcome),
            };
            let shared = self.car.shared();
            match step {
                PollStep::Tick => {
                    let ticket = shared.send_state_request(self.polling.timeout).await?;
                    self.in_flight.push_back(ticket);
                }
                PollStep::Oldest(outcome) => {
                    let Some(ticket) = self.in_flight.pop_front() else {
                        continue;
                    };
                    return match outcome {
                        StateOutcome::Answered(answer) => {
                            shared.accept_state(*answer, ticket.sent_at)
                        }
                        StateOutcome::Expired => {
                            shared.note_timeout(CommandId::GetState);
                            Err(CarError::NoReply {
                                command: CommandId::GetState,
                                tries: 1,
                                per_try: self.polling.timeout,
                            })
                        }
                        StateOutcome::LinkLost => {
                            // Every request in flight went down with the link: one error for all of them.
                            self.in_flight.clear();
                            Err(CarError::LinkLost)
                        }
                    };
                }
            }
        }
    }
}

/// A handle to one car. Cheap to clone; the background tasks (dispatcher, keepalive, reconnection) stop when the
/// last clone is dropped, and the car's watchdog then brakes it within 2 s.
#[derive(Debug, Clone)]
pub struct Car {
    inner: Arc<Inner>,
}

#[derive(Debug)]
struct Inner {
    shared: Arc<Shared>,
    cancel: CancellationToken,
}

impl Drop for Inner {
    fn drop(&mut self) {
        self.cancel.cancel();
    }
}

impl Car {
    /// Opens the link an address names and performs the version handshake.
    ///
    /// Timeout: the connection attempt is bounded by `connect_timeout`, the handshake by `tries` ×
    /// `request_timeout`. Cancellation: dropping the future closes the link; nothing keeps running.
    /// `sim` is refused here: the orchestrator passes the simulator's pipe to [`Car::over_stream`].
    pub async fn connect(address: &CarAddress, config: LinkConfig) -> Result<Car, CarError> {
        let bridged = matches!(address, CarAddress::Tcp { .. } | CarAddress::Udp { .. });
        if bridged && config.car_id == ID_CAR_CLIENT {
            return Err(CarError::InvalidArgument(
                "car id 254: the bridge never forwards the car's replies to it".into(),
            ));
        }
        let link = Link::open(address, config.connect_timeout)
            .await
            .map_err(|source| CarError::Connect {
                address: address.to_string(),
                source,
            })?;
        let reconnect_to = config.reconnect.then(|| address.clone());
        Car::start(link, reconnect_to, config).await
    }

    /// A car behind any framed byte stream (the host end of [`crate::transport::sim_pipe`], a TCP stream, a
    /// serial port). No reconnection: when the stream ends, the link is lost for good.
    ///
    /// Timeout: the handshake is bounded by `tries` × `request_timeout`. Cancellation: dropping the future
    /// closes the stream.
    pub async fn over_stream<S>(stream: S, config: LinkConfig) -> Result<Car, CarError>
    where
        S: AsyncRead + AsyncWrite + Send + 'static,
    {
        let link = Link::over_stream(stream, config.byte_timeout);
        Car::start(link, None, config).await
    }

    /// A car behind an already open [`Link`]. No reconnection.
    ///
    /// Timeout and cancellation: as [`Car::over_stream`].
    pub async fn over_link(link: Link, config: LinkConfig) -> Result<Car, CarError> {
        Car::start(link, None, config).await
    }

    async fn start(
        link: Link,
        reconnect_to: Option<CarAddress>,
        config: LinkConfig,
    ) -> Result<Car, CarError> {
        if config.keepalive.is_some_and(|period| period > WATCHDOG / 4) {
            return Err(CarError::InvalidArgument(format!(
                "keepalive period {:?}: the car's watchdog needs GET_STATE at least every 500 ms",
                config.keepalive.unwrap_or_default()
            )));
        }
        let shared = Arc::new(Shared::new(config));
        let cancel = CancellationToken::new();
        let car = Car {
            inner: Arc::new(Inner {
                shared: shared.clone(),
                cancel: cancel.clone(),
            }),
        };
        shared.link_up(link.sender());
        tokio::spawn(supervise(
            shared.clone(),
            link,
            reconnect_to,
            cancel.clone(),
        ));
        let sample = shared.state(shared.tries()).await.map_err(|e| {
            let other = lock(&shared.health).figures.last_other_car;
            CarError::Handshake(Box::new(match (e, other) {
                (CarError::NoReply { command, .. }, Some(other)) => {
                    CarError::OtherCar { command, other }
                }
                (e, _) => e,
            }))
        })?;
        // The version was taken from the reply by `state`; a broadcast handshake also learns the car's id.
        {
            let mut identity = lock(&shared.identity);
            if identity.car_id == ID_ALL {
                identity.car_id = sample.car_id;
            }
        }
        tracing::info!(version = %sample.state.version, car = shared.identity().car_id, "connected to the car");
        if let Some(period) = shared.config.keepalive {
            tokio::spawn(keep_alive(shared.clone(), period, cancel));
        }
        Ok(car)
    }

    fn shared(&self) -> &Shared {
        &self.inner.shared
    }

    /// The firmware version from the handshake.
    pub fn version(&self) -> FirmwareVersion {
        self.shared().identity().version
    }

    /// The car id requests go to (learned from the handshake when configured as 255).
    pub fn car_id(&self) -> u8 {
        self.shared().identity().car_id
    }

    /// The configuration the handle was made with (the per-try timeout in force is
    /// [`Car::request_timeout`]).
    pub fn config(&self) -> &LinkConfig {
        &self.shared().config
    }

    /// The per-try timeout of requests in force: `config().request_timeout` until
    /// [`Car::set_request_timeout`] changes it.
    pub fn request_timeout(&self) -> Duration {
        self.shared().request_timeout()
    }

    /// Sets the per-try timeout of every request sent from now on, by every clone of this handle: a
    /// client that has measured the link's round trip sets it to what the link needs (a try that gives
    /// up before its reply can arrive is answered by the late reply of an earlier one; a try that
    /// waits far longer than the round trip makes every loss cost that long).
    pub fn set_request_timeout(&self, per_try: Duration) {
        self.shared().set_request_timeout(per_try);
    }

    /// The tries of an acked request in force: `config().tries` until [`Car::set_tries`] changes it.
    pub fn tries(&self) -> u32 {
        self.shared().tries()
    }

    /// Sets how many times every acked request sent from now on is tried (at least once), by every
    /// clone of this handle: with a shorter per-try timeout, more tries keep the same time budget.
    pub fn set_tries(&self, tries: u32) {
        self.shared().set_tries(tries);
    }

    /// Link health: round trips (p50, p99), timeouts, reconnects, strays and drops.
    pub fn health(&self) -> LinkHealth {
        lock(&self.shared().health).snapshot()
    }

    /// Link events (lost, reconnected, timeouts) from now on.
    pub fn events(&self) -> broadcast::Receiver<LinkEvent> {
        self.shared().events.subscribe()
    }

    /// Every PRINTF line of this car from now on, including asynchronous debug prints.
    pub fn printf(&self) -> broadcast::Receiver<String> {
        self.shared().printf.subscribe()
    }

    /// The latest state received, by any caller or the keepalive; `None` before the first.
    pub fn latest_state(&self) -> Option<StateSample> {
        *self.shared().latest.borrow()
    }

    /// Switches the watchdog keepalive on (the default) or off. Off lets the car's watchdog stop the autopilot
    /// 2 s after the last command that feeds it.
    pub fn set_keepalive(&self, on: bool) {
        self.shared().keepalive_on.store(on, Ordering::SeqCst);
    }

    /// Reads the car state (GET_STATE).
    ///
    /// Timeout: one try of `request_timeout`, then [`CarError::NoReply`]. A lost link gives
    /// [`CarError::LinkLost`]; never a default state. Cancellation: safe; a late reply is discarded as stray,
    /// or answers another GET_STATE request still waiting (all are alike: see [`Car::poll_states`]).
    pub async fn state(&self) -> Result<StateSample, CarError> {
        self.shared().state(1).await
    }

    /// One GET_STATE that waits up to `per_try` for its reply, whatever the per-try timeout in force:
    /// to measure a link whose round trip may exceed it.
    ///
    /// Timeout: `per_try`, then [`CarError::NoReply`]. Cancellation: as [`Car::state`].
    pub async fn state_within(&self, per_try: Duration) -> Result<StateSample, CarError> {
        self.shared().state_with(1, per_try).await
    }

    /// A stream of states polled at `period`, pipelined: [`Car::poll_states`] with
    /// [`StatePolling::new`]`(period, request_timeout)`, so that on a link whose round trip is longer than
    /// `period` a sample still comes every `period`.
    ///
    /// Timeout, cancellation and pairing: as [`Car::poll_states`].
    pub fn state_stream(
        &self,
        period: Duration,
    ) -> impl Stream<Item = Result<StateSample, CarError>> + Send + 'static {
        self.poll_states(StatePolling::new(period, self.request_timeout()))
    }

    /// A stream of states: a GET_STATE request every `polling.period` without waiting for the replies (a late
    /// tick is delayed, not bunched up), with at most `polling.max_in_flight` unanswered at once. Items come
    /// in the order the requests were sent. Failures are items too (`Err`), so that a lost link is seen as such;
    /// the stream itself never ends. It holds a clone of the handle, which keeps the link and the keepalive
    /// alive while it exists.
    ///
    /// Pairing: GET_STATE replies carry no request id, so a reply answers the oldest GET_STATE request still
    /// waiting (the car answers in arrival order). A sample's `received_at` is exact; its `requested_at` is the
    /// send time of the request it was paired with, which after a lost request or reply may be up to the
    /// timeout too early (see the module `session`), so round trips may read long, never short, on a lossy
    /// link until the lost request's deadline.
    ///
    /// Timeout: a request without a reply within `polling.timeout` gives a [`CarError::NoReply`] item (and
    /// counts as a timeout in [`Car::health`]); a lost link gives [`CarError::LinkLost`] items. Cancellation:
    /// dropping the stream stops the polling; replies still in flight are then counted as stray.
    pub fn poll_states(
        &self,
        polling: StatePolling,
    ) -> impl Stream<Item = Result<StateSample, CarError>> + Send + 'static {
        let mut ticker = tokio::time::interval(polling.period.max(MIN_STATE_PERIOD));
        ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let poller = StatePoller {
            car: self.clone(),
            polling,
            ticker,
            in_flight: VecDeque::new(),
        };
        futures::stream::unfold(poller, |mut poller| async move {
            let item = poller.next().await;
            Some((item, poller))
        })
    }

    /// Appends route points: packets of 5, each acked, each tried up to `tries` times with `request_timeout`
    /// per try. A retried packet that the car had already stored is dropped by the car's duplicate rule and
    /// acked again, so retries never duplicate points. A packet whose first point has the same (x, y) as the
    /// previous packet's first point would be dropped silently by the car: such an upload is refused with
    /// [`CarError::DuplicateFirstPoint`] before anything is sent. Uploads from several tasks are serialised.
    ///
    /// Acks carry nothing but the command, so after a retry the ack taken may be the late one of an earlier
    /// try, and the real one may then be taken for the next packet's, which the car may never have got. An
    /// upload in which any packet needed more than one try is therefore read back (AP_GET_ROUTE_PART, 20
    /// points per request): the car's route must hold as many points as were sent since this client last
    /// emptied it ([`CarError::RouteLength`]), and end with the points sent ([`CarError::RouteNotStored`]).
    /// Without an emptied route to count from, or once the car's ring may have wrapped, only what can be
    /// read in one piece is compared (a skipped check is logged).
    ///
    /// Timeout: at most `tries` × `request_timeout` per packet, and as much again per 20 points read back.
    /// Cancellation: packets already acked stay on the car; the route is then incomplete, so clear or
    /// replace it.
    pub async fn add_points(&self, points: &[RoutePoint]) -> Result<(), CarError> {
        self.send_route(points, false).await
    }

    /// Replaces the route: one AP_REPLACE_ROUTE of up to 5 points, then AP_ADD_POINTS packets (as the control
    /// station does). With the autopilot inactive the car clears the route first; while active it cuts the
    /// route back to the current segment and continues onto the new points.
    ///
    /// Timeout and cancellation: as [`Car::add_points`].
    pub async fn replace_route(&self, points: &[RoutePoint]) -> Result<(), CarError> {
        if points.is_empty() {
            return Err(CarError::InvalidArgument(
                "a replacement route needs at least one point".into(),
            ));
        }
        {
            let mut route = lock(&self.shared().route);
            if !route.active {
                // Inactive: the car clears the route, and with it its duplicate memory, before storing the new one.
                route.last_first = None;
                route.sent_since_empty = Some(0);
            } else {
                // Active: the car cuts the route back to where it is driving; the count is lost.
                route.sent_since_empty = None;
            }
        }
        self.send_route(points, true).await
    }

    async fn send_route(&self, points: &[RoutePoint], replace_first: bool) -> Result<(), CarError> {
        let shared = self.shared();
        let _one_upload_at_a_time = shared.uploads.lock().await;
        shared.check_packet_starts(points)?;
        let mut retried = false;
        for (n, packet) in points.chunks(POINTS_PER_PACKET).enumerate() {
            let request = if replace_first && n == 0 {
                Request::ReplaceRoute(packet.to_vec())
            } else {
                Request::AddPoints(packet.to_vec())
            };
            let tries = shared
                .acked_after(&request, shared.request_timeout())
                .await?;
            retried |= tries > 1;
            shared.remember_first_point(&packet[0]);
            let mut route = lock(&shared.route);
            route.sent_since_empty = route.sent_since_empty.map(|sent| sent + packet.len());
        }
        if retried {
            self.check_route_ends_with(points).await?;
        }
        Ok(())
    }

    /// Reads the last `points.len()` points of the car's route and compares their (x, y) with `points`;
    /// when this client knows how many points the car should hold, checks the route's length too.
    ///
    /// Reads carry nothing that names the read they answer: after a retried read, the late reply of an
    /// earlier one (another part of the route) can answer the next. So a read-back that disagrees is read
    /// again once, after a per-try timeout in which such late replies arrive; only a second disagreement
    /// is an error.
    async fn check_route_ends_with(&self, points: &[RoutePoint]) -> Result<(), CarError> {
        match self.compare_route_end(points).await {
            Err(CarError::RouteLength { .. } | CarError::RouteNotStored { .. }) => {
                tokio::time::sleep(self.request_timeout()).await;
                self.compare_route_end(points).await
            }
            other => other,
        }
    }

    /// One read-back of [`Car::check_route_ends_with`].
    async fn compare_route_end(&self, points: &[RoutePoint]) -> Result<(), CarError> {
        let route_len = self.route_part(0, 0).await?.route_len;
        let held = usize::try_from(route_len).unwrap_or(0);
        let expected = lock(&self.shared().route)
            .sent_since_empty
            .filter(|&sent| sent <= self.version().profile().route_capacity);
        if let Some(sent) = expected
            && held != sent
        {
            return Err(CarError::RouteLength { held, sent });
        }
        let Some(first) = held.checked_sub(points.len()) else {
            tracing::warn!(
                route_len,
                sent = points.len(),
                "the car's route ring may have wrapped: the upload cannot be read back"
            );
            return Ok(());
        };
        for (k, chunk) in points.chunks(usize::from(MAX_ROUTE_PART)).enumerate() {
            let offset = k * usize::from(MAX_ROUTE_PART);
            let at = i32::try_from(first + offset).unwrap_or(i32::MAX);
            let count = u8::try_from(chunk.len()).unwrap_or(MAX_ROUTE_PART);
            let stored = self.route_part(at, count).await?.points;
            for (i, sent) in chunk.iter().enumerate() {
                let held = stored.get(i).copied().unwrap_or_default();
                let same = (held.px - sent.px).abs() < STORED_POINT_TOLERANCE_M
                    && (held.py - sent.py).abs() < STORED_POINT_TOLERANCE_M;
                if !same {
                    return Err(CarError::RouteNotStored {
                        index: offset + i,
                        sent_x: sent.px,
                        sent_y: sent.py,
                        stored_x: held.px,
                        stored_y: held.py,
                    });
                }
            }
        }
        Ok(())
    }

    /// Empties the route and deactivates the autopilot (AP_CLEAR_POINTS). It does not brake.
    ///
    /// Timeout: `tries` × `request_timeout`. Cancellation: the car may or may not have cleared the route.
    pub async fn clear_route(&self) -> Result<(), CarError> {
        let shared = self.shared();
        shared
            .acked(&Request::ClearPoints, shared.request_timeout())
            .await?;
        *lock(&shared.route) = RouteMemory {
            sent_since_empty: Some(0),
            ..RouteMemory::default()
        };
        Ok(())
    }

    /// Removes the last stored route point (AP_REMOVE_LAST_POINT).
    ///
    /// Timeout: `tries` × `request_timeout`. Cancellation: the point may or may not be removed.
    pub async fn remove_last_point(&self) -> Result<(), CarError> {
        let shared = self.shared();
        shared
            .acked(&Request::RemoveLastPoint, shared.request_timeout())
            .await
    }

    /// Activates or deactivates the autopilot (AP_SET_ACTIVE). `reset` (12.3 only) restarts the route from
    /// `route[0]`; asking for it on older firmware is an error. Deactivation does not brake: use [`Car::brake`].
    ///
    /// Timeout: `tries` × `request_timeout`. Cancellation: the car may or may not have switched.
    pub async fn set_autopilot(&self, active: bool, reset: bool) -> Result<(), CarError> {
        let shared = self.shared();
        shared
            .acked(
                &Request::SetActive { active, reset },
                shared.request_timeout(),
            )
            .await?;
        let mut route = lock(&shared.route);
        route.active = active;
        if reset {
            route.last_first = None;
        }
        Ok(())
    }

    /// Brakes with `current_a` amperes (RC_CONTROL, mode CURRENT_BRAKE, steering 0), which also deactivates the
    /// autopilot. The reference safe stop is 50 A, then polling until the speed is below 0.1 m/s. RC_CONTROL has
    /// no reply: success means "sent"; watch the speed in the state.
    ///
    /// Timeout: only the wait for room in the send queue, at most `request_timeout`
    /// ([`CarError::SendStalled`]). Cancellation: the command may or may not be sent.
    pub async fn brake(&self, current_a: f64) -> Result<(), CarError> {
        let rc = RcControl {
            mode: RcMode::CurrentBrake,
            throttle: current_a.abs(),
            steering: 0.0,
        };
        self.rc_control(rc).await
    }

    /// Manual control (RC_CONTROL); no reply. It deactivates the autopilot.
    ///
    /// Timeout: only the wait for room in the send queue, at most `request_timeout`
    /// ([`CarError::SendStalled`]). Cancellation: the command may or may not be sent.
    pub async fn rc_control(&self, rc: RcControl) -> Result<(), CarError> {
        self.shared().fire(&Request::RcControl(rc)).await
    }

    /// Sets the fused and UWB pose (SET_POS_ACK, acked).
    ///
    /// Timeout: `tries` × `request_timeout`. Cancellation: the pose may or may not be set.
    pub async fn set_pos(&self, pose: Pose) -> Result<(), CarError> {
        let shared = self.shared();
        shared
            .acked(&Request::SetPosAck(pose), shared.request_timeout())
            .await
    }

    /// Sets the ENU reference (SET_ENU_REF, acked). Positions already held are not transformed.
    ///
    /// Timeout: `tries` × `request_timeout`. Cancellation: the reference may or may not be set.
    pub async fn set_enu_ref(&self, reference: EnuRef) -> Result<(), CarError> {
        let shared = self.shared();
        shared
            .acked(&Request::SetEnuRef(reference), shared.request_timeout())
            .await
    }

    /// Reads the ENU reference (GET_ENU_REF).
    ///
    /// Timeout: `tries` × `request_timeout`. Cancellation: safe.
    pub async fn enu_ref(&self) -> Result<EnuRef, CarError> {
        let shared = self.shared();
        match shared
            .exchange(
                &Request::GetEnuRef,
                shared.request_timeout(),
                shared.tries(),
            )
            .await?
            .0
            .reply
        {
            Reply::EnuRef(reference) => Ok(reference),
            other => Err(CarError::UnexpectedReply {
                command: CommandId::GetEnuRef,
                reply: format!("{other:?}"),
            }),
        }
    }

    /// Replaces the car's UWB anchors: CLEAR_UWB_ANCHORS, then ADD_UWB_ANCHOR for each, every one acked.
    /// At most 20 anchors, ids 0–255 (the firmware ignores more, and cannot range to larger ids).
    ///
    /// Timeout: `tries` × `request_timeout` per packet. Cancellation: the car may hold part of the list.
    pub async fn upload_anchors(&self, anchors: &[Anchor]) -> Result<(), CarError> {
        if anchors.len() > 20 {
            return Err(CarError::InvalidArgument(format!(
                "{} anchors; the car keeps at most 20",
                anchors.len()
            )));
        }
        if let Some(anchor) = anchors.iter().find(|a| !(0..=255).contains(&a.id)) {
            return Err(CarError::InvalidArgument(format!(
                "anchor id {} is outside 0..=255",
                anchor.id
            )));
        }
        let shared = self.shared();
        shared
            .acked(&Request::ClearUwbAnchors, shared.request_timeout())
            .await?;
        for anchor in anchors {
            shared
                .acked(&Request::AddUwbAnchor(*anchor), shared.request_timeout())
                .await?;
        }
        Ok(())
    }

    /// Reads part of the stored route (AP_GET_ROUTE_PART); `num` ≤ 20, since the car does not answer more.
    ///
    /// Timeout: `tries` × `request_timeout`. Cancellation: safe.
    pub async fn route_part(&self, first: i32, num: u8) -> Result<RoutePart, CarError> {
        if num > MAX_ROUTE_PART {
            return Err(CarError::InvalidArgument(format!(
                "{num} points asked; the car answers at most 20"
            )));
        }
        let shared = self.shared();
        let request = Request::GetRoutePart { first, num };
        match shared
            .exchange(&request, shared.request_timeout(), shared.tries())
            .await?
            .0
            .reply
        {
            Reply::RoutePart(part) => Ok(part),
            other => Err(CarError::UnexpectedReply {
                command: CommandId::ApGetRoutePart,
                reply: format!("{other:?}"),
            }),
        }
    }

    /// Re-times the route up to a point (AP_SYNC_POINT, acked).
    ///
    /// Timeout: `tries` × `request_timeout`. Cancellation: the car may or may not have applied it.
    pub async fn sync_point(&self, sync: SyncPoint) -> Result<(), CarError> {
        let shared = self.shared();
        shared
            .acked(&Request::SyncPoint(sync), shared.request_timeout())
            .await
    }

    /// Reads the main configuration (GET_MAIN_CONFIG), for a read-modify-write.
    ///
    /// Timeout: `tries` × `request_timeout`. Cancellation: safe.
    pub async fn main_config(&self) -> Result<MainConfig, CarError> {
        let shared = self.shared();
        match shared
            .exchange(
                &Request::GetMainConfig,
                shared.request_timeout(),
                shared.tries(),
            )
            .await?
            .0
            .reply
        {
            Reply::MainConfig { config, .. } => Ok(config),
            other => Err(CarError::UnexpectedReply {
                command: CommandId::GetMainConfig,
                reply: format!("{other:?}"),
            }),
        }
    }

    /// Writes the main configuration (SET_MAIN_CONFIG; the car acks after its flash write).
    ///
    /// Timeout: `tries` × `main_config_timeout`. Cancellation: the car may or may not have written it.
    pub async fn set_main_config(&self, config: &MainConfig) -> Result<(), CarError> {
        if config.version() != self.version() {
            return Err(CarError::InvalidArgument(format!(
                "record laid out for firmware {}, car runs {}",
                config.version(),
                self.version()
            )));
        }
        let shared = self.shared();
        shared
            .acked(
                &Request::SetMainConfig(config.clone()),
                shared.config.main_config_timeout,
            )
            .await
    }

    /// Step 2 of the client checklist (`docs/protocol.md#client-checklist`): reads the main configuration and, if
    /// routes repeat (the factory default), time mode is on, or (11.0+) the UWB position is reported in place of the
    /// fused one, switches those off with a read-modify-write. Returns the fields that were changed, with their old
    /// values.
    ///
    /// Timeout: the read as [`Car::main_config`], the write as [`Car::set_main_config`]. Cancellation: the car
    /// may or may not have written the new record.
    pub async fn prepare_for_test_drive(&self) -> Result<Vec<(ConfigField, u8)>, CarError> {
        let mut config = self.main_config().await?;
        let deviations = config.test_drive_deviations()?;
        if !deviations.is_empty() {
            config.make_test_drive_safe()?;
            self.set_main_config(&config).await?;
        }
        Ok(deviations)
    }

    /// Runs a terminal command and returns its PRINTF output, concatenated (lines usually end with `\n`).
    /// The car's PRINTF carries no request id, so an asynchronous debug print arriving meanwhile is included.
    /// A command with no output (e.g. `set_id_quiet`) returns an empty string.
    ///
    /// Timeout: waits up to `terminal_timeout` for the first line, then until `terminal_quiet` passes without
    /// one, and never more than twice `terminal_timeout` in all (a car printing without pause). A lost link
    /// gives [`CarError::LinkLost`]. Cancellation: safe; the command may already have run.
    pub async fn terminal(&self, command: &str) -> Result<String, CarError> {
        Ok(self
            .shared()
            .terminal_lines(command, |_| true, |_| false)
            .await?
            .concat())
    }

    /// Adds a fault (`fi_add_fault probe kind param start duration`) and checks the car's reply: an error for
    /// every refusal ("Too many faults…", "Invalid fault type…", …). `start` counts probe iterations from now;
    /// `duration` 0 is permanent. Slots are never freed until [`Car::clear_faults`].
    ///
    /// Timeout and cancellation: as [`Car::terminal`]; no reply at all is [`FaultError::NoReply`].
    pub async fn add_fault(
        &self,
        probe: &Probe,
        kind: FaultKind,
        param: f32,
        start: i32,
        duration: i32,
    ) -> Result<(), CarError> {
        let id = probe.to_string();
        if id.len() > MAX_PROBE_ID {
            return Err(FaultError::ProbeIdTooLong(id).into());
        }
        if !param.is_finite() {
            return Err(CarError::InvalidArgument(format!(
                "fault parameter {param} is not finite"
            )));
        }
        let command = fault::add_fault_command(probe, kind, param, start, duration);
        let success = format!("successfully added to probe {probe}.");
        let shared = self.shared();
        let adding = FaultAdding::start(shared);
        // Success lines naming another probe, kept to say what the car answered when nothing
        // named this one.
        let others = std::sync::Mutex::new(Vec::new());
        // Fault commands are in flight together, those of one probe in an ordered lane: their success lines
        // name their probes, and the car answers one probe's commands in the order they arrive.
        let lines = shared
            .terminal_lines_ordered(
                &format!("fi_add_fault {id}"),
                &command,
                |line| {
                    let ours = fault::is_add_fault_reply(line, probe);
                    if !ours && fault::is_add_fault_success(line) {
                        lock(&others).push(line.to_owned());
                    }
                    ours
                },
                |lines| lines.iter().any(|l| l.contains(&success)),
            )
            .await;
        let ran_alone = adding.ran_alone();
        drop(adding);
        let lines = lines?;
        let others = others.into_inner().unwrap_or_else(|e| e.into_inner());
        if lines.is_empty() && ran_alone && !others.is_empty() {
            return Err(FaultError::OtherProbe {
                asked: id,
                reply: others.concat(),
            }
            .into());
        }
        Ok(fault::parse_add_fault_reply(&lines, probe)?)
    }

    /// The faults added since the last clear, as the car lists them (`fi_print_faults`); expired
    /// faults are listed too (they keep their slot). Idempotent: this is how a caller finds out
    /// whether an [`Car::add_fault`] whose reply was lost took effect.
    ///
    /// Timeout and cancellation: as [`Car::terminal`]; no reply at all is [`FaultError::NoReply`].
    pub async fn list_faults(&self) -> Result<Vec<fault::ListedFault>, CarError> {
        let lines = self.print_faults_lines().await?;
        Ok(fault::parse_print_faults_reply(&lines)?)
    }

    /// The faults of whatever part of the `fi_print_faults` reply arrived
    /// ([`fault::parse_print_faults_part`]): on a lossy link, where a whole list may rarely
    /// arrive, several of these show every fault the car holds between them.
    ///
    /// Timeout and cancellation: as [`Car::terminal`]; nothing at all is [`FaultError::NoReply`].
    pub async fn list_faults_part(&self) -> Result<Vec<fault::ListedFault>, CarError> {
        let lines = self.print_faults_lines().await?;
        Ok(fault::parse_print_faults_part(&lines)?)
    }

    /// The reply lines of `fi_print_faults` that arrived.
    async fn print_faults_lines(&self) -> Result<Vec<String>, CarError> {
        self.shared()
            .terminal_lines(
                fault::PRINT_FAULTS_COMMAND,
                fault::is_print_faults_reply,
                fault::print_faults_complete,
            )
            .await
    }

    /// Frees every probe and fault slot and zeroes the counters (`fi_clear_faults`).
    ///
    /// Timeout and cancellation: as [`Car::terminal`].
    pub async fn clear_faults(&self) -> Result<(), CarError> {
        let lines = self.fault_command(fault::CLEAR_FAULTS_COMMAND).await?;
        Ok(fault::parse_clear_faults_reply(&lines)?)
    }

    /// Switches fault injection on or off (`fi_set_enabled`); off freezes the counters.
    ///
    /// Timeout and cancellation: as [`Car::terminal`].
    pub async fn set_fi_enabled(&self, enabled: bool) -> Result<(), CarError> {
        let lines = self
            .fault_command(&fault::set_enabled_command(enabled))
            .await?;
        Ok(fault::parse_set_enabled_reply(&lines, enabled)?)
    }

    /// Resets the UWB position to the fused one (`pos_uwb_reset_pos`).
    ///
    /// Timeout and cancellation: as [`Car::terminal`].
    pub async fn reset_uwb_pos(&self) -> Result<(), CarError> {
        let lines = self.fault_command(fault::RESET_UWB_POS_COMMAND).await?;
        Ok(fault::parse_reset_uwb_reply(&lines)?)
    }

    async fn fault_command(&self, command: &str) -> Result<Vec<String>, CarError> {
        let shared = self.shared();
        shared
            .terminal_lines(command, fault::is_fault_reply, |lines| !lines.is_empty())
            .await
    }
}
