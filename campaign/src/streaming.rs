//! The streaming rule: when to append the next segment so the car never reaches the end of its
//! route during a test.
//!
//! From the car's position along the route and the route's speeds the streamer computes the time
//! the car still needs to reach the point where its autopilot would stop (the route end minus the
//! look-ahead radius, `docs/firmware.md#end-of-route`). The next segment is appended when that time
//! falls to the **lead time**: the 99th percentile of the measured link round trips plus the
//! 99th percentile of the measured generation times plus a safety margin (before any
//! measurement, configured defaults stand in). At every append the streamer records the time
//! left, and once the car confirms the points, the **margin left** (time left minus the delay to
//! the confirmation). A car that reaches the stopping point is a **starvation** event.
//!
//! Pure: time is passed in as [`Duration`]s; nothing here reads a clock.

use std::collections::VecDeque;
use std::time::Duration;

use trajgen::Point;

/// Segments searched ahead of the last closest one when locating the car. Segments are at least
/// 0.6 m long, so this covers ≥ 4.8 m: far more than the car drives between two state samples.
/// Locate the car at the state rate; a car located behind its true place would make the time
/// left look longer than it is.
const ROUTE_WINDOW: usize = 8;

/// The streaming rule's constants (on record: `crate::files::StreamingConfigRecord`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamingConfig {
    /// Added to the measured delays (1000 ms).
    pub margin: Duration,
    /// Round trip assumed before any is measured (500 ms).
    pub initial_round_trip: Duration,
    /// Generation time assumed before any is measured (100 ms).
    pub initial_generation: Duration,
    /// Most recent measurements the percentiles are taken over (200).
    pub window: usize,
    /// Speeds below this count as this, m/s (0.1), so a stopped point does not divide by zero.
    pub min_speed_mps: f64,
}

impl Default for StreamingConfig {
    fn default() -> Self {
        Self {
            margin: Duration::from_millis(1000),
            initial_round_trip: Duration::from_millis(500),
            initial_generation: Duration::from_millis(100),
            window: 200,
            min_speed_mps: 0.1,
        }
    }
}

/// A point of the car's route with the speed it drives towards it (the route the streamer
/// watches is a list of them).
pub use trajgen::Waypoint;

/// `route` as the car's protocol sends it: speed-mode points (`AP_ADD_POINTS`).
pub fn route_points(route: &[Waypoint]) -> Vec<car_link::RoutePoint> {
    route
        .iter()
        .map(|w| car_link::RoutePoint::at(w.position.x, w.position.y, w.speed))
        .collect()
}

/// Where the car is along its route: on segment `segment` (from point `segment` to
/// `segment + 1`) at `fraction` (0..=1) of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Index of the segment's first point.
    pub segment: usize,
    /// How far along the segment, 0..=1.
    pub fraction: f64,
}

/// The autopilot's look-ahead radius at `speed` m/s, the larger of every firmware generation's
/// (`car_link::firmware::steering::largest_look_ahead_radius_m`): 12.x `max(0.8 s · v, 0.8 m)`
/// and 10.x `1.2 m · (1 + 0.05 v)²`. The car stops at the route end once it is within this
/// distance of the last point.
pub fn look_ahead_radius_m(speed: f64) -> f64 {
    car_link::firmware::steering::largest_look_ahead_radius_m(speed)
}

/// Locates `position` on `route`: the closest segment among the `ROUTE_WINDOW` segments from
/// `from_segment` on, and the clamped projection on it. `None` for a route of fewer than two
/// points or a non-finite position.
pub fn locate(route: &[Waypoint], position: Point, from_segment: usize) -> Option<Progress> {
    if route.len() < 2 || !position.is_finite() {
        return None;
    }
    let last = route.len() - 2;
    let first = from_segment.min(last);
    let end = (first + ROUTE_WINDOW).min(last);
    (first..=end)
        .map(|segment| project(route, segment, position))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(progress, _)| progress)
}

/// The progress on `segment` closest to `p`, and its distance.
fn project(route: &[Waypoint], segment: usize, p: Point) -> (Progress, f64) {
    let a = route[segment].position;
    let b = route[segment + 1].position;
    let ab = b - a;
    let length_sq = ab.dot(ab);
    let fraction = if length_sq > 0.0 {
        ((p - a).dot(ab) / length_sq).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let closest = a + ab * fraction;
    (Progress { segment, fraction }, closest.dist(p))
}

/// The time the car at `progress` still needs to reach the point where it would stop: the route
/// end minus the look-ahead radius at the last point's speed. Each stretch is driven at the speed
/// of the point it leads to (at least `min_speed_mps`). Zero when it is already there.
pub fn time_to_end(route: &[Waypoint], progress: Progress, min_speed_mps: f64) -> Duration {
    let Some(last) = route.last() else {
        return Duration::ZERO;
    };
    let stretches = remaining_stretches(route, progress);
    let total: f64 = stretches.iter().map(|(length, _)| length).sum();
    let mut left = total - look_ahead_radius_m(last.speed);
    let mut seconds = 0.0;
    for (length, speed) in stretches {
        if left <= 0.0 {
            break;
        }
        let driven = length.min(left);
        seconds += driven / speed.max(min_speed_mps);
        left -= driven;
    }
    Duration::try_from_secs_f64(seconds).unwrap_or(Duration::MAX)
}

/// The stretches still to drive from `progress`: (length, speed towards its end).
fn remaining_stretches(route: &[Waypoint], progress: Progress) -> Vec<(f64, f64)> {
    let speed = |w: &Waypoint| if w.speed.is_finite() { w.speed } else { 0.0 };
    route
        .windows(2)
        .enumerate()
        .skip(progress.segment)
        .map(|(i, pair)| {
            let length = pair[0].position.dist(pair[1].position);
            let share = if i == progress.segment {
                1.0 - progress.fraction.clamp(0.0, 1.0)
            } else {
                1.0
            };
            (length * share, speed(&pair[1]))
        })
        .collect()
}

/// The most recent `len` measurements of one kind, kept in arrival order and sorted: a
/// percentile is read at every state sample, so it is an index, not a sort of the window.
#[derive(Debug, Clone, PartialEq, Default)]
struct Window {
    arrived: VecDeque<Duration>,
    sorted: Vec<Duration>,
}

impl Window {
    /// Adds `d`; the oldest measurement leaves once there are more than `len`.
    fn push(&mut self, d: Duration, len: usize) {
        self.arrived.push_back(d);
        let at = self.sorted.partition_point(|&x| x < d);
        self.sorted.insert(at, d);
        while self.arrived.len() > len {
            if let Some(old) = self.arrived.pop_front() {
                // Present: every value in `arrived` is in `sorted` once per arrival.
                if let Ok(at) = self.sorted.binary_search(&old) {
                    self.sorted.remove(at);
                }
            }
        }
    }

    /// The nearest-rank 99th percentile; `None` before any measurement.
    fn p99(&self) -> Option<Duration> {
        trajgen::stats::nearest_rank(&self.sorted, 0.99)
    }
}

/// Measured link round trips, append confirmation delays and generation times (the most recent
/// `window` of each).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Delays {
    round_trips: Window,
    /// From deciding an append to the car's confirmation: on a lossy link the retries of the
    /// upload, which a state sample's round trip does not show.
    appends: Window,
    generations: Window,
    window: usize,
}

impl Delays {
    /// No measurements yet; keeps the most recent `window` of each kind (at least 1).
    pub fn new(window: usize) -> Self {
        Self {
            round_trips: Window::default(),
            appends: Window::default(),
            generations: Window::default(),
            window: window.max(1),
        }
    }

    /// One measured request-to-reply time.
    pub fn round_trip(&mut self, d: Duration) {
        self.round_trips.push(d, self.window);
    }

    /// One append's delay from decision to the car's confirmation.
    pub fn append(&mut self, d: Duration) {
        self.appends.push(d, self.window);
    }

    /// One measured segment generation time.
    pub fn generation(&mut self, d: Duration) {
        self.generations.push(d, self.window);
    }

    /// The lead time: the larger of the p99 round trip and the p99 append confirmation delay, +
    /// p99 generation + margin (configured initial values until measured). On a lossy link an
    /// upload needs retries: its confirmation delay, not a state sample's round trip, is what the
    /// car's remaining route must cover.
    pub fn lead_time(&self, config: &StreamingConfig) -> Duration {
        let round_trip = self
            .round_trips
            .p99()
            .unwrap_or(config.initial_round_trip)
            .max(self.appends.p99().unwrap_or_default());
        let generation = self.generations.p99().unwrap_or(config.initial_generation);
        round_trip
            .saturating_add(generation)
            .saturating_add(config.margin)
    }
}

/// What the streamer says after a state sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// Time the car still needs to reach its stopping point.
    pub time_to_end: Duration,
    /// The current lead time.
    pub lead: Duration,
    /// Append the next segment now.
    pub append: bool,
    /// The car has reached its stopping point: a starvation event.
    pub starved: bool,
}

/// One append (on record: `crate::files::AppendRecord`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Append {
    /// When it was decided.
    pub decided_at: Duration,
    /// Time the car still needed then.
    pub time_to_end: Duration,
    /// The lead time then.
    pub lead: Duration,
    /// Delay from the decision to the car's confirmation; absent until confirmed.
    pub confirmed_after: Option<Duration>,
}

impl Append {
    /// The margin left when the car had the points: `time_to_end − confirmed_after`, seconds
    /// (negative: the car would have reached its stopping point first). `None` until confirmed.
    pub fn margin_left_s(&self) -> Option<f64> {
        self.confirmed_after
            .map(|delay| self.time_to_end.as_secs_f64() - delay.as_secs_f64())
    }
}

/// The streaming state of one test: the route the car has, where it is, the delays, the appends
/// and the starvation events.
#[derive(Debug, Clone, PartialEq)]
pub struct Streamer {
    config: StreamingConfig,
    route: Vec<Waypoint>,
    progress: Progress,
    delays: Delays,
    appends: Vec<Append>,
    starvations: Vec<Duration>,
    starving: bool,
}

impl Streamer {
    /// A streamer for a car that has `route` (the start route) and is at its beginning.
    pub fn new(config: StreamingConfig, route: &[Waypoint]) -> Self {
        Self {
            config,
            route: route.to_vec(),
            progress: Progress {
                segment: 0,
                fraction: 0.0,
            },
            delays: Delays::new(config.window),
            appends: Vec::new(),
            starvations: Vec::new(),
            starving: false,
        }
    }

    /// The measured delays (record round trips and generation times here).
    pub fn delays_mut(&mut self) -> &mut Delays {
        &mut self.delays
    }

    /// Where the car was last located.
    pub fn progress(&self) -> Progress {
        self.progress
    }

    /// Feeds the car's position at `now` and decides. A new starvation event is recorded when
    /// the car reaches its stopping point (once per episode). Without a usable position the car
    /// is assumed where it was last seen.
    pub fn observe(&mut self, now: Duration, position: Point) -> Decision {
        if let Some(progress) = locate(&self.route, position, self.progress.segment) {
            self.progress = progress;
        }
        let time_to_end = time_to_end(&self.route, self.progress, self.config.min_speed_mps);
        let lead = self.delays.lead_time(&self.config);
        let starved = time_to_end.is_zero();
        if starved && !self.starving {
            self.starvations.push(now);
        }
        self.starving = starved;
        Decision {
            time_to_end,
            lead,
            append: time_to_end <= lead,
            starved,
        }
    }

    /// Records an append decided by `decision` at `now` of `points`; returns its index for
    /// [`Self::confirmed`].
    pub fn appended(&mut self, now: Duration, decision: &Decision, points: &[Waypoint]) -> usize {
        self.route.extend_from_slice(points);
        self.appends.push(Append {
            decided_at: now,
            time_to_end: decision.time_to_end,
            lead: decision.lead,
            confirmed_after: None,
        });
        self.appends.len() - 1
    }

    /// The car confirmed append `index` at `now`. Unknown indices are ignored.
    pub fn confirmed(&mut self, index: usize, now: Duration) {
        if let Some(append) = self.appends.get_mut(index) {
            let delay = now.saturating_sub(append.decided_at);
            append.confirmed_after = Some(delay);
            self.delays.append(delay);
        }
    }

    /// Every append so far.
    pub fn appends(&self) -> &[Append] {
        &self.appends
    }

    /// When the car reached its stopping point during the test.
    pub fn starvations(&self) -> &[Duration] {
        &self.starvations
    }

    /// The smallest margin left over the confirmed appends, seconds.
    pub fn smallest_margin_s(&self) -> Option<f64> {
        self.appends
            .iter()
            .filter_map(Append::margin_left_s)
            .min_by(f64::total_cmp)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    /// A straight route along y = 0 with points every 2 m from x = 0 to x = 20, at `speed`.
    fn straight(speed: f64) -> Vec<Waypoint> {
        (0..=10)
            .map(|i| Waypoint {
                position: Point::new(2.0 * f64::from(i), 0.0),
                speed,
            })
            .collect()
    }

    fn close(a: Duration, b: f64) -> bool {
        (a.as_secs_f64() - b).abs() < 1e-6
    }

    #[test]
    fn the_look_ahead_radius_covers_both_firmware_generations() {
        assert!((look_ahead_radius_m(0.0) - 1.2).abs() < 1e-12);
        assert!((look_ahead_radius_m(2.0) - 1.6).abs() < 1e-12);
        assert!((look_ahead_radius_m(1.0) - 1.323).abs() < 1e-12);
    }

    #[test]
    fn the_car_is_located_by_projection() {
        let route = straight(1.0);
        let p = locate(&route, Point::new(5.0, 0.3), 0).unwrap();
        assert_eq!(p.segment, 2);
        assert!((p.fraction - 0.5).abs() < 1e-12);
        assert_eq!(locate(&route[..1], Point::new(0.0, 0.0), 0), None);
    }

    #[test]
    fn time_to_end_is_the_distance_to_the_stopping_point_over_the_speeds() {
        // At x = 5 on a 20 m route at 2 m/s: 15 m left, minus the 1.6 m radius, at 2 m/s.
        let route = straight(2.0);
        let progress = locate(&route, Point::new(5.0, 0.0), 0).unwrap();
        assert!(close(
            time_to_end(&route, progress, 0.1),
            (15.0 - 1.6) / 2.0
        ));
        // Within the radius of the end: nothing left.
        let end = locate(&route, Point::new(19.0, 0.0), progress.segment).unwrap();
        assert_eq!(time_to_end(&route, end, 0.1), Duration::ZERO);
    }

    #[test]
    fn each_stretch_is_driven_at_the_speed_of_the_point_it_leads_to() {
        // 0 → 2 m at 1 m/s, 2 → 4 m at 4 m/s, end radius at 4 m/s is 3.2 m: 0.8 m of the second
        // stretch counts. 2 s + 0.2 s.
        let route = vec![
            Waypoint {
                position: Point::new(0.0, 0.0),
                speed: 1.0,
            },
            Waypoint {
                position: Point::new(2.0, 0.0),
                speed: 1.0,
            },
            Waypoint {
                position: Point::new(6.0, 0.0),
                speed: 4.0,
            },
        ];
        let start = Progress {
            segment: 0,
            fraction: 0.0,
        };
        assert!(close(time_to_end(&route, start, 0.1), 2.0 + 0.8 / 4.0));
    }

    #[test]
    fn p99_is_the_nearest_rank() {
        let mut window = Window::default();
        assert_eq!(window.p99(), None);
        window.push(ms(7), 200);
        assert_eq!(window.p99(), Some(ms(7)));
        // Arriving in any order, the 200 values 1..=200 ms: the 198th.
        let mut window = Window::default();
        for k in 0..200 {
            window.push(ms(1 + (k * 37) % 200), 200);
        }
        assert_eq!(window.p99(), Some(ms(198)));
    }

    #[test]
    fn a_slow_append_confirmation_raises_the_lead_time() {
        let config = StreamingConfig::default();
        let mut delays = Delays::new(config.window);
        for _ in 0..100 {
            delays.round_trip(ms(40));
        }
        delays.generation(ms(3));
        assert_eq!(delays.lead_time(&config), ms(40 + 3 + 1000));
        // An upload that needed retries on a lossy link took 4.2 s to be confirmed.
        delays.append(ms(300));
        delays.append(ms(4200));
        assert_eq!(delays.lead_time(&config), ms(4200 + 3 + 1000));
    }

    #[test]
    fn the_lead_time_follows_the_measured_delays() {
        let config = StreamingConfig::default();
        let mut delays = Delays::new(config.window);
        assert_eq!(delays.lead_time(&config), ms(500 + 100 + 1000));
        for rtt in [150, 190, 230] {
            delays.round_trip(ms(rtt));
        }
        delays.generation(ms(3));
        assert_eq!(delays.lead_time(&config), ms(230 + 3 + 1000));
    }

    #[test]
    fn old_measurements_leave_the_window() {
        let mut delays = Delays::new(2);
        for rtt in [900, 100, 120] {
            delays.round_trip(ms(rtt));
        }
        let config = StreamingConfig {
            margin: Duration::ZERO,
            initial_generation: Duration::ZERO,
            ..StreamingConfig::default()
        };
        assert_eq!(delays.lead_time(&config), ms(120));
    }

    #[test]
    fn a_segment_is_appended_when_the_time_left_falls_to_the_lead_time() {
        // 2 m/s, radius 1.6 m, lead 1.6 s: append once less than 1.6 + 3.2 m are left.
        let config = StreamingConfig::default();
        let mut streamer = Streamer::new(config, &straight(2.0));
        let early = streamer.observe(ms(0), Point::new(10.0, 0.0));
        assert!(!early.append);
        let late = streamer.observe(ms(100), Point::new(15.5, 0.0));
        assert!(late.append, "{late:?}");
        assert!(!late.starved);
        let more: Vec<Waypoint> = (11..=14)
            .map(|i| Waypoint {
                position: Point::new(2.0 * f64::from(i), 0.0),
                speed: 2.0,
            })
            .collect();
        let index = streamer.appended(ms(100), &late, &more);
        streamer.confirmed(index, ms(400));
        let margin = streamer.smallest_margin_s().unwrap();
        assert!((margin - (late.time_to_end.as_secs_f64() - 0.3)).abs() < 1e-9);
        assert!(!streamer.observe(ms(500), Point::new(16.0, 0.0)).append);
    }

    #[test]
    fn reaching_the_stopping_point_is_one_starvation_event() {
        let mut streamer = Streamer::new(StreamingConfig::default(), &straight(1.0));
        assert!(!streamer.observe(ms(0), Point::new(10.0, 0.0)).starved);
        assert!(streamer.observe(ms(100), Point::new(19.0, 0.0)).starved);
        assert!(streamer.observe(ms(200), Point::new(19.5, 0.0)).starved);
        assert_eq!(streamer.starvations(), [ms(100)]);
    }

    proptest::proptest! {
        #[test]
        fn the_time_left_never_grows_as_the_car_drives_on(
            speeds in proptest::collection::vec(0.5f64..4.0, 11),
            steps in proptest::collection::vec(0.0f64..0.5, 1..60),
        ) {
            let route: Vec<Waypoint> = straight(1.0)
                .into_iter()
                .zip(speeds)
                .map(|(w, speed)| Waypoint { speed, ..w })
                .collect();
            let mut x = 0.0;
            let mut progress = locate(&route, Point::new(x, 0.0), 0).unwrap();
            let mut before = time_to_end(&route, progress, 0.1);
            for step in steps {
                x += step;
                progress = locate(&route, Point::new(x, 0.2), progress.segment).unwrap();
                let now = time_to_end(&route, progress, 0.1);
                proptest::prop_assert!(now <= before);
                before = now;
            }
        }

        #[test]
        fn the_windows_p99_is_that_of_its_last_values_sorted(
            values in proptest::collection::vec(0u64..50, 1..120),
            len in 1usize..40,
        ) {
            let mut window = Window::default();
            for (k, &v) in values.iter().enumerate() {
                window.push(ms(v), len);
                let mut last: Vec<Duration> =
                    values[(k + 1).saturating_sub(len)..=k].iter().map(|&v| ms(v)).collect();
                last.sort_unstable();
                proptest::prop_assert_eq!(&window.sorted, &last);
                proptest::prop_assert_eq!(window.p99(), trajgen::stats::nearest_rank(&last, 0.99));
            }
        }
    }

    #[test]
    fn an_append_knows_the_margin_it_left() {
        let append = Append {
            decided_at: ms(1000),
            time_to_end: ms(2400),
            lead: ms(1700),
            confirmed_after: Some(ms(180)),
        };
        assert!((append.margin_left_s().unwrap() - 2.22).abs() < 1e-9);
    }
}
