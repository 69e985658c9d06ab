//! `drivecheck shrink CASE.json` (and `drivecheck run --shrink`): a failing case shrunk to the
//! smallest test that still fails the same way every time, on the embedded simulated car in
//! virtual time.
//!
//! The strategy and the policy (which runs, what is kept, the confirmation) are
//! [`campaign::shrink`]'s; this module drives its runs (run k with seed + k, so the sensor noise
//! differs), each on a fresh simulator. The candidates'
//! runs record no MCAP and their run directories are scratch (removed at the end); the shrink
//! directory keeps `minimal.json` (the minimal case as its first confirming run wrote it: a case
//! file every command takes, e.g. `drivecheck replay`) and `shrink.json` (every step).

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use scenarios::Scenario;
use tokio::runtime::Runtime;

use super::signals::{cancel_on_ctrl_c, runtime};
use crate::cli::ShrinkArgs;
use crate::exit::Exit;
use crate::output;
use crate::settings::CaseSettings;
use campaign::files::{Case, Header, SHRINK_FORMAT, SHRINK_SCHEMA_VERSION, ScenarioRef};
use campaign::shrink::{
    Drive, Ended, MINIMAL_FILE, Progress, SHRINK_FILE, Settings, ShrinkFailure, ShrinkReport,
};
use runner::run_dir_name;
use runner::simdrive::{SimDriver, SimSettings};

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
    /// The simulated car: the scenario's, with the car profile applied.
    pub sim: car_sim::SimConfig,
    /// The car's own firmware built for the host, driving that simulated car's physical car
    /// (`--car sitl:TREE`; `None`: the embedded simulated car).
    pub firmware: Option<super::firmware::HostFirmware>,
}

/// The case does not fail at one segment (or two neighbouring ones) in every run: nothing to
/// shrink. A finding about the case, not an error of the tool ([`Exit::Found`]).
#[derive(Debug, thiserror::Error)]
#[error("{}: {reason}", case.display())]
pub(super) struct NotReproduced {
    /// The case file.
    case: std::path::PathBuf,
    /// How its runs ended ([`ShrinkFailure::NotReproducible`]'s text).
    reason: String,
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
    let CaseSettings {
        case,
        scenario,
        seed,
        firmware,
        profile,
        sim,
        ..
    } = CaseSettings::load("shrink", path, &args.drive, false)?;
    // The directory this shrink made (the default one, or an --out that did not exist), removed
    // again when the shrink writes nothing into it: a case with nothing to shrink leaves no
    // empty directory behind.
    let (out, made) = match &args.out {
        Some(out) => (out.clone(), !out.exists()),
        None => (
            runner::claim_default_run_dir(&run_dir_name(
                &format!("shrink-{}", scenario.name),
                seed,
            ))?,
            true,
        ),
    };
    let options = Options {
        runs: args.runs,
        budget: args.budget,
        seed,
        margin: args.margin,
        sim,
        firmware,
    };
    let runtime = runtime(true)?;
    let report = match shrink_case(&runtime, path, &case, &scenario, &options, &out, true) {
        Ok(report) => report,
        Err(error) => {
            if made {
                // Only an empty directory goes (`remove_dir` refuses any other).
                let _ = std::fs::remove_dir(&out);
            }
            let not_reproduced = error.downcast::<NotReproduced>()?;
            output::finding(&not_reproduced);
            output::note(format_args!(
                "on the simulated car of car profile {}: {}",
                profile.name,
                super::twin::agreement_note(path, &profile)
            ));
            if args.json {
                let result = ShrinkJson {
                    case: path,
                    dir: (!made).then_some(out.as_path()),
                    shrunk: false,
                    not_reproduced: Some(&not_reproduced.reason),
                    minimal: None,
                    shrink: None,
                };
                output::print_json(output::json::SHRINK, &result)?;
            }
            return Ok(Exit::Found);
        }
    };
    if args.json {
        let result = ShrinkJson {
            case: path,
            dir: Some(&out),
            shrunk: true,
            not_reproduced: None,
            minimal: Some(out.join(MINIMAL_FILE)),
            shrink: Some(&report),
        };
        output::print_json(output::json::SHRINK, &result)?;
    } else {
        print_summary(&report, &out);
    }
    Ok(Exit::Success)
}

/// A shrink's result as `--json` prints it (docs/json.md).
#[derive(serde::Serialize)]
struct ShrinkJson<'a> {
    /// The case file shrunk.
    case: &'a Path,
    /// The shrink directory (`None` when the shrink made it and, writing nothing, removed it).
    dir: Option<&'a Path>,
    /// Whether the case was shrunk (or was minimal already): false when it does not fail the
    /// same way in every run (exit status 1).
    shrunk: bool,
    /// Why it was not shrunk: how its runs ended.
    not_reproduced: Option<&'a str>,
    /// The minimal case file.
    minimal: Option<std::path::PathBuf>,
    /// `shrink.json`: every step, the case before and after, the confirmation runs.
    shrink: Option<&'a ShrinkReport>,
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
        report.ended.words()
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
/// must be new or empty). The policy is [`campaign::shrink::shrink`]'s; this drives its runs on
/// fresh embedded simulators on `runtime` (virtual time); the first signal (Ctrl-C) ends it with
/// the smallest case so far. With `progress`, shows a spinner on standard error.
pub(super) fn shrink_case(
    runtime: &Runtime,
    path: &Path,
    case: &Case,
    scenario: &Scenario,
    options: &Options,
    out: &Path,
    progress: bool,
) -> Result<ShrinkReport> {
    let started = Instant::now();
    let cancel = runtime.block_on(async { cancel_on_ctrl_c() });
    // Claimed for the whole shrink: another process given the same --out is refused.
    let claim = runner::claim_out_dir(out, false)?;
    if let Some(note) = claim.stale_note() {
        output::note(note);
    }
    let mut sim = SimDriver::new(
        (scenario, options.sim.clone()),
        path,
        case,
        out.join(".scratch"),
        (options.runs, options.seed),
        &cancel,
    );
    sim.firmware = options.firmware.clone();
    // Every run is the case's own test (the campaign's reset, safe stop and start), run 0 on
    // the campaign's own car: the shrink's "before" is the case's figures.
    sim.test = runner::SameTest::of_case(case, scenario)
        .with_context(|| format!("{}: where its test started", path.display()))?
        .map(|test| runner::SameTest {
            campaign_seed: options.seed,
            ..test
        });
    let mut driver = SimRuns {
        sim: &sim,
        runtime,
        started,
        budget: options.budget,
        bar: spinner(progress),
        path,
    };
    let settings = Settings {
        runs: options.runs,
        seed: options.seed,
        test_index: sim.test.map(|t| t.test_index),
        margin_m: options.margin,
    };
    let shrunk = campaign::shrink::shrink(case, scenario, &settings, &mut driver);
    driver.bar.finish_and_clear();
    let _ = std::fs::remove_dir_all(&sim.scratch);
    let shrunk = shrunk.map_err(|failure| match failure {
        ShrinkFailure::Drive(error) => error,
        failure @ ShrinkFailure::NotReproducible { .. } => anyhow::Error::new(NotReproduced {
            case: path.to_owned(),
            reason: failure.to_string(),
        }),
        ShrinkFailure::Shrinker(error) => {
            anyhow::Error::new(error).context(format!("{}: cannot be shrunk", path.display()))
        }
    })?;
    let minimal_file = out.join(MINIMAL_FILE);
    runner::atomic::write(&minimal_file, format!("{}\n", shrunk.minimal.to_json()?))
        .with_context(|| format!("cannot write {}", minimal_file.display()))?;
    let report = ShrinkReport {
        header: Header::current(SHRINK_FORMAT, SHRINK_SCHEMA_VERSION),
        case: path.display().to_string(),
        scenario: ScenarioRef::of(scenario),
        seed: options.seed,
        runs_per_candidate: options.runs,
        min_deviation_m: shrunk.min_deviation_m,
        ended: shrunk.ended,
        before: shrunk.before,
        after: shrunk.after,
        without_faults: shrunk.without_faults,
        confirmation: shrunk.confirmation,
        steps: shrunk.steps,
        simulator_runs: shrunk.runs_driven,
        wall_s: started.elapsed().as_secs_f64(),
        replay_on_car: format!(
            "drivecheck replay {} --car tcp://HOST:PORT",
            minimal_file.display()
        ),
    };
    let file = out.join(SHRINK_FILE);
    runner::atomic::write(&file, format!("{}\n", report.to_json()?))
        .with_context(|| format!("cannot write {}", file.display()))?;
    Ok(report)
}

/// The shrink's runs, each on a fresh embedded simulator, unrecorded; its stop (interrupt,
/// budget) and its progress line.
struct SimRuns<'a> {
    sim: &'a SimDriver<'a>,
    runtime: &'a Runtime,
    started: Instant,
    budget: Duration,
    bar: ProgressBar,
    path: &'a Path,
}

impl Drive for SimRuns<'_> {
    type Error = anyhow::Error;

    fn drive(&mut self, case: &Case, seed: u64) -> Result<Case> {
        let plan = self.sim.plan(case)?;
        Ok(self
            .runtime
            .block_on(self.sim.drive_once(&plan, seed, &SimSettings::default()))?)
    }

    fn stop(&mut self) -> Option<Ended> {
        if self.sim.cancel.is_cancelled() {
            Some(Ended::Interrupted)
        } else if self.started.elapsed() > self.budget {
            Some(Ended::Budget)
        } else {
            None
        }
    }

    fn progress(&mut self, now: Progress<'_>) {
        self.bar.set_message(match now {
            Progress::Reproducing => {
                format!("driving {} to confirm its failure", self.path.display())
            }
            Progress::Candidate {
                step,
                edit,
                commands,
            } => format!("step {step}: {edit} ({commands} commands now)"),
            Progress::Confirming { runs } => {
                format!("confirming the minimal case with {runs} other seeds")
            }
            Progress::WithoutFaults => "driving the minimal case without its faults".to_owned(),
        });
    }
}

fn spinner(show: bool) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = output::bar(None);
    if let Ok(style) = ProgressStyle::with_template("{elapsed_precise} {spinner} {msg}") {
        bar.set_style(style);
    }
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}
