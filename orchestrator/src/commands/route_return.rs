//! `drivecheck route return`: the return route from a pose to the recovery route.

use std::time::Instant;

use anyhow::{Context, Result, bail};
use recovery::{PlanConfig, RecoveryError, ReturnRoute};
use serde::Serialize;
use trajgen::{Point, Pose};

use crate::cli::ReturnArgs;
use crate::exit::Exit;
use crate::output;
use crate::scenario_arg::{load_scenario, print_warnings};
use crate::seed::{choose_seed, rng};

/// What `route return --json` prints.
#[derive(Debug, Serialize)]
struct ReturnSummary {
    scenario: String,
    seed: u64,
    planner: String,
    /// The route from the car's position to the joining point on the recovery route.
    points: Vec<[f64; 2]>,
    length_m: f64,
    lower_bound_m: f64,
    ratio: f64,
    plan_ms: f64,
    /// The clearance from every edge the route keeps (less than the scenario's when the pose is
    /// nearer an edge than that).
    clearance_m: f64,
    length_before_shortening_m: f64,
    /// The recovery segment joined and the joining point.
    join_segment: usize,
    join_point: [f64; 2],
    /// Return route plus the rest of the recovery route: the distance to the start route.
    total_length_m: f64,
    attempts: u32,
    expansions: u64,
    connections_checked: u64,
}

/// Parses `X,Y,HEADING_DEG` into a pose (heading in radians).
pub fn parse_pose(text: &str) -> Result<Pose> {
    let numbers: Vec<f64> = text
        .split(',')
        .map(|part| part.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--from {text:?}: expected X,Y,HEADING_DEG (three numbers)"))?;
    let [x, y, heading_deg] = numbers[..] else {
        bail!(
            "--from {text:?}: expected X,Y,HEADING_DEG (three numbers), got {}",
            numbers.len()
        );
    };
    if !(x.is_finite() && y.is_finite() && heading_deg.is_finite()) {
        bail!("--from {text:?}: the numbers must be finite");
    }
    Ok(Pose::new(Point::new(x, y), heading_deg.to_radians()))
}

/// Plans and prints the return route.
pub fn plan(args: &ReturnArgs) -> Result<Exit> {
    let loaded = load_scenario(args.scenario.name())?;
    print_warnings(args.scenario.name(), &loaded);
    let scenario = &loaded.scenario;
    let from = parse_pose(&args.from)?;
    let seed = choose_seed(args.seed);
    output::note(format_args!("seed {seed}"));
    let config = PlanConfig::default().with_planner(args.planner);
    let recovery_route = scenario.recovery_route.positions();
    let started = Instant::now();
    // From inside the clearance band no route can keep the clearance: relax it as the runner
    // does, and say so.
    let planned = config.plan_with_fallback(
        &scenario.area,
        from,
        &recovery_route,
        &scenario.constraints(),
        &mut rng(seed),
    );
    let route = match planned {
        Ok(route) => route,
        // A finding about the pose, not a usage error: exit 1, as an unsafe area does.
        Err(error @ RecoveryError::NoRoute { .. }) => {
            output::finding(format_args!(
                "no return route from {}: {error}; a car this boxed in (too close to an edge \
                 ahead to turn away) must be moved by hand",
                args.from
            ));
            return Ok(Exit::Found);
        }
        Err(error) => {
            return Err(error).with_context(|| format!("no return route from {}", args.from));
        }
    };
    let plan_ms = started.elapsed().as_secs_f64() * 1e3;
    let summary = summarise(&scenario.name, seed, &route, plan_ms);
    if args.json {
        output::print_json(output::json::ROUTE_RETURN, &summary)?;
    } else {
        print_summary(&summary);
    }
    Ok(Exit::Success)
}

fn summarise(scenario: &str, seed: u64, route: &ReturnRoute, plan_ms: f64) -> ReturnSummary {
    let q = &route.quality;
    ReturnSummary {
        scenario: scenario.to_owned(),
        seed,
        planner: route.planner.name().to_owned(),
        points: route.points.iter().map(|&p| p.into()).collect(),
        length_m: q.length,
        lower_bound_m: q.lower_bound,
        ratio: q.ratio,
        plan_ms,
        clearance_m: route.clearance,
        length_before_shortening_m: q.length_before_shortening,
        join_segment: route.join.segment,
        join_point: route.join.point.into(),
        total_length_m: q.total_length,
        attempts: q.tried.attempts,
        expansions: q.tried.expansions,
        connections_checked: q.tried.connections,
    }
}

fn print_summary(s: &ReturnSummary) {
    println!(
        "{} (seed {}): return route by the {} planner, {} points, joins recovery segment {} at ({:.2}, {:.2})",
        s.scenario,
        s.seed,
        s.planner,
        s.points.len(),
        s.join_segment,
        s.join_point[0],
        s.join_point[1]
    );
    for [x, y] in &s.points {
        println!("{x:10.3} {y:10.3}");
    }
    println!(
        "length {:.2} m (before shortening {:.2} m), lower bound {:.2} m, ratio {:.3}; {:.2} m to the start route; clearance {:.2} m; planned in {:.2} ms",
        s.length_m,
        s.length_before_shortening_m,
        s.lower_bound_m,
        s.ratio,
        s.total_length_m,
        s.clearance_m,
        s.plan_ms
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pose_is_three_numbers_with_the_heading_in_degrees() {
        let pose = parse_pose("-12.5, 3,90").unwrap();
        assert_eq!(pose.position, Point::new(-12.5, 3.0));
        assert!((pose.heading - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(parse_pose("1,2").is_err());
        assert!(parse_pose("1,2,east").is_err());
        assert!(parse_pose("1,2,3,4").is_err());
        assert!(parse_pose("1,NaN,3").is_err());
    }
}
