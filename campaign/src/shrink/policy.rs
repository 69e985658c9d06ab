//! The shrink's policy: which runs to drive, which candidate to keep, when to stop and how the
//! minimal case is confirmed. Pure; the driving is the caller's ([`Drive`]: fresh simulated cars
//! in the orchestrator, a stand-in in the tests).
//!
//! 1. The case is driven `runs` times (run k on the car [`Purpose::Rerun`] k of the case's test,
//!    so that run 0 is the campaign's own car and gives the case's figures; a case without a
//!    test index with [`Purpose::Run`] k): every run must fail at one segment or two
//!    neighbouring ones (its [`Target`]), or there is nothing to shrink.
//! 2. Every run of a kept candidate must fail by `margin` above the threshold, or by as much as
//!    the case did in its least clear run if that is less.
//! 3. Each candidate of the [`Shrinker`] is driven up to `runs` times, stopping at the first run
//!    that does not fail clearly at its target; it is kept only when every run did. Before each
//!    candidate the driver may stop the shrink ([`Drive::stop`]: interrupted, or the budget).
//! 4. A greedy shrink moves values to where the case only just fails, so a case can be kept
//!    because its runs happened to fail: the last case kept is confirmed with twice as many
//!    other seeds (runs `runs` to `3 · runs − 1`). When it does not fail the same way in all of
//!    them, the case itself is driven with those seeds once; a kept case that fails in at least
//!    as many is as robust as the case and stays, otherwise the shrink steps back to the case
//!    kept before it and confirms that one.
//! 5. A minimal case with faults is driven `runs` times without them: does the failure need
//!    them?

use scenarios::Scenario;
use thiserror::Error;

use super::{
    CaseSummary, Confirmation, Edit, Ended, RunResult, ShrinkError, Shrinker, Size, Step, Target,
};
use crate::files::{Case, CommandRecord};
use crate::seed::{Purpose, derive};

/// What drives a case for the shrink.
pub trait Drive {
    /// Why a run could not be driven.
    type Error;

    /// Drives `case` once, its run seeded with `seed` (with [`Settings::test_index`] the
    /// simulated car's seed, the case driven as its own test; otherwise the campaign seed of a
    /// one-test campaign): the case the run wrote, with its results.
    fn drive(&mut self, case: &Case, seed: u64) -> Result<Case, Self::Error>;

    /// Whether the shrink ends before its next candidate: `Some(Ended::Interrupted)` when the
    /// operator interrupted it, `Some(Ended::Budget)` when its time is spent.
    fn stop(&mut self) -> Option<Ended>;

    /// What the shrink does next, for a progress line.
    fn progress(&mut self, _now: Progress<'_>) {}
}

/// What a shrink is doing (see [`Drive::progress`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Progress<'a> {
    /// Driving the case itself to find its target.
    Reproducing,
    /// Driving a candidate.
    Candidate {
        /// The step, from 1.
        step: usize,
        /// The candidate's edit.
        edit: &'a Edit,
        /// Commands of the current (smallest kept) case.
        commands: usize,
    },
    /// Confirming the last case kept with `runs` other seeds.
    Confirming {
        /// Runs.
        runs: u32,
    },
    /// Driving the minimal case without its faults.
    WithoutFaults,
}

/// How a shrink is run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Runs per candidate.
    pub runs: u32,
    /// The seed: the case's campaign seed, run k then on the car [`Purpose::Rerun`] k of test
    /// [`Settings::test_index`]; without a test index run k has the seed [`Purpose::Run`] k of it.
    pub seed: u64,
    /// The case's test in its campaign (`None`: a hand-written case).
    pub test_index: Option<usize>,
    /// How far above the threshold every run must fail (at most the case's own smallest
    /// excess), m.
    pub margin_m: f64,
}

/// Why a shrink failed.
#[derive(Debug, Error)]
pub enum ShrinkFailure<E> {
    /// A run could not be driven.
    #[error("{0}")]
    Drive(E),
    /// The case does not fail in every run at one segment or two neighbouring ones.
    #[error(
        "does not fail in every run at one segment or two neighbouring ones ({}): nothing to \
         shrink; replay it with --vary-seed to see how it varies",
        describe_runs(.runs)
    )]
    NotReproducible {
        /// The runs of the case.
        runs: Vec<RunResult>,
    },
    /// The case cannot be shrunk.
    #[error("cannot be shrunk: {0}")]
    Shrinker(#[source] ShrinkError),
}

/// What a shrink found.
#[derive(Debug, Clone, PartialEq)]
pub struct Shrunk {
    /// Why it stopped.
    pub ended: Ended,
    /// The largest deviation every run of a kept candidate had to reach at its target, m.
    pub min_deviation_m: f64,
    /// The case shrunk.
    pub before: CaseSummary,
    /// The minimal case as its first run wrote it (with results; as planned when it has no
    /// run), with the case's campaign seed (or the shrink's) and test index: `minimal.json`.
    pub minimal: Case,
    /// The minimal case: its size, target and runs.
    pub after: CaseSummary,
    /// The minimal case driven without its faults (absent when it has none, or when the shrink
    /// did not end minimal).
    pub without_faults: Option<Vec<RunResult>>,
    /// The confirmation with other seeds (absent when interrupted).
    pub confirmation: Option<Confirmation>,
    /// Every edit tried, in order.
    pub steps: Vec<Step>,
    /// Runs driven in all.
    pub runs_driven: usize,
}

/// A case the shrink kept, with its runs and the case its first run wrote.
struct Kept {
    case: Case,
    target: Target,
    runs: Vec<RunResult>,
    first: Option<Case>,
}

/// The runs of a shrink: seeds from the settings, counted.
struct Runs<'d, D> {
    driver: &'d mut D,
    seed: u64,
    test_index: Option<usize>,
    driven: usize,
}

impl<D: Drive> Runs<'_, D> {
    /// Drives `case` as runs `first..first + count`; with `target` (a target and a least
    /// deviation), stops after the first run that does not fail there clearly. The runs and the
    /// case the first one wrote.
    fn drive(
        &mut self,
        case: &Case,
        first: u32,
        count: u32,
        target: Option<(Target, f64)>,
    ) -> Result<(Vec<RunResult>, Option<Case>), D::Error> {
        let mut results = Vec::new();
        let mut first_case = None;
        for k in first..first + count {
            let run = u64::from(k);
            let seed = match self.test_index {
                Some(test_index) => derive(self.seed, Purpose::Rerun { test_index, run }),
                None => derive(self.seed, Purpose::Run { run }),
            };
            self.driven += 1;
            let driven = self.driver.drive(case, seed)?;
            let result = RunResult::of(seed, &driven);
            results.push(result);
            first_case.get_or_insert(driven);
            if target.is_some_and(|(t, m)| !result.fails_clearly(t, m)) {
                break;
            }
        }
        Ok((results, first_case))
    }
}

/// Shrinks `case` in `scenario` (see the module doc), driving with `driver`.
pub fn shrink<D: Drive>(
    case: &Case,
    scenario: &Scenario,
    settings: &Settings,
    driver: &mut D,
) -> Result<Shrunk, ShrinkFailure<D::Error>> {
    let n = settings.runs;
    let mut runs = Runs {
        driver,
        seed: settings.seed,
        test_index: settings.test_index,
        driven: 0,
    };
    runs.driver.progress(Progress::Reproducing);
    let (before_runs, before_case) = runs.drive(case, 0, n, None).map_err(ShrinkFailure::Drive)?;
    let Some(target) = Target::of_runs(&before_runs) else {
        return Err(ShrinkFailure::NotReproducible { runs: before_runs });
    };
    let threshold = before_case
        .as_ref()
        .and_then(|c| c.segments.first())
        .map_or(0.0, |s| s.oracle.threshold_m);
    let least = before_runs
        .iter()
        .filter_map(|r| r.max_deviation_m)
        .fold(f64::INFINITY, f64::min);
    let min_deviation = (threshold + settings.margin_m).min(least);
    let mut shrinker = Shrinker::new(case, scenario, target, settings.seed)
        .map_err(ShrinkFailure::Shrinker)?
        .with_min_deviation(min_deviation);
    let before = CaseSummary {
        size: Size::of(case),
        target,
        runs: before_runs.clone(),
    };
    // Every case kept, the case itself first: the confirmation may step back through them.
    let mut kept = vec![Kept {
        case: shrinker.current().clone(),
        target,
        runs: before_runs,
        first: before_case,
    }];
    let mut ended = Ended::Minimal;
    while let Some(candidate) = shrinker.next_candidate() {
        if let Some(stop) = runs.driver.stop() {
            ended = stop;
            break;
        }
        runs.driver.progress(Progress::Candidate {
            step: shrinker.steps().len() + 1,
            edit: &candidate.edit,
            commands: shrinker.current().commands.len(),
        });
        let clearly = Some((candidate.target, min_deviation));
        let (candidate_runs, first) = match runs.drive(&candidate.case, 0, n, clearly) {
            Ok(driven) => driven,
            Err(_) if runs.driver.stop() == Some(Ended::Interrupted) => {
                ended = Ended::Interrupted;
                break;
            }
            Err(error) => return Err(ShrinkFailure::Drive(error)),
        };
        if shrinker.record(candidate, candidate_runs.clone()) {
            kept.push(Kept {
                case: shrinker.current().clone(),
                target: shrinker.target(),
                runs: candidate_runs,
                first,
            });
        }
    }
    let confirmation = if ended == Ended::Interrupted {
        None
    } else {
        Some(confirm(&mut runs, &mut kept, n, min_deviation).map_err(ShrinkFailure::Drive)?)
    };
    let Kept {
        case: current,
        target,
        runs: after_runs,
        first: after_case,
    } = kept.pop().expect("the case itself is always kept");
    let has_faults = current
        .commands
        .iter()
        .any(|c| matches!(c, CommandRecord::AddFault { .. }));
    let without_faults = if has_faults && ended == Ended::Minimal {
        runs.driver.progress(Progress::WithoutFaults);
        let mut bare = current.clone();
        bare.commands
            .retain(|c| matches!(c, CommandRecord::RunSegments { .. }));
        let (bare_runs, _) = runs
            .drive(&bare, 0, n, None)
            .map_err(ShrinkFailure::Drive)?;
        Some(bare_runs)
    } else {
        None
    };
    let mut minimal = after_case.unwrap_or(current);
    minimal.campaign_seed = case.campaign_seed.or(Some(settings.seed));
    minimal.test_index = case.test_index;
    Ok(Shrunk {
        ended,
        min_deviation_m: min_deviation,
        before,
        after: CaseSummary {
            size: Size::of(&minimal),
            target,
            runs: after_runs,
        },
        minimal,
        without_faults,
        confirmation,
        steps: shrinker.steps().to_vec(),
        runs_driven: runs.driven,
    })
}

/// Confirms the last case kept with `2 · n` other seeds (runs `n..3n`), stepping back through
/// `kept` while it is less robust than the case itself (see the module doc); `kept` ends with
/// the case confirmed.
fn confirm<D: Drive>(
    runs: &mut Runs<'_, D>,
    kept: &mut Vec<Kept>,
    n: u32,
    min_deviation: f64,
) -> Result<Confirmation, D::Error> {
    let failed_runs = |results: &[RunResult], target| {
        results
            .iter()
            .filter(|r| r.fails_clearly(target, min_deviation))
            .count()
    };
    let mut stepped_back = 0;
    let mut case_failed: Option<usize> = None;
    loop {
        let last = kept.last().expect("the case itself is always kept");
        runs.driver.progress(Progress::Confirming { runs: n * 2 });
        let (results, _) = runs.drive(&last.case, n, n * 2, None)?;
        let failed = failed_runs(&results, last.target);
        if failed < results.len() && case_failed.is_none() {
            // Not every run failed: how robust is the case itself with these seeds?
            let case = &kept[0];
            let (case_runs, _) = runs.drive(&case.case, n, n * 2, None)?;
            case_failed = Some(failed_runs(&case_runs, case.target));
        }
        let as_robust = failed == results.len() || case_failed.is_some_and(|c| failed >= c);
        if as_robust || kept.len() == 1 {
            return Ok(Confirmation {
                runs: results,
                failed,
                case_failed,
                confirmed: as_robust,
                stepped_back,
            });
        }
        kept.pop();
        stepped_back += 1;
    }
}

/// Runs in words, for the error that a case does not fail the same way.
fn describe_runs(runs: &[RunResult]) -> String {
    runs.iter().map(describe).collect::<Vec<_>>().join("; ")
}

/// A run in words.
fn describe(run: &RunResult) -> String {
    let verdict = run
        .verdict
        .map_or("no verdict", crate::oracle::Verdict::as_str);
    match run.first_failing_segment {
        Some(segment) => format!("seed {}: {verdict} at segment {segment}", run.seed),
        None => format!("seed {}: {verdict}", run.seed),
    }
}
