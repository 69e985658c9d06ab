//! Measures the generator and area validation on the four real areas (not a test; run with
//! `cargo run --release -p trajgen --example measure [-- --reference-km 10]`).
//!
//! Per area and strategy: time per extension (4–7 points + margin 20, chained from the start
//! route, 2000 extensions, seed 1) p50/p99/max, mean outer tries, failures; then the wall time of
//! a 100 km validation (the reference capped at `--reference-km`, default 10 km).

use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;
use trajgen::{
    Area, Generator, GeneratorConfig, Point, Polygon, RouteTail, Strategy, ValidationConfig,
    validate_area,
};

#[path = "../src/test_areas.rs"]
#[allow(dead_code)]
mod areas;

fn points(raw: &[[f64; 2]]) -> Vec<Point> {
    raw.iter().map(|&p| Point::from(p)).collect()
}

fn area(real: &areas::RealArea) -> Area {
    let fence = Polygon::new(points(real.fence)).expect("fence");
    let cutouts = real
        .cutouts
        .iter()
        .map(|c| Polygon::new(points(c)).expect("cutout"))
        .collect();
    Area::new(fence, cutouts).expect("area")
}

struct Figures {
    p50: f64,
    p99: f64,
    max: f64,
    mean_outer: f64,
    failures: usize,
    mean_turn: f64,
    mean_length: f64,
}

fn config(strategy: Strategy) -> GeneratorConfig {
    let mut c = GeneratorConfig::default().with_strategy(strategy);
    if let Ok(v) = std::env::var("LOOP_AFTER") {
        c.margin_loop_after = v.parse().ok();
    }
    if let Ok(v) = std::env::var("CANDIDATES") {
        c.margin_candidates = v.parse().unwrap();
    }
    c
}

fn extensions(area: &Area, start: &[Point], strategy: Strategy, count: usize) -> Figures {
    let generator = Generator::new(config(strategy)).unwrap();
    let mut rng = Pcg64Mcg::seed_from_u64(1);
    let start_tail = RouteTail::from_points(start).unwrap();
    let mut tail = start_tail;
    let mut times = Vec::with_capacity(count);
    let mut outer = 0u64;
    let mut failures = 0;
    let (mut turns, mut length, mut sent) = (0.0, 0.0, 0usize);
    for _ in 0..count {
        let n = rng.random_range(4..=7);
        // Each extension is timed three times from the same RNG state (identical results) and the
        // fastest kept, so that preemption by other processes does not pollute the figures.
        let mut best = f64::INFINITY;
        let mut result = None;
        for _ in 0..3 {
            let mut r = rng.clone();
            let t0 = Instant::now();
            let out = generator.extend(area, &tail, n, &mut r);
            best = best.min(t0.elapsed().as_secs_f64() * 1e3);
            result = Some((out, r));
        }
        let (result, r) = result.unwrap();
        rng = r;
        times.push(best);
        match result {
            Ok(ext) => {
                outer += u64::from(ext.stats.outer_tries);
                let mut prev = tail;
                for &q in &ext.points {
                    let next = prev.advanced(&[q]);
                    turns += trajgen::geometry::turn_angle(prev.heading, next.heading)
                        .abs()
                        .to_degrees();
                    length += prev.end.dist(q);
                    sent += 1;
                    prev = next;
                }
                tail = ext.next_tail;
            }
            Err(_) => {
                failures += 1;
                outer += u64::from(generator.config().outer_tries);
                tail = start_tail;
            }
        }
    }
    times.sort_by(f64::total_cmp);
    let rank = |q: f64| times[((q * count as f64).ceil() as usize).clamp(1, count) - 1];
    Figures {
        p50: rank(0.5),
        p99: rank(0.99),
        max: times[count - 1],
        mean_outer: outer as f64 / count as f64,
        failures,
        mean_turn: turns / sent.max(1) as f64,
        mean_length: length / sent.max(1) as f64,
    }
}

/// Where the reference strategy fails in `name` over seeds 1..=`seeds` (100 km each).
fn reference_failures(name: &str, seeds: u64, km: f64) {
    let real = areas::REAL_AREAS
        .iter()
        .find(|a| a.name == name)
        .expect("a real area name");
    let area = area(real);
    let start = points(real.start_route);
    for seed in 1..=seeds {
        let config = ValidationConfig::default()
            .with_km(km)
            .with_generator(config(Strategy::Reference));
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let report = validate_area(&area, &start, &config, &mut rng, &mut |_| {}).unwrap();
        let failures: Vec<String> = report
            .failure_records
            .iter()
            .map(|f| format!("({:.1}, {:.1}) at {:.1} km", f.at.x, f.at.y, f.km))
            .collect();
        let worst = report
            .hotspots
            .first()
            .map(|h| format!("({:.1}, {:.1}) {}", h.x, h.y, h.outer_tries));
        println!(
            "seed {seed}: {} failures [{}]; worst place {:?}",
            report.failures,
            failures.join("; "),
            worst
        );
    }
}

fn print_extensions() {
    println!("## Extensions: 2000 × (4–7 points + margin 20), seed 1");
    println!();
    println!(
        "| area | strategy | p50 ms | p99 ms | max ms | mean outer tries | failures | mean turn | mean segment |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for real in &areas::REAL_AREAS {
        let area = area(real);
        let start = points(real.start_route);
        for strategy in [Strategy::Reference, Strategy::Wedge] {
            let f = extensions(&area, &start, strategy, 2000);
            println!(
                "| {} | {:?} | {:.3} | {:.3} | {:.3} | {:.2} | {} | {:.1}° | {:.2} m |",
                real.name,
                strategy,
                f.p50,
                f.p99,
                f.max,
                f.mean_outer,
                f.failures,
                f.mean_turn,
                f.mean_length
            );
        }
    }
    println!();
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut reference_km = 10.0;
    let mut km = 100.0;
    let mut validation_only = false;
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--reference-km" => reference_km = args.next().unwrap().parse().unwrap(),
            "--km" => km = args.next().unwrap().parse().unwrap(),
            "--validation-only" => validation_only = true,
            "--reference-failures" => {
                let name = args.next().unwrap();
                let seeds: u64 = args.next().unwrap().parse().unwrap();
                reference_failures(&name, seeds, km);
                return;
            }
            other => panic!("unknown argument {other}"),
        }
    }
    if !validation_only {
        print_extensions();
    }
    println!("## Validation, extensions of 5 + margin 20, seed 1");
    println!();
    println!(
        "| area | strategy | km | wall s | extensions | failures | max / mean / p99 outer | coverage | verdict | worst places |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for real in &areas::REAL_AREAS {
        let area = area(real);
        let start = points(real.start_route);
        for (strategy, km) in [(Strategy::Wedge, km), (Strategy::Reference, reference_km)] {
            let config = ValidationConfig::default()
                .with_km(km)
                .with_generator(config(strategy));
            let mut rng = Pcg64Mcg::seed_from_u64(1);
            let t0 = Instant::now();
            let report = validate_area(&area, &start, &config, &mut rng, &mut |_| {}).unwrap();
            let wall = t0.elapsed().as_secs_f64();
            let spots: Vec<String> = report
                .hotspots
                .iter()
                .map(|h| {
                    format!(
                        "({:.1}, {:.1}) {}/{}",
                        h.x, h.y, h.outer_tries, h.inner_tries
                    )
                })
                .collect();
            println!(
                "| {} | {:?} | {:.1} | {:.2} | {} | {} | {} / {:.2} / {} | {:.1} % | {} | {} |",
                real.name,
                strategy,
                report.km,
                wall,
                report.extensions,
                report.failures,
                report.max_outer_tries,
                report.mean_outer_tries,
                report.p99_outer_tries,
                report.coverage * 100.0,
                report.verdict,
                spots.join("; ")
            );
        }
    }
}
