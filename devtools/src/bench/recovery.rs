//! `drivecheck-dev bench recovery`: both return-route planners side by side on every bundled area.
//!
//! Poses are drawn uniformly in the fence's bounding box, kept when they are drivable and at least
//! `--clearance` from every edge, with a uniform heading. For each planner: success rate, plan
//! time p50/p99/max, mean length before and after shortening, and the mean ratio to the lower
//! bound. Success is also counted as the runner plans: with the clearance relaxed when the
//! scenario's finds nothing (`PlanConfig::plan_with_fallback`), overall and among the poses from
//! which the car can turn around where it stands; the poses left without a route are listed
//! after the table.
//! Run it in release mode.

use std::time::{Duration, Instant};

use anyhow::{Result, ensure};
use rand::RngExt;
use recovery::{PlanConfig, PlannerKind};
use scenarios::Scenario;
use trajgen::{Constraints, Point, Pose};

use super::generator::percentile;
use crate::cli::BenchRecoveryArgs;
use campaign::seed::{Purpose, rng_for};
use orchestrator::exit::Exit;
use orchestrator::seed::{RunRng, rng};

/// Poses drawn before giving up on finding enough with the clearance asked for.
const MAX_DRAWS_PER_POSE: usize = 10_000;

/// Runs the benchmark and prints a Markdown table.
pub fn run(args: &BenchRecoveryArgs) -> Result<Exit> {
    println!(
        "| area | planner | success | with clearance fallback | with fallback, where the car can turn | p50 | p99 | max | mean length before → after shortening | mean ratio before → after | mean total ratio |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut stranded = Vec::new();
    for name in scenarios::bundled::names() {
        let scenario = scenarios::bundled::load(name)?.scenario;
        let poses = random_poses(&scenario, args, &mut rng(args.seed))?;
        for planner in PlannerKind::ALL {
            let figures = measure(&scenario, planner, &poses, args.seed);
            print_row(&scenario.name, planner, &figures);
            stranded.extend(
                figures
                    .stranded
                    .iter()
                    .map(|&(pose, room)| (name, planner, pose, room)),
            );
        }
    }
    if !stranded.is_empty() {
        println!(
            "\nPoses without a route even with the clearance relaxed (heading counter-clockwise from east):"
        );
        for (area, planner, pose, room) in stranded {
            println!(
                "- {area}, {planner}: ({:.2}, {:.2}) heading {:.1}°, {room:.2} m from the nearest edge",
                pose.position.x,
                pose.position.y,
                pose.heading.to_degrees(),
            );
        }
    }
    Ok(Exit::Success)
}

fn random_poses(
    scenario: &Scenario,
    args: &BenchRecoveryArgs,
    rng: &mut RunRng,
) -> Result<Vec<Pose>> {
    let bbox = scenario.area.bbox();
    let mut poses = Vec::with_capacity(args.poses);
    let mut draws = 0;
    while poses.len() < args.poses {
        draws += 1;
        ensure!(
            draws <= MAX_DRAWS_PER_POSE * args.poses.max(1),
            "{}: too few points with {} m clearance",
            scenario.name,
            args.clearance
        );
        let p = Point::new(
            rng.random_range(bbox.min.x..=bbox.max.x),
            rng.random_range(bbox.min.y..=bbox.max.y),
        );
        if scenario.area.contains_point(p) && scenario.area.boundary_distance(p) >= args.clearance {
            let heading = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            poses.push(Pose::new(p, heading));
        }
    }
    Ok(poses)
}

/// Figures of one planner over the poses of one area.
#[derive(Default)]
struct Figures {
    tried: usize,
    planned: usize,
    /// Routes planned as the runner plans them: with the clearance relaxed when the full one
    /// finds nothing (`PlanConfig::plan_with_fallback`).
    planned_with_fallback: usize,
    /// Poses from which the car can turn around where it stands, a full tightest circle with
    /// no clearance (`recovery::can_turn_around`), and fallback routes planned from them.
    turnable: usize,
    planned_turnable: usize,
    /// Poses from which not even the fallback found a route, with their distance to the
    /// nearest edge.
    stranded: Vec<(Pose, f64)>,
    times: Vec<Duration>,
    length_before: f64,
    length: f64,
    ratio_before: f64,
    ratio: f64,
    total_ratio: f64,
}

fn measure(scenario: &Scenario, planner: PlannerKind, poses: &[Pose], seed: u64) -> Figures {
    let config = PlanConfig::default().with_planner(planner);
    let recovery_route = scenario.recovery_route.positions();
    let constraints = scenario.constraints();
    let mut figures = Figures::default();
    for (i, &pose) in poses.iter().enumerate() {
        let mut rng = rng_for(seed, Purpose::RecoveryPose { pose: i });
        let started = Instant::now();
        let result = config.plan(
            &scenario.area,
            pose,
            &recovery_route,
            &constraints,
            &mut rng,
        );
        figures.times.push(started.elapsed());
        figures.tried += 1;
        let rescued = result.is_err()
            && config
                .plan_with_fallback(
                    &scenario.area,
                    pose,
                    &recovery_route,
                    &constraints,
                    &mut rng,
                )
                .is_ok();
        let planned = result.is_ok() || rescued;
        figures.planned_with_fallback += usize::from(planned);
        let no_clearance = Constraints {
            clearance: 0.0,
            ..constraints
        };
        if recovery::can_turn_around(&scenario.area, pose, &no_clearance) {
            figures.turnable += 1;
            figures.planned_turnable += usize::from(planned);
        }
        if result.is_err() && !rescued {
            figures
                .stranded
                .push((pose, scenario.area.boundary_distance(pose.position)));
        }
        if let Ok(route) = result {
            figures.planned += 1;
            figures.length_before += route.quality.length_before_shortening;
            figures.length += route.quality.length;
            figures.ratio_before +=
                route.quality.length_before_shortening / route.quality.lower_bound;
            figures.ratio += route.quality.ratio;
            figures.total_ratio += route.quality.total_ratio;
        }
    }
    figures.times.sort_unstable();
    figures
}

fn print_row(area: &str, planner: PlannerKind, f: &Figures) {
    let ms = |d: Duration| format!("{:.2} ms", d.as_secs_f64() * 1e3);
    let mean = |sum: f64| sum / f.planned.max(1) as f64;
    println!(
        "| {area} | {planner} | {}/{} ({:.1} %) | {}/{} ({:.1} %) | {}/{} ({:.1} %) | {} | {} | {} | {:.2} → {:.2} m | {:.3} → {:.3} | {:.3} |",
        f.planned,
        f.tried,
        100.0 * f.planned as f64 / f.tried.max(1) as f64,
        f.planned_with_fallback,
        f.tried,
        100.0 * f.planned_with_fallback as f64 / f.tried.max(1) as f64,
        f.planned_turnable,
        f.turnable,
        100.0 * f.planned_turnable as f64 / f.turnable.max(1) as f64,
        ms(percentile(&f.times, 0.5)),
        ms(percentile(&f.times, 0.99)),
        ms(f.times.last().copied().unwrap_or_default()),
        mean(f.length_before),
        mean(f.length),
        mean(f.ratio_before),
        mean(f.ratio),
        mean(f.total_ratio),
    );
}
