//! What the commands that drive a car (`run`, `replay`) share, and what `runs` shows the same
//! way: the async runtime, the embedded simulator's debug view the runner records, Ctrl-C, the
//! progress bar, a failed campaign as an error, and the table of a campaign's tests. The
//! connection itself is made in [`crate::vehicle`]; the commands see only the
//! [`Vehicle`](crate::vehicle::Vehicle) it returns.

use std::future::Future;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, Result};
use car_sim::{DebugEvent, SimHandle, Truth};
use indicatif::{ProgressBar, ProgressStyle};
use scenarios::Scenario;
use tokio_util::sync::CancellationToken;

use crate::runner::{CampaignObserver, CampaignReport, RunError, SimulatorView};
use crate::scenario_arg::{load_scenario, print_warnings_of_use};
use crate::vehicle::Vehicle;
use anyhow::bail;
use campaign::files::Case;
use campaign::oracle::Verdict;
use car_link::CarError;

/// The async runtime: on one thread with a paused clock (virtual time, the embedded simulated
/// car) or on two threads against the wall clock.
pub(super) fn runtime(virtual_time: bool) -> Result<tokio::runtime::Runtime> {
    let runtime = if virtual_time {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .start_paused(true)
            .build()
    } else {
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
    };
    runtime.context("cannot start the async runtime")
}

/// The embedded simulator's debug view, as the runner records it.
impl SimulatorView for SimHandle {
    fn truth(&self) -> Truth {
        SimHandle::truth(self)
    }

    fn take_events(&self) -> Vec<DebugEvent> {
        SimHandle::take_events(self)
    }
}

/// The debug view of `sim`, if the car is the embedded simulator.
pub(super) fn sim_view(sim: &Option<SimHandle>) -> Option<&dyn SimulatorView> {
    sim.as_ref().map(|sim| sim as &dyn SimulatorView)
}

/// A token cancelled at the first SIGINT (Ctrl-C), SIGTERM (`timeout`, systemd, a cancelled CI
/// job) or SIGHUP (a closed terminal): the runner then stops the car safely, records the running
/// test as aborted (`interrupted`), completes the run directory and the recording, and the command
/// exits with status 2. A second signal brakes the car registered with
/// [`Interrupt::brake_on_second`] at once, ends the test in flight there (aborted, the hard brake
/// named in its case) and the process with status 2 within half a second. Call it inside the
/// runtime.
pub(super) fn cancel_on_ctrl_c() -> CancellationToken {
    Interrupt::listen().cancel
}

/// The interrupt path of a command that drives (see [`cancel_on_ctrl_c`]): the token the first
/// signal cancels, and the car the second signal brakes.
#[derive(Clone)]
pub(super) struct Interrupt {
    cancel: CancellationToken,
    car: Slot,
    /// How many cars the second signal brakes (several: the first signal's message says so).
    cars: Arc<std::sync::atomic::AtomicUsize>,
}

/// The registered car's brake: a clone of the car, braking with the current given.
type Brake = Box<dyn Fn(f64) -> Pin<Box<dyn Future<Output = Result<(), CarError>> + Send>> + Send>;

/// Where the car the second signal brakes is registered.
type Slot = Arc<Mutex<Option<Brake>>>;

impl std::fmt::Debug for Interrupt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Interrupt")
            .field("cancel", &self.cancel)
            .field("registered", &lock(&self.car).is_some())
            .finish()
    }
}

/// The brake the second signal sends, as the runner's safe stop does.
const SECOND_SIGNAL_BRAKE_A: f64 = 50.0;

/// How long the process lives after the second signal's brake was queued, so that the link's
/// writer sends it (a brake has no reply; RC_CONTROL is fire and forget).
const BRAKE_FLUSH: Duration = Duration::from_millis(100);

/// How long the process lives after the second signal's brake for the runner to write the test
/// in flight and complete the run directory.
const HARD_STOP_GRACE: Duration = Duration::from_millis(500);

/// At most this long for the brake to find room in the link's send queue; the car's 2 s watchdog
/// brakes it in any case once the process is gone.
const BRAKE_SEND_LIMIT: Duration = Duration::from_millis(500);

impl Interrupt {
    /// Listens for SIGINT, SIGTERM and SIGHUP from now on. Call it inside the runtime.
    pub(super) fn listen() -> Self {
        let interrupt = Self {
            cancel: CancellationToken::new(),
            car: Arc::new(Mutex::new(None)),
            cars: Arc::default(),
        };
        let listener = interrupt.clone();
        tokio::spawn(async move {
            let mut signals = Signals::new();
            let first = signals.next().await;
            let cars = match listener.cars.load(std::sync::atomic::Ordering::SeqCst) {
                0 | 1 => "the car",
                _ => "every car",
            };
            eprintln!("{first}: stopping {cars} safely (send it again to brake at once and exit)");
            listener.cancel.cancel();
            let second = signals.next().await;
            eprintln!("{second} again: braking at once and exiting");
            listener.brake_now().await;
            // The test in flight ends at once, aborted; its case, campaign.json and the recording
            // are written in the half second the process still lives (a command that completes
            // sooner exits sooner).
            crate::runner::hard_stop().cancel();
            tokio::time::sleep(HARD_STOP_GRACE).await;
            crate::exit::Exit::Error.exit();
        });
        interrupt
    }

    /// The token the first signal cancels.
    pub(super) fn token(&self) -> &CancellationToken {
        &self.cancel
    }

    /// Registers `car` as the one the second signal brakes, until the returned guard is dropped
    /// (a registered car keeps its link, and so its keepalive, alive).
    pub(super) fn brake_on_second<V: Vehicle>(&self, car: &V) -> BrakeOnSecond {
        self.brake_all_on_second(std::slice::from_ref(car))
    }

    /// [`Interrupt::brake_on_second`] for every car of a campaign on several cars, braked at
    /// once.
    pub(super) fn brake_all_on_second<V: Vehicle>(&self, cars: &[V]) -> BrakeOnSecond {
        self.cars
            .store(cars.len(), std::sync::atomic::Ordering::SeqCst);
        let cars = cars.to_vec();
        let brake: Brake = Box::new(move |current_a| {
            let cars = cars.clone();
            Box::pin(async move {
                let braked =
                    futures::future::join_all(cars.iter().map(|car| car.brake(current_a))).await;
                braked
                    .into_iter()
                    .collect::<Result<Vec<()>, CarError>>()
                    .map(drop)
            })
        });
        *lock(&self.car) = Some(brake);
        BrakeOnSecond {
            car: Arc::clone(&self.car),
        }
    }

    /// Brakes the registered car, if any, and gives the link a moment to send the command.
    async fn brake_now(&self) {
        let Some(braking) = lock(&self.car)
            .as_ref()
            .map(|brake| brake(SECOND_SIGNAL_BRAKE_A))
        else {
            return;
        };
        match tokio::time::timeout(BRAKE_SEND_LIMIT, braking).await {
            Ok(Ok(())) => tokio::time::sleep(BRAKE_FLUSH).await,
            Ok(Err(error)) => eprintln!("cannot brake: {error}"),
            Err(_) => eprintln!("cannot brake: the link's send queue stayed full"),
        }
    }
}

/// While it lives, the second signal brakes the car registered with
/// [`Interrupt::brake_on_second`].
pub(super) struct BrakeOnSecond {
    car: Slot,
}

impl std::fmt::Debug for BrakeOnSecond {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BrakeOnSecond").finish_non_exhaustive()
    }
}

impl Drop for BrakeOnSecond {
    fn drop(&mut self) {
        *lock(&self.car) = None;
    }
}

/// The slot's car, whether or not a thread panicked while holding it.
fn lock(slot: &Mutex<Option<Brake>>) -> std::sync::MutexGuard<'_, Option<Brake>> {
    slot.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The signals that stop a command: SIGINT, and on Unix SIGTERM and SIGHUP.
struct Signals {
    #[cfg(unix)]
    term: Option<tokio::signal::unix::Signal>,
    #[cfg(unix)]
    hup: Option<tokio::signal::unix::Signal>,
}

impl Signals {
    fn new() -> Self {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            Self {
                term: signal(SignalKind::terminate()).ok(),
                hup: signal(SignalKind::hangup()).ok(),
            }
        }
        #[cfg(not(unix))]
        {
            Self {}
        }
    }

    /// Waits for the next signal; its name.
    async fn next(&mut self) -> &'static str {
        #[cfg(unix)]
        {
            async fn on(signal: &mut Option<tokio::signal::unix::Signal>) {
                match signal {
                    Some(signal) => {
                        signal.recv().await;
                    }
                    None => std::future::pending().await,
                }
            }
            tokio::select! {
                () = ctrl_c() => "interrupted (SIGINT)",
                () = on(&mut self.term) => "terminated (SIGTERM)",
                () = on(&mut self.hup) => "hung up (SIGHUP)",
            }
        }
        #[cfg(not(unix))]
        {
            ctrl_c().await;
            "interrupted"
        }
    }
}

/// Ctrl-C; never, if its handler cannot be installed.
async fn ctrl_c() {
    if tokio::signal::ctrl_c().await.is_err() {
        std::future::pending::<()>().await;
    }
}

/// A campaign's progress where it is read (`docs/scaling.md`):
/// - on a terminal, a bar of the tests run and the test running, with a line above it for each
///   test (above [`EVERY_TEST_UP_TO`] tests only for those that did not pass, unless `-v`);
/// - elsewhere (a CI log, a pipe, `nohup`), plain lines: one per test up to [`EVERY_TEST_UP_TO`]
///   tests, and above that a line for every test that did not pass as it ends and a status line
///   every [`STATUS_EVERY`] or 1 % of the tests (done, failed, rate, time left);
/// - with `-q`, nothing (errors and the summary still are).
///
/// Notes (what preflight switched off) are printed unless `-q`.
#[derive(Debug)]
pub(super) struct Progress {
    bar: ProgressBar,
    /// Plain lines instead of the bar (standard error is not a terminal).
    lines: bool,
    /// Lines for every test (not only those that did not pass).
    every_test: bool,
    /// Nothing but notes… and with `-q` not those either.
    quiet: bool,
    state: Mutex<Tally>,
}

/// What the plain lines count.
#[derive(Debug)]
struct Tally {
    tests: usize,
    done: usize,
    not_passed: usize,
    started: std::time::Instant,
    last_status: std::time::Instant,
    last_percent: usize,
    /// On several cars: the test each car drives (by car, in the order they started).
    driving: Vec<(String, Option<usize>)>,
}

impl Tally {
    /// The car that drives `test_index`, on several cars.
    fn car_of(&self, test_index: usize) -> Option<&str> {
        self.driving
            .iter()
            .find(|(_, t)| *t == Some(test_index))
            .map(|(car, _)| car.as_str())
    }

    /// `car1: test 3, car2: test 4` (a car between tests says `reset`).
    fn cars(&self) -> String {
        self.driving
            .iter()
            .map(|(car, test)| match test {
                Some(test) => format!("{car}: test {test}"),
                None => format!("{car}: -"),
            })
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Up to this many tests, every test gets a line.
pub(super) const EVERY_TEST_UP_TO: usize = 100;

/// Failing cases (and explanations) a summary lists at most, unless `-v`.
const LISTED_AT_MOST: usize = 20;

/// Whether a campaign of `tests` tests gets a line (and a table row) for every test.
fn every_test(tests: usize) -> bool {
    tests <= EVERY_TEST_UP_TO || crate::output::verbosity() == crate::output::Verbosity::Verbose
}

/// How many failing cases (and explanations) a summary lists: [`LISTED_AT_MOST`], all with `-v`.
pub(super) fn listed_at_most() -> usize {
    if crate::output::verbosity() == crate::output::Verbosity::Verbose {
        usize::MAX
    } else {
        LISTED_AT_MOST
    }
}

/// Above [`EVERY_TEST_UP_TO`] tests, a status line at least this often (when a test ends).
const STATUS_EVERY: Duration = Duration::from_secs(10);

impl Progress {
    /// Progress of `tests` tests, as the process's verbosity and standard error say.
    pub(super) fn new(tests: usize) -> Self {
        use crate::output::{Verbosity, verbosity};
        let quiet = verbosity() == Verbosity::Quiet;
        let lines = !std::io::stderr().is_terminal();
        let bar = if quiet || lines {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(tests as u64)
        };
        if let Ok(style) =
            ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} tests  {msg}")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        let now = std::time::Instant::now();
        Self {
            bar,
            lines,
            every_test: every_test(tests),
            quiet,
            state: Mutex::new(Tally {
                tests,
                done: 0,
                not_passed: 0,
                started: now,
                last_status: now,
                last_percent: 0,
                driving: Vec::new(),
            }),
        }
    }

    /// Removes the bar.
    pub(super) fn finish(&self) {
        self.bar.finish_and_clear();
    }

    /// A line above the bar, or on standard error.
    fn line(&self, text: &str) {
        if self.bar.is_hidden() {
            eprintln!("{text}");
        } else {
            self.bar.println(text);
        }
    }
}

impl Tally {
    /// `412/10000 tests (4 %), 180 did not pass, 52.1 tests/s, about 3m 4s left`.
    fn status(&self) -> String {
        let elapsed = self.started.elapsed().as_secs_f64();
        let rate = self.done as f64 / elapsed.max(1e-9);
        let left = (self.tests.saturating_sub(self.done)) as f64 / rate.max(1e-9);
        format!(
            "{}/{} tests ({} %), {} did not pass, {:.1} tests/s, about {} left",
            self.done,
            self.tests,
            100 * self.done / self.tests.max(1),
            self.not_passed,
            rate,
            humantime::format_duration(Duration::from_secs(left.round().min(1e9) as u64))
        )
    }
}

impl CampaignObserver for Progress {
    fn note(&self, text: &str) {
        if !self.quiet {
            self.line(text);
        }
    }

    fn detail(&self, text: &str) {
        if crate::output::verbosity() == crate::output::Verbosity::Verbose {
            self.line(text);
        }
    }

    fn tests_planned(&self, tests: usize) {
        self.bar.set_length(tests as u64);
        if let Ok(mut tally) = self.state.lock() {
            tally.tests = tests;
        }
    }

    fn test_started(&self, test_index: usize) {
        self.bar.set_message(format!("test {test_index}: running"));
    }

    fn test_started_on(&self, test_index: usize, car: &str) {
        let Ok(mut tally) = self.state.lock() else {
            return;
        };
        match tally.driving.iter_mut().find(|(c, _)| c == car) {
            Some(driving) => driving.1 = Some(test_index),
            None => tally.driving.push((car.to_owned(), Some(test_index))),
        }
        self.bar.set_message(tally.cars());
        if self.lines && self.every_test && !self.quiet {
            self.line(&format!("test {test_index}: started on car {car}"));
        }
    }

    fn car_left(&self, car: &str, reason: &str) {
        if let Ok(mut tally) = self.state.lock() {
            tally.driving.retain(|(c, _)| c != car);
            self.bar.set_message(tally.cars());
        }
        if !self.quiet {
            self.line(&format!(
                "car {car} left the campaign: {reason}; the other cars go on"
            ));
        }
    }

    fn test_finished(&self, test_index: usize, verdict: Option<Verdict>) {
        self.bar.inc(1);
        if self.quiet {
            return;
        }
        let passed = verdict == Some(Verdict::Passed);
        let Ok(mut tally) = self.state.lock() else {
            return;
        };
        tally.done += 1;
        tally.not_passed += usize::from(!passed);
        let on = tally
            .car_of(test_index)
            .map(|car| format!(" on car {car}"))
            .unwrap_or_default();
        if let Some(driving) = tally
            .driving
            .iter_mut()
            .find(|(_, t)| *t == Some(test_index))
        {
            driving.1 = None;
        }
        let word = verdict.map_or("not run".to_owned(), |v| format!("{}{on}", v.as_str()));
        let word = word.as_str();
        // The bar names the test until the next starts: at the end, the last one's verdict.
        self.bar.set_message(format!("test {test_index}: {word}"));
        if self.every_test || !passed {
            if self.lines && self.every_test {
                self.line(&format!(
                    "test {test_index}: {word} ({}/{} done, {} did not pass)",
                    tally.done, tally.tests, tally.not_passed
                ));
            } else {
                self.line(&format!("test {test_index}: {word}"));
            }
        }
        if self.lines && !self.every_test {
            let percent = 100 * tally.done / tally.tests.max(1);
            if percent > tally.last_percent || tally.last_status.elapsed() >= STATUS_EVERY {
                tally.last_percent = percent;
                tally.last_status = std::time::Instant::now();
                self.line(&tally.status());
            }
        }
    }
}

/// A campaign that did not run to its end, with where its record is.
#[derive(Debug, thiserror::Error)]
#[error("{error} (run directory {})", dir.display())]
pub(super) struct CampaignFailed {
    error: RunError,
    dir: PathBuf,
}

impl CampaignFailed {
    pub(super) fn new(error: RunError, dir: &Path) -> Self {
        Self {
            error,
            dir: dir.to_owned(),
        }
    }
}

/// Prints a campaign's table of tests and its summary (with the wall time when known). Above
/// [`EVERY_TEST_UP_TO`] tests the table lists the tests that did not pass (every test with `-v`);
/// with `-q` only the summary is printed.
pub(super) fn print_report(report: &CampaignReport, wall: Option<Duration>) {
    use crate::output::{Verbosity, verbosity};
    let every = every_test(report.tests.len());
    let listed: Vec<_> = report
        .tests
        .iter()
        .filter(|t| every || t.verdict != Some(Verdict::Passed))
        .collect();
    if verbosity() > Verbosity::Quiet {
        print_table(&listed);
        if listed.len() < report.tests.len() {
            println!(
                "({} passing tests not listed: -v lists every test)",
                report.tests.len() - listed.len()
            );
        }
    }
    print_summary(report, wall);
}

/// A campaign's result as `--json` prints it (docs/json.md): the run directory, the wall time
/// when known, `campaign.json`'s record and every test's row of the table.
#[derive(serde::Serialize)]
pub(super) struct CampaignJson<'a> {
    /// The run directory.
    dir: &'a Path,
    /// The campaign's wall time, seconds (when this command ran it).
    wall_time_s: Option<f64>,
    /// `campaign.json`: the settings and the summary.
    campaign: &'a campaign::files::CampaignRecord,
    /// Every test, in order.
    tests: &'a [crate::runner::TestSummary],
}

/// Prints a campaign's result as one JSON document (`command` is the command that printed it).
pub(super) fn print_report_json(
    command: &str,
    report: &CampaignReport,
    wall: Option<Duration>,
) -> Result<()> {
    crate::output::print_json(
        command,
        &CampaignJson {
            dir: &report.dir,
            wall_time_s: wall.map(|w| w.as_secs_f64()),
            campaign: &report.record,
            tests: &report.tests,
        },
    )
}

/// The table of `tests`.
fn print_table(tests: &[&crate::runner::TestSummary]) {
    // On several cars, which car drove each test.
    let cars = tests.iter().any(|t| t.car.is_some());
    let (car_head, car_rule) = if cars { (" car |", "---|") } else { ("", "") };
    println!(
        "| test |{car_head} verdict | worst deviation | starvations | smallest margin | reason |"
    );
    println!("|---|{car_rule}---|---|---|---|---|");
    for t in tests {
        let car = if cars {
            format!(" {} |", t.car.as_deref().unwrap_or("-"))
        } else {
            String::new()
        };
        println!(
            "| {} |{car} {} | {} | {} | {} | {} |",
            t.test_index,
            t.verdict.map_or("not run", Verdict::as_str),
            metres(t.worst_deviation_m),
            t.starvations,
            t.smallest_margin_s
                .map_or_else(|| "-".to_owned(), |m| format!("{m:.2} s")),
            t.reason.as_deref().unwrap_or("")
        );
    }
}

/// A campaign's summary: its counts, the failing cases and the run directory.
fn print_summary(report: &CampaignReport, wall: Option<Duration>) {
    let Some(s) = &report.record.summary else {
        return;
    };
    if crate::output::chatty() {
        println!();
    }
    println!(
        "tests {}, passed {}, failed {}, aborted {}, worst deviation {}{}",
        s.tests,
        s.passed,
        s.failed,
        s.aborted,
        metres(s.worst_deviation_m),
        wall.map_or_else(String::new, |w| format!(
            "; {:.1} s wall time",
            w.as_secs_f64()
        ))
    );
    if let Some(why) = &s.uwb_not_tested {
        println!("UWB NOT TESTED: {why}");
    }
    // This session's cars (a resumed campaign's earlier ones are in `runs show`).
    let last = report.record.cars.last().and_then(|c| c.session);
    let cars: Vec<_> = report
        .record
        .cars
        .iter()
        .filter(|c| c.session == last)
        .cloned()
        .collect();
    for line in cars_lines(&cars) {
        println!("{line}");
    }
    let shown = listed_at_most();
    for file in s.failing_cases.iter().take(shown) {
        println!("  {}", report.dir.join(file).display());
    }
    if s.failing_cases.len() > shown {
        // `-q` and `-v` do not go together: under `-q` the way to them is the run directory.
        let hint = if crate::output::verbosity() == crate::output::Verbosity::Quiet {
            "runs show -v lists them all"
        } else {
            "-v lists them all"
        };
        println!(
            "  … and {} more failing cases in the run directory ({hint})",
            s.failing_cases.len() - shown
        );
    }
    println!("run directory: {}", report.dir.display());
}

/// A line per car of a campaign on several cars: `car A (tcp://…): 12 tests`, or for a car that
/// left, `car B (tcp://…): LEFT after 3 tests: <why>`.
pub(super) fn cars_lines(cars: &[campaign::files::CarRun]) -> Vec<String> {
    cars.iter()
        .map(|car| {
            let tests = match car.tests.len() {
                1 => "1 test".to_owned(),
                n => format!("{n} tests"),
            };
            let line = match &car.left {
                Some(why) => format!(
                    "car {} ({}): LEFT the campaign after {tests}: {why}",
                    car.name, car.address
                ),
                None => format!("car {} ({}): {tests}", car.name, car.address),
            };
            match car.session {
                Some(session) => format!("session {session}: {line}"),
                None => line,
            }
        })
        .collect()
}

/// Metres with two decimals, or `-`.
pub(super) fn metres(value: Option<f64>) -> String {
    value.map_or_else(|| "-".to_owned(), |m| format!("{m:.2} m"))
}

/// The scenario `name` a run directory `dir` (given with `flag`) names, to load when no
/// `--scenario` is given: it must be bundled.
pub(super) fn bundled_scenario(flag: &str, dir: &Path, name: &str) -> Result<String> {
    if scenarios::bundled::text(name).is_none() {
        bail!(
            "{flag} {}: its scenario `{name}` is not bundled; give its file with --scenario",
            dir.display()
        );
    }
    Ok(name.to_owned())
}

/// The case files (`case-NNN.json`) of run directory `dir`, in test order.
pub(super) fn case_files(dir: &Path) -> Result<Vec<PathBuf>> {
    // `case-NNN.json` only: not a partial case kept by a resumed campaign
    // (`case-NNN.partial-K.json`).
    let index = |p: &PathBuf| {
        p.file_name().and_then(|n| n.to_str()).and_then(|n| {
            n.strip_prefix("case-")?
                .strip_suffix(".json")?
                .parse::<u64>()
                .ok()
        })
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| index(p).is_some())
        .collect();
    // By test index: names sort wrong past 999 (`case-1000` before `case-999`).
    files.sort_by_key(|p| (index(p), p.clone()));
    Ok(files)
}

/// Refuses, before anything is driven, an output file a command writes only at its end
/// (`--junit`): its directory must exist, and it must not lie in the run directory `run_dir`,
/// where it could replace a recorded file.
pub(super) fn check_output_file(flag: &str, file: &Path, run_dir: &Path) -> Result<()> {
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_owned());
    let (file_abs, dir_abs) = (absolute(file), absolute(run_dir));
    if file_abs.starts_with(&dir_abs) {
        bail!(
            "{flag} {}: inside the run directory {}, where it could replace a recorded file; \
             write it elsewhere",
            file.display(),
            run_dir.display()
        );
    }
    let parent = file_abs.parent().unwrap_or(Path::new("/"));
    if !parent.is_dir() {
        bail!(
            "{flag} {}: the directory {} does not exist",
            file.display(),
            parent.display()
        );
    }
    Ok(())
}

/// The largest case file read, bytes (a case of 1,000 segments of 100 points is about 20 MB).
pub const MAX_CASE_BYTES: u64 = 64 * 1024 * 1024;

/// The case file at `path`, read and parsed; errors name the file (and the field). Only a regular
/// file of at most [`MAX_CASE_BYTES`] is read: a FIFO or a device would block or never end.
pub(super) fn read_case(path: &Path) -> Result<Case> {
    let meta =
        std::fs::metadata(path).with_context(|| format!("cannot read {}", path.display()))?;
    if !meta.is_file() {
        bail!(
            "{}: not a regular file (a directory, FIFO or device): a case is a JSON file",
            path.display()
        );
    }
    if meta.len() > MAX_CASE_BYTES {
        bail!(
            "{}: {} bytes: a case file is at most {MAX_CASE_BYTES} bytes",
            path.display(),
            meta.len()
        );
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    Case::from_json(&text).with_context(|| path.display().to_string())
}

/// The scenario a case is driven in: `--scenario`, or the bundled one the case names.
pub(super) fn scenario_of(
    scenario: Option<&str>,
    case_path: &Path,
    case: &Case,
) -> Result<Scenario> {
    let arg = scenario.unwrap_or(&case.scenario.name);
    let loaded = match scenario {
        Some(arg) => load_scenario(arg)?,
        None => {
            let name = &case.scenario.name;
            if scenarios::bundled::text(name).is_none() {
                bail!(
                    "{}: scenario.name `{name}` is not a bundled scenario; give its file with \
                     --scenario",
                    case_path.display()
                );
            }
            load_scenario(name)?
        }
    };
    print_warnings_of_use(arg, &loaded);
    Ok(loaded.scenario)
}

/// Refuses a case recorded in another scenario (or without a hash) unless told to proceed.
pub(super) fn check_hash(case: &Case, scenario: &Scenario, ignore: bool) -> Result<()> {
    let hash = scenario.hash();
    let problem = match &case.scenario.hash {
        Some(recorded) if *recorded == hash => return Ok(()),
        Some(recorded) => format!(
            "the case was recorded in scenario `{}` with hash {}, but scenario `{}` hashes to {}",
            case.scenario.name,
            short(recorded),
            scenario.name,
            short(&hash)
        ),
        None => format!(
            "the case names no scenario hash, so it cannot be checked against scenario `{}`",
            scenario.name
        ),
    };
    if ignore {
        eprintln!("warning: {problem}; replaying anyway (--ignore-scenario-hash)");
        return Ok(());
    }
    bail!("{problem}; pass --ignore-scenario-hash to replay it anyway")
}

fn short(hash: &str) -> &str {
    hash.get(..12).unwrap_or(hash)
}

/// A scratch directory of this process (`drivecheck-<kind>-<pid>-<name>` in the system's
/// temporary directory), removed when dropped: for runs whose case files are read from the
/// report, not from disk.
pub(super) struct Scratch(pub PathBuf);

impl Scratch {
    /// Where a bench puts its run directories: `given` (`--scratch DIR`, created new and kept),
    /// else a scratch directory removed when the returned guard is dropped.
    pub(super) fn given_or_new(
        given: Option<&Path>,
        kind: &str,
        name: &str,
    ) -> Result<(Option<Self>, PathBuf)> {
        match given {
            Some(dir) => {
                std::fs::create_dir(dir)
                    .with_context(|| format!("--scratch {}: cannot create it", dir.display()))?;
                Ok((None, dir.to_owned()))
            }
            None => {
                let scratch = Self::new(kind, name)?;
                let root = scratch.0.clone();
                Ok((Some(scratch), root))
            }
        }
    }

    pub(super) fn new(kind: &str, name: &str) -> Result<Self> {
        let path =
            std::env::temp_dir().join(format!("drivecheck-{kind}-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        Ok(Self(path))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::connect_sim;
    use car_link::RoutePoint;

    /// Drives the embedded simulated car on its autopilot at 1.5 m/s for 3 s (a straight route
    /// onward from where it stands, along the scenario's start route), then, when `brake`,
    /// registers it with an interrupt and brakes as the second signal does; the car's speed 0.5 s
    /// later.
    async fn speed_after(brake: bool) -> f64 {
        let scenario = scenarios::bundled::load("parking-lot-2anchors")
            .expect("bundled")
            .scenario;
        let (car, sim) = connect_sim(&car_sim::SimConfig::from_scenario(&scenario))
            .await
            .expect("the simulated car");
        let start = scenario.start_route.positions();
        let (from, to) = (start[0], start[1]);
        let (dx, dy) = (to.x - from.x, to.y - from.y);
        let step = 2.0 / dx.hypot(dy);
        let route: Vec<RoutePoint> = (1..=15)
            .map(|k| {
                let k = f64::from(k) * step;
                RoutePoint::at(from.x + k * dx, from.y + k * dy, 1.5)
            })
            .collect();
        car.clear_route().await.expect("cleared");
        car.add_points(&route).await.expect("uploaded");
        car.set_autopilot(true, false).await.expect("started");
        tokio::time::sleep(Duration::from_secs(3)).await;
        assert!(sim.truth().speed > 1.0, "the car drives: {:?}", sim.truth());
        let interrupt = Interrupt {
            cancel: CancellationToken::new(),
            car: Arc::new(Mutex::new(None)),
            cars: Arc::default(),
        };
        let guard = interrupt.brake_on_second(&car);
        if brake {
            interrupt.brake_now().await;
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
        drop(guard);
        assert!(
            lock(&interrupt.car).is_none(),
            "the guard unregisters the car"
        );
        sim.truth().speed
    }

    #[tokio::test(start_paused = true)]
    async fn the_second_signal_brakes_the_registered_car() {
        let coasting = speed_after(false).await;
        let braked = speed_after(true).await;
        assert!(
            coasting > 1.0,
            "without the brake it still drives: {coasting}"
        );
        assert!(braked < 0.3, "the brake stops it: {braked}");
    }
}
