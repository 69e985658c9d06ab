//! The progress of a campaign on standard error: a bar on a terminal, plain lines elsewhere,
//! nothing with `-q` (the runner's `CampaignObserver`). What is printed at which verbosity is
//! [`crate::output`]'s: the runner's notes are [`Says::Note`]s, its warnings (a car left armed)
//! [`Says::Safety`], its details [`Says::Detail`], the lines per test [`Says::Progress`].

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

use campaign::oracle::Verdict;
use runner::CampaignObserver;

use crate::output::{self, Says};

/// A campaign's progress where it is read (`docs/scaling.md`):
/// - on a terminal, a bar of the tests run and the test running, with a line above it for each
///   test (above [`EVERY_TEST_UP_TO`] tests only for those that did not pass, unless `-v`);
/// - elsewhere (a CI log, a pipe, `nohup`), plain lines: one per test up to [`EVERY_TEST_UP_TO`]
///   tests, and above that a line for every test that did not pass as it ends and a status line
///   every [`STATUS_EVERY`] or 1 % of the tests (done, failed, rate, time left);
/// - with `-q`, nothing (errors and the summary still are).
///
/// Notes (how the reset joins the start route) are printed unless `-q`, details (what preflight
/// switched off on the simulated car) only with `-v`, warnings (a car left with fault injection
/// enabled) always.
#[derive(Debug)]
pub(super) struct Progress {
    bar: ProgressBar,
    /// Plain lines instead of the bar (standard error is not a terminal).
    lines: bool,
    /// Lines for every test (not only those that did not pass).
    every_test: bool,
    /// No lines of progress (`-q`).
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
pub(super) fn every_test(tests: usize) -> bool {
    tests <= EVERY_TEST_UP_TO || output::verbosity() == output::Verbosity::Verbose
}

/// How many failing cases (and explanations) a summary lists: [`LISTED_AT_MOST`], all with `-v`.
pub(super) fn listed_at_most() -> usize {
    if output::verbosity() == output::Verbosity::Verbose {
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
        let quiet = !output::shows(Says::Progress);
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
        if output::shows(Says::Note) {
            self.line(text);
        }
    }

    fn warning(&self, text: &str) {
        // Also with `-q`: a car left armed is not a detail.
        if output::shows(Says::Safety) {
            self.line(&format!("warning: {text}"));
        }
    }

    fn detail(&self, text: &str) {
        if output::shows(Says::Detail) {
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
        if output::shows(Says::Note) {
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

/// The runner's warnings on standard error ([`Says::Safety`], whatever `-q` says), and nothing
/// else: for a command that shows no campaign progress of its own (`run --dry-run`, `replay`).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct WarningsOnly;

impl CampaignObserver for WarningsOnly {
    fn note(&self, _text: &str) {}

    fn warning(&self, text: &str) {
        output::safety(format_args!("warning: {text}"));
    }

    fn tests_planned(&self, _tests: usize) {}

    fn test_started(&self, _test_index: usize) {}

    fn test_finished(&self, _test_index: usize, _verdict: Option<Verdict>) {}
}
