//! The campaign runner: drives planned tests against a car in real time (or in virtual time
//! against the simulator) and writes the run directory (`docs/method.md#a-test-step-by-step`).
//!
//! [`run_campaign`] performs, on tokio's clock:
//! 1. **Preflight**, once: the firmware version, the configuration the method needs (routes not
//!    repeated, speed mode, the fused position reported; set by read-modify-write or refused),
//!    the scenario's anchors uploaded, fault injection enabled and cleared, the car inside the
//!    fence, and the link's round trip measured (`preflight`).
//! 2. Per test, the **reset** (`reset`): faults and route cleared, a return route planned with
//!    the `recovery` crate from the car's RTK pose and driven with the rest of the recovery
//!    route to its end, the car braked to a stop, the UWB estimate set to the RTK estimate.
//! 3. The **test drive** (`drive`, the async loop around the state machine
//!    [`campaign::drive::TestDrive`]): the start route from where the car stands, then the
//!    planned commands, streamed: each segment is appended when the time the car still needs to
//!    reach its stopping point falls to the lead time (measured round trips and generation time
//!    plus a margin, and a round trip per command still to send before it); fault commands are
//!    confirmed by their reply. State samples at a fixed rate feed the oracle (per segment) and
//!    the safety monitor. At the end, and on any abort, the safe stop: a slow (0.8 m/s)
//!    extension generated with the ahead margin, then braking until the speed is below 0.1 m/s
//!    (or braking at once when the monitor demands it).
//! 4. The **run directory** (`run_dir`): `campaign.json` (written at the start and again at
//!    the end) and one case file per test, in the formats of [`campaign::files`]; and all along,
//!    the telemetry recording `campaign.mcap` ([`recording`], written through a journal):
//!    every state sample, every command sent with its answer, the planned segments and return
//!    routes, the fault commands, the oracle results, the safety stops, each test's start and
//!    end, and with the embedded simulator its truth and debug events.
//!
//! The car is any [`Vehicle`] (the runner is generic over it), progress reaches the caller
//! through a [`CampaignObserver`], and the simulator's debug view reaches the journal through a
//! [`SimulatorView`] (`events`): the runner knows neither the car's protocol nor the terminal nor
//! the simulator.
//!
//! Invariants: a lost link is never a pass (the test is `aborted` with reason `link lost` and the
//! campaign ends as an error); every random choice derives from the campaign seed; in virtual
//! time the same seed gives identical case files (nothing in a case file reads the wall clock)
//! and a recording whose messages are identical (its log time is tokio's clock); a recording
//! error ends the campaign as an error after the running test.
//!
//! Not here: planning the tests (`campaign::model`), judging samples (`campaign::oracle`), the
//! safety and streaming rules (`campaign::safety`, `campaign::streaming`), the drive's decisions
//! (`campaign::drive`), the wire protocol (`car-link`).

pub mod atomic;
mod drive;
mod dry_run;
pub mod emergency;
mod events;
mod fresh;
mod journal;
pub mod junit;
mod lab;
pub mod merge;
mod pause;
mod preflight;
mod reset;
mod run_dir;
pub mod scratch;
pub mod session_end;
pub mod simdrive;
pub mod store;
mod telemetry;
pub mod vehicle;

use std::path::{Path, PathBuf};
use std::time::Duration;

use car_link::CarError;
use scenarios::Scenario;
use thiserror::Error;
use tokio_util::sync::CancellationToken;
use trajgen::{GenerationError, Generator, Point, RouteTail, Strategy};

use crate::vehicle::{SimulatorView, Vehicle};
use campaign::drive::DriveSettings;
use campaign::files::{
    Case, CaseError, CasesFrom, CommandRecord, ReplayOf, RoutePointRecord, Settings, TestTiming,
};
use campaign::model::{Campaign, Command, ModelError, ProbeRates, TestPlan, TestPlanner};
use campaign::oracle::{FailurePolicy, Verdict};
use campaign::safety::{Abort, AbortReason, SafetyConfig};
use campaign::shard::Shard;
use campaign::streaming::StreamingConfig;
use recording::{
    DEFAULT_CHUNK_INTERVAL, FaultRecord, OracleRecord, PlannedSegment, Recorder, RecordingError,
    RecordingStart, SafetyRecord, TestEvent, TestEventKind,
};

pub use dry_run::{DryRun, dry_run};
pub use events::{CampaignObserver, Silent};
pub use fresh::SPAN_GAP_NS;
pub use fresh::{SameTest, run_campaign_fresh, start_of_test};
pub use lab::{LabCar, run_campaign_on_cars};
pub use pause::{PAUSE_ENV, note_signal, pause_at};
pub use run_dir::{
    CAMPAIGN_FILE, CampaignReport, DEFAULT_RUNS_DIR, RECORDING_FILE, RUNS_DIR_ENV, TestSummary,
    runs_root,
};
pub use run_dir::{
    RunDirectory, Staged, claim_default_run_dir, claim_out_dir, claim_run_dir_again, is_cut_off,
    is_used, rfc3339_now, run_dir_name,
};
pub use session_end::{NotDisarmed, disarm, end_session};

use journal::Journal;
use preflight::Preflight;
use telemetry::Telemetry;

use campaign::drive::{BRAKE_TIMEOUT, SAFE_STOP_SPEED_MPS, STOPPED_SPEED_MPS};

/// Brake current of the safe stop, amperes (the reference's 50 A).
const BRAKE_CURRENT_A: f64 = 50.0;

/// How a campaign runs.
#[derive(Debug, Clone)]
pub struct RunConfig {
    /// Seed, number of tests, faults or not.
    pub campaign: Campaign,
    /// What happens after a failing segment.
    pub policy: FailurePolicy,
    /// The safety monitor's limits as configured. Preflight may raise the stale-telemetry limit
    /// to what the measured link needs; the limits in force are recorded in `campaign.json`.
    pub safety: SafetyConfig,
    /// The streaming rule's constants.
    pub streaming: StreamingConfig,
    /// Period of the state samples (50 ms: 20 Hz).
    pub state_period: Duration,
    /// The run directory to write.
    pub out_dir: PathBuf,
    /// The car as the user named it (`sim`, `tcp://…`), for `campaign.json`.
    pub car_label: String,
    /// The profile of the embedded simulated car, for `campaign.json` and every case (`None` on
    /// a real car).
    pub car_profile: Option<recording::LoadedProfile>,
    /// On the car's own firmware built for the host: its tree's hash, for `campaign.json`.
    pub car_firmware_tree_hash: Option<String>,
    /// What each test drives: a plan generated from the seed, an earlier run's case of the same
    /// index, or one recorded case every time.
    pub tests: Tests,
    /// What `campaign.mcap` keeps (every test by default; a shrink's candidate runs write none).
    pub record: RecordMode,
    /// Run only this shard of the campaign's tests (`run --shard K/N`).
    pub shard: Option<Shard>,
    /// Serve every recorded message live as well (`run --live`).
    pub live: Option<recording::live::LiveView>,
    /// An interrupted campaign continued in its run directory (`run --resume`).
    pub resume: Option<ResumeSource>,
    /// How a campaign on fresh simulated cars explains a failing test as it ends, in the worker
    /// that ran it, from the messages it recorded (`run`; `None`: the case files are written
    /// without explanations, and `run` explains from the recording at the end).
    pub explain: Option<ExplainHeld>,
}

/// Explains test `test_index`'s failing segments (`case`) from the messages a worker recorded of
/// it, as its case file keeps them; `None` when they hold no samples of it. `run` gives the
/// report's (`report::explain::explain_held`): the runner does not depend on the report.
pub type ExplainHeld = fn(
    &[recording::Held],
    usize,
    &Case,
    &Scenario,
) -> Option<Vec<campaign::files::SegmentExplanationRecord>>;

/// An interrupted campaign continued (`run --resume`): its run directory is `out_dir`; the tests
/// whose case files stay are not driven again.
#[derive(Debug, Clone, PartialEq)]
pub struct ResumeSource {
    /// Its `campaign.json` as the sessions before left it.
    pub record: campaign::files::CampaignRecord,
    /// The tests that ended: their case files stay, and they are not driven.
    pub kept: std::collections::BTreeSet<usize>,
    /// Every test a case file was written for before (`kept` and those cut off).
    pub earlier: Vec<usize>,
    /// The recording of the sessions before, moved aside: copied into the new `campaign.mcap`
    /// (the kept tests' spans, or everything of a recording without spans), up to any damage
    /// a killed process left, then removed.
    pub prior_recording: Option<PathBuf>,
}

/// What the tests of a campaign drive: one of three sources, so that no campaign can be given two.
#[derive(Debug, Clone, Default)]
pub enum Tests {
    /// Plans generated from the campaign's seed (`run`).
    #[default]
    Generated,
    /// An earlier run's cases, test for test (`run --cases-from DIR`).
    Cases(CasesSource),
    /// One recorded case in every test (`replay`, and the commands that drive a case again).
    Replay(ReplaySource),
}

impl Tests {
    /// Where the replayed case came from, for `campaign.json`.
    pub fn replay_of(&self) -> Option<&ReplayOf> {
        match self {
            Tests::Replay(replay) => Some(&replay.of),
            _ => None,
        }
    }

    /// Where the earlier run's cases came from, for `campaign.json`.
    pub fn cases_from(&self) -> Option<&CasesFrom> {
        match self {
            Tests::Cases(cases) => Some(&cases.of),
            _ => None,
        }
    }
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
    /// Drive it as test `i` of its campaign: the one test of the campaign is test `i` (its
    /// reset's and safe stop's seeds, its case file `case-NNN.json`), with the campaign's seed
    /// as [`RunConfig::campaign`]'s. `None`: as test 0 of a campaign of its own.
    pub as_test: Option<usize>,
}

/// An earlier run's cases driven again, test for test (`run --cases-from DIR`): test *i* drives
/// the plan of case file *i* (read when the test begins), with its faults at their places.
#[derive(Debug, Clone, PartialEq)]
pub struct CasesSource {
    /// The case file of every test, by test index.
    pub files: Vec<PathBuf>,
    /// Where they came from, for `campaign.json`.
    pub of: CasesFrom,
}

impl CasesSource {
    /// The plan of the case file `path` as test `test_index` drives it: read, checked against
    /// the scenario and planned as a replay plans it (`Case::replay_plan`; a case a run wrote
    /// has its ahead margins, so the commands are the case's own).
    pub fn plan(
        path: &Path,
        scenario: &Scenario,
        generator: &Generator,
        campaign: &Campaign,
        test_index: usize,
    ) -> Result<TestPlan, RunError> {
        let text = std::fs::read_to_string(path).map_err(|source| RunError::Io {
            path: path.to_owned(),
            source,
        })?;
        let case_error = |source| RunError::CaseFile {
            path: path.to_owned(),
            source: Box::new(source),
        };
        let case = Case::from_json(&text).map_err(case_error)?;
        if case.test_index != Some(test_index) {
            return Err(case_error(CaseError::Invalid {
                path: "test_index".to_owned(),
                message: format!("{:?}, not test {test_index}", case.test_index),
            }));
        }
        case.replay_plan(
            scenario,
            generator,
            campaign.seed,
            campaign.no_faults,
            test_index,
        )
        .map_err(case_error)
    }
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
            car_profile: None,
            car_firmware_tree_hash: None,
            tests: Tests::Generated,
            record: RecordMode::All,
            shard: None,
            live: None,
            resume: None,
            explain: None,
        }
    }

    /// The indices of the tests this run drives: all of the campaign's, or its shard's; a case
    /// driven again as test `i` of its campaign ([`ReplaySource::as_test`]) is test `i` alone.
    pub fn test_indices(&self) -> Vec<usize> {
        if let Tests::Replay(ReplaySource {
            as_test: Some(test_index),
            ..
        }) = &self.tests
        {
            return vec![*test_index];
        }
        let tests = self.campaign.tests;
        let all: Vec<usize> = match self.shard {
            Some(shard) => shard.tests(tests).collect(),
            None => (0..tests).collect(),
        };
        match &self.resume {
            Some(resume) => all
                .into_iter()
                .filter(|t| !resume.kept.contains(t))
                .collect(),
            None => all,
        }
    }
}

/// What the recording (`campaign.mcap`) keeps (`run --record`). Case files are always written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RecordMode {
    /// Every test, and everything between tests.
    #[default]
    All,
    /// The tests that did not pass (failed or aborted), and what happens outside tests: a large
    /// campaign keeps what a user looks at.
    Failing,
    /// No recording at all (no `campaign.mcap`).
    None,
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
    /// The car stopped answering sensibly in a test (no state for too long, states without a
    /// position or that no car could reach; the abort said which): in a campaign on several cars
    /// the test is cut off and another car drives it, as after a lost link.
    #[error("test {test_index}: the car stopped answering sensibly ({reason})")]
    Unresponsive {
        /// The test that was running.
        test_index: usize,
        /// The abort that said so.
        reason: AbortReason,
    },
    /// The operator interrupted the campaign (after the safe stop).
    #[error("interrupted during test {test_index}")]
    Interrupted {
        /// The test that was running.
        test_index: usize,
    },
    /// Every car of a campaign on several cars left it before its tests were driven.
    #[error(
        "no car left to drive test {test_index} and those after it: {}",
        cars.iter().map(|(car, reason)| format!("car {car}: {reason}")).collect::<Vec<_>>().join("; ")
    )]
    NoCarLeft {
        /// The first test not driven.
        test_index: usize,
        /// Each car that left (its name) and why.
        cars: Vec<(String, String)>,
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
    /// The recovery route ends far from the start route and no route joins them.
    #[error("no route from the recovery route's end to start_route[0]: {0}")]
    StartJoin(#[source] recovery::RecoveryError),
    /// The reset drive did not end at the recovery route's end.
    #[error("test {test_index}: reset: {reason}")]
    Reset {
        /// The test.
        test_index: usize,
        /// What happened.
        reason: String,
    },
    /// A case to drive (`run --cases-from`) cannot be read or driven.
    #[error("{}: {source}", path.display())]
    CaseFile {
        /// The case file.
        path: PathBuf,
        /// What is wrong with it.
        source: Box<CaseError>,
    },
    /// A case file or the campaign record could not be written.
    #[error(transparent)]
    Case(#[from] CaseError),
    /// The recording (`campaign.mcap`) could not be written.
    #[error("recording: {0}")]
    Recording(#[source] RecordingError),
    /// The run directory exists and is not empty (nothing was written): the commands refuse it
    /// before running.
    #[error(
        "{}: exists and is not empty: a run directory is created fresh (give another --out, or remove it)",
        path.display()
    )]
    OutDirUsed {
        /// The directory.
        path: PathBuf,
    },
    /// Another drivecheck process is writing the run directory (it holds its claim file).
    #[error(
        "{}: another drivecheck process is writing it ({}): give another --out",
        path.display(),
        holder
    )]
    OutDirClaimed {
        /// The directory.
        path: PathBuf,
        /// What the claim file says of its holder.
        holder: String,
    },
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

/// A campaign that did not run to its end (see [`run_campaign`]).
#[derive(Debug, Error)]
#[error("{error}")]
pub struct CampaignFailure {
    /// Why it ended.
    pub error: RunError,
    /// What the run directory holds: `None` when it could not be created or completed.
    pub report: Option<CampaignReport>,
}

impl CampaignFailure {
    fn without_report(error: RunError) -> Self {
        Self {
            error,
            report: None,
        }
    }
}

/// Everything a test needs that stays the same over the campaign.
#[derive(Debug)]
pub(crate) struct Context<'a, V> {
    pub(crate) car: &'a V,
    pub(crate) scenario: &'a Scenario,
    pub(crate) config: &'a RunConfig,
    /// The safety limits in force: [`RunConfig::safety`] with the stale-telemetry limit preflight
    /// found the link needs (the one value every monitor of the campaign uses, and
    /// `campaign.json` records).
    pub(crate) safety: SafetyConfig,
    pub(crate) sample_timeout: Duration,
    pub(crate) generator: Generator,
    pub(crate) rates: ProbeRates,
    pub(crate) cancel: &'a CancellationToken,
    pub(crate) journal: &'a Journal<'a>,
    /// What the reset drives after the recovery route's end to reach `start_route[0]` when the
    /// scenario needs a planned join ([`reset::plan_start_join`]); empty otherwise.
    pub(crate) start_join: Vec<Point>,
}

impl<V> Context<'_, V> {
    /// What the test drive's state machine needs of the campaign.
    pub fn drive_settings(&self) -> DriveSettings<'_> {
        DriveSettings {
            area: &self.scenario.area,
            generator: self.generator,
            safety: self.safety,
            streaming: self.config.streaming,
            policy: self.config.policy,
            oracle_threshold_m: self.scenario.campaign.oracle_threshold_m,
            stop_points: self.scenario.campaign.points_per_segment.min,
            rates: self.rates,
            campaign_seed: self.config.campaign.seed,
            steering: Some(campaign::drive::Steering::of(&self.scenario.vehicle)),
        }
    }
}

/// Runs a campaign against `car` in `scenario` and writes its run directory, with its recording
/// `campaign.mcap`. Progress goes to `observer`; `sim` is the embedded simulator's debug view when
/// `car` is simulated (its truth and debug events are recorded too), `None` for a real car.
///
/// Returns the report, with every case written, when every test ran (whatever their verdicts);
/// a [`CampaignFailure`] when the campaign could not run to its end (preflight refused, link
/// lost, interrupted, a reset or a plan failed): the run directory is then still complete
/// (`campaign.json` with its end time and summary, a case file for every test started, the
/// recording completed as far as it could be written) and the failure carries its report. A
/// recording that cannot be written is an error ([`RunError::Recording`]): the campaign stops
/// after the running test.
///
/// Timeout: every car command is bounded by the link's timeouts; a reset drive by its route's
/// length at its speed plus 60 s; braking by [`campaign::drive::BRAKE_TIMEOUT`]. Cancellation:
/// The process's hard stop: cancelled by the operator's second signal after it braked the car at
/// once (`commands::shared::Interrupt`). The drive and the braking end at it, so that the test in
/// flight is recorded as aborted and the run directory and the recording are completed before
/// the process exits. Signals are the process's, and so is this token.
pub fn hard_stop() -> &'static CancellationToken {
    static HARD_STOP: std::sync::OnceLock<CancellationToken> = std::sync::OnceLock::new();
    HARD_STOP.get_or_init(CancellationToken::new)
}

/// `cancel` performs the safe stop of the running test, records it as `aborted (interrupted)`
/// and ends the campaign with [`RunError::Interrupted`]. Dropping the future instead stops at
/// once without a safe stop (the car's watchdog then brakes it within 2 s) and leaves
/// `campaign.json` without an end.
pub async fn run_campaign<V: Vehicle>(
    car: &V,
    scenario: &Scenario,
    config: &RunConfig,
    cancel: &CancellationToken,
    observer: &dyn CampaignObserver,
    sim: Option<&dyn SimulatorView>,
) -> Result<CampaignReport, CampaignFailure> {
    let origin = tokio::time::Instant::now();
    let settings = Settings::new(scenario, config.campaign.tests, config.policy);
    let mut dir = RunDirectory::create(config, scenario, settings)
        .map_err(CampaignFailure::without_report)?;
    let start = RecordingStart {
        campaign: dir.record(),
        scenario,
        origin,
        simulated: sim.is_some(),
        chunk_interval: DEFAULT_CHUNK_INTERVAL,
        live: config.live.as_ref(),
        test_spans: false,
        sim_profile: config.car_profile.as_ref().filter(|_| sim.is_some()),
    };
    let started = match (config.record, config.live.as_ref()) {
        // Nothing kept, but a live view still gets the area and every message.
        (RecordMode::None, Some(live)) => {
            Recorder::live_only(origin, sim.is_some(), 1, live, Some(scenario)).map(Some)
        }
        (RecordMode::None, None) => Ok(None),
        (RecordMode::All | RecordMode::Failing, _) => {
            Recorder::create(&dir.path().join(RECORDING_FILE), &start).map(Some)
        }
    };
    let journal = match started {
        Ok(Some(mut recorder)) => {
            // A resumed campaign's messages follow those of the sessions before.
            if let Some(resume) = &config.resume
                && config.record != RecordMode::None
            {
                match continue_recording(&mut recorder, resume, observer) {
                    Ok(after_ns) => recorder.continue_after(after_ns),
                    Err(error) => return Err(recording_not_started(dir, error)),
                }
            }
            Journal::new(recorder, sim)
        }
        Ok(None) => Journal::without_recording(sim),
        Err(error) => return Err(recording_not_started(dir, error)),
    };
    let inputs = Inputs {
        car,
        scenario,
        config,
        cancel,
        observer,
        journal: &journal,
    };
    let result = run_tests(&inputs, &mut dir).await;
    // After the second signal the command line disarms the car it brakes, in the moment the
    // process still lives: the run directory comes first here.
    if !hard_stop().is_cancelled() {
        end_session(car, None, observer).await;
    }
    finish_campaign(dir, journal, result)
}

/// Copies the recording of the sessions before into `recorder` (`run --resume`, see
/// [`ResumeSource::prior_recording`]) and removes it; returns the log time after which the new
/// session's messages go (0 without one). The copy is read a span at a time: the kept tests'
/// spans of a recording with test spans (the embedded simulator's: a span of a test cut off is
/// left out, it is driven again), or every message of one without (a car for the whole
/// campaign). Damage (the unfinished end a `kill -9` leaves) ends the copy: what was whole
/// before it is kept, and a note says so.
pub fn continue_recording(
    recorder: &mut Recorder,
    resume: &ResumeSource,
    observer: &dyn CampaignObserver,
) -> Result<u64, RecordingError> {
    let Some(prior) = &resume.prior_recording else {
        return Ok(0);
    };
    let mut spans = recording::Spans::open(prior)?;
    let mut end_ns = 0;
    let mut copied = 0;
    while let Some(span) = spans.next() {
        let span = match span {
            Ok(span) => span,
            Err(error) => {
                observer.note(&format!(
                    "the recording of the session before ends early ({error}): kept its {copied} \
                     whole span(s)"
                ));
                break;
            }
        };
        let spanned = spans_claim_tests(&spans);
        match span.test_index {
            Some(test) if !resume.kept.contains(&test) => continue,
            // A test driven again (above), or what follows the last test of a spanned recording
            // (a test whose span was never closed).
            None if spanned => continue,
            _ => {
                end_ns = end_ns.max(span.end_ns);
                recorder.copy_span(span, 0)?;
            }
        }
        copied += 1;
    }
    if let Err(error) = std::fs::remove_file(prior) {
        observer.note(&format!(
            "cannot remove {} after copying it: {error}",
            prior.display()
        ));
    }
    Ok(if end_ns == 0 { 0 } else { end_ns + SPAN_GAP_NS })
}

/// The journal of a campaign whose tests are recorded in memory and written whole, one after
/// another, each with its span (fresh simulated cars, `fresh`; several cars, `lab`): the
/// recording as `config.record` asks (nothing but a live view's area with `--record none
/// --live`), a resumed campaign's earlier sessions copied first. Returns it with the log time
/// where the first test's messages go.
pub fn spanned_journal<'a>(
    config: &RunConfig,
    scenario: &Scenario,
    dir: &RunDirectory,
    origin: tokio::time::Instant,
    simulated: bool,
    observer: &dyn CampaignObserver,
) -> Result<(Journal<'a>, u64), RecordingError> {
    let recorder = match (config.record, config.live.as_ref()) {
        // Nothing kept, but a live view still gets the area (and each test its messages).
        (RecordMode::None, Some(live)) => Some(Recorder::live_only(
            origin,
            simulated,
            1,
            live,
            Some(scenario),
        )?),
        (RecordMode::None, None) => None,
        (RecordMode::All | RecordMode::Failing, _) => {
            let start = RecordingStart {
                campaign: dir.record(),
                scenario,
                origin,
                simulated,
                chunk_interval: DEFAULT_CHUNK_INTERVAL,
                // The area goes out to the live view from here; the tests' messages from their
                // own recorders.
                live: config.live.as_ref(),
                test_spans: true,
                sim_profile: config.car_profile.as_ref().filter(|_| simulated),
            };
            Some(Recorder::create(&dir.path().join(RECORDING_FILE), &start)?)
        }
    };
    let mut first_offset_ns = SPAN_GAP_NS;
    Ok(match recorder {
        Some(mut recorder) => {
            // A resumed campaign's tests follow those of the sessions before.
            if let Some(resume) = &config.resume
                && config.record != RecordMode::None
            {
                first_offset_ns =
                    first_offset_ns.max(continue_recording(&mut recorder, resume, observer)?);
            }
            (Journal::new(recorder, None), first_offset_ns)
        }
        None => (Journal::without_recording(None), first_offset_ns),
    })
}

/// Does the recording `spans` reads give a span per test (the embedded simulator's)?
fn spans_claim_tests<R: std::io::Read>(spans: &recording::Spans<R>) -> bool {
    spans
        .metadata("drivecheck.recording")
        .and_then(|m| m.get("test_spans"))
        .is_some_and(|v| v == "true")
}

/// The failure of a campaign whose recording could not be started: the run directory is
/// completed (no test ran) and the failure carries its report.
fn recording_not_started(dir: RunDirectory, error: RecordingError) -> CampaignFailure {
    match dir.finish() {
        Ok(report) => CampaignFailure {
            error: RunError::Recording(error),
            report: Some(report),
        },
        Err(finishing) => CampaignFailure::without_report(finishing),
    }
}

/// Completes the run directory and the recording after the tests ran with `result`: the report,
/// or the failure with the report.
#[allow(
    clippy::result_large_err,
    reason = "the failure of run_campaign, returned once per campaign"
)]
fn finish_campaign(
    dir: RunDirectory,
    journal: Journal<'_>,
    result: Result<(), RunError>,
) -> Result<CampaignReport, CampaignFailure> {
    let report = dir.finish().map_err(CampaignFailure::without_report)?;
    let recorded = journal.finish(&report.record);
    match result.and(recorded) {
        Ok(()) => Ok(report),
        Err(error) => Err(CampaignFailure {
            error,
            report: Some(report),
        }),
    }
}

/// What [`run_campaign`] was given, with the journal it opened: what [`run_tests`] works with.
struct Inputs<'a, V> {
    car: &'a V,
    scenario: &'a Scenario,
    config: &'a RunConfig,
    cancel: &'a CancellationToken,
    observer: &'a dyn CampaignObserver,
    journal: &'a Journal<'a>,
}

async fn run_tests<V: Vehicle>(
    inputs: &Inputs<'_, V>,
    dir: &mut RunDirectory,
) -> Result<(), RunError> {
    let Inputs {
        car,
        scenario,
        config,
        cancel,
        observer,
        journal,
    } = *inputs;
    let start_join = reset::plan_start_join(scenario, config.campaign.seed)?;
    let (ctx, mut telemetry, preflight) =
        open_session(car, scenario, config, cancel, journal, start_join).await?;
    if !preflight.switched_off.is_empty() {
        observer.note(&switched_off_note(&preflight.switched_off));
    }
    if !ctx.start_join.is_empty() {
        observer.note(&start_join_note(&ctx.start_join));
    }
    dir.set_firmware(car.version().to_string());
    dir.set_runtime(ctx.safety, config.streaming);
    let tests = TestSource::new(scenario, config)?;
    let indices = config.test_indices();
    observer.tests_planned(indices.len());
    for test_index in indices {
        if cancel.is_cancelled() {
            return Err(RunError::Interrupted { test_index });
        }
        observer.test_started(test_index);
        if config.record == RecordMode::Failing {
            journal.hold();
        }
        let (case, end) =
            plan_and_run(&ctx, &mut telemetry, &tests, test_index, dir.settings()).await?;
        // The test's messages first, written through to the file, then its case file: a test
        // with a case file is in the recording, whenever the process is killed (#51 item 2).
        record_test_end(journal, test_index, &case);
        if config.record == RecordMode::Failing {
            journal.release(case.verdict != Some(Verdict::Passed));
            journal.flush();
        }
        journal.check()?;
        dir.write_case(&case)?;
        observer.test_finished(test_index, case.verdict);
        if let TestEnd::Stop(error) = end {
            return Err(error);
        }
    }
    Ok(())
}

/// The note for the configuration fields preflight switched off.
fn switched_off_note(switched_off: &[String]) -> String {
    format!("preflight: switched off {}", switched_off.join(", "))
}

/// The note for a recovery route that needs a planned join to the start route.
fn start_join_note(start_join: &[Point]) -> String {
    format!(
        "the recovery route ends far from start_route[0]: every reset drives a planned join of {} points",
        start_join.len()
    )
}

/// A car ready for tests: preflight passed (which measured the link and prepared the car), the
/// state samples flowing. Returns the test's context, the telemetry and what preflight found.
async fn open_session<'a, V: Vehicle>(
    car: &'a V,
    scenario: &'a Scenario,
    config: &'a RunConfig,
    cancel: &'a CancellationToken,
    journal: &'a Journal<'a>,
    start_join: Vec<Point>,
) -> Result<(Context<'a, V>, Telemetry, Preflight), RunError> {
    let preflight = Preflight::run(car, scenario, config, journal).await?;
    let safety = SafetyConfig {
        stale_after: preflight.stale_after,
        ..config.safety
    };
    let ctx = Context {
        car,
        scenario,
        config,
        safety,
        sample_timeout: preflight.sample_timeout,
        generator: Generator::new(scenario.generator.generator_config(Strategy::Wedge))
            .map_err(RunError::Generator)?,
        rates: preflight.rates,
        cancel,
        journal,
        start_join,
    };
    let mut telemetry = Telemetry::start(car, config.state_period, ctx.sample_timeout);
    // The first sample comes a round trip after polling starts: wait for it (or for the link's
    // end), so that no safety monitor is armed before samples flow.
    let _ = tokio::time::timeout(
        ctx.safety.stale_after + ctx.sample_timeout,
        telemetry.next(journal),
    )
    .await;
    Ok((ctx, telemetry, preflight))
}

/// What every campaign of `scenario` computes before it drives (its planner, the start route's
/// tail) and the plan of its first test with `seed`, as `run` plans it: `scenario check` calls
/// it, so that it refuses a scenario whose first test `run` could not plan (a generator that
/// cannot draw in the area with its settings).
pub fn plan_first_test(scenario: &Scenario, seed: u64) -> Result<TestPlan, RunError> {
    let config = RunConfig::new(
        Campaign {
            seed,
            tests: 1,
            no_faults: false,
        },
        PathBuf::new(),
        "scenario check",
    );
    TestSource::new(scenario, &config)?.plan(0)
}

/// Where a campaign's test plans come from: generated from the seed, or a replayed case.
pub struct TestSource<'a> {
    planner: TestPlanner,
    start_tail: RouteTail,
    scenario: &'a Scenario,
    config: &'a RunConfig,
}

impl<'a> TestSource<'a> {
    fn new(scenario: &'a Scenario, config: &'a RunConfig) -> Result<Self, RunError> {
        Ok(Self {
            planner: TestPlanner::new(scenario)?,
            start_tail: campaign::model::start_tail(scenario)?,
            scenario,
            config,
        })
    }

    /// The plan of test `test_index`.
    fn plan(&self, test_index: usize) -> Result<TestPlan, RunError> {
        match &self.config.tests {
            Tests::Cases(cases) => {
                let path = cases.files.get(test_index).ok_or(RunError::CaseFile {
                    path: PathBuf::from(&cases.of.run),
                    source: Box::new(CaseError::Invalid {
                        path: "tests".to_owned(),
                        message: format!("no case for test {test_index}"),
                    }),
                })?;
                CasesSource::plan(
                    path,
                    self.scenario,
                    self.planner.generator(),
                    &self.config.campaign,
                    test_index,
                )
            }
            Tests::Replay(replay) => Ok(TestPlan {
                test_index,
                ..replay.plan.clone()
            }),
            Tests::Generated => {
                Ok(self
                    .planner
                    .plan_test(&self.config.campaign, test_index, self.start_tail)?)
            }
        }
    }
}

/// Plans test `test_index` and runs it (reset and drive); its case and how it ended.
async fn plan_and_run<V: Vehicle>(
    ctx: &Context<'_, V>,
    telemetry: &mut Telemetry,
    tests: &TestSource<'_>,
    test_index: usize,
    settings: &Settings,
) -> Result<(Case, TestEnd), RunError> {
    let started = tokio::time::Instant::now();
    let plan = tests.plan(test_index)?;
    let per_segment = started.elapsed() / plan.segments().count().max(1) as u32;
    tracing::debug!(
        test = test_index,
        commands = plan.commands.len(),
        segments = plan.segments().count(),
        faults = plan.faults().count(),
        "test planned"
    );
    let config = ctx.config;
    let mut case = Case::planned(
        &plan,
        ctx.scenario,
        config.campaign.seed,
        config.campaign.no_faults,
        settings.clone(),
    );
    let end = run_test(ctx, telemetry, &plan, &mut case, per_segment).await;
    Ok((case, end))
}

/// Records a test's oracle results and its end, and writes the recording's open chunk.
fn record_test_end(journal: &Journal<'_>, test_index: usize, case: &Case) {
    for placement in &case.fault_places {
        let command = case.commands.get(placement.command_index);
        if let Some(Command::AddFault(fault)) = command.map(CommandRecord::to_command) {
            journal.write(&FaultRecord::placed(
                test_index,
                &fault,
                (*placement).into(),
            ));
        }
    }
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
async fn run_test<V: Vehicle>(
    ctx: &Context<'_, V>,
    telemetry: &mut Telemetry,
    plan: &TestPlan,
    case: &mut Case,
    generation: Duration,
) -> TestEnd {
    let test_index = plan.test_index;
    let started = tokio::time::Instant::now();
    let seconds = |d: Duration| d.as_millis() as f64 / 1000.0;
    let reset = match reset::reset(ctx, telemetry, test_index).await {
        Ok(reset) => reset,
        Err(stopped) => {
            case.timing = Some(TestTiming {
                reset_s: seconds(started.elapsed()),
                drive_s: 0.0,
            });
            return record_stop_before_drive(ctx.journal, case, stopped, test_index);
        }
    };
    let reset_s = seconds(started.elapsed());
    tracing::debug!(
        test = test_index,
        return_points = reset.return_route.len(),
        clearance_m = reset.clearance_m,
        "car reset"
    );
    let driving = tokio::time::Instant::now();
    record_test_start(ctx.journal, plan);
    case.return_route = reset
        .return_route
        .iter()
        .copied()
        .map(RoutePointRecord::from)
        .collect();
    case.return_clearance_m =
        (reset.clearance_m < ctx.scenario.generator.clearance_m).then_some(reset.clearance_m);
    let (outcome, error) = drive::drive(ctx, telemetry, plan, reset.standing, generation).await;
    outcome.write_into(case, error.as_ref().map(ToString::to_string).as_deref());
    case.timing = Some(TestTiming {
        reset_s,
        drive_s: seconds(driving.elapsed()),
    });
    tracing::debug!(
        test = test_index,
        verdict = case.verdict.map(Verdict::as_str),
        reason = case.reason.as_deref(),
        error = error.as_ref().map(tracing::field::display),
        "test driven"
    );
    match error {
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
/// command or its reply now and then; only idempotent commands are retried). At 30 % loss each
/// way a round trip fails about half the time: 8 tries fail together 0.4 % of the time.
const IDEMPOTENT_TRIES: u32 = 8;

/// Runs an idempotent car command up to [`IDEMPOTENT_TRIES`] times; a lost link is not retried.
///
/// Timeout: each try as the command's own. Cancellation: safe for an idempotent command.
pub async fn retried<T, F, Fut>(mut command: F) -> Result<T, CarError>
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
pub enum Stopped {
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
            case.reason = Some(if hard_stop().is_cancelled() {
                format!(
                    "reset: {}: {}",
                    abort.reason,
                    campaign::drive::BRAKED_AT_ONCE
                )
            } else {
                format!("reset: {}", abort.reason)
            });
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
