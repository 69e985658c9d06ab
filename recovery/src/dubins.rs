//! Dubins paths turned into drivable polylines, and the lower bound on a route's length.
//!
//! A Dubins path of radius `R` is sampled at `n` equal arc-length steps `Δ = L / n`. A chord of
//! an arc of radius `R` spanning `Δ` is `2R sin(Δ / 2R)` long and turns `Δ / R` from the previous
//! one, so choosing `Δ ≤ min(max_segment, R · (max_turn − margin))` and
//! `2R sin(Δ / 2R) ≥ min_segment` keeps every segment and turn within the constraints (the first
//! and the last chord turn only half as much from the end headings). Every piece is still checked
//! with [`trajgen::check_route`] before use.

use dubins_paths::PathType;
use dubins_paths::f64::{DubinsPath, Intermediate, PosRot};
use trajgen::{Area, Constraints, Point, Pose};

use crate::connect::{Connect, Scene};
use crate::join::Target;
use crate::polyline::{distance, length, piece_is_valid};

/// Safety margin kept below the turn limit, radians (0.5°).
const TURN_MARGIN: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// A Dubins path's polyline can be a little shorter than the path: paths longer than
/// `max_length / CHORD_FACTOR` cannot give a piece shorter than `max_length`.
const CHORD_FACTOR: f64 = 0.95;

/// The turning radius of the lower bound: smoothing every corner of a polyline by an arc tangent
/// to both segments at `min_segment / 2` from the vertex gives arcs of radius at least
/// `(min_segment / 2) / tan(max_turn / 2)` (1.12 m by default).
pub(crate) fn bound_radius(c: &Constraints) -> f64 {
    (c.min_segment / 2.0) / (c.max_turn / 2.0).tan()
}

/// A lower bound on the length of any drivable route from the car's pose `from` to the joint's
/// pose `to`.
///
/// Proof sketch: smooth every corner of the route (the turn from the car's heading at the first
/// point and the turn into the recovery segment at the last included) by an arc tangent to both
/// segments at `a = min_segment / 2` from the vertex, extending the route by `a` before its start
/// along the car's heading and by `a` after its end along the joint's heading. Each arc is no
/// longer than the corner it replaces, and its radius is at least [`bound_radius`]; the smooth
/// curve is at most `2a` longer than the route and is a path of bounded curvature between the two
/// shifted poses, so it is no shorter than the Dubins path between them. Hence
/// `length ≥ Dubins(from − a, to + a) − 2a`, and `length ≥` the straight-line distance.
pub(crate) fn lower_bound(from: Pose, to: Pose, c: &Constraints) -> f64 {
    let a = c.min_segment / 2.0;
    let straight = from.position.dist(to.position);
    let start = Pose::new(
        from.position - Point::from_heading(from.heading) * a,
        from.heading,
    );
    let end = Pose::new(
        to.position + Point::from_heading(to.heading) * a,
        to.heading,
    );
    // A radius that underflowed to 0 (a minimum segment of 5e-324 m) or is not finite bounds
    // nothing, and the Dubins paths panic on it: the straight line is the bound then.
    let radius = bound_radius(c);
    if !(radius > 0.0 && radius.is_finite()) {
        return straight;
    }
    let dubins = DubinsPath::shortest_from(pos_rot(start), pos_rot(end), radius)
        .map_or(0.0, |p| p.length() - 2.0 * a);
    straight.max(dubins)
}

fn pos_rot(pose: Pose) -> PosRot {
    PosRot::from_floats(pose.position.x, pose.position.y, pose.heading)
}

/// Samples Dubins paths of one radius into drivable polylines.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Discretiser {
    radius: f64,
    step_min: f64,
    step_max: f64,
}

impl Discretiser {
    /// The discretiser for `radius`, or `None` when no step fits the constraints.
    pub fn new(radius: f64, c: &Constraints) -> Option<Self> {
        let half_chord = c.min_segment / (2.0 * radius);
        if radius.is_nan() || radius <= 0.0 || half_chord >= 1.0 {
            return None;
        }
        let step_min = 2.0 * radius * half_chord.asin() * (1.0 + 1e-9);
        let step_max = c.max_segment.min(radius * (c.max_turn - TURN_MARGIN));
        (step_min < step_max).then_some(Self {
            radius,
            step_min,
            step_max,
        })
    }

    /// The points of `path`'s polyline after its start and before its end, or `None` when the
    /// path is too short for any step that fits.
    fn samples(&self, path: &DubinsPath) -> Option<impl Iterator<Item = Point>> {
        let total = path.length();
        let steps = (total / self.step_max).ceil().max(1.0);
        let step = total / steps;
        if step < self.step_min {
            return None;
        }
        let path = *path;
        Some((1..steps as usize).map(move |i| {
            let q = path.sample(step * i as f64);
            Point::new(q.x(), q.y())
        }))
    }

    /// The polyline of `path` (points after its start, ending exactly at `end`), or `None` when
    /// the path is too short for any step that fits.
    #[cfg(test)]
    pub fn points(&self, path: &DubinsPath, end: Point) -> Option<Vec<Point>> {
        let mut points: Vec<Point> = self.samples(path)?.collect();
        points.push(end);
        Some(points)
    }

    /// The polyline of `path` as [`Self::points`] gives it, sampled one point at a time and
    /// given up at the first point outside `area` (such a piece is never valid:
    /// [`trajgen::check_route`] checks every point), which spares sampling the rest of a path
    /// that leaves the area early.
    fn points_within(&self, path: &DubinsPath, end: Point, area: &Area) -> Sampled {
        let Some(samples) = self.samples(path) else {
            return Sampled::TooShort;
        };
        let mut points = Vec::new();
        for p in samples.chain(std::iter::once(end)) {
            if !area.contains_point(p) {
                return Sampled::Leaves;
            }
            points.push(p);
        }
        Sampled::Points(points)
    }
}

/// A Dubins path sampled by [`Discretiser::points_within`].
enum Sampled {
    /// Too short for any step that fits.
    TooShort,
    /// A point of it is outside the area.
    Leaves,
    /// Its polyline, inside the area point by point.
    Points(Vec<Point>),
}

/// Connects poses by discretised Dubins paths of several radii, shortest first.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DubinsConnector {
    discretisers: Vec<Discretiser>,
    tries: usize,
}

impl DubinsConnector {
    /// A connector trying `radii` (those that fit the constraints), at most `tries` paths per
    /// connection, shortest first.
    pub fn new(radii: &[f64], c: &Constraints, tries: usize) -> Self {
        Self {
            tries,
            discretisers: radii
                .iter()
                .filter_map(|&r| Discretiser::new(r, c))
                .collect(),
        }
    }

    /// Every Dubins path from `from` to `to` over all radii and words, shortest first.
    fn candidates(&self, from: Pose, to: Pose) -> Vec<(DubinsPath, Discretiser)> {
        let (q0, q1) = (pos_rot(from), pos_rot(to));
        let mut paths: Vec<(DubinsPath, Discretiser)> = self
            .discretisers
            .iter()
            .flat_map(|d| {
                let intermediate = Intermediate::new(q0, q1, d.radius);
                PathType::ALL.into_iter().filter_map(move |word| {
                    let param = intermediate.word(word).ok()?;
                    let path = DubinsPath {
                        qi: q0,
                        rho: d.radius,
                        param,
                        path_type: word,
                    };
                    Some((path, *d))
                })
            })
            .collect();
        paths.sort_by(|a, b| a.0.length().total_cmp(&b.0.length()));
        paths
    }
}

impl Connect for DubinsConnector {
    fn connect(
        &self,
        scene: Scene<'_>,
        from: Pose,
        to: Target,
        max_length: f64,
        checks: &mut u64,
    ) -> Option<Vec<Point>> {
        let candidates = self.candidates(from, to.pose());
        for (path, discretiser) in candidates.into_iter().take(self.tries) {
            if path.length() * CHORD_FACTOR >= max_length {
                return None;
            }
            let points = match discretiser.points_within(&path, to.point, scene.area) {
                Sampled::TooShort => continue,
                Sampled::Leaves => {
                    *checks += 1;
                    continue;
                }
                Sampled::Points(points) => points,
            };
            let piece_length = distance(from.position, points[0]) + length(&points);
            if piece_length >= max_length {
                continue;
            }
            *checks += 1;
            if piece_is_valid(scene.area, scene.constraints, from, &points, to.next) {
                return Some(points);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use trajgen::{Area, Polygon, check_route};

    fn open_field() -> Area {
        let fence = Polygon::new(vec![
            Point::new(-100.0, -100.0),
            Point::new(100.0, -100.0),
            Point::new(100.0, 100.0),
            Point::new(-100.0, 100.0),
        ])
        .unwrap();
        Area::new(fence, vec![]).unwrap()
    }

    #[test]
    fn bound_radius_of_the_method_is_about_1_12_m() {
        let r = bound_radius(&Constraints::default());
        assert!((r - 1.1196).abs() < 1e-3, "{r}");
    }

    /// A minimum segment so short that the bound's radius underflows to 0 (`segment_min_m =
    /// 5e-324` in a scenario, found by the scenario fuzzer): the straight line, not a panic in
    /// the Dubins paths ("rho must be greater than 0").
    #[test]
    fn a_radius_that_underflows_bounds_by_the_straight_line() {
        let c = Constraints {
            min_segment: 5e-324,
            ..Constraints::default()
        };
        assert_eq!(bound_radius(&c), 0.0);
        let from = Pose::new(Point::new(0.0, 0.0), 0.0);
        let behind = Pose::new(Point::new(-3.0, 0.0), 0.0);
        assert_eq!(lower_bound(from, behind, &c), 3.0);
    }

    #[test]
    fn lower_bound_is_the_straight_line_when_aligned() {
        let c = Constraints::default();
        let from = Pose::new(Point::new(0.0, 0.0), 0.0);
        let to = Pose::new(Point::new(7.0, 0.0), 0.0);
        assert!((lower_bound(from, to, &c) - 7.0).abs() < 1e-9);
        let behind = Pose::new(Point::new(-3.0, 0.0), 0.0);
        assert!(lower_bound(from, behind, &c) > 3.0 + 2.0 * bound_radius(&c));
    }

    /// The tightest drivable U-turn (segments of `min_segment` turning just under the limit,
    /// starting with a full turn at the car) is still no shorter than the bound.
    #[test]
    fn the_tightest_u_turn_respects_the_lower_bound() {
        let c = Constraints::default();
        let turn = c.max_turn - 1e-6;
        let mut points = vec![Point::new(0.0, 0.0)];
        let mut heading = 0.0;
        for _ in 0..6 {
            heading += turn;
            let last = *points.last().unwrap();
            points.push(last + Point::from_heading(heading) * c.min_segment);
        }
        let from = Pose::new(points[0], 0.0);
        let to = Pose::new(*points.last().unwrap(), heading + turn);
        let bound = lower_bound(from, to, &c);
        assert!(length(&points) >= bound, "{} < {bound}", length(&points));
        assert!(
            length(&points) < 1.3 * bound,
            "the bound is not far off: {bound}"
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            failure_persistence: None,
            ..ProptestConfig::with_cases(300)
        })]
        /// Every discretised word of every radius keeps the segment lengths and the turn limit,
        /// from the start heading to the joint into the target's next point.
        #[test]
        fn discretised_dubins_paths_keep_every_constraint(
            x in -20.0..20.0f64, y in -20.0..20.0f64,
            h0 in -3.2..3.2f64, h1 in -3.2..3.2f64,
            radius in prop::sample::select(vec![1.5, 2.0, 3.0, 4.5]),
        ) {
            let c = Constraints::default();
            let area = open_field();
            let discretiser = Discretiser::new(radius, &c).unwrap();
            let from = Pose::new(Point::new(0.0, 0.0), h0);
            let end = Point::new(x, y);
            let next = end + Point::from_heading(h1);
            let intermediate = Intermediate::new(pos_rot(from), PosRot::from_floats(x, y, h1), radius);
            for word in PathType::ALL {
                let Ok(param) = intermediate.word(word) else { continue };
                let path = DubinsPath { qi: pos_rot(from), rho: radius, param, path_type: word };
                let Some(points) = discretiser.points(&path, end) else { continue };
                let mut route = vec![from.position];
                route.extend_from_slice(&points);
                route.push(next);
                prop_assert_eq!(check_route(&area, &route, &c, Some(h0)), Ok(()), "{:?}", word);
            }
        }
    }
}
