//! Acceptance tests of the simulated car on the model (no link): driving accuracy, UWB deviation,
//! faults, determinism and the watchdog, with fixtures copied from the bundled two-anchor parking
//! lot.

use std::collections::VecDeque;
use std::f64::consts::PI;

use scenarios::geometry::{Area, Point, Polygon, point_segment_distance};

use crate::noise::Noise;
use crate::{
    CarOptions, FirmwareVersion, Placement, RadioPath, RcMode, RoutePoint, SimCar, StateReport,
    World, WorldAnchor,
};

/// The fence of `parking-lot-2anchors.xml` (route id 2).
const LOT_FENCE: [(f64, f64); 28] = [
    (-24.522, -61.688),
    (-26.349, -60.216),
    (-29.623, -56.968),
    (-31.678, -54.684),
    (-32.922, -53.009),
    (-32.795, -52.222),
    (-32.033, -51.207),
    (-31.196, -49.862),
    (-30.181, -48.898),
    (-29.267, -48.34),
    (-28.125, -48.517),
    (-27.516, -49.228),
    (-27.161, -50.015),
    (-26.603, -50.953),
    (-26.045, -51.664),
    (-24.7, -52.248),
    (-22.796, -52.527),
    (-21.408, -52.067),
    (-19.582, -51.705),
    (-18.555, -52.77),
    (-18.288, -53.436),
    (-18.432, -54.785),
    (-19.65, -55.902),
    (-20.563, -56.942),
    (-21.122, -57.932),
    (-21.553, -59.404),
    (-22.568, -60.47),
    (-23.405, -61.307),
];
/// Its start route (route id 0).
const LOT_START: [(f64, f64); 3] = [(-25.957, -59.162), (-26.472, -58.634), (-27.333, -57.831)];
/// Its anchors: (id, x, y, height).
const LOT_ANCHORS: [(u8, f64, f64, f64); 2] =
    [(234, -36.477, -53.315, 1.0), (50, -24.33, -64.749, 1.0)];

fn lot_area() -> Area {
    let fence = Polygon::new(LOT_FENCE.iter().map(|&(x, y)| Point::new(x, y)).collect())
        .expect("the lot's fence is a simple polygon");
    Area::new(fence, Vec::new()).expect("a valid area")
}

fn lot_world() -> World {
    World {
        anchors: LOT_ANCHORS
            .iter()
            .map(|&(id, x, y, height)| WorldAnchor {
                id,
                position: Point::new(x, y),
                height,
                range_bias_m: None,
            })
            .collect(),
        ..World::default()
    }
}

fn start_points() -> Vec<Point> {
    LOT_START.iter().map(|&(x, y)| Point::new(x, y)).collect()
}

/// A random drivable extension of `route` (segments 0.6–2.0 m, turns below 30°, `clearance` from
/// the fence), backtracking out of corners.
fn random_route(
    area: &Area,
    route: &mut Vec<Point>,
    extra_m: f64,
    clearance: f64,
    noise: &mut Noise,
) {
    let fixed = route.len();
    let target = polyline_length(route) + extra_m;
    let mut attempts = 0;
    while polyline_length(route) < target {
        attempts += 1;
        assert!(attempts < 200_000, "the route generator is stuck");
        let n = route.len();
        let heading = (route[n - 1] - route[n - 2]).heading();
        let candidate = (0..60).find_map(|_| {
            let len = noise.uniform_in(0.6, 2.0);
            let turn = noise.uniform_in(-29.0, 29.0).to_radians();
            let p = route[n - 1] + Point::from_heading(heading + turn) * len;
            let ok = area.contains_segment(route[n - 1], p)
                && area.segment_boundary_distance(route[n - 1], p) >= clearance;
            ok.then_some(p)
        });
        match candidate {
            Some(p) => route.push(p),
            None => {
                let keep = (route.len().saturating_sub(4)).max(fixed);
                route.truncate(keep);
            }
        }
    }
}

fn polyline_length(points: &[Point]) -> f64 {
    points.windows(2).map(|w| w[0].dist(w[1])).sum()
}

/// The nearest-rank percentile `p` of `xs` (the workspace's one definition).
fn percentile(mut xs: Vec<f64>, p: f64) -> f64 {
    xs.sort_by(f64::total_cmp);
    trajgen::stats::nearest_rank(&xs, p).expect("no samples")
}

/// An orchestrator stand-in: uploads the route in acked packets of 5 as the car needs it and polls
/// GET_STATE every 50 ms.
struct Driver {
    car: SimCar,
    queue: VecDeque<RoutePoint>,
    stopped: bool,
}

impl Driver {
    fn new(mut car: SimCar, route: &[RoutePoint]) -> Self {
        car.terminal("pos_uwb_reset_pos");
        if car.firmware().profile().uwb_reset == car_link::firmware::UwbReset::PositionOnly {
            // 12.x's reset copies the position only, and the UWB heading of a car that stood
            // still since boot is frozen at 0°: set the whole pose, as an orchestrator must.
            let s = car.get_state();
            car.set_pos(s.px, s.py, s.yaw);
        }
        car.set_config(crate::FirmwareConfig {
            ap_repeat_routes: false,
            ..*car.config()
        });
        let mut d = Self {
            car,
            queue: route.iter().copied().collect(),
            stopped: false,
        };
        d.upload();
        d.upload();
        d.car.set_active(true, false);
        d
    }

    fn upload(&mut self) {
        let n = self.queue.len().min(5);
        if n > 0 {
            let packet: Vec<RoutePoint> = self.queue.drain(..n).collect();
            self.car.add_points(&packet);
        }
    }

    /// Runs for `ms`, calling `on_poll` with every state.
    fn run(&mut self, ms: u64, mut on_poll: impl FnMut(&SimCar, &StateReport)) {
        let end = self.car.now_ms() + ms;
        while self.car.now_ms() < end {
            self.car.step();
            if self.car.now_ms().is_multiple_of(50) {
                let state = self.car.get_state();
                if state.ap_route_left <= 8 {
                    self.upload();
                }
                if self.queue.is_empty() && state.ap_route_left <= 3 && !self.stopped {
                    // The method's safe stop: brake with RC_CONTROL near the route's end (a 10.x
                    // car that overshoots its route-end circle at speed would otherwise follow
                    // the wrapped window back towards route[0]: `docs/firmware.md#control-cycle`).
                    self.car.rc_control(RcMode::Brake, 50.0, 0.0);
                    self.stopped = true;
                }
                on_poll(&self.car, &state);
            }
        }
    }
}

fn placed_car(firmware: FirmwareVersion, seed: u64, route: &[Point]) -> SimCar {
    let heading = (route[1] - route[0]).heading();
    let mut car = SimCar::new(CarOptions {
        firmware,
        seed,
        world: lot_world(),
        placement: Placement {
            x: route[0].x,
            y: route[0].y,
            heading,
        },
        ..CarOptions::default()
    });
    for &(id, x, y, h) in &LOT_ANCHORS {
        car.add_anchor(i16::from(id), x as f32, y as f32, h as f32);
    }
    car
}

fn route_points(points: &[Point], speeds: impl Fn(usize) -> f64) -> Vec<RoutePoint> {
    points
        .iter()
        .enumerate()
        .map(|(i, p)| RoutePoint::at(p.x as f32, p.y as f32, speeds(i) as f32))
        .collect()
}

/// Distance from `p` to the route near segment `*k` (tracking progress monotonically).
fn cross_track(route: &[Point], k: &mut usize, p: Point) -> f64 {
    let hi = (*k + 12).min(route.len() - 1);
    let (best, d) = (*k..hi)
        .map(|i| (i, point_segment_distance(p, route[i], route[i + 1])))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((*k, f64::INFINITY));
    *k = best;
    d
}

/// How the car steers in a cross-track measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Steering {
    /// The documented firmware (`docs/firmware.md#steering-law`) with the distance compensation
    /// dividing `R_pp`.
    Documented,
    /// The documented firmware with `ap_ang_dist_comp 0`.
    CompensationOff,
    /// The 2016 code: the distance compensation multiplies the steering angle (not reproduced by
    /// the simulator; a test-only experiment for comparison).
    MultiplyAngle2016,
    /// The documented law with perfect sensing and steering: no GNSS noise or delay and an
    /// instant servo, i.e. the floor of the law itself at the 10 ms tick.
    DocumentedIdealSensors,
}

/// Cross-track error of the true position from the planned polyline, at the 20 Hz polls.
struct CrossTrack {
    p50: f64,
    p95: f64,
    max: f64,
    samples: usize,
    outside: bool,
}

/// Drives the scenario's start route and `length_m` of random route at 3 m/s and measures the
/// cross-track error of the true position (start route and last segments excluded).
fn drive_and_measure(
    scenario: &scenarios::Scenario,
    firmware: FirmwareVersion,
    seed: u64,
    length_m: f64,
    steering: Steering,
    configure: impl Fn(&mut SimCar),
) -> CrossTrack {
    let area = &scenario.area;
    let mut route = scenario.start_route.positions();
    let start_len = route.len();
    let mut noise = Noise::stream(seed, 99);
    random_route(area, &mut route, length_m, 0.6, &mut noise);
    let start_speeds: Vec<f64> = scenario
        .start_route
        .points
        .iter()
        .map(|p| p.speed)
        .collect();
    let points = route_points(&route, |i| start_speeds.get(i).copied().unwrap_or(3.0));
    let ideal = steering == Steering::DocumentedIdealSensors;
    let mut car = SimCar::new(CarOptions {
        firmware,
        seed,
        world: World::from_scenario(scenario),
        placement: Placement::at_start_of(scenario).expect("a start route"),
        gnss: if ideal {
            crate::GnssModel {
                sigma_m: 0.0,
                latency_ms: 0,
                ..crate::GnssModel::default()
            }
        } else {
            crate::GnssModel::default()
        },
        ..CarOptions::default()
    });
    if steering == Steering::CompensationOff {
        assert_eq!(
            car.terminal("ap_ang_dist_comp 0"),
            ["Angle distance compensation disabled\n"]
        );
    }
    if ideal {
        let mut config = *car.config();
        config.vehicle.steering_ramp_time = 0.0;
        car.set_config(config);
    }
    configure(&mut car);
    crate::autopilot::experiment::set_multiply_angle(steering == Steering::MultiplyAngle2016);
    let mut driver = Driver::new(car, &points);
    let (mut errors, mut k, mut outside) = (Vec::new(), 0usize, false);
    let total_ms = ((polyline_length(&route) / 3.0 + 30.0) * 1000.0) as u64;
    driver.run(total_ms, |car, _| {
        let t = car.truth();
        let p = Point::new(t.x, t.y);
        let e = cross_track(&route, &mut k, p);
        outside |= !area.contains_point(p);
        if k >= start_len + 2 && k + 3 < route.len() {
            errors.push(e);
        }
    });
    crate::autopilot::experiment::set_multiply_angle(false);
    assert!(
        k + 3 >= route.len(),
        "the car did not reach the route end (segment {k} of {})",
        route.len()
    );
    CrossTrack {
        p50: percentile(errors.clone(), 0.5),
        p95: percentile(errors.clone(), 0.95),
        max: percentile(errors.clone(), 1.0),
        samples: errors.len(),
        outside,
    }
}

/// The simulator's acceptance criteria asked for a cross-track p95 below 0.15 m. The documented
/// autopilot with its default configuration cannot do that on the method's routes (turns up to 30°
/// every 0.6–2 m) at 3 m/s: pure pursuit cuts the corners by an amount set by its look-ahead
/// radius, 1.59 m for 10.1 there (p95 0.15–0.21 m over 1 km routes; 0.14–0.16 m with
/// `ap_ang_dist_comp 0`) and 0.8 s · 3 m/s = 2.4 m for 12.3 (p95 0.28–0.53 m). Perfect sensing and
/// an instant servo change nothing (the floor is the law's geometry), and the 2016 law that
/// multiplied the angle is no better. The bounds below guard the measured behaviour of the faithful
/// model; the figures are printed with `--nocapture`, and the ignored `cross_track_at_3_m_s_*`
/// tests measure more.
#[test]
fn drives_the_start_route_and_200_m_at_3_m_s_on_every_bundled_area_inside_the_fence() {
    for (k, name) in scenarios::bundled::names().iter().enumerate() {
        let scenario = scenarios::bundled::load(name)
            .expect("a bundled area")
            .scenario;
        for (firmware, bound) in [
            (FirmwareVersion::V10_1, 0.25),
            (FirmwareVersion::V12_3, 0.6),
        ] {
            let m = drive_and_measure(
                &scenario,
                firmware,
                k as u64 + 1,
                200.0,
                Steering::Documented,
                |_| {},
            );
            println!(
                "{name} {firmware}: cross-track p95 {:.3} m, max {:.3} m",
                m.p95, m.max
            );
            assert!(
                m.p95 < bound,
                "{name} {firmware}: cross-track p95 {:.3} m",
                m.p95
            );
            assert!(!m.outside, "{name} {firmware}: the car left the area");
        }
    }
}

/// The measurement behind the cross-track figures of the test above: cross-track p50/p95/max
/// at 3 m/s over 1 km routes on every bundled area, seeds 1–5, both generations, for the documented
/// steering law, without the distance compensation, with the 2016 law, and with the documented law
/// on ideal sensors. Long: run it with
/// `cargo test -p car-sim --release -- --ignored --nocapture cross_track_at_3`.
#[test]
#[ignore = "long measurement; run explicitly"]
fn cross_track_at_3_m_s_per_firmware_area_seed_and_steering_law() {
    let laws = [
        Steering::Documented,
        Steering::CompensationOff,
        Steering::MultiplyAngle2016,
        Steering::DocumentedIdealSensors,
    ];
    println!("firmware area seed law: p50 / p95 / max cross-track, m (samples)");
    for firmware in [FirmwareVersion::V10_1, FirmwareVersion::V12_3] {
        for law in laws {
            let mut all_p95 = Vec::new();
            for name in scenarios::bundled::names() {
                let scenario = scenarios::bundled::load(name)
                    .expect("a bundled area")
                    .scenario;
                for seed in 1..=5 {
                    let m = drive_and_measure(&scenario, firmware, seed, 1000.0, law, |_| {});
                    println!(
                        "{firmware} {name} {seed} {law:?}: {:.3} / {:.3} / {:.3} ({}){}",
                        m.p50,
                        m.p95,
                        m.max,
                        m.samples,
                        if m.outside { " LEFT THE AREA" } else { "" }
                    );
                    all_p95.push(m.p95);
                }
            }
            println!(
                "{firmware} {law:?}: p95 over the runs {:.3}–{:.3} m, median {:.3} m",
                percentile(all_p95.clone(), 0.0),
                percentile(all_p95.clone(), 1.0),
                percentile(all_p95, 0.5)
            );
        }
    }
}

/// Cross-track at 3 m/s with the look-ahead radius an orchestrator can configure (documented
/// knobs: SET_MAIN_CONFIG `ap_base_rad` / `ap_rad_time_ahead`, terminal `ap_ang_dist_comp`), over
/// 500 m routes on every bundled area, seeds 1–2. Long: run it with
/// `cargo test -p car-sim --release -- --ignored --nocapture cross_track_at_3`.
#[test]
#[ignore = "long measurement; run explicitly"]
fn cross_track_at_3_m_s_with_the_documented_look_ahead_settings() {
    // (firmware, distance compensation, ap_base_rad, ap_rad_time_ahead): the look-ahead radius at
    // 3 m/s is 1.3225 · ap_base_rad (10.1) or max(3 · ap_rad_time_ahead, ap_base_rad) (12.3).
    let settings = [
        (FirmwareVersion::V10_1, true, 1.2, 0.0),
        (FirmwareVersion::V10_1, false, 1.2, 0.0),
        (FirmwareVersion::V10_1, true, 1.0, 0.0),
        (FirmwareVersion::V10_1, false, 1.0, 0.0),
        (FirmwareVersion::V12_3, true, 0.8, 0.8),
        (FirmwareVersion::V12_3, true, 0.8, 0.5),
        (FirmwareVersion::V12_3, false, 0.8, 0.5),
        (FirmwareVersion::V12_3, false, 0.8, 0.4),
    ];
    for (firmware, compensation, base_rad, time_ahead) in settings {
        let mut p95 = Vec::new();
        for name in scenarios::bundled::names() {
            let scenario = scenarios::bundled::load(name)
                .expect("a bundled area")
                .scenario;
            for seed in 1..=2 {
                let m = drive_and_measure(
                    &scenario,
                    firmware,
                    seed,
                    500.0,
                    if compensation {
                        Steering::Documented
                    } else {
                        Steering::CompensationOff
                    },
                    |car| {
                        let mut config = *car.config();
                        config.ap_base_rad = base_rad;
                        config.ap_rad_time_ahead = time_ahead;
                        car.set_config(config);
                    },
                );
                assert!(!m.outside, "{name}: the car left the area");
                p95.push(m.p95);
            }
        }
        let text: Vec<String> = p95.iter().map(|p| format!("{p:.3}")).collect();
        println!(
            "{firmware} compensation {compensation} ap_base_rad {base_rad} ap_rad_time_ahead \
             {time_ahead}: cross-track p95 per area and seed {}",
            text.join(" ")
        );
    }
}

/// A random drive on the lot: one random speed (3–12 km/h) per run of 5 points, like the
/// method's RunSegments.
fn lot_drive(firmware: FirmwareVersion, seed: u64, length_m: f64) -> (Driver, Vec<Point>) {
    let area = lot_area();
    let mut route = start_points();
    let mut noise = Noise::stream(seed, 98);
    random_route(&area, &mut route, length_m, 0.5, &mut noise);
    let speeds: Vec<f64> = (0..route.len() / 5 + 1)
        .map(|_| noise.uniform_in(3.0, 12.0) / 3.6)
        .collect();
    let points = route_points(&route, |i| speeds[i / 5]);
    let car = placed_car(firmware, seed, &route);
    (Driver::new(car, &points), route)
}

fn deviation(s: &StateReport) -> f64 {
    f64::from(s.px_uwb - s.px).hypot(f64::from(s.py_uwb - s.py))
}

#[test]
fn uwb_deviation_over_a_ten_minute_drive_is_in_the_published_range() {
    for (firmware, seed) in [(FirmwareVersion::V10_1, 11), (FirmwareVersion::V12_3, 12)] {
        let (mut driver, _) = lot_drive(firmware, seed, 1500.0);
        let mut devs = Vec::new();
        driver.run(600_000, |car, s| {
            if car.now_ms() > 5_000 {
                devs.push(deviation(s));
            }
        });
        let p50 = percentile(devs.clone(), 0.5);
        let p95 = percentile(devs.clone(), 0.95);
        let max = percentile(devs, 1.0);
        println!("{firmware}: UWB–RTK deviation p50 {p50:.3} m, p95 {p95:.3} m, max {max:.3} m");
        assert!((0.1..0.6).contains(&p95), "{firmware}: p95 {p95:.3} m");
    }
}

#[test]
fn an_offset_4_fault_on_one_anchor_for_8_iterations_raises_the_deviation_clearly() {
    let (mut driver, _) = lot_drive(FirmwareVersion::V10_1, 21, 300.0);
    let mut before = Vec::new();
    driver.run(30_000, |car, s| {
        if car.now_ms() > 5_000 {
            before.push(deviation(s));
        }
    });
    let baseline = percentile(before, 0.95);
    assert_eq!(
        driver.car.terminal("fi_set_enabled 1"),
        ["Fault Injection enabled\n"]
    );
    assert_eq!(
        driver
            .car
            .terminal("fi_add_fault uwb_range_50 OFFSET 4.0 0 8"),
        [
            "Fault OFFSET with parameter 4.00 successfully added to probe uwb_range_50."
                .to_string()
                + "\n"
        ]
    );
    let mut after: f64 = 0.0;
    driver.run(4_000, |_, s| after = after.max(deviation(s)));
    println!("baseline p95 {baseline:.3} m, peak after the fault {after:.3} m");
    assert!(
        after > baseline + 1.0,
        "peak {after:.3} m vs baseline p95 {baseline:.3} m"
    );
    let applied = driver.car.fault_injection().probes()[0].iteration;
    assert!(applied >= 8, "the probe ran {applied} times");
}

#[test]
fn the_same_seed_gives_identical_telemetry_and_another_seed_does_not() {
    let telemetry = |seed: u64| {
        let (mut driver, _) = lot_drive(FirmwareVersion::V10_1, seed, 150.0);
        driver.car.terminal("fi_set_enabled 1");
        driver
            .car
            .terminal("fi_add_fault uwb_travel_dist AMPLIFICATION 3 50 10");
        let mut states = Vec::new();
        driver.run(60_000, |_, s| states.push(*s));
        states
    };
    let a = telemetry(5);
    assert_eq!(a, telemetry(5));
    assert_ne!(a, telemetry(6));
}

#[test]
fn a_silent_link_for_two_seconds_brakes_and_stops_the_autopilot() {
    for firmware in [FirmwareVersion::V10_1, FirmwareVersion::V12_3] {
        let (mut driver, _) = lot_drive(firmware, 31, 100.0);
        driver.run(10_000, |_, _| {});
        assert!(driver.car.autopilot().is_active());
        let v0 = driver.car.truth().speed;
        assert!(v0 > 0.5, "driving at {v0} m/s");
        // Silence: step without any command.
        driver.car.run_for(2_000);
        assert!(
            driver.car.autopilot().is_active(),
            "not yet expired at exactly 2 s"
        );
        driver.car.step();
        assert!(driver.car.watchdog_expired());
        assert!(!driver.car.autopilot().is_active());
        assert_eq!(
            driver.car.motor().mode(),
            crate::motor::MotorCommand::CurrentBrake(40.0)
        );
        driver.car.run_for(1_000);
        assert!(driver.car.truth().speed.abs() < 0.05, "{firmware}: stopped");
        // 10.x keeps braking at standstill; 12.3 only above 2 km/h (then the motor's own 10 A).
        let stopped_mode = driver.car.motor().mode();
        if firmware.profile().watchdog_brake != car_link::firmware::WatchdogBrake::Always {
            driver.car.run_for(3_000);
            assert_eq!(
                driver.car.motor().mode(),
                crate::motor::MotorCommand::CurrentBrake(10.0)
            );
        } else {
            assert_eq!(stopped_mode, crate::motor::MotorCommand::CurrentBrake(40.0));
        }
    }
}

#[test]
fn the_watchdog_is_expired_from_two_seconds_after_boot_and_heartbeats_do_not_count() {
    let mut car = SimCar::new(CarOptions::default());
    car.run_for(2_000);
    assert!(!car.watchdog_expired());
    car.step();
    assert!(car.watchdog_expired());
    // Commands that do not reset it: anchors, route part.
    car.add_anchor(1, 0.0, 0.0, 0.0);
    car.route_part(0, 1);
    car.step();
    assert!(car.watchdog_expired());
    car.get_state();
    car.step();
    assert!(!car.watchdog_expired());
}

#[test]
fn set_active_0_and_clear_do_not_brake_the_motor_holds_its_rpm_for_two_seconds() {
    let (mut driver, _) = lot_drive(FirmwareVersion::V10_1, 41, 100.0);
    driver.run(8_000, |_, _| {});
    driver.car.set_active(false, false);
    driver.car.step();
    let mode = driver.car.motor().mode();
    assert!(
        matches!(mode, crate::motor::MotorCommand::Rpm(r) if r > 0.0),
        "{mode:?}"
    );
    for _ in 0..150 {
        driver.car.step();
        driver.car.get_state();
    }
    assert_eq!(driver.car.motor().mode(), mode);
    driver.car.run_for(600);
    driver.car.get_state();
    assert_eq!(
        driver.car.motor().mode(),
        crate::motor::MotorCommand::CurrentBrake(10.0)
    );
}

#[test]
fn the_px_fault_changes_only_the_reported_value() {
    let (mut driver, _) = lot_drive(FirmwareVersion::V10_1, 51, 100.0);
    driver.run(3_000, |_, _| {});
    driver.car.terminal("fi_set_enabled 1");
    driver.car.terminal("fi_add_fault px OFFSET 10 0 0");
    let s = driver.car.get_state();
    let fused = driver.car.truth().fused;
    assert!((s.px - fused.x - 10.0).abs() < 1e-3);
    driver.run(3_000, |car, s| {
        assert!((s.px - car.truth().fused.x - 10.0).abs() < 1e-3);
    });
    // The car still follows its route (control uses the unfaulted fused px).
    assert!(driver.car.autopilot().is_active());
}

#[test]
fn rc_control_deactivates_and_brakes_to_a_stop() {
    let (mut driver, _) = lot_drive(FirmwareVersion::V10_1, 61, 100.0);
    driver.run(8_000, |_, _| {});
    driver.car.rc_control(RcMode::Brake, 50.0, 0.0);
    assert!(!driver.car.autopilot().is_active());
    let mut t = 0;
    while driver.car.get_state().speed.abs() >= 0.1 && t < 500 {
        driver.car.step();
        t += 1;
    }
    assert!(t < 100, "stopped within a second ({t} ticks)");
}

#[test]
fn on_a_bench_the_fused_heading_never_changes_whatever_the_steering() {
    let mut car = SimCar::new(CarOptions {
        imu_on_bench: true,
        gnss: crate::GnssModel {
            enabled: false,
            ..crate::GnssModel::default()
        },
        ..CarOptions::default()
    });
    car.rc_control(RcMode::Speed, 1.0, 1.0);
    for _ in 0..300 {
        car.step();
        car.get_state();
    }
    let t = car.truth();
    assert!(t.heading.abs() > 0.5, "the simulated car turned");
    assert_eq!(t.fused.yaw, 0.0, "the fused heading did not");
    assert!(
        t.fused.x > 2.0 && t.fused.y.abs() < 1e-3,
        "dead reckoning in a straight line"
    );
}

fn nlos_events(walls: Vec<crate::Wall>) -> Vec<crate::DebugEvent> {
    let square = Polygon::new(vec![
        Point::new(14.5, -0.5),
        Point::new(15.5, -0.5),
        Point::new(15.5, 0.5),
        Point::new(14.5, 0.5),
    ])
    .expect("a square");
    let world = World {
        anchors: vec![
            WorldAnchor {
                id: 1,
                position: Point::new(0.0, 0.0),
                height: 1.0,
                range_bias_m: None,
            },
            WorldAnchor {
                id: 2,
                position: Point::new(20.0, 0.0),
                height: 1.0,
                range_bias_m: None,
            },
        ],
        obstacles: vec![square],
        walls,
    };
    let mut car = SimCar::new(CarOptions {
        world,
        preload_anchors: true,
        record_events: true,
        placement: Placement {
            x: 10.0,
            y: 0.0,
            heading: 0.0,
        },
        ..CarOptions::default()
    });
    car.terminal("pos_uwb_reset_pos");
    for _ in 0..200 {
        car.step();
        car.get_state();
    }
    car.drain_events()
}

#[test]
fn a_blocked_anchor_reads_the_reflected_path_or_nothing() {
    use crate::{DebugEvent, RadioPath, RangeResult};
    let wall = crate::Wall {
        a: Point::new(0.0, 4.0),
        b: Point::new(30.0, 4.0),
    };
    let reflected = (9.915f64.powi(2) + 8.0f64.powi(2)).sqrt();
    let events = nlos_events(vec![wall]);
    let ranges: Vec<(Option<RadioPath>, RangeResult)> = events
        .iter()
        .filter_map(|e| match e {
            DebugEvent::Range {
                anchor: 2,
                path,
                result,
                ..
            } => Some((*path, *result)),
            _ => None,
        })
        .collect();
    assert!(ranges.len() >= 8, "anchor 2 ranged every 200 ms");
    for (path, result) in &ranges {
        assert!(
            matches!(path, Some(RadioPath::Reflected { wall: 0, .. })),
            "{path:?}"
        );
        if let RangeResult::Measured(r) = result {
            let r = f64::from(*r);
            assert!(
                r > reflected - 0.3 && r < reflected + 0.6,
                "{r} vs {reflected}"
            );
        }
    }
    let fused_from_2 = |events: &[DebugEvent]| {
        events
            .iter()
            .filter(|e| matches!(e, DebugEvent::RangeFused { anchor: 2, .. }))
            .count()
    };
    assert!(fused_from_2(&events) > 0);
    // Without the wall the signal is blocked: nothing reaches the estimator from anchor 2.
    let blocked = nlos_events(Vec::new());
    assert!(blocked.iter().any(|e| matches!(
        e,
        DebugEvent::Range {
            anchor: 2,
            result: RangeResult::Blocked,
            ..
        }
    )));
    assert_eq!(fused_from_2(&blocked), 0);
}

/// UWB–RTK deviations of a drive on a bundled area, with or without its environment.
fn scenario_deviations(name: &str, with_environment: bool, seed: u64, ms: u64) -> Vec<f64> {
    let scenario = scenarios::bundled::load(name).expect("bundled").scenario;
    let mut route = scenario.start_route.positions();
    let mut noise = Noise::stream(seed, 97);
    random_route(&scenario.area, &mut route, 600.0, 0.5, &mut noise);
    let points = route_points(&route, |_| 1.5);
    let mut world = World::from_scenario(&scenario);
    if !with_environment {
        world.obstacles.clear();
        world.walls.clear();
    }
    let mut car = SimCar::new(CarOptions {
        seed,
        world,
        preload_anchors: true,
        placement: Placement::at_start_of(&scenario).expect("a start"),
        ..CarOptions::default()
    });
    car.step();
    let mut driver = Driver::new(car, &points);
    let mut devs = Vec::new();
    driver.run(ms, |car, s| {
        if car.now_ms() > 5_000 {
            devs.push(deviation(s));
        }
    });
    devs
}

#[test]
fn the_rock_and_its_wall_reflection_raise_the_uwb_deviation() {
    let clear = scenario_deviations("parking-lot-rock", false, 71, 180_000);
    let rock = scenario_deviations("parking-lot-rock", true, 71, 180_000);
    let (clear95, rock95) = (
        percentile(clear.clone(), 0.95),
        percentile(rock.clone(), 0.95),
    );
    let (clear_max, rock_max) = (percentile(clear, 1.0), percentile(rock, 1.0));
    println!(
        "rock lot: p95 {clear95:.3} m (max {clear_max:.3}) without the rock, \
         {rock95:.3} m (max {rock_max:.3}) with it"
    );
    assert!(rock95 > clear95 + 0.2, "{rock95:.3} vs {clear95:.3}");
}

/// One GET_STATE poll of a drive: whether the car was in the rock's shadow (anchor 234 reached
/// only by the wall reflection), for how long it had been in or out of it, and the deviation.
struct ShadowSample {
    shadowed: bool,
    settled_ms: u64,
    deviation: f64,
}

/// A fixed-seed random drive through the bundled `parking-lot-rock` with its environment.
fn rock_lot_drive(seed: u64, ms: u64) -> Vec<ShadowSample> {
    let scenario = scenarios::bundled::load("parking-lot-rock")
        .expect("bundled")
        .scenario;
    let mut route = scenario.start_route.positions();
    let mut noise = Noise::stream(seed, 96);
    random_route(&scenario.area, &mut route, 800.0, 0.5, &mut noise);
    let points = route_points(&route, |_| 1.5);
    let world = World::from_scenario(&scenario);
    let anchor = world.anchor(234).expect("anchor 234").position;
    let mut car = SimCar::new(CarOptions {
        seed,
        world: world.clone(),
        preload_anchors: true,
        placement: Placement::at_start_of(&scenario).expect("a start"),
        ..CarOptions::default()
    });
    car.step();
    let mut driver = Driver::new(car, &points);
    let (mut samples, mut last, mut since) = (Vec::new(), false, 0u64);
    driver.run(ms, |car, s| {
        let t = car.truth();
        let shadowed = !matches!(
            world.radio_path(Point::new(t.x, t.y), anchor),
            RadioPath::LineOfSight { .. }
        );
        if shadowed != last {
            (last, since) = (shadowed, car.now_ms());
        }
        if car.now_ms() > 5_000 {
            samples.push(ShadowSample {
                shadowed,
                settled_ms: car.now_ms() - since,
                deviation: deviation(s),
            });
        }
    });
    samples
}

/// The illustrative rock of `parking-lot-rock` must make a region of the lot fail the 1 m oracle
/// (anchor 234 reached only by a wall reflection 1.1–1.8 m longer than the direct path) and
/// leave the rest, the start route included, nominal.
#[test]
fn the_illustrative_rock_shadows_a_minority_of_the_lot_with_a_deviation_of_about_two_metres() {
    let scenario = scenarios::bundled::load("parking-lot-rock")
        .expect("bundled")
        .scenario;
    let world = World::from_scenario(&scenario);
    let anchor = world.anchor(234).expect("anchor 234").position;
    // The geometry on a 0.25 m grid: the shadow's share and the reflection's extra length.
    let bbox = scenario.area.bbox();
    let (mut drivable, mut extra, mut blocked) = (0usize, Vec::new(), 0usize);
    for i in 0..=((bbox.size().0 / 0.25) as usize) {
        for j in 0..=((bbox.size().1 / 0.25) as usize) {
            let p = Point::new(bbox.min.x + i as f64 * 0.25, bbox.min.y + j as f64 * 0.25);
            if !scenario.area.contains_point(p) {
                continue;
            }
            drivable += 1;
            match world.radio_path(p, anchor) {
                RadioPath::LineOfSight { .. } => {}
                RadioPath::Reflected { length, direct, .. } => extra.push(length - direct),
                RadioPath::Blocked => blocked += 1,
            }
        }
    }
    let share = (extra.len() + blocked) as f64 / drivable as f64;
    let reflected = extra.len() as f64 / (extra.len() + blocked) as f64;
    let (extra_min, extra_max) = (percentile(extra.clone(), 0.0), percentile(extra, 1.0));
    println!(
        "rock lot: shadow {:.1} % of the lot, {:.0} % of it with a reflection {extra_min:.2}–{extra_max:.2} m longer",
        share * 100.0,
        reflected * 100.0
    );
    // Where the wall offers no reflection the range to 234 fails (the firmware drops the
    // exchange): most of the shadow must reflect, as the published 2 m came from a reflection.
    assert!(
        reflected > 0.7,
        "reflected share of the shadow {reflected:.2}"
    );
    assert!((0.02..0.10).contains(&share), "shadow share {share:.3}");
    assert!(extra_min > 1.0 && extra_max < 3.0);
    for p in scenario
        .start_route
        .positions()
        .into_iter()
        .chain(scenario.recovery_route.positions())
    {
        let path = world.radio_path(p, anchor);
        assert!(matches!(path, RadioPath::LineOfSight { .. }), "{p:?}");
    }

    // A drive through it: the deviation once the filter has settled, in and out of the shadow.
    let samples = rock_lot_drive(81, 300_000);
    let time_share = samples.iter().filter(|s| s.shadowed).count() as f64 / samples.len() as f64;
    let inside: Vec<f64> = samples
        .iter()
        .filter(|s| s.shadowed && s.settled_ms >= 2_000)
        .map(|s| s.deviation)
        .collect();
    let outside: Vec<f64> = samples
        .iter()
        .filter(|s| !s.shadowed && s.settled_ms >= 3_000)
        .map(|s| s.deviation)
        .collect();
    let failing = inside.iter().filter(|&&d| d > 1.0).count() as f64 / inside.len() as f64;
    let (in50, in95) = (
        percentile(inside.clone(), 0.5),
        percentile(inside.clone(), 0.95),
    );
    let (out50, out95) = (
        percentile(outside.clone(), 0.5),
        percentile(outside.clone(), 0.95),
    );
    println!(
        "rock lot drive: {:.1} % of the time in the shadow; settled deviation in it p50 {in50:.2} m, \
         p95 {in95:.2} m, {:.0} % over 1 m ({} samples); outside p50 {out50:.2} m, p95 {out95:.2} m \
         ({} samples); overall p95 {:.2} m",
        time_share * 100.0,
        failing * 100.0,
        inside.len(),
        outside.len(),
        percentile(samples.iter().map(|s| s.deviation).collect(), 0.95),
    );
    assert!(
        inside.len() >= 80,
        "the drive spent too little time in the shadow"
    );
    assert!(
        (1.0..2.5).contains(&in50),
        "median deviation in the shadow {in50:.2} m"
    );
    assert!(in95 < 3.0, "p95 deviation in the shadow {in95:.2} m");
    assert!(
        failing > 0.5,
        "only {:.0} % of the shadow fails the 1 m oracle",
        failing * 100.0
    );
    assert!(out95 < 0.6, "p95 deviation outside the shadow {out95:.2} m");
}

/// The 12.3 UWB heading after SET_POS (`docs/firmware.md#resetting-the-estimate`). The car
/// stands 3 s after boot with its anchors (so the heading estimator's p_old is left near the boot
/// estimate, (0, 0)), then the orchestrator's reset (`pos_uwb_reset_pos` + SET_POS with the RTK
/// pose) and a drive. SET_POS sets the heading exactly; afterwards the documented estimator (stale
/// p_old, kept drift, PI loop on the estimate's track) keeps it within a few degrees of the truth
/// (3.5–6.6° measured).
#[test]
fn the_12_3_uwb_heading_after_set_pos_starts_exact_and_stays_within_ten_degrees() {
    let area = lot_area();
    let mut route = start_points();
    let mut noise = Noise::stream(3, 94);
    random_route(&area, &mut route, 150.0, 0.5, &mut noise);
    let points = route_points(&route, |_| 3.0);
    let mut car = placed_car(FirmwareVersion::V12_3, 3, &route);
    for _ in 0..300 {
        car.step();
        if car.now_ms().is_multiple_of(50) {
            car.get_state();
        }
    }
    let heading_error = |car: &SimCar| {
        let t = car.truth();
        let e = (f64::from(-t.uwb.yaw).to_radians() - t.heading + PI).rem_euclid(2.0 * PI) - PI;
        e.to_degrees().abs()
    };
    let mut driver = Driver::new(car, &points);
    let fused_yaw = driver.car.truth().fused.yaw;
    assert!(
        (driver.car.truth().uwb.yaw - fused_yaw).abs() < 1e-3,
        "SET_POS gives the UWB estimate the RTK heading"
    );
    let (mut worst, mut devs) = (0.0f64, Vec::new());
    driver.run(40_000, |car, s| {
        worst = worst.max(heading_error(car));
        devs.push(deviation(s));
    });
    let (p95, max) = (percentile(devs.clone(), 0.95), percentile(devs, 1.0));
    println!(
        "12.3 after SET_POS: heading error ≤ {worst:.1}°, deviation p95 {p95:.2} m, max {max:.2} m"
    );
    assert!(worst < 10.0, "UWB heading error {worst:.1}°");
    assert!(max < 1.5, "UWB–RTK deviation {max:.2} m");
}
