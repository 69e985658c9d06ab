//! The campaign runner: drives planned tests against a car in real time (or in virtual time
//! against the simulator) and writes the run directory (method §6, issue 6).
//!
//! [`run_campaign`] performs, on tokio's clock:
//! 1. **Preflight**, once: the firmware version, the configuration the method needs (routes not
//!    repeated, speed mode, the fused position reported; set by read-modify-write or refused),
//!    the scenario's anchors uploaded, fault injection enabled and cleared, the car inside the
//!    fence, and the link's round trip measured ([`preflight`]).
//! 2. Per test, the **reset** ([`reset`]): faults and route cleared, a return route planned with
//!    the `recovery` crate from the car's RTK pose and driven with the rest of the recovery
//!    route to its end, the car braked to a stop, the UWB estimate set to the RTK estimate.
//! 3. The **test drive** ([`drive`]): the start route from where the car stands, then the
//!    planned commands, streamed: each segment is appended when the time the car still needs to
//!    reach its stopping point falls to the lead time (measured round trips and generation time
//!    plus a margin, and a round trip per command still to send before it); fault commands are
//!    confirmed by their reply. State samples at a fixed rate feed the oracle (per segment) and
//!    the safety monitor. At the end, and on any abort, the safe stop: a slow (0.8 m/s)
//!    extension generated with the ahead margin, then braking until the speed is below 0.1 m/s
//!    (or braking at once when the monitor demands it).
//! 4. The **record** ([`record`]): `campaign.json` (written at the start and again at the end)
//!    and one case file per test, in the formats of [`campaign::case`]; and all along, the
//!    telemetry recording `campaign.mcap` ([`crate::recording`], written through a journal):
//!    every state sample, every command sent with its answer, the planned segments and return
//!    routes, the fault commands, the oracle results, the safety stops, each test's start and
//!    end, and with the embedded simulator its truth and debug events.
//!
//! Invariants: a lost link is never a pass (the test is `aborted` with reason `link lost` and the
//! campaign ends as an error); every random choice derives from the campaign seed; in virtual
//! time the same seed gives identical case files (nothing in a case file reads the wall clock)
//! and a recording whose messages are identical (its log time is tokio's clock); a recording
//! error ends the campaign as an error after the running test.
//!
//! Not here: planning the tests (`campaign::model`), judging samples (`campaign::oracle`), the safety
//! and streaming rules (`campaign::safety`, `campaign::streaming`), the wire protocol (`car-link`).

pub mod drive;
mod journal;
pub mod preflight;
pub mod record;
pub mod reset;
mod telemetry;

use std::path::PathBuf;
use std::time::Duration;

use car_link::{Car, CarError};
use car_sim::SimHandle;
use indicatif::ProgressBar;
use scenarios::Scenario;
use thiserror::Error;
use tokio_util::sync::CancellationToken;
use trajgen::{GenerationError, Generator, Strategy};

use crate::recording::{
    DEFAULT_CHUNK_INTERVAL, OracleRecord, PlannedSegment, Recorder, RecordingError, RecordingStart,
    SafetyRecord, TestEvent, TestEventKind,
};
use campaign::case::{Case, CaseError, ReplayOf, RoutePointRecord, Settings};
use campaign::model::{Campaign, ModelError, ProbeRates, TestPlan, TestPlanner};
use campaign::oracle::{FailurePolicy, Verdict};
use campaign::safety::{Abort, AbortReason, SafetyConfig};
use campaign::streaming::StreamingConfig;

pub use preflight::Preflight;
pub use record::{
    CampaignReport, RECORDING_FILE, RunDirectory, TestSummary, rfc3339_now, run_dir_name,
};

use journal::Journal;
use telemetry::Telemetry;

/// Speed of the safe stop's extension, m/s (method §6).
pub const SAFE_STOP_SPEED_MPS: f64 = 0.8;
/// The car counts as stopped below this speed, m/s.
pub const STOPPED_SPEED_MPS: f64 = 0.1;
/// Brake current of the safe stop, amperes (the reference's 50 A).
pub const BRAKE_CURRENT_A: f64 = 50.0;
/// Longest the runner brakes waiting for the car to stop.
pub const BRAKE_TIMEOUT: Duration = Duration::from_secs(5);

/// How a campaign runs.
#[derive(Debug, Clone, PartialEq)]
pub struct RunConfig {
    /// Seed, number of tests, faults or not.
    pub campaign: Campaign,
    /// What happens after a failing segment.
    pub policy: FailurePolicy,
    /// The safety monitor's limits (the stale-telemetry limit is raised to what the measured
    /// link allows, see [`Preflight::safety`]).
    pub safety: SafetyConfig,
    /// The streaming rule's constants.
    pub streaming: StreamingConfig,
    /// Period of the state samples (50 ms: 20 Hz).
    pub state_period: Duration,
    /// The run directory to write.
    pub out_dir: PathBuf,
    /// The car as the user named it (`sim`, `tcp://…`), for `campaign.json`.
    pub car_label: String,
    /// A recorded case to drive in every test instead of generated tests (`drivecheck replay`).
    pub replay: Option<ReplaySource>,
}

/// A case driven again instead of generated tests: every test of the campaign drives its plan
/// after the usual reset.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplaySource {
    /// The plan every test drives (its test index is set per test), see
    /// [`Case::replay_plan`].
    pub plan: TestPlan,
    /// Where it came from, for `campaign.json`.
    pub of: ReplayOf,
}

impl RunConfig {
    /// The defaults for `campaign`, writing to `out_dir`.
    pub fn new(campaign: Campaign, out_dir: PathBuf, car_label: impl Into<String>) -> Self {
        Self {
            campaign,
            policy: FailurePolicy::default(),
            safety: SafetyConfig::default(),
            streaming: StreamingConfig::default(),
            state_period: Duration::from_millis(50),
            out_dir,
            car_label: car_label.into(),
            replay: None,
        }
    }
}

/// Why a campaign could not run (or not to its end).
#[derive(Debug, Error)]
pub enum RunError {
    /// The car is not fit for the method (version, configuration, position).
    #[error("preflight: {0}")]
    Preflight(String),
    /// A command to the car failed outside a test drive.
    #[error("{what}: {source}")]
    Car {
        /// What the runner was doing.
        what: String,
        /// The link's error.
        source: CarError,
    },
    /// The link was lost: the test was aborted and the campaign cannot go on.
    #[error("test {test_index}: the link to the car was lost")]
    LinkLost {
        /// The test that was running.
        test_index: usize,
    },
    /// The operator interrupted the campaign (after the safe stop).
    #[error("interrupted during test {test_index}")]
    Interrupted {
        /// The test that was running.
        test_index: usize,
    },
    /// A test could not be planned.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The scenario's generator settings are unusable.
    #[error("generator: {0}")]
    Generator(#[source] GenerationError),
    /// No return route to the recovery route.
    #[error("test {test_index}: no return route: {source}")]
    Recovery {
        /// The test.
        test_index: usize,
        /// The planner's reason.
        source: recovery::RecoveryError,
    },
    /// The reset drive did not end at the recovery route's end.
    #[error("test {test_index}: reset: {reason}")]
    Reset {
        /// The test.
        test_index: usize,
        /// What happened.
        reason: String,
    },
    /// A case file or the campaign record could not be written.
    #[error(transparent)]
    Case(#[from] CaseError),
    /// The recording (`campaign.mcap`) could not be written.
    #[error("recording: {0}")]
    Recording(#[source] RecordingError),
    /// Writing the run directory failed.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

impl RunError {
    /// The error of `source` while doing `what`.
    pub fn car(what: impl Into<String>, source: CarError) -> Self {
        Self::Car {
            what: what.into(),
            source,
        }
    }
}

/// What a test's run ended with, besides its case file.
#[derive(Debug)]
enum TestEnd {
    /// The campaign goes on.
    Continue,
    /// The campaign stops with this error (the case is recorded).
    Stop(RunError),
}

/// Everything a test needs that stays the same over the campaign.
#[derive(Debug)]
pub(crate) struct Context<'a> {
    pub(crate) car: &'a Car,
    pub(crate) scenario: &'a Scenario,
    pub(crate) config: &'a RunConfig,
    pub(crate) safety: SafetyConfig,
    pub(crate) sample_timeout: Duration,
    pub(crate) generator: Generator,
    pub(crate) rates: ProbeRates,
    pub(crate) cancel: &'a CancellationToken,
    pub(crate) journal: &'a Journal<'a>,
}

/// Runs a campaign against `car` in `scenario` and writes its run directory, with its recording
/// `campaign.mcap`; `sim` is the embedded simulator's handle when `car` is simulated (its truth
/// and debug events are recorded too), `None` for a real car.
///
/// Returns the report when every test ran (whatever their verdicts); an error when the campaign
/// could not run to its end (preflight refused, link lost, interrupted, a reset or a plan
/// failed): the run directory is then still complete (`campaign.json` with its end time and
/// summary, a case file for every test started, the recording completed as far as it could be
/// written). A recording that cannot be written is an error ([`RunError::Recording`]): the
/// campaign stops after the running test.
///
/// Timeout: every car command is bounded by the link's timeouts; a reset drive by its route's
/// length at its speed plus 60 s; braking by [`BRAKE_TIMEOUT`]. Cancellation: `cancel` performs
/// the safe stop of the running test, records it as `aborted (interrupted)` and ends the campaign
/// with [`RunError::Interrupted`]. Dropping the future instead stops at once without a safe stop
/// (the car's watchdog then brakes it within 2 s) and leaves `campaign.json` without an end.
pub async fn run_campaign(
    car: &Car,
    scenario: &Scenario,
    config: &RunConfig,
    sim: Option<&SimHandle>,
    cancel: &CancellationToken,
    progress: &ProgressBar,
) -> Result<CampaignReport, RunError> {
    let origin = tokio::time::Instant::now();
    let settings = Settings::new(scenario, config.campaign.tests, config.policy);
    let mut dir = RunDirectory::create(config, scenario, settings)?;
    let start = RecordingStart {
        campaign: dir.record(),
        scenario,
        origin,
        simulated: sim.is_some(),
        chunk_interval: DEFAULT_CHUNK_INTERVAL,
    };
    let journal = match Recorder::create(&dir.path().join(RECORDING_FILE), &start) {
        Ok(recorder) => Journal::new(recorder, sim),
        Err(error) => {
            dir.finish()?;
            return Err(RunError::Recording(error));
        }
    };
    let run = Run {
        car,
        scenario,
        config,
        cancel,
        progress,
        journal: &journal,
    };
    let result = run_tests(&run, &mut dir).await;
    let report = dir.finish()?;
    let recorded = journal.finish(&report.record);
    result.and(recorded).map(|()| report)
}

/// What [`run_tests`] works with.
struct Run<'a> {
    car: &'a Car,
    scenario: &'a Scenario,
    config: &'a RunConfig,
    cancel: &'a CancellationToken,
    progress: &'a ProgressBar,
    journal: &'a Journal<'a>,
}

async fn run_tests(run: &Run<'_>, dir: &mut RunDirectory) -> Result<(), RunError> {
    let Run {
        car,
        scenario,
        config,
        cancel,
        progress,
        journal,
    } = *run;
    let preflight = Preflight::run(car, scenario, config, journal).await?;
    if !preflight.switched_off.is_empty() {
        progress.println(format!(
            "preflight: switched off {}",
            preflight.switched_off.join(", ")
        ));
    }
    dir.set_firmware(car.version().to_string());
    dir.set_runtime(preflight.safety, config.streaming);
    let ctx = Context {
        car,
        scenario,
        config,
        safety: preflight.safety,
        sample_timeout: preflight.sample_timeout,
        generator: Generator::new(scenario.generator.generator_config(Strategy::Wedge))
            .map_err(RunError::Generator)?,
        rates: preflight.rates,
        cancel,
        journal,
    };
    let planner = TestPlanner::new(scenario)?;
    let start_tail = campaign::model::start_tail(scenario)?;
    let mut telemetry = Telemetry::start(car, config.state_period, ctx.sample_timeout);
    // The first sample comes a round trip after polling starts: wait for it (or for the link's
    // end), so that no safety monitor is armed before samples flow.
    let _ = tokio::time::timeout(
        preflight.safety.stale_after + ctx.sample_timeout,
        telemetry.next(journal),
    )
    .await;
    progress.set_length(config.campaign.tests as u64);
    for test_index in 0..config.campaign.tests {
        if cancel.is_cancelled() {
            return Err(RunError::Interrupted { test_index });
        }
        let started = tokio::time::Instant::now();
        let plan = match &config.replay {
            Some(replay) => TestPlan {
                test_index,
                ..replay.plan.clone()
            },
            None => planner.plan_test(&config.campaign, test_index, start_tail)?,
        };
        let per_segment = started.elapsed() / plan.segments().count().max(1) as u32;
        let mut case = Case::planned(
            &plan,
            scenario,
            config.campaign.seed,
            config.campaign.no_faults,
            dir.settings().clone(),
        );
        let end = run_test(&ctx, &mut telemetry, &plan, &mut case, per_segment).await;
        dir.write_case(&case)?;
        record_test_end(journal, test_index, &case);
        progress.set_message(format!(
            "test {test_index}: {}",
            case.verdict.map_or("not run", Verdict::as_str)
        ));
        progress.inc(1);
        if let TestEnd::Stop(error) = end {
            return Err(error);
        }
        journal.check()?;
    }
    Ok(())
}

/// Records a test's oracle results and its end, and writes the recording's open chunk.
fn record_test_end(journal: &Journal<'_>, test_index: usize, case: &Case) {
    for result in &case.segments {
        journal.write(&OracleRecord {
            test_index,
            result: result.clone(),
        });
    }
    if let Some(verdict) = case.verdict {
        journal.write(&TestEvent {
            test_index,
            event: TestEventKind::Ended {
                verdict,
                reason: case.reason.clone(),
            },
        });
    }
    journal.flush();
}

/// Records that test `plan` starts, with its segments as planned.
fn record_test_start(journal: &Journal<'_>, plan: &TestPlan) {
    let test_index = plan.test_index;
    journal.write(&TestEvent {
        test_index,
        event: TestEventKind::Started {
            commands: plan.commands.len(),
        },
    });
    for (segment_index, (command_index, segment)) in plan.segments().enumerate() {
        journal.write(&PlannedSegment::new(
            test_index,
            command_index,
            segment_index,
            segment,
        ));
    }
}

/// Resets the car, drives the test and records the outcome in `case`.
async fn run_test(
    ctx: &Context<'_>,
    telemetry: &mut Telemetry,
    plan: &TestPlan,
    case: &mut Case,
    generation: Duration,
) -> TestEnd {
    let test_index = plan.test_index;
    let reset = match reset::reset(ctx, telemetry, test_index).await {
        Ok(reset) => reset,
        Err(stopped) => return record_stop_before_drive(ctx.journal, case, stopped, test_index),
    };
    record_test_start(ctx.journal, plan);
    case.return_route = reset
        .return_route
        .iter()
        .copied()
        .map(RoutePointRecord::from)
        .collect();
    case.return_clearance_m =
        (reset.clearance_m < ctx.scenario.generator.clearance_m).then_some(reset.clearance_m);
    let outcome = drive::drive(ctx, telemetry, plan, reset.standing, generation).await;
    outcome.record(case);
    match outcome.stop {
        Some(error) => TestEnd::Stop(error),
        None if outcome
            .abort
            .is_some_and(|a| a.reason == AbortReason::LinkLost) =>
        {
            TestEnd::Stop(RunError::LinkLost { test_index })
        }
        None if outcome
            .abort
            .is_some_and(|a| a.reason == AbortReason::Interrupted) =>
        {
            TestEnd::Stop(RunError::Interrupted { test_index })
        }
        None => TestEnd::Continue,
    }
}

/// Tries of an idempotent car command before its error counts (a lossy link drops a terminal
/// command or its reply now and then; only idempotent commands are retried).
const IDEMPOTENT_TRIES: u32 = 3;

/// Runs an idempotent car command up to [`IDEMPOTENT_TRIES`] times; a lost link is not retried.
///
/// Timeout: each try as the command's own. Cancellation: safe for an idempotent command.
pub(crate) async fn retried<T, F, Fut>(mut command: F) -> Result<T, CarError>
where
    F: FnMut() -> Fut,
    Fut: Future<Output = Result<T, CarError>>,
{
    let mut tries = 1;
    loop {
        match command().await {
            Err(CarError::LinkLost) => return Err(CarError::LinkLost),
            Err(_) if tries < IDEMPOTENT_TRIES => tries += 1,
            result => return result,
        }
    }
}

/// How a reset ended when it did not bring the car to the start.
#[derive(Debug)]
pub(crate) enum Stopped {
    /// Stopped for this reason (link lost, safety, interrupt).
    Abort(Abort),
    /// Failed; the campaign cannot go on.
    Error(RunError),
}

fn record_stop_before_drive(
    journal: &Journal<'_>,
    case: &mut Case,
    stopped: Stopped,
    test_index: usize,
) -> TestEnd {
    case.verdict = Some(Verdict::Aborted);
    match stopped {
        Stopped::Abort(abort) => {
            journal.write(&SafetyRecord::new(None, abort));
            case.reason = Some(format!("reset: {}", abort.reason));
            case.abort = Some(abort);
            match abort.reason {
                AbortReason::LinkLost => TestEnd::Stop(RunError::LinkLost { test_index }),
                AbortReason::Interrupted => TestEnd::Stop(RunError::Interrupted { test_index }),
                _ => TestEnd::Continue,
            }
        }
        Stopped::Error(error) => {
            case.reason = Some(error.to_string());
            TestEnd::Stop(error)
        }
    }
}
