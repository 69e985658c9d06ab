//! Property tests of the generator on synthetic areas and the five real areas: every generated
//! segment keeps the constraints (checked with [`check_route`], joint with the tail included), the
//! margin continuation exists and is valid, the same seed gives the same trajectory, and a
//! failure is always a typed error.

use proptest::prelude::*;
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;

use crate::constraints::{Constraints, check_route};
use crate::generator::{GenerationError, Generator, GeneratorConfig, Pose, RouteTail, Strategy};
use crate::geometry::Point;
use crate::test_support::{Fixture, all_areas};

fn fixtures() -> &'static [Fixture] {
    static AREAS: std::sync::OnceLock<Vec<Fixture>> = std::sync::OnceLock::new();
    AREAS.get_or_init(all_areas)
}

fn strategy() -> impl proptest::strategy::Strategy<Value = Strategy> {
    prop_oneof![3 => Just(Strategy::Wedge), 1 => Just(Strategy::Reference)]
}

/// Checks one extension from `tail` against every constraint, the margin included.
fn assert_valid(
    fixture: &Fixture,
    tail: &RouteTail,
    n: usize,
    margin: usize,
    ext: &[Point],
    proof: &[Point],
    c: &Constraints,
) {
    assert_eq!(ext.len(), n, "{}: exactly n points", fixture.name);
    assert_eq!(
        proof.len(),
        margin,
        "{}: exactly ahead_margin margin points",
        fixture.name
    );
    let mut route = vec![tail.end];
    route.extend_from_slice(ext);
    route.extend_from_slice(proof);
    assert_eq!(
        check_route(&fixture.area, &route, c, Some(tail.heading)),
        Ok(()),
        "{}: extension from {:?}",
        fixture.name,
        tail
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    /// Every generated segment lies inside the fence and outside the cutouts, within the length
    /// and turn limits (joint with the existing route included), and the margin is valid too.
    #[test]
    fn every_extension_keeps_the_constraints(
        area in 0..7usize,
        seed in any::<u64>(),
        strategy in strategy(),
        sizes in proptest::collection::vec(1..=7usize, 1..6),
        margin in prop_oneof![Just(20usize), Just(15), Just(0)],
        clearance in prop_oneof![3 => Just(0.0), 1 => Just(0.2)],
    ) {
        let fixture = &fixtures()[area];
        let constraints = Constraints { clearance, ..Constraints::default() };
        let config = GeneratorConfig::default()
            .with_strategy(strategy)
            .with_ahead_margin(margin)
            .with_constraints(constraints);
        let generator = Generator::new(config).unwrap();
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let mut tail = RouteTail::from_points(&fixture.start_route).unwrap();
        for n in sizes {
            match generator.extend(&fixture.area, &tail, n, &mut rng) {
                Ok(ext) => {
                    assert_valid(fixture, &tail, n, margin, &ext.points, &ext.margin, &constraints);
                    prop_assert_eq!(ext.next_tail, tail.advanced(&ext.points));
                    tail = ext.next_tail;
                }
                // The reference may give up on the tight parking lots (and anything may with a
                // clearance); the wedge strategy never does without one.
                Err(GenerationError::GenerationFailed { outer_tries, .. }) => {
                    prop_assert!(strategy == Strategy::Reference || clearance > 0.0,
                        "{}: wedge strategy failed", fixture.name);
                    prop_assert!(outer_tries >= 1 && outer_tries <= config.outer_tries);
                    break;
                }
                Err(other) => prop_assert!(false, "unexpected error {other}"),
            }
        }
    }

    /// From any pose inside an area the generator returns a valid extension or a typed failure,
    /// never a short one.
    #[test]
    fn from_a_random_pose_the_result_is_valid_or_a_typed_failure(
        area in 0..7usize,
        seed in any::<u64>(),
        fx in 0.0..1.0f64,
        fy in 0.0..1.0f64,
        heading in -3.2..3.2f64,
        n in 1..=7usize,
    ) {
        let fixture = &fixtures()[area];
        let bbox = fixture.area.bbox();
        let (w, h) = bbox.size();
        let position = bbox.min + Point::new(fx * w, fy * h);
        prop_assume!(fixture.area.contains_point(position));
        let config = GeneratorConfig::default().with_ahead_margin(15);
        let generator = Generator::new(config).unwrap();
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let pose = Pose::new(position, heading);
        match generator.extend_from_pose(&fixture.area, pose, n, &mut rng) {
            Ok(ext) => assert_valid(
                fixture, &RouteTail::from_pose(pose), n, 15, &ext.points, &ext.margin,
                &config.constraints,
            ),
            Err(e) => prop_assert!(matches!(e, GenerationError::GenerationFailed { .. }), "{e}"),
        }
    }

    /// Same seed, same trajectory.
    #[test]
    fn the_same_seed_gives_the_same_trajectory(
        area in 0..7usize,
        seed in any::<u64>(),
        strategy in strategy(),
    ) {
        let fixture = &fixtures()[area];
        let generator = Generator::new(GeneratorConfig::default().with_strategy(strategy)).unwrap();
        let tail = RouteTail::from_points(&fixture.start_route).unwrap();
        let run = || {
            let mut rng = Pcg64Mcg::seed_from_u64(seed);
            generator.extend_many(&fixture.area, &tail, 12, 4, &mut rng)
        };
        prop_assert_eq!(run(), run());
    }

    /// The clearance check's fast path (edges far from the segment skipped) answers exactly as
    /// the distance to every edge does.
    #[test]
    fn the_clearance_check_agrees_with_the_distance_to_every_edge(
        area in 0..7usize,
        (u, v) in (0.0..1.0f64, 0.0..1.0f64),
        (heading, length) in (-4.0..4.0f64, 0.0..3.0f64),
        limit in 0.0..3.0f64,
    ) {
        let area = &fixtures()[area].area;
        let bbox = area.bbox();
        let a = Point::new(
            bbox.min.x + u * (bbox.max.x - bbox.min.x),
            bbox.min.y + v * (bbox.max.y - bbox.min.y),
        );
        let b = a + Point::from_heading(heading) * length;
        let distance = area.segment_boundary_distance(a, b);
        prop_assert_eq!(
            area.segment_boundary_distance_below(a, b, limit),
            (distance < limit).then_some(distance)
        );
    }
}
