//! `drivecheck shrink CASE.json` (and `drivecheck run --shrink`): a failing case shrunk to the
//! smallest test that still fails the same way every time, on the embedded simulated car in
//! virtual time.
//!
//! The strategy is [`campaign::shrink`]'s; this module drives its candidates. Every candidate is
//! driven `--runs` times (run k with seed + k, so the sensor noise differs), each on a fresh
//! simulator, and its runs stop at the first that does not fail the same way. The candidates'
//! runs record no MCAP and their run directories are scratch (removed at the end); the shrink
//! directory keeps `minimal.json` (the minimal case as its first confirming run wrote it: a case
//! file every command takes, e.g. `drivecheck replay`) and `shrink.json` (every step).

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use scenarios::Scenario;
use tokio_util::sync::CancellationToken;

use super::shared::{cancel_on_ctrl_c, check_hash, read_case, runtime, scenario_of};
use super::simdrive::{SimDriver, SimSettings};
use crate::cli::ShrinkArgs;
use crate::exit::Exit;
use crate::runner::run_dir_name;
use crate::seed::choose_seed;
use campaign::case::{Case, CommandRecord, ScenarioRef, tool_version};
use campaign::shrink::{
    CaseSummary, Confirmation, Ended, MINIMAL_FILE, RunResult, SHRINK_FILE, SHRINK_FORMAT,
    ShrinkReport, Shrinker, Size, Target,
};

/// `--margin`'s default (and `run --shrink`'s margin), metres.
pub(super) const DEFAULT_MARGIN_M: f64 = 0.1;

/// How a shrink is run.
#[derive(Debug, Clone)]
pub(super) struct Options {
    /// Runs per candidate.
    pub runs: u32,
    /// Wall-time budget.
    pub budget: Duration,
    /// Seed of run 1 of every candidate.
    pub seed: u64,
    /// How far above the threshold every run must fail (at most the case's own smallest
    /// excess), m.
    pub margin: f64,
}

/// The case does not fail at one segment (or two neighbouring ones) in every run: nothing to
/// shrink. A finding about the case, not an error of the tool ([`Exit::Found`]).
#[derive(Debug, thiserror::Error)]
#[error(
    "{}: does not fail in every run at one segment or two neighbouring ones ({}): nothing to \
     shrink; replay it with --vary-seed to see how it varies",
    case.display(),
    runs.join("; ")
)]
pub(super) struct NotReproduced {
    /// The case file.
    case: std::path::PathBuf,
    /// How each run ended.
    runs: Vec<String>,
}

/// `drivecheck shrink`. Exit status: 0 the case was shrunk (or was minimal already), 1 it does
/// not fail the same way in every run ([`NotReproduced`]), 2 an error (the case refused).
pub fn shrink(args: &ShrinkArgs) -> Result<Exit> {
    if !(args.margin.is_finite() && args.margin >= 0.0) {
        bail!(
            "--margin {}: must be a finite number of metres, 0 or more",
            args.margin
        );
    }
    let path = &args.case;
    let case = read_case(path)?;
    let scenario = scenario_of(args.scenario.as_deref(), path, &case)?;
    check_hash(&case, &scenario, args.ignore_scenario_hash)?;
    let seed = args
        .seed
        .or(case.campaign_seed)
        .unwrap_or_else(|| choose_seed(None));
    let out = match &args.out {
        Some(out) => out.clone(),
        None => crate::runner::claim_default_run_dir(&run_dir_name(
            &format!("shrink-{}", scenario.name),
            seed,
        ))?,
    };
    let options = Options {
        runs: args.runs,
        budget: args.budget,
        seed,
        margin: args.margin,
    };
    let runtime = runtime(true)?;
    let report = match runtime.block_on(async {
        let cancel = cancel_on_ctrl_c();
        shrink_case(path, &case, &scenario, &options, &out, &cancel, true).await
    }) {
        Ok(report) => report,
        Err(error) => {
            let not_reproduced = error.downcast::<NotReproduced>()?;
            eprintln!("{not_reproduced}");
            return Ok(Exit::Found);
        }
    };
    print_summary(&report, &out);
    Ok(Exit::Success)
}

/// Prints the before/after table and where the files are.
pub(super) fn print_summary(report: &ShrinkReport, out: &Path) {
    print!("{}", report.table());
    let kept = report
        .steps
        .iter()
        .filter(|s| s.outcome == campaign::shrink::Outcome::Kept)
        .count();
    println!(
        "{} steps tried, {kept} kept, {} simulator runs, {:.1} s wall time; {}",
        report.steps.len(),
        report.simulator_runs,
        report.wall_s,
        match report.ended {
            Ended::Minimal => "no simpler case fails the same way",
            Ended::Budget => "stopped by the time budget (--budget)",
            Ended::Interrupted => "interrupted",
        }
    );
    if let Some(c) = &report.confirmation {
        let seeds = c.runs.first().map_or(0, |r| r.seed);
        println!(
            "the minimal case fails the same way in {} of {} other seed(s) from {seeds}{}{}",
            c.failed,
            c.runs.len(),
            c.case_failed
                .map(|n| format!(" (the case itself: {n})"))
                .unwrap_or_default(),
            if c.stepped_back > 0 {
                format!(
                    " (after stepping back {} kept step(s) that only just failed)",
                    c.stepped_back
                )
            } else {
                String::new()
            }
        );
    }
    if let Some(runs) = &report.without_faults {
        let failed = runs
            .iter()
            .filter(|r| r.fails_at(report.after.target))
            .count();
        println!(
            "without its faults the minimal case fails the same way in {failed} of {} runs",
            runs.len()
        );
    }
    println!(
        "minimal case: {}; every step: {}",
        out.join(MINIMAL_FILE).display(),
        out.join(SHRINK_FILE).display()
    );
    println!("on the car: {}", report.replay_on_car);
}

/// Shrinks `case` (read from `path`) in `scenario` and writes the shrink directory `out` (which
/// must be new or empty). With `progress`, shows a spinner on standard error.
pub(super) async fn shrink_case(
    path: &Path,
    case: &Case,
    scenario: &Scenario,
    options: &Options,
    out: &Path,
    cancel: &CancellationToken,
    progress: bool,
) -> Result<ShrinkReport> {
    let started = Instant::now();
    if crate::runner::is_used(out) {
        bail!(crate::runner::RunError::OutDirUsed {
            path: out.to_owned()
        });
    }
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let driver = SimDriver::new(
        scenario,
        path,
        case,
        out.join(".scratch"),
        (options.runs, options.seed),
        cancel,
    );
    let plain = SimSettings::default();
    let bar = spinner(progress);
    bar.set_message(format!("driving {} to confirm its failure", path.display()));
    // The case as it is: it must fail at the same segment in every run.
    let (before_runs, before_cases) = driver.drive_all(case, None, &plain).await?;
    let before_case = before_cases.into_iter().next().map(|(_, c)| c);
    let target = match Target::of_runs(&before_runs) {
        Some(target) => target,
        None => {
            return Err(NotReproduced {
                case: path.to_owned(),
                runs: before_runs.iter().map(describe).collect(),
            }
            .into());
        }
    };
    // Every run must fail by the margin above the threshold, or by as much as the case itself
    // did in its least clear run if that is less.
    let threshold = before_case
        .as_ref()
        .and_then(|c| c.segments.first())
        .map_or(0.0, |s| s.oracle.threshold_m);
    let least = before_runs
        .iter()
        .filter_map(|r| r.max_deviation_m)
        .fold(f64::INFINITY, f64::min);
    let min_deviation = (threshold + options.margin).min(least);
    let mut shrinker = Shrinker::new(case, scenario, target, options.seed)
        .with_context(|| format!("{}: cannot be shrunk", path.display()))?
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
        if cancel.is_cancelled() {
            ended = Ended::Interrupted;
            break;
        }
        if started.elapsed() > options.budget {
            ended = Ended::Budget;
            break;
        }
        bar.set_message(format!(
            "step {}: {} ({} commands now)",
            shrinker.steps().len() + 1,
            candidate.edit,
            shrinker.current().commands.len()
        ));
        let (runs, cases) = match driver
            .drive_all(
                &candidate.case,
                Some((candidate.target, min_deviation)),
                &plain,
            )
            .await
        {
            Err(_) if cancel.is_cancelled() => {
                ended = Ended::Interrupted;
                break;
            }
            result => result?,
        };
        if shrinker.record(candidate, runs.clone()) {
            kept.push(Kept {
                case: shrinker.current().clone(),
                target: shrinker.target(),
                runs,
                first: cases.into_iter().next().map(|(_, c)| c),
            });
        }
        bar.tick();
    }
    // A greedy shrink moves values to where the case only just fails: a case kept because its
    // runs happened to fail. Confirm the last one with twice as many other seeds; when it does
    // not fail the same way in all of them, step back to the case kept before it.
    let confirmer = SimDriver {
        seed: options.seed.wrapping_add(u64::from(options.runs)),
        runs: options.runs * 2,
        count: std::cell::Cell::new(0),
        scratch: driver.scratch.clone(),
        of: driver.of.clone(),
        ..driver
    };
    let mut stepped_back = 0;
    let mut case_failed: Option<usize> = None;
    let confirmation = loop {
        if ended == Ended::Interrupted {
            break None;
        }
        let last = kept.last().expect("the case itself is always kept");
        bar.set_message(format!(
            "confirming the minimal case with {} other seeds",
            confirmer.runs
        ));
        let failed_runs = |runs: &[RunResult], target| {
            runs.iter()
                .filter(|r| r.fails_clearly(target, min_deviation))
                .count()
        };
        let (runs, _) = confirmer.drive_all(&last.case, None, &plain).await?;
        let failed = failed_runs(&runs, last.target);
        if failed < runs.len() && case_failed.is_none() {
            // Not every run failed: how robust is the case itself with these seeds?
            let case = &kept[0];
            let (case_runs, _) = confirmer.drive_all(&case.case, None, &plain).await?;
            case_failed = Some(failed_runs(&case_runs, case.target));
        }
        let as_robust = failed == runs.len() || case_failed.is_some_and(|c| failed >= c);
        if as_robust || kept.len() == 1 {
            break Some(Confirmation {
                runs,
                failed,
                case_failed,
                confirmed: as_robust,
                stepped_back,
            });
        }
        kept.pop();
        stepped_back += 1;
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
        bar.set_message("driving the minimal case without its faults");
        let mut bare = current.clone();
        bare.commands
            .retain(|c| matches!(c, CommandRecord::RunSegments { .. }));
        Some(driver.drive_all(&bare, None, &plain).await?.0)
    } else {
        None
    };
    bar.finish_and_clear();
    let _ = std::fs::remove_dir_all(&driver.scratch);
    // The minimal case as its first confirming run wrote it (with results), or as planned.
    let mut written = after_case.unwrap_or(current);
    written.campaign_seed = case.campaign_seed.or(Some(options.seed));
    written.test_index = case.test_index;
    let minimal_file = out.join(MINIMAL_FILE);
    crate::atomic::write(&minimal_file, format!("{}\n", written.to_json()?))
        .with_context(|| format!("cannot write {}", minimal_file.display()))?;
    let report = ShrinkReport {
        format: SHRINK_FORMAT.to_owned(),
        schema_version: 1,
        tool_version: tool_version().to_owned(),
        case: path.display().to_string(),
        scenario: ScenarioRef::of(scenario),
        seed: options.seed,
        runs_per_candidate: options.runs,
        min_deviation_m: min_deviation,
        ended,
        before,
        after: CaseSummary {
            size: Size::of(&written),
            target,
            runs: after_runs,
        },
        without_faults,
        confirmation,
        steps: shrinker.steps().to_vec(),
        simulator_runs: driver.count.get() + confirmer.count.get(),
        wall_s: started.elapsed().as_secs_f64(),
        replay_on_car: format!(
            "drivecheck replay {} --car tcp://HOST:PORT",
            minimal_file.display()
        ),
    };
    let file = out.join(SHRINK_FILE);
    crate::atomic::write(&file, format!("{}\n", report.to_json()?))
        .with_context(|| format!("cannot write {}", file.display()))?;
    Ok(report)
}

/// A case the shrink kept, with its runs and the case its first run wrote.
struct Kept {
    case: Case,
    target: Target,
    runs: Vec<RunResult>,
    first: Option<Case>,
}

/// A run in words, for the error that a case does not fail the same way.
fn describe(run: &RunResult) -> String {
    let verdict = run
        .verdict
        .map_or("no verdict", campaign::oracle::Verdict::as_str);
    match run.first_failing_segment {
        Some(segment) => format!("seed {}: {verdict} at segment {segment}", run.seed),
        None => format!("seed {}: {verdict}", run.seed),
    }
}

fn spinner(show: bool) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new_spinner();
    if let Ok(style) = ProgressStyle::with_template("{elapsed_precise} {spinner} {msg}") {
        bar.set_style(style);
    }
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}
