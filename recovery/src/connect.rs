//! Connectors: ways to join a pose to a target by a drivable piece of route.

use trajgen::{Area, Constraints, Point, Pose};

use crate::join::Target;

/// The area and the constraints every planned piece must respect.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Scene<'a> {
    /// Where the car may drive.
    pub area: &'a Area,
    /// Segment lengths, turn limit and clearance.
    pub constraints: &'a Constraints,
}

/// A way of connecting a pose to a target.
pub(crate) trait Connect {
    /// The points after `from.position` up to and including `to.point`, such that
    /// `from.position → points… → to.next` is drivable (the turn from `from.heading` and the turn
    /// into `to.next` included) and the points are shorter than `max_length`. The shortest such
    /// piece this connector knows, or `None`. `checks` counts the candidate pieces checked.
    fn connect(
        &self,
        scene: Scene<'_>,
        from: Pose,
        to: Target,
        max_length: f64,
        checks: &mut u64,
    ) -> Option<Vec<Point>>;
}
