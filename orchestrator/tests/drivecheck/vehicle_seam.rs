//! The vehicle seam is real: a campaign runs end to end through a second implementation of
//! [`Vehicle`], a tap that wraps the embedded simulated car and records every call the runner
//! makes, when it started and when it was answered.
//!
//! What the tap observed is checked against the runner's invariants (ARCHITECTURE.md): the car is
//! prepared (anchors, fault injection) before it moves; a route segment is never sent before the
//! car confirmed the previous one; the autopilot is never started on an empty route; faults are
//! sent only while a test drives, each fault a case file says was confirmed exactly once and no
//! other; every test ends braking. And the tap changes nothing: the same campaign without it
//! writes byte-identical case files.

use std::future::Future;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use campaign::files::{Case, CommandRecord};
use campaign::model::{Campaign, Command};
use car_link::config::{ConfigField, MainConfig};
use car_link::fault::ListedFault;
use car_link::health::LinkHealth;
use car_link::message::{Anchor, Pose};
use car_link::{
    CarError, FaultKind, FirmwareVersion, Probe, RoutePoint, StatePolling, StateSample,
};
use futures::{Stream, StreamExt};
use runner::vehicle::{Vehicle, connect_sim};
use runner::{RecordMode, RunConfig, Silent, run_campaign};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

const SCENARIO: &str = "parking-lot-2anchors";
const SEED: u64 = 3;
const TESTS: usize = 3;

/// What the runner asked of the car.
#[derive(Debug, Clone, PartialEq)]
enum Op {
    StateWithin,
    State,
    PollStates,
    ClearRoute,
    AddPoints(usize),
    RoutePart,
    SetAutopilot(bool),
    Brake,
    SetPos,
    UploadAnchors(usize),
    MainConfig,
    PrepareForTestDrive,
    SetFiEnabled(bool),
    AddFault {
        probe: String,
        kind: FaultKind,
        param: f32,
        start: i32,
        duration: i32,
    },
    ListFaults,
    ClearFaults,
    ResetUwbPos,
}

/// One call: what, when it was made, and when (and how) it was answered.
#[derive(Debug, Clone)]
struct Call {
    op: Op,
    started: Instant,
    ended: Option<(Instant, bool)>,
}

/// What the tap saw.
#[derive(Debug, Default)]
struct Log {
    calls: Vec<Call>,
    /// Route uploads started and not yet answered, and the most there ever were at once.
    uploads_in_flight: usize,
    most_uploads_in_flight: usize,
    /// State samples the telemetry stream gave.
    samples: usize,
}

/// A vehicle that drives another and records every call.
#[derive(Debug, Clone)]
struct Tap<V> {
    inner: V,
    log: Arc<Mutex<Log>>,
}

impl<V: Vehicle> Tap<V> {
    fn new(inner: V) -> Self {
        Self {
            inner,
            log: Arc::default(),
        }
    }

    fn log(&self) -> std::sync::MutexGuard<'_, Log> {
        self.log.lock().expect("the log")
    }

    /// Records `op` as made now; its index.
    fn begin(&self, op: Op) -> usize {
        let mut log = self.log();
        if matches!(op, Op::AddPoints(_)) {
            log.uploads_in_flight += 1;
            log.most_uploads_in_flight = log.most_uploads_in_flight.max(log.uploads_in_flight);
        }
        log.calls.push(Call {
            op,
            started: Instant::now(),
            ended: None,
        });
        log.calls.len() - 1
    }

    /// Records the answer to call `index`.
    fn end(&self, index: usize, ok: bool) {
        let mut log = self.log();
        if matches!(log.calls[index].op, Op::AddPoints(_)) {
            log.uploads_in_flight -= 1;
        }
        log.calls[index].ended = Some((Instant::now(), ok));
    }

    /// `call` recorded as `op`.
    async fn tapped<T>(
        &self,
        op: Op,
        call: impl Future<Output = Result<T, CarError>>,
    ) -> Result<T, CarError> {
        let index = self.begin(op);
        let result = call.await;
        self.end(index, result.is_ok());
        result
    }
}

impl<V: Vehicle> Vehicle for Tap<V> {
    fn version(&self) -> FirmwareVersion {
        self.inner.version()
    }

    fn request_timeout(&self) -> Duration {
        self.inner.request_timeout()
    }

    fn set_request_timeout(&self, per_try: Duration) {
        self.inner.set_request_timeout(per_try);
    }

    fn configured_tries(&self) -> u32 {
        self.inner.configured_tries()
    }

    fn set_tries(&self, tries: u32) {
        self.inner.set_tries(tries);
    }

    fn health(&self) -> LinkHealth {
        self.inner.health()
    }

    fn set_keepalive(&self, on: bool) {
        self.inner.set_keepalive(on);
    }

    fn state(&self) -> impl Future<Output = Result<StateSample, CarError>> + Send {
        self.tapped(Op::State, self.inner.state())
    }

    fn state_within(
        &self,
        per_try: Duration,
    ) -> impl Future<Output = Result<StateSample, CarError>> + Send {
        self.tapped(Op::StateWithin, self.inner.state_within(per_try))
    }

    fn poll_states(
        &self,
        polling: StatePolling,
    ) -> impl Stream<Item = Result<StateSample, CarError>> + Send + 'static {
        let index = self.begin(Op::PollStates);
        self.end(index, true);
        let log = Arc::clone(&self.log);
        self.inner.poll_states(polling).inspect(move |item| {
            if item.is_ok() {
                log.lock().expect("the log").samples += 1;
            }
        })
    }

    fn clear_route(&self) -> impl Future<Output = Result<(), CarError>> + Send {
        self.tapped(Op::ClearRoute, self.inner.clear_route())
    }

    fn add_points(
        &self,
        points: &[RoutePoint],
    ) -> impl Future<Output = Result<(), CarError>> + Send {
        self.tapped(Op::AddPoints(points.len()), self.inner.add_points(points))
    }

    fn route_part(
        &self,
        first: i32,
        num: u8,
    ) -> impl Future<Output = Result<car_link::message::RoutePart, CarError>> + Send {
        self.tapped(Op::RoutePart, self.inner.route_part(first, num))
    }

    fn set_autopilot(
        &self,
        active: bool,
        reset: bool,
    ) -> impl Future<Output = Result<(), CarError>> + Send {
        self.tapped(
            Op::SetAutopilot(active),
            self.inner.set_autopilot(active, reset),
        )
    }

    fn brake(&self, current_a: f64) -> impl Future<Output = Result<(), CarError>> + Send {
        self.tapped(Op::Brake, self.inner.brake(current_a))
    }

    fn set_pos(&self, pose: Pose) -> impl Future<Output = Result<(), CarError>> + Send {
        self.tapped(Op::SetPos, self.inner.set_pos(pose))
    }

    fn upload_anchors(
        &self,
        anchors: &[Anchor],
    ) -> impl Future<Output = Result<(), CarError>> + Send {
        self.tapped(
            Op::UploadAnchors(anchors.len()),
            self.inner.upload_anchors(anchors),
        )
    }

    fn main_config(&self) -> impl Future<Output = Result<MainConfig, CarError>> + Send {
        self.tapped(Op::MainConfig, self.inner.main_config())
    }

    fn prepare_for_test_drive(
        &self,
    ) -> impl Future<Output = Result<Vec<(ConfigField, u8)>, CarError>> + Send {
        self.tapped(Op::PrepareForTestDrive, self.inner.prepare_for_test_drive())
    }

    fn set_fi_enabled(&self, enabled: bool) -> impl Future<Output = Result<(), CarError>> + Send {
        self.tapped(
            Op::SetFiEnabled(enabled),
            self.inner.set_fi_enabled(enabled),
        )
    }

    fn add_fault(
        &self,
        probe: &Probe,
        kind: FaultKind,
        param: f32,
        start: i32,
        duration: i32,
    ) -> impl Future<Output = Result<(), CarError>> + Send {
        let op = Op::AddFault {
            probe: probe.to_string(),
            kind,
            param,
            start,
            duration,
        };
        let call = self.inner.add_fault(probe, kind, param, start, duration);
        self.tapped(op, call)
    }

    fn list_faults_part(&self) -> impl Future<Output = Result<Vec<ListedFault>, CarError>> + Send {
        self.tapped(Op::ListFaults, self.inner.list_faults_part())
    }

    fn clear_faults(&self) -> impl Future<Output = Result<(), CarError>> + Send {
        self.tapped(Op::ClearFaults, self.inner.clear_faults())
    }

    fn reset_uwb_pos(&self) -> impl Future<Output = Result<(), CarError>> + Send {
        self.tapped(Op::ResetUwbPos, self.inner.reset_uwb_pos())
    }
}

/// Runs the campaign on a fresh embedded simulated car (in virtual time, on a runtime of its
/// own), through a tap when `tap`; the case files it wrote, and what the tap saw.
fn campaign(out: &Path, tap: bool) -> (Vec<String>, Option<Log>) {
    let scenario = scenarios::bundled::load(SCENARIO)
        .expect("bundled")
        .scenario;
    let campaign = Campaign {
        seed: SEED,
        tests: TESTS,
        no_faults: false,
    };
    let mut config = RunConfig::new(campaign, out.to_owned(), "sim");
    config.record = RecordMode::None;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .expect("a runtime");
    let log = runtime.block_on(async {
        let sim_config = car_sim::SimConfig {
            seed: SEED,
            ..car_sim::SimConfig::from_scenario(&scenario)
        };
        let (car, sim) = connect_sim(&sim_config).await.expect("the simulated car");
        let cancel = CancellationToken::new();
        let log = if tap {
            let tapped = Tap::new(car);
            run_campaign(&tapped, &scenario, &config, &cancel, &Silent, None)
                .await
                .expect("the campaign runs");
            let log = std::mem::take(&mut *tapped.log());
            Some(log)
        } else {
            run_campaign(&car, &scenario, &config, &cancel, &Silent, None)
                .await
                .expect("the campaign runs");
            None
        };
        sim.shutdown();
        log
    });
    let cases = (0..TESTS)
        .map(|i| {
            std::fs::read_to_string(out.join(format!("case-{i:03}.json"))).expect("a case file")
        })
        .collect();
    (cases, log)
}

/// The index of the first call at or after `from` that is `op`.
fn find(calls: &[Call], from: usize, op: &Op) -> Option<usize> {
    (from..calls.len()).find(|&k| calls[k].op == *op)
}

/// The faults test `case` says the car confirmed, as the tap records them sent.
fn confirmed_faults(case: &Case) -> Vec<Op> {
    case.fault_places
        .iter()
        .map(
            |placement| match case.commands[placement.command_index].to_command() {
                Command::AddFault(fault) => Op::AddFault {
                    probe: fault.probe.to_string(),
                    kind: fault.kind,
                    param: fault.param as f32,
                    start: i32::try_from(fault.start).expect("a start in range"),
                    duration: i32::try_from(fault.duration).expect("a duration in range"),
                },
                other => panic!("fault place on {other:?}"),
            },
        )
        .collect()
}

#[test]
fn a_campaign_runs_through_a_tapped_vehicle_as_the_runner_promises() {
    let dir = tempfile::tempdir().expect("a directory");
    let (tapped_cases, log) = campaign(&dir.path().join("tapped"), true);
    let log = log.expect("the tap's log");
    let calls = &log.calls;

    // The tap changes nothing.
    let (plain_cases, _) = campaign(&dir.path().join("plain"), false);
    assert_eq!(
        tapped_cases, plain_cases,
        "the case files differ through the tap"
    );

    // Every call was answered, and on this link without loss, answered well.
    for call in calls {
        assert_eq!(
            call.ended.map(|(_, ok)| ok),
            Some(true),
            "unanswered or failed: {call:?}"
        );
    }
    assert!(
        log.samples > 100,
        "the telemetry stream flowed: {}",
        log.samples
    );

    // Preflight: the round trip measured first, then configuration, anchors, fault injection on
    // and cleared, all before the car is asked to move.
    let first_move = find(calls, 0, &Op::SetAutopilot(true)).expect("the car drove");
    let before: Vec<&Op> = calls[..first_move].iter().map(|c| &c.op).collect();
    assert_eq!(before[0], &Op::StateWithin, "{before:?}");
    for needed in [
        Op::PrepareForTestDrive,
        Op::UploadAnchors(2),
        Op::SetFiEnabled(true),
        Op::ClearFaults,
        Op::ResetUwbPos,
    ] {
        assert!(
            before.contains(&&needed),
            "{needed:?} not before {before:?}"
        );
    }

    // A segment is never sent before the car confirmed the previous one.
    assert_eq!(log.most_uploads_in_flight, 1);

    // The autopilot never starts on an empty route.
    let mut route_points = 0;
    for call in calls {
        match call.op {
            Op::ClearRoute => route_points = 0,
            Op::AddPoints(n) => route_points += n,
            Op::SetAutopilot(true) => assert!(route_points > 0, "started on an empty route"),
            _ => {}
        }
    }

    // The session ends disarmed: its last calls clear the faults and disable fault injection.
    let ops: Vec<&Op> = calls.iter().map(|c| &c.op).collect();
    assert_eq!(
        ops[ops.len() - 2..],
        [&Op::ClearFaults, &Op::SetFiEnabled(false)],
        "{ops:?}"
    );
    let calls = &calls[..calls.len() - 2];

    // Each test: the reset (from its clear_faults) and the drive (from the autopilot's second
    // start, after the return route's). Faults only during the drive, exactly those the case
    // says were confirmed; the test ends braking after its last route upload.
    let resets: Vec<usize> = (0..calls.len())
        .filter(|&k| calls[k].op == Op::ClearFaults)
        .skip(1) // preflight's
        .collect();
    assert_eq!(resets.len(), TESTS, "one reset per test");
    let mut faults_sent = 0;
    for (test_index, &reset) in resets.iter().enumerate() {
        let end = resets.get(test_index + 1).copied().unwrap_or(calls.len());
        let window = &calls[reset..end];
        let starts: Vec<usize> = (0..window.len())
            .filter(|&k| window[k].op == Op::SetAutopilot(true))
            .collect();
        assert_eq!(
            starts.len(),
            2,
            "test {test_index}: the return route, then the drive"
        );
        let drive_start = window[starts[1]].ended.expect("answered").0;
        let sent: Vec<Op> = window
            .iter()
            .filter(|c| matches!(c.op, Op::AddFault { .. }))
            .map(|c| {
                assert!(
                    c.started >= drive_start,
                    "test {test_index}: a fault before the drive started"
                );
                c.op.clone()
            })
            .collect();
        let case = Case::from_json(&tapped_cases[test_index]).expect("a case");
        assert_eq!(sent, confirmed_faults(&case), "test {test_index}");
        faults_sent += sent.len();
        let last_upload = window
            .iter()
            .rposition(|c| matches!(c.op, Op::AddPoints(_)))
            .expect("routes sent");
        assert!(
            window[last_upload..].iter().any(|c| c.op == Op::Brake),
            "test {test_index} does not end braking"
        );
        let brakes = window[starts[1]..]
            .iter()
            .filter(|c| c.op == Op::Brake)
            .count();
        assert!(brakes > 0, "test {test_index}: the drive never braked");
        assert!(
            case.commands
                .iter()
                .any(|c| matches!(c, CommandRecord::RunSegments { .. })),
            "test {test_index} drove segments"
        );
    }
    assert!(faults_sent > 0, "the campaign sent faults");
}

/// `run --dry-run` does everything before driving and nothing after: the tap sees preflight, the
/// route uploaded and read back, the faults uploaded and listed, everything cleared, and never
/// the autopilot switched on; the car stands where it stood.
#[test]
fn a_dry_run_uploads_and_reads_back_but_never_starts_the_autopilot() {
    let scenario = scenarios::bundled::load(SCENARIO)
        .expect("bundled")
        .scenario;
    let campaign = Campaign {
        seed: SEED,
        tests: TESTS,
        no_faults: false,
    };
    let config = RunConfig::new(campaign, std::path::PathBuf::new(), "sim");
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .expect("a runtime");
    let (found, log, moved) = runtime.block_on(async {
        let sim_config = car_sim::SimConfig {
            seed: SEED,
            ..car_sim::SimConfig::from_scenario(&scenario)
        };
        let (car, sim) = connect_sim(&sim_config).await.expect("the simulated car");
        let tapped = Tap::new(car);
        let before = tapped.state().await.expect("a state").state;
        let found = runner::dry_run(&tapped, &scenario, &config, &Silent)
            .await
            .expect("the dry run passes on the simulated car");
        tokio::time::sleep(Duration::from_secs(2)).await;
        let after = tapped.state().await.expect("a state").state;
        let moved = (after.px - before.px).hypot(after.py - before.py);
        let log = std::mem::take(&mut *tapped.log());
        sim.shutdown();
        (found, log, moved)
    });
    let ops: Vec<&Op> = log.calls.iter().map(|c| &c.op).collect();
    assert!(
        !ops.iter().any(|op| matches!(op, Op::SetAutopilot(true))),
        "the autopilot was switched on: {ops:?}"
    );
    let count = |f: fn(&Op) -> bool| ops.iter().filter(|op| f(op)).count();
    assert!(count(|op| matches!(op, Op::RoutePart)) >= 1, "{ops:?}");
    assert_eq!(
        count(|op| matches!(op, Op::AddFault { .. })),
        found.faults_uploaded
    );
    assert!(
        found.faults_uploaded > 0,
        "seed {SEED}'s first test has faults"
    );
    assert_eq!(found.faults_listed, found.faults_uploaded);
    assert!(found.route_points > 4, "{found:?}");
    assert!(found.route_read_back_error < 0.01, "{found:?}");
    // The last word on the route and the faults is a clear: nothing is left on the car.
    let last = |f: fn(&Op) -> bool| ops.iter().rposition(|op| f(op));
    assert!(last(|op| matches!(op, Op::ClearRoute)) > last(|op| matches!(op, Op::AddPoints(_))));
    assert!(
        last(|op| matches!(op, Op::ClearFaults)) > last(|op| matches!(op, Op::AddFault { .. }))
    );
    // The session ends disarmed: fault injection off after it was last on.
    assert!(
        last(|op| matches!(op, Op::SetFiEnabled(false)))
            > last(|op| matches!(op, Op::SetFiEnabled(true))),
        "{ops:?}"
    );
    assert!(moved < 0.05, "the car moved {moved:.3} m");
}
