//! `drivecheck explain CASE.json|RUN_DIR`: why segments failed ([`report::explain`],
//! the method in `campaign::explain`); with `--score`, how right that is against the simulated
//! car's hidden truth.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result, bail};

use super::case_input::read_case as read_case_file;
use super::signals::{cancel_on_ctrl_c, runtime};
use crate::cli::ExplainArgs;
use crate::exit::Exit;
use crate::output;
use crate::profile_arg::LoadedProfile;
use crate::scenario_arg::optional_scenario;
use campaign::case::Case;
use campaign::explain::counterfactual::settle;
use campaign::explain::score::SegmentScore;
use campaign::explain::{Cause, Source};
use report::explain::{
    CaseExplanation, ExplainOptions, Explanations, Scored, calibrate, describe, explain_run,
    score_run,
};
use runner::simdrive::{SimDriver, SimSettings};

/// Explains the target's failing segments (see the module doc). Exit status 0, or 2 on an error.
pub fn explain(args: &ExplainArgs) -> Result<Exit> {
    let scenario = optional_scenario(args.scenario.as_deref())?;
    let (dir, only) = if args.target.is_dir() {
        (args.target.clone(), None)
    } else if args.target.is_file() {
        let dir = args
            .target
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
            .to_owned();
        (dir, Some(args.target.as_path()))
    } else {
        bail!(
            "{}: no such case file or run directory",
            args.target.display()
        );
    };
    if args.calibrate {
        if only.is_some() {
            bail!("--calibrate takes a fault-free run directory");
        }
        if !(args.budget > 0.0 && args.budget < 1.0) {
            bail!("--budget {}: must be between 0 and 1", args.budget);
        }
        let c = calibrate(&dir, scenario.as_ref(), args.budget)
            .with_context(|| format!("cannot calibrate on {}", dir.display()))?;
        if args.json {
            output::print_json(output::json::EXPLAIN_CALIBRATE, &c)?;
        } else {
            println!(
                "{} samples and {} segments of a fault-free run, false-alarm budget {:.1} %:\n\
                 --nominal {:.3} --min-growth {:.3}",
                c.samples,
                c.segments,
                c.budget * 100.0,
                c.nominal_m,
                c.min_growth_m
            );
        }
        return Ok(Exit::Success);
    }
    let mut options = ExplainOptions {
        all_segments: args.all_segments,
        ..ExplainOptions::default()
    };
    for (value, name) in [
        (args.nominal, "--nominal"),
        (args.min_growth, "--min-growth"),
    ] {
        if value.is_some_and(|v| !(v.is_finite() && v >= 0.0)) {
            bail!("{name}: must be a length in metres, 0 or more");
        }
    }
    if let Some(nominal) = args.nominal {
        options.config.nominal_m = nominal;
    }
    if let Some(min_growth) = args.min_growth {
        options.config.min_growth_m = min_growth;
    }
    if args.score {
        if only.is_some() {
            bail!("--score takes a run directory (every failing segment of the run is scored)");
        }
        let mut explanations = Explanations {
            cases: Vec::new(),
            notes: Vec::new(),
        };
        let profile = crate::profile_arg::load(args.profile.as_deref())?;
        let firmware = if args.counterfactual_runs > 0 {
            super::firmware::fresh_car("explain --score", &args.car)?
        } else {
            None
        };
        let mut scored = Vec::new();
        for run in run_dirs(&dir) {
            let (e, mut s, recorded_in) = score_run(&run, scenario.as_ref(), &options)
                .with_context(|| format!("cannot score {}", run.display()))?;
            if args.counterfactual_runs > 0 {
                counterfactual(
                    recorded_in.as_ref(),
                    &mut s,
                    args.counterfactual_runs,
                    (&profile, firmware.as_ref()),
                )
                .with_context(|| format!("cannot drive the cases of {} again", run.display()))?;
            }
            explanations.cases.extend(e.cases);
            explanations.notes.extend(e.notes);
            scored.extend(s);
        }
        if args.json {
            let out = serde_json::json!({ "cases": explanations.cases, "scored": scored });
            output::print_json(output::json::EXPLAIN_SCORE, &out)?;
        } else {
            print!("{}", score_table(&scored));
        }
        return Ok(Exit::Success);
    }
    let mut explanations = Explanations {
        cases: Vec::new(),
        notes: Vec::new(),
    };
    for run in run_dirs(&dir) {
        let e = explain_run(&run, only, scenario.as_ref(), &options)
            .with_context(|| format!("cannot explain {}", run.display()))?;
        explanations.cases.extend(e.cases);
        explanations.notes.extend(e.notes);
    }
    if args.json {
        output::print_json(output::json::EXPLAIN, &explanations)?;
    } else {
        print!("{}", text(&explanations));
    }
    Ok(Exit::Success)
}

/// Settles the truth of every scored segment in which several faults moved the estimate by a
/// counterfactual (the policy is `campaign::explain::counterfactual::settle`; this drives): its
/// case driven `runs` times as it was and as often without each of those faults, on fresh
/// embedded simulated cars in `scenario` (the run's own) in virtual time, seeds from the case's
/// campaign seed.
fn counterfactual(
    scenario: Option<&scenarios::Scenario>,
    scored: &mut [Scored],
    runs: u32,
    (profile, firmware): (&LoadedProfile, Option<&super::firmware::HostFirmware>),
) -> Result<()> {
    let pending: BTreeSet<std::path::PathBuf> = scored
        .iter()
        .filter(|s| s.score.needs_counterfactual())
        .map(|s| s.case.clone())
        .collect();
    if pending.is_empty() {
        return Ok(());
    }
    let scenario = scenario.context("the run's scenario is unknown (give --scenario)")?;
    output::progress(format_args!(
        "driving {} case(s) again without each fault that moved a failing segment's estimate ({runs} runs each)",
        pending.len()
    ));
    let sim = profile.sim_config(scenario)?;
    let scratch =
        std::env::temp_dir().join(format!("drivecheck-counterfactual-{}", std::process::id()));
    // A signal's second coming ends the process: the scratch directory goes with it.
    let _registered = runner::scratch::Scratch::register(&scratch);
    let runtime = runtime(true)?;
    let cancel = runtime.block_on(async { cancel_on_ctrl_c() });
    let result = pending.iter().enumerate().try_for_each(|(k, path)| {
        runner::pause_at("counterfactual", k);
        let case = read_case_file(path)?;
        let seed = case.campaign_seed.unwrap_or_default();
        let mut driver = SimDriver::new(
            (scenario, sim.clone()),
            path,
            &case,
            scratch.clone(),
            (runs, seed),
            &cancel,
        );
        driver.firmware = firmware.cloned();
        let settings = SimSettings::default();
        let mut of_case: Vec<&mut SegmentScore> = scored
            .iter_mut()
            .filter(|s| &s.case == path)
            .map(|s| &mut s.score)
            .collect();
        settle(&case, &mut of_case, |variant| {
            let driven = runtime.block_on(driver.drive_all(variant, &settings));
            // A run cut off by the signal is no run: nothing is settled with it.
            if cancel.is_cancelled() {
                return Err(super::signals::Interrupted(
                    "the counterfactual runs did not end; nothing was scored",
                )
                .into());
            }
            anyhow::Ok(driven?.into_iter().map(|(_, case)| case).collect())
        })
    });
    let _ = std::fs::remove_dir_all(&scratch);
    result
}

/// The run directories of `dir`: a replay directory's runs (`run-1/`, `run-2/`, … beside its
/// `replay.json`), else `dir` itself.
fn run_dirs(dir: &Path) -> Vec<std::path::PathBuf> {
    if !dir.join(campaign::replay::REPLAY_FILE).is_file() {
        return vec![dir.to_owned()];
    }
    let mut runs: Vec<(u32, std::path::PathBuf)> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter_map(|p| {
            let n = p
                .file_name()?
                .to_str()?
                .strip_prefix("run-")?
                .parse()
                .ok()?;
            p.join(runner::CAMPAIGN_FILE).is_file().then_some((n, p))
        })
        .collect();
    runs.sort();
    runs.into_iter().map(|(_, p)| p).collect()
}

/// The explanations as text: per segment, its growth and the causes in order.
fn text(explanations: &Explanations) -> String {
    let mut out = String::new();
    for case in &explanations.cases {
        let commands = read_case(case);
        for segment in &case.segments {
            let _ = writeln!(
                out,
                "{} segment {} ({}): |UWB − RTK| {:.2} → {:.2} m from {:.1} s to {:.1} s{}",
                case.case.display(),
                segment.segment_index,
                segment.verdict,
                segment.error_from_m,
                segment.error_to_m,
                segment.from_s,
                segment.to_s,
                if segment.carried_over {
                    " (carried over from before the segment)"
                } else {
                    ""
                }
            );
            // A passing segment (`--all-segments`) whose error was largest before it grew.
            if segment.causes.iter().all(|c| c.steps == 0) {
                out.push_str("  no growth to explain: the error did not grow up to its largest\n");
                continue;
            }
            for (k, cause) in segment.causes.iter().enumerate() {
                let _ = writeln!(
                    out,
                    "  {}. {} — {:.0} % of the growth ({:.2} m, {} step{}){}",
                    k + 1,
                    describe(&cause.source, commands.as_ref()),
                    cause.share * 100.0,
                    cause.growth_m,
                    cause.steps,
                    if cause.steps == 1 { "" } else { "s" },
                    ambiguity(cause, commands.as_ref())
                );
            }
        }
    }
    if explanations.cases.iter().all(|c| c.segments.is_empty()) {
        out.push_str("no failing segment to explain\n");
    }
    for note in &explanations.notes {
        let _ = writeln!(out, "note: {note}");
    }
    out
}

fn read_case(case: &CaseExplanation) -> Option<Case> {
    let text = std::fs::read_to_string(&case.case).ok()?;
    Case::from_json(&text).ok()
}

fn ambiguity(cause: &Cause, case: Option<&Case>) -> String {
    cause
        .ambiguous_with
        .map(|other| {
            format!(
                "; cannot always be told apart from {}",
                describe(&other, case)
            )
        })
        .unwrap_or_default()
}

/// The scores as text: per class of truth, what was named first; then the share right.
fn score_table(scored: &[Scored]) -> String {
    let scored: Vec<&SegmentScore> = scored.iter().map(|s| &s.score).collect();
    let named_class = |s: &SegmentScore| match s.named {
        Some(Source::Fault { .. }) if s.right => "that fault".to_owned(),
        Some(Source::Fault { .. }) => "another fault".to_owned(),
        Some(Source::Anchor { anchor_id }) => format!("anchor {anchor_id}"),
        Some(Source::Odometry) => "odometry".to_owned(),
        Some(Source::Heading) => "heading".to_owned(),
        Some(Source::Unexplained) | None => "unexplained".to_owned(),
    };
    let mut matrix: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    let mut columns: Vec<String> = Vec::new();
    for &s in &scored {
        let column = named_class(s);
        if !columns.contains(&column) {
            columns.push(column.clone());
        }
        *matrix
            .entry(s.truth_class.clone())
            .or_default()
            .entry(column)
            .or_default() += 1;
    }
    columns.sort();
    let mut out = String::new();
    let _ = writeln!(
        out,
        "| truth \\ named first | {} | right |",
        columns.join(" | ")
    );
    let _ = writeln!(out, "|---|{}---|", "---|".repeat(columns.len()));
    for (truth, row) in &matrix {
        let total: usize = row.values().sum();
        let right = scored
            .iter()
            .filter(|s| &s.truth_class == truth && s.right)
            .count();
        let cells: Vec<String> = columns
            .iter()
            .map(|c| row.get(c).copied().unwrap_or(0).to_string())
            .collect();
        let _ = writeln!(out, "| {truth} | {} | {right}/{total} |", cells.join(" | "));
    }
    let right = scored.iter().filter(|s| s.right).count();
    let _ = writeln!(
        out,
        "\n{} failing segments; the first cause named is the truth in {right} ({:.0} %)",
        scored.len(),
        100.0 * right as f64 / scored.len().max(1) as f64
    );
    out
}
