//! The test drive's loop: the start route sent, then the pure state machine
//! ([`campaign::drive::TestDrive`]: streaming, oracle, safety, the safe stop) fed with what
//! happens and its actions carried out on the car.
//!
//! One loop waits for whichever comes first: the operator's interrupt, the answer to the route
//! operation in flight (a segment or the safe stop's extension appended), the answer to the fault
//! command in flight, the time the next fault is due at its place, a state sample, or the
//! monitor's tick. Before waiting it asks the machine for the next route operation and the next
//! fault (one of each in flight at a time): segments are streamed by time, faults sent at their
//! places on the route, and neither waits for the other.
//!
//! Recorded in the campaign's journal as they happen: every command with its answer (fault
//! commands as sent and confirmed or refused, an operation abandoned when the drive stopped),
//! every state sample, and the first stop demanded.

use std::future::Future;
use std::pin::Pin;
use std::time::Duration;

use car_link::fault::FaultError;
use car_link::{CarError, StateSample};
use tokio::time::{Instant, MissedTickBehavior};
use trajgen::Point;

use super::reset::car_stop;
use super::telemetry::{Sample, Telemetry};
use super::{BRAKE_CURRENT_A, Context, RunError, Stopped};
use crate::vehicle::Vehicle;
use campaign::drive::{
    Action, DriveOutcome, Event, LinkStatus, Operation, Reply, TestDrive, start_route,
};
use campaign::model::{Fault, TestPlan};
use campaign::streaming::{Waypoint, route_points};
use recording::{CarCommand, FaultRecord, SafetyRecord};

/// Drives `plan` from `standing` (see the module doc). `generation` is the measured generation
/// time of one segment, fed to the lead time. Returns the drive's outcome, and the error that
/// ends the campaign if one happened (the test is then recorded as aborted).
///
/// Timeout: none of its own beyond the safety monitor's staleness limit, the link's timeouts
/// and [`campaign::drive::BRAKE_TIMEOUT`]; the drive ends when the plan is done or the test is
/// stopped. Cancellation: the context's token performs the safe stop and records `interrupted`.
pub async fn drive<V: Vehicle>(
    ctx: &Context<'_, V>,
    telemetry: &mut Telemetry,
    plan: &TestPlan,
    standing: Point,
    generation: Duration,
) -> (DriveOutcome, Option<RunError>) {
    let start = start_route(&ctx.scenario.start_route, standing);
    let uploaded = upload_start(ctx, &start, plan.test_index).await;
    // The test's clock and the monitor start when the car does.
    let t0 = Instant::now();
    let mut machine = TestDrive::new(ctx.drive_settings(), plan, &start, generation);
    let error = match uploaded {
        Ok(()) => {
            super::pause::pause(super::pause::At::In, plan.test_index, ctx.cancel);
            run(ctx, telemetry, &mut machine, plan.test_index, t0).await;
            None
        }
        Err(Stopped::Abort(abort)) => {
            machine.end_before_start(Some(abort));
            None
        }
        Err(Stopped::Error(error)) => {
            machine.end_before_start(None);
            Some(error)
        }
    };
    (machine.finish(t0.elapsed()), error)
}

async fn upload_start<V: Vehicle>(
    ctx: &Context<'_, V>,
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

/// What the answer to the operation in flight is recorded as.
#[derive(Debug, Clone, Copy)]
enum Recorded {
    /// An AP_ADD_POINTS (`id`: its number in the recording).
    Points { id: Option<u64> },
    /// The fault of command `command`.
    Fault { command: usize, fault: Fault },
}

/// How an operation ended: `Ok(true)` for a fault added whose reply was lost (the car's list of
/// faults showed it).
type OpResult = Result<bool, CarError>;
type OpFuture = Pin<Box<dyn Future<Output = OpResult> + Send>>;
type InFlight = (Recorded, OpFuture);

/// What the loop woke up for.
enum Woke {
    Interrupt,
    HardStop,
    Op(Recorded, OpResult),
    Fault(Recorded, OpResult),
    FaultDue,
    Sample(Sample),
    Tick,
}

/// The loop (see the module doc), until the machine is done.
async fn run<V: Vehicle>(
    ctx: &Context<'_, V>,
    telemetry: &mut Telemetry,
    machine: &mut TestDrive<'_>,
    test_index: usize,
    t0: Instant,
) {
    let mut op: Option<InFlight> = None;
    let mut fault_ops: Vec<InFlight> = Vec::new();
    let mut ticker = tokio::time::interval(ctx.config.state_period);
    ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
    telemetry.drain(ctx.journal);
    // Made once, not at every wake: each would take a waiter slot or a timer and give it back.
    let hard_stopped = super::hard_stop().cancelled();
    let interrupted = ctx.cancel.cancelled();
    let fault_due = tokio::time::sleep_until(t0);
    tokio::pin!(hard_stopped, interrupted, fault_due);
    let mut fault_due_at = None;
    while !machine.is_done() {
        if op.is_none() {
            let health = ctx.car.health();
            let link = LinkStatus {
                rtt_p99: health.rtt_p99,
                lossy: telemetry.unanswered() > 0 || health.timeouts > 0,
                request_timeout: ctx.car.request_timeout(),
            };
            let asked = Instant::now();
            let next = machine.next_operation(t0.elapsed(), link);
            if matches!(next, Some(Operation::AppendStop { .. })) {
                // The extension was generated in that call: its generation time.
                machine.extension_generated_in(asked.elapsed());
            }
            op = next.map(|operation| start(ctx, test_index, operation));
        }
        while let Some(operation) = machine.next_fault(t0.elapsed()) {
            fault_ops.push(start(ctx, test_index, operation));
        }
        let due = machine.fault_due().map(|due| t0 + due);
        if let Some(at) = due
            && fault_due_at != due
        {
            fault_due.as_mut().reset(at);
        }
        fault_due_at = due;
        let woke = tokio::select! {
            biased;
            () = &mut hard_stopped => Woke::HardStop,
            () = &mut interrupted, if machine.interruptible() => Woke::Interrupt,
            (recorded, result) = wait_op(&mut op) => Woke::Op(recorded, result),
            (recorded, result) = wait_any(&mut fault_ops) => Woke::Fault(recorded, result),
            () = &mut fault_due, if due.is_some() => Woke::FaultDue,
            sample = telemetry.next(ctx.journal) => Woke::Sample(sample),
            _ = ticker.tick() => Woke::Tick,
        };
        let event = match woke {
            Woke::Interrupt => Event::Interrupt,
            Woke::HardStop => Event::BrakedAtOnce,
            Woke::Op(recorded, result) => {
                op = None;
                record_answer(ctx, test_index, recorded, &result);
                Event::Reply(reply(result))
            }
            Woke::Fault(recorded, result) => {
                record_answer(ctx, test_index, recorded, &result);
                let resent = matches!(result, Ok(true));
                let command_index = match recorded {
                    Recorded::Fault { command, .. } => command,
                    Recorded::Points { .. } => continue,
                };
                Event::FaultReply {
                    command_index,
                    reply: reply(result),
                    resent,
                }
            }
            // The next fault is due: the loop asks for it.
            Woke::FaultDue => continue,
            Woke::Sample(Sample::State(sample)) => Event::Sample(drive_sample(&sample)),
            Woke::Sample(Sample::LinkLost) => Event::LinkLost,
            Woke::Tick => Event::Tick,
        };
        let actions = machine.handle(t0.elapsed(), event);
        let in_flight = InFlightOps {
            op: &mut op,
            faults: &mut fault_ops,
        };
        carry_out(ctx, machine, in_flight, actions, test_index, t0).await;
    }
}

/// The reply the machine gets for an operation's result.
fn reply(result: OpResult) -> Reply {
    match result {
        Ok(_) => Reply::Done,
        Err(CarError::LinkLost) => Reply::LinkLost,
        Err(error) => Reply::Failed(error.to_string()),
    }
}

/// The operations in flight: the route's and the faults'.
struct InFlightOps<'o> {
    op: &'o mut Option<InFlight>,
    faults: &'o mut Vec<InFlight>,
}

/// Carries out `actions` in order (and those of a lost link the brake command finds).
async fn carry_out<V: Vehicle>(
    ctx: &Context<'_, V>,
    machine: &mut TestDrive<'_>,
    in_flight: InFlightOps<'_>,
    actions: Vec<Action>,
    test_index: usize,
    t0: Instant,
) {
    let mut actions = std::collections::VecDeque::from(actions);
    while let Some(action) = actions.pop_front() {
        match action {
            Action::Stop(abort) => {
                ctx.journal
                    .write(&SafetyRecord::new(Some(test_index), abort));
            }
            Action::Abandon | Action::AbandonFault => {
                let abandoned: Vec<InFlight> = match action {
                    Action::Abandon => in_flight.op.take().into_iter().collect(),
                    _ => std::mem::take(in_flight.faults),
                };
                for (recorded, _) in abandoned {
                    let abandoned = Err::<bool, _>("abandoned: the drive stopped");
                    record_answer(ctx, test_index, recorded, &abandoned);
                }
            }
            Action::Brake => {
                let brake = CarCommand::Brake {
                    current_a: BRAKE_CURRENT_A,
                };
                let braked =
                    ctx.journal
                        .call(Some(test_index), brake, ctx.car.brake(BRAKE_CURRENT_A));
                if let Err(CarError::LinkLost) = braked.await {
                    actions.extend(machine.handle(t0.elapsed(), Event::LinkLost));
                }
            }
        }
    }
}

/// What the machine needs of a state sample.
fn drive_sample(sample: &StateSample) -> campaign::drive::Sample {
    let s = &sample.state;
    campaign::drive::Sample {
        rtk: Point::new(s.px, s.py),
        uwb: Point::new(s.px_uwb, s.py_uwb),
        speed: s.speed,
        round_trip: sample.rtt(),
        yaw_deg: s.yaw,
        version: s.version,
        look_ahead_radius_m: s.ap_rad,
    }
}

/// Records and starts `operation` on the car.
fn start<V: Vehicle>(ctx: &Context<'_, V>, test_index: usize, operation: Operation) -> InFlight {
    let car = ctx.car.clone();
    match operation {
        Operation::AddFault {
            command_index,
            fault,
            on_probe,
        } => {
            let sent = FaultRecord::sent(test_index, command_index, &fault);
            ctx.journal.write(&sent);
            let recorded = Recorded::Fault {
                command: command_index,
                fault,
            };
            let future = async move { add_fault_once(&car, fault, on_probe).await };
            (recorded, Box::pin(future))
        }
        Operation::AppendSegment { points, .. } | Operation::AppendStop { points } => {
            let points = route_points(&points);
            let command = CarCommand::add_points(&points);
            let id = ctx.journal.sent(Some(test_index), command);
            let future = async move { car.add_points(&points).await.map(|()| false) };
            (Recorded::Points { id }, Box::pin(future))
        }
    }
}

/// Records the answer to an operation.
fn record_answer<V, E: std::fmt::Display>(
    ctx: &Context<'_, V>,
    test_index: usize,
    recorded: Recorded,
    result: &Result<bool, E>,
) {
    let result = &result.as_ref().map(|_| ());
    match recorded {
        Recorded::Points { id } => ctx.journal.answered(id, result),
        Recorded::Fault { command, fault } => {
            let answered = FaultRecord::answered(test_index, command, &fault, result);
            ctx.journal.write(&answered);
        }
    }
}

/// Waits for the first of the operations in flight to end and takes it out of `ops`; never
/// completes without one. Cancel-safe: the futures stay in `ops` until one ends.
async fn wait_any(ops: &mut Vec<InFlight>) -> (Recorded, OpResult) {
    if ops.is_empty() {
        return std::future::pending().await;
    }
    std::future::poll_fn(|cx| {
        for k in 0..ops.len() {
            if let std::task::Poll::Ready(result) = ops[k].1.as_mut().poll(cx) {
                let (recorded, _) = ops.remove(k);
                return std::task::Poll::Ready((recorded, result));
            }
        }
        std::task::Poll::Pending
    })
    .await
}

/// Waits for the operation in flight; never completes without one. Cancel-safe: the
/// operation's future stays in `op`.
async fn wait_op(op: &mut Option<InFlight>) -> (Recorded, OpResult) {
    match op {
        Some((recorded, future)) => (*recorded, future.as_mut().await),
        None => std::future::pending().await,
    }
}

/// Tries of a fault command whose reply was lost.
const FAULT_TRIES: u32 = 5;
/// Reads of the car's fault list, at most, that decide whether a fault command took effect.
const FAULT_LIST_READS: usize = 8;

/// Whether the car holds more than `before` faults on `probe`: the distinct faults of that probe
/// that up to [`FAULT_LIST_READS`] reads of its fault list show between them, complete or not.
/// A lossy link loses lines of a reply but never adds any, and the list has no count of its own:
/// a read can look complete (its header and last line arrived) and miss the very fault in
/// question, which would then be added twice (seen at 30 % loss: "too many faults on this
/// probe"); and at 30 % loss a list of a few faults arrives whole in under one read of ten.
/// Each block that arrives is a fault the car holds; at 30 % loss a given one shows in a read
/// about half the time, so eight reads all miss it about once in 200. `Ok(false)` after eight
/// reads without it; an error when no read got any answer.
async fn holds_more_than<V: Vehicle>(
    car: &V,
    probe: &car_link::Probe,
    before: usize,
) -> Result<bool, CarError> {
    let id = probe.to_string();
    let mut seen: Vec<car_link::fault::ListedFault> = Vec::new();
    let mut answered = false;
    let mut last_error = None;
    for _ in 0..FAULT_LIST_READS {
        match car.list_faults_part().await {
            Ok(listed) => {
                answered = true;
                for fault in listed.into_iter().filter(|f| f.probe == id) {
                    if !seen.iter().any(|s| same_fault(s, &fault)) {
                        seen.push(fault);
                    }
                }
                if seen.len() > before {
                    return Ok(true);
                }
            }
            Err(CarError::LinkLost) => return Err(CarError::LinkLost),
            Err(error) => last_error = Some(error),
        }
    }
    match (answered, last_error) {
        (false, Some(error)) => Err(FaultError::Unconfirmed(error.to_string()).into()),
        _ => Ok(false),
    }
}

/// Whether two listed faults are the same slot (the iteration counter moves on between reads).
pub(super) fn same_fault(
    a: &car_link::fault::ListedFault,
    b: &car_link::fault::ListedFault,
) -> bool {
    a.probe == b.probe
        && a.kind == b.kind
        && a.param == b.param
        && a.start == b.start
        && a.duration == b.duration
}

/// Adds `fault` to the car, which holds `before` faults on its probe. When the reply is lost
/// (or so much of it that it reads as neither success nor a refusal), asks the car for its faults (`fi_print_faults`): a fault more on the probe means the command
/// took effect; otherwise it is sent again (up to [`FAULT_TRIES`] times in all). So a lost reply
/// neither aborts the test nor adds the fault twice. `Ok(true)`: added, found in the car's list
/// after a lost reply.
///
/// Timeout: each try as [`Vehicle::add_fault`] and [`Vehicle::list_faults_part`]. Cancellation: safe between
/// tries; a fault command cancelled in flight may or may not have taken effect.
async fn add_fault_once<V: Vehicle>(car: &V, fault: Fault, before: usize) -> OpResult {
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
            // A reply that is lost, or partly lost (a lossy link drops some of its lines, and
            // what is left reads as neither success nor a refusal), says nothing of the car.
            Err(CarError::Fault(
                FaultError::NoReply | FaultError::Unexpected(_) | FaultError::OtherProbe { .. },
            )) if tries < FAULT_TRIES => {
                if holds_more_than(car, &probe, before).await? {
                    return Ok(true);
                }
                tries += 1;
            }
            result => return result.map(|()| false),
        }
    }
}
