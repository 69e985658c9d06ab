//! The car's main configuration (the fields of the firmware's config record that the model uses).

use std::f32::consts::PI;

use car_link::firmware::FirmwareVersion;

/// Time mode of the autopilot (`ap_mode_time`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ApTimeMode {
    /// 0: speeds come from the route points (what tests use).
    #[default]
    Speed,
    /// 1: route point times are times of day.
    TimeOfDay,
    /// 2: route point times are relative to the activation.
    RelativeToStart,
}

impl ApTimeMode {
    /// The mode from its config byte; values above 2 behave like "absolute time" in the firmware
    /// (any non-zero value enables time mode), so they map to [`ApTimeMode::TimeOfDay`].
    pub fn from_byte(b: u8) -> Self {
        match b {
            0 => Self::Speed,
            2 => Self::RelativeToStart,
            _ => Self::TimeOfDay,
        }
    }

    /// The config byte.
    pub fn to_byte(self) -> u8 {
        match self {
            Self::Speed => 0,
            Self::TimeOfDay => 1,
            Self::RelativeToStart => 2,
        }
    }
}

/// Vehicle parameters (`car.*` in the firmware's config).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleParams {
    /// Wheel revolutions per motor revolution.
    pub gear_ratio: f32,
    /// Wheel diameter, m.
    pub wheel_diam: f32,
    /// Motor poles (ERPM = mechanical RPM · poles / 2).
    pub motor_poles: f32,
    /// Wheelbase L, m.
    pub axis_distance: f32,
    /// Steering angle at full lock, rad.
    pub steering_max_angle_rad: f32,
    /// Servo position of straight ahead (0..1).
    pub steering_center: f32,
    /// Servo travel between the two full locks.
    pub steering_range: f32,
    /// Time for a full 0→1 servo sweep, s (0 = instant).
    pub steering_ramp_time: f32,
    /// `car.yaw_use_odometry`: integrate the Ackermann arc instead of stepping along the IMU yaw.
    pub yaw_use_odometry: bool,
    /// `car.yaw_imu_gain`: pull of the odometry yaw towards the IMU, degrees per IMU sample.
    pub yaw_imu_gain: f32,
    /// `car.disable_motor`: throttle commands are ignored.
    pub disable_motor: bool,
    /// `car.clamp_imu_yaw_stationary` (10.2+; absent in 10.1).
    pub clamp_imu_yaw_stationary: bool,
    /// `car.use_uwb_pos` (11.0+): report and steer on the UWB pose.
    pub use_uwb_pos: bool,
}

impl VehicleParams {
    /// The defaults of a firmware generation.
    pub fn defaults(firmware: FirmwareVersion) -> Self {
        Self {
            gear_ratio: (1.0 / 3.0) * (21.0 / 37.0),
            wheel_diam: 0.11,
            motor_poles: 4.0,
            axis_distance: 0.475,
            steering_max_angle_rad: 0.42041,
            steering_center: 0.5,
            steering_range: 0.58,
            steering_ramp_time: firmware.profile().default_steering_ramp_time_s as f32,
            yaw_use_odometry: false,
            yaw_imu_gain: 0.5,
            disable_motor: false,
            clamp_imu_yaw_stationary: firmware.profile().default_clamp_imu_yaw_stationary,
            use_uwb_pos: false,
        }
    }

    /// Speed per ERPM, (m/s)/ERPM: `gear·(2/poles)/60·π·wheel_diam`.
    pub fn speed_per_erpm(&self) -> f32 {
        self.gear_ratio * (2.0 / self.motor_poles) * (1.0 / 60.0) * self.wheel_diam * PI
    }

    /// Distance per tachometer count, m: `gear·(2/poles)/6·π·wheel_diam`.
    pub fn distance_per_count(&self) -> f32 {
        self.gear_ratio * (2.0 / self.motor_poles) * (1.0 / 6.0) * self.wheel_diam * PI
    }

    /// The speed-dependent steering scale `1 / (1 + 0.05·|v|)²`.
    pub fn steering_scale(speed: f32) -> f32 {
        car_link::firmware::steering::speed_scale(speed)
    }

    /// The servo position for a steering angle (autopilot mapping), not clamped.
    pub fn servo_for_angle(&self, angle: f32) -> f32 {
        angle / ((2.0 * self.steering_max_angle_rad) / self.steering_range) + self.steering_center
    }

    /// The steering angle odometry sees for a servo position (positive = left turn).
    pub fn angle_for_servo(&self, servo: f32) -> f32 {
        (servo - self.steering_center) * 2.0 * self.steering_max_angle_rad / self.steering_range
    }
}

/// The part of the firmware's main configuration that the simulated car obeys.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FirmwareConfig {
    /// `ap_repeat_routes`: loop over the route forever (factory default **on**).
    pub ap_repeat_routes: bool,
    /// `ap_base_rad`: base look-ahead radius, m.
    pub ap_base_rad: f32,
    /// `ap_rad_time_ahead` (12.x): look-ahead time, s.
    pub ap_rad_time_ahead: f32,
    /// `ap_mode_time`.
    pub ap_mode_time: ApTimeMode,
    /// `ap_max_speed`, m/s.
    pub ap_max_speed: f32,
    /// `ap_time_add_repeat_ms`.
    pub ap_time_add_repeat_ms: i32,
    /// `uwb_max_corr` (12.2+), m.
    pub uwb_max_corr: f32,
    /// `gps_comp`: correct the fused position with GNSS fixes.
    pub gps_comp: bool,
    /// `gps_req_rtk`: only RTK fixes correct the position.
    pub gps_req_rtk: bool,
    /// `gps_use_rtcm_base_as_enu_ref`.
    pub gps_use_rtcm_base_as_enu_ref: bool,
    /// `gps_corr_gain_stat`, m per fix.
    pub gps_corr_gain_stat: f32,
    /// `gps_corr_gain_dyn`, m per metre driven.
    pub gps_corr_gain_dyn: f32,
    /// `gps_corr_gain_yaw`, degrees per metre driven.
    pub gps_corr_gain_yaw: f32,
    /// `gps_use_ubx_info`.
    pub gps_use_ubx_info: bool,
    /// `gps_ubx_max_acc`, m.
    pub gps_ubx_max_acc: f32,
    /// `gps_ant_x`, m forward of the reference point.
    pub gps_ant_x: f32,
    /// `gps_ant_y`, m to the left of the reference point.
    pub gps_ant_y: f32,
    /// `car.simulate_motor` (the simulator always simulates; this is what GET_MAIN_CONFIG reports).
    pub simulate_motor: bool,
    /// The vehicle (`car.*`).
    pub vehicle: VehicleParams,
}

impl FirmwareConfig {
    /// The factory defaults of a firmware generation (with `simulate_motor` on: this is a HIL board).
    pub fn defaults(firmware: FirmwareVersion) -> Self {
        Self {
            ap_repeat_routes: true,
            ap_base_rad: firmware.profile().default_base_radius_m as f32,
            ap_rad_time_ahead: firmware.profile().default_radius_time_ahead_s as f32,
            ap_mode_time: ApTimeMode::Speed,
            ap_max_speed: 8.333_333,
            ap_time_add_repeat_ms: 60_000,
            uwb_max_corr: 0.1,
            gps_comp: true,
            gps_req_rtk: true,
            gps_use_rtcm_base_as_enu_ref: true,
            gps_corr_gain_stat: 0.05,
            gps_corr_gain_dyn: 0.05,
            gps_corr_gain_yaw: 1.0,
            gps_use_ubx_info: true,
            gps_ubx_max_acc: 0.12,
            gps_ant_x: 0.0,
            gps_ant_y: 0.0,
            simulate_motor: true,
            vehicle: VehicleParams::defaults(firmware),
        }
    }
}

/// The firmware's `utils_truncate_number`: `x` limited to `[lo, hi]` by two comparisons, as the C
/// code does it. Unlike `f32::clamp` it never panics on what a host may configure: a NaN `x` or
/// bound passes through, and inverted bounds (a negative maximum speed) give `hi`.
pub(crate) fn truncate<T: PartialOrd>(x: T, lo: T, hi: T) -> T {
    if x > hi {
        hi
    } else if x < lo {
        lo
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derived_constants_match_the_behaviour_document() {
        let v = VehicleParams::defaults(FirmwareVersion::V10_1);
        assert!((v.speed_per_erpm() - 5.448_26e-4).abs() < 1e-8);
        assert!((v.distance_per_count() - 5.448_26e-3).abs() < 1e-7);
        assert!((1.0 / v.speed_per_erpm() - 1835.45).abs() < 0.05);
        // 0.68980 servo units per radian.
        assert!((v.servo_for_angle(1.0) - v.steering_center - 0.689_80).abs() < 1e-4);
        let r_min = v.axis_distance / v.steering_max_angle_rad.tan();
        assert!((r_min - 1.062).abs() < 1e-3);
    }

    #[test]
    fn era_defaults_differ_where_documented() {
        let old = FirmwareConfig::defaults(FirmwareVersion::V10_1);
        let new = FirmwareConfig::defaults(FirmwareVersion::V12_3);
        assert_eq!((old.ap_base_rad, new.ap_base_rad), (1.2, 0.8));
        assert_eq!(old.vehicle.steering_ramp_time, 0.6);
        assert_eq!(new.vehicle.steering_ramp_time, 0.0);
        assert!(old.ap_repeat_routes && new.ap_repeat_routes);
    }
}
