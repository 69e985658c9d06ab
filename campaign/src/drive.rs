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

use crate::case::{Case, SegmentResult, StreamingRecord};
use crate::model::{Command, Fault, FaultWindow, ProbeRates, Segment, TestPlan, test_rng_seed};
use crate::oracle::{
    FailurePolicy, JudgedSegment, SegmentOracle, SegmentOutcome, SegmentVerdict, test_verdict,
};
use crate::safety::{Abort, AbortReason, CarSample, SafetyConfig, SafetyMonitor, StopAction};
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
    /// The operation in flight ended.
    Reply(Reply),
    /// The monitor's tick (at the state rate, also when no sample comes).
    Tick,
    /// The operator interrupted the campaign.
    Interrupt,
    /// The link to the car is lost (the telemetry ended, or the brake command found it lost).
    LinkLost,
}

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
        /// Faults on the same probe that the car confirmed in this test: one more on the
        /// probe when the car lists its faults means a command whose reply was lost took
        /// effect.
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
    /// The fault commands the car confirmed (their command indices), and when.
    pub faults_confirmed: Vec<(usize, Duration)>,
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
    /// The fault of command `command`.
    Fault { command: usize },
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
    stopping: Stopping,
    abort: Option<Abort>,
    /// Details of the stop or its end, for the abort's text.
    detail: Option<String>,
    actions: Vec<Action>,
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
            stopping: Stopping::default(),
            abort: None,
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
            Event::Sample(sample) => self.on_sample(now, sample),
            Event::LinkLost => {
                let abort = self.safety.link_lost(now);
                self.on_abort(abort, now);
            }
            Event::Tick => self.on_tick(now),
        }
        if matches!(self.phase, Phase::Braking | Phase::Done)
            && self.cursor.in_flight.take().is_some()
        {
            self.actions.push(Action::Abandon);
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
                Command::AddFault(fault) => return Some(self.fault_op(*fault)),
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

    /// The lead time before the commands from `from` to the next segment: the streamer's, plus
    /// a round trip for every fault command before that segment and every extra packet of it,
    /// plus one request timeout (a retry) once the link has shown it loses packets.
    fn lead(&self, decision: Decision, from: usize, link: LinkStatus) -> Duration {
        let commands = self.plan.commands.get(from..).unwrap_or_default();
        let faults = commands.iter().take_while(|c| c.fault().is_some()).count();
        let packets = commands
            .iter()
            .find_map(Command::segment)
            .map_or(1, |s| s.points.len().div_ceil(POINTS_PER_PACKET));
        let rtt = link
            .rtt_p99
            .unwrap_or(self.settings.streaming.initial_round_trip);
        let extra = u32::try_from(faults + packets.saturating_sub(1)).unwrap_or(u32::MAX);
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

    fn fault_op(&mut self, fault: Fault) -> Operation {
        let command_index = self.cursor.command;
        // Faults on this probe the car confirmed in this test (the reset cleared the others).
        let on_probe = self
            .faults
            .iter()
            .filter(|(i, _)| {
                self.plan.commands[*i]
                    .fault()
                    .is_some_and(|f| f.probe == fault.probe)
            })
            .count();
        self.cursor.in_flight = Some(InFlight::Fault {
            command: command_index,
        });
        Operation::AddFault {
            command_index,
            fault,
            on_probe,
        }
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
        let mut rng =
            crate::seed::rng(stop_seed(self.settings.campaign_seed, self.plan.test_index));
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
            (InFlight::Fault { command }, Reply::Done) => {
                self.faults.push((command, now));
                self.cursor.command += 1;
            }
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
            (InFlight::Segment { .. } | InFlight::Fault { .. }, Reply::Failed(error)) => {
                let command_index = self.cursor.command;
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
            appends: self.streamer.appends().to_vec(),
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

/// The seed of test `test_index`'s safe stop extension.
fn stop_seed(campaign_seed: u64, test_index: usize) -> u64 {
    let seed = test_rng_seed(campaign_seed, test_index);
    let mut last = [0u8; 8];
    last.copy_from_slice(&seed[24..]);
    u64::from_le_bytes(last)
}

#[cfg(test)]
mod tests {
    use trajgen::Polygon;

    use super::*;
    use crate::model::{FaultKind, Probe};
    use crate::oracle::Verdict;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    /// A 40 m × 20 m rectangle.
    fn area() -> Area {
        let fence = Polygon::new(vec![
            Point::new(0.0, 0.0),
            Point::new(40.0, 0.0),
            Point::new(40.0, 20.0),
            Point::new(0.0, 20.0),
        ])
        .unwrap();
        Area::new(fence, vec![]).unwrap()
    }

    /// Points every 2 m along y = 10 from `from` to `to` (inclusive).
    fn along(from: f64, to: f64) -> Vec<Point> {
        let n = ((to - from) / 2.0).round() as usize;
        (0..=n)
            .map(|i| Point::new(from + 2.0 * i as f64, 10.0))
            .collect()
    }

    /// The start route: x = 2 … 10 at 1 m/s.
    fn start() -> Vec<Waypoint> {
        along(2.0, 10.0)
            .into_iter()
            .map(|position| Waypoint {
                position,
                speed: 1.0,
            })
            .collect()
    }

    /// A hand-written segment of 4 points at 1 m/s from `from` on.
    fn segment(from: f64) -> Command {
        let points = along(from, from + 6.0);
        Command::RunSegments(Segment {
            intent: None,
            speeds: vec![1.0; points.len()],
            points,
            margin: Vec::new(),
        })
    }

    fn fault(probe: Probe) -> Command {
        Command::AddFault(Fault {
            probe,
            kind: FaultKind::Offset,
            param: 2.0,
            start: 0,
            duration: 50,
        })
    }

    fn plan(commands: Vec<Command>) -> TestPlan {
        let positions: Vec<Point> = start().iter().map(|w| w.position).collect();
        TestPlan {
            test_index: 0,
            start_tail: RouteTail::from_points(&positions).unwrap(),
            commands,
        }
    }

    fn settings(area: &Area, policy: FailurePolicy) -> DriveSettings<'_> {
        DriveSettings {
            area,
            generator: Generator::default(),
            safety: SafetyConfig::default(),
            streaming: StreamingConfig::default(),
            policy,
            oracle_threshold_m: 1.0,
            stop_points: 4,
            rates: ProbeRates::firmware_10(2),
            campaign_seed: 7,
        }
    }

    const LINK: LinkStatus = LinkStatus {
        rtt_p99: Some(Duration::from_millis(20)),
        lossy: false,
        request_timeout: Duration::from_secs(1),
    };

    /// A drive on the straight route, fed with samples every 50 ms (round trips of 20 ms, so
    /// the lead time is 20 ms + 0 ms generation + 1 s margin).
    struct Harness<'a> {
        drive: TestDrive<'a>,
        now: Duration,
        /// The UWB estimate's offset from RTK (north), metres.
        uwb_offset: f64,
    }

    impl<'a> Harness<'a> {
        fn new(area: &'a Area, plan: &'a TestPlan, policy: FailurePolicy) -> Self {
            let drive = TestDrive::new(settings(area, policy), plan, &start(), Duration::ZERO);
            Self {
                drive,
                now: Duration::ZERO,
                uwb_offset: 0.0,
            }
        }

        /// One sample 50 ms after the last, of the car at `at` driving at `speed`.
        fn sample_at(&mut self, at: Point, speed: f64) -> Vec<Action> {
            self.now += ms(50);
            let sample = Sample {
                rtk: at,
                uwb: Point::new(at.x, at.y + self.uwb_offset),
                speed,
                round_trip: ms(20),
            };
            self.drive.handle(self.now, Event::Sample(sample))
        }

        /// One sample of the car at `x` on y = 10, at 1 m/s.
        fn sample(&mut self, x: f64) -> Vec<Action> {
            self.sample_at(Point::new(x, 10.0), 1.0)
        }

        fn next(&mut self) -> Option<Operation> {
            self.drive.next_operation(self.now, LINK)
        }

        fn reply(&mut self, reply: Reply) -> Vec<Action> {
            self.drive.handle(self.now, Event::Reply(reply))
        }

        /// Drives along y = 10 from `from` to `to` at 1 m/s, starting every operation that is
        /// due at once and confirming it at once; the operations, in order.
        fn drive_to(&mut self, from: f64, to: f64) -> Vec<Operation> {
            let mut sent = Vec::new();
            let mut x = from;
            while x <= to + 1e-9 {
                let actions = self.sample(x);
                assert!(actions.is_empty(), "at x = {x}: {actions:?}");
                while let Some(op) = self.next() {
                    sent.push(op);
                    if self.drive.phase() != Phase::Extending {
                        assert!(self.reply(Reply::Done).is_empty());
                    }
                }
                x += 0.05;
            }
            sent
        }
    }

    fn append_index(op: &Operation) -> Option<usize> {
        match op {
            Operation::AppendSegment { command_index, .. } => Some(*command_index),
            _ => None,
        }
    }

    #[test]
    fn nothing_is_sent_before_the_first_sample() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        assert_eq!(h.next(), None);
        assert_eq!(h.drive.phase(), Phase::Commands);
        assert!(h.sample(2.0).is_empty());
        assert_eq!(h.next(), None, "6.7 s from the stopping point");
    }

    #[test]
    fn the_first_segment_is_appended_when_the_time_to_the_end_falls_to_the_lead_time() {
        let (area, plan) = (area(), plan(vec![segment(12.0), segment(20.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        // The car stops 1.323 m before x = 10 (look-ahead at 1 m/s); the lead time is 1.02 s.
        h.sample(7.6);
        assert_eq!(h.next(), None, "1.077 s left");
        h.sample(7.7);
        let Some(Operation::AppendSegment {
            command_index,
            points,
        }) = h.next()
        else {
            panic!("no segment appended with 0.977 s left");
        };
        assert_eq!(command_index, 0);
        let xs: Vec<f64> = points.iter().map(|w| w.position.x).collect();
        assert_eq!(xs, [12.0, 14.0, 16.0, 18.0]);
        assert!(points.iter().all(|w| w.speed == 1.0));
        let outcome = h.drive.finish(h.now);
        assert_eq!(outcome.streaming.appends.len(), 1);
        assert_eq!(outcome.streaming.appends[0].lead, ms(1020));
        assert_eq!(outcome.streaming.appends[0].confirmed_after, None);
    }

    #[test]
    fn the_next_segment_waits_for_the_previous_one_to_be_confirmed() {
        let (area, plan) = (area(), plan(vec![segment(12.0), segment(20.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(7.7);
        assert_eq!(h.next().as_ref().and_then(append_index), Some(0));
        // Segment 0 is still on its way: nothing else goes out, however late it gets.
        h.sample(15.7);
        assert_eq!(h.next(), None);
        h.now += ms(30);
        assert!(h.reply(Reply::Done).is_empty());
        assert_eq!(h.next().as_ref().and_then(append_index), Some(1));
        let outcome = h.drive.finish(h.now);
        assert_eq!(outcome.streaming.appends[0].confirmed_after, Some(ms(80)));
    }

    #[test]
    fn after_an_append_the_next_decision_waits_for_a_sample() {
        let (area, plan) = (area(), plan(vec![segment(12.0), segment(20.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(7.7);
        assert!(h.next().is_some());
        assert!(h.reply(Reply::Done).is_empty());
        assert_eq!(h.next(), None, "no sample located on the new route yet");
        h.sample(7.75);
        assert_eq!(h.next(), None, "7.9 s left of the new route");
    }

    #[test]
    fn fault_commands_go_out_in_order_once_their_segment_is_done_and_confirmed() {
        let commands = vec![
            segment(12.0),
            fault(Probe::UwbYaw),
            fault(Probe::UwbYaw),
            segment(20.0),
        ];
        let (area, plan) = (area(), plan(commands));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(7.7);
        assert_eq!(h.next().as_ref().and_then(append_index), Some(0));
        assert!(h.reply(Reply::Done).is_empty());
        // Segment 0 ends at x = 18 (stopping point 16.677); two faults before segment 3 add two
        // round trips to the lead time: 1.06 s.
        h.sample(15.6);
        assert_eq!(h.next(), None, "1.077 s left");
        h.sample(15.7);
        let first = h.next();
        assert!(
            matches!(
                first,
                Some(Operation::AddFault {
                    command_index: 1,
                    on_probe: 0,
                    ..
                })
            ),
            "{first:?}"
        );
        assert_eq!(h.next(), None, "one operation at a time");
        h.now += ms(20);
        assert!(h.reply(Reply::Done).is_empty());
        let second = h.next();
        assert!(
            matches!(
                second,
                Some(Operation::AddFault {
                    command_index: 2,
                    on_probe: 1,
                    ..
                })
            ),
            "{second:?}"
        );
        h.now += ms(20);
        assert!(h.reply(Reply::Done).is_empty());
        assert_eq!(h.next().as_ref().and_then(append_index), Some(3));
        let outcome = h.drive.finish(h.now);
        assert_eq!(
            outcome.faults_confirmed,
            [(1, ms(170)), (2, ms(190))],
            "confirmed 20 ms after each was sent"
        );
    }

    #[test]
    fn a_lossy_link_sends_earlier_by_a_request_timeout() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(6.7);
        assert_eq!(h.next(), None, "1.977 s left");
        let lossy = LinkStatus {
            lossy: true,
            ..LINK
        };
        assert!(h.drive.next_operation(h.now, lossy).is_some());
    }

    #[test]
    fn the_default_policy_stops_at_the_first_failing_segment() {
        let commands = vec![segment(12.0), segment(20.0), segment(28.0)];
        let (area, plan) = (area(), plan(commands));
        let mut h = Harness::new(&area, &plan, FailurePolicy::StopAtFailingSegment);
        h.uwb_offset = 2.0;
        let sent = h.drive_to(7.0, 17.95);
        assert_eq!(
            sent.iter().filter_map(append_index).collect::<Vec<_>>(),
            [0, 1]
        );
        assert_eq!(h.drive.phase(), Phase::Commands);
        // Leaving segment 0 judges it: failed, so the safe stop begins.
        h.uwb_offset = 0.0;
        assert!(h.sample(18.05).is_empty());
        assert_eq!(h.drive.phase(), Phase::StopPending);
        let Some(Operation::AppendStop { points }) = h.next() else {
            panic!("no safe stop extension");
        };
        assert_eq!(points.len(), 4);
        assert!(points.iter().all(|w| w.speed == SAFE_STOP_SPEED_MPS));
        assert!(points.iter().all(|w| area.contains_point(w.position)));
        assert_eq!(h.drive.phase(), Phase::Extending);
        let outcome = h.drive.finish(h.now);
        assert_eq!(outcome.segments.len(), 1, "segment 1 is not judged");
        assert_eq!(outcome.segments[0].oracle.verdict, SegmentVerdict::Failed);
        assert_eq!(outcome.abort, None);
    }

    #[test]
    fn continue_and_record_judges_every_segment() {
        let commands = vec![segment(12.0), segment(20.0), segment(28.0)];
        let (area, plan) = (area(), plan(commands));
        let mut h = Harness::new(&area, &plan, FailurePolicy::ContinueAndRecord);
        h.uwb_offset = 2.0;
        h.drive_to(7.0, 17.95);
        h.uwb_offset = 0.5;
        let sent = h.drive_to(18.0, 27.0);
        assert_eq!(
            sent.iter().filter_map(append_index).collect::<Vec<_>>(),
            [2]
        );
        assert_eq!(h.drive.phase(), Phase::Commands);
        // Segment 2, being driven, is judged on what was seen of it.
        let outcome = h.drive.finish(h.now);
        let verdicts: Vec<SegmentVerdict> =
            outcome.segments.iter().map(|s| s.oracle.verdict).collect();
        assert_eq!(
            verdicts,
            [
                SegmentVerdict::Failed,
                SegmentVerdict::Passed,
                SegmentVerdict::Passed
            ]
        );
        let commands: Vec<usize> = outcome.segments.iter().map(|s| s.command_index).collect();
        assert_eq!(commands, [0, 1, 2]);
    }

    #[test]
    fn an_interrupt_demands_the_safe_stop_once() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(5.0);
        assert!(h.drive.interruptible());
        let actions = h.drive.handle(h.now, Event::Interrupt);
        let [Action::Stop(abort)] = actions[..] else {
            panic!("{actions:?}");
        };
        assert_eq!(abort.reason, AbortReason::Interrupted);
        assert_eq!(abort.action, StopAction::SafeStop);
        assert!(!h.drive.interruptible());
        assert_eq!(h.drive.phase(), Phase::StopPending);
        assert!(matches!(h.next(), Some(Operation::AppendStop { .. })));
        // A second stop is not recorded again.
        assert!(h.drive.handle(h.now, Event::Interrupt).is_empty());
        assert_eq!(h.drive.abort(), Some(abort));
    }

    #[test]
    fn a_starving_car_demands_the_safe_stop() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(8.0);
        let actions = h.sample(8.7);
        assert!(
            matches!(
                actions[..],
                [Action::Stop(Abort {
                    reason: AbortReason::Starved,
                    ..
                })]
            ),
            "{actions:?}"
        );
        assert_eq!(h.drive.phase(), Phase::StopPending);
    }

    #[test]
    fn a_braking_abort_abandons_the_operation_in_flight_and_brakes() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(7.7);
        assert!(h.next().is_some());
        let actions = h.sample_at(Point::new(7.75, 12.0), 1.0);
        let [Action::Stop(abort), Action::Abandon, Action::Brake] = actions[..] else {
            panic!("{actions:?}");
        };
        assert!(matches!(abort.reason, AbortReason::OffRoute { .. }));
        assert_eq!(h.drive.phase(), Phase::Braking);
        assert_eq!(h.next(), None);
    }

    #[test]
    fn a_lost_link_ends_the_drive_at_once() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(5.0);
        let actions = h.drive.handle(h.now, Event::LinkLost);
        assert!(
            matches!(
                actions[..],
                [Action::Stop(Abort {
                    reason: AbortReason::LinkLost,
                    ..
                })]
            ),
            "{actions:?}"
        );
        assert!(h.drive.is_done());
        let outcome = h.drive.finish(h.now);
        assert_eq!(outcome.abort_text.as_deref(), Some("link lost"));
        // So does a command that finds it lost, abandoning nothing (the answer came).
        let (area, plan) = (self::area(), self::plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(7.7);
        assert!(h.next().is_some());
        let actions = h.reply(Reply::LinkLost);
        assert!(matches!(actions[..], [Action::Stop(_)]), "{actions:?}");
        assert!(h.drive.is_done());
    }

    #[test]
    fn a_refused_command_brakes_with_the_reason() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(7.7);
        assert!(h.next().is_some());
        let actions = h.reply(Reply::Failed("no reply".to_owned()));
        assert!(
            matches!(
                actions[..],
                [
                    Action::Stop(Abort {
                        reason: AbortReason::CommandRefused { command_index: 0 },
                        ..
                    }),
                    Action::Brake
                ]
            ),
            "{actions:?}"
        );
        let outcome = h.drive.finish(h.now);
        assert_eq!(
            outcome.abort_text.as_deref(),
            Some("command 0 failed: command 0: no reply")
        );
    }

    #[test]
    fn the_safe_stop_rolls_out_the_extension_then_brakes_until_the_car_stands() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        let sent = h.drive_to(7.0, 15.7);
        assert_eq!(sent.len(), 2, "{sent:?}");
        let Operation::AppendStop { points } = &sent[1] else {
            panic!("{sent:?}");
        };
        // The plan is done: its extension is on its way.
        assert_eq!(h.drive.phase(), Phase::Extending);
        assert!(h.reply(Reply::Done).is_empty());
        assert_eq!(h.drive.phase(), Phase::Rolling);
        // Still rolling on the extension, then at its end: brake.
        assert!(h.sample_at(points[0].position, 0.8).is_empty());
        let end = points[points.len() - 1].position;
        assert_eq!(h.sample_at(end, 0.8), [Action::Brake]);
        assert_eq!(h.drive.phase(), Phase::Braking);
        assert_eq!(h.sample_at(end, 0.3), [Action::Brake]);
        assert!(h.sample_at(end, 0.05).is_empty());
        assert!(h.drive.is_done());
        let outcome = h.drive.finish(h.now);
        assert_eq!(outcome.abort, None);
        assert_eq!(outcome.segments.len(), 1);
        assert_eq!(outcome.segments[0].oracle.verdict, SegmentVerdict::Passed);
        assert_eq!(outcome.streaming.appends.len(), 2);
        assert!(outcome.streaming.starvations_ms.is_empty());
    }

    #[test]
    fn the_safe_stop_brakes_at_once_when_the_car_already_stands() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(5.0);
        h.drive.handle(h.now, Event::Interrupt);
        assert!(matches!(h.next(), Some(Operation::AppendStop { .. })));
        assert!(h.reply(Reply::Done).is_empty());
        assert_eq!(h.sample_at(Point::new(5.0, 10.0), 0.0), [Action::Brake]);
        assert_eq!(h.drive.phase(), Phase::Braking);
    }

    #[test]
    fn braking_gives_up_after_5_s() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.sample(5.0);
        let actions = h.sample_at(Point::new(5.05, 13.0), 1.0);
        assert_eq!(actions.len(), 2, "{actions:?}");
        let braking_at = h.now;
        while h.now + ms(50) < braking_at + BRAKE_TIMEOUT {
            assert_eq!(h.sample_at(Point::new(5.05, 13.0), 1.0), [Action::Brake]);
            assert!(h.drive.handle(h.now, Event::Tick).is_empty());
        }
        assert!(!h.drive.is_done());
        h.now = braking_at + BRAKE_TIMEOUT;
        assert!(h.drive.handle(h.now, Event::Tick).is_empty());
        assert!(h.drive.is_done());
        let text = h.drive.finish(h.now).abort_text.unwrap();
        assert!(
            text.ends_with(
                "off the planned route at (5.05, 13.00): the car did not stop within 5 s of braking"
            ),
            "{text}"
        );
    }

    #[test]
    fn a_drive_stopped_before_the_start_is_aborted_with_no_segment() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let mut h = Harness::new(&area, &plan, FailurePolicy::default());
        h.drive
            .end_before_start(Some(Abort::new(AbortReason::LinkLost, Duration::ZERO)));
        assert!(h.drive.is_done());
        let outcome = h.drive.finish(Duration::ZERO);
        assert!(outcome.segments.is_empty());
        assert_eq!(outcome.abort_text.as_deref(), Some("link lost"));
        let judged: Vec<JudgedSegment> = Vec::new();
        assert_eq!(
            test_verdict(&judged, outcome.abort_text.as_deref()).verdict,
            Verdict::Aborted
        );
    }

    #[test]
    fn the_safe_stop_extension_is_the_same_for_the_same_seed() {
        let (area, plan) = (area(), plan(vec![segment(12.0)]));
        let extension = || {
            let mut h = Harness::new(&area, &plan, FailurePolicy::default());
            h.sample(5.0);
            h.drive.handle(h.now, Event::Interrupt);
            h.next()
        };
        assert_eq!(extension(), extension());
    }
}
