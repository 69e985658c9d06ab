//! The runtime safety monitor: a pure state machine fed with the car's state samples and the
//! current time, which says when a test must stop and how.
//!
//! The reference orchestrator checked the fence only when planning
//! (`docs/method.md#what-the-reference-got-wrong`). This monitor watches the car while it drives,
//! at the state rate:
//! - the car's (RTK-fused) position outside the fence or inside a cutout by more than
//!   [`SafetyConfig::area_margin_m`];
//! - its cross-track error from the planned route above [`SafetyConfig::max_cross_track_m`];
//! - no state sample for longer than [`SafetyConfig::stale_after`] ([`DEFAULT_STALE_AFTER`] by
//!   default);
//! - a sample without a finite position, or without an RTK fix;
//! - a lost link, reported by the link ([`SafetyMonitor::link_lost`]).
//!
//! Each trips a typed [`Abort`] that says whether to brake at once or perform the safe stop
//! (a slow extension of the route, then brake). The first abort is latched: later inputs do not
//! change it. A lost link is never a pass: it always aborts the test.
//!
//! Time is passed in as [`Duration`]s since any fixed origin (the runner's clock, real or
//! virtual); nothing here reads a clock.

use std::fmt;
use std::time::Duration;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use trajgen::geometry::point_segment_distance;
use trajgen::{Area, Point};

/// Segments of the route searched ahead of the last closest one (like the autopilot's look-ahead
/// window), so a route that passes near itself does not hide a deviation.
const ROUTE_WINDOW: usize = 8;

/// The fastest a car can move, metres per second, by which [`AbortReason::Implausible`] tells
/// garbage from a state (54 km/h: several times what a test drives, above any car of this
/// method).
pub const MAX_PLAUSIBLE_SPEED_MPS: f64 = 15.0;

/// What a position may move between two samples beyond [`MAX_PLAUSIBLE_SPEED_MPS`], metres: an
/// RTK solution going from float to fixed moves by up to a metre or so.
pub const PLAUSIBLE_JUMP_M: f64 = 2.0;

/// The default longest time without a state sample, 500 ms. What it protects: while no sample
/// comes the monitor is blind, and the car drives on along its route; the streaming keeps at
/// least a margin of 1 s of route (plus round trips and generation time) ahead of it
/// (`crate::streaming`), so a stop for stale telemetry within 500 ms comes while the car still
/// has route ahead, far before the car's own 2 s watchdog, and after at most 1.7 m at a test's
/// top speed of 12 km/h. Against it: a loaded host delays samples by about 300 ms (289–302 ms
/// measured, #51), which the earlier 250 ms took for a car that stopped answering — and a car
/// that stops answering leaves a campaign on several cars.
pub const DEFAULT_STALE_AFTER: Duration = Duration::from_millis(500);

/// The monitor's limits (on record: `crate::files::SafetyConfigRecord`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetyConfig {
    /// How far the car may be outside the drivable region (outside the fence or inside a
    /// cutout) before the test is stopped, metres (0.3: RTK noise and the autopilot cutting a
    /// corner).
    pub area_margin_m: f64,
    /// Largest distance from the planned route, metres (1.5).
    pub max_cross_track_m: f64,
    /// Longest time without a state sample ([`DEFAULT_STALE_AFTER`]).
    pub stale_after: Duration,
    /// The fastest a car's position may move between two samples, m/s
    /// ([`MAX_PLAUSIBLE_SPEED_MPS`]; infinite: never [`AbortReason::Implausible`], for a
    /// harness that moves its car by whole metres between samples).
    pub max_plausible_speed_mps: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            area_margin_m: 0.3,
            max_cross_track_m: 1.5,
            stale_after: DEFAULT_STALE_AFTER,
            max_plausible_speed_mps: MAX_PLAUSIBLE_SPEED_MPS,
        }
    }
}

/// Serde for a [`Duration`] as whole milliseconds.
pub(crate) mod millis {
    use std::time::Duration;

    use serde::{Deserialize, Deserializer, Serializer};

    /// Writes whole milliseconds.
    pub(crate) fn serialize<S: Serializer>(d: &Duration, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
    }

    /// Reads whole milliseconds.
    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Duration, D::Error> {
        u64::deserialize(d).map(Duration::from_millis)
    }
}

/// What the monitor needs from one state sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarSample {
    /// The car's RTK-fused position (never the UWB estimate, which faults may disturb).
    pub position: Point,
    /// Whether the RTK solution was valid for this sample.
    pub rtk_fix: bool,
}

/// How to stop the car.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum StopAction {
    /// Append a slow extension of the route with the ahead margin, then brake: the car is under
    /// control and inside the area.
    SafeStop,
    /// Brake now: where the car is, or whether it hears us, is not known to be safe.
    Brake,
}

/// Why a test was stopped.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum AbortReason {
    /// The car is outside the fence by more than the margin.
    OutsideFence {
        /// Where it was.
        x: f64,
        /// Where it was.
        y: f64,
        /// How far outside, metres.
        distance_m: f64,
    },
    /// The car is inside a cutout by more than the margin.
    InsideCutout {
        /// Where it was.
        x: f64,
        /// Where it was.
        y: f64,
        /// How far inside, metres.
        distance_m: f64,
    },
    /// The car is too far from the planned route.
    OffRoute {
        /// Where it was.
        x: f64,
        /// Where it was.
        y: f64,
        /// Its distance from the route, metres.
        cross_track_m: f64,
    },
    /// No state sample arrived for too long.
    StaleTelemetry {
        /// Time since the last sample, milliseconds.
        age_ms: u64,
    },
    /// A state sample had no finite position.
    NoPosition,
    /// The car's position moved farther between two samples than any car can
    /// ([`MAX_PLAUSIBLE_SPEED_MPS`] over the time between them, and [`PLAUSIBLE_JUMP_M`] for an
    /// RTK solution that changes): what it sends is not a state.
    Implausible {
        /// How far the position moved, metres.
        jump_m: f64,
        /// In how long, milliseconds.
        dt_ms: u64,
    },
    /// The RTK fix was lost: the reference is gone.
    RtkLost,
    /// The link to the car was lost.
    LinkLost,
    /// The car reached the end of its route during the test (a starvation event).
    Starved,
    /// The operator interrupted the campaign.
    Interrupted,
    /// The test ran past its time limit: three times its planned driving time and a minute
    /// (the car does not keep up with its route; a simulated car never hangs a campaign).
    TimeLimit {
        /// The limit, seconds.
        limit_s: f64,
    },
    /// The car refused or did not answer a command of the test.
    CommandRefused {
        /// The command's index in the test.
        command_index: usize,
    },
}

impl AbortReason {
    /// Does the car stop answering sensibly (no state for too long, a state without a position,
    /// or positions no car could reach)? In a campaign on several cars such a test is cut off
    /// and given to another car, as one whose link was lost.
    pub fn car_unresponsive(&self) -> bool {
        matches!(
            self,
            Self::StaleTelemetry { .. } | Self::NoPosition | Self::Implausible { .. }
        )
    }

    /// How to stop the car for this reason.
    pub fn action(&self) -> StopAction {
        match self {
            Self::RtkLost | Self::Starved | Self::Interrupted | Self::TimeLimit { .. } => {
                StopAction::SafeStop
            }
            Self::OutsideFence { .. }
            | Self::InsideCutout { .. }
            | Self::OffRoute { .. }
            | Self::StaleTelemetry { .. }
            | Self::NoPosition
            | Self::Implausible { .. }
            | Self::LinkLost
            | Self::CommandRefused { .. } => StopAction::Brake,
        }
    }
}

impl fmt::Display for AbortReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::OutsideFence { x, y, distance_m } => {
                write!(f, "left the fence by {distance_m:.2} m at ({x:.2}, {y:.2})")
            }
            Self::InsideCutout { x, y, distance_m } => write!(
                f,
                "entered a cutout by {distance_m:.2} m at ({x:.2}, {y:.2})"
            ),
            Self::OffRoute {
                x,
                y,
                cross_track_m,
            } => write!(
                f,
                "{cross_track_m:.2} m off the planned route at ({x:.2}, {y:.2})"
            ),
            Self::StaleTelemetry { age_ms } => write!(f, "no state for {age_ms} ms"),
            Self::NoPosition => f.write_str("a state sample had no position"),
            Self::Implausible { jump_m, dt_ms } => write!(
                f,
                "the car's position moved {jump_m:.1} m in {dt_ms} ms: its state is not physical"
            ),
            Self::RtkLost => f.write_str("RTK fix lost"),
            Self::LinkLost => f.write_str("link lost"),
            Self::Starved => f.write_str("the car reached the end of its route (starvation)"),
            Self::Interrupted => f.write_str("interrupted"),
            Self::TimeLimit { limit_s } => write!(
                f,
                "ran past its time limit of {limit_s:.0} s (3 × its planned driving time + 60 s)"
            ),
            Self::CommandRefused { command_index } => {
                write!(f, "command {command_index} failed")
            }
        }
    }
}

/// A stop the monitor demands.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Abort {
    /// Why.
    pub reason: AbortReason,
    /// How to stop.
    pub action: StopAction,
    /// When it was detected (the time passed in), milliseconds in files.
    #[serde(with = "millis")]
    #[schemars(with = "u64")]
    pub at: Duration,
}

impl Abort {
    /// An abort for `reason` at `at`, with the reason's action.
    pub fn new(reason: AbortReason, at: Duration) -> Self {
        Self {
            reason,
            action: reason.action(),
            at,
        }
    }
}

/// The runtime safety monitor of one drive (see the module doc).
#[derive(Debug, Clone)]
pub struct SafetyMonitor {
    config: SafetyConfig,
    area: Area,
    route: Vec<Point>,
    cursor: usize,
    last_sample_at: Duration,
    /// The last sample's position and when it came.
    last_position: Option<(Duration, Point)>,
    tripped: Option<Abort>,
}

impl SafetyMonitor {
    /// A monitor for a car driving in `area`, armed at `now` (staleness counts from then).
    pub fn new(area: Area, config: SafetyConfig, now: Duration) -> Self {
        Self {
            config,
            area,
            route: Vec::new(),
            cursor: 0,
            last_sample_at: now,
            last_position: None,
            tripped: None,
        }
    }

    /// Replaces the planned route (after a reset: the start route, or a return route).
    pub fn set_route(&mut self, points: &[Point]) {
        self.route = points.to_vec();
        self.cursor = 0;
    }

    /// Appends points to the planned route (a segment sent to the car).
    pub fn extend_route(&mut self, points: &[Point]) {
        self.route.extend_from_slice(points);
    }

    /// The latched abort, if any.
    pub fn abort(&self) -> Option<Abort> {
        self.tripped
    }

    /// Feeds one state sample received at `now`; returns the (latched) abort, if any.
    pub fn sample(&mut self, now: Duration, sample: CarSample) -> Option<Abort> {
        if self.tripped.is_some() {
            return self.tripped;
        }
        if let Some(abort) = self.stale(now) {
            return self.trip(abort.reason, now);
        }
        self.last_sample_at = now;
        if let Some(reason) = self.implausible(now, sample.position) {
            return self.trip(reason, now);
        }
        match self.check_sample(sample) {
            Some(reason) => self.trip(reason, now),
            None => None,
        }
    }

    /// Checks the time since the last sample at `now` (call it at the state rate even when no
    /// sample arrives); returns the (latched) abort, if any.
    pub fn tick(&mut self, now: Duration) -> Option<Abort> {
        if self.tripped.is_some() {
            return self.tripped;
        }
        match self.stale(now) {
            Some(abort) => self.trip(abort.reason, now),
            None => None,
        }
    }

    /// The link reports the car lost at `now`: always an abort.
    pub fn link_lost(&mut self, now: Duration) -> Abort {
        self.trip(AbortReason::LinkLost, now)
            .unwrap_or(Abort::new(AbortReason::LinkLost, now))
    }

    /// Stops the test for a reason found outside the monitor (starvation, Ctrl-C) at `now`.
    pub fn stop(&mut self, reason: AbortReason, now: Duration) -> Abort {
        self.trip(reason, now).unwrap_or(Abort::new(reason, now))
    }

    fn trip(&mut self, reason: AbortReason, now: Duration) -> Option<Abort> {
        if self.tripped.is_none() {
            self.tripped = Some(Abort::new(reason, now));
        }
        self.tripped
    }

    fn stale(&self, now: Duration) -> Option<Abort> {
        let age = now.saturating_sub(self.last_sample_at);
        (age > self.config.stale_after).then(|| {
            let age_ms = u64::try_from(age.as_millis()).unwrap_or(u64::MAX);
            Abort::new(AbortReason::StaleTelemetry { age_ms }, now)
        })
    }

    /// A move from the last sample's position to `p` that no car makes in the time between.
    fn implausible(&mut self, now: Duration, p: Point) -> Option<AbortReason> {
        if !p.is_finite() {
            return None;
        }
        let last = self.last_position.replace((now, p));
        let (then, q) = last?;
        let dt = now.saturating_sub(then);
        let jump_m = (p - q).norm();
        let reach_m = self.config.max_plausible_speed_mps * dt.as_secs_f64() + PLAUSIBLE_JUMP_M;
        (jump_m > reach_m).then(|| AbortReason::Implausible {
            jump_m,
            dt_ms: u64::try_from(dt.as_millis()).unwrap_or(u64::MAX),
        })
    }

    fn check_sample(&mut self, sample: CarSample) -> Option<AbortReason> {
        let p = sample.position;
        if !p.is_finite() {
            return Some(AbortReason::NoPosition);
        }
        if let Some(reason) = self.area_violation(p) {
            return Some(reason);
        }
        if let Some(reason) = self.off_route(p) {
            return Some(reason);
        }
        (!sample.rtk_fix).then_some(AbortReason::RtkLost)
    }

    /// Outside the fence or inside a cutout by more than the margin.
    fn area_violation(&self, p: Point) -> Option<AbortReason> {
        let margin = self.config.area_margin_m;
        let fence = self.area.fence();
        if !fence.contains(p) {
            let distance_m = fence.boundary_distance(p);
            return (distance_m > margin).then_some(AbortReason::OutsideFence {
                x: p.x,
                y: p.y,
                distance_m,
            });
        }
        self.area
            .cutouts()
            .iter()
            .filter(|c| c.contains(p))
            .map(|c| c.boundary_distance(p))
            .find(|&distance_m| distance_m > margin)
            .map(|distance_m| AbortReason::InsideCutout {
                x: p.x,
                y: p.y,
                distance_m,
            })
    }

    fn off_route(&mut self, p: Point) -> Option<AbortReason> {
        let cross_track_m = self.cross_track(p)?;
        (cross_track_m > self.config.max_cross_track_m).then_some(AbortReason::OffRoute {
            x: p.x,
            y: p.y,
            cross_track_m,
        })
    }

    /// Distance to the nearest route segment in the window ahead of the last closest one (which
    /// moves forward); `None` without a route.
    fn cross_track(&mut self, p: Point) -> Option<f64> {
        match self.route.as_slice() {
            [] => None,
            [only] => Some(p.dist(*only)),
            route => {
                let last = route.len() - 2;
                let end = (self.cursor + ROUTE_WINDOW).min(last);
                let (index, distance) = (self.cursor.min(last)..=end)
                    .map(|i| (i, point_segment_distance(p, route[i], route[i + 1])))
                    .min_by(|a, b| a.1.total_cmp(&b.1))?;
                self.cursor = index;
                Some(distance)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use trajgen::Polygon;

    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    /// A 20 m square with a 2 m cutout at (10..12, 10..12).
    fn area() -> Area {
        let square = |x0: f64, y0: f64, s: f64| {
            Polygon::new(vec![
                Point::new(x0, y0),
                Point::new(x0 + s, y0),
                Point::new(x0 + s, y0 + s),
                Point::new(x0, y0 + s),
            ])
            .unwrap()
        };
        Area::new(square(0.0, 0.0, 20.0), vec![square(10.0, 10.0, 2.0)]).unwrap()
    }

    fn monitor() -> SafetyMonitor {
        let mut m = SafetyMonitor::new(area(), SafetyConfig::default(), ms(0));
        m.set_route(&[
            Point::new(2.0, 5.0),
            Point::new(8.0, 5.0),
            Point::new(18.0, 5.0),
        ]);
        m
    }

    fn at(x: f64, y: f64) -> CarSample {
        CarSample {
            position: Point::new(x, y),
            rtk_fix: true,
        }
    }

    #[test]
    fn a_car_on_its_route_inside_the_area_drives_on() {
        let mut m = monitor();
        // 3 m to 15 m at 10 m/s, a sample every 50 ms.
        for i in 0..=24u32 {
            let x = 3.0 + 0.5 * f64::from(i);
            assert_eq!(m.sample(ms(50 * u64::from(i)), at(x, 5.4)), None);
        }
        assert_eq!(m.tick(ms(1300)), None);
    }

    #[test]
    fn a_position_no_car_could_reach_is_not_a_state() {
        let mut m = monitor();
        assert_eq!(m.sample(ms(0), at(3.0, 5.0)), None);
        // An RTK solution that moves 1.9 m between two samples is still a car.
        assert_eq!(m.sample(ms(50), at(4.9, 5.0)), None);
        // 12 m in 50 ms is 240 m/s: garbage with a valid checksum.
        let abort = m.sample(ms(100), at(16.9, 5.0)).unwrap();
        assert!(
            matches!(abort.reason, AbortReason::Implausible { jump_m, dt_ms: 50 } if (jump_m - 12.0).abs() < 1e-9),
            "{abort:?}"
        );
        assert!(abort.reason.car_unresponsive());
        assert_eq!(abort.action, StopAction::Brake);
        assert_eq!(
            abort.reason.to_string(),
            "the car's position moved 12.0 m in 50 ms: its state is not physical"
        );
    }

    #[test]
    fn a_car_that_stops_answering_sensibly_is_told_from_one_that_drives_badly() {
        assert!(AbortReason::StaleTelemetry { age_ms: 300 }.car_unresponsive());
        assert!(AbortReason::NoPosition.car_unresponsive());
        let badly = [
            AbortReason::OutsideFence {
                x: 0.0,
                y: 0.0,
                distance_m: 1.0,
            },
            AbortReason::OffRoute {
                x: 0.0,
                y: 0.0,
                cross_track_m: 2.0,
            },
            AbortReason::RtkLost,
            AbortReason::Starved,
            AbortReason::TimeLimit { limit_s: 60.0 },
        ];
        assert!(badly.iter().all(|r| !r.car_unresponsive()));
    }

    #[test]
    fn leaving_the_fence_beyond_the_margin_brakes() {
        let mut m = SafetyMonitor::new(area(), SafetyConfig::default(), ms(0));
        assert_eq!(m.sample(ms(10), at(-0.2, 5.0)), None, "within the margin");
        let abort = m.sample(ms(20), at(-0.5, 5.0)).unwrap();
        assert!(
            matches!(abort.reason, AbortReason::OutsideFence { distance_m, .. } if (distance_m - 0.5).abs() < 1e-9)
        );
        assert_eq!(abort.action, StopAction::Brake);
        assert_eq!(abort.at, ms(20));
    }

    #[test]
    fn entering_a_cutout_beyond_the_margin_brakes() {
        let mut m = SafetyMonitor::new(area(), SafetyConfig::default(), ms(0));
        assert_eq!(m.sample(ms(10), at(10.1, 11.0)), None, "within the margin");
        let abort = m.sample(ms(20), at(11.0, 11.0)).unwrap();
        assert!(
            matches!(abort.reason, AbortReason::InsideCutout { distance_m, .. } if (distance_m - 1.0).abs() < 1e-9)
        );
        assert_eq!(abort.action, StopAction::Brake);
    }

    #[test]
    fn drifting_off_the_planned_route_brakes() {
        let mut m = monitor();
        assert_eq!(m.sample(ms(10), at(6.0, 6.4)), None);
        let abort = m.sample(ms(20), at(6.0, 6.6)).unwrap();
        assert!(
            matches!(abort.reason, AbortReason::OffRoute { cross_track_m, .. } if (cross_track_m - 1.6).abs() < 1e-9)
        );
        assert_eq!(abort.action, StopAction::Brake);
    }

    #[test]
    fn a_route_passing_near_itself_does_not_hide_a_deviation() {
        // Out along y = 5 and back along y = 7 after 12 segments; the car drifts onto the way back
        // while still on the way out.
        let mut route: Vec<Point> = (0..=12)
            .map(|i| Point::new(1.0 + f64::from(i), 5.0))
            .collect();
        route.extend((0..=12).rev().map(|i| Point::new(1.0 + f64::from(i), 7.0)));
        let mut m = SafetyMonitor::new(area(), SafetyConfig::default(), ms(0));
        m.set_route(&route);
        assert_eq!(m.sample(ms(10), at(1.5, 5.0)), None);
        let abort = m.sample(ms(20), at(2.0, 7.0)).unwrap();
        assert!(matches!(abort.reason, AbortReason::OffRoute { .. }));
    }

    #[test]
    fn stale_telemetry_brakes_after_500_ms() {
        let mut m = monitor();
        assert_eq!(m.sample(ms(100), at(3.0, 5.0)), None);
        // A loaded host's gap (about 300 ms, #51) is no stale telemetry.
        assert_eq!(m.tick(ms(402)), None);
        assert_eq!(m.tick(ms(600)), None);
        let abort = m.tick(ms(601)).unwrap();
        assert_eq!(abort.reason, AbortReason::StaleTelemetry { age_ms: 501 });
        assert_eq!(abort.action, StopAction::Brake);
    }

    #[test]
    fn a_late_sample_is_still_stale() {
        let mut m = monitor();
        let abort = m.sample(ms(700), at(3.0, 5.0)).unwrap();
        assert_eq!(abort.reason, AbortReason::StaleTelemetry { age_ms: 700 });
    }

    #[test]
    fn a_lost_link_aborts_and_is_never_a_pass() {
        let mut m = monitor();
        assert_eq!(m.sample(ms(10), at(3.0, 5.0)), None);
        let abort = m.link_lost(ms(20));
        assert_eq!(abort.reason, AbortReason::LinkLost);
        assert_eq!(abort.action, StopAction::Brake);
        assert_eq!(m.abort(), Some(abort));
        assert_eq!(abort.reason.to_string(), "link lost");
    }

    #[test]
    fn a_lost_rtk_fix_or_position_stops_the_test() {
        let mut m = monitor();
        let abort = m
            .sample(
                ms(10),
                CarSample {
                    position: Point::new(3.0, 5.0),
                    rtk_fix: false,
                },
            )
            .unwrap();
        assert_eq!(abort.reason, AbortReason::RtkLost);
        assert_eq!(abort.action, StopAction::SafeStop);
        let mut m = monitor();
        let abort = m.sample(ms(10), at(f64::NAN, 5.0)).unwrap();
        assert_eq!(abort.reason, AbortReason::NoPosition);
    }

    #[test]
    fn the_first_abort_is_latched() {
        let mut m = monitor();
        let first = m.sample(ms(10), at(-5.0, 5.0)).unwrap();
        assert_eq!(m.sample(ms(20), at(3.0, 5.0)), Some(first));
        assert_eq!(m.tick(ms(10_000)), Some(first));
        assert_eq!(m.link_lost(ms(10_001)), first);
        assert_eq!(m.stop(AbortReason::Interrupted, ms(10_002)), first);
    }

    #[test]
    fn an_abort_survives_a_round_trip_through_json() {
        let abort = Abort::new(AbortReason::StaleTelemetry { age_ms: 300 }, ms(1234));
        let json = serde_json::to_string(&abort).unwrap();
        assert_eq!(
            json,
            r#"{"reason":{"kind":"stale_telemetry","age_ms":300},"action":"brake","at":1234}"#
        );
        assert_eq!(serde_json::from_str::<Abort>(&json).unwrap(), abort);
    }

    proptest::proptest! {
        /// A car moving at any speed up to [`MAX_PLAUSIBLE_SPEED_MPS`], sampled at any rate,
        /// is never called implausible.
        #[test]
        fn no_drivable_path_is_implausible(
            steps in proptest::collection::vec((1u64..250, 0.0f64..1.0, -3.2f64..3.2), 1..200),
        ) {
            let mut m = SafetyMonitor::new(area(), SafetyConfig::default(), ms(0));
            let (mut t, mut p) = (0, Point::new(10.0, 5.0));
            for (dt, fraction, heading) in steps {
                t += dt;
                let d = fraction * MAX_PLAUSIBLE_SPEED_MPS * dt as f64 / 1000.0;
                p = p + Point::new(d * heading.cos(), d * heading.sin());
                let tripped = m.implausible(ms(t), p);
                proptest::prop_assert!(tripped.is_none(), "{tripped:?} at {t} ms");
            }
        }
    }
}
