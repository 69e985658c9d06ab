//! A campaign on fresh simulated cars: every test runs on a simulated car of its own, seeded from
//! the campaign's seed and the test's index, standing where the plan of the test before it ends;
//! up to `jobs` tests at once, each on a thread with its own async runtime (its own virtual
//! clock). A test therefore depends on (scenario, seed, index) only: the serial run, `--jobs N`
//! and the shards of a campaign give the same case files.
//!
//! Each test is the whole method on its car: preflight (which measures the link, uploads the
//! anchors, enables fault injection), the reset with its return route from where the car stands,
//! the drive and its safe stop. Its recording is held in memory ([`Recorder::in_memory`]); the
//! campaign's thread writes the case files, the recording and the progress in test order, so that
//! `campaign.mcap` is the same whatever the number of jobs: test *k*'s messages follow test
//! *k − 1*'s, log time shifted to start 1 ms after the last message before them, and a
//! `drivecheck.test.<k>` metadata record gives their span (`drivecheck runs merge` reads it).
//!
//! Not here: how a simulated car is made (`FreshCars`, implemented with `car-sim` by
//! `crate::vehicle::EmbeddedSims`). The seam's traits and types (`FreshCars`,
//! `StartPose`) are `crate::vehicle`'s.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;

use scenarios::Scenario;
use tokio_util::sync::CancellationToken;
use trajgen::Point;

use super::journal::Journal;
use super::run_dir::RunDirectory;
use super::{
    CampaignFailure, CampaignObserver, CampaignReport, RecordMode, RunConfig, RunError, TestEnd,
    TestSource, finish_campaign, open_session, plan_and_run, record_test_end, reset,
    start_join_note, switched_off_note,
};
use crate::vehicle::{ConnectError, FreshCars, StartPose, Vehicle};
use campaign::files::{Case, Settings};
use campaign::model::{Campaign, TestPlan, TestPlanner};
use campaign::oracle::Verdict;
use campaign::safety::SafetyConfig;
use recording::{Held, Recorder};

/// Where the car stands when test `test_index` begins: where the plan of the test before it ends
/// (the last point it drives, heading along its last leg), as on a car that drove it; `None` for
/// the first test.
fn start_pose(tests: &TestSource<'_>, test_index: usize) -> Result<Option<StartPose>, RunError> {
    if test_index == 0 {
        return Ok(None);
    }
    Ok(end_pose(&tests.plan(test_index - 1)?))
}

/// Where the simulated car stood when test `test_index` of a generated campaign (`run` on the
/// embedded simulator, without `--cases-from`) began, as the campaign placed it: where the plan
/// of the test before it ends; `None` for the first test (the start of the start route). What
/// a case driven again as that test starts from ([`ReplaySource::as_test`](crate::ReplaySource)).
pub fn start_of_test(
    scenario: &Scenario,
    campaign: &Campaign,
    test_index: usize,
) -> Result<Option<StartPose>, RunError> {
    let Some(before) = test_index.checked_sub(1) else {
        return Ok(None);
    };
    let planner = TestPlanner::new(scenario)?;
    let plan = planner.plan_test(campaign, before, campaign::model::start_tail(scenario)?)?;
    Ok(end_pose(&plan))
}

/// The test a case was on the embedded simulator, as a case driven again as that test drives
/// it: the campaign's seed (its reset, safe stop and simulated car), the test's index, and where
/// the campaign placed the car.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SameTest {
    /// The campaign's seed.
    pub campaign_seed: u64,
    /// The test's index.
    pub test_index: usize,
    /// Where its car stood when it began ([`start_of_test`]).
    pub start: Option<StartPose>,
}

impl SameTest {
    /// The test of `case` in `scenario`: `None` for a case that names no campaign seed or test
    /// index (written by hand). The start is derived as the campaign placed the car
    /// ([`start_of_test`], from the case's settings' number of tests and `no_faults`): exact for
    /// a generated campaign (sharded or resumed alike), not for a test of `run --cases-from`,
    /// whose car stood where the case before it ended.
    pub fn of_case(case: &Case, scenario: &Scenario) -> Result<Option<Self>, RunError> {
        let (Some(campaign_seed), Some(test_index)) = (case.campaign_seed, case.test_index) else {
            return Ok(None);
        };
        let tests = case
            .settings
            .as_ref()
            .map_or(test_index + 1, |s| s.tests.max(test_index + 1));
        let campaign = Campaign {
            seed: campaign_seed,
            tests,
            no_faults: case.no_faults,
        };
        Ok(Some(Self {
            campaign_seed,
            test_index,
            start: start_of_test(scenario, &campaign, test_index)?,
        }))
    }
}

/// The last point `plan` drives, heading along its last leg.
fn end_pose(plan: &TestPlan) -> Option<StartPose> {
    let points: Vec<Point> = plan
        .segments()
        .flat_map(|(_, segment)| segment.points.iter().copied())
        .collect();
    let [.., before, last] = points[..] else {
        return None;
    };
    Some(StartPose {
        position: last,
        heading: (last - before).heading(),
    })
}

/// The first command id of test `test_index`'s recording: ids stay unique in the campaign's file.
fn first_command(test_index: usize) -> u64 {
    (test_index as u64 + 1) << 32
}

/// Log time between the last message of a test and the first of the next in the campaign's
/// recording.
pub const SPAN_GAP_NS: u64 = 1_000_000;

/// What one test on a fresh car gave.
struct Ran {
    case: Case,
    end: TestEnd,
    held: Vec<Held>,
    firmware: String,
    safety: SafetyConfig,
    switched_off: Vec<String>,
    start_join: usize,
}

/// What the campaign shares with its workers.
struct Shared<'a, C: ?Sized> {
    cars: &'a C,
    scenario: &'a Scenario,
    config: &'a RunConfig,
    cancel: &'a CancellationToken,
    tests: TestSource<'a>,
    start_join: Vec<Point>,
    /// The settings of `campaign.json` as created (without the runtime constants).
    settings: Settings,
}

/// Runs a campaign with a fresh simulated car per test, up to `jobs` at once (see the module
/// doc), and writes its run directory as [`super::run_campaign`] does: same files, same
/// failures. A test that stops the campaign (interrupted, a preflight refused, a reset that
/// failed) lets the tests already running end; no test starts after it.
///
/// Call it outside any async runtime: each test runs on a runtime of its own, on one of `jobs`
/// threads. Cancellation: `cancel` makes every running test stop safely, recorded as `aborted
/// (interrupted)`, and the campaign ends with [`RunError::Interrupted`].
#[allow(
    clippy::result_large_err,
    reason = "the failure of run_campaign, returned once per campaign"
)]
pub fn run_campaign_fresh<C: FreshCars + ?Sized>(
    cars: &C,
    scenario: &Scenario,
    config: &RunConfig,
    jobs: usize,
    cancel: &CancellationToken,
    observer: &dyn CampaignObserver,
) -> Result<CampaignReport, CampaignFailure> {
    let origin = tokio::time::Instant::now();
    let settings = Settings::new(scenario, config.campaign.tests, config.policy);
    let mut dir = RunDirectory::create(config, scenario, settings.clone())
        .map_err(CampaignFailure::without_report)?;
    let (journal, first_offset_ns) =
        match super::spanned_journal(config, scenario, &dir, origin, true, observer) {
            Ok(opened) => opened,
            Err(error) => return Err(super::recording_not_started(dir, error)),
        };
    let result = prepare(scenario, config, cars, cancel, settings).and_then(|shared| {
        run_tests(
            &shared,
            jobs.max(1),
            observer,
            &mut dir,
            &journal,
            first_offset_ns,
        )
    });
    finish_campaign(dir, journal, result)
}

fn prepare<'a, C: FreshCars + ?Sized>(
    scenario: &'a Scenario,
    config: &'a RunConfig,
    cars: &'a C,
    cancel: &'a CancellationToken,
    settings: Settings,
) -> Result<Shared<'a, C>, RunError> {
    Ok(Shared {
        cars,
        scenario,
        config,
        cancel,
        tests: TestSource::new(scenario, config)?,
        start_join: reset::plan_start_join(scenario, config.campaign.seed)?,
        settings,
    })
}

/// Runs the tests on `jobs` threads and writes what they give in test order.
fn run_tests<C: FreshCars + ?Sized>(
    shared: &Shared<'_, C>,
    jobs: usize,
    observer: &dyn CampaignObserver,
    dir: &mut RunDirectory,
    journal: &Journal<'_>,
    first_offset_ns: u64,
) -> Result<(), RunError> {
    let indices = shared.config.test_indices();
    observer.tests_planned(indices.len());
    let next = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let (tx, rx) = mpsc::channel::<(usize, Result<Ran, RunError>)>();
    std::thread::scope(|scope| {
        for _ in 0..jobs.min(indices.len()) {
            let tx = tx.clone();
            let (next, stop, indices) = (&next, &stop, &indices);
            scope.spawn(move || {
                loop {
                    if stop.load(Ordering::SeqCst) || shared.cancel.is_cancelled() {
                        break;
                    }
                    let Some(&test_index) = indices.get(next.fetch_add(1, Ordering::SeqCst)) else {
                        break;
                    };
                    super::pause::pause(super::pause::At::Before, test_index, shared.cancel);
                    if shared.cancel.is_cancelled() {
                        break;
                    }
                    let ran = run_one(shared, test_index);
                    if matches!(
                        &ran,
                        Err(_)
                            | Ok(Ran {
                                end: TestEnd::Stop(_),
                                ..
                            })
                    ) {
                        stop.store(true, Ordering::SeqCst);
                    }
                    if tx.send((test_index, ran)).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        let mut writer = InOrder::new(indices.clone(), first_offset_ns);
        let mut first_error = None;
        for (test_index, ran) in rx {
            for (test_index, ran) in writer.ready(test_index, ran) {
                let written =
                    write_test(shared, observer, dir, journal, &mut writer, test_index, ran);
                if let Err(error) = written {
                    stop.store(true, Ordering::SeqCst);
                    first_error.get_or_insert(error);
                }
            }
        }
        if let (None, Some(&test_index)) = (&first_error, indices.get(writer.next))
            && shared.cancel.is_cancelled()
        {
            first_error = Some(RunError::Interrupted { test_index });
        }
        first_error.map_or(Ok(()), Err)
    })
}

/// Results in test order: what came early waits for the tests before it.
struct InOrder {
    indices: Vec<usize>,
    /// Position in `indices` of the next test to write.
    next: usize,
    waiting: BTreeMap<usize, Result<Ran, RunError>>,
    /// Where the next test's messages start in the campaign's recording, ns.
    offset_ns: u64,
    /// The first test written: its car gives the campaign's firmware and runtime constants.
    first: bool,
}

impl InOrder {
    /// `offset_ns`: where the first test's messages start (after the campaign's own messages at
    /// log time 0, the area, and a resumed campaign's earlier tests).
    fn new(indices: Vec<usize>, offset_ns: u64) -> Self {
        Self {
            indices,
            next: 0,
            waiting: BTreeMap::new(),
            offset_ns,
            first: true,
        }
    }

    /// Takes `ran` of test `test_index` and returns the tests now due, in order.
    fn ready(
        &mut self,
        test_index: usize,
        ran: Result<Ran, RunError>,
    ) -> Vec<(usize, Result<Ran, RunError>)> {
        self.waiting.insert(test_index, ran);
        let mut due = Vec::new();
        while let Some(&index) = self.indices.get(self.next) {
            let Some(ran) = self.waiting.remove(&index) else {
                break;
            };
            due.push((index, ran));
            self.next += 1;
        }
        due
    }
}

/// Writes test `test_index`'s case file and recording, and reports it.
fn write_test<C: FreshCars + ?Sized>(
    shared: &Shared<'_, C>,
    observer: &dyn CampaignObserver,
    dir: &mut RunDirectory,
    journal: &Journal<'_>,
    order: &mut InOrder,
    test_index: usize,
    ran: Result<Ran, RunError>,
) -> Result<(), RunError> {
    let ran = ran?;
    if std::mem::take(&mut order.first) {
        if !ran.switched_off.is_empty() {
            observer.detail(&switched_off_note(&ran.switched_off));
        }
        if ran.start_join > 0 {
            observer.note(&start_join_note(&shared.start_join));
        }
        dir.set_firmware(ran.firmware.clone());
        dir.set_runtime(ran.safety, shared.config.streaming);
    }
    observer.test_started(test_index);
    let keep = match shared.config.record {
        RecordMode::All => true,
        RecordMode::Failing => ran.case.verdict != Some(Verdict::Passed),
        RecordMode::None => false,
    };
    // The recording first (its span written through to the file), then the case file: a test
    // with a case file has its span, whenever the process is killed (#51 item 2). A recording
    // that failed writes no case file: a resume drives the test again.
    if keep && !ran.held.is_empty() {
        let last = ran.held.iter().map(Held::log_time).max().unwrap_or(0);
        journal.write_held(ran.held, order.offset_ns);
        journal.test_span(test_index, order.offset_ns, order.offset_ns + last, None);
        order.offset_ns += last + SPAN_GAP_NS;
    }
    journal.check()?;
    dir.write_case(&ran.case)?;
    observer.test_finished(test_index, ran.case.verdict);
    if let TestEnd::Stop(error) = ran.end {
        return Err(error);
    }
    Ok(())
}

/// Runs test `test_index` on a fresh car, on a runtime of its own.
fn run_one<C: FreshCars + ?Sized>(
    shared: &Shared<'_, C>,
    test_index: usize,
) -> Result<Ran, RunError> {
    // Time only: a fresh car is in process (no sockets), and without an I/O driver a runtime
    // parks without a system call, which in virtual time is most of its parking.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .start_paused(shared.cars.virtual_time())
        .build();
    let runtime = runtime.map_err(|source| RunError::Io {
        path: "the async runtime".into(),
        source,
    })?;
    runtime.block_on(fresh_test(shared, test_index))
}

/// Test `test_index` on a fresh car: the car, preflight, reset and drive.
async fn fresh_test<C: FreshCars + ?Sized>(
    shared: &Shared<'_, C>,
    test_index: usize,
) -> Result<Ran, RunError> {
    let Shared {
        cars,
        scenario,
        config,
        cancel,
        ..
    } = *shared;
    let origin = tokio::time::Instant::now();
    let start = start_pose(&shared.tests, test_index)?;
    let (car, sim) = cars
        .connect(test_index, start)
        .await
        .map_err(|error: ConnectError| {
            RunError::Preflight(format!(
                "the simulated car of test {test_index}: {}",
                with_causes(&error)
            ))
        })?;
    let journal = match (config.record, config.live.as_ref()) {
        (RecordMode::None, Some(live)) => Journal::new(
            Recorder::live_only(origin, true, first_command(test_index), live, None)
                .map_err(RunError::Recording)?,
            Some(&*sim),
        ),
        (RecordMode::None, None) => Journal::without_recording(Some(&*sim)),
        (RecordMode::All | RecordMode::Failing, _) => Journal::new(
            Recorder::in_memory(
                origin,
                true,
                first_command(test_index),
                config.live.as_ref(),
            ),
            Some(&*sim),
        ),
    };
    let (ctx, mut telemetry, preflight) = open_session(
        &car,
        scenario,
        config,
        cancel,
        &journal,
        shared.start_join.clone(),
    )
    .await?;
    let settings = shared
        .settings
        .clone()
        .with_runtime(ctx.safety, config.streaming);
    let (case, end) =
        plan_and_run(&ctx, &mut telemetry, &shared.tests, test_index, &settings).await?;
    record_test_end(&journal, test_index, &case);
    drop(telemetry);
    // A test `--record failing` does not keep is dropped before its messages are encoded.
    let held = if config.record == RecordMode::Failing && case.verdict == Some(Verdict::Passed) {
        journal.drop_held();
        Vec::new()
    } else {
        journal.take_held()
    };
    let end = match (end, journal.check()) {
        (TestEnd::Continue, Err(error)) => TestEnd::Stop(error),
        (end, _) => end,
    };
    // A failing test is explained here, in parallel with the other workers, from the messages
    // it recorded; `run` then has nothing to read back for it (`drivecheck explain` finds the
    // same in the recording).
    let mut case = case;
    if case.verdict == Some(Verdict::Failed)
        && !held.is_empty()
        && let Some(explain) = config.explain
        && let Some(explanation) = explain(&held, test_index, &case, scenario)
    {
        case.explanation = explanation;
    }
    Ok(Ran {
        held,
        end,
        firmware: car.version().to_string(),
        safety: ctx.safety,
        switched_off: preflight.switched_off,
        start_join: ctx.start_join.len(),
        case,
    })
}

/// `error` and its causes, joined by `: ` (as the command line prints an error).
fn with_causes(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut cause = error.source();
    while let Some(next) = cause {
        text.push_str(": ");
        text.push_str(&next.to_string());
        cause = next.source();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use campaign::model::{Command, Segment};

    #[test]
    fn a_plan_ends_at_its_last_point_heading_along_its_last_leg() {
        let segment = |points: Vec<Point>| {
            Command::RunSegments(Segment {
                intent: None,
                speeds: vec![1.0; points.len()],
                points,
                margin: Vec::new(),
            })
        };
        let mut plan = TestPlan {
            test_index: 0,
            start_tail: trajgen::RouteTail::from_points(&[
                Point::new(-1.0, 0.0),
                Point::new(0.0, 0.0),
            ])
            .unwrap(),
            commands: vec![
                segment(vec![Point::new(0.0, 0.0), Point::new(1.0, 0.0)]),
                segment(vec![Point::new(1.0, 1.0)]),
            ],
        };
        let pose = end_pose(&plan).unwrap();
        assert_eq!(pose.position, Point::new(1.0, 1.0));
        assert!((pose.heading - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        plan.commands.truncate(0);
        assert_eq!(end_pose(&plan), None);
    }

    #[test]
    fn command_ids_of_different_tests_never_meet() {
        assert!(first_command(0) + u64::from(u32::MAX) < first_command(1));
        assert_ne!(first_command(0), 1);
    }
}
