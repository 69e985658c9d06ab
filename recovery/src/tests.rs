//! Properties of planned return routes on the five real areas.

use proptest::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;
use trajgen::{Area, Point, Polygon, check_route};

use crate::{Constraints, PlanConfig, PlannerKind, Pose, RecoveryError, can_turn_around, plan};
use trajgen::test_areas::{REAL_AREAS, RealArea};

fn points(raw: &[[f64; 2]]) -> Vec<Point> {
    raw.iter().map(|&p| Point::from(p)).collect()
}

fn area_of(real: &RealArea) -> Area {
    let fence = Polygon::new(points(real.fence)).unwrap();
    let cutouts = real
        .cutouts
        .iter()
        .map(|c| Polygon::new(points(c)).unwrap())
        .collect();
    Area::new(fence, cutouts).unwrap()
}

/// A uniformly random pose at least `clearance` metres from every edge, random heading.
fn clear_pose(area: &Area, clearance: f64, rng: &mut Pcg64Mcg) -> Pose {
    let bbox = area.bbox();
    loop {
        let p = Point::new(
            rng.random_range(bbox.min.x..bbox.max.x),
            rng.random_range(bbox.min.y..bbox.max.y),
        );
        if area.contains_point(p) && area.boundary_distance(p) >= clearance {
            let heading = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            return Pose::new(p, heading);
        }
    }
}

/// A clear pose (see [`clear_pose`]) from which the car can turn around where it stands.
fn turnable_pose(area: &Area, clearance: f64, rng: &mut Pcg64Mcg) -> Pose {
    loop {
        let pose = clear_pose(area, clearance, rng);
        if can_turn_around(area, pose, &Constraints::default()) {
            return pose;
        }
    }
}

/// Plans from a clear pose drawn from `seed` and checks the route end to end, joint included.
///
/// The pose must also let the car turn around where it stands ([`can_turn_around`]): about one
/// pose in 200 with 1 m clearance faces the fence in a narrow tip or corner with no forward way
/// out (see `a_boxed_in_pose_is_no_route_not_a_bad_route`).
fn route_from_clear_pose_passes_the_check(planner: PlannerKind, real: &RealArea, seed: u64) {
    let area = area_of(real);
    let recovery = points(real.recovery_route);
    let c = Constraints::default();
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let from = turnable_pose(&area, 1.0, &mut rng);
    let config = PlanConfig::default().with_planner(planner);
    let route = config
        .plan(&area, from, &recovery, &c, &mut rng)
        .unwrap_or_else(|e| panic!("{planner} in {} from {from:?}: {e}", real.name));
    assert_eq!(route.points[0], from.position);
    assert_eq!(route.points.last(), Some(&route.join.point));
    let checked = route.checked_points();
    assert_eq!(
        check_route(&area, &checked, &c, Some(from.heading)),
        Ok(()),
        "{planner} in {} from {from:?}",
        real.name
    );
    assert_eq!(route.join.next, recovery[route.join.segment + 1]);
    let q = route.quality;
    // The lower bounds are proven: no drivable route beats them.
    assert!(q.length >= q.lower_bound - 1e-9, "{q:?}");
    assert!(q.total_length >= q.total_lower_bound - 1e-9, "{q:?}");
    assert!(q.length <= q.length_before_shortening + 1e-9, "{q:?}");
}

proptest! {
    #![proptest_config(ProptestConfig {
        failure_persistence: None,
        ..ProptestConfig::with_cases(48)
    })]

    /// From any pose with 1 m clearance in any real area, the Dubins planner finds a route that
    /// passes the check end to end, joint included.
    #[test]
    fn dubins_routes_from_clear_poses_are_drivable_in_every_real_area(
        area in 0..REAL_AREAS.len(),
        seed in any::<u64>(),
    ) {
        route_from_clear_pose_passes_the_check(PlannerKind::Dubins, &REAL_AREAS[area], seed);
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        failure_persistence: None,
        ..ProptestConfig::with_cases(12)
    })]

    /// The same for the reference planner (slower: fewer cases).
    #[test]
    fn reference_routes_from_clear_poses_are_drivable_in_every_real_area(
        area in 0..REAL_AREAS.len(),
        seed in any::<u64>(),
    ) {
        route_from_clear_pose_passes_the_check(PlannerKind::Reference, &REAL_AREAS[area], seed);
    }
}

#[test]
fn the_same_seed_gives_the_same_route() {
    for real in &REAL_AREAS {
        let area = area_of(real);
        let recovery = points(real.recovery_route);
        for planner in PlannerKind::ALL {
            let config = PlanConfig::default().with_planner(planner);
            let run = |seed: u64| {
                let mut rng = Pcg64Mcg::seed_from_u64(seed);
                let from = clear_pose(&area, 1.0, &mut rng);
                config.plan(&area, from, &recovery, &Constraints::default(), &mut rng)
            };
            assert_eq!(run(7), run(7), "{planner} in {}", real.name);
        }
    }
}

#[test]
fn poses_outside_the_fence_or_in_a_cutout_are_typed_errors() {
    let real = &REAL_AREAS[0];
    let area = area_of(real);
    let recovery = points(real.recovery_route);
    let c = Constraints::default();
    let mut rng = Pcg64Mcg::seed_from_u64(1);
    let outside = Pose::new(Point::new(100.0, 100.0), 0.0);
    assert_eq!(
        plan(&area, outside, &recovery, &c, &mut rng),
        Err(RecoveryError::PoseOutside { x: 100.0, y: 100.0 })
    );
    let cutout = &area.cutouts()[1];
    let inside_cutout = cutout
        .vertices()
        .iter()
        .fold(Point::default(), |s, &v| s + v)
        * (1.0 / cutout.vertices().len() as f64);
    assert!(matches!(
        plan(
            &area,
            Pose::new(inside_cutout, 0.0),
            &recovery,
            &c,
            &mut rng
        ),
        Err(RecoveryError::PoseInCutout { cutout: 1, .. })
    ));
    let on_fence = area.fence().vertices()[0];
    assert!(matches!(
        plan(&area, Pose::new(on_fence, 0.0), &recovery, &c, &mut rng),
        Err(RecoveryError::PoseOnEdge { .. })
    ));
    assert_eq!(
        plan(
            &area,
            Pose::new(Point::new(f64::NAN, 0.0), 0.0),
            &recovery,
            &c,
            &mut rng
        ),
        Err(RecoveryError::NonFinitePose)
    );
}

#[test]
fn an_unjoinable_recovery_route_is_a_typed_error() {
    let real = &REAL_AREAS[0];
    let area = area_of(real);
    let c = Constraints::default();
    let mut rng = Pcg64Mcg::seed_from_u64(1);
    let from = clear_pose(&area, 1.0, &mut rng);
    let too_short = [Point::new(0.0, 0.0), Point::new(0.3, 0.0)];
    assert!(matches!(
        plan(&area, from, &too_short, &c, &mut rng),
        Err(RecoveryError::InvalidRecoveryRoute { .. })
    ));
    assert!(matches!(
        plan(&area, from, &too_short[..1], &c, &mut rng),
        Err(RecoveryError::InvalidRecoveryRoute { .. })
    ));
}

#[test]
fn a_search_out_of_budget_reports_what_it_tried() {
    let real = &REAL_AREAS[0];
    let area = area_of(real);
    let recovery = points(real.recovery_route);
    let search = crate::SearchConfig {
        max_expansions: 1,
        ..crate::SearchConfig::default()
    };
    let config = PlanConfig::default().with_search(search);
    let mut rng = Pcg64Mcg::seed_from_u64(3);
    // With one expansion only poses a single Dubins shot can leave fail; some of 50 must.
    let poses: Vec<Pose> = (0..50).map(|_| clear_pose(&area, 1.0, &mut rng)).collect();
    let failures: Vec<RecoveryError> = poses
        .into_iter()
        .filter_map(|from| {
            config
                .plan(&area, from, &recovery, &Constraints::default(), &mut rng)
                .err()
        })
        .collect();
    assert!(!failures.is_empty());
    for failure in failures {
        let RecoveryError::NoRoute { planner, tried } = failure else {
            panic!("expected NoRoute, got {failure:?}");
        };
        assert_eq!(planner, PlannerKind::Dubins);
        assert_eq!(tried.expansions, 1);
        assert!(tried.connections > 0);
    }
}

#[test]
fn planner_names_round_trip() {
    for planner in PlannerKind::ALL {
        assert_eq!(planner.name().parse::<PlannerKind>(), Ok(planner));
    }
    assert!("astar".parse::<PlannerKind>().is_err());
}

#[test]
fn the_joined_route_follows_the_recovery_route_into_the_start_route() {
    for real in &REAL_AREAS {
        let area = area_of(real);
        let recovery = points(real.recovery_route);
        let mut rng = Pcg64Mcg::seed_from_u64(5);
        let from = clear_pose(&area, 1.0, &mut rng);
        let route = plan(&area, from, &recovery, &Constraints::default(), &mut rng).unwrap();
        let joined = route.joined(&recovery);
        let after_joint = &joined[route.points.len()..];
        assert_eq!(after_joint, &recovery[route.join.segment + 1..]);
        let start = Point::from(real.start_route[0]);
        assert!(joined.last().unwrap().dist(start) < 2.5, "{}", real.name);
    }
}

#[test]
fn a_pose_in_a_tight_tip_that_can_turn_around_gets_a_route() {
    // Found by the property test: 1 m from the fence near the lot's narrow west tip, facing it.
    let real = &REAL_AREAS[2];
    let area = area_of(real);
    let recovery = points(real.recovery_route);
    let c = Constraints::default();
    let from = Pose::new(
        Point::new(-31.221323305932295, -52.749620061651385),
        -3.030978544029649,
    );
    assert!(can_turn_around(&area, from, &c));
    let mut rng = Pcg64Mcg::seed_from_u64(1);
    let route = plan(&area, from, &recovery, &c, &mut rng).unwrap();
    assert_eq!(
        check_route(&area, &route.checked_points(), &c, Some(from.heading)),
        Ok(())
    );
}

#[test]
fn a_boxed_in_pose_is_no_route_not_a_bad_route() {
    // Parking lot with two anchors: 1.0 m from the fence, facing into the lot's narrow west tip
    // 1.13 m ahead (found by the measurement over 200 random poses).
    let real = &REAL_AREAS[2];
    assert_eq!(real.name, "parking-lot-2anchors");
    let area = area_of(real);
    let recovery = points(real.recovery_route);
    let c = Constraints::default();
    let from = Pose::new(Point::new(-31.7309, -52.5241), (-174.7f64).to_radians());
    assert!(area.boundary_distance(from.position) >= 1.0);
    assert!(!can_turn_around(&area, from, &c));
    // Every reference attempt exhausts the generator's 5000 outer tries: three attempts suffice.
    let reference = crate::ReferenceConfig {
        attempts: 3,
        ..crate::ReferenceConfig::default()
    };
    for planner in PlannerKind::ALL {
        let mut rng = Pcg64Mcg::seed_from_u64(1);
        let config = PlanConfig::default()
            .with_planner(planner)
            .with_reference(reference.clone());
        let result = config.plan(&area, from, &recovery, &c, &mut rng);
        assert!(
            matches!(result, Err(RecoveryError::NoRoute { .. })),
            "{planner}: {result:?}"
        );
    }
}

#[test]
fn nonsense_constants_are_typed_errors() {
    let real = &REAL_AREAS[0];
    let area = area_of(real);
    let recovery = points(real.recovery_route);
    let mut rng = Pcg64Mcg::seed_from_u64(1);
    let from = clear_pose(&area, 1.0, &mut rng);
    let c = Constraints::default();
    let no_grid = PlanConfig::default().with_search(crate::SearchConfig {
        grid_cell: 0.0,
        ..crate::SearchConfig::default()
    });
    assert!(matches!(
        no_grid.plan(&area, from, &recovery, &c, &mut rng),
        Err(RecoveryError::InvalidConfig { .. })
    ));
    let no_turning = Constraints {
        max_turn: 0.0,
        ..Constraints::default()
    };
    assert!(matches!(
        plan(&area, from, &recovery, &no_turning, &mut rng),
        Err(RecoveryError::InvalidConstraints { .. })
    ));
}

#[test]
fn the_earliest_join_policy_joins_where_the_reference_planner_does() {
    for real in &REAL_AREAS {
        let area = area_of(real);
        let recovery = points(real.recovery_route);
        let mut rng = Pcg64Mcg::seed_from_u64(11);
        let from = turnable_pose(&area, 1.0, &mut rng);
        let c = Constraints::default();
        let plan_with = |config: PlanConfig| {
            config
                .plan(&area, from, &recovery, &c, &mut Pcg64Mcg::seed_from_u64(1))
                .unwrap()
        };
        let earliest =
            plan_with(PlanConfig::default().with_join_policy(crate::JoinPolicy::Earliest));
        let reference = plan_with(PlanConfig::default().with_planner(PlannerKind::Reference));
        assert_eq!(earliest.join, reference.join, "{}", real.name);
        let anywhere = plan_with(PlanConfig::default());
        assert!(
            anywhere.join.remaining <= earliest.join.remaining,
            "{}",
            real.name
        );
        assert_eq!(
            check_route(&area, &earliest.checked_points(), &c, Some(from.heading)),
            Ok(())
        );
    }
}

/// A 20 m square with a straight recovery route across its middle.
fn open_square() -> (Area, Vec<Point>) {
    let fence = Polygon::new(vec![
        Point::new(0.0, 0.0),
        Point::new(20.0, 0.0),
        Point::new(20.0, 20.0),
        Point::new(0.0, 20.0),
    ])
    .unwrap();
    let recovery = (0..5)
        .map(|i| Point::new(6.0 + 2.0 * f64::from(i), 10.0))
        .collect();
    (Area::new(fence, vec![]).unwrap(), recovery)
}

#[test]
fn inside_the_clearance_band_the_fallback_keeps_the_largest_clearance_it_can() {
    let (area, recovery) = open_square();
    let c = Constraints {
        clearance: 0.5,
        ..Constraints::default()
    };
    let config = PlanConfig::default();
    // (distance from the south fence, heading along it) → the clearance the route keeps.
    for (room, expected) in [(2.0, 0.5), (0.3, 0.25), (0.2, 0.0)] {
        let from = Pose::new(Point::new(10.0, room), 0.0);
        let mut rng = Pcg64Mcg::seed_from_u64(1);
        let route = config
            .plan_with_fallback(&area, from, &recovery, &c, &mut rng)
            .unwrap_or_else(|e| panic!("{room} m from the fence: {e}"));
        assert_eq!(route.clearance, expected, "{room} m from the fence");
        assert_eq!(route.points[0], from.position);
        let kept = Constraints {
            clearance: route.clearance,
            ..c
        };
        assert_eq!(
            check_route(&area, &route.checked_points(), &kept, Some(from.heading)),
            Ok(()),
            "{room} m from the fence"
        );
        let plain = config.plan(&area, from, &recovery, &c, &mut Pcg64Mcg::seed_from_u64(1));
        if expected == c.clearance {
            // Outside the band the fallback is the plain plan.
            assert_eq!(plain, Ok(route));
        } else {
            // Inside it no route can start with the full clearance.
            assert!(
                matches!(plain, Err(RecoveryError::NoRoute { .. })),
                "{room} m from the fence: {plain:?}"
            );
        }
    }
}

#[test]
fn the_fallback_does_not_retry_errors_a_smaller_clearance_cannot_cure() {
    let (area, recovery) = open_square();
    let c = Constraints {
        clearance: 0.5,
        ..Constraints::default()
    };
    let mut rng = Pcg64Mcg::seed_from_u64(1);
    let config = PlanConfig::default();
    let outside = Pose::new(Point::new(30.0, 5.0), 0.0);
    assert_eq!(
        config.plan_with_fallback(&area, outside, &recovery, &c, &mut rng),
        Err(RecoveryError::PoseOutside { x: 30.0, y: 5.0 })
    );
    let from = Pose::new(Point::new(10.0, 0.2), 0.0);
    let negative = Constraints {
        clearance: -1.0,
        ..c
    };
    assert!(matches!(
        config.plan_with_fallback(&area, from, &recovery, &negative, &mut rng),
        Err(RecoveryError::InvalidConstraints { .. })
    ));
    // Facing the fence 0.2 m away: not even without clearance is there a way out.
    let boxed_in = Pose::new(Point::new(10.0, 0.2), -std::f64::consts::FRAC_PI_2);
    assert!(matches!(
        config.plan_with_fallback(&area, boxed_in, &recovery, &c, &mut rng),
        Err(RecoveryError::NoRoute { .. })
    ));
}

/// A uniformly random pose inside the area closer than `band` metres to an edge, random
/// heading, from which the car can turn around without clearance.
fn band_pose(area: &Area, band: f64, rng: &mut Pcg64Mcg) -> Pose {
    let bbox = area.bbox();
    loop {
        let p = Point::new(
            rng.random_range(bbox.min.x..bbox.max.x),
            rng.random_range(bbox.min.y..bbox.max.y),
        );
        let heading = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
        let pose = Pose::new(p, heading);
        if area.contains_point(p)
            && area.boundary_distance(p) < band
            && can_turn_around(area, pose, &Constraints::default())
        {
            return pose;
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        failure_persistence: None,
        ..ProptestConfig::with_cases(24)
    })]

    /// From any pose inside the 0.5 m clearance band of a real area where the car can turn
    /// around, the fallback finds a route; it keeps a clearance no larger than the car's distance
    /// to the nearest edge and passes the check end to end with it.
    #[test]
    fn the_fallback_gets_the_car_home_from_inside_the_clearance_band(
        area in 0..REAL_AREAS.len(),
        seed in any::<u64>(),
    ) {
        let real = &REAL_AREAS[area];
        let area = area_of(real);
        let recovery = points(real.recovery_route);
        let c = Constraints { clearance: 0.5, ..Constraints::default() };
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let from = band_pose(&area, c.clearance, &mut rng);
        let route = PlanConfig::default()
            .plan_with_fallback(&area, from, &recovery, &c, &mut rng)
            .map_err(|e| TestCaseError::fail(format!("{} from {from:?}: {e}", real.name)))?;
        prop_assert!(route.clearance < c.clearance);
        prop_assert!(route.clearance <= area.boundary_distance(from.position));
        let kept = Constraints { clearance: route.clearance, ..c };
        prop_assert_eq!(
            check_route(&area, &route.checked_points(), &kept, Some(from.heading)),
            Ok(()),
            "{} from {:?}", real.name, from
        );
    }
}
