//! `drivecheck route generate`: extend the start route with generated, margin-proven extensions.

use std::process::ExitCode;

use anyhow::{Context, Result, ensure};
use rand::RngExt;
use serde::Serialize;
use trajgen::{ExtensionStats, Generator, Point, RouteTail};

use crate::cli::GenerateArgs;
use crate::scenario_arg::{load_scenario, print_warnings};
use crate::seed::{choose_seed, rng};

/// What `route generate --json` prints.
#[derive(Debug, Serialize)]
struct GeneratedRoute {
    scenario: String,
    seed: u64,
    speed_mps: f64,
    start_route: Vec<[f64; 2]>,
    points: Vec<[f64; 2]>,
    stats: RouteStats,
}

/// Totals over the extensions of one generated route.
#[derive(Debug, Default, Serialize)]
struct RouteStats {
    extensions: u64,
    extension_sizes: Vec<usize>,
    outer_tries_total: u64,
    outer_tries_max: u32,
    inner_tries: u64,
    samples: u64,
    backtracks: u64,
}

impl RouteStats {
    fn add(&mut self, size: usize, stats: &ExtensionStats) {
        self.extensions += 1;
        self.extension_sizes.push(size);
        self.outer_tries_total += u64::from(stats.outer_tries);
        self.outer_tries_max = self.outer_tries_max.max(stats.outer_tries);
        self.inner_tries += stats.inner_tries;
        self.samples += stats.samples;
        self.backtracks += stats.backtracks;
    }
}

/// Generates `--points` points after the start route, in extensions of the scenario's size.
pub fn generate(args: &GenerateArgs) -> Result<ExitCode> {
    let loaded = load_scenario(&args.scenario)?;
    print_warnings(&loaded);
    let scenario = &loaded.scenario;
    let seed = choose_seed(args.seed);
    eprintln!("seed {seed}");
    let speed_mps = args.speed.unwrap_or(scenario.campaign.speed_kmh.min / 3.6);
    ensure!(
        speed_mps.is_finite() && speed_mps > 0.0,
        "--speed must be a positive number of m/s, got {speed_mps}"
    );
    let generator = Generator::new(scenario.generator.generator_config(args.strategy.into()))?;
    let start_route = scenario.start_route.positions();
    let mut tail = RouteTail::from_points(&start_route)
        .context("the scenario's start route cannot be extended")?;
    let sizes = scenario.campaign.points_per_segment;
    let mut rng = rng(seed);
    let mut points: Vec<Point> = Vec::with_capacity(args.points);
    let mut stats = RouteStats::default();
    while points.len() < args.points {
        let n = rng
            .random_range(sizes.min..=sizes.max)
            .min(args.points - points.len());
        let extension = generator
            .extend(&scenario.area, &tail, n, &mut rng)
            .with_context(|| format!("extension {} failed", stats.extensions + 1))?;
        stats.add(n, &extension.stats);
        points.extend_from_slice(&extension.points);
        tail = extension.next_tail;
    }
    let route = GeneratedRoute {
        scenario: scenario.name.clone(),
        seed,
        speed_mps,
        start_route: start_route.iter().map(|&p| p.into()).collect(),
        points: points.iter().map(|&p| p.into()).collect(),
        stats,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&route)?);
    } else {
        print_route(&route);
    }
    Ok(ExitCode::SUCCESS)
}

fn print_route(route: &GeneratedRoute) {
    println!(
        "{}: {} points after the {}-point start route, {} extensions, speed {:.2} m/s",
        route.scenario,
        route.points.len(),
        route.start_route.len(),
        route.stats.extensions,
        route.speed_mps
    );
    for [x, y] in &route.points {
        println!("{x:10.3} {y:10.3}");
    }
    println!(
        "outer tries: total {}, max {}; inner tries {}; backtracks {}",
        route.stats.outer_tries_total,
        route.stats.outer_tries_max,
        route.stats.inner_tries,
        route.stats.backtracks
    );
}
