//! `drivecheck-dev bench placement`: how close to its place on the route each fault is added over a
//! slow, jittery link (`docs/case-format.md`, "Where a fault acts over a slow link").
//!
//! For each firmware generation, campaign seed and link seed, a campaign on fresh embedded
//! simulated cars in virtual time, each behind the simulator's own impaired link (one-way latency
//! plus a uniform jitter, order kept, as `drivecheck sim --link-latency … --link-jitter …`
//! serves it), every test driven to its end (`--on-failure continue`), unrecorded. Every fault
//! the cars added gives one placement error (`fault_places[].error_m` of the case files: where the
//! car was when it added the fault, less the place). The table gives their distribution.

use anyhow::{Result, bail};
use car_link::firmware::FirmwareVersion;
use car_sim::LinkImpairment;
use tokio_util::sync::CancellationToken;

use crate::cli::BenchPlacementArgs;
use campaign::model::Campaign;
use campaign::oracle::FailurePolicy;
use campaign::seed::Purpose;
use orchestrator::commands::scratch::Scratch;
use orchestrator::commands::signals::runtime;
use orchestrator::exit::Exit;
use runner::vehicle::EmbeddedSims;
use runner::{RecordMode, RunConfig, Silent, run_campaign_fresh};

/// The error the issue of anchored faults allows, metres.
const WITHIN_M: f64 = 0.2;

/// Placement errors of one firmware generation, metres (signed: positive past the place).
struct Errors {
    firmware: FirmwareVersion,
    errors: Vec<f64>,
    /// Faults the cars added whose place could not be measured (no sample came after).
    unmeasured: usize,
}

impl Errors {
    fn row(&self) -> String {
        let mut abs: Vec<f64> = self.errors.iter().map(|e| e.abs()).collect();
        abs.sort_by(f64::total_cmp);
        let q = |q| trajgen::stats::nearest_rank(&abs, q).unwrap_or(f64::NAN);
        let within = |m: f64| abs.iter().filter(|&&e| e <= m).count();
        let mean = self.errors.iter().sum::<f64>() / self.errors.len().max(1) as f64;
        format!(
            "| {} | {} | {} | {} | {} | {:.3} | {:.3} | {:.3} | {:+.3} |",
            self.firmware,
            abs.len(),
            self.unmeasured,
            within(0.1),
            within(WITHIN_M),
            q(0.5),
            q(0.95),
            abs.last().copied().unwrap_or(f64::NAN),
            mean
        )
    }
}

/// Runs the benchmark and prints its table.
pub fn run(args: &BenchPlacementArgs) -> Result<Exit> {
    let loaded = orchestrator::scenario_arg::load_scenario(&args.scenario)?;
    let scenario = loaded.scenario;
    let firmwares: Vec<FirmwareVersion> = match args.firmware.as_str() {
        "both" => FirmwareVersion::SIMULATED.to_vec(),
        one => match car_sim::simulated_firmware(one) {
            Ok(firmware) => vec![firmware],
            Err(error) => bail!("--firmware {one}: {error} (or `both`)"),
        },
    };
    let link = LinkImpairment {
        latency: args.link_latency,
        jitter: args.link_jitter,
        ..LinkImpairment::default()
    };
    let runtime_guard = runtime(true)?;
    let _context = runtime_guard.enter();
    let scratch = Scratch::new("placement", "runs")?;
    let mut rows = Vec::new();
    for &firmware in &firmwares {
        let mut errors = Errors {
            firmware,
            errors: Vec::new(),
            unmeasured: 0,
        };
        for seed in args.seed..args.seed + u64::from(args.seeds) {
            for link_seed in 1..=u64::from(args.link_seeds) {
                let mut config = RunConfig::new(
                    Campaign {
                        seed,
                        tests: args.tests as usize,
                        no_faults: false,
                    },
                    scratch.0.join(format!("{firmware}-{seed}-{link_seed}")),
                    "sim",
                );
                config.policy = FailurePolicy::ContinueAndRecord;
                config.record = RecordMode::None;
                let sim = car_sim::SimConfig {
                    firmware,
                    link,
                    // The link's draws differ per link seed, the car's per test (as `run`).
                    seed: campaign::seed::derive(seed, Purpose::PlacementSim { link_seed }),
                    ..car_sim::SimConfig::from_scenario(&scenario)
                };
                let cars = EmbeddedSims::with_config(sim, true);
                let report = run_campaign_fresh(
                    &cars,
                    &scenario,
                    &config,
                    1,
                    &CancellationToken::new(),
                    &Silent,
                )
                .map_err(|failure| anyhow::anyhow!("{}", failure.error))?;
                for case in report.cases() {
                    for place in &case?.fault_places {
                        match place.error_m {
                            Some(error) => errors.errors.push(error),
                            None => errors.unmeasured += 1,
                        }
                    }
                }
            }
        }
        rows.push(errors);
    }
    println!(
        "## Fault placement on {}: {} campaign seeds from {} × {} link seeds, {} tests each, one-way latency {:?} + up to {:?}\n",
        scenario.name,
        args.seeds,
        args.seed,
        args.link_seeds,
        args.tests,
        args.link_latency,
        args.link_jitter
    );
    println!(
        "| firmware | faults | unmeasured | within 0.1 m | within {WITHIN_M} m | median \\|error\\| | p95 | largest | mean (signed) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for row in &rows {
        println!("{}", row.row());
    }
    Ok(Exit::Success)
}
