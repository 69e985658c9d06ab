//! The commands a test is made of: drive a generated extension of the route ([`Segment`]) or
//! inject a [`Fault`] into one of the car's UWB [`Probe`]s.
//!
//! A command is concrete: a [`Segment`] carries the points the car drives (and the ahead margin
//! that proved a continuation exists), a [`Fault`] carries the exact firmware parameters. A
//! command is what the runner sends and what a replay re-sends.

pub use car_link::fault::{FaultKind, Probe, UnknownProbe};
use trajgen::{Point, RouteTail, Waypoint};

/// One step of a test.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// Append a generated extension of the route and drive it.
    RunSegments(Segment),
    /// Inject a fault into one probe of the car's UWB positioning.
    AddFault(Fault),
}

impl Command {
    /// The command's name in case files and reports (`run_segments`, `add_fault`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::RunSegments(_) => "run_segments",
            Self::AddFault(_) => "add_fault",
        }
    }

    /// The segment, when this command drives one.
    pub fn segment(&self) -> Option<&Segment> {
        match self {
            Self::RunSegments(segment) => Some(segment),
            Self::AddFault(_) => None,
        }
    }

    /// The fault, when this command injects one.
    pub fn fault(&self) -> Option<&Fault> {
        match self {
            Self::AddFault(fault) => Some(fault),
            Self::RunSegments(_) => None,
        }
    }
}

/// What a `RunSegments` command asked the generator for: enough to generate its points again
/// from the same route tail.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentIntent {
    /// Seed of the generator's RNG (`crate::seed::rng`).
    pub seed: u64,
    /// Number of points to append.
    pub points: usize,
    /// Speed of every point of the extension, m/s.
    pub speed_mps: f64,
}

/// An extension of the route: the points the car drives, each with its speed.
///
/// Generated segments have an intent and one speed for all their points; segments replayed from
/// a hand-written case may have neither (their points and speeds are what the case says).
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// What was asked of the generator; `None` for a segment written by hand.
    pub intent: Option<SegmentIntent>,
    /// The concrete points continuing the route tail (exactly `intent.points` when generated).
    /// They are what the car drives and what a replay re-sends.
    pub points: Vec<Point>,
    /// The speed towards each point, m/s (as many as `points`).
    pub speeds: Vec<f64>,
    /// The ahead margin: the continuation generated after `points` (never sent) proving that the
    /// car can always be slowed down and stopped inside the area; may be empty when written by
    /// hand.
    pub margin: Vec<Point>,
}

impl Segment {
    /// The segment the generator produced for `intent` from `tail`: every point at the intent's
    /// speed, except where the route turns so tightly that this speed would ask more than
    /// `MAX_LATERAL_ACCEL_MPS2` (4 m/s²) of the car: there the points are slowed to `√(a·R)`,
    /// `R` the radius of the turn (see `capped_speeds`).
    pub fn generated_from(
        tail: &RouteTail,
        intent: SegmentIntent,
        points: Vec<Point>,
        margin: Vec<Point>,
    ) -> Self {
        let speeds = capped_speeds(tail, &points, margin.first().copied(), intent.speed_mps);
        Self {
            intent: Some(intent),
            speeds,
            points,
            margin,
        }
    }

    /// The points with their speeds (a missing speed repeats the last one).
    pub fn waypoints(&self) -> impl Iterator<Item = Waypoint> + '_ {
        let last = self.speeds.last().copied().unwrap_or(0.0);
        self.points
            .iter()
            .enumerate()
            .map(move |(i, &p)| Waypoint::new(p, self.speeds.get(i).copied().unwrap_or(last)))
    }

    /// Length of the extension from `start` (the route's end before it) through its points, metres.
    pub fn length_from(&self, start: Point) -> f64 {
        let mut length = 0.0;
        let mut previous = start;
        for &p in &self.points {
            length += previous.dist(p);
            previous = p;
        }
        length
    }
}

/// The largest lateral acceleration a generated segment asks of the car, m/s². The generator's
/// tightest loops (30° turns every 0.6 m: a radius of 1.16 m) are tighter than the autopilot's
/// look-ahead circle; driven at up to 12 km/h the car runs wide of them by up to a metre, which
/// can take it out of the area. Below this limit (√(4 · 1.16) = 2.15 m/s there) it follows them;
/// turns wider than 2.8 m keep the drawn speed up to 12 km/h.
const MAX_LATERAL_ACCEL_MPS2: f64 = 4.0;

/// The speed towards each of `points` (continuing `tail`, followed by `next` when known): `speed`
/// capped at `√(MAX_LATERAL_ACCEL_MPS2 · R)` for the turns at both ends of the leg towards the
/// point, `R = L / (2 sin(θ / 2))` for a turn `θ` between legs, `L` the shorter leg.
pub fn capped_speeds(
    tail: &RouteTail,
    points: &[Point],
    next: Option<Point>,
    speed: f64,
) -> Vec<f64> {
    let route: Vec<Point> = std::iter::once(tail.end)
        .chain(points.iter().copied())
        .chain(next)
        .collect();
    let heading = |a: Point, b: Point| (b.y - a.y).atan2(b.x - a.x);
    // The cap at vertex `k` of `route` (k = 0 is the tail's end, entered along its heading).
    let cap = |k: usize| -> f64 {
        let Some(&out_to) = route.get(k + 1) else {
            return f64::INFINITY;
        };
        let at = route[k];
        let out_len = at.dist(out_to);
        let (in_heading, in_len) = match k.checked_sub(1) {
            Some(prev) => (heading(route[prev], at), route[prev].dist(at)),
            None => (tail.heading, out_len),
        };
        let turn = heading(at, out_to) - in_heading;
        let turn =
            (turn + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        let half = (turn.abs() / 2.0).sin();
        if half <= 1e-9 {
            return f64::INFINITY;
        }
        let radius = in_len.min(out_len) / (2.0 * half);
        (MAX_LATERAL_ACCEL_MPS2 * radius).sqrt()
    };
    (0..points.len())
        .map(|j| speed.min(cap(j)).min(cap(j + 1)))
        .collect()
}

/// Where on the test route a fault is sent: a place, not a time, so that a case is the same test
/// on any link. The firmware counts a fault's `start` and `duration` from the moment the fault is
/// added; sending it when the car reaches a place on the route makes where it acts independent of
/// the link's latency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultPlace {
    /// The segment (its index among the test's segments, from 0) on which the fault is sent.
    pub segment_index: usize,
    /// How far along that segment, metres from its start (the end of the route before it).
    pub along_m: f64,
}

/// One fault to inject: `fi_add_fault <probe> <kind> <param> <start> <duration>`.
///
/// `start` and `duration` count iterations of the probe, not seconds: the fault applies on calls
/// `start + 1 … start + duration` of the probe after it is added (`docs/firmware.md`, fault injection).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    /// Where the fault applies.
    pub probe: Probe,
    /// What it does to the value.
    pub kind: FaultKind,
    /// Its parameter (metres for ranges, a factor for amplification, degrees for yaw offsets).
    pub param: f64,
    /// Probe iterations after the add before it applies.
    pub start: u32,
    /// Probe iterations it applies for (0 would be permanent; generated faults are never 0).
    pub duration: u32,
    /// Where on the route it is sent (not part of the firmware's command). `None` for a fault of
    /// a hand-written or version-1 case without a place: it is sent as the earlier tool sent
    /// faults, once the preceding segment is appended and the car has 4 or fewer route points
    /// left.
    pub at: Option<FaultPlace>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tight_turns_are_slowed_and_straight_legs_keep_their_speed() {
        let tail = RouteTail {
            end: Point::new(0.0, 0.0),
            heading: 0.0,
        };
        // 30° turns every 0.6 m (the generator's tightest loop), then straight on.
        let mut points = Vec::new();
        let (mut p, mut h) = (tail.end, 0.0f64);
        for _ in 0..4 {
            h += 30f64.to_radians();
            p = p + Point::from_heading(h) * 0.6;
            points.push(p);
        }
        for _ in 0..3 {
            p = p + Point::from_heading(h) * 2.0;
            points.push(p);
        }
        let speeds = capped_speeds(&tail, &points, None, 3.3);
        let tight = (MAX_LATERAL_ACCEL_MPS2 * 0.6 / (2.0 * 15f64.to_radians().sin())).sqrt();
        assert!((speeds[1] - tight).abs() < 1e-9, "{speeds:?}");
        assert!((tight - 2.15).abs() < 0.01);
        assert_eq!(speeds[6], 3.3);
        assert!(speeds.iter().all(|&v| v <= 3.3 && v > 2.0));
        assert_eq!(capped_speeds(&tail, &points[4..], None, 1.0), vec![1.0; 3]);
    }

    #[test]
    fn a_segment_measures_its_length_from_the_route_end() {
        let tail = RouteTail {
            end: Point::new(0.0, 0.0),
            heading: 0.0,
        };
        let segment = Segment::generated_from(
            &tail,
            SegmentIntent {
                seed: 0,
                points: 2,
                speed_mps: 1.0,
            },
            vec![Point::new(1.0, 0.0), Point::new(1.0, 2.0)],
            vec![],
        );
        assert_eq!(segment.speeds, vec![1.0, 1.0]);
        assert!((segment.length_from(Point::new(0.0, 0.0)) - 3.0).abs() < 1e-12);
    }
}
