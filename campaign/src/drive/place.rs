//! Faults sent at their place on the route, not at a time.
//!
//! The firmware counts a fault's `start` and `duration` in probe calls from the moment the fault
//! is added, so where on the route a fault acts depends on when the car receives it. A
//! [`Placer`] sends each fault when the car reaches the fault's place, so that a case is the same
//! test on any link:
//!
//! - **The place.** A fault with a place ([`FaultPlace`]) is sent at that distance along its
//!   segment. A fault without one (a hand-written or version-1 case) is sent as the earlier tool
//!   sent faults: once its preceding segment is appended and the car has 4 or fewer route points
//!   left of it (the firmware's `ap_route_left` counts the points from the start of the stretch
//!   the car drives to the route's end, both included: 4 left means the car has reached the
//!   segment's fourth point from the end). Either way the place becomes a distance along the
//!   car's route once its segment is appended.
//! - **When to send.** The car's distance along its route is known at each state sample, as it
//!   was when the car answered, about half a round trip before the sample arrived (measured so
//!   that it is continuous where the car cuts a corner: see [`Placer::along`]). From the
//!   last sample and the median round trip, the placer predicts when the car will be at the
//!   place and sends the command half a round trip before: the car then adds the fault as it
//!   passes the place. For the last samples before the command is due the prediction runs the
//!   car's autopilot forward from the sample (its position, heading, speed and look-ahead radius: see
//!   `pursuit`), so a car cutting a bend, which advances along its route up to a quarter faster
//!   than its wheels turn and slower on the way out, arrives when predicted; farther away, and
//!   for a car that reports no heading, it follows the speeds the route asks for (see
//!   [`Placer::travel_s`]). The caller wakes the drive at [`Placer::due`].
//! - **Where it acted.** The car added the fault at about the middle of the command's round trip
//!   (after a lost reply resolved by listing the car's faults: half a round trip after sending).
//!   The car's distance at that time is interpolated between the samples around it; the
//!   difference from the place is the placement's error.
//!
//! Fault commands are in flight together, also those of one probe (the car answers a probe's
//! commands in the order they arrive: see `car_link::Car::add_fault`), so faults placed closer
//! together than the car drives in a round trip are each sent at its own time. Segments are
//! streamed by the time-based rule independently: a fault never delays a segment.

use std::cell::Cell;
use std::collections::VecDeque;
use std::time::Duration;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use trajgen::Point;

use crate::files::{FaultPlacementRecord, PlaceRuleRecord};
use crate::model::{Command, Fault, FaultPlace, FaultWindow, ProbeRates, TestPlan};
use crate::streaming::{Progress, Waypoint, look_ahead_radius_m};

mod pursuit;
pub use pursuit::Steering;

/// How the earlier tool placed a fault: once its segment's car had this many route points left.
pub const EARLIER_TOOL_POINTS_LEFT: usize = 4;

/// Round trips kept for the median.
const ROUND_TRIPS: usize = 9;
/// Samples kept to interpolate where the car was.
const HISTORY: usize = 64;
/// The window over which the car's progress along its route is compared with its wheels'
/// travel, seconds.
const PROGRESS_WINDOW_S: f64 = 1.0;
/// The bounds of that ratio: a car advances along its route at its wheel speed but for cutting
/// corners and drifting, a few percent; beyond these the measurement says more about a jump in
/// where the car is located on its route (a new route, a reset) than about the car.
const PROGRESS_RATIO: (f64, f64) = (0.8, 1.25);
/// Fault commands in flight at once at most: as many as the car takes on one probe.
pub const MAX_IN_FLIGHT: usize = car_link::firmware::FAULTS_PER_PROBE;
/// Wheel travel below which the progress ratio is not measured, metres.
const MIN_WHEEL_TRAVEL_M: f64 = 0.2;
/// How soon a command must be due, after the sample that predicts it arrived, for the car's
/// autopilot to be run forward (see [`Placer::pursue`]), seconds: the last samples before it is
/// sent.
const PURSUIT_WINDOW_S: f64 = 0.5;
/// How much further than the pursuit window (after the round trip) a prediction is integrated
/// finely, seconds ([`Placer::travel_s`]): every prediction that can make a command due, or be
/// pursued, within a second of the next samples is exact.
const FINE_MARGIN_S: f64 = 1.0;
/// Fine steps in each coarse step of [`Placer::travel_s`].
const COARSE_STEPS: usize = 25;
/// The slowest speed a prediction assumes, m/s (a standing car's place is never predicted).
const MIN_SPEED_MPS: f64 = 0.05;

/// Which rule placed a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum PlaceRule {
    /// The case gave the place.
    Planned,
    /// The case gave none: the earlier tool's rule (4 or fewer route points left).
    EarlierTool,
}

/// Where a fault was meant to act and where it did: what a case file and the recording keep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FaultPlacement {
    /// The fault command's index in the plan.
    pub command_index: usize,
    /// The rule that placed it.
    pub rule: PlaceRule,
    /// The segment it is placed on (among the test's segments, from 0).
    pub segment_index: usize,
    /// The place: metres along that segment from its start.
    pub planned_along_m: f64,
    /// When the command was sent, seconds since the test began.
    pub sent_s: f64,
    /// When the car added the fault (estimated), seconds since the test began.
    pub added_s: f64,
    /// Where the car was then: metres along the segment (absent when no sample came after).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub actual_along_m: Option<f64>,
    /// `actual_along_m − planned_along_m`: positive when the fault was added past its place.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_m: Option<f64>,
    /// The estimated window in which the fault acted, seconds since the test began (from the
    /// probe's call rate: `start` and `duration` calls after it was added).
    pub acts_from_s: f64,
    /// The window's end.
    pub acts_to_s: f64,
}

impl From<PlaceRule> for PlaceRuleRecord {
    fn from(rule: PlaceRule) -> Self {
        match rule {
            PlaceRule::Planned => Self::Planned,
            PlaceRule::EarlierTool => Self::EarlierTool,
        }
    }
}

impl From<FaultPlacement> for FaultPlacementRecord {
    fn from(p: FaultPlacement) -> Self {
        Self {
            command_index: p.command_index,
            rule: p.rule.into(),
            segment_index: p.segment_index,
            planned_along_m: p.planned_along_m,
            sent_s: p.sent_s,
            added_s: p.added_s,
            actual_along_m: p.actual_along_m,
            error_m: p.error_m,
            acts_from_s: p.acts_from_s,
            acts_to_s: p.acts_to_s,
        }
    }
}

impl From<PlaceRuleRecord> for PlaceRule {
    fn from(rule: PlaceRuleRecord) -> Self {
        match rule {
            PlaceRuleRecord::Planned => Self::Planned,
            PlaceRuleRecord::EarlierTool => Self::EarlierTool,
        }
    }
}

impl From<FaultPlacementRecord> for FaultPlacement {
    fn from(p: FaultPlacementRecord) -> Self {
        Self {
            command_index: p.command_index,
            rule: p.rule.into(),
            segment_index: p.segment_index,
            planned_along_m: p.planned_along_m,
            sent_s: p.sent_s,
            added_s: p.added_s,
            actual_along_m: p.actual_along_m,
            error_m: p.error_m,
            acts_from_s: p.acts_from_s,
            acts_to_s: p.acts_to_s,
        }
    }
}

/// A fault not sent yet.
#[derive(Debug, Clone, Copy)]
struct Pending {
    command_index: usize,
    fault: Fault,
    rule: PlaceRule,
    segment_index: usize,
    /// Along the segment: the case's place, or (earlier tool) known once the segment is appended.
    along_m: Option<f64>,
    /// The place as a distance along the car's route, once its segment is appended.
    target_s: Option<f64>,
}

/// A fault command in flight.
#[derive(Debug, Clone, Copy)]
struct InFlight {
    pending: Pending,
    sent: Duration,
}

/// Where the car was at a sample.
#[derive(Debug, Clone, Copy)]
struct Fix {
    /// When (the sample's arrival less half its round trip), seconds since the test began.
    t: f64,
    /// Its distance along the route, metres.
    s: f64,
    /// Its wheel speed, m/s.
    wheel: f64,
}

/// Where the car was seen last.
#[derive(Debug, Clone, Copy)]
struct Seen {
    /// When the car was there (the sample's arrival less half its round trip).
    car_time: f64,
    /// Where it was.
    position: Point,
    /// Its heading, radians counter-clockwise from east, when the car reported one.
    heading: Option<f64>,
    /// The route's stretch the streamer located it on.
    stretch: usize,
    /// Its wheel speed, m/s.
    wheel: f64,
    /// Its firmware, whose look-ahead radius grows with the speed as its version says.
    version: car_link::firmware::FirmwareVersion,
    /// Its distance along the route, metres.
    s: f64,
    /// Its speed along the route, m/s (its wheel speed times [`Placer::progress_ratio`]).
    speed: f64,
    /// Its autopilot's look-ahead radius, metres.
    radius: f64,
}

/// The faults of a test, sent at their places (see the module doc).
#[derive(Debug, Clone)]
pub struct Placer {
    /// The car's route: its points with their speeds, and the distance along it at each,
    /// metres.
    route: Vec<Waypoint>,
    route_s: Vec<f64>,
    /// The unit normal of the miter at each route point ([`Self::compute_miter`]), kept as the
    /// route grows: a sample's place is found on three stretches, and the pursuit does so at
    /// every tick.
    miters: Vec<Option<Point>>,
    /// The car's route index of each appended segment's first point.
    segment_first: Vec<usize>,
    pending: Vec<Pending>,
    in_flight: Vec<InFlight>,
    placements: Vec<FaultPlacement>,
    /// Placements whose actual place waits for a sample after the car added the fault.
    unresolved: Vec<usize>,
    history: VecDeque<Fix>,
    round_trips: VecDeque<Duration>,
    /// The median of `round_trips` (zero before the first).
    median_round_trip: Duration,
    seen: Option<Seen>,
    /// How the car steers, to run its autopilot forward (see [`Steering`]); without it the
    /// prediction follows the route's speeds only.
    steering: Option<Steering>,
    /// The last prediction: the sample's time and the target it was made for, and the seconds
    /// (the drive asks for [`Self::due`] after every event; the pursuit runs once per sample).
    predicted: Cell<Option<(f64, f64, f64)>>,
}

impl Placer {
    /// The faults of `plan`, for a car whose route starts with `start` (the start route's
    /// points) and that steers as `steering` says.
    pub fn new(plan: &TestPlan, start: &[Waypoint], steering: Option<Steering>) -> Self {
        let mut segments = 0usize;
        let mut pending = Vec::new();
        for (command_index, command) in plan.commands.iter().enumerate() {
            match command {
                Command::RunSegments(_) => segments += 1,
                Command::AddFault(fault) => {
                    let (rule, segment_index, along_m) = match fault.at {
                        Some(FaultPlace {
                            segment_index,
                            along_m,
                        }) => (PlaceRule::Planned, segment_index, Some(along_m)),
                        None => (PlaceRule::EarlierTool, segments.saturating_sub(1), None),
                    };
                    pending.push(Pending {
                        command_index,
                        fault: *fault,
                        rule,
                        segment_index,
                        along_m,
                        target_s: None,
                    });
                }
            }
        }
        let mut placer = Self {
            route: Vec::new(),
            route_s: Vec::new(),
            miters: Vec::new(),
            segment_first: Vec::new(),
            pending,
            in_flight: Vec::new(),
            placements: Vec::new(),
            unresolved: Vec::new(),
            history: VecDeque::new(),
            round_trips: VecDeque::new(),
            median_round_trip: Duration::ZERO,
            seen: None,
            steering,
            predicted: Cell::new(None),
        };
        placer.extend(start);
        placer
    }

    /// The car's route grows by `points` (a segment or the safe stop's extension).
    pub fn extend(&mut self, points: &[Waypoint]) {
        // A goal near the old end may lie on the new points: predict again.
        self.predicted.set(None);
        for &w in points {
            let s = match (self.route.last(), self.route_s.last()) {
                (Some(end), Some(&s)) => s + end.position.dist(w.position),
                _ => 0.0,
            };
            self.route.push(w);
            self.route_s.push(s);
        }
        // The old last point's miter turns with the new stretch after it.
        let from = self.miters.len().saturating_sub(1);
        self.miters.truncate(from);
        for i in from..self.route.len() {
            let miter = self.compute_miter(i);
            self.miters.push(miter);
        }
    }

    /// Segment `segment_index` was appended: its first point is the route's point `first` and
    /// it has `len` points (call after [`Self::extend`] with them). Its faults get their
    /// targets.
    pub fn segment_appended(&mut self, segment_index: usize, first: usize, len: usize) {
        if self.segment_first.len() == segment_index {
            self.segment_first.push(first);
        }
        let Some(start) = first.checked_sub(1) else {
            return;
        };
        let last = first + len.saturating_sub(1);
        let (Some(&start_s), Some(&last_s)) = (self.route_s.get(start), self.route_s.get(last))
        else {
            return;
        };
        let earlier = last.saturating_sub(EARLIER_TOOL_POINTS_LEFT - 1).max(start);
        let earlier_s = self.route_s.get(earlier).copied().unwrap_or(start_s);
        for p in self
            .pending
            .iter_mut()
            .filter(|p| p.segment_index == segment_index)
        {
            let along = p.along_m.unwrap_or(earlier_s - start_s);
            p.along_m = Some(along);
            p.target_s = Some((start_s + along).min(last_s));
        }
    }

    /// A state sample arrived at `now`: the car was at `sample.rtk`, located by the streamer
    /// at `progress` on its route, about half of the sample's round trip ago.
    pub fn observe(&mut self, now: Duration, sample: &super::Sample, progress: Progress) {
        let (position, speed, round_trip) = (sample.rtk, sample.speed, sample.round_trip);
        self.round_trips.push_back(round_trip);
        if self.round_trips.len() > ROUND_TRIPS {
            self.round_trips.pop_front();
        }
        let mut sorted = [Duration::ZERO; ROUND_TRIPS];
        let sorted = &mut sorted[..self.round_trips.len()];
        for (slot, &rtt) in sorted.iter_mut().zip(&self.round_trips) {
            *slot = rtt;
        }
        sorted.sort_unstable();
        self.median_round_trip = sorted[sorted.len() / 2];
        let Some(s) = self.along(position, progress) else {
            return;
        };
        let car_time = now.as_secs_f64() - round_trip.as_secs_f64() / 2.0;
        self.history.push_back(Fix {
            t: car_time,
            s,
            wheel: speed.abs(),
        });
        if self.history.len() > HISTORY {
            self.history.pop_front();
        }
        // The radius the car reports (it is −1 when its autopilot is inactive); else the larger
        // of the two firmware generations' at its speed.
        let reported = sample.look_ahead_radius_m;
        let radius = if reported.is_finite() && reported > 0.0 {
            reported
        } else {
            look_ahead_radius_m(speed)
        };
        let wheel = speed.abs();
        let speed = wheel * self.progress_ratio();
        let heading = (-sample.yaw_deg.to_radians()).rem_euclid(std::f64::consts::TAU);
        self.seen = Some(Seen {
            car_time,
            position,
            heading: heading.is_finite().then_some(heading),
            stretch: progress.segment,
            wheel,
            version: sample.version,
            s,
            speed,
            radius,
        });
        self.resolve();
    }

    /// When the next fault should be sent (seconds since the test began), if one's place is
    /// known: half a round trip before the car is predicted to reach it. Up to
    /// `MAX_IN_FLIGHT` (5) fault commands are in flight together, whatever their probes.
    pub fn due(&self) -> Option<Duration> {
        if self.in_flight.len() >= MAX_IN_FLIGHT {
            return None;
        }
        let seen = self.seen?;
        let round_trip = self.median_round_trip().as_secs_f64();
        let target = self.next()?.target_s?;
        let at = seen.car_time + self.predict_s(&seen, target, round_trip) - round_trip / 2.0;
        Some(Duration::from_secs_f64(at.max(0.0)))
    }

    /// The fault to send at `now`, if one is due; it is then in flight. Call again for the next.
    pub fn take_due(&mut self, now: Duration) -> Option<(usize, Fault)> {
        if self.due()? > now {
            return None;
        }
        let next = *self.next()?;
        self.pending
            .retain(|p| p.command_index != next.command_index);
        self.in_flight.push(InFlight {
            pending: next,
            sent: now,
        });
        Some((next.command_index, next.fault))
    }

    /// Fault commands on `probe` in flight.
    pub fn in_flight_on(&self, probe: &crate::model::Probe) -> usize {
        self.in_flight
            .iter()
            .filter(|f| &f.pending.fault.probe == probe)
            .count()
    }

    /// Whether a fault command is in flight.
    pub fn in_flight(&self) -> bool {
        !self.in_flight.is_empty()
    }

    /// The car confirmed fault command `command_index` at `now` (`resent`: its reply was lost
    /// and the car's fault list showed it added). Returns when the car added it.
    pub fn confirmed(
        &mut self,
        command_index: usize,
        now: Duration,
        resent: bool,
        rates: &ProbeRates,
    ) -> Option<(usize, Duration)> {
        let at = self
            .in_flight
            .iter()
            .position(|f| f.pending.command_index == command_index)?;
        let flight = self.in_flight.remove(at);
        let sent = flight.sent.as_secs_f64();
        let half_rtt = self.median_round_trip().as_secs_f64() / 2.0;
        let elapsed = now.as_secs_f64() - sent;
        // The middle of the command's round trip; after a lost reply, half a round trip after
        // sending (the reply's time says nothing then).
        let added = if resent || elapsed > 6.0 * half_rtt.max(0.001) {
            sent + half_rtt
        } else {
            sent + elapsed / 2.0
        };
        let added_at = Duration::from_secs_f64(added.max(0.0));
        let p = flight.pending;
        let window = FaultWindow::of(&p.fault, added_at, rates);
        self.placements.push(FaultPlacement {
            command_index: p.command_index,
            rule: p.rule,
            segment_index: p.segment_index,
            planned_along_m: p.along_m.unwrap_or(0.0),
            sent_s: sent,
            added_s: added,
            actual_along_m: None,
            error_m: None,
            acts_from_s: window.from.as_secs_f64(),
            acts_to_s: window.to.as_secs_f64(),
        });
        self.unresolved.push(self.placements.len() - 1);
        self.resolve();
        Some((p.command_index, added_at))
    }

    /// Fault command `command_index` ended without being added (refused, or the link lost).
    pub fn dropped(&mut self, command_index: usize) {
        self.in_flight
            .retain(|f| f.pending.command_index != command_index);
    }

    /// Every fault command in flight is given up (the drive stopped).
    pub fn dropped_all(&mut self) {
        self.in_flight.clear();
    }

    /// The placements so far (sent and confirmed faults), in the order the car added them.
    pub fn placements(&self) -> &[FaultPlacement] {
        &self.placements
    }

    /// The next fault to send: of those whose segment is appended, the one whose place comes
    /// first on the route (in plan order among equal places).
    fn next(&self) -> Option<&Pending> {
        self.pending
            .iter()
            .filter(|p| p.target_s.is_some())
            .min_by(|a, b| {
                a.target_s
                    .unwrap_or(f64::INFINITY)
                    .total_cmp(&b.target_s.unwrap_or(f64::INFINITY))
                    .then(a.command_index.cmp(&b.command_index))
            })
    }

    /// How far the car advanced along its route per metre its wheels turned, over the last
    /// [`PROGRESS_WINDOW_S`] (1 until then, within [`PROGRESS_RATIO`]): its speed along the route
    /// is its wheel speed at the last sample times this. A place is reached along the route,
    /// which a car cutting a corner or drifting advances along a little faster or slower than
    /// its wheels. The wheel speed is read by the car at the sample; the progress between two
    /// samples is not as sure over a jittery link (each sample's time is uncertain by half its
    /// round trip's jitter, ±20 ms here, ±20 % of the progress over 0.2 s), so it is measured
    /// over a second.
    fn progress_ratio(&self) -> f64 {
        let Some(last) = self.history.back() else {
            return 1.0;
        };
        let Some(from) = self
            .history
            .iter()
            .rposition(|f| last.t - f.t >= PROGRESS_WINDOW_S)
        else {
            return 1.0;
        };
        let fixes = self.history.range(from..);
        let wheels: f64 = fixes
            .clone()
            .zip(fixes.skip(1))
            .map(|(a, b)| (a.wheel + b.wheel) / 2.0 * (b.t - a.t))
            .sum();
        let progress = last.s - self.history[from].s;
        if wheels < MIN_WHEEL_TRAVEL_M {
            return 1.0;
        }
        (progress / wheels).clamp(PROGRESS_RATIO.0, PROGRESS_RATIO.1)
    }

    /// The car's distance along its route at `position`, near the stretch `hint` (where the
    /// streamer located it), continuous where the car cuts a corner.
    ///
    /// The closest point of the route is not: a car inside a corner is closest to the stretch
    /// before it up to the corner's bisector and to the stretch after it beyond, and there the
    /// closest point jumps by about 2·d·tan(θ/2) (d the car's distance inside the corner, θ the
    /// turn): 8 cm at 10 cm and 45°, which is a placement error before any link. Here each
    /// stretch owns the region between the bisectors (miters) of the corners at its ends, and
    /// inside it a position is at the fraction λ whose line, through the route at λ and turning
    /// from one miter's direction to the other's, passes through it. On the route that is the
    /// route's own distance; across a miter both stretches agree. Outside every region near
    /// `hint` (before the route's first point), the closest point on `hint`'s stretch.
    fn along(&self, position: Point, hint: Progress) -> Option<f64> {
        if !position.is_finite() {
            return None;
        }
        let stretches = self.route.len().saturating_sub(1);
        let from = hint.segment.saturating_sub(1);
        let to = (hint.segment + 2).min(stretches);
        (from..to)
            .filter_map(|i| self.mitered(i, position))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(s, _)| s)
            .or_else(|| self.distance(hint))
    }

    /// On stretch `i` (points `i`, `i + 1`), the distance along the route of `p` and `p`'s
    /// distance from the route there, when `p` is between the stretch's miters.
    fn mitered(&self, i: usize, p: Point) -> Option<(f64, f64)> {
        let (a, b) = (self.route.get(i)?.position, self.route.get(i + 1)?.position);
        let d = b - a;
        let length = d.norm();
        if length < 1e-9 {
            return None;
        }
        let (ma, mb) = (self.miter(i)?, self.miter(i + 1)?);
        let q = p - a;
        // g(λ) = (q − λd)·(ma + λ(mb − ma)): p's side of the line at λ; g(0) ≥ 0 ≥ g(1) inside.
        let (g0, g1) = (q.dot(ma), (q - d).dot(mb));
        if g0 < 0.0 || g1 > 0.0 {
            return None;
        }
        let dm = mb - ma;
        let (c0, c1, c2) = (g0, q.dot(dm) - d.dot(ma), -d.dot(dm));
        let linear = if g0 - g1 > 0.0 { g0 / (g0 - g1) } else { 0.0 };
        let lambda = if c2.abs() < 1e-12 {
            linear
        } else {
            let disc = (c1 * c1 - 4.0 * c2 * c0).max(0.0).sqrt();
            let roots = [(-c1 + disc) / (2.0 * c2), (-c1 - disc) / (2.0 * c2)];
            // Exactly one root lies in [0, 1] (g changes sign there); take the one closest to
            // the straight-miter estimate against rounding.
            roots
                .into_iter()
                .filter(|r| r.is_finite())
                .min_by(|x, y| (x - linear).abs().total_cmp(&(y - linear).abs()))
                .unwrap_or(linear)
        }
        .clamp(0.0, 1.0);
        Some((self.route_s[i] + lambda * length, p.dist(a + d * lambda)))
    }

    /// The unit normal of the miter at route point `i` (kept, see [`Self::compute_miter`]).
    fn miter(&self, i: usize) -> Option<Point> {
        self.miters.get(i).copied().flatten()
    }

    /// The unit normal of the miter at route point `i`: the bisector of the turn there (the
    /// stretch's own direction at the route's ends and at a U-turn).
    fn compute_miter(&self, i: usize) -> Option<Point> {
        let unit = |from: usize, to: usize| {
            let d = self.route.get(to)?.position - self.route.get(from)?.position;
            let n = d.norm();
            (n > 1e-9).then(|| d * (1.0 / n))
        };
        let incoming = i.checked_sub(1).and_then(|h| unit(h, i));
        let outgoing = unit(i, i + 1);
        match (incoming, outgoing) {
            (Some(a), Some(b)) => {
                let sum = a + b;
                let n = sum.norm();
                Some(if n > 1e-6 { sum * (1.0 / n) } else { b })
            }
            (one, other) => one.or(other),
        }
    }

    /// Seconds the car seen at `seen` needs to reach `target` (a distance along its route): its
    /// autopilot run forward ([`Self::pursue`]) when the route's speeds ([`Self::travel_s`]) say
    /// the command is due within [`PURSUIT_WINDOW_S`] of the sample's arrival (`round_trip` after
    /// the car's time), else the route's speeds (the drive asks again at every sample).
    fn predict_s(&self, seen: &Seen, target: f64, round_trip: f64) -> f64 {
        if let Some((car_time, cached, seconds)) = self.predicted.get()
            && car_time == seen.car_time
            && cached == target
        {
            return seconds;
        }
        let by_speeds = self.travel_s(seen, target, round_trip + PURSUIT_WINDOW_S + FINE_MARGIN_S);
        let seconds = if by_speeds - round_trip <= PURSUIT_WINDOW_S
            && let Some(t) = self.pursue(seen, target)
        {
            t
        } else {
            by_speeds
        };
        self.predicted.set(Some((seen.car_time, target, seconds)));
        seconds
    }

    /// Seconds the car seen at `seen` needs to reach `target` (a distance along its route),
    /// from the route's speeds.
    ///
    /// In speed mode the firmware's autopilot drives at the route's speed interpolated at its
    /// goal, the point a look-ahead radius ahead (`docs/firmware.md`, autopilot), and its motor
    /// reaches a new speed within a tenth of a second (RPM mode, 13.6 m/s²): a car at `s` drives
    /// at about the route's speed at `s + radius`. So the time is the integral of 1/speed over
    /// the way, the speeds taken where the goal will be, with the car's radius as it reported
    /// it; scaled by how the car's measured speed compares with the route's where it was
    /// measured (1 for a car that keeps its route's speeds; a car that does not, or a link that
    /// shifts the samples' times, keeps its own ratio). Where the route gives no speed, the
    /// measured speed.
    ///
    /// Integrated in 2 cm steps up to `fine_s` seconds of way, beyond in steps [`COARSE_STEPS`]
    /// times longer: a place that far ahead is only "not yet" (the drive asks again at every
    /// sample), and a long way in fine steps was a tenth of a simulated test's time.
    fn travel_s(&self, seen: &Seen, target: f64, fine_s: f64) -> f64 {
        const STEP_M: f64 = 0.02;
        let way = (target - seen.s).max(0.0);
        let steps = (way / STEP_M).ceil() as usize;
        if steps == 0 {
            return 0.0;
        }
        let ratio = self
            .route_speed(seen.s + seen.radius)
            .map(|asked| seen.speed / asked)
            .filter(|r| r.is_finite() && *r > 0.0);
        let ds = way / steps as f64;
        // The goals only move forward: the stretch is found by walking, not searched each step.
        let mut stretch = 0;
        let mut seconds_at = |at: f64, length: f64| {
            let speed = match (ratio, self.route_speed_from(&mut stretch, at + seen.radius)) {
                (Some(ratio), Some(asked)) => ratio * asked,
                _ => seen.speed,
            };
            length / speed.max(MIN_SPEED_MPS)
        };
        let mut seconds = 0.0;
        let mut k = 0;
        while k < steps && seconds < fine_s {
            seconds += seconds_at(seen.s + (k as f64 + 0.5) * ds, ds);
            k += 1;
        }
        while k < steps {
            let n = COARSE_STEPS.min(steps - k);
            seconds += seconds_at(seen.s + (k as f64 + n as f64 / 2.0) * ds, n as f64 * ds);
            k += n;
        }
        seconds
    }

    /// The speed the autopilot sets with its goal at `s` along the route: the speeds of the
    /// stretch's two points interpolated by the goal's distance from them (the last point's
    /// beyond the end). `None` where the route gives no positive speed.
    fn route_speed(&self, s: f64) -> Option<f64> {
        self.speed_before(self.route_s.partition_point(|&x| x <= s), s)
    }

    /// [`Self::route_speed`] for an `s` no smaller than at the previous call with `stretch`
    /// (start it at 0): the index of the first route point beyond `s` (the distances along the
    /// route only grow) is found by walking on from `stretch`, which it updates.
    fn route_speed_from(&self, stretch: &mut usize, s: f64) -> Option<f64> {
        let mut i = (*stretch).min(self.route_s.len());
        while self.route_s.get(i).is_some_and(|&x| x <= s) {
            i += 1;
        }
        *stretch = i;
        self.speed_before(i, s)
    }

    /// [`Self::route_speed`] at `s`, `i` the index of the first route point beyond it.
    fn speed_before(&self, i: usize, s: f64) -> Option<f64> {
        let last = self.route.len().checked_sub(1)?;
        let speed = if i == 0 {
            self.route[0].speed
        } else if i > last {
            self.route[last].speed
        } else {
            let (s0, s1) = (self.route_s[i - 1], self.route_s[i]);
            let (v0, v1) = (self.route[i - 1].speed, self.route[i].speed);
            if s1 > s0 {
                v0 + (v1 - v0) * (s - s0) / (s1 - s0)
            } else {
                v1
            }
        };
        (speed.is_finite() && speed > 0.0).then_some(speed)
    }

    fn distance(&self, progress: Progress) -> Option<f64> {
        let a = *self.route_s.get(progress.segment)?;
        let b = self.route_s.get(progress.segment + 1).copied().unwrap_or(a);
        Some(a + (b - a) * progress.fraction.clamp(0.0, 1.0))
    }

    fn median_round_trip(&self) -> Duration {
        self.median_round_trip
    }

    /// Finds where the car was when each unresolved fault was added: between the samples seen
    /// before and after that time.
    fn resolve(&mut self) {
        let history = &self.history;
        let route_s = &self.route_s;
        let segment_first = &self.segment_first;
        let placements = &mut self.placements;
        self.unresolved.retain(|&i| {
            let placement = &mut placements[i];
            let t = placement.added_s;
            let Some(after) = history.iter().position(|f| f.t >= t) else {
                return true;
            };
            let b = history[after];
            let s = match after.checked_sub(1).map(|before| history[before]) {
                Some(a) if b.t > a.t => a.s + (b.s - a.s) * (t - a.t) / (b.t - a.t),
                _ => b.s,
            };
            let start = segment_first
                .get(placement.segment_index)
                .and_then(|&first| first.checked_sub(1))
                .and_then(|start| route_s.get(start));
            if let Some(&start_s) = start {
                let actual = s - start_s;
                placement.actual_along_m = Some(actual);
                placement.error_m = Some(actual - placement.planned_along_m);
            }
            false
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::streaming::locate;

    /// A placer on the route (0,0) → (4,0) → (4,4) → (8,4): a left-hand and a right-hand 90°
    /// corner.
    fn placer() -> (Placer, Vec<Point>) {
        let points = vec![
            Point::new(0.0, 0.0),
            Point::new(4.0, 0.0),
            Point::new(4.0, 4.0),
            Point::new(8.0, 4.0),
        ];
        let waypoints: Vec<Waypoint> = points.iter().map(|&p| Waypoint::new(p, 1.0)).collect();
        let plan = TestPlan {
            test_index: 0,
            start_tail: trajgen::RouteTail::from_points(&points[..2]).unwrap(),
            commands: Vec::new(),
        };
        (Placer::new(&plan, &waypoints, None), points)
    }

    fn hint(route: &[Point], p: Point, from: usize) -> Progress {
        let route: Vec<Waypoint> = route.iter().map(|&q| Waypoint::new(q, 1.0)).collect();
        locate(&route, p, from).unwrap()
    }

    #[test]
    fn the_kept_miters_are_those_of_the_grown_route() {
        let (mut placer, _) = placer();
        // A point at a time, two at once, and one on top of the last (no stretch, no miter).
        let more = [(8.0, 8.0), (4.0, 10.0), (0.0, 9.0), (0.0, 9.0), (-3.0, 5.0)];
        let waypoints: Vec<Waypoint> = more
            .iter()
            .map(|&(x, y)| Waypoint::new(Point::new(x, y), 1.0))
            .collect();
        placer.extend(&waypoints[..1]);
        placer.extend(&waypoints[1..3]);
        placer.extend(&waypoints[3..]);
        assert_eq!(placer.miters.len(), placer.route.len());
        for i in 0..placer.route.len() {
            assert_eq!(placer.miter(i), placer.compute_miter(i), "point {i}");
        }
        // The corner at (8, 4) turned left by 90°: its miter is the bisector, not the old end's.
        let m = placer.miter(3).unwrap();
        assert!((m.x - 0.5f64.sqrt()).abs() < 1e-12 && (m.y - 0.5f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn on_the_route_the_distance_is_the_routes_own() {
        let (placer, route) = placer();
        for (p, s) in [
            ((0.5, 0.0), 0.5),
            ((3.0, 0.0), 3.0),
            ((4.0, 0.0), 4.0),
            ((4.0, 1.5), 5.5),
            ((4.0, 4.0), 8.0),
            ((6.5, 4.0), 10.5),
        ] {
            let p = Point::new(p.0, p.1);
            let along = placer.along(p, hint(&route, p, 0)).unwrap();
            assert!((along - s).abs() < 1e-9, "{p:?}: {along} instead of {s}");
        }
    }

    #[test]
    fn a_car_cutting_a_corner_advances_without_a_jump() {
        let (placer, route) = placer();
        // A quarter circle of radius 1 inside the first corner, from (3, 0) to (4, 1): 0.29 m
        // inside the corner at its middle.
        let steps = 200;
        let mut progress = hint(&route, Point::new(3.0, 0.0), 0);
        let (mut previous, mut previous_closest) = (None::<f64>, None::<f64>);
        let (mut largest, mut largest_closest) = (0.0_f64, 0.0_f64);
        for k in 0..=steps {
            let angle = std::f64::consts::FRAC_PI_2 * k as f64 / steps as f64;
            let p = Point::new(3.0 + angle.sin(), 1.0 - angle.cos());
            progress = hint(&route, p, progress.segment);
            let s = placer.along(p, progress).unwrap();
            let closest = placer.distance(progress).unwrap();
            if let (Some(a), Some(b)) = (previous, previous_closest) {
                assert!(s >= a - 1e-9, "backwards at {p:?}: {a} → {s}");
                largest = largest.max(s - a);
                largest_closest = largest_closest.max(closest - b);
            }
            previous = Some(s);
            previous_closest = Some(closest);
        }
        // The arc is 1.57 m long in 200 steps of 7.9 mm: no step of the distance is much more.
        assert!(largest < 0.03, "largest step {largest}");
        // The closest point jumps by 2 · 0.29 · tan 45° at the bisector.
        assert!(
            largest_closest > 0.5,
            "closest point's largest step {largest_closest}"
        );
        assert!((previous.unwrap() - 5.0).abs() < 1e-9);
    }

    /// A placer on a route along the x axis through the points `(x, speed)`.
    fn placer_along_x(points: &[(f64, f64)]) -> Placer {
        let route: Vec<Waypoint> = points
            .iter()
            .map(|&(x, v)| Waypoint::new(Point::new(x, 0.0), v))
            .collect();
        let plan = TestPlan {
            test_index: 0,
            start_tail: trajgen::RouteTail::from_points(&[
                Point::new(0.0, 0.0),
                Point::new(1.0, 0.0),
            ])
            .unwrap(),
            commands: Vec::new(),
        };
        Placer::new(&plan, &route, None)
    }

    #[test]
    fn a_car_is_predicted_to_speed_up_where_its_goal_reaches_a_faster_stretch() {
        // 1 m/s to x = 10, then towards x = 20 at 3 m/s: on that stretch the autopilot's speed
        // rises from 1 to 3 m/s as its goal, 1 m ahead, moves along it.
        let mut placer = placer_along_x(&[(0.0, 1.0), (10.0, 1.0), (20.0, 3.0)]);
        for k in 0..=6 {
            let sample = super::super::Sample {
                rtk: Point::new(7.4 + 0.1 * k as f64, 0.0),
                uwb: Point::new(7.4 + 0.1 * k as f64, 0.0),
                speed: 1.0,
                round_trip: Duration::ZERO,
                yaw_deg: 0.0,
                version: car_link::firmware::FirmwareVersion::V10_1,
                look_ahead_radius_m: 1.0,
            };
            let progress = Progress {
                segment: 0,
                fraction: sample.rtk.x / 10.0,
            };
            placer.observe(Duration::from_millis(100 * k), &sample, progress);
        }
        let seen = placer.seen.unwrap();
        assert!((seen.s - 8.0).abs() < 1e-9 && (seen.speed - 1.0).abs() < 1e-9);
        // To x = 11: 1 s to x = 9 (goal at 10), then ∫₀² du / (1 + 0.2 u) = 5 ln 1.4 s.
        let expected = 1.0 + 5.0 * 1.4f64.ln();
        let predicted = placer.travel_s(&seen, 11.0, f64::INFINITY);
        assert!(
            (predicted - expected).abs() < 0.01,
            "{predicted} instead of {expected}"
        );
        // A car driving at twice its route's speeds keeps doing so.
        let fast = Seen { speed: 2.0, ..seen };
        assert!((placer.travel_s(&fast, 11.0, f64::INFINITY) - expected / 2.0).abs() < 0.01);
    }

    /// Up to `fine_s` seconds of way the prediction is the fine integral itself; beyond, it
    /// stays beyond and within a percent of it.
    #[test]
    fn a_far_place_is_predicted_coarsely_and_a_near_one_exactly() {
        let placer = placer_along_x(&[(0.0, 1.0), (10.0, 0.5), (30.0, 3.0), (60.0, 1.0)]);
        for (s, speed, radius) in [(0.0, 1.0, 1.0), (4.2, 0.8, 1.5), (12.0, 0.6, 1.1)] {
            let seen = Seen {
                car_time: 1.0,
                position: Point::new(s, 0.0),
                heading: Some(0.0),
                stretch: 0,
                wheel: speed,
                version: car_link::firmware::FirmwareVersion::V10_1,
                s,
                speed,
                radius,
            };
            for target in [s + 0.3, s + 1.7, s + 9.0, 59.0, 75.0] {
                let exact = placer.travel_s(&seen, target, f64::INFINITY);
                for fine_s in [0.5, 2.0, 5.0] {
                    let quick = placer.travel_s(&seen, target, fine_s);
                    if exact < fine_s {
                        assert_eq!(quick.to_bits(), exact.to_bits(), "{s} → {target}");
                    } else {
                        assert!(quick >= fine_s, "{quick} < {fine_s}");
                        assert!((quick - exact).abs() <= 0.01 * exact, "{quick} vs {exact}");
                    }
                }
            }
        }
    }

    /// A placer on a straight 1 m/s route along x, fed samples of a car at `x(t)` with wheel
    /// speed `wheel`, every 50 ms for 2 s, each arriving after a round trip of 340 ms ± 40 ms
    /// (one in three late, the others early).
    fn seen_after(x: impl Fn(f64) -> f64, wheel: f64) -> Seen {
        let mut placer = placer_along_x(&[(0.0, 1.0), (100.0, 1.0)]);
        for k in 0..=40 {
            let t = 0.05 * k as f64;
            let jitter = if k % 3 == 1 { 0.04 } else { -0.04 };
            // The car answered at t; the reply came half a round trip plus the jitter later.
            let round_trip = 0.34 + jitter;
            let arrival = t + 0.17 + jitter;
            let position = Point::new(x(t), 0.0);
            let sample = super::super::Sample {
                rtk: position,
                uwb: position,
                speed: wheel,
                round_trip: Duration::from_secs_f64(round_trip),
                yaw_deg: 0.0,
                version: car_link::firmware::FirmwareVersion::V10_1,
                look_ahead_radius_m: 1.0,
            };
            let progress = Progress {
                segment: 0,
                fraction: position.x / 100.0,
            };
            placer.observe(Duration::from_secs_f64(arrival), &sample, progress);
        }
        placer.seen.unwrap()
    }

    #[test]
    fn the_speed_along_the_route_is_not_thrown_by_the_links_jitter() {
        // At 2 m/s, a sample's time is 20 ms off either way: the progress between the last
        // sample (late) and one 0.2 s before it (early) reads 17 % slow. The wheel speed does
        // not, and the progress per wheel travel over a second is 4 % off at most.
        let seen = seen_after(|t| 10.0 + 2.0 * t, 2.0);
        assert!((seen.speed - 2.0).abs() < 0.1, "{}", seen.speed);
        // A car advancing along its route faster than its wheels turn (cutting corners) keeps
        // its ratio, measured over a second.
        let cutting = seen_after(|t| 10.0 + 2.4 * t, 2.0);
        assert!((cutting.speed - 2.4).abs() < 0.12, "{}", cutting.speed);
        // A jump in where the car is located says nothing of its speed beyond the bounds.
        let jumped = seen_after(
            |t| {
                if t < 1.5 {
                    10.0 + 2.0 * t
                } else {
                    20.0 + 2.0 * t
                }
            },
            2.0,
        );
        assert!((jumped.speed - 2.5).abs() < 1e-9, "{}", jumped.speed);
    }

    #[test]
    fn before_the_route_the_closest_point_is_taken() {
        let (placer, route) = placer();
        let p = Point::new(-1.0, 0.3);
        assert_eq!(placer.along(p, hint(&route, p, 0)), Some(0.0));
        assert_eq!(
            placer.along(Point::new(f64::NAN, 0.0), hint(&route, p, 0)),
            None
        );
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig {
            failure_persistence: None,
            ..proptest::prelude::ProptestConfig::with_cases(200)
        })]
        /// Walking on from the last stretch finds the speed the search over the whole route
        /// finds, for any rising distances (before the start, on the route, beyond its end),
        /// on a route with repeated points and changing speeds.
        #[test]
        fn the_walked_route_speed_is_the_searched_one(
            legs in proptest::collection::vec((0.0..3.0f64, 0.1..4.0f64), 1..12),
            steps in proptest::collection::vec(0.0..2.0f64, 1..40),
            from in -2.0..2.0f64,
        ) {
            let mut at = Point::new(0.0, 0.0);
            let mut waypoints = vec![Waypoint::new(at, 1.0)];
            for (i, &(length, speed)) in legs.iter().enumerate() {
                at = at + Point::from_heading(i as f64) * length;
                waypoints.push(Waypoint::new(at, speed));
            }
            let points: Vec<Point> = waypoints.iter().map(|w| w.position).collect();
            let plan = TestPlan {
                test_index: 0,
                start_tail: trajgen::RouteTail::from_points(&[Point::new(-1.0, 0.0), points[0]]).unwrap(),
                commands: Vec::new(),
            };
            let placer = Placer::new(&plan, &waypoints, None);
            let mut stretch = 0;
            let mut s = from;
            for step in steps {
                proptest::prop_assert_eq!(
                    placer.route_speed_from(&mut stretch, s),
                    placer.route_speed(s),
                    "at {}", s
                );
                s += step;
            }
        }
    }
}
