//! The laws the firmware's autopilot steers by (`docs/firmware.md#control-cycle`,
//! `docs/firmware.md#steering-law`): the look-ahead radius, the speed-dependent steering clamp and
//! pure pursuit with distance compensation.
//!
//! One implementation serves both users: the simulated car computes in `f32`, as the firmware
//! does, and the campaign's fault placement runs the car's autopilot forward in `f64`
//! (`campaign::drive::place::pursuit`); placing a fault within 0.2 m rests on the two agreeing.

use std::ops::{Add, Div, Mul, Neg, Sub};

use super::LookAheadLaw;

/// The stretches of the route the goal search looks at by default (`ap_set_look_ahead`).
pub const LOOK_AHEAD_STRETCHES: usize = 8;

/// A floating-point type the laws compute in: `f32` (as the firmware) or `f64`.
pub trait Real:
    Copy
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// The constant `x` in this type (rounded once from its decimal literal).
    fn lit(x: f64) -> Self;
    /// |self|.
    fn abs(self) -> Self;
    /// √(self² + other²).
    fn hypot(self, other: Self) -> Self;
    /// The four-quadrant arc tangent of self / x.
    fn atan2(self, x: Self) -> Self;
    /// The arc tangent.
    fn atan(self) -> Self;
    /// The sine.
    fn sin(self) -> Self;
    /// The cosine.
    fn cos(self) -> Self;
    /// The smaller of the two.
    fn min(self, other: Self) -> Self;
    /// The larger of the two.
    fn max(self, other: Self) -> Self;
}

macro_rules! real {
    ($t:ty) => {
        impl Real for $t {
            fn lit(x: f64) -> Self {
                x as $t
            }
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            fn hypot(self, other: Self) -> Self {
                <$t>::hypot(self, other)
            }
            fn atan2(self, x: Self) -> Self {
                <$t>::atan2(self, x)
            }
            fn atan(self) -> Self {
                <$t>::atan(self)
            }
            fn sin(self) -> Self {
                <$t>::sin(self)
            }
            fn cos(self) -> Self {
                <$t>::cos(self)
            }
            fn min(self, other: Self) -> Self {
                <$t>::min(self, other)
            }
            fn max(self, other: Self) -> Self {
                <$t>::max(self, other)
            }
        }
    };
}
real!(f32);
real!(f64);

/// The speed-dependent scale of the steering clamp and the 10.x look-ahead radius,
/// `1 / (1 + 0.05·|v|)²` (`speed` in m/s).
pub fn speed_scale<F: Real>(speed: F) -> F {
    let div = F::lit(1.0) + speed.abs() * F::lit(0.05);
    F::lit(1.0) / (div * div)
}

/// The largest steering angle at `speed`: full lock `max_angle` scaled by [`speed_scale`].
pub fn max_steering_angle<F: Real>(max_angle: F, speed: F) -> F {
    max_angle * speed_scale(speed)
}

/// The look-ahead radius at `speed` (m/s) by `law`, from `ap_base_rad` (`base`, metres) and
/// `ap_rad_time_ahead` (`time_ahead`, seconds).
pub fn look_ahead_radius<F: Real>(law: LookAheadLaw, base: F, time_ahead: F, speed: F) -> F {
    match law {
        LookAheadLaw::SpeedScaled => base / speed_scale(speed),
        LookAheadLaw::TimeAhead => (time_ahead * speed.abs()).max(base),
    }
}

/// How the pursuit's distance compensation (`ap_ang_dist_comp`) enters the steering angle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compensation {
    /// Switched off: `δ = atan(L / R_pp)`.
    Off,
    /// The documented law of both generations: the pursuit radius divided,
    /// `R_pp ← R_pp / min(1 + 0.2·D, 5)`, before `δ = atan(L / R_pp)`.
    DivideRadius,
    /// The 2016 code before the switch existed: `δ = atan(L / R_pp) · min(1 + 0.2·D, 5)`. Not what
    /// a car runs; kept to measure the difference.
    MultiplyAngle2016,
}

/// A car's pose for the steering law: position (m) and heading (radians counter-clockwise from
/// east, the negated firmware yaw in radians).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PursuitPose<F> {
    /// East, m.
    pub x: F,
    /// North, m.
    pub y: F,
    /// Heading, radians counter-clockwise from east.
    pub heading: F,
}

/// The pure-pursuit steering angle (radians, positive turns left) of a car at `car` towards the
/// goal `(goal_x, goal_y)`, with wheelbase `wheelbase` (not clamped: see
/// [`max_steering_angle`]). A goal straight ahead (lateral offset ≤ 1e-6 m) gives 0.
pub fn pursuit_angle<F: Real>(
    car: PursuitPose<F>,
    goal_x: F,
    goal_y: F,
    wheelbase: F,
    compensation: Compensation,
) -> F {
    let d = (goal_x - car.x).hypot(goal_y - car.y);
    let gamma = car.heading - (goal_y - car.y).atan2(goal_x - car.x);
    let dx = d * gamma.cos();
    let dy = d * gamma.sin();
    if dy.abs() <= F::lit(1e-6) {
        return F::lit(0.0);
    }
    let mut r = -(dx * dx + dy * dy) / (F::lit(2.0) * dy);
    let correction = (F::lit(1.0) + F::lit(0.2) * d).min(F::lit(5.0));
    match compensation {
        Compensation::Off => {}
        Compensation::DivideRadius => r = r / correction,
        Compensation::MultiplyAngle2016 => return (wheelbase / r).atan() * correction,
    }
    (wheelbase / r).atan()
}

/// The largest look-ahead radius at `speed` of every generation the method tests, with the
/// factory settings: how close to its route's end a car of any of them may stop, metres.
pub fn largest_look_ahead_radius_m(speed: f64) -> f64 {
    super::Generation::ALL
        .into_iter()
        .map(|g| g.reference().profile())
        .filter(|p| p.supported)
        .map(|p| p.look_ahead_radius_m(speed))
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_constants_round_alike_in_f32() {
        // Rounding a decimal to f64 and then to f32 gives the f32 literal for every constant the
        // laws use, so the simulated car's arithmetic is the firmware's.
        assert_eq!(f32::lit(0.05), 0.05f32);
        assert_eq!(f32::lit(0.2), 0.2f32);
        assert_eq!(f32::lit(1e-6), 1e-6f32);
    }

    #[test]
    fn steering_turns_towards_the_goal_and_divides_the_radius() {
        let car = PursuitPose {
            x: 0.0f64,
            y: 0.0,
            heading: 0.0,
        };
        let left = pursuit_angle(car, 1.0, 1.0, 0.475, Compensation::DivideRadius);
        let right = pursuit_angle(car, 1.0, -1.0, 0.475, Compensation::DivideRadius);
        assert!(left > 0.0 && right < 0.0 && (left + right).abs() < 1e-12);
        assert_eq!(
            pursuit_angle(car, 2.0, 0.0, 0.475, Compensation::DivideRadius),
            0.0
        );
        // R_pp = 1 for a goal at (1, 1): off gives atan(L).
        let off = pursuit_angle(car, 1.0, 1.0, 0.475, Compensation::Off);
        assert!((off - 0.475f64.atan()).abs() < 1e-12);
        let d = 2f64.sqrt();
        let divided = (0.475 * (1.0 + 0.2 * d)).atan();
        assert!((left - divided).abs() < 1e-12);
        let multiplied = pursuit_angle(car, 1.0, 1.0, 0.475, Compensation::MultiplyAngle2016);
        assert!((multiplied - off * (1.0 + 0.2 * d)).abs() < 1e-12);
    }

    #[test]
    fn f32_and_f64_agree() {
        let car32 = PursuitPose {
            x: 1.0f32,
            y: -2.0,
            heading: 0.3,
        };
        let car64 = PursuitPose {
            x: 1.0f64,
            y: -2.0,
            heading: 0.3,
        };
        let a = pursuit_angle(car32, 3.0, 0.5, 0.475, Compensation::DivideRadius);
        let b = pursuit_angle(car64, 3.0, 0.5, 0.475, Compensation::DivideRadius);
        assert!((f64::from(a) - b).abs() < 1e-5);
    }

    #[test]
    fn look_ahead_radius_per_law() {
        let r = |law, v: f64| look_ahead_radius(law, 1.2, 0.8, v);
        assert!((r(LookAheadLaw::SpeedScaled, 0.0) - 1.2).abs() < 1e-12);
        assert!((r(LookAheadLaw::SpeedScaled, 2.0) - 1.2 * 1.1 * 1.1).abs() < 1e-12);
        let t = |v: f64| look_ahead_radius(LookAheadLaw::TimeAhead, 0.8, 0.8, v);
        assert!((t(0.5) - 0.8).abs() < 1e-12);
        assert!((t(-2.0) - 1.6).abs() < 1e-12);
        assert!((largest_look_ahead_radius_m(0.0) - 1.2).abs() < 1e-12);
        assert!((largest_look_ahead_radius_m(2.0) - 1.6).abs() < 1e-12);
        assert!((max_steering_angle(0.42f64, 0.0) - 0.42).abs() < 1e-15);
    }
}
