//! The shortening pass (`docs/method.md#return-routes`): remove runs of points, interpolate, take
//! shortcuts, repeat until no gain.
//!
//! Every change keeps the route drivable: each candidate is checked with
//! [`trajgen::check_route`] on the changed piece together with its neighbours (the turn from the
//! car's heading at the start and the joint into the recovery route at the end included).

use trajgen::{Point, Pose, check_route};

use crate::connect::{Connect, Scene};
use crate::dubins::lower_bound;
use crate::join::Target;
use crate::polyline::{distance, heading_at, interpolate, length, piece_is_valid};

/// The constants of the shortening pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shortening {
    /// Longest segment after interpolation, metres (1.5).
    pub max_piece: f64,
    /// Smallest gain a shortcut must bring, metres (0.02; positive, so the pass ends).
    pub min_gain: f64,
    /// Most rounds of remove–interpolate–shortcut (20).
    pub max_rounds: u32,
}

/// A connector for shortcuts and how far (counted in points) its shortcuts reach.
pub(crate) struct Shortcuts<'a> {
    /// The connector.
    pub connector: &'a dyn Connect,
    /// Farthest point a shortcut from a point reaches, counted in points.
    pub window: usize,
}

impl Default for Shortening {
    fn default() -> Self {
        Self {
            max_piece: 1.5,
            min_gain: 0.02,
            max_rounds: 20,
        }
    }
}

/// A route being shortened: the car's pose, the points (the car's position first, the joining
/// point last) and the recovery point after the joint.
pub(crate) struct Draft<'a> {
    /// Area and constraints.
    pub scene: Scene<'a>,
    /// The car's pose.
    pub start: Pose,
    /// The route, car's position first.
    pub points: Vec<Point>,
    /// The recovery point the route continues to.
    pub next: Point,
    /// Candidate pieces checked so far.
    pub checks: u64,
}

impl Draft<'_> {
    /// Runs the whole pass, with each of `shortcuts` in turn in every round.
    pub fn shorten(&mut self, shortcuts: &[Shortcuts<'_>], shortening: &Shortening) {
        for _ in 0..shortening.max_rounds {
            let before = length(&self.points);
            self.remove_runs();
            self.interpolate(shortening.max_piece);
            for s in shortcuts {
                self.shortcuts(s, shortening.min_gain);
            }
            if before - length(&self.points) <= shortening.min_gain {
                break;
            }
        }
        self.remove_runs();
    }

    /// The point after `i` (the recovery point after the last).
    fn after(&self, i: usize) -> Point {
        self.points.get(i + 1).copied().unwrap_or(self.next)
    }

    fn pose_at(&self, i: usize) -> Pose {
        Pose::new(self.points[i], heading_at(self.start, &self.points, i))
    }

    /// Removes, from each point on, the longest run of following points whose removal keeps the
    /// route drivable.
    fn remove_runs(&mut self) {
        let c = *self.scene.constraints;
        let mut i = 0;
        while i + 2 < self.points.len() {
            let from = self.pose_at(i);
            let keep = (i + 2..self.points.len()).rev().find(|&j| {
                let d = distance(from.position, self.points[j]);
                if d < c.min_segment || d > c.max_segment {
                    return false;
                }
                self.checks += 1;
                piece_is_valid(self.scene.area, &c, from, &[self.points[j]], self.after(j))
            });
            if let Some(j) = keep {
                self.points.drain(i + 1..j);
            }
            i += 1;
        }
    }

    /// Splits long segments (kept only when the result is still drivable).
    fn interpolate(&mut self, max_piece: f64) {
        let c = self.scene.constraints;
        let mut denser = interpolate(&self.points, max_piece.min(c.max_segment));
        denser.push(self.next);
        if check_route(self.scene.area, &denser, c, Some(self.start.heading)).is_ok() {
            denser.pop();
            self.points = denser;
        }
    }

    /// From each point, replaces the farthest stretch (within the window) that `connector` can
    /// shorten by more than the minimum gain.
    fn shortcuts(&mut self, shortcuts: &Shortcuts<'_>, min_gain: f64) {
        let mut i = 0;
        while i + 2 < self.points.len() {
            let from = self.pose_at(i);
            let reach = i
                .saturating_add(shortcuts.window)
                .min(self.points.len() - 1);
            for j in (i + 2..=reach).rev() {
                let current = length(&self.points[i..=j]);
                let to = Target {
                    point: self.points[j],
                    next: self.after(j),
                };
                // No drivable piece is shorter than the lower bound: skip hopeless shortcuts.
                let bound = distance(from.position, to.point).max(lower_bound(
                    from,
                    to.pose(),
                    self.scene.constraints,
                ));
                if bound >= current - min_gain {
                    continue;
                }
                let piece = shortcuts.connector.connect(
                    self.scene,
                    from,
                    to,
                    current - min_gain,
                    &mut self.checks,
                );
                if let Some(piece) = piece {
                    self.points.splice(i + 1..=j, piece);
                    break;
                }
            }
            i += 1;
        }
    }
}
