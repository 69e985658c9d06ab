//! The protocol shell: an async task on tokio's clock that owns the simulated board, steps it every
//! 10 ms, and serves one client at a time in-process, over TCP or over UDP, with optional link
//! impairment on the simulator's side.
//!
//! On a paused tokio clock (`tokio::time::pause`, or `#[tokio::test(start_paused = true)]`) the
//! simulation runs in virtual time, as fast as the CPU allows and deterministically: the same seed
//! and the same requests give bit-identical replies.

use std::collections::VecDeque;
use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bytes::Bytes;
use car_link::frame::{FrameDecoder, FrameEncoder};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, DuplexStream};
use tokio::net::{TcpListener, UdpSocket};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::{Instant, sleep_until, timeout};

use crate::car::{CarOptions, GnssModel, Placement, SensorErrors, SimCar, TICK_MS};
use crate::debug::{DebugEvent, Truth};
use crate::noise::Noise;
use crate::protocol::Board;
use crate::uwb::RadioModel;
use crate::world::World;
use car_link::firmware::FirmwareVersion;
use car_link::message::ID_CAR_CLIENT;
use car_link::version::CommandId;

/// The default port of the reference bridge.
pub const DEFAULT_PORT: u16 = 8300;
/// The firmware's parser resets after this long without a byte (20–30 ms).
const FIRMWARE_BYTE_TIMEOUT: Duration = Duration::from_millis(30);
/// The bridge's parser resets after this long without a byte.
const BRIDGE_BYTE_TIMEOUT: Duration = Duration::from_millis(500);

/// How a byte-stream connection reaches the board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Hop {
    /// Straight to the board, like USB: the firmware's byte timeout, every reply forwarded.
    Direct,
    /// Through the reference bridge: its 500 ms byte timeout, and replies stamped 254 (other than
    /// PRINTF) are not forwarded.
    Bridge,
}

impl Hop {
    fn byte_timeout(self) -> Duration {
        match self {
            Hop::Direct => FIRMWARE_BYTE_TIMEOUT,
            Hop::Bridge => BRIDGE_BYTE_TIMEOUT,
        }
    }

    fn forwards(self, payload: &[u8]) -> bool {
        // Replies stamped with ID_CAR_CLIENT are not forwarded by the bridge, PRINTF excepted (its
        // id is the same in every version).
        let printf = CommandId::Printf.code(FirmwareVersion::LATEST);
        self == Hop::Direct
            || !(payload.first() == Some(&ID_CAR_CLIENT) && payload.get(1).copied() != printf)
    }
}
/// Payloads queued towards a client before the simulator drops them.
const CLIENT_QUEUE: usize = 256;
/// Noise stream of the link impairment.
const STREAM_LINK: u64 = 3;

/// Impairment the simulator applies to its side of the link, in both directions.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkImpairment {
    /// Added one-way latency.
    pub latency: Duration,
    /// Extra one-way delay drawn uniformly from `[0, jitter]` (order is kept, as on a stream).
    pub jitter: Duration,
    /// Probability that a payload is lost, 0..1.
    pub loss: f64,
    /// Probability that a payload is delivered twice, 0..1.
    pub duplication: f64,
    /// Close each client connection this long after it was opened.
    pub disconnect_after: Option<Duration>,
}

/// Everything that defines a simulated car and its link.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SimConfig {
    /// Firmware generation (default 10.1).
    pub firmware: FirmwareVersion,
    /// Seed of every random draw (physics and link).
    pub seed: u64,
    /// The car id (default 1).
    pub car_id: Option<u8>,
    /// The world: anchors, obstacles, walls.
    pub world: World,
    /// Where the car stands at boot.
    pub placement: Option<Placement>,
    /// The UWB radio model.
    pub radio: RadioModel,
    /// The GNSS receiver.
    pub gnss: GnssModel,
    /// The errors of the car's odometry and IMU.
    pub sensors: SensorErrors,
    /// Load the world's anchors into the firmware at boot (the real car boots with none).
    pub preload_anchors: bool,
    /// Record debug events (read them with [`SimHandle::take_events`]).
    pub record_events: bool,
    /// HIL-bench fidelity: the IMU does not rotate (see [`CarOptions::imu_on_bench`]).
    pub imu_on_bench: bool,
    /// Simulation only: the UWB correction clamp (see [`CarOptions::uwb_step_clamp_m`]).
    pub uwb_step_clamp_m: Option<f32>,
    /// Over TCP: close a client's connection after this long without a complete frame from it,
    /// so that a client that went silent, never spoke or trickles bytes that make no frame does
    /// not hold the only slot (`None`: never). A live client sends at least every 500 ms (the keepalive feeding the watchdog).
    pub idle_timeout: Option<Duration>,
    /// Link impairment.
    pub link: LinkImpairment,
    /// Conformance only: see [`CarOptions::misname_fault_probe`].
    pub misname_fault_probe: bool,
}

impl SimConfig {
    /// A car in a scenario's world, standing at the start of its start route.
    pub fn from_scenario(scenario: &scenarios::Scenario) -> Self {
        Self {
            world: World::from_scenario(scenario),
            placement: Placement::at_start_of(scenario),
            ..Self::default()
        }
    }

    /// The car's options.
    pub fn car_options(&self) -> CarOptions {
        let defaults = CarOptions::default();
        CarOptions {
            firmware: self.firmware,
            seed: self.seed,
            car_id: self.car_id.unwrap_or(defaults.car_id),
            world: self.world.clone(),
            radio: self.radio,
            gnss: self.gnss,
            sensors: self.sensors,
            placement: self.placement.unwrap_or(defaults.placement),
            preload_anchors: self.preload_anchors,
            record_events: self.record_events,
            imu_on_bench: self.imu_on_bench,
            uwb_step_clamp_m: self.uwb_step_clamp_m,
            misname_fault_probe: self.misname_fault_probe,
        }
    }
}

/// What the simulation shares with its handle.
#[derive(Debug)]
struct Shared {
    truth: Truth,
    events: Vec<DebugEvent>,
    fault_injection: FaultInjectionView,
    /// The board answers nothing from now on ([`SimHandle::freeze`]).
    frozen: bool,
}

/// The simulated car's fault injection as its handle sees it (what a car does not report: the
/// firmware has no command that says whether fault injection is enabled).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FaultInjectionView {
    /// Whether fault injection is enabled (`fi_set_enabled 1`).
    pub enabled: bool,
    /// The fault slots taken (until `fi_clear_faults`).
    pub faults_armed: usize,
}

impl FaultInjectionView {
    fn of(car: &SimCar) -> Self {
        Self {
            enabled: car.fault_injection().is_enabled(),
            faults_armed: car.fault_injection().faults_armed(),
        }
    }
}

/// A running simulated car. Dropping it stops the simulation and closes its connections.
#[derive(Debug)]
pub struct SimHandle {
    shared: Arc<Mutex<Shared>>,
    tasks: Vec<JoinHandle<()>>,
    local_addr: Option<SocketAddr>,
}

impl SimHandle {
    /// The debug view at the last simulated tick.
    pub fn truth(&self) -> Truth {
        self.lock().truth
    }

    /// The fault injection at the last simulated tick: enabled or not, and the faults armed.
    pub fn fault_injection(&self) -> FaultInjectionView {
        self.lock().fault_injection
    }

    /// Takes the debug events recorded so far (empty unless `record_events`).
    pub fn take_events(&self) -> Vec<DebugEvent> {
        std::mem::take(&mut self.lock().events)
    }

    /// The bound address of a TCP or UDP server.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }

    /// Freezes the board: from now on it answers nothing, while its connection stays open and
    /// the simulated world goes on (a car whose firmware hangs, not one whose link is lost).
    pub fn freeze(&self) {
        self.lock().frozen = true;
    }

    /// Stops the simulation and its connections at once.
    pub fn shutdown(&self) {
        for task in &self.tasks {
            task.abort();
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Shared> {
        // A poisoned lock only means a panicking reader; the data is plain values.
        self.shared.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Drop for SimHandle {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Messages from the transports to the simulation.
enum CoreMsg {
    /// A client connected; replies go to this sender.
    Connected(mpsc::Sender<Bytes>),
    /// A received payload.
    Payload(Bytes),
}

/// A payload waiting for its delivery time.
struct Delayed {
    due: Instant,
    payload: Bytes,
}

/// One direction of the impaired link: loss, duplication, latency and jitter, order kept.
struct ImpairedQueue {
    queue: VecDeque<Delayed>,
    last_due: Option<Instant>,
}

impl ImpairedQueue {
    fn new() -> Self {
        Self {
            queue: VecDeque::new(),
            last_due: None,
        }
    }

    fn push(&mut self, at: Instant, payload: Bytes, link: &LinkImpairment, noise: &mut Noise) {
        if noise.chance(link.loss) {
            return;
        }
        let copies = if noise.chance(link.duplication) { 2 } else { 1 };
        let jitter = link.jitter.mul_f64(noise.uniform());
        // An absurd latency saturates instead of overflowing the clock.
        let delay = link.latency.saturating_add(jitter);
        let mut due = at
            .checked_add(delay)
            .unwrap_or(at + Duration::from_secs(86_400 * 365));
        if let Some(last) = self.last_due {
            due = due.max(last);
        }
        self.last_due = Some(due);
        for _ in 0..copies {
            self.queue.push_back(Delayed {
                due,
                payload: payload.clone(),
            });
        }
    }

    fn next_due(&self) -> Option<Instant> {
        self.queue.front().map(|d| d.due)
    }

    fn pop_due(&mut self, now: Instant) -> Option<Bytes> {
        if self.next_due()? <= now {
            self.queue.pop_front().map(|d| d.payload)
        } else {
            None
        }
    }
}

/// Ticks run at the latest together when nothing is due in between ([`Core::run`]).
pub(crate) const HEARTBEAT_TICKS: u32 = 10;

/// The simulation task: the board, the clock and the impaired link.
struct Core {
    board: Board,
    /// What the board is built from, for a reboot after an internal fault.
    options: CarOptions,
    link: LinkImpairment,
    noise: Noise,
    inbound: ImpairedQueue,
    outbound: ImpairedQueue,
    client: Option<mpsc::Sender<Bytes>>,
    shared: Arc<Mutex<Shared>>,
    record_events: bool,
}

impl Core {
    fn new(config: &SimConfig) -> Self {
        let options = config.car_options();
        let car = SimCar::new(options.clone());
        let shared = Arc::new(Mutex::new(Shared {
            truth: car.truth(),
            events: Vec::new(),
            fault_injection: FaultInjectionView::of(&car),
            frozen: false,
        }));
        Core {
            board: Board::new(car),
            options,
            link: config.link,
            noise: Noise::stream(config.seed, STREAM_LINK),
            inbound: ImpairedQueue::new(),
            outbound: ImpairedQueue::new(),
            client: None,
            shared,
            record_events: config.record_events,
        }
    }

    async fn run(mut self, mut rx: mpsc::Receiver<CoreMsg>) {
        let tick = Duration::from_millis(TICK_MS);
        let mut next_tick = Instant::now() + tick;
        let mut rx_open = true;
        loop {
            // The board's ticks are run when something is due (a payload in or out) or at the
            // latest every `HEARTBEAT_TICKS` ticks, in order, not one wake per tick: whoever reads
            // the car sees every tick up to then (a reply is flushed after the ticks before it).
            let heartbeat = next_tick + tick * (HEARTBEAT_TICKS - 1);
            let wake = [self.inbound.next_due(), self.outbound.next_due()]
                .into_iter()
                .flatten()
                .fold(heartbeat, Instant::min);
            tokio::select! {
                biased;
                msg = rx.recv(), if rx_open => match msg {
                    Some(m) => self.receive(m),
                    None => rx_open = false,
                },
                () = sleep_until(wake) => {}
            }
            let now = Instant::now();
            self.catch_up(now, &mut next_tick, tick);
            self.flush_outbound(now);
        }
    }

    fn receive(&mut self, msg: CoreMsg) {
        match msg {
            CoreMsg::Connected(tx) => {
                self.client = Some(tx);
                self.inbound = ImpairedQueue::new();
                self.outbound = ImpairedQueue::new();
            }
            CoreMsg::Payload(p) => {
                let now = Instant::now();
                self.inbound.push(now, p, &self.link, &mut self.noise);
            }
        }
    }

    /// Runs everything due up to `now` in time order: requests before the tick they precede.
    fn catch_up(&mut self, now: Instant, next_tick: &mut Instant, tick: Duration) {
        loop {
            let request_due = self.inbound.next_due().filter(|d| *d <= now);
            match request_due {
                Some(due) if due <= *next_tick => {
                    if let Some(p) = self.inbound.pop_due(now) {
                        self.guarded(|core| core.handle(due, &p));
                    }
                }
                _ if *next_tick <= now => {
                    self.guarded(|core| core.board.car_mut().step());
                    *next_tick += tick;
                    self.publish();
                }
                _ => return,
            }
        }
    }

    /// Runs `f` on the core; a panic in the model (a fault of the simulator itself: the
    /// fuzzers find none) reboots the board where the car stands, as the firmware's hardware
    /// watchdog would, instead of ending the task and leaving the server deaf.
    fn guarded(&mut self, f: impl FnOnce(&mut Self)) {
        if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(self))).is_ok() {
            return;
        }
        let truth = self.board.car().truth();
        let mut options = self.options.clone();
        if [truth.x, truth.y, truth.heading]
            .iter()
            .all(|v| v.is_finite())
        {
            options.placement = Placement {
                x: truth.x,
                y: truth.y,
                heading: truth.heading,
            };
        }
        eprintln!("simulated car: internal fault (see the panic above); the board reboots");
        self.board = Board::new(SimCar::new(options));
    }

    fn handle(&mut self, at: Instant, payload: &[u8]) {
        for out in self.board.handle(payload) {
            self.outbound
                .push(at + out.delay, out.payload, &self.link, &mut self.noise);
        }
    }

    fn flush_outbound(&mut self, now: Instant) {
        let frozen = self.shared.lock().unwrap_or_else(|e| e.into_inner()).frozen;
        while let Some(p) = self.outbound.pop_due(now) {
            if frozen {
                continue;
            }
            if let Some(tx) = &self.client
                && tx.try_send(p).is_err()
                && tx.is_closed()
            {
                self.client = None;
            }
        }
    }

    fn publish(&mut self) {
        let truth = self.board.car().truth();
        let events = if self.record_events {
            self.board.car_mut().drain_events()
        } else {
            Vec::new()
        };
        let fault_injection = FaultInjectionView::of(self.board.car());
        let mut shared = self.shared.lock().unwrap_or_else(|e| e.into_inner());
        shared.truth = truth;
        shared.events.extend(events);
        shared.fault_injection = fault_injection;
    }
}

fn start_core(config: &SimConfig) -> (mpsc::Sender<CoreMsg>, Arc<Mutex<Shared>>, JoinHandle<()>) {
    let core = Core::new(config);
    let shared = Arc::clone(&core.shared);
    let (tx, rx) = mpsc::channel(CLIENT_QUEUE);
    let task = tokio::spawn(core.run(rx));
    (tx, shared, task)
}

/// Serves one byte-stream connection: frames in, frames out, until the stream ends, the
/// simulation stops, or the scripted disconnect time.
async fn serve_stream<S>(
    stream: S,
    core: mpsc::Sender<CoreMsg>,
    disconnect_after: Option<Duration>,
    idle_timeout: Option<Duration>,
    hop: Hop,
) where
    S: AsyncRead + AsyncWrite + Unpin,
{
    let (tx, mut rx) = mpsc::channel::<Bytes>(CLIENT_QUEUE);
    if core.send(CoreMsg::Connected(tx)).await.is_err() {
        return;
    }
    let deadline = disconnect_after.map(|d| Instant::now() + d);
    let (mut reader, mut writer) = tokio::io::split(stream);
    let mut decoder = FrameDecoder::firmware();
    let encoder = FrameEncoder::to_firmware();
    let mut buf = vec![0u8; 4096];
    // A complete frame, not a byte, keeps the connection: a client trickling bytes that never
    // make a frame does not hold the car's only slot.
    let mut last_frame = Instant::now();
    loop {
        let disconnect = async {
            match deadline {
                Some(d) => sleep_until(d).await,
                None => std::future::pending().await,
            }
        };
        let idle = async {
            match idle_timeout {
                Some(idle) => sleep_until(last_frame + idle).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            () = disconnect => return,
            () = idle => return,
            out = rx.recv() => {
                let Some(payload) = out else { return };
                if !hop.forwards(&payload) {
                    continue;
                }
                // A payload the firmware cannot send (over 1024 bytes) is silently not sent.
                if let Ok(frame) = encoder.encode_to_bytes(&payload)
                    && writer.write_all(&frame).await.is_err()
                {
                    return;
                }
            }
            read = timeout(hop.byte_timeout(), reader.read(&mut buf)) => match read {
                Ok(Ok(0)) | Ok(Err(_)) => return,
                Ok(Ok(n)) => {
                    decoder.push(&buf[..n]);
                    match forward_frames(&mut decoder, &core).await {
                        None => return,
                        Some(0) => {}
                        Some(_) => last_frame = Instant::now(),
                    }
                }
                Err(_) => {
                    // The byte timeout: abandon a half-received frame.
                    while decoder.expire().is_some() {
                        match forward_frames(&mut decoder, &core).await {
                            None => return,
                            Some(0) => {}
                            Some(_) => last_frame = Instant::now(),
                        }
                    }
                }
            },
        }
    }
}

/// Sends every complete valid frame to the simulation; dropped candidates are ignored as the
/// firmware does. Returns the frames sent, `None` when the simulation is gone.
async fn forward_frames(decoder: &mut FrameDecoder, core: &mpsc::Sender<CoreMsg>) -> Option<usize> {
    let mut sent = 0;
    while let Some(item) = decoder.next_frame() {
        if let Ok(frame) = item {
            core.send(CoreMsg::Payload(frame.payload)).await.ok()?;
            sent += 1;
        }
    }
    Some(sent)
}

/// Starts a simulated car in this process and returns the client's end of an in-memory byte
/// stream (framed as over TCP; give it to `car_link::Car::over_stream`) and the handle.
///
/// Must be called inside a tokio runtime. On a paused clock the simulation runs in virtual time.
/// The simulation stops when the handle is dropped or [`SimHandle::shutdown`] is called; the
/// stream then reads end-of-file. A scripted disconnect closes the stream after
/// `link.disconnect_after`, while the car keeps running (its watchdog then brakes it).
pub fn spawn_in_process(config: &SimConfig) -> (DuplexStream, SimHandle) {
    let pipe = car_link::transport::sim_pipe();
    let (core, shared, core_task) = start_core(config);
    let conn = tokio::spawn(serve_stream(
        pipe.car,
        core,
        config.link.disconnect_after,
        None,
        Hop::Direct,
    ));
    let handle = SimHandle {
        shared,
        tasks: vec![core_task, conn],
        local_addr: None,
    };
    (pipe.host, handle)
}

/// Serves a simulated car over TCP at `addr` as the reference bridge would (it listens on port
/// 8300; bind loopback unless exposing it is intended). One client at a time: a second
/// connection is accepted and closed at once; a client that sends no complete frame for
/// `config.idle_timeout` is disconnected, freeing the slot. Like the bridge, replies stamped with id 254 are
/// not forwarded (PRINTF excepted) and the parser waits 500 ms for a frame's next byte. The car
/// keeps running between connections.
///
/// Timeout: none; it returns as soon as the listener is bound (an error if binding fails).
/// Cancellation: dropping the future before it completes binds nothing. The server then runs on
/// tokio's clock until the handle is dropped or shut down, which closes the listener and the
/// client connection.
pub async fn serve_tcp(addr: SocketAddr, config: &SimConfig) -> io::Result<SimHandle> {
    let listener = TcpListener::bind(addr).await?;
    let local_addr = listener.local_addr()?;
    let (core, shared, core_task) = start_core(config);
    let disconnect_after = config.link.disconnect_after;
    let idle_timeout = config.idle_timeout;
    let acceptor = tokio::spawn(async move {
        let busy = Arc::new(AtomicBool::new(false));
        while let Ok((stream, _)) = listener.accept().await {
            if busy.swap(true, Ordering::SeqCst) {
                drop(stream);
                continue;
            }
            let _ = stream.set_nodelay(true);
            let (core, busy) = (core.clone(), busy.clone());
            tokio::spawn(async move {
                serve_stream(stream, core, disconnect_after, idle_timeout, Hop::Bridge).await;
                busy.store(false, Ordering::SeqCst);
            });
        }
    });
    Ok(SimHandle {
        shared,
        tasks: vec![core_task, acceptor],
        local_addr: Some(local_addr),
    })
}

/// Serves a simulated car over UDP at `addr`, like the bridge's UDP mode: one bare payload per
/// datagram, replies to the last sender's IP address at the bound port + 1.
///
/// Timeout: none; it returns as soon as the socket is bound (an error if binding fails).
/// Cancellation: dropping the future before it completes binds nothing. The server then runs on
/// tokio's clock until the handle is dropped or shut down.
pub async fn serve_udp(addr: SocketAddr, config: &SimConfig) -> io::Result<SimHandle> {
    let socket = UdpSocket::bind(addr).await?;
    let local_addr = socket.local_addr()?;
    let (core, shared, core_task) = start_core(config);
    let reply_port = local_addr.port().wrapping_add(1);
    let task = tokio::spawn(async move {
        let (tx, mut rx) = mpsc::channel::<Bytes>(CLIENT_QUEUE);
        if core.send(CoreMsg::Connected(tx)).await.is_err() {
            return;
        }
        let mut peer: Option<SocketAddr> = None;
        let mut buf = vec![0u8; 65_536];
        loop {
            tokio::select! {
                got = socket.recv_from(&mut buf) => {
                    let Ok((n, from)) = got else { continue };
                    peer = Some(SocketAddr::new(from.ip(), reply_port));
                    let payload = Bytes::copy_from_slice(&buf[..n]);
                    if core.send(CoreMsg::Payload(payload)).await.is_err() {
                        return;
                    }
                }
                out = rx.recv() => {
                    let Some(payload) = out else { return };
                    if !Hop::Bridge.forwards(&payload) {
                        continue;
                    }
                    if let Some(to) = peer {
                        let _ = socket.send_to(&payload, to).await;
                    }
                }
            }
        }
    });
    Ok(SimHandle {
        shared,
        tasks: vec![core_task, task],
        local_addr: Some(local_addr),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use car_link::message::{Dialect, Request};

    #[test]
    fn a_fault_of_the_model_reboots_the_board_where_the_car_stands_and_it_answers() {
        let config = SimConfig {
            placement: Some(Placement {
                x: 3.0,
                y: -2.0,
                heading: 0.5,
            }),
            ..SimConfig::default()
        };
        let mut core = Core::new(&config);
        for _ in 0..10 {
            core.board.car_mut().step();
        }
        core.guarded(|_| panic!("a fault of the model"));
        let get_state = Request::GetState
            .encode(1, Dialect::host(config.firmware))
            .unwrap();
        assert_eq!(core.board.handle(&get_state).len(), 1);
        let truth = core.board.car().truth();
        assert!(
            (truth.x - 3.0).abs() < 1e-6 && (truth.y + 2.0).abs() < 1e-6,
            "{truth:?}"
        );
        assert_eq!(truth.time_ms, 0, "a fresh board");
    }
}
