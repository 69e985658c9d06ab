//! Where a return route may join the recovery route, and what is left to drive after it.
//!
//! A return route *joins* the recovery route at a point `J` on a recovery segment `k` (from
//! recovery point `k` to `k + 1`): its last point is `J`, and the car then drives on to recovery
//! point `k + 1` and along the rest of the recovery route. `J` is placed so that the stretch
//! `J → k + 1` is itself a valid segment (between `min_segment` and `max_segment` long, inside the
//! area): the return route followed by recovery point `k + 1` then passes
//! [`trajgen::check_route`] end to end, the turn at the joint included. No shorter joining stub is
//! ever needed. Recovery segments shorter than `min_segment` are not joined.

use trajgen::{Area, Constraints, Point, Pose, check_route};

use crate::error::RecoveryError;

/// Spacing of the join points along a recovery segment, metres.
const JOIN_SPACING: f64 = 0.25;

/// Spacing of the points along the recovery route used for the total lower bound, metres.
const BOUND_SPACING: f64 = 0.1;

/// A point where the return route joins the recovery route.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Join {
    /// Index of the recovery segment joined (from recovery point `segment` to `segment + 1`).
    pub segment: usize,
    /// The joining point `J`: the return route's last point, on the recovery segment.
    pub point: Point,
    /// Recovery point `segment + 1`: where the car drives next, straight on from `J`.
    pub next: Point,
    /// Length of the recovery route still to drive from `J` to its end, metres.
    pub remaining: f64,
}

impl Join {
    /// The pose at the joint: at `J`, heading along the recovery segment.
    pub fn pose(&self) -> Pose {
        Pose::new(self.point, (self.next - self.point).heading())
    }

    /// As a connection target.
    pub(crate) fn target(&self) -> Target {
        Target {
            point: self.point,
            next: self.next,
        }
    }
}

/// Where a connection must end: at `point`, so that the route can continue straight to `next`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Target {
    /// The last point of the connection.
    pub point: Point,
    /// The point after it (already part of the route); fixes the heading at `point`.
    pub next: Point,
}

impl Target {
    /// The pose at `point`, heading towards `next`.
    pub fn pose(&self) -> Pose {
        Pose::new(self.point, (self.next - self.point).heading())
    }
}

/// The recovery route prepared for planning: its joins, and sample poses for the lower bound.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RecoveryRoute {
    /// Every admissible join, latest along the route first (the least left to drive).
    pub joins: Vec<Join>,
    /// Poses along the whole route with the length left after each, for the total lower bound.
    pub samples: Vec<(Pose, f64)>,
}

impl RecoveryRoute {
    /// Prepares `points` (at least two, finite) for joining in `area`.
    pub fn new(area: &Area, points: &[Point], c: &Constraints) -> Result<Self, RecoveryError> {
        if points.len() < 2 {
            return Err(RecoveryError::InvalidRecoveryRoute {
                reason: "a recovery route needs at least two points",
            });
        }
        if points.iter().any(|p| !p.is_finite()) {
            return Err(RecoveryError::InvalidRecoveryRoute {
                reason: "the recovery route has a non-finite coordinate",
            });
        }
        let remaining = remaining_after_each_point(points);
        let mut joins: Vec<Join> = (0..points.len() - 1)
            .flat_map(|k| segment_joins(area, points, k, remaining[k + 1], c))
            .collect();
        if joins.is_empty() {
            return Err(RecoveryError::InvalidRecoveryRoute {
                reason: "no point of the recovery route can be joined (every segment is shorter \
                         than min_segment, leaves the area or comes closer to an edge than the \
                         clearance)",
            });
        }
        joins.sort_by(|a, b| a.remaining.total_cmp(&b.remaining));
        let samples = bound_samples(points, &remaining);
        Ok(Self { joins, samples })
    }

    /// The join where the most recovery route is left (the earliest): the method's single target.
    pub fn earliest(&self) -> &Join {
        &self.joins[self.joins.len() - 1]
    }

    /// The same route with the earliest join as the only one.
    pub fn only_earliest(self) -> Self {
        Self {
            joins: vec![*self.earliest()],
            samples: self.samples,
        }
    }
}

/// Length of the route from each point to the end.
fn remaining_after_each_point(points: &[Point]) -> Vec<f64> {
    let mut remaining = vec![0.0; points.len()];
    for k in (0..points.len() - 1).rev() {
        remaining[k] = remaining[k + 1] + points[k].dist(points[k + 1]);
    }
    remaining
}

/// Admissible joins on segment `k`: points `J` whose stretch `J → k + 1` is a valid segment.
fn segment_joins(
    area: &Area,
    points: &[Point],
    k: usize,
    remaining_after: f64,
    c: &Constraints,
) -> Vec<Join> {
    let (a, b) = (points[k], points[k + 1]);
    let length = a.dist(b);
    if length < c.min_segment {
        return Vec::new();
    }
    let direction = (b - a) * (1.0 / length);
    let longest = length.min(c.max_segment);
    let count = ((longest - c.min_segment) / JOIN_SPACING).floor() as usize;
    (0..=count)
        .map(|i| (c.min_segment + i as f64 * JOIN_SPACING).min(longest))
        .map(|d| Join {
            segment: k,
            point: b - direction * d,
            next: b,
            remaining: remaining_after + d,
        })
        .filter(|j| check_route(area, &[j.point, j.next], c, None).is_ok())
        .collect()
}

/// Poses every [`BOUND_SPACING`] metres along the route, each with the length left after it.
fn bound_samples(points: &[Point], remaining: &[f64]) -> Vec<(Pose, f64)> {
    let mut samples = Vec::new();
    for k in 0..points.len() - 1 {
        let (a, b) = (points[k], points[k + 1]);
        let length = a.dist(b);
        if length == 0.0 {
            continue;
        }
        let heading = (b - a).heading();
        let count = (length / BOUND_SPACING).ceil() as usize;
        for i in 0..count {
            let t = i as f64 / count as f64;
            let pose = Pose::new(a + (b - a) * t, heading);
            samples.push((pose, remaining[k + 1] + length * (1.0 - t)));
        }
    }
    samples
}
