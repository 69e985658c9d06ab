//! The test drive: the start route, the planned commands streamed to the car, the oracle and the
//! safety monitor at the state rate, and the safe stop.
//!
//! One loop waits for whichever comes first: the operator's interrupt, the reply to the command
//! in flight (one at a time, in plan order), a state sample, or the monitor's tick. Commands run
//! as the method says (§6): a `RunSegments` is appended when the time the car needs to reach its
//! stopping point falls to the lead time, and it is done when that happens again for the next
//! command (the car is almost at the segment's end); the fault commands after it are sent then,
//! each confirmed by its reply, and the lead time grows by a round trip for each of them and for
//! each extra packet of the next segment. Samples are assigned to the segment the car drives
//! (from where the streamer locates it on the route); a segment is judged when the car leaves
//! it. The first failing segment ends the test under the default policy.
//!
//! Recorded in the campaign's journal as they happen: every command with its answer (fault
//! commands as sent and confirmed or refused), every state sample, and the first stop demanded.

use std::future::Future;
use std::pin::Pin;
use std::time::Duration;

use car_link::fault::FaultError;
use car_link::message::POINTS_PER_PACKET;
use car_link::{Car, CarError, RoutePoint, StateSample};
use tokio::time::{Instant, MissedTickBehavior};
use trajgen::{Point, RouteTail};

use super::reset::car_stop;
use super::telemetry::{Sample, Telemetry};
use super::{
    BRAKE_CURRENT_A, BRAKE_TIMEOUT, Context, RunError, SAFE_STOP_SPEED_MPS, STOPPED_SPEED_MPS,
    Stopped,
};
use crate::recording::{CarCommand, FaultRecord, SafetyRecord};
use campaign::case::{Case, SegmentResult, StreamingRecord};
use campaign::model::{Command, Fault, FaultWindow, Segment, TestPlan};
use campaign::oracle::{JudgedSegment, SegmentOracle, SegmentOutcome, test_verdict};
use campaign::safety::{Abort, AbortReason, CarSample, SafetyMonitor};
use campaign::streaming::{Decision, Streamer, Waypoint};

/// In the safe stop, brake once the car needs less than this to reach its stopping point.
const ROLL_END: Duration = Duration::from_millis(500);

/// What a test drive produced.
#[derive(Debug)]
pub(crate) struct DriveOutcome {
    /// The oracle's result for every segment judged.
    pub(crate) segments: Vec<SegmentResult>,
    /// The stop demanded, if any.
    pub(crate) abort: Option<Abort>,
    /// The abort's reason in words, with details.
    pub(crate) abort_text: Option<String>,
    /// How the segments were streamed.
    pub(crate) streaming: StreamingRecord,
    /// An error that ends the campaign (the test is recorded as aborted).
    pub(crate) stop: Option<RunError>,
}

impl DriveOutcome {
    /// Writes the results, the verdict and its reason into `case`.
    pub(crate) fn record(&self, case: &mut Case) {
        let judged: Vec<JudgedSegment> = self
            .segments
            .iter()
            .map(|s| JudgedSegment {
                segment_index: s.segment_index,
                command_index: s.command_index,
                outcome: s.oracle,
            })
            .collect();
        let abort_text = match (&self.abort_text, &self.stop) {
            (Some(text), _) => Some(text.clone()),
            (None, Some(error)) => Some(error.to_string()),
            (None, None) => None,
        };
        let verdict = test_verdict(&judged, abort_text.as_deref());
        case.segments = self.segments.clone();
        case.verdict = Some(verdict.verdict);
        case.reason = verdict.reason;
        case.abort = self.abort;
        case.streaming = Some(self.streaming.clone());
    }
}

/// Drives `plan` from `standing` (see the module doc). `generation` is the measured generation
/// time of one segment, fed to the lead time.
///
/// Timeout: none of its own beyond the safety monitor's staleness limit, the link's timeouts
/// and [`BRAKE_TIMEOUT`]; the drive ends when the plan is done or the test is stopped.
/// Cancellation: the context's token performs the safe stop and records `interrupted`.
pub(crate) async fn drive(
    ctx: &Context<'_>,
    telemetry: &mut Telemetry,
    plan: &TestPlan,
    standing: Point,
    generation: Duration,
) -> DriveOutcome {
    let start = start_route(ctx, standing);
    let uploaded = upload_start(ctx, &start, plan.test_index).await;
    // The test's clock and the monitor start when the car does.
    let mut drive = Drive::new(ctx, plan, &start, generation);
    if let Err(stopped) = uploaded {
        drive.stopped_before_start(stopped);
        return drive.finish();
    }
    drive.run(telemetry).await;
    drive.finish()
}

/// The route the test starts on: where the car stands, then the start route.
fn start_route(ctx: &Context<'_>, standing: Point) -> Vec<Waypoint> {
    let points = &ctx.scenario.start_route.points;
    let speed = points.first().map_or(SAFE_STOP_SPEED_MPS, |p| p.speed);
    std::iter::once(Waypoint {
        position: standing,
        speed,
    })
    .chain(points.iter().copied())
    .collect()
}

async fn upload_start(
    ctx: &Context<'_>,
    route: &[Waypoint],
    test_index: usize,
) -> Result<(), Stopped> {
    let (car, journal, test) = (ctx.car, ctx.journal, Some(test_index));
    journal
        .call(test, CarCommand::ClearRoute, car.clear_route())
        .await
        .map_err(|e| car_stop("clearing the route", e))?;
    let points = route_points(route);
    journal
        .call(
            test,
            CarCommand::add_points(&points),
            car.add_points(&points),
        )
        .await
        .map_err(|e| car_stop("uploading the start route", e))?;
    let start = CarCommand::SetAutopilot {
        active: true,
        reset: false,
    };
    journal
        .call(test, start, car.set_autopilot(true, false))
        .await
        .map_err(|e| car_stop("starting the autopilot", e))
}

fn route_points(route: &[Waypoint]) -> Vec<RoutePoint> {
    route
        .iter()
        .map(|w| RoutePoint::at(w.position.x, w.position.y, w.speed))
        .collect()
}

/// A segment appended to the car's route, and what the oracle made of it.
#[derive(Debug)]
struct Run {
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
    /// On the segment of run `k`.
    Run(usize),
    /// On the safe stop's extension.
    Stop,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
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

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum OpKind {
    /// A segment appended (`id`: its number in the recording).
    Append {
        append: usize,
        id: Option<u64>,
    },
    Fault {
        command: usize,
    },
    Extension {
        append: usize,
        id: Option<u64>,
    },
}

type OpFuture = Pin<Box<dyn Future<Output = Result<(), CarError>> + Send>>;
type InFlight = (OpKind, OpFuture);

enum Event {
    Interrupt,
    Op(OpKind, Result<(), CarError>),
    Sample(Sample),
    Tick,
}

struct Drive<'c, 'a> {
    ctx: &'c Context<'a>,
    plan: &'c TestPlan,
    t0: Instant,
    streamer: Streamer,
    safety: SafetyMonitor,
    route_len: usize,
    tail: RouteTail,
    runs: Vec<Run>,
    faults: Vec<(usize, Duration)>,
    cursor: usize,
    appended: Option<usize>,
    decision: Option<Decision>,
    speed: f64,
    phase: Phase,
    abort: Option<Abort>,
    detail: Option<String>,
    judging: bool,
    stop_first: Option<usize>,
    /// When the car had the safe stop's extension, or braking began: the end of the test
    /// proper.
    stop_began: Option<Duration>,
    brake_now: bool,
    brake_deadline: Option<Instant>,
    stop: Option<RunError>,
    /// Whether the link has lost a request or a reply (then the lead time allows one retry).
    lossy: bool,
}

impl<'c, 'a> Drive<'c, 'a> {
    fn new(
        ctx: &'c Context<'a>,
        plan: &'c TestPlan,
        start: &[Waypoint],
        generation: Duration,
    ) -> Self {
        let mut streamer = Streamer::new(ctx.config.streaming, start);
        streamer.delays_mut().generation(generation);
        let mut safety = SafetyMonitor::new(ctx.scenario.area.clone(), ctx.safety, Duration::ZERO);
        let positions: Vec<Point> = start.iter().map(|w| w.position).collect();
        safety.set_route(&positions);
        Self {
            ctx,
            plan,
            t0: Instant::now(),
            streamer,
            safety,
            route_len: start.len(),
            tail: plan.start_tail,
            runs: Vec::new(),
            faults: Vec::new(),
            cursor: 0,
            appended: None,
            decision: None,
            speed: 0.0,
            phase: Phase::Commands,
            abort: None,
            detail: None,
            judging: true,
            stop_first: None,
            stop_began: None,
            brake_now: false,
            brake_deadline: None,
            stop: None,
            lossy: false,
        }
    }

    fn now(&self) -> Duration {
        self.t0.elapsed()
    }

    fn stopped_before_start(&mut self, stopped: Stopped) {
        match stopped {
            Stopped::Abort(abort) => self.abort = Some(abort),
            Stopped::Error(error) => self.stop = Some(error),
        }
        self.phase = Phase::Done;
    }

    async fn run(&mut self, telemetry: &mut Telemetry) {
        let mut op: Option<InFlight> = None;
        let mut ticker = tokio::time::interval(self.ctx.config.state_period);
        ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
        telemetry.drain(self.ctx.journal);
        while self.phase != Phase::Done {
            self.lossy = telemetry.unanswered() > 0 || self.ctx.car.health().timeouts > 0;
            if op.is_none() {
                op = self.next_op();
            }
            let interruptible = self.abort.is_none();
            let event = tokio::select! {
                biased;
                () = self.ctx.cancel.cancelled(), if interruptible => Event::Interrupt,
                (kind, result) = wait_op(&mut op) => Event::Op(kind, result),
                sample = telemetry.next(self.ctx.journal) => Event::Sample(sample),
                _ = ticker.tick() => Event::Tick,
            };
            if matches!(event, Event::Op(..)) {
                op = None;
            }
            self.handle(event);
            if matches!(self.phase, Phase::Braking | Phase::Done)
                && let Some((kind, _)) = op.take()
            {
                self.record_answer(kind, &Err::<(), _>("abandoned: the drive stopped"));
            }
            if self.brake_now {
                self.brake().await;
            }
        }
    }

    fn handle(&mut self, event: Event) {
        match event {
            Event::Interrupt => {
                let abort = self.safety.stop(AbortReason::Interrupted, self.now());
                self.on_abort(abort);
            }
            Event::Op(kind, result) => self.op_done(kind, result),
            Event::Sample(Sample::State(sample)) => self.on_sample(&sample),
            Event::Sample(Sample::LinkLost) => {
                let abort = self.safety.link_lost(self.now());
                self.on_abort(abort);
            }
            Event::Tick => self.on_tick(),
        }
    }

    async fn brake(&mut self) {
        self.brake_now = false;
        let brake = CarCommand::Brake {
            current_a: BRAKE_CURRENT_A,
        };
        let test = Some(self.plan.test_index);
        let braked = self
            .ctx
            .journal
            .call(test, brake, self.ctx.car.brake(BRAKE_CURRENT_A));
        if let Err(CarError::LinkLost) = braked.await {
            let abort = self.safety.link_lost(self.now());
            self.on_abort(abort);
        }
    }

    fn on_sample(&mut self, sample: &StateSample) {
        let now = self.now();
        let s = &sample.state;
        let rtk = Point::new(s.px, s.py);
        let uwb = Point::new(s.px_uwb, s.py_uwb);
        self.speed = s.speed;
        self.streamer.delays_mut().round_trip(sample.rtt());
        // GET_STATE carries no fix type (firmware §5): the fused position is the reference.
        let car = CarSample {
            position: rtk,
            rtk_fix: true,
        };
        if let Some(abort) = self.safety.sample(now, car) {
            self.on_abort(abort);
        }
        let decision = self.streamer.observe(now, rtk);
        self.decision = Some(decision);
        self.track(now, uwb, rtk);
        self.advance_stop(now, decision);
    }

    fn advance_stop(&mut self, now: Duration, decision: Decision) {
        let stopped = self.speed.abs() < STOPPED_SPEED_MPS;
        match self.phase {
            Phase::Commands if decision.starved => {
                let abort = self.safety.stop(AbortReason::Starved, now);
                self.on_abort(abort);
            }
            Phase::Rolling if decision.time_to_end <= ROLL_END || stopped => self.begin_braking(),
            Phase::Braking if stopped => self.phase = Phase::Done,
            Phase::Braking => self.brake_now = true,
            _ => {}
        }
    }

    fn on_tick(&mut self) {
        if let Some(abort) = self.safety.tick(self.now()) {
            self.on_abort(abort);
        }
        let late = self.brake_deadline.is_some_and(|d| Instant::now() >= d);
        if self.phase == Phase::Braking && late {
            self.detail
                .get_or_insert_with(|| "the car did not stop within 5 s of braking".to_owned());
            self.phase = Phase::Done;
        }
    }

    /// The first stop demanded wins; a lost link ends the drive at once.
    fn on_abort(&mut self, abort: Abort) {
        if self.abort.is_some() || self.phase == Phase::Done {
            return;
        }
        self.abort = Some(abort);
        let record = SafetyRecord::new(Some(self.plan.test_index), abort);
        self.ctx.journal.write(&record);
        if abort.reason == AbortReason::LinkLost {
            self.phase = Phase::Done;
            return;
        }
        match abort.action {
            campaign::safety::StopAction::SafeStop => self.begin_stop(),
            campaign::safety::StopAction::Brake => self.begin_braking(),
        }
    }

    fn begin_stop(&mut self) {
        if self.phase == Phase::Commands {
            self.phase = Phase::StopPending;
        }
    }

    fn begin_braking(&mut self) {
        if matches!(self.phase, Phase::Braking | Phase::Done) {
            return;
        }
        self.stop_began.get_or_insert(self.now());
        self.phase = Phase::Braking;
        self.brake_now = true;
        self.brake_deadline = Some(Instant::now() + BRAKE_TIMEOUT);
    }

    fn next_op(&mut self) -> Option<InFlight> {
        match self.phase {
            Phase::Commands => self.next_command(),
            Phase::StopPending => self.extension(),
            _ => None,
        }
    }

    /// The next command to send, if it is time (see the module doc).
    fn next_command(&mut self) -> Option<InFlight> {
        let decision = self.decision?;
        let plan = self.plan;
        loop {
            let Some(command) = plan.commands.get(self.cursor) else {
                self.begin_stop();
                return self.extension();
            };
            match command {
                Command::AddFault(fault) => return Some(self.fault_op(*fault)),
                Command::RunSegments(_) if self.appended == Some(self.cursor) => {
                    if decision.time_to_end > self.lead(decision, self.cursor + 1) {
                        return None;
                    }
                    self.cursor += 1;
                    self.appended = None;
                }
                Command::RunSegments(segment) => {
                    let lead = self.lead(decision, self.cursor);
                    if decision.time_to_end > lead {
                        return None;
                    }
                    return Some(self.append_op(Decision { lead, ..decision }, segment));
                }
            }
        }
    }

    /// The lead time before the commands from `from` to the next segment: the streamer's, plus
    /// a round trip for every fault command before that segment and every extra packet of it,
    /// plus one request timeout (a retry) once the link has shown it loses packets.
    fn lead(&self, decision: Decision, from: usize) -> Duration {
        let commands = self.plan.commands.get(from..).unwrap_or_default();
        let faults = commands.iter().take_while(|c| c.fault().is_some()).count();
        let packets = commands
            .iter()
            .find_map(Command::segment)
            .map_or(1, |s| s.points.len().div_ceil(POINTS_PER_PACKET));
        let rtt = self
            .ctx
            .car
            .health()
            .rtt_p99
            .unwrap_or(self.ctx.config.streaming.initial_round_trip);
        let extra = u32::try_from(faults + packets.saturating_sub(1)).unwrap_or(u32::MAX);
        let retry = if self.lossy {
            self.ctx.car.config().request_timeout
        } else {
            Duration::ZERO
        };
        decision
            .lead
            .saturating_add(rtt.saturating_mul(extra))
            .saturating_add(retry)
    }

    fn fault_op(&mut self, fault: Fault) -> InFlight {
        let command = self.cursor;
        let sent = FaultRecord::sent(self.plan.test_index, command, &fault);
        self.ctx.journal.write(&sent);
        let car = self.ctx.car.clone();
        // Faults on this probe the car confirmed in this test (the reset cleared the others).
        let before = self
            .faults
            .iter()
            .filter(|(i, _)| {
                self.plan.commands[*i]
                    .fault()
                    .is_some_and(|f| f.probe == fault.probe)
            })
            .count();
        let future = async move { add_fault_once(&car, fault, before).await };
        (OpKind::Fault { command }, Box::pin(future))
    }

    fn append_op(&mut self, decision: Decision, segment: &Segment) -> InFlight {
        let command_index = self.cursor;
        let waypoints: Vec<Waypoint> = segment.waypoints().collect();
        let append = self.streamer.appended(self.now(), &decision, &waypoints);
        self.safety.extend_route(&segment.points);
        self.runs.push(Run {
            command_index,
            first: self.route_len,
            entered: None,
            left: None,
            oracle: SegmentOracle::new(),
            result: None,
        });
        self.route_len += waypoints.len();
        self.tail = self.tail.advanced(&segment.points);
        self.appended = Some(command_index);
        // The route changed: the next decision waits for a sample located on the new route.
        self.decision = None;
        let car = self.ctx.car.clone();
        let points = route_points(&waypoints);
        let id = self.record_add_points(&points);
        let future = async move { car.add_points(&points).await };
        (OpKind::Append { append, id }, Box::pin(future))
    }

    /// The safe stop's slow extension, generated with the ahead margin from the route's end;
    /// braking at once when none can be generated.
    fn extension(&mut self) -> Option<InFlight> {
        let points = self.ctx.scenario.campaign.points_per_segment.min.max(1);
        let mut rng = crate::seed::rng(stop_seed(
            self.ctx.config.campaign.seed,
            self.plan.test_index,
        ));
        let started = Instant::now();
        let extension =
            match self
                .ctx
                .generator
                .extend(&self.ctx.scenario.area, &self.tail, points, &mut rng)
            {
                Ok(extension) => extension,
                Err(error) => {
                    self.detail = Some(format!("no safe stop extension: {error}"));
                    self.begin_braking();
                    return None;
                }
            };
        self.streamer.delays_mut().generation(started.elapsed());
        let waypoints: Vec<Waypoint> = extension
            .points
            .iter()
            .map(|&position| Waypoint {
                position,
                speed: SAFE_STOP_SPEED_MPS,
            })
            .collect();
        let decision = self.decision.unwrap_or(Decision {
            time_to_end: Duration::ZERO,
            lead: Duration::ZERO,
            append: true,
            starved: false,
        });
        let append = self.streamer.appended(self.now(), &decision, &waypoints);
        self.safety.extend_route(&extension.points);
        self.stop_first = Some(self.route_len);
        self.route_len += waypoints.len();
        self.phase = Phase::Extending;
        let car = self.ctx.car.clone();
        let points = route_points(&waypoints);
        let id = self.record_add_points(&points);
        let future = async move { car.add_points(&points).await };
        Some((OpKind::Extension { append, id }, Box::pin(future)))
    }

    /// Records the AP_ADD_POINTS about to be sent; its id in the recording.
    fn record_add_points(&self, points: &[RoutePoint]) -> Option<u64> {
        let command = CarCommand::add_points(points);
        self.ctx.journal.sent(Some(self.plan.test_index), command)
    }

    /// Records the answer to the command `kind`.
    fn record_answer<E: std::fmt::Display>(&self, kind: OpKind, result: &Result<(), E>) {
        let journal = self.ctx.journal;
        match kind {
            OpKind::Append { id, .. } | OpKind::Extension { id, .. } => {
                journal.answered(id, result);
            }
            OpKind::Fault { command } => {
                if let Some(fault) = self.plan.commands[command].fault() {
                    let test_index = self.plan.test_index;
                    journal.write(&FaultRecord::answered(test_index, command, fault, result));
                }
            }
        }
    }

    fn op_done(&mut self, kind: OpKind, result: Result<(), CarError>) {
        self.record_answer(kind, &result);
        let now = self.now();
        match (kind, result) {
            (_, Err(CarError::LinkLost)) => {
                let abort = self.safety.link_lost(now);
                self.on_abort(abort);
            }
            (OpKind::Append { append, .. }, Ok(())) => self.streamer.confirmed(append, now),
            (OpKind::Fault { command }, Ok(())) => {
                self.faults.push((command, now));
                self.cursor += 1;
            }
            (OpKind::Extension { append, .. }, Ok(())) => {
                self.streamer.confirmed(append, now);
                if self.phase == Phase::Extending {
                    self.phase = Phase::Rolling;
                    self.stop_began.get_or_insert(now);
                }
            }
            (OpKind::Extension { .. }, Err(error)) => {
                self.detail = Some(format!("the safe stop extension failed: {error}"));
                self.begin_braking();
            }
            (OpKind::Append { .. } | OpKind::Fault { .. }, Err(error)) => {
                let command_index = self.cursor;
                self.detail = Some(format!("command {command_index}: {error}"));
                let abort = self
                    .safety
                    .stop(AbortReason::CommandRefused { command_index }, now);
                self.on_abort(abort);
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
            Region::Run(k) => {
                self.close_runs_before(k, now);
                if self.judging {
                    let run = &mut self.runs[k];
                    run.entered.get_or_insert(now);
                    run.oracle.push(uwb, rtk);
                }
            }
            Region::Stop => self.close_runs_before(self.runs.len(), now),
        }
    }

    fn region(&self, stretch: usize) -> Region {
        if self.stop_first.is_some_and(|first| stretch + 1 >= first) {
            return Region::Stop;
        }
        match self.runs.iter().rposition(|r| r.first <= stretch + 1) {
            Some(k) => Region::Run(k),
            None => Region::Start,
        }
    }

    fn close_runs_before(&mut self, k: usize, now: Duration) {
        for j in 0..k.min(self.runs.len()) {
            if self.runs[j].result.is_some() {
                continue;
            }
            let verdict = self.judge(j, now);
            if !self.ctx.config.policy.continue_after(verdict) {
                self.judging = false;
                self.begin_stop();
                return;
            }
        }
    }

    fn judge(&mut self, j: usize, now: Duration) -> campaign::oracle::SegmentVerdict {
        let threshold = self.ctx.scenario.campaign.oracle_threshold_m;
        let run = &mut self.runs[j];
        run.left = Some(now);
        let outcome = run.oracle.result(threshold);
        run.result = Some(outcome);
        outcome.verdict
    }

    /// The segment being driven when the drive ended is judged on what was seen of it.
    fn finish(mut self) -> DriveOutcome {
        let now = self.now();
        if self.judging {
            for j in 0..self.runs.len() {
                if self.runs[j].result.is_none() && self.runs[j].entered.is_some() {
                    self.judge(j, now);
                }
            }
        }
        let segments = self.results();
        let abort_text = self.abort.map(|a| match &self.detail {
            Some(detail) => format!("{}: {detail}", a.reason),
            None => a.reason.to_string(),
        });
        DriveOutcome {
            segments,
            abort: self.abort,
            abort_text,
            streaming: self.streaming_record(),
            stop: self.stop,
        }
    }

    fn results(&self) -> Vec<SegmentResult> {
        self.runs
            .iter()
            .enumerate()
            .filter_map(|(segment_index, run)| {
                let oracle = run.result?;
                Some(SegmentResult {
                    segment_index,
                    command_index: run.command_index,
                    faults_preceding: self.plan.faults_before(run.command_index),
                    faults_active: self.faults_active(run),
                    oracle,
                })
            })
            .collect()
    }

    /// The faults estimated to apply while `run` was driven.
    fn faults_active(&self, run: &Run) -> Vec<usize> {
        let (Some(from), Some(to)) = (run.entered, run.left) else {
            return Vec::new();
        };
        self.faults
            .iter()
            .filter(|&&(command, added_at)| {
                self.plan.commands[command].fault().is_some_and(|fault| {
                    FaultWindow::of(fault, added_at, &self.ctx.rates).overlaps(from, to)
                })
            })
            .map(|&(command, _)| command)
            .collect()
    }

    /// The appends and the starvation events of the test proper: the car reaching the end of
    /// the safe stop's extension (or braking to a stop) is the stop, not a starvation.
    fn streaming_record(&self) -> StreamingRecord {
        let during_test = |at: &&Duration| self.stop_began.is_none_or(|stop| **at < stop);
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

/// Waits for the command in flight; never completes without one. Cancel-safe: the command's
/// future stays in `op`.
async fn wait_op(op: &mut Option<InFlight>) -> (OpKind, Result<(), CarError>) {
    match op {
        Some((kind, future)) => (*kind, future.as_mut().await),
        None => std::future::pending().await,
    }
}

/// The seed of test `test_index`'s safe stop extension.
fn stop_seed(campaign_seed: u64, test_index: usize) -> u64 {
    let seed = campaign::model::test_rng_seed(campaign_seed, test_index);
    let mut last = [0u8; 8];
    last.copy_from_slice(&seed[24..]);
    u64::from_le_bytes(last)
}

/// Tries of a fault command whose reply was lost.
const FAULT_TRIES: u32 = 3;

/// Adds `fault` to the car, which holds `before` faults on its probe. When the reply is lost,
/// asks the car for its faults (`fi_print_faults`): a fault more on the probe means the command
/// took effect; otherwise it is sent again (up to [`FAULT_TRIES`] times in all). So a lost reply
/// neither aborts the test nor adds the fault twice.
///
/// Timeout: each try as `Car::add_fault` and `Car::list_faults`. Cancellation: safe between
/// tries; a fault command cancelled in flight may or may not have taken effect.
async fn add_fault_once(car: &Car, fault: Fault, before: usize) -> Result<(), CarError> {
    let (probe, kind) = (fault.probe, fault.kind);
    let mut tries = 1;
    loop {
        let result = car
            .add_fault(
                &probe,
                kind,
                fault.param as f32,
                i32::try_from(fault.start).unwrap_or(i32::MAX),
                i32::try_from(fault.duration).unwrap_or(i32::MAX),
            )
            .await;
        match result {
            Err(CarError::Fault(FaultError::NoReply)) if tries < FAULT_TRIES => {
                let listed = super::retried(|| car.list_faults()).await?;
                let id = probe.to_string();
                if listed.iter().filter(|f| f.probe == id).count() > before {
                    return Ok(());
                }
                tries += 1;
            }
            result => return result,
        }
    }
}
