//! `drivecheck route generate`: extend the start route with generated, margin-proven extensions.

use anyhow::{Context, Result, ensure};
use rand::RngExt;
use scenarios::Interval;
use serde::Serialize;
use trajgen::{ExtensionStats, Generator, Point, RouteTail};

use crate::cli::GenerateArgs;
use crate::exit::Exit;
use crate::output;
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
pub fn generate(args: &GenerateArgs) -> Result<Exit> {
    let loaded = load_scenario(args.scenario.name())?;
    print_warnings(args.scenario.name(), &loaded);
    let scenario = &loaded.scenario;
    let seed = choose_seed(args.seed);
    output::note(format_args!("seed {seed}"));
    let speed_kmh = args.speed_kmh.unwrap_or(scenario.campaign.speed_kmh.min);
    let top_kmh = scenarios::MAX_SPEED_KMH;
    ensure!(
        speed_kmh.is_finite() && speed_kmh > 0.0 && speed_kmh <= top_kmh,
        "--speed-kmh must be more than 0 and at most {top_kmh} km/h (the autopilot's top speed), \
         got {speed_kmh}"
    );
    let speed_mps = speed_kmh / 3.6;
    let generator = Generator::new(scenario.generator.generator_config(args.strategy.into()))?;
    let start_route = scenario.start_route.positions();
    let mut tail = RouteTail::from_points(&start_route)
        .context("the scenario's start route cannot be extended")?;
    let sizes = scenario.campaign.points_per_segment;
    let mut rng = rng(seed);
    let mut points: Vec<Point> = Vec::with_capacity(args.points);
    let mut stats = RouteStats::default();
    while points.len() < args.points {
        let n = extension_size(args.points - points.len(), sizes, &mut rng);
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
        output::print_json(output::json::ROUTE_GENERATE, &route)?;
    } else {
        print_route(&route);
    }
    Ok(Exit::Success)
}

/// The size of the next extension when `remaining` points are still to come: drawn within
/// `sizes`, but never leaving fewer than `sizes.min` for the last one, so that every extension
/// is within `sizes` whenever the total can be split that way (with the default 4–7, any total
/// of at least 4). A total below `sizes.min` is one short extension.
fn extension_size<R: rand::Rng + ?Sized>(
    remaining: usize,
    sizes: Interval<usize>,
    rng: &mut R,
) -> usize {
    if remaining <= sizes.max {
        return remaining;
    }
    let highest = sizes.max.min(remaining - sizes.min);
    if highest < sizes.min {
        // No split keeps every extension within the sizes: the last one comes out short.
        return sizes.max;
    }
    rng.random_range(sizes.min..=highest)
}

fn print_route(route: &GeneratedRoute) {
    println!(
        "{} (seed {}): {} points after the {}-point start route, {} extensions, speed {:.2} m/s",
        route.scenario,
        route.seed,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::seed::rng;

    fn split(total: usize, min: usize, max: usize, seed: u64) -> Vec<usize> {
        let (mut rng, mut left, mut sizes) = (rng(seed), total, Vec::new());
        while left > 0 {
            let n = extension_size(left, Interval { min, max }, &mut rng);
            sizes.push(n);
            left -= n;
        }
        sizes
    }

    #[test]
    fn every_extension_has_4_to_7_points_for_any_total_of_at_least_4() {
        for total in 4..200 {
            for seed in 0..20 {
                let sizes = split(total, 4, 7, seed);
                assert_eq!(sizes.iter().sum::<usize>(), total);
                assert!(
                    sizes.iter().all(|n| (4..=7).contains(n)),
                    "{total}: {sizes:?}"
                );
            }
        }
    }

    #[test]
    fn a_total_below_the_smallest_size_is_one_extension() {
        assert_eq!(split(3, 4, 7, 1), vec![3]);
    }
}
