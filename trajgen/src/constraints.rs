//! The constraints every drivable trajectory satisfies, and the check that a route meets them.
//!
//! A route is a polyline. It is drivable in an [`Area`] when every segment is between
//! [`Constraints::min_segment`] and [`Constraints::max_segment`] long, the heading changes by less
//! than [`Constraints::max_turn`] at every inner vertex, and every segment lies entirely inside the
//! fence and outside every cutout (keeping [`Constraints::clearance`] from every edge when set).

use thiserror::Error;

use crate::geometry::{Area, Point, turn_angle};

/// Limits on a trajectory's shape. The defaults are the method's
/// (`docs/method.md#drivable-trajectories`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Constraints {
    /// Shortest segment, metres (default 0.6).
    pub min_segment: f64,
    /// Longest segment, metres (default 2.0).
    pub max_segment: f64,
    /// Largest heading change between consecutive segments, radians; a turn must be strictly
    /// smaller (default 30°).
    pub max_turn: f64,
    /// Distance every segment keeps from every boundary edge, metres (default 0: none).
    pub clearance: f64,
}

impl Default for Constraints {
    fn default() -> Self {
        Self {
            min_segment: 0.6,
            max_segment: 2.0,
            max_turn: 30f64.to_radians(),
            clearance: 0.0,
        }
    }
}

/// The first way in which a route breaks the [`Constraints`].
///
/// Segment `i` runs from point `i` to point `i + 1`; the turn at vertex `i` is between segments
/// `i − 1` and `i`.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum Violation {
    /// A coordinate is NaN or infinite.
    #[error("point {index} has a non-finite coordinate")]
    NonFinite {
        /// Index of the point.
        index: usize,
    },
    /// A point is not strictly inside the drivable region.
    #[error("point {index} at ({x:.3}, {y:.3}) is outside the area")]
    PointOutside {
        /// Index of the point.
        index: usize,
        /// East coordinate.
        x: f64,
        /// North coordinate.
        y: f64,
    },
    /// A segment meets the fence or a cutout.
    #[error("segment {index} leaves the area (it meets the fence or a cutout)")]
    LeavesArea {
        /// Index of the segment.
        index: usize,
    },
    /// A segment comes closer to a boundary edge than the clearance.
    #[error("segment {index} comes within {distance:.3} m of an edge (clearance {clearance:.3} m)")]
    TooCloseToEdge {
        /// Index of the segment.
        index: usize,
        /// Its distance to the nearest edge, metres.
        distance: f64,
        /// The required clearance, metres.
        clearance: f64,
    },
    /// A segment is shorter than the minimum.
    #[error("segment {index} is {length:.3} m long, shorter than {min:.3} m")]
    SegmentTooShort {
        /// Index of the segment.
        index: usize,
        /// Its length, metres.
        length: f64,
        /// The minimum, metres.
        min: f64,
    },
    /// A segment is longer than the maximum.
    #[error("segment {index} is {length:.3} m long, longer than {max:.3} m")]
    SegmentTooLong {
        /// Index of the segment.
        index: usize,
        /// Its length, metres.
        length: f64,
        /// The maximum, metres.
        max: f64,
    },
    /// The heading changes too much at a vertex.
    #[error("the route turns {turn_deg:.1}° at point {vertex}, the limit is {max_deg:.1}°")]
    TurnTooSharp {
        /// Index of the vertex where the turn happens (for the first segment of a route checked
        /// with an initial heading, vertex 0).
        vertex: usize,
        /// The turn, degrees (absolute).
        turn_deg: f64,
        /// The limit, degrees.
        max_deg: f64,
    },
}

/// Checks a whole route and returns the first violation.
///
/// `initial_heading`, when given, is the heading (radians) the route must continue from: the turn
/// from it into the first segment is checked too (for a route that extends another, or starts at a
/// car's pose).
pub fn check_route(
    area: &Area,
    points: &[Point],
    constraints: &Constraints,
    initial_heading: Option<f64>,
) -> Result<(), Violation> {
    match route_violations(area, points, constraints, initial_heading).next() {
        Some(v) => Err(v),
        None => Ok(()),
    }
}

/// Every violation of a route, in order along the route (lazily).
pub fn route_violations<'a>(
    area: &'a Area,
    points: &'a [Point],
    constraints: &'a Constraints,
    initial_heading: Option<f64>,
) -> impl Iterator<Item = Violation> + 'a {
    let finite = points
        .iter()
        .enumerate()
        .filter(|(_, p)| !p.is_finite())
        .map(|(index, _)| Violation::NonFinite { index });
    let inside = points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.is_finite() && !area.contains_point(**p))
        .map(|(index, p)| Violation::PointOutside {
            index,
            x: p.x,
            y: p.y,
        });
    let segments = points
        .windows(2)
        .enumerate()
        .flat_map(move |(index, w)| segment_violations(area, index, w[0], w[1], constraints));
    let turns = (0..points.len().saturating_sub(1)).filter_map(move |index| {
        let heading = (points[index + 1] - points[index]).heading();
        let previous = if index == 0 {
            initial_heading?
        } else {
            (points[index] - points[index - 1]).heading()
        };
        turn_violation(index, previous, heading, constraints)
    });
    finite.chain(inside).chain(segments).chain(turns)
}

/// The violation of a turn from heading `previous` to heading `next` at `vertex`, if any.
pub fn turn_violation(
    vertex: usize,
    previous: f64,
    next: f64,
    constraints: &Constraints,
) -> Option<Violation> {
    let turn = turn_angle(previous, next).abs();
    (turn >= constraints.max_turn).then(|| Violation::TurnTooSharp {
        vertex,
        turn_deg: turn.to_degrees(),
        max_deg: constraints.max_turn.to_degrees(),
    })
}

fn segment_violations(
    area: &Area,
    index: usize,
    a: Point,
    b: Point,
    constraints: &Constraints,
) -> Option<Violation> {
    let length = a.dist(b);
    if length < constraints.min_segment {
        return Some(Violation::SegmentTooShort {
            index,
            length,
            min: constraints.min_segment,
        });
    }
    if length > constraints.max_segment {
        return Some(Violation::SegmentTooLong {
            index,
            length,
            max: constraints.max_segment,
        });
    }
    if area.segment_meets_boundary(a, b) {
        return Some(Violation::LeavesArea { index });
    }
    if constraints.clearance > 0.0
        && let Some(distance) = area.segment_boundary_distance_below(a, b, constraints.clearance)
    {
        return Some(Violation::TooCloseToEdge {
            index,
            distance,
            clearance: constraints.clearance,
        });
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Polygon;

    fn area() -> Area {
        let sq = |x0: f64, y0: f64, s: f64| {
            Polygon::new(vec![
                Point::new(x0, y0),
                Point::new(x0 + s, y0),
                Point::new(x0 + s, y0 + s),
                Point::new(x0, y0 + s),
            ])
            .unwrap()
        };
        Area::new(sq(0., 0., 20.), vec![sq(8., 8., 4.)]).unwrap()
    }

    #[test]
    fn a_gentle_route_inside_the_area_passes() {
        let route = [
            Point::new(2., 2.),
            Point::new(3.5, 2.),
            Point::new(5., 2.3),
            Point::new(6.4, 2.9),
        ];
        assert_eq!(
            check_route(&area(), &route, &Constraints::default(), Some(0.0)),
            Ok(())
        );
    }

    #[test]
    fn each_violation_is_named_with_its_index() {
        let c = Constraints::default();
        let a = area();
        let p = Point::new;
        assert!(matches!(
            check_route(&a, &[p(2., 2.), p(2.3, 2.)], &c, None),
            Err(Violation::SegmentTooShort { index: 0, .. })
        ));
        assert!(matches!(
            check_route(&a, &[p(2., 2.), p(4., 2.), p(6.5, 2.)], &c, None),
            Err(Violation::SegmentTooLong { index: 1, .. })
        ));
        assert!(matches!(
            check_route(&a, &[p(2., 2.), p(3.5, 2.), p(4., 3.)], &c, None),
            Err(Violation::TurnTooSharp { vertex: 1, .. })
        ));
        assert!(matches!(
            check_route(&a, &[p(7.5, 8.6), p(8.6, 7.5)], &c, None),
            Err(Violation::LeavesArea { index: 0 })
        ));
        assert!(matches!(
            check_route(
                &a,
                &[p(2., 2.), p(3.5, 2.)],
                &c,
                Some(std::f64::consts::FRAC_PI_2)
            ),
            Err(Violation::TurnTooSharp { vertex: 0, .. })
        ));
        let clear = Constraints {
            clearance: 1.5,
            ..c
        };
        assert!(matches!(
            check_route(&a, &[p(1., 5.), p(2.5, 5.)], &clear, None),
            Err(Violation::TooCloseToEdge { index: 0, .. })
        ));
    }
}
