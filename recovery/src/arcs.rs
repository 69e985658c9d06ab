//! The reference method's connector: arcs at near-maximum turn from both ends, joined by a line.
//!
//! From the car, arcs of `steps` segments of `step` metres turn `turn` per segment, left and right
//! (the 0-segment arc is the car's own pose). From the target, the same arcs are grown backwards,
//! so that driving them forward ends at the target along its heading. A point of a car arc and a
//! point of a target arc are joined by a straight line (split into pieces of at most
//! `max_segment`) when both turns into and out of the line are below the limit. Candidates are
//! tried shortest first; the first that stays in the area wins.

use trajgen::geometry::turn_angle;
use trajgen::{Area, Constraints, Point, Pose, check_route};

use crate::connect::{Connect, Scene};
use crate::join::Target;
use crate::polyline::{piece_is_valid, split_points};

/// The arcs-and-line connector (`docs/method.md#return-routes`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcConnector {
    /// Length of each arc segment, metres (0.7).
    pub step: f64,
    /// Turn per arc segment, radians (29.5°).
    pub turn: f64,
    /// Segments per arc (11).
    pub steps: usize,
    /// Most candidates checked against the area per connection, shortest first (64).
    pub tries: usize,
}

impl Default for ArcConnector {
    fn default() -> Self {
        Self {
            step: 0.7,
            turn: 29.5f64.to_radians(),
            steps: 11,
            tries: 64,
        }
    }
}

/// A point of an arc, the heading of the arc's segment at that point (arriving at it for a car
/// arc, leaving it for a target arc) and that heading's unit vector.
#[derive(Debug, Clone, Copy)]
struct ArcPoint {
    index: usize,
    side: f64,
    point: Point,
    heading: f64,
    direction: Point,
}

/// Whether a car at `pose` can turn around where it stands: a full circle of the tightest arcs
/// the constraints allow ([`ArcConnector::tight`]), to the left or to the right, stays in the area.
///
/// A sufficient condition for a return route to exist from a pose, not a necessary one: a car
/// 1 m from the fence but facing it in a narrow corner may have no forward way out at all.
pub fn can_turn_around(area: &Area, pose: Pose, c: &Constraints) -> bool {
    let arcs = ArcConnector::tight(c);
    [1.0, -1.0].into_iter().any(|side| {
        let mut points = vec![pose.position];
        for k in 1..=arcs.steps {
            let heading = pose.heading + side * arcs.turn * k as f64;
            let last = points[points.len() - 1];
            points.push(last + Point::from_heading(heading) * arcs.step);
        }
        check_route(area, &points, c, Some(pose.heading)).is_ok()
    })
}

/// `v` rotated by the angle whose sine and cosine are given.
fn rotate(v: Point, (sin, cos): (f64, f64)) -> Point {
    Point::new(cos * v.x - sin * v.y, sin * v.x + cos * v.y)
}

impl ArcConnector {
    /// The tightest arcs the constraints allow: `min_segment` steps (plus 2 %) turning just under
    /// the limit (by 0.5°), as many as make a full turn.
    pub fn tight(c: &Constraints) -> Self {
        let turn = c.max_turn - 0.5f64.to_radians().min(c.max_turn / 2.0);
        Self {
            step: c.min_segment * 1.02,
            turn,
            steps: (std::f64::consts::TAU / turn).ceil() as usize,
            tries: 12,
        }
    }

    /// Both arcs from a pose at the origin heading east, forward; the pose itself first.
    fn local_arcs(&self) -> Vec<ArcPoint> {
        let mut out = vec![ArcPoint {
            index: 0,
            side: 0.0,
            point: Point::default(),
            heading: 0.0,
            direction: Point::new(1.0, 0.0),
        }];
        for side in [1.0, -1.0] {
            let mut point = Point::default();
            for index in 1..=self.steps {
                let heading = side * self.turn * index as f64;
                let direction = Point::from_heading(heading);
                point = point + direction * self.step;
                out.push(ArcPoint {
                    index,
                    side,
                    point,
                    heading,
                    direction,
                });
            }
        }
        out
    }

    /// The local arcs placed at `pose`: driven forward from it, or (`backward`) grown backwards
    /// from it so that driving them forward ends at the pose (mirrored across the heading line
    /// and reversed).
    fn placed(local: &[ArcPoint], pose: Pose, backward: bool) -> Vec<ArcPoint> {
        let rotation = pose.heading.sin_cos();
        local
            .iter()
            .map(|a| {
                let (offset, direction, heading) = if backward {
                    (
                        Point::new(-a.point.x, a.point.y),
                        Point::new(a.direction.x, -a.direction.y),
                        -a.heading,
                    )
                } else {
                    (a.point, a.direction, a.heading)
                };
                ArcPoint {
                    point: pose.position + rotate(offset, rotation),
                    direction: rotate(direction, rotation),
                    heading: pose.heading + heading,
                    ..*a
                }
            })
            .collect()
    }

    /// The points of one arc from the pose up to `end` (excluded the pose, included `end`).
    fn arc_points(arcs: &[ArcPoint], end: &ArcPoint) -> impl Iterator<Item = Point> {
        arcs.iter()
            .filter(move |a| a.side == end.side && a.index >= 1 && a.index <= end.index)
            .map(|a| a.point)
    }

    /// The piece for one candidate: car arc to `a`, line, target arc from `b` to the target.
    fn piece(
        car: &[ArcPoint],
        target: &[ArcPoint],
        a: &ArcPoint,
        b: &ArcPoint,
        max_segment: f64,
    ) -> Vec<Point> {
        let mut points: Vec<Point> = Self::arc_points(car, a).collect();
        points.extend(split_points(a.point, b.point, max_segment));
        let mut back: Vec<Point> = Self::arc_points(target, b).collect();
        back.reverse();
        points.extend(back);
        points.push(target[0].point);
        points
    }
}

impl Connect for ArcConnector {
    fn connect(
        &self,
        scene: Scene<'_>,
        from: Pose,
        to: Target,
        max_length: f64,
        checks: &mut u64,
    ) -> Option<Vec<Point>> {
        let c = scene.constraints;
        let local = self.local_arcs();
        let car = Self::placed(&local, from, false);
        let target = Self::placed(&local, to.pose(), true);
        let cos_limit = c.max_turn.cos();
        let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
        for (i, a) in car.iter().enumerate() {
            for (j, b) in target.iter().enumerate() {
                let arcs_length = (a.index + b.index) as f64 * self.step;
                if arcs_length >= max_length {
                    continue;
                }
                let line = b.point - a.point;
                let distance = line.dot(line).sqrt();
                let length = arcs_length + distance;
                // A turn below the limit, without angles: the line's direction is within
                // `max_turn` of both arc headings (strictly; the check below is exact).
                let fits = distance >= c.min_segment
                    && length < max_length
                    && a.direction.dot(line) > distance * cos_limit
                    && b.direction.dot(line) > distance * cos_limit
                    && turn_angle(a.heading, line.heading()).abs() < c.max_turn
                    && turn_angle(line.heading(), b.heading).abs() < c.max_turn;
                if fits {
                    candidates.push((length, i, j));
                }
            }
        }
        candidates.sort_by(|x, y| x.0.total_cmp(&y.0));
        candidates
            .into_iter()
            .take(self.tries)
            .find_map(|(_, i, j)| {
                let points = Self::piece(&car, &target, &car[i], &target[j], c.max_segment);
                *checks += 1;
                piece_is_valid(scene.area, c, from, &points, to.next).then_some(points)
            })
    }
}
