//! The test drive as a pure state machine: the planned commands streamed to the car, the oracle
//! and the safety monitor at the state rate, and the safe stop.
//!
//! A [`TestDrive`] is fed [`Event`]s, each with the time since the test began (a state sample,
//! the answer to the operation in flight, the monitor's tick, the operator's interrupt, a lost
//! link), and answers with [`Action`]s (record the stop demanded, abandon the operation in flight,
//! brake). When no operation is in flight the caller asks it for the next one
//! ([`TestDrive::next_operation`]): a segment or the safe stop's extension to append, or a fault
//! to add. At most one operation is in flight at a time, in plan order. Nothing here reads a
//! clock or talks to the car: the orchestrator's loop (`runner::drive`) does that, and feeds the
//! answers back.
//!
//! The rules (`docs/method.md#the-model`):
//! - **Streaming.** A `RunSegments` command is appended when the time the car needs to reach its
//!   stopping point falls to the lead time, and it is done when that happens again for the next
//!   command (the car is almost at the segment's end); the fault commands after it are sent then,
//!   each confirmed by its answer, and the lead time grows by a round trip for each of them and
//!   for each extra packet of the next segment, and by a request timeout (one retry) once the
//!   link has lost a packet. After an append the next decision waits for a sample located on the
//!   new route.
//! - **Oracle.** Samples are assigned to the segment the car drives (from where the streamer
//!   locates it on the route); a segment is judged when the car leaves it, and the segment being
//!   driven when the drive ends is judged on what was seen of it. Under
//!   [`FailurePolicy::StopAtFailingSegment`] the first failing segment ends the test.
//! - **Safety.** The [`SafetyMonitor`] watches every sample and tick; the first stop demanded wins.
//!   A lost link ends the drive at once.
//! - **Safe stop** (at the plan's end, after a failing segment, or when a stop asks for it):
//!   phases [`Phase::Commands`] → [`Phase::StopPending`] (the extension waits until no command
//!   is in flight) → [`Phase::Extending`] (a slow extension generated with the ahead margin from
//!   the route's end, with the scenario's generator and the test's seeded RNG, is on its way) →
//!   [`Phase::Rolling`] (the car drives it) → [`Phase::Braking`] (once the car needs less than
//!   0.5 s to its stopping point, or stands; brake at every sample until it is slower than
//!   [`STOPPED_SPEED_MPS`], at most [`BRAKE_TIMEOUT`]) → [`Phase::Done`]. A stop that demands
//!   braking skips to braking; so does an extension that cannot be generated or is refused.

use std::time::Duration;

use car_link::message::POINTS_PER_PACKET;
use scenarios::Route;
use trajgen::{Area, Generator, Point, RouteTail};

use crate::files::{Case, SegmentResult, StreamingRecord};
use crate::model::{Command, Fault, FaultWindow, ProbeRates, Segment, TestPlan};
use crate::oracle::{
    FailurePolicy, JudgedSegment, SegmentOracle, SegmentOutcome, SegmentVerdict, test_verdict,
};
use crate::safety::{Abort, AbortReason, CarSample, SafetyConfig, SafetyMonitor, StopAction};
use crate::seed::{Purpose, rng_for};
use crate::streaming::{Decision, Streamer, StreamingConfig, Waypoint};

/// Speed of the safe stop's extension, m/s (`docs/method.md#the-model`).
pub const SAFE_STOP_SPEED_MPS: f64 = 0.8;
/// The car counts as stopped below this speed, m/s.
pub const STOPPED_SPEED_MPS: f64 = 0.1;
/// Longest the drive brakes waiting for the car to stop.
pub const BRAKE_TIMEOUT: Duration = Duration::from_secs(5);
/// In the safe stop, brake once the car needs less than this to reach its stopping point.
const ROLL_END: Duration = Duration::from_millis(500);

/// What a drive needs besides its plan: the area, the generator and the rules in force.
#[derive(Debug, Clone, Copy)]
pub struct DriveSettings<'a> {
    /// The test area (watched by the safety monitor; the safe stop's extension stays in it).
    pub area: &'a Area,
    /// The scenario's generator, for the safe stop's extension.
    pub generator: Generator,
    /// The safety limits in force.
    pub safety: SafetyConfig,
    /// The streaming rule's constants.
    pub streaming: StreamingConfig,
    /// What happens after a failing segment.
    pub policy: FailurePolicy,
    /// The oracle's threshold, metres.
    pub oracle_threshold_m: f64,
    /// Points of the safe stop's extension (the scenario's fewest points per segment; at least
    /// one is generated).
    pub stop_points: usize,
    /// The fault probes' call rates, to estimate when a fault applied.
    pub rates: ProbeRates,
    /// The campaign's seed: the safe stop extension's RNG derives from it and the test index.
    pub campaign_seed: u64,
    /// How the car steers (the scenario's vehicle), to predict when it reaches a fault's place.
    pub steering: Option<Steering>,
}

/// One state sample, as the drive uses it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// The car's RTK-fused position: the oracle's reference and what the monitor and the
    /// streamer locate the car by.
    pub rtk: Point,
    /// The car's UWB estimate: what the oracle judges.
    pub uwb: Point,
    /// The car's speed, m/s.
    pub speed: f64,
    /// The sample's request-to-reply time (a measured link round trip).
    pub round_trip: Duration,
    /// The car's heading, degrees clockwise from east, as GET_STATE reports its yaw (NaN when
    /// unknown).
    pub yaw_deg: f64,
    /// The car's firmware version, as GET_STATE reports it (its autopilot's look-ahead law).
    pub version: car_link::firmware::FirmwareVersion,
    /// The autopilot's look-ahead radius the car reports, metres (−1 while it is inactive;
    /// NaN when the car does not report one).
    pub look_ahead_radius_m: f64,
}

/// How the operation in flight ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// The car confirmed it.
    Done,
    /// The link to the car is lost.
    LinkLost,
    /// The car refused it or did not answer; the error in words.
    Failed(String),
}

/// What happened, fed to [`TestDrive::handle`].
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A state sample arrived.
    Sample(Sample),
    /// The operation in flight (a segment or the safe stop's extension) ended.
    Reply(Reply),
    /// A fault command in flight ended; `resent`: its reply was lost and the car's list of
    /// faults showed it added (so its reply's time does not say when).
    FaultReply {
        /// The fault command's index in the plan.
        command_index: usize,
        /// How it ended.
        reply: Reply,
        /// Whether the reply was lost and the fault found in the car's list.
        resent: bool,
    },
    /// The monitor's tick (at the state rate, also when no sample comes).
    Tick,
    /// The operator interrupted the campaign.
    Interrupt,
    /// The link to the car is lost (the telemetry ended, or the brake command found it lost).
    LinkLost,
    /// The operator's second signal braked the car at once: the drive ends now, aborted, so that
    /// its case can be written before the process exits.
    BrakedAtOnce,
}

/// What the case of a test ended by [`Event::BrakedAtOnce`] says.
pub const BRAKED_AT_ONCE: &str =
    "a second signal braked the car at once (50 A): the drive ended there";

/// What the link shows now, for the lead time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkStatus {
    /// The 99th-percentile round trip measured by the link, if any yet (otherwise the streaming
    /// rule's initial round trip stands in).
    pub rtt_p99: Option<Duration>,
    /// Whether the link has lost a request or a reply (then the lead time allows one retry).
    pub lossy: bool,
    /// How long the link waits for a reply before it asks again.
    pub request_timeout: Duration,
}

/// An operation to start (when none is in flight); its end comes back as [`Event::Reply`].
#[derive(Debug, Clone, PartialEq)]
pub enum Operation {
    /// Append the points of segment command `command_index` to the car's route (AP_ADD_POINTS).
    AppendSegment {
        /// The command's index in the plan.
        command_index: usize,
        /// The points with their speeds.
        points: Vec<Waypoint>,
    },
    /// Append the safe stop's extension to the car's route (AP_ADD_POINTS), every point at
    /// [`SAFE_STOP_SPEED_MPS`]. Report the time its generation took with
    /// [`TestDrive::extension_generated_in`].
    AppendStop {
        /// The points with their speeds.
        points: Vec<Waypoint>,
    },
    /// Add the fault of command `command_index`.
    AddFault {
        /// The command's index in the plan.
        command_index: usize,
        /// The fault.
        fault: Fault,
        /// Faults on the same probe that the car confirmed in this test, and those sent before
        /// this one and still in flight: one more on the probe when the car lists its faults
        /// means a command whose reply was lost took effect.
        on_probe: usize,
    },
}

/// What the caller must do after an event, in order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Action {
    /// A stop was demanded (the first one of the drive): record it.
    Stop(Abort),
    /// The drive stopped with an operation in flight: drop it and record it as abandoned.
    Abandon,
    /// The drive stopped with fault commands in flight: drop them and record them as abandoned.
    AbandonFault,
    /// Send one brake command; if it finds the link lost, feed [`Event::LinkLost`].
    Brake,
}

/// The phases of a drive (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Running the plan's commands.
    Commands,
    /// Stopping: the extension is sent once no command is in flight.
    StopPending,
    /// The extension is on its way.
    Extending,
    /// The car drives the extension.
    Rolling,
    /// Braking until the car stands.
    Braking,
    /// Over.
    Done,
}

/// What a drive produced.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveOutcome {
    /// The oracle's result for every segment judged.
    pub segments: Vec<SegmentResult>,
    /// The stop demanded, if any.
    pub abort: Option<Abort>,
    /// The stop's reason in words, with details (`link lost`, `command 3 failed: …`).
    pub abort_text: Option<String>,
    /// How the segments were streamed.
    pub streaming: StreamingRecord,
    /// The fault commands the car confirmed (their command indices), and when the car added
    /// them (estimated).
    pub faults_confirmed: Vec<(usize, Duration)>,
    /// Where each confirmed fault was meant to act and where it did.
    pub fault_places: Vec<FaultPlacement>,
}

impl DriveOutcome {
    /// Writes the results, the verdict and its reason into `case`. `error`: the error that ended
    /// the campaign during the drive, if any; it is the reason when no stop was demanded.
    pub fn write_into(&self, case: &mut Case, error: Option<&str>) {
        let judged: Vec<JudgedSegment> = self
            .segments
            .iter()
            .map(|s| JudgedSegment {
                segment_index: s.segment_index,
                command_index: s.command_index,
                outcome: s.oracle,
            })
            .collect();
        let abort_text = self.abort_text.as_deref().or(error);
        let verdict = test_verdict(&judged, abort_text);
        case.segments = self.segments.clone();
        case.verdict = Some(verdict.verdict);
        case.reason = verdict.reason;
        case.abort = self.abort;
        case.streaming = Some(self.streaming.clone());
        case.fault_places = self.fault_places.iter().map(|&p| p.into()).collect();
    }
}

/// The route a test starts on: where the car stands, then the scenario's start route (the first
/// leg at the start route's first speed).
pub fn start_route(start: &Route, standing: Point) -> Vec<Waypoint> {
    let speed = start.first().map_or(SAFE_STOP_SPEED_MPS, |p| p.speed);
    std::iter::once(Waypoint {
        position: standing,
        speed,
    })
    .chain(start.points.iter().copied())
    .collect()
}

/// A segment appended to the car's route, and what the oracle made of it.
#[derive(Debug, Clone)]
struct AppendedSegment {
    command_index: usize,
    /// Index of its first point on the car's route.
    first: usize,
    entered: Option<Duration>,
    left: Option<Duration>,
    oracle: SegmentOracle,
    result: Option<SegmentOutcome>,
}

/// Where the car is on its route.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Region {
    /// Still on the start route.
    Start,
    /// On appended segment `k`.
    Segment(usize),
    /// On the safe stop's extension.
    Stop,
}

/// The operation in flight.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum InFlight {
    /// A segment (`append`: its index in the streamer's appends).
    Segment { append: usize },
    /// The safe stop's extension.
    Extension { append: usize },
}

/// How far the plan's commands have got.
#[derive(Debug, Clone, Default)]
struct Cursor {
    /// The command to run next (or being run).
    command: usize,
    /// The segment command appended last, until the car is almost at its end.
    appended: Option<usize>,
    /// The operation in flight.
    in_flight: Option<InFlight>,
    /// The streamer's decision at the last sample located on the current route.
    decision: Option<Decision>,
}

/// The car's route as sent, and where the safe stop's extension begins on it.
#[derive(Debug, Clone)]
struct RouteSent {
    /// Points on the car's route.
    len: usize,
    /// The route's tail after the last segment (where the extension continues from).
    tail: RouteTail,
    /// Index of the extension's first point.
    stop_first: Option<usize>,
}

/// The safe stop's bookkeeping.
#[derive(Debug, Clone, Default)]
struct Stopping {
    /// When the car had the safe stop's extension, or braking began: the end of the test proper.
    began: Option<Duration>,
    /// A brake command is due.
    brake_now: bool,
    /// When braking gives up waiting for the car to stop.
    brake_deadline: Option<Duration>,
}

/// The test drive (see the module doc).
#[derive(Debug, Clone)]
pub struct TestDrive<'a> {
    settings: DriveSettings<'a>,
    plan: &'a TestPlan,
    phase: Phase,
    streamer: Streamer,
    safety: SafetyMonitor,
    route: RouteSent,
    cursor: Cursor,
    segments: Vec<AppendedSegment>,
    /// Whether segments are still judged (not after a failure stopped the test).
    judging: bool,
    faults: Vec<(usize, Duration)>,
    /// The faults, sent at their places.
    placer: Placer,
    stopping: Stopping,
    abort: Option<Abort>,
    /// The test's time limit ([`AbortReason::TimeLimit`]).
    time_limit: Duration,
    /// Details of the stop or its end, for the abort's text.
    detail: Option<String>,
    actions: Vec<Action>,
}

/// A test's time limit: three times the time its route takes at its planned speeds, from the end
/// of the start route, and a minute.
fn time_limit(plan: &TestPlan, start: &[Waypoint]) -> Duration {
    let mut at = start.last().map(|w| w.position);
    let mut planned_s: f64 = 0.0;
    for (_, segment) in plan.segments() {
        for (point, &speed) in segment.points.iter().zip(&segment.speeds) {
            if let Some(from) = at
                && speed > 0.0
            {
                planned_s += from.dist(*point) / speed;
            }
            at = Some(*point);
        }
    }
    Duration::from_secs_f64((3.0 * planned_s + 60.0).min(1e9))
}

impl<'a> TestDrive<'a> {
    /// A drive of `plan` for a car that has `start` (see [`start_route`]) and stands at its
    /// beginning; the test's clock starts now (`Duration::ZERO`). `generation`: the measured
    /// generation time of one segment, fed to the lead time.
    pub fn new(
        settings: DriveSettings<'a>,
        plan: &'a TestPlan,
        start: &[Waypoint],
        generation: Duration,
    ) -> Self {
        let mut streamer = Streamer::new(settings.streaming, start);
        streamer.delays_mut().generation(generation);
        let mut safety = SafetyMonitor::new(settings.area.clone(), settings.safety, Duration::ZERO);
        let positions: Vec<Point> = start.iter().map(|w| w.position).collect();
        safety.set_route(&positions);
        let placer = Placer::new(plan, start, settings.steering);
        Self {
            settings,
            plan,
            phase: Phase::Commands,
            streamer,
            safety,
            route: RouteSent {
                len: start.len(),
                tail: plan.start_tail,
                stop_first: None,
            },
            cursor: Cursor::default(),
            segments: Vec::new(),
            judging: true,
            faults: Vec::new(),
            placer,
            stopping: Stopping::default(),
            abort: None,
            time_limit: time_limit(plan, start),
            detail: None,
            actions: Vec::new(),
        }
    }

    /// Ends the drive before the car started (the start route could not be sent): with `abort`
    /// as the stop, or none when the campaign ends with an error.
    pub fn end_before_start(&mut self, abort: Option<Abort>) {
        if let Some(abort) = abort {
            self.abort = Some(abort);
        }
        self.phase = Phase::Done;
    }

    /// The drive's phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Whether the drive is over.
    pub fn is_done(&self) -> bool {
        self.phase == Phase::Done
    }

    /// Whether an interrupt still counts (no stop has been demanded yet).
    pub fn interruptible(&self) -> bool {
        self.abort.is_none()
    }

    /// The stop demanded, if any.
    pub fn abort(&self) -> Option<Abort> {
        self.abort
    }

    /// The next operation to start at `now`, if it is time for one (see the module doc); `None`
    /// while one is in flight. May begin braking (an extension that cannot be generated): the
    /// brake command is then due with the actions of the next event.
    pub fn next_operation(&mut self, now: Duration, link: LinkStatus) -> Option<Operation> {
        if self.cursor.in_flight.is_some() {
            return None;
        }
        match self.phase {
            Phase::Commands => self.next_command(now, link),
            Phase::StopPending => self.extension(now),
            _ => None,
        }
    }

    /// The next fault command to start at `now`, if one is due (see [`Placer`]; call again for
    /// the next); `None` once the test is stopping for a failure or a stop demanded.
    pub fn next_fault(&mut self, now: Duration) -> Option<Operation> {
        if !self.faults_wanted() {
            return None;
        }
        let (command_index, fault) = self.placer.take_due(now)?;
        // Faults on this probe the car confirmed in this test (the reset cleared the others), and
        // those sent before this one and still in flight: the car adds in the order it receives.
        let earlier_in_flight = self.placer.in_flight_on(&fault.probe).saturating_sub(1);
        let on_probe = earlier_in_flight
            + self
                .faults
                .iter()
                .filter(|(i, _)| {
                    self.plan.commands[*i]
                        .fault()
                        .is_some_and(|f| f.probe == fault.probe)
                })
                .count();
        Some(Operation::AddFault {
            command_index,
            fault,
            on_probe,
        })
    }

    /// When the next fault is due (time since the test began): wake the drive then and ask
    /// [`Self::next_fault`].
    pub fn fault_due(&self) -> Option<Duration> {
        if self.faults_wanted() {
            self.placer.due()
        } else {
            None
        }
    }

    /// Faults are sent while the test runs its plan to the end: not after a failure stopped it,
    /// a stop was demanded, or braking began.
    fn faults_wanted(&self) -> bool {
        self.judging && self.abort.is_none() && !matches!(self.phase, Phase::Braking | Phase::Done)
    }

    /// The time generating the safe stop's extension took (measured around the
    /// [`Self::next_operation`] call that returned [`Operation::AppendStop`]): a generation time
    /// for the lead time.
    pub fn extension_generated_in(&mut self, generation: Duration) {
        self.streamer.delays_mut().generation(generation);
    }

    /// Feeds `event` at `now`; returns what to do, in order.
    pub fn handle(&mut self, now: Duration, event: Event) -> Vec<Action> {
        match event {
            Event::Interrupt => {
                let abort = self.safety.stop(AbortReason::Interrupted, now);
                self.on_abort(abort, now);
            }
            Event::Reply(reply) => {
                if let Some(op) = self.cursor.in_flight.take() {
                    self.op_done(op, reply, now);
                }
            }
            Event::FaultReply {
                command_index,
                reply,
                resent,
            } => self.fault_done(command_index, reply, resent, now),
            Event::Sample(sample) => self.on_sample(now, sample),
            Event::LinkLost => {
                let abort = self.safety.link_lost(now);
                self.on_abort(abort, now);
            }
            Event::Tick => self.on_tick(now),
            Event::BrakedAtOnce => {
                let abort = self.safety.stop(AbortReason::Interrupted, now);
                self.on_abort(abort, now);
                self.detail = Some(match self.detail.take() {
                    Some(before) => format!("{before}; {BRAKED_AT_ONCE}"),
                    None => BRAKED_AT_ONCE.to_owned(),
                });
                self.phase = Phase::Done;
            }
        }
        if matches!(self.phase, Phase::Braking | Phase::Done)
            && self.cursor.in_flight.take().is_some()
        {
            self.actions.push(Action::Abandon);
        }
        if matches!(self.phase, Phase::Braking | Phase::Done) && self.placer.in_flight() {
            self.placer.dropped_all();
            self.actions.push(Action::AbandonFault);
        }
        if std::mem::take(&mut self.stopping.brake_now) {
            self.actions.push(Action::Brake);
        }
        std::mem::take(&mut self.actions)
    }

    /// Ends the drive at `now`: the segment being driven is judged on what was seen of it.
    pub fn finish(mut self, now: Duration) -> DriveOutcome {
        if self.judging {
            for j in 0..self.segments.len() {
                if self.segments[j].result.is_none() && self.segments[j].entered.is_some() {
                    self.judge(j, now);
                }
            }
        }
        let abort_text = self.abort.map(|a| match &self.detail {
            Some(detail) => format!("{}: {detail}", a.reason),
            None => a.reason.to_string(),
        });
        DriveOutcome {
            segments: self.results(),
            abort: self.abort,
            abort_text,
            streaming: self.streaming_record(),
            faults_confirmed: self.faults,
            fault_places: self.placer.placements().to_vec(),
        }
    }

    fn on_sample(&mut self, now: Duration, sample: Sample) {
        self.streamer.delays_mut().round_trip(sample.round_trip);
        // GET_STATE carries no fix type (`docs/firmware.md#fused-position`): the fused position is
        // the reference.
        let car = CarSample {
            position: sample.rtk,
            rtk_fix: true,
        };
        if let Some(abort) = self.safety.sample(now, car) {
            self.on_abort(abort, now);
        }
        let decision = self.streamer.observe(now, sample.rtk);
        self.cursor.decision = Some(decision);
        self.placer.observe(now, &sample, self.streamer.progress());
        self.track(now, sample.uwb, sample.rtk);
        self.advance_stop(now, decision, sample.speed);
    }

    fn advance_stop(&mut self, now: Duration, decision: Decision, speed: f64) {
        let stopped = speed.abs() < STOPPED_SPEED_MPS;
        match self.phase {
            Phase::Commands if decision.starved => {
                let abort = self.safety.stop(AbortReason::Starved, now);
                self.on_abort(abort, now);
            }
            Phase::Rolling if decision.time_to_end <= ROLL_END || stopped => {
                self.begin_braking(now);
            }
            Phase::Braking if stopped => self.phase = Phase::Done,
            Phase::Braking => self.stopping.brake_now = true,
            _ => {}
        }
    }

    fn on_tick(&mut self, now: Duration) {
        if let Some(abort) = self.safety.tick(now) {
            self.on_abort(abort, now);
        }
        if matches!(self.phase, Phase::Commands | Phase::Rolling) && now > self.time_limit {
            let limit_s = self.time_limit.as_secs_f64();
            let abort = self.safety.stop(AbortReason::TimeLimit { limit_s }, now);
            self.on_abort(abort, now);
        }
        let late = self.stopping.brake_deadline.is_some_and(|d| now >= d);
        if self.phase == Phase::Braking && late {
            self.detail
                .get_or_insert_with(|| "the car did not stop within 5 s of braking".to_owned());
            self.phase = Phase::Done;
        }
    }

    /// The first stop demanded wins; a lost link ends the drive at once.
    fn on_abort(&mut self, abort: Abort, now: Duration) {
        if self.abort.is_some() || self.phase == Phase::Done {
            return;
        }
        self.abort = Some(abort);
        self.actions.push(Action::Stop(abort));
        if abort.reason == AbortReason::LinkLost {
            self.phase = Phase::Done;
            return;
        }
        match abort.action {
            StopAction::SafeStop => self.begin_stop(),
            StopAction::Brake => self.begin_braking(now),
        }
    }

    fn begin_stop(&mut self) {
        if self.phase == Phase::Commands {
            self.phase = Phase::StopPending;
        }
    }

    fn begin_braking(&mut self, now: Duration) {
        if matches!(self.phase, Phase::Braking | Phase::Done) {
            return;
        }
        self.stopping.began.get_or_insert(now);
        self.phase = Phase::Braking;
        self.stopping.brake_now = true;
        self.stopping.brake_deadline = Some(now.saturating_add(BRAKE_TIMEOUT));
    }

    /// The next command to send, if it is time (see the module doc).
    fn next_command(&mut self, now: Duration, link: LinkStatus) -> Option<Operation> {
        let decision = self.cursor.decision?;
        let plan = self.plan;
        loop {
            let Some(command) = plan.commands.get(self.cursor.command) else {
                self.begin_stop();
                return self.extension(now);
            };
            match command {
                // Faults are sent at their places, beside the segments (`next_fault`).
                Command::AddFault(_) => self.cursor.command += 1,
                Command::RunSegments(_) if self.cursor.appended == Some(self.cursor.command) => {
                    let next = self.cursor.command + 1;
                    if decision.time_to_end > self.lead(decision, next, link) {
                        return None;
                    }
                    self.cursor.command = next;
                    self.cursor.appended = None;
                }
                Command::RunSegments(segment) => {
                    let lead = self.lead(decision, self.cursor.command, link);
                    if decision.time_to_end > lead {
                        return None;
                    }
                    return Some(self.append_op(now, Decision { lead, ..decision }, segment));
                }
            }
        }
    }

    /// The lead time before the next segment from command `from` on: the streamer's, plus a
    /// round trip for every extra packet of it, plus one request timeout (a retry) once the link
    /// has shown it loses packets. Fault commands do not delay a segment: they are sent beside
    /// it, at their places.
    fn lead(&self, decision: Decision, from: usize, link: LinkStatus) -> Duration {
        let commands = self.plan.commands.get(from..).unwrap_or_default();
        let packets = commands
            .iter()
            .find_map(Command::segment)
            .map_or(1, |s| s.points.len().div_ceil(POINTS_PER_PACKET));
        let rtt = link
            .rtt_p99
            .unwrap_or(self.settings.streaming.initial_round_trip);
        let extra = u32::try_from(packets.saturating_sub(1)).unwrap_or(u32::MAX);
        let retry = if link.lossy {
            link.request_timeout
        } else {
            Duration::ZERO
        };
        decision
            .lead
            .saturating_add(rtt.saturating_mul(extra))
            .saturating_add(retry)
    }

    fn append_op(&mut self, now: Duration, decision: Decision, segment: &Segment) -> Operation {
        let command_index = self.cursor.command;
        let points: Vec<Waypoint> = segment.waypoints().collect();
        let append = self.streamer.appended(now, &decision, &points);
        self.safety.extend_route(&segment.points);
        self.segments.push(AppendedSegment {
            command_index,
            first: self.route.len,
            entered: None,
            left: None,
            oracle: SegmentOracle::new(),
            result: None,
        });
        self.placer.extend(&segment.waypoints().collect::<Vec<_>>());
        self.placer
            .segment_appended(self.segments.len() - 1, self.route.len, points.len());
        self.route.len += points.len();
        self.route.tail = self.route.tail.advanced(&segment.points);
        self.cursor.appended = Some(command_index);
        // The route changed: the next decision waits for a sample located on the new route.
        self.cursor.decision = None;
        self.cursor.in_flight = Some(InFlight::Segment { append });
        Operation::AppendSegment {
            command_index,
            points,
        }
    }

    /// The safe stop's slow extension, generated with the ahead margin from the route's end;
    /// braking at once when none can be generated.
    fn extension(&mut self, now: Duration) -> Option<Operation> {
        let count = self.settings.stop_points.max(1);
        let test_index = self.plan.test_index;
        let mut rng = rng_for(
            self.settings.campaign_seed,
            Purpose::SafeStop { test_index },
        );
        let extension = match self.settings.generator.extend(
            self.settings.area,
            &self.route.tail,
            count,
            &mut rng,
        ) {
            Ok(extension) => extension,
            Err(error) => {
                self.detail = Some(format!("no safe stop extension: {error}"));
                self.begin_braking(now);
                return None;
            }
        };
        let points: Vec<Waypoint> = extension
            .points
            .iter()
            .map(|&position| Waypoint {
                position,
                speed: SAFE_STOP_SPEED_MPS,
            })
            .collect();
        let decision = self.cursor.decision.unwrap_or(Decision {
            time_to_end: Duration::ZERO,
            lead: Duration::ZERO,
            append: true,
            starved: false,
        });
        let append = self.streamer.appended(now, &decision, &points);
        self.safety.extend_route(&extension.points);
        self.placer.extend(&points);
        self.route.stop_first = Some(self.route.len);
        self.route.len += points.len();
        self.phase = Phase::Extending;
        self.cursor.in_flight = Some(InFlight::Extension { append });
        Some(Operation::AppendStop { points })
    }

    fn op_done(&mut self, op: InFlight, reply: Reply, now: Duration) {
        match (op, reply) {
            (_, Reply::LinkLost) => {
                let abort = self.safety.link_lost(now);
                self.on_abort(abort, now);
            }
            (InFlight::Segment { append }, Reply::Done) => self.streamer.confirmed(append, now),
            (InFlight::Extension { append }, Reply::Done) => {
                self.streamer.confirmed(append, now);
                if self.phase == Phase::Extending {
                    self.phase = Phase::Rolling;
                    self.stopping.began.get_or_insert(now);
                }
            }
            (InFlight::Extension { .. }, Reply::Failed(error)) => {
                self.detail = Some(format!("the safe stop extension failed: {error}"));
                self.begin_braking(now);
            }
            (InFlight::Segment { .. }, Reply::Failed(error)) => {
                let command_index = self.cursor.command;
                self.detail = Some(format!("command {command_index}: {error}"));
                let abort = self
                    .safety
                    .stop(AbortReason::CommandRefused { command_index }, now);
                self.on_abort(abort, now);
            }
        }
    }

    fn fault_done(&mut self, command_index: usize, reply: Reply, resent: bool, now: Duration) {
        match reply {
            Reply::Done => {
                if let Some(added) =
                    self.placer
                        .confirmed(command_index, now, resent, &self.settings.rates)
                {
                    self.faults.push(added);
                }
            }
            Reply::LinkLost => {
                self.placer.dropped(command_index);
                let abort = self.safety.link_lost(now);
                self.on_abort(abort, now);
            }
            Reply::Failed(error) => {
                self.placer.dropped(command_index);
                self.detail = Some(format!("command {command_index}: {error}"));
                let abort = self
                    .safety
                    .stop(AbortReason::CommandRefused { command_index }, now);
                self.on_abort(abort, now);
            }
        }
    }

    /// Feeds the sample to the segment the car drives; judges the segments it has left.
    fn track(&mut self, now: Duration, uwb: Point, rtk: Point) {
        if !self.judging {
            return;
        }
        match self.region(self.streamer.progress().segment) {
            Region::Start => {}
            Region::Segment(k) => {
                self.close_segments_before(k, now);
                if self.judging {
                    let segment = &mut self.segments[k];
                    segment.entered.get_or_insert(now);
                    segment.oracle.push(uwb, rtk);
                }
            }
            Region::Stop => self.close_segments_before(self.segments.len(), now),
        }
    }

    /// The region of the route's stretch `stretch` (from point `stretch` to `stretch + 1`).
    fn region(&self, stretch: usize) -> Region {
        if self
            .route
            .stop_first
            .is_some_and(|first| stretch + 1 >= first)
        {
            return Region::Stop;
        }
        match self.segments.iter().rposition(|s| s.first <= stretch + 1) {
            Some(k) => Region::Segment(k),
            None => Region::Start,
        }
    }

    fn close_segments_before(&mut self, k: usize, now: Duration) {
        for j in 0..k.min(self.segments.len()) {
            if self.segments[j].result.is_some() {
                continue;
            }
            let verdict = self.judge(j, now);
            if !self.settings.policy.continue_after(verdict) {
                self.judging = false;
                self.begin_stop();
                return;
            }
        }
    }

    fn judge(&mut self, j: usize, now: Duration) -> SegmentVerdict {
        let threshold = self.settings.oracle_threshold_m;
        let segment = &mut self.segments[j];
        segment.left = Some(now);
        let outcome = segment.oracle.result(threshold);
        segment.result = Some(outcome);
        outcome.verdict
    }

    fn results(&self) -> Vec<SegmentResult> {
        self.segments
            .iter()
            .enumerate()
            .filter_map(|(segment_index, segment)| {
                let oracle = segment.result?;
                Some(SegmentResult {
                    segment_index,
                    command_index: segment.command_index,
                    faults_preceding: self.plan.faults_before(segment.command_index),
                    faults_active: self.faults_active(segment),
                    oracle,
                })
            })
            .collect()
    }

    /// The faults estimated to apply while `segment` was driven.
    fn faults_active(&self, segment: &AppendedSegment) -> Vec<usize> {
        let (Some(from), Some(to)) = (segment.entered, segment.left) else {
            return Vec::new();
        };
        self.faults
            .iter()
            .filter(|&&(command, added_at)| {
                self.plan.commands[command].fault().is_some_and(|fault| {
                    FaultWindow::of(fault, added_at, &self.settings.rates).overlaps(from, to)
                })
            })
            .map(|&(command, _)| command)
            .collect()
    }

    /// The appends and the starvation events of the test proper: the car reaching the end of
    /// the safe stop's extension (or braking to a stop) is the stop, not a starvation.
    fn streaming_record(&self) -> StreamingRecord {
        let began = self.stopping.began;
        let during_test = |at: &&Duration| began.is_none_or(|stop| **at < stop);
        StreamingRecord {
            appends: self.streamer.appends().iter().map(|&a| a.into()).collect(),
            starvations_ms: self
                .streamer
                .starvations()
                .iter()
                .filter(during_test)
                .map(|d| u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
                .collect(),
            smallest_margin_s: self.streamer.smallest_margin_s(),
        }
    }
}

mod place;
#[cfg(test)]
mod tests;

pub use place::{EARLIER_TOOL_POINTS_LEFT, FaultPlacement, PlaceRule, Placer, Steering};
