//! The physical car and its world, apart from any firmware: the motor controller and motor, the
//! steering servo, the true motion (a kinematic bicycle), and the sensors' physics — the GNSS
//! receiver's noise, the UWB radio against the [`World`], what the IMU and the motor controller
//! measure.
//!
//! Two firmwares drive it: [`crate::SimCar`], our model of the car's firmware, steps [`Motion`]
//! and [`GnssNoise`] inside its own tick; and the car's **own** firmware built for the host
//! (`sitl`, driven by `runner::vehicle`), which commands a whole [`Plant`] through the motor and
//! servo frames and reads its sensors. The same seed gives both the same noise streams (the GNSS
//! receiver's and the radio's), so a difference between the two is a difference of firmware.
//!
//! No I/O and no clock: time passes only through [`Plant::step`], one 10 ms tick.

use std::f64::consts::PI;

use scenarios::geometry::Point;

use crate::car::{GnssModel, Placement, SensorErrors, TICK_MS};
use crate::config::{VehicleParams, truncate};
use crate::debug::Truth;
use crate::motor::{HIL_V_IN, Motor, MotorCommand};
use crate::noise::Noise;
use crate::servo::Servo;
use crate::uwb::{ANTENNA_OFFSET_M, RadioModel, RangeMeasurement, measure_range};
use crate::world::World;

/// The GNSS receiver's noise stream (the same stream id as the simulated car's).
pub(crate) const STREAM_GNSS: u64 = 1;
/// The UWB radio's noise stream.
pub(crate) const STREAM_UWB: u64 = 2;
/// Standard gravity, m/s² (the IMU reads accelerations in g).
const G: f64 = 9.806_65;

/// The true motion of the car's reference point (the rear axle's centre).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// East, m.
    pub x: f64,
    /// North, m.
    pub y: f64,
    /// Heading, radians counter-clockwise from east, in [−π, π).
    pub heading: f64,
    /// Speed, m/s (signed).
    pub speed: f64,
    /// Steering angle, rad (positive left).
    pub steering: f64,
    /// Longitudinal acceleration over the last step, m/s².
    pub accel_long: f64,
    /// Yaw rate over the last step, rad/s (counter-clockwise).
    pub yaw_rate: f64,
}

impl Motion {
    /// Standing at `placement`.
    pub fn standing(placement: Placement) -> Self {
        Self {
            x: placement.x,
            y: placement.y,
            heading: placement.heading,
            speed: 0.0,
            steering: 0.0,
            accel_long: 0.0,
            yaw_rate: 0.0,
        }
    }

    /// One tick ([`TICK_MS`]) of the car `vehicle` driven by `motor` and steered by `servo`:
    /// the speed the motor's rpm gives (times `odometry_scale`, the distance really driven per
    /// distance counted) and the steering angle of the servo's position.
    pub fn tick(
        &mut self,
        vehicle: &VehicleParams,
        motor: &Motor,
        servo: &Servo,
        odometry_scale: f64,
    ) {
        let speed = f64::from(motor.rpm()) * f64::from(vehicle.speed_per_erpm()) * odometry_scale;
        let delta = f64::from(vehicle.angle_for_servo(servo.position()));
        self.advance(
            speed,
            delta,
            f64::from(vehicle.steering_max_angle_rad),
            f64::from(vehicle.axis_distance),
            TICK_MS as f64 / 1000.0,
        );
    }

    /// One step of `dt` seconds at `speed` (m/s) with steering angle `delta` (rad, clamped to
    /// `±max_angle`), on a wheelbase of `axis_distance` m: the exact arc of a kinematic bicycle.
    pub fn advance(&mut self, speed: f64, delta: f64, max_angle: f64, axis_distance: f64, dt: f64) {
        let delta = truncate(delta, -max_angle, max_angle);
        let d = speed * dt;
        let curvature = delta.tan() / axis_distance;
        let dpsi = d * curvature;
        if curvature.abs() < 1e-9 {
            self.x += d * self.heading.cos();
            self.y += d * self.heading.sin();
        } else {
            self.x += ((self.heading + dpsi).sin() - self.heading.sin()) / curvature;
            self.y += (self.heading.cos() - (self.heading + dpsi).cos()) / curvature;
        }
        self.heading = (self.heading + dpsi + PI).rem_euclid(2.0 * PI) - PI;
        self.accel_long = (speed - self.speed) / dt;
        self.yaw_rate = dpsi / dt;
        self.speed = speed;
        self.steering = delta;
    }

    /// Where the UWB antenna is ([`ANTENNA_OFFSET_M`] ahead of the reference point).
    pub fn uwb_antenna(&self) -> Point {
        let off = f64::from(ANTENNA_OFFSET_M);
        Point::new(
            self.x + off * self.heading.cos(),
            self.y + off * self.heading.sin(),
        )
    }

    /// Where a GNSS antenna mounted at (`ant_x` ahead, `ant_y` left) of the reference point is.
    pub fn gnss_antenna(&self, ant_x: f64, ant_y: f64) -> Point {
        let (s, c) = self.heading.sin_cos();
        Point::new(
            self.x + ant_x * c - ant_y * s,
            self.y + ant_x * s + ant_y * c,
        )
    }
}

/// The GNSS receiver's position noise: white, or a first-order Gauss–Markov process per axis
/// ([`GnssModel::correlation_s`]).
#[derive(Debug, Clone)]
pub struct GnssNoise {
    noise: Noise,
    error: Option<(f64, f64)>,
}

impl GnssNoise {
    /// The receiver of a car seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Self {
            noise: Noise::stream(seed, STREAM_GNSS),
            error: None,
        }
    }

    /// The next fix's noise (east, north), m. White noise draws exactly what it always drew, so
    /// a model without correlation reproduces earlier runs.
    pub fn next(&mut self, model: &GnssModel) -> (f64, f64) {
        let sigma = model.sigma_m;
        let white = (self.noise.gaussian(sigma), self.noise.gaussian(sigma));
        if model.correlation_s <= 0.0 {
            return white;
        }
        let next = match self.error {
            None => white,
            Some((ex, ey)) => {
                let a = (-(model.period_ms as f64 / 1000.0) / model.correlation_s).exp();
                let b = (1.0 - a * a).sqrt();
                (a * ex + b * white.0, a * ey + b * white.1)
            }
        };
        self.error = Some(next);
        next
    }
}

/// Everything that defines a physical car and its world.
#[derive(Debug, Clone, PartialEq)]
pub struct PlantOptions {
    /// The car's geometry, gearing and steering (what its firmware is configured with).
    pub vehicle: VehicleParams,
    /// Where the GNSS antenna is mounted, m ahead and left of the reference point.
    pub gnss_antenna: (f64, f64),
    /// The anchors as they physically stand, obstacles and walls.
    pub world: World,
    /// The UWB radio.
    pub radio: RadioModel,
    /// The GNSS receiver.
    pub gnss: GnssModel,
    /// The errors of the car's odometry and IMU.
    pub sensors: SensorErrors,
    /// Where the car stands at the start.
    pub placement: Placement,
    /// The seed of the noise streams.
    pub seed: u64,
}

/// What the IMU measures, in the board's axes: acceleration in g, angular rate in °/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuReading {
    /// Acceleration x (forward), y (left), z (up), g.
    pub accel_g: [f64; 3],
    /// Angular rate about x, y, z (counter-clockwise seen from above is positive z), °/s.
    pub gyro_dps: [f64; 3],
    /// The magnetometer, as the firmware reads it after its own axis swap and board rotation
    /// ([`magnetometer`]).
    pub mag: [f64; 3],
}

/// What the magnetometer reads on a car whose IMU yaw is `imu_yaw_deg` (degrees clockwise, 0 =
/// east): a unit horizontal field that the firmware's start-up (`ahrs.c`'s initial orientation
/// takes its yaw from the magnetometer, `atan2(−m_y, −m_x) − 90°` on level ground) turns into that
/// yaw. So the firmware's raw IMU yaw starts at the car's true heading (plus its bias), as the
/// simulated car's does ([`crate::car::raw_imu_yaw`]), and the gyro turns it from there. (The
/// firmware uses the magnetometer nowhere else with its default `mag_use = false`.)
pub fn magnetometer(imu_yaw_deg: f64) -> [f64; 3] {
    // −(yaw clockwise) is the heading counter-clockwise
    let h = (-imu_yaw_deg).to_radians();
    [-h.sin(), -h.cos(), 0.0]
}

/// What the motor controller reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorReading {
    /// Electrical RPM.
    pub rpm: f64,
    /// Tachometer, signed counts.
    pub tachometer: i32,
    /// Tachometer, absolute counts.
    pub tachometer_abs: i32,
    /// Input voltage, V.
    pub v_in: f64,
    /// Duty cycle, −1 to 1.
    pub duty: f64,
}

/// A GNSS fix as the receiver measured it: the antenna's position with noise, local metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssMeasurement {
    /// When it was measured, ms since the start.
    pub measured_ms: u64,
    /// When it reaches the firmware, ms since the start.
    pub arrives_ms: u64,
    /// East, m.
    pub x: f64,
    /// North, m.
    pub y: f64,
}

/// The physical car: commanded through its motor controller and servo, read through its sensors.
#[derive(Debug, Clone)]
pub struct Plant {
    options: PlantOptions,
    now_ms: u64,
    motor: Motor,
    servo: Servo,
    motion: Motion,
    tacho_abs: f64,
    last_tacho: i32,
    gnss: GnssNoise,
    uwb: Noise,
}

impl Plant {
    /// The car standing at `options.placement`, its servo centred.
    pub fn new(options: PlantOptions) -> Self {
        Self {
            now_ms: 0,
            motor: Motor::default(),
            servo: Servo::new(options.vehicle.steering_center),
            motion: Motion::standing(options.placement),
            tacho_abs: 0.0,
            last_tacho: 0,
            gnss: GnssNoise::new(options.seed),
            uwb: Noise::stream(options.seed, STREAM_UWB),
            options,
        }
    }

    /// The options it was made with.
    pub fn options(&self) -> &PlantOptions {
        &self.options
    }

    /// Time since the start, ms.
    pub fn now_ms(&self) -> u64 {
        self.now_ms
    }

    /// A command to the motor controller.
    pub fn command_motor(&mut self, command: MotorCommand) {
        self.motor.command(command);
    }

    /// A new servo position (0 to 1); the servo ramps towards it.
    pub fn command_servo(&mut self, position: f32) {
        self.servo.command(position);
    }

    /// One 10 ms tick: the motor, the motion, the servo (in the simulated car's order).
    pub fn step(&mut self) {
        self.now_ms += TICK_MS;
        self.motor.step();
        let v = &self.options.vehicle;
        self.motion.tick(
            v,
            &self.motor,
            &self.servo,
            self.options.sensors.odometry_scale,
        );
        self.servo.step(v.steering_ramp_time);
        let tacho = self.motor.tachometer();
        self.tacho_abs += f64::from(tacho.abs_diff(self.last_tacho));
        self.last_tacho = tacho;
    }

    /// The true motion now.
    pub fn motion(&self) -> Motion {
        self.motion
    }

    /// The servo's position now (0 to 1).
    pub fn servo_position(&self) -> f32 {
        self.servo.position()
    }

    /// What the IMU reads now: gravity, the longitudinal and centripetal accelerations, the yaw
    /// rate, with the car's gyro drift ([`SensorErrors::yaw_drift_deg_per_min`], turned into a
    /// rate bias; the firmware's yaw is clockwise, so a clockwise drift is a negative z rate).
    pub fn imu(&self) -> ImuReading {
        let m = self.motion;
        let drift_dps = self.options.sensors.yaw_drift_deg_per_min / 60.0;
        ImuReading {
            accel_g: [m.accel_long / G, m.speed * m.yaw_rate / G, 1.0],
            gyro_dps: [0.0, 0.0, m.yaw_rate.to_degrees() - drift_dps],
            mag: magnetometer(
                crate::car::raw_imu_yaw(m.heading, self.options.sensors.yaw_bias_deg) as f64,
            ),
        }
    }

    /// What the motor controller reports now.
    pub fn motor_reading(&self) -> MotorReading {
        MotorReading {
            rpm: f64::from(self.motor.rpm()),
            tachometer: self.motor.tachometer(),
            tachometer_abs: self.tacho_abs.min(f64::from(i32::MAX)) as i32,
            v_in: f64::from(HIL_V_IN),
            duty: f64::from(self.motor.duty()),
        }
    }

    /// The fix the receiver measures on this tick, if it measures one (every
    /// [`GnssModel::period_ms`]), with its arrival time.
    pub fn gnss_fix(&mut self) -> Option<GnssMeasurement> {
        let model = self.options.gnss;
        if !model.enabled || model.period_ms == 0 || !self.now_ms.is_multiple_of(model.period_ms) {
            return None;
        }
        let (ax, ay) = self.options.gnss_antenna;
        let antenna = self.motion.gnss_antenna(ax, ay);
        let (ex, ey) = self.gnss.next(&model);
        Some(GnssMeasurement {
            measured_ms: self.now_ms,
            arrives_ms: self.now_ms + model.latency_ms,
            x: antenna.x + ex,
            y: antenna.y + ey,
        })
    }

    /// One UWB range request from the car's antenna to the anchor at `address`, now.
    pub fn range(&mut self, address: u8) -> RangeMeasurement {
        measure_range(
            &self.options.world,
            None,
            address,
            self.motion.uwb_antenna(),
            &self.options.radio,
            &mut self.uwb,
        )
    }

    /// The debug view: the true pose; the firmware's estimates are not the plant's to know, so
    /// they are `fused` and `uwb` as given.
    pub fn truth(&self, fused: crate::FwPose, uwb: crate::FwPose) -> Truth {
        let m = self.motion;
        Truth {
            time_ms: self.now_ms,
            x: m.x,
            y: m.y,
            heading: m.heading,
            speed: m.speed,
            steering_angle: m.steering,
            fused,
            uwb,
        }
    }
}

/// WGS-84's semi-major axis, m.
const WGS84_A: f64 = 6_378_137.0;
/// WGS-84's flattening.
const WGS84_F: f64 = 1.0 / 298.257_223_563;

/// The geodetic place of the local ENU frame's origin: what a receiver's fixes are expressed
/// against (the firmware converts them back with its ENU reference, SET_ENU_REF).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeodeticOrigin {
    /// Latitude, degrees north.
    pub lat: f64,
    /// Longitude, degrees east.
    pub lon: f64,
    /// Height above the ellipsoid, m.
    pub height: f64,
}

impl GeodeticOrigin {
    /// Latitude, longitude (degrees) and height (m) of the local point (`east`, `north`, `up`).
    pub fn to_llh(&self, east: f64, north: f64, up: f64) -> (f64, f64, f64) {
        let e2 = WGS84_F * (2.0 - WGS84_F);
        let (sp, cp) = self.lat.to_radians().sin_cos();
        let (sl, cl) = self.lon.to_radians().sin_cos();
        let v = WGS84_A / (1.0 - e2 * sp * sp).sqrt();
        let x0 = (v + self.height) * cp * cl;
        let y0 = (v + self.height) * cp * sl;
        let z0 = (v * (1.0 - e2) + self.height) * sp;
        let x = x0 - sl * east - sp * cl * north + cp * cl * up;
        let y = y0 + cl * east - sp * sl * north + cp * sl * up;
        let z = z0 + cp * north + sp * up;
        // ECEF to geodetic by fixed-point iteration on the latitude (converges to well below a
        // micrometre in a few rounds this close to the surface).
        let p = x.hypot(y);
        let lon = y.atan2(x);
        let mut lat = z.atan2(p * (1.0 - e2));
        let mut height = 0.0;
        for _ in 0..8 {
            let s = lat.sin();
            let n = WGS84_A / (1.0 - e2 * s * s).sqrt();
            height = p / lat.cos() - n;
            lat = z.atan2(p * (1.0 - e2 * n / (n + height)));
        }
        (lat.to_degrees(), lon.to_degrees(), height)
    }

    /// The NMEA GGA sentence (with its `$` and checksum, without a line end) of an RTK-fixed
    /// fix (quality 4) at the local point (`east`, `north`) on the ground, at `ms_today` ms
    /// after UTC midnight.
    pub fn gga(&self, east: f64, north: f64, ms_today: u64) -> String {
        let (lat, lon, height) = self.to_llh(east, north, 0.0);
        let minutes = |deg: f64| {
            let d = deg.abs().trunc();
            (d, (deg.abs() - d) * 60.0)
        };
        let (lat_d, lat_m) = minutes(lat);
        let (lon_d, lon_m) = minutes(lon);
        let t = ms_today % 86_400_000;
        let body = format!(
            "GPGGA,{:02}{:02}{:02}.{:02},{lat_d:02}{lat_m:010.7},{},{lon_d:03}{lon_m:010.7},{},4,12,0.8,{height:.3},M,0.0,M,1.0,0000",
            t / 3_600_000,
            t / 60_000 % 60,
            t / 1000 % 60,
            t % 1000 / 10,
            if lat < 0.0 { 'S' } else { 'N' },
            if lon < 0.0 { 'W' } else { 'E' },
        );
        let sum = body.bytes().fold(0u8, |a, b| a ^ b);
        format!("${body}*{sum:02X}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plant() -> Plant {
        Plant::new(PlantOptions {
            vehicle: VehicleParams::defaults(car_link::FirmwareVersion::default()),
            gnss_antenna: (0.0, 0.0),
            world: World::default(),
            radio: RadioModel::default(),
            gnss: GnssModel::default(),
            sensors: SensorErrors::default(),
            placement: Placement {
                x: 1.0,
                y: 2.0,
                heading: 0.0,
            },
            seed: 3,
        })
    }

    #[test]
    fn drives_forward_and_counts_the_tachometer() {
        let mut p = plant();
        p.command_motor(MotorCommand::Current(20.0));
        for _ in 0..100 {
            p.step();
        }
        let m = p.motion();
        assert!(m.x > 1.5, "{m:?}");
        assert!((m.y - 2.0).abs() < 1e-9);
        let r = p.motor_reading();
        assert!(
            r.tachometer > 0 && r.tachometer_abs == r.tachometer,
            "{r:?}"
        );
        assert!(p.imu().accel_g[0] > 0.0);
    }

    #[test]
    fn a_left_turn_is_a_positive_yaw_rate() {
        let mut p = plant();
        p.command_motor(MotorCommand::Current(20.0));
        p.command_servo(0.9);
        for _ in 0..100 {
            p.step();
        }
        assert!(p.motion().heading > 0.1);
        assert!(p.imu().gyro_dps[2] > 1.0);
        assert!(
            p.imu().accel_g[1] > 0.0,
            "centripetal acceleration points left"
        );
    }

    /// The firmware's conversion back (`pos.c`: llh to ECEF, then the ENU rotation of its
    /// reference), written out as the firmware computes it.
    fn to_enu(origin: &GeodeticOrigin, lat: f64, lon: f64, h: f64) -> (f64, f64, f64) {
        let ecef = |lat: f64, lon: f64, h: f64| {
            let e2 = WGS84_F * (2.0 - WGS84_F);
            let (sp, cp) = lat.to_radians().sin_cos();
            let (sl, cl) = lon.to_radians().sin_cos();
            let v = WGS84_A / (1.0 - e2 * sp * sp).sqrt();
            (
                (v + h) * cp * cl,
                (v + h) * cp * sl,
                (v * (1.0 - e2) + h) * sp,
            )
        };
        let (x0, y0, z0) = ecef(origin.lat, origin.lon, origin.height);
        let (x, y, z) = ecef(lat, lon, h);
        let (dx, dy, dz) = (x - x0, y - y0, z - z0);
        let (sp, cp) = origin.lat.to_radians().sin_cos();
        let (sl, cl) = origin.lon.to_radians().sin_cos();
        (
            -sl * dx + cl * dy,
            -sp * cl * dx - sp * sl * dy + cp * dz,
            cp * cl * dx + cp * sl * dy + sp * dz,
        )
    }

    #[test]
    fn local_points_go_to_llh_and_back() {
        let origin = GeodeticOrigin {
            lat: 57.7,
            lon: 12.9,
            height: 150.0,
        };
        for (e, n) in [(0.0, 0.0), (120.5, -33.25), (-2_000.0, 1_500.0)] {
            let (lat, lon, h) = origin.to_llh(e, n, 0.0);
            let (e2, n2, u2) = to_enu(&origin, lat, lon, h);
            assert!((e2 - e).abs() < 1e-6 && (n2 - n).abs() < 1e-6 && u2.abs() < 1e-6);
        }
    }

    #[test]
    fn gga_sentences_are_well_formed() {
        let origin = GeodeticOrigin {
            lat: 57.7,
            lon: 12.9,
            height: 0.0,
        };
        let s = origin.gga(0.0, 10.0, 12 * 3_600_000 + 61_230);
        assert!(s.starts_with("$GPGGA,120101.23,5742.0"), "{s}");
        let (body, sum) = s[1..].split_once('*').unwrap();
        assert_eq!(
            u8::from_str_radix(sum, 16).unwrap(),
            body.bytes().fold(0, |a, b| a ^ b)
        );
        let fields: Vec<&str> = body.split(',').collect();
        assert_eq!((fields[3], fields[5], fields[6]), ("N", "E", "4"));
        // 10 m north of 57.7° N is 57.7° + 10/111.4 km, in minutes past 57°
        let minutes: f64 = fields[2][2..].parse().unwrap();
        assert!((minutes - 42.0 - 10.0 / 1_855.6).abs() < 2e-5, "{minutes}");
    }

    #[test]
    fn fixes_come_at_the_receivers_rate_with_its_latency() {
        let mut p = plant();
        let mut fixes = Vec::new();
        for _ in 0..100 {
            p.step();
            fixes.extend(p.gnss_fix());
        }
        assert_eq!(fixes.len(), 5, "5 Hz for 1 s");
        assert!(fixes.iter().all(|f| f.arrives_ms == f.measured_ms + 100));
        assert!(fixes.iter().all(|f| (f.x - 1.0).abs() < 0.1));
    }
}
