//! `drivecheck area validate`: one long generated trajectory through the area, and a verdict.

use std::time::Instant;

use anyhow::{Context, Result, ensure};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use trajgen::{AreaVerdict, ValidationConfig, ValidationReport, validate_area};

use crate::cli::ValidateArgs;
use crate::exit::Exit;
use crate::output;
use crate::scenario_arg::{load_scenario, print_warnings};
use crate::seed::{choose_seed, rng};
use report::svg::area_picture;

/// Points per extension during validation (`docs/method.md#validating-an-area`).
const VALIDATION_EXTENSION_POINTS: usize = 5;

/// What `area validate --json` prints.
#[derive(Debug, Serialize)]
struct ValidationSummary {
    scenario: String,
    seed: u64,
    strategy: String,
    verdict: String,
    km: f64,
    target_km: f64,
    completed: bool,
    extensions: u64,
    failures: u64,
    max_outer_tries: u32,
    mean_outer_tries: f64,
    p99_outer_tries: u32,
    outer_tries_limit: u32,
    wall_s: f64,
    coverage: f64,
    hotspots: Vec<HotSpotSummary>,
}

#[derive(Debug, Serialize)]
struct HotSpotSummary {
    x: f64,
    y: f64,
    /// Outer tries of the hardest extension there (the limit for a failure).
    tries: u32,
    /// Candidate points drawn for that extension: the effort where outer tries stay at 1.
    inner_tries: u64,
    failures: u32,
}

/// Below this share of drivable cells visited, the report points out the parts never driven.
const LOW_COVERAGE: f64 = 0.9;

/// Validates the area and exits 0 when safe, 1 when unsafe.
pub fn validate(args: &ValidateArgs) -> Result<Exit> {
    ensure!(
        args.km.is_finite() && args.km > 0.0,
        "--km must be a positive number, got {}",
        args.km
    );
    let loaded = load_scenario(args.scenario.name())?;
    print_warnings(args.scenario.name(), &loaded);
    let scenario = &loaded.scenario;
    let seed = choose_seed(args.seed);
    output::note(format_args!("seed {seed}"));
    let mut config = ValidationConfig::default()
        .with_km(args.km)
        .with_generator(scenario.generator.generator_config(args.strategy.into()));
    config.extension_points = VALIDATION_EXTENSION_POINTS;

    let bar = progress_bar(args.km);
    let started = Instant::now();
    let report = validate_area(
        &scenario.area,
        &scenario.start_route.positions(),
        &config,
        &mut rng(seed),
        &mut |progress| {
            bar.set_position((progress.km * 1000.0) as u64);
            bar.set_message(format!(
                "failures {}  max outer tries {}",
                progress.failures, progress.max_outer_tries
            ));
        },
    )
    .context("validation could not run")?;
    let wall_s = started.elapsed().as_secs_f64();
    bar.finish_and_clear();

    if let Some(path) = &args.svg {
        runner::atomic::write(path, area_picture(scenario, &report))
            .with_context(|| format!("cannot write {}", path.display()))?;
        output::note(format_args!("wrote {}", path.display()));
    }
    let summary = summarise(&scenario.name, seed, args, &report, wall_s);
    if args.json {
        output::print_json(output::json::AREA_VALIDATE, &summary)?;
    } else {
        print_summary(&summary);
    }
    Ok(match report.verdict {
        AreaVerdict::Safe => Exit::Success,
        AreaVerdict::Unsafe => Exit::Found,
    })
}

fn progress_bar(km: f64) -> ProgressBar {
    let bar = output::bar(Some((km * 1000.0) as u64));
    if let Ok(style) =
        ProgressStyle::with_template("{bar:40} {pos:>7}/{len:7} m  {elapsed_precise}  {msg}")
    {
        bar.set_style(style);
    }
    bar
}

fn summarise(
    scenario: &str,
    seed: u64,
    args: &ValidateArgs,
    report: &ValidationReport,
    wall_s: f64,
) -> ValidationSummary {
    ValidationSummary {
        scenario: scenario.to_owned(),
        seed,
        strategy: format!("{:?}", args.strategy).to_lowercase(),
        verdict: report.verdict.as_str().to_owned(),
        km: report.km,
        target_km: report.target_km,
        completed: report.completed,
        extensions: report.extensions,
        failures: report.failures,
        max_outer_tries: report.max_outer_tries,
        mean_outer_tries: report.mean_outer_tries,
        p99_outer_tries: report.p99_outer_tries,
        outer_tries_limit: report.outer_tries_limit,
        wall_s,
        coverage: report.coverage,
        hotspots: report
            .hotspots
            .iter()
            .map(|h| HotSpotSummary {
                x: h.x,
                y: h.y,
                tries: h.outer_tries,
                inner_tries: h.inner_tries,
                failures: h.failures,
            })
            .collect(),
    }
}

fn print_summary(s: &ValidationSummary) {
    println!(
        "area {} (seed {}, strategy {})",
        s.scenario, s.seed, s.strategy
    );
    println!(
        "  driven      {:.3} km of {} km{}",
        s.km,
        s.target_km,
        if s.completed { "" } else { " (stopped early)" }
    );
    println!("  extensions  {}   failures {}", s.extensions, s.failures);
    println!(
        "  outer tries max {} (limit {}, safe at ≤ {}), mean {:.2}, p99 {}",
        s.max_outer_tries,
        s.outer_tries_limit,
        s.outer_tries_limit / 2,
        s.mean_outer_tries,
        s.p99_outer_tries
    );
    println!(
        "  coverage    {:.1} % of the drivable 0.5 m cells",
        s.coverage * 100.0
    );
    if s.coverage < LOW_COVERAGE {
        println!(
            "  note: parts of the area were never driven (grey in the --out picture); the generator avoids \
             places too narrow to turn around in"
        );
    }
    println!("  wall time   {:.2} s", s.wall_s);
    if !s.hotspots.is_empty() {
        println!("  hot spots (worst first):");
        for h in &s.hotspots {
            println!(
                "    ({:8.2}, {:8.2})  {:5} outer tries  {:6} inner tries  {} failure(s)",
                h.x, h.y, h.tries, h.inner_tries, h.failures
            );
        }
    }
    println!("verdict: {}", s.verdict);
}
