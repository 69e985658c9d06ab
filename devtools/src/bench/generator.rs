//! `drivecheck-dev bench generator`: both generator strategies side by side on every bundled area.
//!
//! For each area and strategy: the time of one extension (4–7 points plus the ahead margin, from
//! a continuous route) at p50/p99/max, mean and max outer tries, failures, and the wall time of a
//! validation run. Run it in release mode; the machine's noise is part of the figures, so compare
//! strategies measured in the same run.

use std::time::{Duration, Instant};

use anyhow::{Result, ensure};
use rand::RngExt;
use scenarios::Scenario;
use trajgen::{Generator, Strategy, ValidationConfig, validate_area};

use crate::cli::BenchGeneratorArgs;
use orchestrator::exit::Exit;
use orchestrator::seed::rng;

/// One row of the table.
struct Row {
    area: String,
    strategy: Strategy,
    p50: Duration,
    p99: Duration,
    max: Duration,
    mean_outer_tries: f64,
    max_outer_tries: u32,
    failures: u64,
    validation: Duration,
    validation_km: f64,
    verdict: String,
}

/// Runs the benchmark and prints a Markdown table.
pub fn generator(args: &BenchGeneratorArgs) -> Result<Exit> {
    if let Some(clearance) = args.clearance {
        ensure!(
            clearance.is_finite() && clearance >= 0.0,
            "--clearance must be a distance of 0 m or more, not {clearance}"
        );
    }
    println!(
        "| area | strategy | p50 | p99 | max | mean outer tries | max outer tries | failures | {} km validation | verdict |",
        args.km
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for name in scenarios::bundled::names() {
        let mut scenario = scenarios::bundled::load(name)?.scenario;
        if let Some(clearance) = args.clearance {
            scenario.generator.clearance_m = clearance;
        }
        for strategy in [Strategy::Reference, Strategy::Wedge] {
            let row = measure(&scenario, strategy, args)?;
            print_row(&row);
        }
    }
    Ok(Exit::Success)
}

fn measure(scenario: &Scenario, strategy: Strategy, args: &BenchGeneratorArgs) -> Result<Row> {
    let config = scenario.generator.generator_config(strategy);
    let generator = Generator::new(config)?;
    let sizes = scenario.campaign.points_per_segment;
    let mut rng = rng(args.seed);
    let start = campaign::model::start_tail(scenario)?;
    let mut tail = start;
    let mut times = Vec::with_capacity(args.extensions);
    let (mut tries_sum, mut tries_max, mut failures) = (0u64, 0u32, 0u64);
    for _ in 0..args.extensions {
        let n = rng.random_range(sizes.min..=sizes.max);
        let started = Instant::now();
        let result = generator.extend(&scenario.area, &tail, n, &mut rng);
        times.push(started.elapsed());
        match result {
            Ok(extension) => {
                tries_sum += u64::from(extension.stats.outer_tries);
                tries_max = tries_max.max(extension.stats.outer_tries);
                tail = extension.next_tail;
            }
            Err(_) => {
                // A failed extension used every outer try; start again from the start route.
                failures += 1;
                tries_sum += u64::from(config.outer_tries);
                tries_max = config.outer_tries;
                tail = start;
            }
        }
    }
    times.sort_unstable();
    let validation_config = ValidationConfig::default()
        .with_km(args.km)
        .with_generator(config);
    let started = Instant::now();
    let report = validate_area(
        &scenario.area,
        &scenario.start_route.positions(),
        &validation_config,
        &mut rng,
        &mut |_| {},
    )?;
    let validation = started.elapsed();
    Ok(Row {
        area: scenario.name.clone(),
        strategy,
        p50: percentile(&times, 0.50),
        p99: percentile(&times, 0.99),
        max: times.last().copied().unwrap_or_default(),
        mean_outer_tries: tries_sum as f64 / args.extensions.max(1) as f64,
        max_outer_tries: tries_max,
        failures,
        validation,
        validation_km: report.km,
        verdict: report.verdict.as_str().to_owned(),
    })
}

/// The `q`-quantile of sorted durations (nearest rank); zero for none.
pub(super) fn percentile(sorted: &[Duration], q: f64) -> Duration {
    trajgen::stats::nearest_rank(sorted, q).unwrap_or_default()
}

fn print_row(row: &Row) {
    let ms = |d: Duration| format!("{:.3} ms", d.as_secs_f64() * 1e3);
    println!(
        "| {} | {:?} | {} | {} | {} | {:.2} | {} | {} | {:.2} s ({:.1} km) | {} |",
        row.area,
        row.strategy,
        ms(row.p50),
        ms(row.p99),
        ms(row.max),
        row.mean_outer_tries,
        row.max_outer_tries,
        row.failures,
        row.validation.as_secs_f64(),
        row.validation_km,
        row.verdict
    );
}
