//! The real test areas: the pure crates' test fixtures agree with the bundled scenarios, and return
//! routes are found and drivable from random poses in every bundled area.

use proptest::prelude::*;
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;
use scenarios::{Scenario, bundled};
use trajgen::test_areas::REAL_AREAS;
use trajgen::{Point, Pose, check_route};

fn scenario(name: &str) -> Scenario {
    bundled::load(name)
        .expect("bundled scenarios load")
        .scenario
}

fn points(raw: &[[f64; 2]]) -> Vec<Point> {
    raw.iter().copied().map(Point::from).collect()
}

#[test]
fn the_fixtures_of_the_pure_crates_are_the_bundled_areas() {
    for real in REAL_AREAS {
        let s = scenario(real.name);
        assert_eq!(
            s.area.fence().vertices(),
            points(real.fence),
            "{}",
            real.name
        );
        let cutouts: Vec<Vec<Point>> = s
            .area
            .cutouts()
            .iter()
            .map(|c| c.vertices().to_vec())
            .collect();
        let fixture: Vec<Vec<Point>> = real.cutouts.iter().map(|c| points(c)).collect();
        assert_eq!(cutouts, fixture, "{}", real.name);
        assert_eq!(
            s.start_route.positions(),
            points(real.start_route),
            "{}",
            real.name
        );
        assert_eq!(
            s.recovery_route.positions(),
            points(real.recovery_route),
            "{}",
            real.name
        );
    }
    let mut names: Vec<&str> = REAL_AREAS.iter().map(|r| r.name).collect();
    names.sort_unstable();
    assert_eq!(names, bundled::names());
}

/// A pose with at least 1 m clearance from every edge from which the car can turn around, drawn
/// from a fraction of the fence's bounding box; `None` when that spot is not such a pose.
fn pose_at(s: &Scenario, fx: f64, fy: f64, heading: f64) -> Option<Pose> {
    let b = s.area.bbox();
    let p = Point::new(
        b.min.x + fx * (b.max.x - b.min.x),
        b.min.y + fy * (b.max.y - b.min.y),
    );
    let pose = Pose::new(p, heading);
    let clear = s.area.contains_point(p) && s.area.boundary_distance(p) >= 1.0;
    (clear && recovery::can_turn_around(&s.area, pose, &s.constraints())).then_some(pose)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// From any pose with 1 m clearance where the car can turn, a return route is found, and the
    /// route with its joint onto the recovery route is drivable end to end.
    #[test]
    fn a_return_route_is_found_and_drivable_from_random_poses(
        area in 0..bundled::names().len(),
        fx in 0.0..1.0f64,
        fy in 0.0..1.0f64,
        heading in -std::f64::consts::PI..std::f64::consts::PI,
        seed in any::<u64>(),
    ) {
        let s = scenario(bundled::names()[area]);
        let pose = pose_at(&s, fx, fy, heading)
            .ok_or_else(|| TestCaseError::reject("not a clear pose from which the car can turn"))?;
        let recovery_route = s.recovery_route.positions();
        let c = s.constraints();
        let route = recovery::plan(&s.area, pose, &recovery_route, &c, &mut Pcg64Mcg::seed_from_u64(seed))
            .map_err(|e| TestCaseError::fail(format!("{}: {e}", s.name)))?;
        prop_assert_eq!(route.points[0], pose.position);
        check_route(&s.area, &route.checked_points(), &c, Some(pose.heading))
            .map_err(|v| TestCaseError::fail(format!("{}: {v}", s.name)))?;
        // A route along the straight line measures the bound up to rounding.
        let q = &route.quality;
        prop_assert!(q.length >= q.lower_bound * (1.0 - 1e-12), "{}: {pose:?}: {q:?}", s.name);
    }
}
