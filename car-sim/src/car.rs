//! The simulated car: every firmware task stepped on a 10 ms tick, and the firmware's command
//! handlers. No I/O and no clock: time advances only through [`SimCar::step`].

use std::collections::VecDeque;
use std::f64::consts::PI;

use crate::autopilot::{ApInputs, Autopilot, FwPose, RoutePart, RoutePoint, StoreOutcome};
use crate::config::{FirmwareConfig, VehicleParams, truncate};
use crate::debug::{DebugEvent, Truth};
use crate::fault::FaultInjection;
use crate::motor::{HIL_TEMP_MOS, HIL_V_IN, Motor, MotorCommand};
use crate::noise::Noise;
use crate::plant::{GnssNoise, Motion, STREAM_UWB};
use crate::positioning::{FusedPosition, GnssFix, OdometryInput, wrap180};
use crate::servo::Servo;
use crate::terminal::{NO_COMMAND, invalid_command, scan_i32, tokenize, truncate_printf};
use crate::uwb::{
    AnchorList, RadioModel, RangeMeasurement, RangeResult, Schedule, UwbEstimator, measure_range,
};
use crate::world::World;
use car_link::firmware::{
    FirmwareProfile, FirmwareVersion, UwbEstimator as Estimator, WatchdogBrake,
};

/// The base tick of the simulation, ms.
pub const TICK_MS: u64 = car_link::firmware::TICK.as_millis() as u64;
/// The communication watchdog's limit, ms.
pub const WATCHDOG_MS: u64 = car_link::firmware::WATCHDOG.as_millis() as u64;
/// Watchdog brake current, A.
const WATCHDOG_BRAKE_A: f32 = 40.0;
/// UWB scheduling period, ms.
const UWB_PERIOD_MS: u64 = car_link::firmware::RANGING_SLOT.as_millis() as u64;
/// Delay between a range request and its reply, ms (the exchanges take a few ms).
const UWB_REPLY_DELAY_MS: u64 = 10;
/// Odometry runs on every 10th IMU sample in both generations.
const IMU_SAMPLES_PER_ODOMETRY_TICK: u32 = 10;
/// Milliseconds per day.
const MS_PER_DAY: i64 = 86_400_000;

/// The simulated GNSS receiver (RTK).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssModel {
    /// Whether a receiver is fitted (false = a bench without GNSS: pure dead reckoning).
    pub enabled: bool,
    /// Measurement period, ms (5 Hz).
    pub period_ms: u64,
    /// Delay from measurement to arrival at the firmware, ms.
    pub latency_ms: u64,
    /// Standard deviation of the RTK position noise per axis, m.
    pub sigma_m: f64,
    /// The noise's correlation time, s: a first-order Gauss–Markov process per axis,
    /// `e ← a·e + σ·√(1 − a²)·w` with `a = exp(−period/correlation_s)` at every fix, stationary
    /// with standard deviation `sigma_m`. 0 draws every fix's noise afresh (white).
    pub correlation_s: f64,
    /// UTC time of day at boot, ms (the firmware learns it from the first fix).
    pub utc_at_boot_ms: i64,
}

/// The default noise is fitted to the real car driving the published circle route (the firmware
/// repository vedderb/rise_sdvp, commit 8b9c36a0003023ef53d7f8d0e5fb2c0728fa609a,
/// `Misc/Test Data/paper_2018-06/`: `plot_data/diff_circle.xml` and `plot_data/ap_circle.xml`,
/// bundled in `devtools/data/real-car/`), by `drivecheck-dev bench fidelity --fit-gnss
/// --route-runs 10` over σ 0.6–2.0 cm and correlation times 0–5 s: **σ 1.0 cm per axis,
/// correlation time 0.4 s**. The real car's figures (fix vs fused history p50 / p95, distance to
/// the route p50 / p95, its mean change per 100 ms, its correlation time) 1.19 / 2.33 cm,
/// 2.23 / 3.94 cm, 0.43 cm, 0.63 s; the simulated car's with this noise (median of 10 runs)
/// 1.08 / 2.20 cm, 1.94 / 4.03 cm, 0.46 cm, 0.60 s; with the white 1.5 cm used before 2.51 /
/// 5.20 cm, 2.09 / 4.93 cm, 0.83 cm, 0.21 s (`docs/fidelity.md#route-following`).
impl Default for GnssModel {
    fn default() -> Self {
        Self {
            enabled: true,
            period_ms: 200,
            latency_ms: 100,
            sigma_m: 0.010,
            correlation_s: 0.4,
            utc_at_boot_ms: 12 * 3_600_000,
        }
    }
}

/// How the car's own sensors are wrong (a car profile's `[odometry]` and `[imu]`): the errors
/// a real car has that its firmware does not know of.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorErrors {
    /// Distance really driven per distance the car counts (1: the odometry is right). The car
    /// counts its wheel turns as before; the true motion is this much longer.
    pub odometry_scale: f64,
    /// Constant error of the IMU yaw the firmware reads (its yaw minus the true one), degrees in
    /// the firmware's sense (clockwise).
    pub yaw_bias_deg: f64,
    /// How fast that error grows, degrees per minute since boot.
    pub yaw_drift_deg_per_min: f64,
}

impl Default for SensorErrors {
    fn default() -> Self {
        Self {
            odometry_scale: 1.0,
            yaw_bias_deg: 0.0,
            yaw_drift_deg_per_min: 0.0,
        }
    }
}

/// A GNSS fix that corrected the fused position (`docs/firmware.md#fused-position`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssCorrection {
    /// When the fix arrived, ms since boot.
    pub at_ms: u64,
    /// When it was measured, ms since boot.
    pub measured_ms: u64,
    /// The distance between the pose history's entry closest to `measured_ms` and the fix (minus
    /// the antenna offset), before the correction, m: the firmware's "Diff (cm)" of
    /// `pos_gnss_corr_info 1` (`pos.c`, `correct_pos_gps`).
    pub diff_m: f32,
}

/// A true pose to place the car at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// East, m.
    pub x: f64,
    /// North, m.
    pub y: f64,
    /// Heading, radians counter-clockwise from east.
    pub heading: f64,
}

impl Placement {
    /// The start of a scenario's start route, heading along its first segment (`None` for a start
    /// route with fewer than two distinct points).
    pub fn at_start_of(scenario: &scenarios::Scenario) -> Option<Self> {
        let points = scenario.start_route.positions();
        let first = *points.first()?;
        let next = points.iter().copied().find(|p| *p != first)?;
        Some(Self {
            x: first.x,
            y: first.y,
            heading: (next - first).heading(),
        })
    }
}

/// Everything that defines one simulated car (the link is not part of it).
#[derive(Debug, Clone, PartialEq)]
pub struct CarOptions {
    /// The firmware generation.
    pub firmware: FirmwareVersion,
    /// The seed of every random draw.
    pub seed: u64,
    /// The car id (10.x: from DIP switches; 12.x default 0).
    pub car_id: u8,
    /// The world: anchors, obstacles, walls.
    pub world: World,
    /// The UWB radio model.
    pub radio: RadioModel,
    /// The GNSS receiver.
    pub gnss: GnssModel,
    /// The errors of the car's odometry and IMU.
    pub sensors: SensorErrors,
    /// Where the car stands at boot (the fused estimate starts there too; UWB starts at (0, 0)).
    pub placement: Placement,
    /// Load the world's anchors into the firmware's list at boot (the real firmware boots with
    /// none; the orchestrator uploads them).
    pub preload_anchors: bool,
    /// Record [`DebugEvent`]s (drain them with [`SimCar::drain_events`]).
    pub record_events: bool,
    /// HIL-bench fidelity (`docs/firmware.md#odometry-and-yaw`): the board lies on a desk, so the
    /// IMU never rotates and its yaw stays at the boot heading whatever the simulated motion
    /// (default false: the IMU yaw follows the simulated kinematics). Combine with
    /// `gnss.enabled = false` for a bench without a receiver.
    pub imu_on_bench: bool,
    /// Simulation only: the UWB estimator's largest correction per range, m (`None`: the
    /// firmware's constant [`crate::uwb::MAX_STEP_M`], 0.2 m). No firmware setting changes it;
    /// `drivecheck sweep` varies it to show the method's trade-off (larger helps against wheel
    /// slip, smaller against reflections).
    pub uwb_step_clamp_m: Option<f32>,
    /// Conformance only: `fi_add_fault` adds the fault, but its success line names another probe
    /// (the id asked with a `0` appended: `uwb_range_500` for `uwb_range_50`), as a car whose
    /// replies drivecheck does not recognise (default false: the firmware's reply).
    pub misname_fault_probe: bool,
}

impl Default for CarOptions {
    fn default() -> Self {
        Self {
            firmware: FirmwareVersion::default(),
            seed: 0,
            car_id: 1,
            world: World::default(),
            radio: RadioModel::default(),
            gnss: GnssModel::default(),
            sensors: SensorErrors::default(),
            placement: Placement {
                x: 0.0,
                y: 0.0,
                heading: 0.0,
            },
            preload_anchors: false,
            record_events: false,
            imu_on_bench: false,
            uwb_step_clamp_m: None,
            misname_fault_probe: false,
        }
    }
}

/// RC_CONTROL modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RcMode {
    /// 0: motor current, A.
    Current,
    /// 1: duty cycle −1..1.
    Duty,
    /// 2: speed, m/s (through the autopilot's RPM conversion).
    Speed,
    /// 3: brake current, A.
    Brake,
    /// Any other byte: the throttle is ignored.
    Other(u8),
}

impl RcMode {
    /// The mode of a wire byte.
    pub fn from_byte(b: u8) -> Self {
        match b {
            0 => Self::Current,
            1 => Self::Duty,
            2 => Self::Speed,
            3 => Self::Brake,
            other => Self::Other(other),
        }
    }
}

/// The values of a GET_STATE reply (`docs/protocol.md#state-reply`), as the firmware holds them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateReport {
    /// Car id.
    pub id: u8,
    /// Firmware major.
    pub fw_major: u8,
    /// Firmware minor.
    pub fw_minor: u8,
    /// Roll, degrees.
    pub roll: f32,
    /// Pitch, degrees.
    pub pitch: f32,
    /// Yaw, degrees clockwise (fused; UWB with `use_uwb_pos`).
    pub yaw: f32,
    /// Acceleration, g.
    pub accel: [f32; 3],
    /// Angular rate, rad/s.
    pub gyro: [f32; 3],
    /// Raw magnetometer, µT.
    pub mag: [f32; 3],
    /// Fused px (after the `px` probe; UWB px with `use_uwb_pos`), m.
    pub px: f32,
    /// Fused py, m.
    pub py: f32,
    /// Odometry speed, m/s.
    pub speed: f32,
    /// Input voltage, V.
    pub v_in: f32,
    /// MOSFET temperature, °C.
    pub temp_mos: f32,
    /// Motor controller fault code.
    pub mc_fault: u8,
    /// Last GNSS fix minus the antenna offset, m.
    pub px_gps: f32,
    /// Last GNSS fix minus the antenna offset, m.
    pub py_gps: f32,
    /// Autopilot goal, m.
    pub ap_goal_px: f32,
    /// Autopilot goal, m.
    pub ap_goal_py: f32,
    /// Look-ahead radius, m (−1 when inactive).
    pub ap_rad: f32,
    /// Time of day, ms (−1 until known).
    pub ms_today: i32,
    /// Points left.
    pub ap_route_left: i16,
    /// UWB px (fused px with `use_uwb_pos`), m.
    pub px_uwb: f32,
    /// UWB py, m.
    pub py_uwb: f32,
}

/// A simulated car.
#[derive(Debug, Clone)]
pub struct SimCar {
    options: CarOptions,
    /// What the firmware version of `options` is like.
    profile: FirmwareProfile,
    config: FirmwareConfig,
    car_id: u8,
    now_ms: u64,
    motor: Motor,
    servo: Servo,
    truth: Motion,
    fused: FusedPosition,
    uwb: UwbEstimator,
    anchors: AnchorList,
    autopilot: Autopilot,
    fi: FaultInjection,
    gnss_noise: GnssNoise,
    uwb_noise: Noise,
    gnss_in_flight: VecDeque<(u64, GnssFix)>,
    last_gnss_correction: Option<GnssCorrection>,
    range_in_flight: Option<(u64, RangeMeasurement)>,
    watchdog_reset_ms: u64,
    watchdog_expired: bool,
    ms_today_base: Option<(i64, u64)>,
    enu_ref: (f64, f64, f64),
    events: Vec<DebugEvent>,
}

/// The firmware's raw IMU yaw (degrees clockwise, 0 = east) on a car heading `heading`
/// (radians counter-clockwise) with an IMU error of `error_deg`: the true heading, because the
/// IMU's start-up takes it from a magnetometer that reads true ([`crate::plant::magnetometer`]
/// gives the firmware on the host that reading) and the gyro turns it from there. 12.x's UWB
/// estimator uses it as it is (its antenna direction, `docs/firmware.md#uwb-estimator-12x`).
pub fn raw_imu_yaw(heading: f64, error_deg: f64) -> f32 {
    wrap180((-heading.to_degrees() + error_deg) as f32)
}

impl SimCar {
    /// A car just booted with `options`.
    pub fn new(options: CarOptions) -> Self {
        let fw = options.firmware;
        let config = FirmwareConfig::defaults(fw);
        let p = options.placement;
        let mut car = Self {
            config,
            car_id: options.car_id,
            now_ms: 0,
            motor: Motor::default(),
            servo: Servo::new(config.vehicle.steering_center),
            truth: Motion::standing(p),
            fused: FusedPosition::new(fw),
            uwb: UwbEstimator::new(fw),
            anchors: AnchorList::new(fw),
            autopilot: Autopilot::new(fw),
            fi: FaultInjection::default(),
            gnss_noise: GnssNoise::new(options.seed),
            uwb_noise: Noise::stream(options.seed, STREAM_UWB),
            gnss_in_flight: VecDeque::new(),
            last_gnss_correction: None,
            range_in_flight: None,
            watchdog_reset_ms: 0,
            watchdog_expired: false,
            ms_today_base: None,
            enu_ref: (0.0, 0.0, 0.0),
            events: Vec::new(),
            options,
            profile: fw.profile(),
        };
        car.place(p);
        if let Some(clamp) = car.options.uwb_step_clamp_m {
            car.uwb.set_step_clamp(clamp);
        }
        if car.options.preload_anchors {
            let world_anchors = car.options.world.anchors.clone();
            for a in world_anchors {
                car.anchors.add(
                    i16::from(a.id),
                    a.position.x as f32,
                    a.position.y as f32,
                    a.height as f32,
                );
            }
        }
        car
    }

    /// Puts the car at a true pose, standing, with the fused estimate there too (as if it had
    /// been powered for a while under RTK). The UWB estimate is not touched.
    pub fn place(&mut self, placement: Placement) {
        self.truth.x = placement.x;
        self.truth.y = placement.y;
        self.truth.heading = placement.heading;
        self.truth.speed = 0.0;
        let pose = FwPose {
            x: placement.x as f32,
            y: placement.y as f32,
            yaw: self.imu_yaw(),
        };
        self.fused.set_pose(pose, self.imu_yaw());
    }

    // ----- time -----

    /// Simulation time since boot, ms.
    pub fn now_ms(&self) -> u64 {
        self.now_ms
    }

    /// Advances the simulation by one 10 ms tick.
    pub fn step(&mut self) {
        self.now_ms += TICK_MS;
        self.motor.step();
        self.move_truth();
        self.servo.step(self.config.vehicle.steering_ramp_time);
        if (self.now_ms / TICK_MS).is_multiple_of(self.odometry_divider()) {
            self.odometry_tick();
        }
        self.gnss_tick();
        self.uwb_tick();
        self.watchdog_tick();
        self.autopilot_tick();
    }

    /// Advances by whole ticks until at least `ms` more have passed.
    pub fn run_for(&mut self, ms: u64) {
        let end = self.now_ms + ms;
        while self.now_ms < end {
            self.step();
        }
    }

    // ----- the tasks -----

    fn imu_yaw(&self) -> f32 {
        let heading = if self.options.imu_on_bench {
            self.options.placement.heading
        } else {
            self.truth.heading
        };
        let sensors = self.options.sensors;
        let error =
            sensors.yaw_bias_deg + sensors.yaw_drift_deg_per_min * self.now_ms as f64 / 60_000.0;
        raw_imu_yaw(heading, error)
    }

    fn move_truth(&mut self) {
        let scale = self.options.sensors.odometry_scale;
        self.truth
            .tick(&self.config.vehicle, &self.motor, &self.servo, scale);
    }

    fn odometry_tick(&mut self) {
        let divider = self.odometry_divider();
        let steering = self.config.vehicle.angle_for_servo(self.servo.position());
        let imu_yaw = self.imu_yaw();
        let step = self.fused.odometry_tick(
            &self.config,
            OdometryInput {
                tacho: self.motor.tachometer(),
                rpm: self.motor.rpm(),
                imu_yaw,
                steering_angle: steering,
                imu_samples: IMU_SAMPLES_PER_ODOMETRY_TICK,
                now_ms: self.now_ms,
            },
        );
        let distance = self.probe("uwb_travel_dist", step.distance);
        let yaw_in = match self.profile.uwb_estimator {
            Estimator::TrackedYaw => imu_yaw,
            Estimator::CopiedYaw => self.fused.pose().yaw,
        };
        let yaw = self.probe("uwb_yaw", yaw_in);
        let dt = (TICK_MS * divider) as f32 / 1000.0;
        let clamp = self.config.vehicle.clamp_imu_yaw_stationary;
        self.uwb.dead_reckon(distance, yaw, step.speed, dt, clamp);
    }

    fn probe(&mut self, id: &str, value: f32) -> f32 {
        let out = self.fi.evaluate(id, value);
        if out.applied_slots != 0 && self.options.record_events {
            self.events.push(DebugEvent::Fault {
                at_ms: self.now_ms,
                probe: id.to_string(),
                slots: out.applied_slots,
                iteration: out.iteration,
                before: value,
                after: out.value,
            });
        }
        out.value
    }

    fn gnss_tick(&mut self) {
        let model = self.options.gnss;
        if !model.enabled || model.period_ms == 0 {
            return;
        }
        if self.now_ms.is_multiple_of(model.period_ms) {
            let fix = self.measure_gnss();
            self.gnss_in_flight
                .push_back((self.now_ms + model.latency_ms, fix));
        }
        while let Some(&(arrival, fix)) = self.gnss_in_flight.front() {
            if arrival > self.now_ms {
                break;
            }
            self.gnss_in_flight.pop_front();
            if self.ms_today_base.is_none() {
                self.ms_today_base = Some((model.utc_at_boot_ms, 0));
            }
            if let Some(diff_m) = self.fused.gnss_fix(&self.config, fix) {
                self.last_gnss_correction = Some(GnssCorrection {
                    at_ms: self.now_ms,
                    measured_ms: fix.measured_ms,
                    diff_m,
                });
            }
        }
    }

    fn measure_gnss(&mut self) -> GnssFix {
        let antenna = self.truth.gnss_antenna(
            f64::from(self.config.gps_ant_x),
            f64::from(self.config.gps_ant_y),
        );
        let (ex, ey) = self.gnss_noise.next(&self.options.gnss);
        GnssFix {
            x: (antenna.x + ex) as f32,
            y: (antenna.y + ey) as f32,
            measured_ms: self.now_ms,
            rtk: true,
        }
    }

    fn uwb_tick(&mut self) {
        if let Some((due, m)) = self.range_in_flight
            && due <= self.now_ms
        {
            self.range_in_flight = None;
            if let RangeResult::Measured(r) = m.result {
                self.fuse_range(m.address, r);
            }
        }
        if !self.now_ms.is_multiple_of(UWB_PERIOD_MS) {
            return;
        }
        let index = match self.anchors.schedule(self.uwb.position()) {
            Schedule::Range(i) => i,
            Schedule::Idle => return,
            Schedule::WalkWouldHang => {
                self.record(DebugEvent::AnchorWalkWouldHang { at_ms: self.now_ms });
                return;
            }
        };
        let anchor = self.anchors.anchors()[index];
        let address = anchor.id as u8;
        let m = measure_range(
            &self.options.world,
            self.anchors.find(address),
            address,
            self.truth.uwb_antenna(),
            &self.options.radio,
            &mut self.uwb_noise,
        );
        self.record(DebugEvent::Range {
            at_ms: self.now_ms,
            anchor: address,
            path: m.path,
            true_range: m.true_range,
            result: m.result,
        });
        self.range_in_flight = Some((self.now_ms + UWB_REPLY_DELAY_MS, m));
    }

    fn fuse_range(&mut self, address: u8, measured: f32) {
        let r = self.probe(&format!("uwb_range_{address}"), measured);
        let now = self.now_ms;
        let Some(anchor) = self.anchors.find_mut(address) else {
            return;
        };
        anchor.dist_last = r;
        anchor.last_ms = Some(now);
        let (ax, ay) = (anchor.px, anchor.py);
        let moved = self.uwb.range_update(ax, ay, r, self.config.uwb_max_corr);
        self.record(DebugEvent::RangeFused {
            at_ms: now,
            anchor: address,
            range: r,
            moved,
        });
    }

    fn watchdog_tick(&mut self) {
        if self.now_ms.saturating_sub(self.watchdog_reset_ms) <= WATCHDOG_MS {
            self.watchdog_expired = false;
            return;
        }
        if !self.watchdog_expired {
            self.watchdog_expired = true;
            self.record(DebugEvent::WatchdogExpired { at_ms: self.now_ms });
        }
        self.autopilot.deactivate();
        let brake = match self.profile.watchdog_brake {
            WatchdogBrake::Always => true,
            WatchdogBrake::AboveSpeed { mps } => self.fused.speed().abs() > mps,
        };
        if brake && !self.config.vehicle.disable_motor {
            self.motor
                .command(MotorCommand::CurrentBrake(WATCHDOG_BRAKE_A));
        }
    }

    fn autopilot_tick(&mut self) {
        let inputs = ApInputs {
            fused: self.fused.pose(),
            uwb: self.uwb.pose(),
            speed: self.fused.speed(),
            ms_today: self.ms_today(),
        };
        let out = self.autopilot.cycle(&self.config, &inputs);
        if let Some(s) = out.servo {
            self.servo.command(s);
        }
        if let Some(m) = out.motor {
            self.motor.command(m);
        }
        if out.zero_length_segment {
            self.record(DebugEvent::ZeroLengthSegment { at_ms: self.now_ms });
        }
    }

    fn record(&mut self, event: DebugEvent) {
        if self.options.record_events {
            self.events.push(event);
        }
    }

    fn kick_watchdog(&mut self) {
        self.watchdog_reset_ms = self.now_ms;
    }

    /// Time of day, ms; −1 until GNSS time or SET_MS_TODAY.
    pub fn ms_today(&self) -> i32 {
        match self.ms_today_base {
            Some((base, at)) => {
                let elapsed = i64::try_from(self.now_ms - at).unwrap_or(i64::MAX / 2);
                (base.wrapping_add(elapsed)).rem_euclid(MS_PER_DAY) as i32
            }
            None => -1,
        }
    }

    // ----- observation -----

    /// The firmware version.
    pub fn firmware(&self) -> FirmwareVersion {
        self.options.firmware
    }

    /// Odometry runs on every n-th 10 ms tick ([`FirmwareProfile::odometry_tick`]).
    fn odometry_divider(&self) -> u64 {
        (self.profile.odometry_tick.as_millis() as u64 / TICK_MS).max(1)
    }

    /// The car id the firmware answers to (besides 255 and 254).
    pub fn car_id(&self) -> u8 {
        self.car_id
    }

    /// The configuration in force.
    pub fn config(&self) -> &FirmwareConfig {
        &self.config
    }

    /// The options the car was built with.
    pub fn options(&self) -> &CarOptions {
        &self.options
    }

    /// The debug view now.
    pub fn truth(&self) -> Truth {
        let t = self.truth;
        Truth {
            time_ms: self.now_ms,
            x: t.x,
            y: t.y,
            heading: t.heading,
            speed: t.speed,
            steering_angle: t.steering,
            fused: self.fused.pose(),
            uwb: self.uwb.pose(),
        }
    }

    /// Takes the recorded debug events.
    pub fn drain_events(&mut self) -> Vec<DebugEvent> {
        std::mem::take(&mut self.events)
    }

    /// The last GNSS fix that corrected the fused position (`None` before the first).
    pub fn last_gnss_correction(&self) -> Option<GnssCorrection> {
        self.last_gnss_correction
    }

    /// The autopilot (read-only).
    pub fn autopilot(&self) -> &Autopilot {
        &self.autopilot
    }

    /// Fault injection (read-only).
    pub fn fault_injection(&self) -> &FaultInjection {
        &self.fi
    }

    /// The firmware's anchor list.
    pub fn anchor_list(&self) -> &AnchorList {
        &self.anchors
    }

    /// The motor simulator (read-only).
    pub fn motor(&self) -> &Motor {
        &self.motor
    }

    /// Whether the watchdog is expired now.
    pub fn watchdog_expired(&self) -> bool {
        self.watchdog_expired
    }

    // ----- commands (`docs/protocol.md#command-ids`); each says if it resets the watchdog -----

    /// GET_STATE. Resets the watchdog; passes px through the `px` probe.
    pub fn get_state(&mut self) -> StateReport {
        self.kick_watchdog();
        let fused = self.fused.pose();
        let uwb = self.uwb.pose();
        let swap = self.profile.swaps_uwb_position && self.config.vehicle.use_uwb_pos;
        let (main, other) = if swap { (uwb, fused) } else { (fused, uwb) };
        let (mut px, mut px_uwb) = (main.x, other.x);
        if swap {
            px_uwb = self.probe("px", px_uwb);
        } else {
            px = self.probe("px", px);
        }
        let FirmwareVersion {
            major: fw_major,
            minor: fw_minor,
        } = self.options.firmware;
        let (gx, gy) = self.fused.gps();
        let (goal_x, goal_y) = self.autopilot.goal();
        StateReport {
            id: self.car_id,
            fw_major,
            fw_minor,
            roll: 0.0,
            pitch: 0.0,
            yaw: main.yaw,
            accel: self.accelerations(),
            gyro: [0.0, 0.0, self.truth.yaw_rate as f32],
            mag: self.magnetometer(),
            px,
            py: main.y,
            speed: self.fused.speed(),
            v_in: HIL_V_IN,
            temp_mos: HIL_TEMP_MOS,
            mc_fault: 0,
            px_gps: gx,
            py_gps: gy,
            ap_goal_px: goal_x,
            ap_goal_py: goal_y,
            ap_rad: self.autopilot.rad_now(),
            ms_today: self.ms_today(),
            ap_route_left: self
                .autopilot
                .route_left()
                .clamp(i16::MIN.into(), i16::MAX.into()) as i16,
            px_uwb,
            py_uwb: other.y,
        }
    }

    fn accelerations(&self) -> [f32; 3] {
        let g = 9.81;
        let t = self.truth;
        [
            (t.accel_long / g) as f32,
            (t.speed * t.yaw_rate / g) as f32,
            1.0,
        ]
    }

    fn magnetometer(&self) -> [f32; 3] {
        // A horizontal field of 18 µT towards north and 45 µT down, seen from the rotating car.
        let h = self.truth.heading;
        let north_in_car = PI / 2.0 - h;
        [
            (18.0 * north_in_car.cos()) as f32,
            (18.0 * north_in_car.sin()) as f32,
            -45.0,
        ]
    }

    /// TERMINAL_CMD: the PRINTF texts it produces. Resets the watchdog.
    pub fn terminal(&mut self, text: &str) -> Vec<String> {
        self.kick_watchdog();
        let args = tokenize(text);
        let max = self.profile.max_printf_len;
        let lines = match args.first() {
            None => vec![NO_COMMAND.to_string()],
            Some(&cmd) => self.run_terminal(cmd, &args),
        };
        lines
            .into_iter()
            .filter(|l| !l.is_empty())
            .map(|l| truncate_printf(l, max))
            .collect()
    }

    fn run_terminal(&mut self, cmd: &str, args: &[&str]) -> Vec<String> {
        if let Some(mut out) = self.fi.terminal(args) {
            if self.options.misname_fault_probe
                && cmd == "fi_add_fault"
                && let Some(id) = args.get(1)
            {
                let (asked, other) = (format!("probe {id}."), format!("probe {id}0."));
                for line in &mut out {
                    *line = line.replace(&asked, &other);
                }
            }
            return out;
        }
        if let Some(out) = self.autopilot.terminal(args) {
            return out;
        }
        match cmd {
            "ping" => vec!["pong\n".to_string()],
            "pos_uwb_reset_pos" => {
                self.uwb.reset_to(self.fused.pose());
                vec!["UWB Position Reset\n".to_string()]
            }
            "pos_uwb_anchors" => self.anchor_report(),
            "set_id" | "set_id_quiet" if self.profile.terminal_set_id => {
                self.cmd_set_id(args, cmd == "set_id")
            }
            "help" => vec![HELP.to_string()],
            _ => vec![invalid_command(cmd)],
        }
    }

    fn cmd_set_id(&mut self, args: &[&str], verbose: bool) -> Vec<String> {
        if args.len() != 2 {
            return vec!["Wrong number of arguments\n".to_string()];
        }
        match scan_i32(args[1])
            .and_then(|n| u8::try_from(n).ok())
            .filter(|&n| n <= 254)
        {
            Some(n) => {
                self.car_id = n;
                if verbose {
                    vec![format!("ID is now {n}\n")]
                } else {
                    Vec::new()
                }
            }
            None => vec![format!("Invalid argument {}\n", args[1])],
        }
    }

    fn anchor_report(&self) -> Vec<String> {
        let mut out = vec!["UWB anchor list:".to_string()];
        for a in self.anchors.anchors() {
            let age = (self.now_ms - a.last_ms.unwrap_or(0)) as f64 / 1000.0;
            out.push(format!(
                "ID       : {}\nPX       : {:.2}\nPY       : {:.2}\nHeight   : {:.2} m\nLast dist: {:.2} m\nAge      : {:.2} s\n\n",
                a.id,
                f64::from(a.px),
                f64::from(a.py),
                f64::from(a.height),
                f64::from(a.dist_last),
                age
            ));
        }
        out
    }

    /// SET_POS / SET_POS_ACK: sets the fused pose (re-basing the yaw offset) and the UWB pose.
    /// Resets the watchdog.
    pub fn set_pos(&mut self, x: f32, y: f32, yaw: f32) {
        self.kick_watchdog();
        let pose = FwPose { x, y, yaw };
        self.fused.set_pose(pose, self.imu_yaw());
        self.uwb.set_pose(pose);
    }

    /// SET_YAW_OFFSET(_ACK). Resets the watchdog.
    pub fn set_yaw_offset(&mut self, offset: f32) {
        self.kick_watchdog();
        self.fused.set_yaw_offset(offset, self.imu_yaw());
    }

    /// SET_MS_TODAY. Resets the watchdog.
    pub fn set_ms_today(&mut self, ms: i32) {
        self.kick_watchdog();
        self.ms_today_base = Some((i64::from(ms), self.now_ms));
    }

    /// SET_ENU_REF: stored (positions already held are not transformed). Resets the watchdog.
    pub fn set_enu_ref(&mut self, lat: f64, lon: f64, height: f64) {
        self.kick_watchdog();
        self.enu_ref = (lat, lon, height);
    }

    /// GET_ENU_REF. Resets the watchdog.
    pub fn enu_ref(&mut self) -> (f64, f64, f64) {
        self.kick_watchdog();
        self.enu_ref
    }

    /// AP_ADD_POINTS. Resets the watchdog.
    pub fn add_points(&mut self, points: &[RoutePoint]) {
        self.kick_watchdog();
        let out = self.autopilot.add_points(points, &self.config);
        self.record_store(out);
    }

    /// AP_REPLACE_ROUTE. Resets the watchdog.
    pub fn replace_route(&mut self, points: &[RoutePoint]) {
        self.kick_watchdog();
        let ms = self.ms_today();
        let out = self.autopilot.replace_route(points, &self.config, ms);
        self.record_store(out);
    }

    fn record_store(&mut self, out: StoreOutcome) {
        if out.dropped_as_duplicate {
            self.record(DebugEvent::DuplicatePacketDropped { at_ms: self.now_ms });
        }
        if out.ring_overflow {
            self.record(DebugEvent::RouteRingOverflow { at_ms: self.now_ms });
        }
    }

    /// AP_REMOVE_LAST_POINT. Resets the watchdog.
    pub fn remove_last_point(&mut self) {
        self.kick_watchdog();
        self.autopilot.remove_last_point();
    }

    /// AP_CLEAR_POINTS (deactivates, no brake). Resets the watchdog.
    pub fn clear_route(&mut self) {
        self.kick_watchdog();
        let ms = self.ms_today();
        self.autopilot.clear(ms);
    }

    /// AP_GET_ROUTE_PART; `None` (no reply) when `num > 20`. Does **not** reset the watchdog.
    pub fn route_part(&self, first: i32, num: u8) -> Option<RoutePart> {
        self.autopilot.route_part(first, num)
    }

    /// AP_SET_ACTIVE (`reset_state` is 12.3's second byte; 10.x ignores it). No brake on
    /// deactivation. Resets the watchdog.
    pub fn set_active(&mut self, active: bool, reset_state: bool) {
        self.kick_watchdog();
        let ms = self.ms_today();
        self.autopilot.set_active(active, reset_state, ms);
    }

    /// AP_SYNC_POINT. Resets the watchdog.
    pub fn sync_point(&mut self, point: i32, time_ms: i32, min_diff_ms: i32) {
        self.kick_watchdog();
        let car = self.fused.pose();
        self.autopilot
            .sync_point(point, time_ms, min_diff_ms, car, &self.config);
    }

    /// RC_CONTROL: deactivates the autopilot, then applies throttle and steering. Resets the
    /// watchdog.
    pub fn rc_control(&mut self, mode: RcMode, throttle: f32, steering: f32) {
        self.kick_watchdog();
        self.autopilot.deactivate();
        let v = self.config.vehicle;
        if !v.disable_motor {
            let command = match mode {
                RcMode::Current => Some(MotorCommand::Current(throttle)),
                RcMode::Duty => Some(MotorCommand::Duty(throttle.clamp(-1.0, 1.0))),
                RcMode::Speed => {
                    let speed = truncate(
                        throttle,
                        -self.config.ap_max_speed,
                        self.config.ap_max_speed,
                    );
                    Some(MotorCommand::Rpm((speed / v.speed_per_erpm()).trunc()))
                }
                RcMode::Brake => Some(MotorCommand::CurrentBrake(throttle)),
                RcMode::Other(_) => None,
            };
            if let Some(c) = command.filter(|c| !command_is_nan(c)) {
                self.motor.command(c);
            }
        }
        let s = steering.clamp(-1.0, 1.0) * VehicleParams::steering_scale(self.fused.speed());
        self.servo
            .command(v.steering_center - s * v.steering_range / 2.0);
    }

    /// SET_SERVO_DIRECT: ramped; does not deactivate the autopilot. Resets the watchdog.
    pub fn set_servo_direct(&mut self, position: f32) {
        self.kick_watchdog();
        self.servo.command(position);
    }

    /// ADD_UWB_ANCHOR. Does **not** reset the watchdog.
    pub fn add_anchor(&mut self, id: i16, px: f32, py: f32, height: f32) {
        self.anchors.add(id, px, py, height);
    }

    /// CLEAR_UWB_ANCHORS. Does **not** reset the watchdog.
    pub fn clear_anchors(&mut self) {
        self.anchors.clear();
    }

    /// SET_MAIN_CONFIG (the record already decoded). Resets the watchdog.
    pub fn set_config(&mut self, config: FirmwareConfig) {
        self.kick_watchdog();
        self.config = config;
    }

    /// GET_MAIN_CONFIG(_DEFAULT): the configuration in force, or the defaults. Resets the watchdog.
    pub fn main_config(&mut self, defaults: bool) -> FirmwareConfig {
        self.kick_watchdog();
        if defaults {
            FirmwareConfig::defaults(self.options.firmware)
        } else {
            self.config
        }
    }

    /// Any other command that resets the watchdog (VESC_FWD).
    pub fn note_watchdog_reset(&mut self) {
        self.kick_watchdog();
    }
}

fn command_is_nan(c: &MotorCommand) -> bool {
    match *c {
        MotorCommand::Duty(x)
        | MotorCommand::Current(x)
        | MotorCommand::CurrentBrake(x)
        | MotorCommand::Rpm(x) => x.is_nan(),
        MotorCommand::Position => false,
    }
}

/// The `help` text (the firmware's list is longer; these are the commands the simulator knows).
const HELP: &str = "Valid commands are:\nhelp\nping\npos_uwb_reset_pos\npos_uwb_anchors\n\
fi_set_enabled\nfi_add_fault\nfi_clear_faults\nfi_print_faults\nfi_reset_cnt\n\
ap_set_look_ahead\nap_dynamic_rad\nap_ang_dist_comp\nap_state\n";

#[cfg(test)]
mod tests {
    use super::*;

    /// The fixes' noise: its spread and its lag-one correlation, per axis east.
    fn gnss_noise_statistics(correlation_s: f64) -> (f64, f64) {
        let mut c = SimCar::new(CarOptions {
            gnss: GnssModel {
                sigma_m: 0.02,
                correlation_s,
                ..GnssModel::default()
            },
            ..CarOptions::default()
        });
        let model = c.options.gnss;
        let xs: Vec<f64> = (0..40_000).map(|_| c.gnss_noise.next(&model).0).collect();
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
        let lag = xs
            .windows(2)
            .map(|w| (w[0] - mean) * (w[1] - mean))
            .sum::<f64>()
            / (n - 1.0);
        (var.sqrt(), lag / var)
    }

    /// Drives straight east at a steady duty cycle for 5 s without GNSS (the fused position is
    /// dead reckoning): the true distance, the distance the car counted, the fused yaw and the
    /// true heading (degrees clockwise).
    fn drive_blind(sensors: SensorErrors) -> (f64, f64, f32, f64) {
        let mut c = SimCar::new(CarOptions {
            gnss: GnssModel {
                enabled: false,
                ..GnssModel::default()
            },
            sensors,
            ..CarOptions::default()
        });
        for _ in 0..500 {
            c.rc_control(RcMode::Duty, 0.1, 0.0);
            c.step();
        }
        let t = c.truth();
        let counted = f64::from(t.fused.x).hypot(f64::from(t.fused.y));
        (
            t.x.hypot(t.y),
            counted,
            t.fused.yaw,
            -t.heading.to_degrees(),
        )
    }

    #[test]
    fn odometry_scale_and_yaw_bias_make_the_car_count_and_steer_wrongly() {
        let (truth, counted, yaw, heading) = drive_blind(SensorErrors::default());
        assert!(truth > 2.0, "the car drove {truth} m");
        assert!(
            (truth / counted - 1.0).abs() < 0.005,
            "{truth} vs {counted}"
        );
        assert!((f64::from(yaw) - heading).abs() < 0.01);
        let (truth, counted, _, _) = drive_blind(SensorErrors {
            odometry_scale: 1.03,
            ..SensorErrors::default()
        });
        assert!(
            (truth / counted - 1.03).abs() < 0.005,
            "{truth} vs {counted}"
        );
        let (_, _, yaw, heading) = drive_blind(SensorErrors {
            yaw_bias_deg: 1.5,
            yaw_drift_deg_per_min: 6.0,
            ..SensorErrors::default()
        });
        // 1.5° of bias and 6°/min for 5 s: 2.0°.
        assert!(
            (f64::from(yaw) - heading - 2.0).abs() < 0.05,
            "{yaw} vs {heading}"
        );
    }

    #[test]
    fn gnss_noise_is_gauss_markov_with_its_correlation_time() {
        // 0.6 s at 5 Hz: a = exp(-0.2/0.6) = 0.717.
        let (sd, rho) = gnss_noise_statistics(0.6);
        assert!((sd - 0.02).abs() < 0.001, "sd {sd}");
        assert!((rho - (-0.2f64 / 0.6).exp()).abs() < 0.02, "rho {rho}");
        let (sd, rho) = gnss_noise_statistics(0.0);
        assert!((sd - 0.02).abs() < 0.001, "sd {sd}");
        assert!(rho.abs() < 0.02, "white noise, rho {rho}");
    }

    fn car(firmware: FirmwareVersion) -> SimCar {
        SimCar::new(CarOptions {
            firmware,
            ..CarOptions::default()
        })
    }

    #[test]
    fn rc_control_plus_one_turns_right_and_minus_one_left() {
        for (steering, turns_right) in [(1.0, true), (-1.0, false)] {
            let mut c = car(FirmwareVersion::V12_3);
            c.rc_control(RcMode::Speed, 1.0, steering);
            c.run_for(1_000);
            assert_eq!(c.truth().heading < 0.0, turns_right, "steering {steering}");
        }
    }

    #[test]
    fn ms_today_is_unknown_until_gnss_time_or_set_ms_today() {
        let mut c = SimCar::new(CarOptions {
            gnss: GnssModel {
                enabled: false,
                ..GnssModel::default()
            },
            ..CarOptions::default()
        });
        c.run_for(1_000);
        assert_eq!(c.get_state().ms_today, -1);
        c.set_ms_today(45_296_789);
        c.run_for(1_000);
        assert_eq!(c.get_state().ms_today, 45_297_789);
        let mut g = car(FirmwareVersion::V10_1);
        assert_eq!(g.get_state().ms_today, -1);
        g.run_for(400);
        assert!(g.get_state().ms_today >= 12 * 3_600_000);
        assert_ne!(g.get_state().px_gps, 0.0);
    }

    #[test]
    fn terminal_commands_and_their_texts() {
        let mut old = car(FirmwareVersion::V10_1);
        assert_eq!(old.terminal("ping"), ["pong\n"]);
        assert_eq!(old.terminal(""), ["No command received\n"]);
        assert_eq!(
            old.terminal("fi_clear_faults\n"),
            ["Invalid command: fi_clear_faults\n\ntype help to list all available commands\n"]
        );
        assert_eq!(
            old.terminal("set_id 3"),
            ["Invalid command: set_id\ntype help to list all available commands\n"]
        );
        assert_eq!(old.terminal("pos_uwb_reset_pos"), ["UWB Position Reset\n"]);
        old.add_anchor(50, 1.0, 2.0, 1.5);
        let list = old.terminal("pos_uwb_anchors");
        assert_eq!(list[0], "UWB anchor list:");
        assert!(
            list[1].starts_with(
                "ID       : 50\nPX       : 1.00\nPY       : 2.00\nHeight   : 1.50 m\n"
            )
        );
        let mut new = car(FirmwareVersion::V12_3);
        assert_eq!(new.terminal("set_id 3"), ["ID is now 3\n"]);
        assert_eq!(new.car_id(), 3);
        assert!(new.terminal("set_id_quiet 4").is_empty());
        assert_eq!(new.car_id(), 4);
    }

    #[test]
    fn printf_text_is_cut_to_the_era_limit() {
        let long = format!("x{}", "y".repeat(600));
        let old = car(FirmwareVersion::V10_1).terminal(&long);
        let new = car(FirmwareVersion::V12_3).terminal(&long);
        assert_eq!(old[0].len(), 252);
        assert_eq!(new[0].len(), 508);
    }

    #[test]
    fn use_uwb_pos_swaps_the_estimates_in_12x_only() {
        for firmware in [FirmwareVersion::V10_1, FirmwareVersion::V12_3] {
            let mut c = SimCar::new(CarOptions {
                firmware,
                placement: Placement {
                    x: 3.0,
                    y: 4.0,
                    heading: 0.0,
                },
                ..CarOptions::default()
            });
            let mut cfg = *c.config();
            cfg.vehicle.use_uwb_pos = true;
            c.set_config(cfg);
            let s = c.get_state();
            let swapped = firmware.profile().swaps_uwb_position;
            assert_eq!((s.px, s.px_uwb) == (0.0, 3.0), swapped, "{firmware}");
            assert_eq!((s.px, s.px_uwb) == (3.0, 0.0), !swapped, "{firmware}");
        }
    }
}
