//! `drivecheck run`: a test campaign against the embedded simulated car (in virtual time by
//! default, or against the wall clock) or a car behind TCP, UDP or a serial port.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use car_link::firmware::{MAX_STALE_LIMIT, WATCHDOG};
use car_link::{Car, CarAddress, LinkConfig};
use indicatif::{ProgressBar, ProgressStyle};
use scenarios::Scenario;
use tokio_util::sync::CancellationToken;

use crate::cli::{OnFailure, RunArgs};
use crate::runner::{CampaignReport, RunConfig, RunError, run_campaign, run_dir_name};
use crate::scenario_arg::{load_scenario, print_warnings};
use crate::seed::choose_seed;
use campaign::model::Campaign;
use campaign::oracle::{FailurePolicy, Verdict};

/// Runs the campaign and prints the final table. Exit status: 0 every test passed, 1 a test
/// failed or was aborted, 2 an error (preflight refused, link lost, interrupted, …).
pub fn run(args: &RunArgs) -> Result<ExitCode> {
    let loaded = load_scenario(&args.scenario)?;
    print_warnings(&loaded);
    let scenario = loaded.scenario;
    let address: CarAddress = args
        .car
        .parse()
        .with_context(|| format!("--car {}", args.car))?;
    let seed = choose_seed(args.seed);
    let campaign = Campaign {
        seed,
        tests: args.tests.unwrap_or(scenario.campaign.tests),
        no_faults: args.no_faults,
    };
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(run_dir_name(&scenario.name, seed)));
    let mut config = RunConfig::new(campaign, out, args.car.clone());
    if args.stale_after.is_zero() || args.stale_after > MAX_STALE_LIMIT {
        anyhow::bail!(
            "--stale-after {}: must be above 0 and at most {} (the car's watchdog brakes after {} \
             without commands)",
            humantime::format_duration(args.stale_after),
            humantime::format_duration(MAX_STALE_LIMIT),
            humantime::format_duration(WATCHDOG),
        );
    }
    config.safety.stale_after = args.stale_after;
    config.policy = match args.on_failure {
        OnFailure::Stop => FailurePolicy::StopAtFailingSegment,
        OnFailure::Continue => FailurePolicy::ContinueAndRecord,
    };
    let virtual_time = address == CarAddress::Sim && !args.realtime;
    eprintln!(
        "seed {seed}: {} tests on {} with car {}{}, writing {}",
        campaign.tests,
        scenario.name,
        args.car,
        if virtual_time { " (virtual time)" } else { "" },
        config.out_dir.display()
    );
    let runtime = runtime(virtual_time)?;
    let started = Instant::now();
    let result = runtime.block_on(campaign_on(&address, &scenario, &config));
    let wall = started.elapsed();
    finish(result, wall)
}

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

/// How the runner talks to any car: round trips on a radio link can exceed the 250 ms default.
pub fn car_config() -> LinkConfig {
    LinkConfig {
        request_timeout: Duration::from_secs(1),
        terminal_timeout: Duration::from_secs(2),
        ..LinkConfig::default()
    }
}

/// Connects to the car (starting the embedded simulator for `sim`) and runs the campaign,
/// interrupted by Ctrl-C.
async fn campaign_on(
    address: &CarAddress,
    scenario: &Scenario,
    config: &RunConfig,
) -> Result<CampaignReport, anyhow::Error> {
    let (car, sim) = connect(address, scenario, config.campaign.seed).await?;
    let cancel = cancel_on_ctrl_c();
    let progress = progress_bar(config.campaign.tests);
    let result = run_campaign(&car, scenario, config, sim.as_ref(), &cancel, &progress).await;
    progress.finish_and_clear();
    result.map_err(|error| anyhow::Error::new(CampaignFailed::new(error, &config.out_dir)))
}

/// The car at `address`; for `sim` a fresh embedded simulated car seeded with `seed`, with its
/// handle.
pub(super) async fn connect(
    address: &CarAddress,
    scenario: &Scenario,
    seed: u64,
) -> Result<(Car, Option<car_sim::SimHandle>)> {
    if *address != CarAddress::Sim {
        let car = Car::connect(address, car_config())
            .await
            .with_context(|| format!("cannot connect to the car at {address}"))?;
        return Ok((car, None));
    }
    let sim_config = car_sim::SimConfig {
        seed,
        ..car_sim::SimConfig::from_scenario(scenario)
    };
    let (stream, sim) = car_sim::spawn_in_process(&sim_config);
    let car = Car::over_stream(stream, car_config())
        .await
        .context("cannot connect to the embedded simulated car")?;
    Ok((car, Some(sim)))
}

/// A token cancelled when the operator presses Ctrl-C (the runner then stops the car safely).
/// Call it inside the runtime.
pub(super) fn cancel_on_ctrl_c() -> CancellationToken {
    let cancel = CancellationToken::new();
    let on_ctrl_c = cancel.clone();
    tokio::spawn(async move {
        if tokio::signal::ctrl_c().await.is_ok() {
            eprintln!("interrupted: stopping the car safely");
            on_ctrl_c.cancel();
        }
    });
    cancel
}

pub(super) fn progress_bar(tests: usize) -> ProgressBar {
    let bar = ProgressBar::new(tests as u64);
    if let Ok(style) =
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} tests  {msg}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// A campaign that did not run to its end, with where its record is.
#[derive(Debug, thiserror::Error)]
#[error("{error} (run directory {})", dir.display())]
pub(super) struct CampaignFailed {
    error: RunError,
    dir: PathBuf,
}

impl CampaignFailed {
    pub(super) fn new(error: RunError, dir: &std::path::Path) -> Self {
        Self {
            error,
            dir: dir.to_owned(),
        }
    }
}

fn finish(result: Result<CampaignReport>, wall: Duration) -> Result<ExitCode> {
    let report = result?;
    print_report(&report, Some(wall));
    let summary = report.record.summary.as_ref();
    let all_passed = summary.is_some_and(|s| s.passed == s.tests && s.tests > 0);
    Ok(if all_passed {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// Prints a campaign's table of tests and its summary (with the wall time when known).
pub(super) fn print_report(report: &CampaignReport, wall: Option<Duration>) {
    println!("| test | verdict | worst deviation | starvations | smallest margin | reason |");
    println!("|---|---|---|---|---|---|");
    for t in &report.tests {
        println!(
            "| {} | {} | {} | {} | {} | {} |",
            t.test_index,
            t.verdict.map_or("not run", Verdict::as_str),
            metres(t.worst_deviation_m),
            t.starvations,
            t.smallest_margin_s
                .map_or_else(|| "-".to_owned(), |m| format!("{m:.2} s")),
            t.reason.as_deref().unwrap_or("")
        );
    }
    let Some(s) = &report.record.summary else {
        return;
    };
    println!();
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
    for file in &s.failing_cases {
        println!("  {}", report.dir.join(file).display());
    }
    println!("run directory: {}", report.dir.display());
}

pub(super) fn metres(value: Option<f64>) -> String {
    value.map_or_else(|| "-".to_owned(), |m| format!("{m:.2} m"))
}
