//! Where the car will drive next: its autopilot's pure pursuit, run forward from the last sample.
//!
//! A car cutting a corner does not advance along its route at its wheel speed: inside a bend its
//! distance along the route grows faster than its wheels turn, on the way out of it slower (by a
//! quarter on the generator's 30° bends at 2–3 m/s, where the car runs 0.2–0.5 m inside). A ratio
//! measured over the last second is right in the middle of a long bend and wrong past its ends,
//! where a fault's place often is. So the placer drives the car forward as its firmware does
//! (`docs/firmware.md`, autopilot): every 10 ms the goal where the look-ahead circle last cuts the
//! next 8 stretches of the route, the pure-pursuit steering angle towards it with the distance
//! compensation and the speed-dependent clamp, the route's speed at the goal, a kinematic bicycle;
//! and it reads the predicted positions' distance along the route as it reads the samples'.

use car_link::firmware::FirmwareProfile;
use car_link::firmware::steering::{self, Compensation, LOOK_AHEAD_STRETCHES, PursuitPose};
use trajgen::Point;

use super::{Placer, Seen};
use crate::streaming::Progress;

/// The firmware's control period, seconds.
const TICK_S: f64 = 0.01;
/// The motor's acceleration in RPM mode, m/s² (25 000 ERPM/s).
const MOTOR_ACCEL_MPS2: f64 = 13.6;
/// The longest pursuit, ticks (8 s).
const MAX_TICKS: usize = 800;

/// How the car steers: what its autopilot's law needs of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Steering {
    /// The distance between the axles, metres.
    pub wheelbase_m: f64,
    /// The largest steering angle of the front wheels, radians.
    pub max_angle_rad: f64,
}

impl Steering {
    /// The steering of the scenario's vehicle.
    pub fn of(vehicle: &scenarios::Vehicle) -> Self {
        Self {
            wheelbase_m: vehicle.wheelbase_m,
            max_angle_rad: vehicle.max_steering_angle_rad,
        }
    }

    /// The steering angle towards `goal` of a car at `position` heading `heading` (radians
    /// counter-clockwise from east) at `speed`: the firmware's law
    /// (`car_link::firmware::steering`), pure pursuit with its radius divided by
    /// `min(1 + 0.2·D, 5)`, clamped to `±max / (1 + 0.05·|v|)²`. Positive turns left.
    fn angle(&self, position: Point, heading: f64, goal: Point, speed: f64) -> f64 {
        let car = PursuitPose {
            x: position.x,
            y: position.y,
            heading,
        };
        let angle = steering::pursuit_angle(
            car,
            goal.x,
            goal.y,
            self.wheelbase_m,
            Compensation::DivideRadius,
        );
        let max = steering::max_steering_angle(self.max_angle_rad, speed);
        angle.clamp(-max, max)
    }
}

impl Seen {
    /// The car's look-ahead radius at `speed`: the one it reported, grown or shrunk by its
    /// firmware's law (`profile`, its version's).
    fn radius_at(&self, profile: &FirmwareProfile, speed: f64) -> f64 {
        let law = |v: f64| profile.look_ahead_radius_m(v);
        self.radius * law(speed) / law(self.wheel)
    }
}

impl Placer {
    /// Seconds the car seen at `seen` needs to reach `target` (a distance along its route), its
    /// autopilot run forward; `None` without a heading or a steering, or when the pursuit does
    /// not reach the target in [`MAX_TICKS`].
    pub(super) fn pursue(&self, seen: &Seen, target: f64) -> Option<f64> {
        let steering = self.steering?;
        let mut heading = seen.heading?;
        if target <= seen.s {
            return Some(0.0);
        }
        let profile = seen.version.profile();
        let mut position = seen.position;
        let mut stretch = seen.stretch;
        let mut speed = seen.wheel;
        let mut s = seen.s;
        for tick in 0..MAX_TICKS {
            stretch = self.closest_stretch(position, stretch);
            let goal = self.goal(position, seen.radius_at(&profile, speed), stretch)?;
            // The speed at the goal: its stretch's two speeds interpolated at it.
            let at = self.route_s[goal.1] + goal.0.dist(self.route[goal.1].position);
            let wanted = self.route_speed(at).unwrap_or(speed);
            speed += (wanted - speed).clamp(-MOTOR_ACCEL_MPS2 * TICK_S, MOTOR_ACCEL_MPS2 * TICK_S);
            let angle = steering.angle(position, heading, goal.0, speed);
            let step = speed.max(super::MIN_SPEED_MPS) * TICK_S;
            heading += step * angle.tan() / steering.wheelbase_m;
            position = position + Point::from_heading(heading) * step;
            let next = self.along(
                position,
                Progress {
                    segment: stretch,
                    fraction: 0.0,
                },
            )?;
            if next >= target {
                let fraction = if next > s {
                    ((target - s) / (next - s)).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                return Some((tick as f64 + fraction) * TICK_S);
            }
            s = next;
        }
        None
    }

    /// The autopilot's goal for a car at `position` whose closest stretch is `stretch`: where
    /// the circle of `radius` around it last cuts the next [`LOOK_AHEAD_STRETCHES`] stretches
    /// (on a stretch, the cut nearer its end); the route's last point once the circle reaches
    /// it; else the closest point. With the stretch it lies on.
    fn goal(&self, position: Point, radius: f64, stretch: usize) -> Option<(Point, usize)> {
        let last = self.route.len().checked_sub(1)?;
        let mut goal = None;
        for i in stretch..(stretch + LOOK_AHEAD_STRETCHES).min(last) {
            let (a, b) = (self.route[i].position, self.route[i + 1].position);
            if let Some(hit) = circle_cut(position, radius, a, b) {
                goal = Some((hit, i));
                if i + 1 == last {
                    return Some((b, i));
                }
            }
        }
        goal.or_else(|| {
            let i = stretch.min(last.saturating_sub(1));
            let (a, b) = (self.route.get(i)?.position, self.route.get(i + 1)?.position);
            Some((
                trajgen::geometry::closest_point_on_segment(position, a, b),
                i,
            ))
        })
    }

    /// The stretch closest to `position` among the look-ahead window from `from` (the firmware's
    /// `point_now`, which only moves forward).
    fn closest_stretch(&self, position: Point, from: usize) -> usize {
        let last = self.route.len().saturating_sub(1);
        (from..(from + LOOK_AHEAD_STRETCHES).min(last))
            .min_by(|&i, &j| {
                let d = |k: usize| {
                    trajgen::geometry::point_segment_distance(
                        position,
                        self.route[k].position,
                        self.route[k + 1].position,
                    )
                };
                d(i).total_cmp(&d(j))
            })
            .unwrap_or(from)
    }
}

/// Where the circle of `radius` around `center` cuts the stretch `a`–`b`: with two cuts the one
/// nearer `b`.
fn circle_cut(center: Point, radius: f64, a: Point, b: Point) -> Option<Point> {
    let d = b - a;
    let qa = d.dot(d);
    if qa <= 1e-12 {
        return None;
    }
    let f = a - center;
    let qb = 2.0 * f.dot(d);
    let qc = f.dot(f) - radius * radius;
    let disc = qb * qb - 4.0 * qa * qc;
    if disc.is_nan() || disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    [(-qb + root) / (2.0 * qa), (-qb - root) / (2.0 * qa)]
        .into_iter()
        .find(|t| (0.0..=1.0).contains(t))
        .map(|t| a + d * t)
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use car_link::firmware::FirmwareVersion;
    use trajgen::Point;

    use super::super::{Placer, Seen};
    use super::Steering;
    use crate::drive::Sample;
    use crate::model::TestPlan;
    use crate::streaming::{Waypoint, locate};

    fn steering() -> Steering {
        Steering::of(&scenarios::Vehicle::default())
    }

    /// A placer on `points` at `speed`, and what it saw of a car at the first point heading
    /// `yaw_deg` (clockwise from east, as the car reports it) at `speed`.
    fn seen_on(points: &[Point], speed: f64, yaw_deg: f64) -> (Placer, Seen) {
        let route: Vec<Waypoint> = points.iter().map(|&p| Waypoint::new(p, speed)).collect();
        let plan = TestPlan {
            test_index: 0,
            start_tail: trajgen::RouteTail::from_points(&points[..2]).unwrap(),
            commands: Vec::new(),
        };
        let mut placer = Placer::new(&plan, &route, Some(steering()));
        let sample = Sample {
            rtk: points[0],
            uwb: points[0],
            speed,
            round_trip: Duration::ZERO,
            yaw_deg,
            version: FirmwareVersion::V10_1,
            look_ahead_radius_m: FirmwareVersion::V10_1.profile().look_ahead_radius_m(speed),
        };
        let progress = locate(&route, points[0], 0).unwrap();
        placer.observe(Duration::ZERO, &sample, progress);
        let seen = placer.seen.unwrap();
        (placer, seen)
    }

    #[test]
    fn the_steering_turns_towards_the_goal_and_is_clamped_with_speed() {
        let s = steering();
        let left = s.angle(Point::new(0.0, 0.0), 0.0, Point::new(1.0, 0.2), 1.0);
        let right = s.angle(Point::new(0.0, 0.0), 0.0, Point::new(1.0, -0.2), 1.0);
        assert!(left > 0.0 && (left + right).abs() < 1e-12, "{left} {right}");
        // Straight ahead: no steering; heading north with the goal to the west: left.
        assert_eq!(
            s.angle(Point::new(0.0, 0.0), 0.0, Point::new(2.0, 0.0), 1.0),
            0.0
        );
        let north = std::f64::consts::FRAC_PI_2;
        assert!(s.angle(Point::new(0.0, 0.0), north, Point::new(-0.5, 1.0), 1.0) > 0.0);
        // A goal beside the car asks for full lock, less at speed: 0.42 rad at 0, 0.30 at 8 m/s.
        let beside = |v| s.angle(Point::new(0.0, 0.0), 0.0, Point::new(0.0, 1.0), v);
        assert!((beside(0.0) - 0.42041).abs() < 1e-9);
        assert!((beside(8.0) - 0.42041 / 1.4f64.powi(2)).abs() < 1e-9);
    }

    #[test]
    fn on_a_straight_route_the_car_takes_the_way_over_its_speed() {
        // North along x = 0 at 2 m/s: the car reports a yaw of −90° (clockwise from east).
        let points: Vec<Point> = (0..12).map(|i| Point::new(0.0, i as f64)).collect();
        let (placer, seen) = seen_on(&points, 2.0, -90.0);
        let t = placer.pursue(&seen, 4.0).unwrap();
        assert!((t - 2.0).abs() < 0.02, "{t}");
        // A car 30° off its route turns onto it first: later.
        let (placer, seen) = seen_on(&points, 2.0, -60.0);
        let off = placer.pursue(&seen, 4.0).unwrap();
        assert!(off > t + 0.01, "{off} against {t}");
    }

    #[test]
    fn a_car_cutting_a_bend_reaches_a_place_past_it_sooner_than_its_wheels_turn_the_way() {
        // A left bend of 30° every 0.8 m (a circle of about 1.5 m), at 2 m/s: the autopilot's
        // goal, 1.45 m ahead, pulls the car inside, where the distance along the route grows
        // faster than its wheels turn; a car driving the route itself would need 1.2 s for 2.4 m
        // (the car starts on the route, so the gain is less than the quarter deep in a bend).
        let mut points = vec![Point::new(0.0, 0.0), Point::new(0.8, 0.0)];
        let mut heading: f64 = 0.0;
        for _ in 0..12 {
            heading += 30f64.to_radians();
            let last = *points.last().unwrap();
            points.push(last + Point::from_heading(heading) * 0.8);
        }
        let (placer, seen) = seen_on(&points, 2.0, 0.0);
        let t = placer.pursue(&seen, 2.4).unwrap();
        assert!(t < 1.2 * 0.93, "{t}");
        // The route's speeds alone say 1.2 s.
        assert!((placer.travel_s(&seen, 2.4, f64::INFINITY) - 1.2).abs() < 0.01);
    }
}
