//! The reset before every test (`docs/method.md#a-test-step-by-step`): clear the faults and the
//! route, plan a return route from the car's RTK pose with the `recovery` crate, drive it and the
//! rest of the recovery route to its end, brake to a stop, and set the UWB estimate to the RTK
//! estimate (its position with `pos_uwb_reset_pos`, and from firmware 11.0 its heading too, with
//! SET_POS). The test drive then starts from where the car stands, at the end of the recovery
//! route: every test starts from the same known state. A car the safety monitor braked just outside
//! the drivable region is first driven back in ([`reentry`]).
//!
//! The return route keeps the scenario's clearance from every edge when it can. A car that stopped
//! inside the clearance band (nearer an edge than the clearance: it cuts corners, and braking
//! carries it on) cannot start a route that keeps it, so the route is then planned with half the
//! clearance, or none ([`recovery::PlanConfig::plan_with_fallback`]); [`ResetDone::clearance_m`]
//! says which one it keeps.
//!
//! Recorded: the return route as planned, every command (between tests: without a test index)
//! with its answer, and every state sample.

use std::time::Duration;

use car_link::firmware::UwbReset;
use car_link::{CarError, StateSample};
use recovery::{PlanConfig, ReturnRoute};
use tokio::time::{Instant, MissedTickBehavior, sleep_until};
use trajgen::geometry::closest_point_on_segment;
use trajgen::{Area, Point, Pose, Waypoint};

use super::telemetry::{Sample, Telemetry};
use super::{
    BRAKE_CURRENT_A, BRAKE_TIMEOUT, Context, RunError, STOPPED_SPEED_MPS, Stopped, retried,
};
use crate::vehicle::Vehicle;
use campaign::safety::{Abort, AbortReason, CarSample, SafetyConfig, SafetyMonitor};
use campaign::streaming::{Streamer, route_points};
use recording::{CarCommand, PlannedReturnRoute, Pose as RecordedPose};

/// Slack on top of the time a reset drive needs at its speeds.
const RESET_SLACK: Duration = Duration::from_secs(60);
/// Near the end of its route and slower than this, the car has stopped at the route end.
const NEAR_END: Duration = Duration::from_secs(2);
/// Largest distance outside the drivable region from which the reset drives the car back.
pub const MAX_REENTRY_M: f64 = 1.5;
/// How far inside the drivable region a re-entry aims.
pub const REENTRY_INSIDE_M: f64 = 0.5;

/// Where the reset left the car.
#[derive(Debug, Clone, PartialEq)]
pub struct ResetDone {
    /// The return route driven: from the car's position to the joint with the recovery route,
    /// with the speed of each point.
    pub return_route: Vec<Waypoint>,
    /// Where the car stands, stopped, with UWB equal to RTK.
    pub standing: Point,
    /// The clearance from every edge the return route keeps, metres: the scenario's, or less when
    /// the car stood inside the clearance band (see the module doc).
    pub clearance_m: f64,
}

/// How braking ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BrakeEnd {
    /// The car is slower than 0.1 m/s.
    Stopped,
    /// It did not stop within [`BRAKE_TIMEOUT`].
    TimedOut,
    /// The link is lost.
    LinkLost,
    /// The operator's second signal braked the car at once ([`super::hard_stop`]).
    HardStopped,
}

/// Resets the car for test `test_index` (see the module doc).
///
/// Timeout: the drive is bounded by the route's length at its speeds plus 60 s, braking by
/// [`BRAKE_TIMEOUT`]. Cancellation: the context's token brakes the car and returns an
/// `Interrupted` abort; dropping the future leaves the car driving until its watchdog stops it.
pub async fn reset<V: Vehicle>(
    ctx: &Context<'_, V>,
    telemetry: &mut Telemetry,
    test_index: usize,
) -> Result<ResetDone, Stopped> {
    let car = ctx.car;
    let journal = ctx.journal;
    retried(|| journal.call(None, CarCommand::ClearFaults, car.clear_faults()))
        .await
        .map_err(|e| car_stop("clearing the faults", e))?;
    journal
        .call(None, CarCommand::ClearRoute, car.clear_route())
        .await
        .map_err(|e| car_stop("clearing the route", e))?;
    let sample = retried(|| car.state())
        .await
        .map_err(|e| car_stop("reading the state", e))?;
    journal.state(&sample);
    let car_pose = pose_of(&sample);
    let entry = reentry(&ctx.scenario.area, car_pose);
    let route = plan_return(ctx, entry.unwrap_or(car_pose), test_index)?;
    let speed = recovery_speed(ctx);
    let mut return_route: Vec<Waypoint> = entry
        .map(|_| car_pose.position)
        .into_iter()
        .chain(route.points.iter().copied())
        .map(|p| Waypoint::new(p, speed))
        .collect();
    journal.write(&PlannedReturnRoute {
        test_index,
        points: return_route.iter().map(|&w| w.into()).collect(),
    });
    let mut drive = return_route.clone();
    drive.extend(recovery_rest(ctx, &route));
    drive.extend(ctx.start_join.iter().map(|&p| Waypoint::new(p, speed)));
    // Re-entering, the car may first have to turn away from the boundary.
    let slack = entry.map_or(0.0, |_| MAX_REENTRY_M);
    let safety = SafetyConfig {
        area_margin_m: ctx.safety.area_margin_m + slack,
        max_cross_track_m: ctx.safety.max_cross_track_m + slack,
        ..ctx.safety
    };
    follow_to_end(ctx, telemetry, &drive, safety, test_index).await?;
    retried(|| journal.call(None, CarCommand::ResetUwbPos, car.reset_uwb_pos()))
        .await
        .map_err(|e| car_stop("resetting the UWB position", e))?;
    let standing = retried(|| car.state())
        .await
        .map_err(|e| car_stop("reading the state", e))?;
    journal.state(&standing);
    if car.version().profile().uwb_reset == UwbReset::PositionOnly {
        // From 11.0 `pos_uwb_reset_pos` resets the position only
        // (`docs/firmware.md#resetting-the-estimate`); SET_POS with the RTK pose also sets the UWB
        // heading.
        let s = &standing.state;
        let pose = car_link::message::Pose {
            x: s.px,
            y: s.py,
            yaw: s.yaw,
        };
        let command = CarCommand::SetPos {
            pose: RecordedPose {
                x: s.px,
                y: s.py,
                yaw_deg: s.yaw,
            },
        };
        retried(|| journal.call(None, command.clone(), car.set_pos(pose)))
            .await
            .map_err(|e| car_stop("setting the UWB pose", e))?;
    }
    Ok(ResetDone {
        return_route: std::mem::take(&mut return_route),
        standing: Point::new(standing.state.px, standing.state.py),
        clearance_m: route.clearance,
    })
}

/// A failed car command: a lost link aborts the test, anything else stops the campaign.
pub fn car_stop(what: &str, error: CarError) -> Stopped {
    match error {
        CarError::LinkLost => Stopped::Abort(Abort::new(AbortReason::LinkLost, Duration::ZERO)),
        other => Stopped::Error(RunError::car(what, other)),
    }
}

/// The car's pose from a state: RTK position, heading from the clockwise yaw in degrees.
pub fn pose_of(sample: &StateSample) -> Pose {
    let s = &sample.state;
    Pose::new(Point::new(s.px, s.py), (-s.yaw).to_radians())
}

/// Where a car standing outside the drivable region by at most [`MAX_REENTRY_M`] (the safety
/// monitor braked it there) re-enters it: [`REENTRY_INSIDE_M`] inside the nearest boundary, on
/// the line from the car through the nearest boundary point, heading that way. `None` when the
/// car is inside (or too far out to drive back unattended).
pub fn reentry(area: &Area, car: Pose) -> Option<Pose> {
    let p = car.position;
    if area.contains_point(p) || !p.is_finite() {
        return None;
    }
    let nearest = area
        .edges()
        .iter()
        .map(|e| closest_point_on_segment(p, e.a, e.b))
        .min_by(|a, b| a.dist(p).total_cmp(&b.dist(p)))?;
    let outside_by = nearest.dist(p);
    if outside_by > MAX_REENTRY_M || outside_by == 0.0 {
        return None;
    }
    let inward = (nearest - p) * (1.0 / outside_by);
    let entry = nearest + inward * REENTRY_INSIDE_M;
    area.contains_point(entry)
        .then(|| Pose::new(entry, inward.heading()))
}

/// The return route from `from`, keeping the scenario's clearance or, from inside the clearance
/// band, the largest fallback clearance that gives a route (see the module doc).
fn plan_return<V: Vehicle>(
    ctx: &Context<'_, V>,
    from: Pose,
    test_index: usize,
) -> Result<ReturnRoute, Stopped> {
    let scenario = ctx.scenario;
    let purpose = campaign::seed::Purpose::Reset { test_index };
    let mut rng = campaign::seed::rng_for(ctx.config.campaign.seed, purpose);
    PlanConfig::default()
        .plan_with_fallback(
            &scenario.area,
            from,
            &scenario.recovery_route.positions(),
            &scenario.constraints(),
            &mut rng,
        )
        .map_err(|source| Stopped::Error(RunError::Recovery { test_index, source }))
}

/// How far back along the start route's first segment the planned join aims, metres: the car
/// arrives at `start_route[0]` heading along the start route.
const JOIN_LEAD_IN_M: f64 = 1.0;

/// The route from the recovery route's end to `start_route[0]` for a scenario whose recovery
/// route ends farther from it than a straight step may be ([`scenarios::needs_planned_join`]):
/// planned once per campaign with the return-route planner, from the recovery route's end (heading
/// along its last segment) to a lead-in that ends at `start_route[0]` along the start route's
/// first segment. The points after the recovery route's end, `start_route[0]` last; empty when
/// the straight step is used. Deterministic from the campaign seed.
pub fn plan_start_join(scenario: &scenarios::Scenario, seed: u64) -> Result<Vec<Point>, RunError> {
    if !scenarios::needs_planned_join(scenario) {
        return Ok(Vec::new());
    }
    let recovery = scenario.recovery_route.positions();
    let start = scenario.start_route.positions();
    let (&[.., before_end, end], &[first, second, ..]) = (recovery.as_slice(), start.as_slice())
    else {
        return Ok(Vec::new());
    };
    let along = (second - first) * (1.0 / first.dist(second));
    let lead_in = first - along * JOIN_LEAD_IN_M;
    let target = [lead_in, first];
    let from = Pose::new(end, (end - before_end).heading());
    let mut rng = campaign::seed::rng_for(seed, campaign::seed::Purpose::StartJoin);
    let route = PlanConfig::default()
        .plan_with_fallback(
            &scenario.area,
            from,
            &target,
            &scenario.constraints(),
            &mut rng,
        )
        .map_err(RunError::StartJoin)?;
    Ok(route.joined(&target).into_iter().skip(1).collect())
}

/// The speed of the reset drive: the recovery route's (its first point's).
fn recovery_speed<V: Vehicle>(ctx: &Context<'_, V>) -> f64 {
    ctx.scenario
        .recovery_route
        .first()
        .map_or(super::SAFE_STOP_SPEED_MPS, |p| p.speed)
}

/// The recovery route after the return route's joint, at the recovery speed.
fn recovery_rest<V: Vehicle>(ctx: &Context<'_, V>, route: &ReturnRoute) -> Vec<Waypoint> {
    let speed = recovery_speed(ctx);
    route
        .joined(&ctx.scenario.recovery_route.positions())
        .into_iter()
        .skip(route.points.len())
        .map(|position| Waypoint::new(position, speed))
        .collect()
}

/// Uploads `route`, drives it until the car stops at its end (watched with `safety`), then
/// brakes to a stop.
async fn follow_to_end<V: Vehicle>(
    ctx: &Context<'_, V>,
    telemetry: &mut Telemetry,
    route: &[Waypoint],
    safety: SafetyConfig,
    test_index: usize,
) -> Result<(), Stopped> {
    let points = route_points(route);
    let journal = ctx.journal;
    journal
        .call(
            None,
            CarCommand::add_points(&points),
            ctx.car.add_points(&points),
        )
        .await
        .map_err(|e| car_stop("uploading the return route", e))?;
    let start = CarCommand::SetAutopilot {
        active: true,
        reset: false,
    };
    journal
        .call(None, start, ctx.car.set_autopilot(true, false))
        .await
        .map_err(|e| car_stop("starting the autopilot", e))?;
    let outcome = watch_until_end(ctx, telemetry, route, safety).await;
    let braked = brake_until_stopped(ctx, telemetry).await;
    match (outcome, braked) {
        (Err(abort), _) => Err(Stopped::Abort(abort)),
        (Ok(false), _) => Err(Stopped::Error(RunError::Reset {
            test_index,
            reason: format!(
                "the car did not reach the end of the recovery route within {} s",
                (expected_duration(route) + RESET_SLACK).as_secs()
            ),
        })),
        (Ok(true), BrakeEnd::LinkLost) => Err(Stopped::Abort(Abort::new(
            AbortReason::LinkLost,
            Duration::ZERO,
        ))),
        (Ok(true), BrakeEnd::TimedOut) => Err(Stopped::Error(RunError::Reset {
            test_index,
            reason: "the car did not stop at the end of the recovery route".to_owned(),
        })),
        (Ok(true), BrakeEnd::Stopped) => Ok(()),
        (Ok(true), BrakeEnd::HardStopped) => Err(Stopped::Abort(Abort::new(
            AbortReason::Interrupted,
            Duration::ZERO,
        ))),
    }
}

/// Watches the car drive `route` until it stands at its end (`true`) or the time it needs plus
/// [`RESET_SLACK`] has passed (`false`); an abort from the safety monitor, the link or the
/// operator.
async fn watch_until_end<V: Vehicle>(
    ctx: &Context<'_, V>,
    telemetry: &mut Telemetry,
    route: &[Waypoint],
    config: SafetyConfig,
) -> Result<bool, Abort> {
    let t0 = Instant::now();
    let positions: Vec<Point> = route.iter().map(|w| w.position).collect();
    let mut safety = SafetyMonitor::new(ctx.scenario.area.clone(), config, Duration::ZERO);
    safety.set_route(&positions);
    let mut streamer = Streamer::new(ctx.config.streaming, route);
    let deadline = t0 + expected_duration(route) + RESET_SLACK;
    let mut ticker = tokio::time::interval(ctx.config.state_period);
    ticker.set_missed_tick_behavior(MissedTickBehavior::Delay);
    telemetry.drain(ctx.journal);
    // Made once, not at every sample: each would take a waiter slot and a timer and give them back.
    let cancelled = ctx.cancel.cancelled();
    let timed_out = sleep_until(deadline);
    tokio::pin!(cancelled, timed_out);
    loop {
        let now = t0.elapsed();
        tokio::select! {
            biased;
            () = &mut cancelled => {
                return Err(safety.stop(AbortReason::Interrupted, now));
            }
            sample = telemetry.next(ctx.journal) => {
                let Sample::State(sample) = sample else {
                    return Err(safety.link_lost(now));
                };
                let s = &sample.state;
                let position = Point::new(s.px, s.py);
                let now = t0.elapsed();
                // GET_STATE carries no fix type (`docs/firmware.md#fused-position`): the fused
                // position is the reference.
                if let Some(abort) = safety.sample(now, CarSample { position, rtk_fix: true }) {
                    return Err(abort);
                }
                let decision = streamer.observe(now, position);
                let stopped = s.speed.abs() < STOPPED_SPEED_MPS;
                if decision.starved || (decision.time_to_end < NEAR_END && stopped) {
                    return Ok(true);
                }
            }
            _ = ticker.tick() => {
                if let Some(abort) = safety.tick(t0.elapsed()) {
                    return Err(abort);
                }
            }
            () = &mut timed_out => return Ok(false),
        }
    }
}

/// The time `route` takes at its speeds (at least 0.1 m/s).
fn expected_duration(route: &[Waypoint]) -> Duration {
    let seconds: f64 = route
        .windows(2)
        .map(|w| w[0].position.dist(w[1].position) / w[1].speed.max(0.1))
        .sum();
    Duration::try_from_secs_f64(seconds).unwrap_or(Duration::MAX / 4)
}

/// Brakes with [`BRAKE_CURRENT_A`] at every state sample until the car is slower than
/// [`STOPPED_SPEED_MPS`], at most [`BRAKE_TIMEOUT`].
pub async fn brake_until_stopped<V: Vehicle>(
    ctx: &Context<'_, V>,
    telemetry: &mut Telemetry,
) -> BrakeEnd {
    let deadline = Instant::now() + BRAKE_TIMEOUT;
    let journal = ctx.journal;
    telemetry.drain(journal);
    let hard_stopped = super::hard_stop().cancelled();
    let timed_out = sleep_until(deadline);
    tokio::pin!(hard_stopped, timed_out);
    loop {
        let brake = CarCommand::Brake {
            current_a: BRAKE_CURRENT_A,
        };
        let braked = journal.call(None, brake, ctx.car.brake(BRAKE_CURRENT_A));
        if let Err(CarError::LinkLost) = braked.await {
            return BrakeEnd::LinkLost;
        }
        tokio::select! {
            biased;
            () = &mut hard_stopped => return BrakeEnd::HardStopped,
            sample = telemetry.next(journal) => match sample {
                Sample::LinkLost => return BrakeEnd::LinkLost,
                Sample::State(s) if s.state.speed.abs() < STOPPED_SPEED_MPS => {
                    return BrakeEnd::Stopped;
                }
                Sample::State(_) => {}
            },
            () = &mut timed_out => return BrakeEnd::TimedOut,
        }
    }
}

#[cfg(test)]
mod tests {
    use trajgen::Polygon;

    use super::*;

    fn square() -> Area {
        let fence = Polygon::new(vec![
            Point::new(0.0, 0.0),
            Point::new(10.0, 0.0),
            Point::new(10.0, 10.0),
            Point::new(0.0, 10.0),
        ])
        .unwrap();
        Area::new(fence, vec![]).unwrap()
    }

    #[test]
    fn a_recovery_route_ending_far_from_the_start_route_gets_a_drivable_planned_join() {
        let text = include_str!("../../orchestrator/tests/fixtures/short-recovery.toml");
        let scenario = scenarios::from_toml_str(text, "short-recovery.toml")
            .unwrap()
            .scenario;
        let join = plan_start_join(&scenario, 7).unwrap();
        let recovery = scenario.recovery_route.positions();
        let start = scenario.start_route.positions();
        let end = *recovery.last().unwrap();
        assert!(end.dist(start[0]) > 3.0, "the fixture needs a planned join");
        assert_eq!(join.last(), Some(&start[0]), "{join:?}");
        // From the recovery route's end, along its last heading, onto the start route: a route
        // the car can drive, turning onto the start route no sharper than the generator may.
        let mut route = vec![end];
        route.extend(&join);
        route.push(start[1]);
        let heading = (end - recovery[recovery.len() - 2]).heading();
        let mut constraints = scenario.constraints();
        constraints.clearance = 0.0;
        trajgen::check_route(&scenario.area, &route, &constraints, Some(heading)).unwrap();
        assert_eq!(
            plan_start_join(&scenario, 7).unwrap(),
            join,
            "deterministic"
        );
        // A scenario whose recovery route ends near the start route needs none.
        let bundled = scenarios::bundled::load("parking-lot-2anchors")
            .unwrap()
            .scenario;
        assert!(plan_start_join(&bundled, 7).unwrap().is_empty());
    }

    #[test]
    fn a_car_just_outside_re_enters_half_a_metre_inside_the_nearest_edge() {
        let car = Pose::new(Point::new(10.4, 5.0), 0.0);
        let entry = reentry(&square(), car).unwrap();
        assert!(entry.position.dist(Point::new(9.5, 5.0)) < 1e-9);
        assert!((entry.heading.abs() - std::f64::consts::PI).abs() < 1e-9);
    }

    #[test]
    fn a_car_inside_or_far_outside_needs_no_re_entry() {
        assert_eq!(
            reentry(&square(), Pose::new(Point::new(5.0, 5.0), 0.0)),
            None
        );
        assert_eq!(
            reentry(&square(), Pose::new(Point::new(13.0, 5.0), 0.0)),
            None
        );
    }
}
