//! The fused ("RTK") position of the firmware (`docs/firmware.md#odometry-and-yaw`,
//! `docs/firmware.md#fused-position`): odometry dead reckoning along the IMU heading, corrected by
//! GNSS fixes with latency compensation through a pose history.

use std::collections::VecDeque;

use crate::autopilot::FwPose;
use crate::config::FirmwareConfig;
use car_link::firmware::{FirmwareProfile, FirmwareVersion};

/// Entries of the pose history.
const HISTORY_LEN: usize = 100;
/// Below this speed the yaw is clamped (stationary clamp), m/s.
const STATIONARY_SPEED: f32 = 0.05;

/// One history entry.
#[derive(Debug, Clone, Copy, PartialEq)]
struct HistoryEntry {
    px: f32,
    py: f32,
    yaw: f32,
    time_ms: u64,
}

/// A GNSS fix as the firmware receives it (already converted to local ENU).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssFix {
    /// Antenna east, m.
    pub x: f32,
    /// Antenna north, m.
    pub y: f32,
    /// When the fix was measured (simulation time, ms).
    pub measured_ms: u64,
    /// Whether it is an RTK fix (type 4 or 5).
    pub rtk: bool,
}

/// What one odometry tick measured.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OdometryStep {
    /// Distance since the previous tick, m (quantised to the tachometer).
    pub distance: f32,
    /// Speed from the motor RPM, m/s (signed).
    pub speed: f32,
}

/// What the odometry task reads at one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryInput {
    /// The motor's integer tachometer.
    pub tacho: i32,
    /// The motor's electrical RPM.
    pub rpm: f32,
    /// The IMU yaw, degrees clockwise.
    pub imu_yaw: f32,
    /// The steering angle from the servo position, rad (used with `yaw_use_odometry`).
    pub steering_angle: f32,
    /// IMU samples since the previous tick (for the IMU pull of `yaw_use_odometry`).
    pub imu_samples: u32,
    /// Simulation time, ms.
    pub now_ms: u64,
}

/// The fused position estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct FusedPosition {
    firmware: FirmwareProfile,
    px: f32,
    py: f32,
    yaw: f32,
    yaw_offset: f32,
    odo_yaw: f32,
    speed: f32,
    tacho_prev: Option<i32>,
    history: VecDeque<HistoryEntry>,
    driven_since_fix: f32,
    prev_corr: Option<(f32, f32, u64)>,
    px_gps: f32,
    py_gps: f32,
}

/// Wraps an angle in degrees to [−180, 180]. A huge angle (a fault's blown-up yaw, where
/// subtracting 360 no longer changes the value) is first reduced with `fmod`, as the firmware's
/// angle normalisation does, so the car keeps running whatever value a fault produces.
pub fn wrap180(mut a: f32) -> f32 {
    if !a.is_finite() {
        return a;
    }
    if a.abs() > 1.0e6 {
        a %= 360.0;
    }
    while a > 180.0 {
        a -= 360.0;
    }
    while a < -180.0 {
        a += 360.0;
    }
    a
}

impl FusedPosition {
    /// The estimate at boot: the origin, heading from the IMU.
    pub fn new(firmware: FirmwareVersion) -> Self {
        Self {
            firmware: firmware.profile(),
            px: 0.0,
            py: 0.0,
            yaw: 0.0,
            yaw_offset: 0.0,
            odo_yaw: 0.0,
            speed: 0.0,
            tacho_prev: None,
            history: VecDeque::with_capacity(HISTORY_LEN),
            driven_since_fix: 0.0,
            prev_corr: None,
            px_gps: 0.0,
            py_gps: 0.0,
        }
    }

    /// The fused pose.
    pub fn pose(&self) -> FwPose {
        FwPose {
            x: self.px,
            y: self.py,
            yaw: self.yaw,
        }
    }

    /// The odometry speed, m/s.
    pub fn speed(&self) -> f32 {
        self.speed
    }

    /// The last fix minus the antenna offset (0 before the first fix).
    pub fn gps(&self) -> (f32, f32) {
        (self.px_gps, self.py_gps)
    }

    /// The IMU yaw offset, degrees.
    pub fn yaw_offset(&self) -> f32 {
        self.yaw_offset
    }

    /// SET_POS: sets the position and re-bases the yaw offset so that the fused yaw is `yaw`.
    pub fn set_pose(&mut self, pose: FwPose, imu_yaw: f32) {
        self.px = pose.x;
        self.py = pose.y;
        self.set_yaw(pose.yaw, imu_yaw);
    }

    fn set_yaw(&mut self, yaw: f32, imu_yaw: f32) {
        self.yaw_offset = wrap180(imu_yaw - yaw);
        self.yaw = wrap180(yaw);
        self.odo_yaw = self.yaw;
    }

    /// SET_YAW_OFFSET: sets the IMU yaw offset.
    pub fn set_yaw_offset(&mut self, offset: f32, imu_yaw: f32) {
        self.yaw_offset = offset;
        self.yaw = wrap180(imu_yaw - offset);
        self.odo_yaw = self.yaw;
    }

    /// One odometry tick: motor values to distance and speed, the heading from the IMU, the
    /// position step and the history entry.
    pub fn odometry_tick(&mut self, cfg: &FirmwareConfig, input: OdometryInput) -> OdometryStep {
        let OdometryInput {
            tacho,
            rpm,
            imu_yaw,
            steering_angle,
            imu_samples,
            now_ms,
        } = input;
        let v = &cfg.vehicle;
        let distance = match self.tacho_prev.replace(tacho) {
            Some(prev) => tacho.wrapping_sub(prev) as f32 * v.distance_per_count(),
            None => 0.0,
        };
        self.speed = rpm * v.speed_per_erpm();
        if v.clamp_imu_yaw_stationary && self.speed.abs() < STATIONARY_SPEED {
            self.yaw_offset = wrap180(imu_yaw - self.yaw);
        }
        if v.yaw_use_odometry {
            self.odometry_yaw_step(cfg, distance, imu_yaw, steering_angle, imu_samples);
        } else {
            self.yaw = wrap180(imu_yaw - self.yaw_offset);
            let a = -self.yaw.to_radians();
            self.px += distance * a.cos();
            self.py += distance * a.sin();
        }
        self.driven_since_fix += distance.abs();
        self.push_history(now_ms);
        OdometryStep {
            distance,
            speed: self.speed,
        }
    }

    /// `yaw_use_odometry = 1`: the Ackermann arc with the firmware's second-order sign quirk, then
    /// the IMU pull (`yaw_imu_gain` degrees per IMU sample, snapping within ±1.2·gain).
    fn odometry_yaw_step(
        &mut self,
        cfg: &FirmwareConfig,
        distance: f32,
        imu_yaw: f32,
        steering_angle: f32,
        imu_samples: u32,
    ) {
        let l = cfg.vehicle.axis_distance;
        let a = -self.odo_yaw.to_radians();
        if steering_angle.abs() >= 1e-6 {
            let r_rear = l / steering_angle.tan();
            let r_front = (l * l + r_rear * r_rear).sqrt().copysign(r_rear);
            let dpsi = 2.0 * distance / (r_rear + r_front);
            self.px += r_rear * ((a + dpsi).sin() - a.sin());
            self.py += r_rear * ((a - dpsi).cos() - a.cos());
            self.odo_yaw = wrap180(-(a + dpsi).to_degrees());
        } else {
            self.px += distance * a.cos();
            self.py += distance * a.sin();
        }
        let gain = cfg.vehicle.yaw_imu_gain;
        if gain > 1e-10 {
            let target = wrap180(imu_yaw - self.yaw_offset);
            for _ in 0..imu_samples {
                let diff = wrap180(target - self.odo_yaw);
                if diff.abs() <= 1.2 * gain {
                    self.odo_yaw = target;
                } else {
                    self.odo_yaw = wrap180(self.odo_yaw + gain.copysign(diff));
                }
            }
        }
        self.yaw = self.odo_yaw;
    }

    fn push_history(&mut self, now_ms: u64) {
        if self.history.len() == HISTORY_LEN {
            self.history.pop_front();
        }
        self.history.push_back(HistoryEntry {
            px: self.px,
            py: self.py,
            yaw: self.yaw,
            time_ms: now_ms,
        });
    }

    /// The history entry nearest `t`: walk back from the newest while the distance in time keeps
    /// decreasing.
    fn history_at(&self, t: u64) -> Option<HistoryEntry> {
        let mut best: Option<HistoryEntry> = None;
        for e in self.history.iter().rev() {
            match best {
                Some(b) if e.time_ms.abs_diff(t) >= b.time_ms.abs_diff(t) => break,
                _ => best = Some(*e),
            }
        }
        best
    }

    /// A GNSS fix arrives: store `px_gps/py_gps`, then correct heading and position if the gate
    /// allows. Returns, when the fix corrected the position, the distance between the history
    /// entry closest to the fix time and the fix (minus the antenna offset) before the correction,
    /// m: what the firmware prints and plots as "Diff (cm)" with `pos_gnss_corr_info 1`
    /// (`pos.c`, `correct_pos_gps`).
    pub fn gnss_fix(&mut self, cfg: &FirmwareConfig, fix: GnssFix) -> Option<f32> {
        let (gx, gy) = self.minus_antenna_offset(cfg, fix.x, fix.y);
        self.px_gps = gx;
        self.py_gps = gy;
        let gate = cfg.gps_comp && (!cfg.gps_req_rtk || fix.rtk);
        if !gate {
            return None;
        }
        self.correct_heading(cfg, gx, gy, fix.measured_ms);
        let diff = self.correct_position(cfg, gx, gy, fix.measured_ms);
        self.prev_corr = Some((gx, gy, fix.measured_ms));
        self.driven_since_fix = 0.0;
        diff
    }

    fn minus_antenna_offset(&self, cfg: &FirmwareConfig, x: f32, y: f32) -> (f32, f32) {
        let a = -self.yaw.to_radians();
        let (s, c) = a.sin_cos();
        // 10.x quirk: the y offset enters with the wrong sign.
        let ant_y = if self.firmware.gnss_antenna_y_flipped {
            -cfg.gps_ant_y
        } else {
            cfg.gps_ant_y
        };
        let ox = cfg.gps_ant_x * c - ant_y * s;
        let oy = cfg.gps_ant_x * s + ant_y * c;
        (x - ox, y - oy)
    }

    fn correct_heading(&mut self, cfg: &FirmwareConfig, gx: f32, gy: f32, t_fix: u64) {
        let Some((px_prev, py_prev, t_prev)) = self.prev_corr else {
            return;
        };
        let Some(h) = self.history_at(t_fix.midpoint(t_prev)) else {
            return;
        };
        let track = -(gy - py_prev).atan2(gx - px_prev).to_degrees();
        let e = wrap180(track - h.yaw);
        let max_step = cfg.gps_corr_gain_yaw * self.driven_since_fix;
        let target = self.yaw_offset - e;
        self.yaw_offset = wrap180(crate::motor::step_towards(
            self.yaw_offset,
            target,
            max_step,
        ));
    }

    /// Steps the history entry closest to the fix time towards the fix and moves the position by
    /// as much; the entry's distance to the fix before the step, m.
    fn correct_position(
        &mut self,
        cfg: &FirmwareConfig,
        gx: f32,
        gy: f32,
        t_fix: u64,
    ) -> Option<f32> {
        let h = self.history_at(t_fix)?;
        let diff = (h.px - gx).hypot(h.py - gy);
        let g = cfg.gps_corr_gain_stat + cfg.gps_corr_gain_dyn * self.driven_since_fix;
        let hx = crate::motor::step_towards(h.px, gx, g);
        let hy = crate::motor::step_towards(h.py, gy, g);
        self.px += hx - h.px;
        self.py += hy - h.py;
        Some(diff)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> FirmwareConfig {
        FirmwareConfig::defaults(FirmwareVersion::V10_1)
    }

    #[test]
    fn any_angle_wraps_into_a_half_turn_either_way() {
        assert_eq!(wrap180(190.0), -170.0);
        assert_eq!(wrap180(-540.0), -180.0);
        // A blown-up angle (a bitflip in the exponent) ends instead of looping forever.
        for a in [2.6e36f32, -1.0e30, 1.0e7 + 0.5, f32::MAX] {
            let w = wrap180(a);
            assert!((-180.0..=180.0).contains(&w), "{a} -> {w}");
        }
        assert!(wrap180(f32::INFINITY).is_infinite());
        assert!(wrap180(f32::NAN).is_nan());
    }

    #[test]
    fn dead_reckoning_steps_along_the_imu_heading() {
        let c = cfg();
        let mut f = FusedPosition::new(FirmwareVersion::V10_1);
        f.odometry_tick(
            &c,
            OdometryInput {
                tacho: 0,
                rpm: 0.0,
                imu_yaw: 90.0,
                steering_angle: 0.0,
                imu_samples: 10,
                now_ms: 0,
            },
        );
        let step = f.odometry_tick(
            &c,
            OdometryInput {
                tacho: 100,
                rpm: 1835.45,
                imu_yaw: 90.0,
                steering_angle: 0.3,
                imu_samples: 10,
                now_ms: 10,
            },
        );
        assert!((step.distance - 0.544_826).abs() < 1e-5);
        assert!((step.speed - 1.0).abs() < 1e-4);
        // Yaw +90 faces south.
        let p = f.pose();
        assert!(p.x.abs() < 1e-5 && (p.y + 0.544_826).abs() < 1e-5, "{p:?}");
    }

    #[test]
    fn a_stationary_car_converges_at_a_quarter_metre_per_second_per_axis() {
        let c = cfg();
        let mut f = FusedPosition::new(FirmwareVersion::V10_1);
        for k in 0..100u64 {
            f.odometry_tick(
                &c,
                OdometryInput {
                    tacho: 0,
                    rpm: 0.0,
                    imu_yaw: 0.0,
                    steering_angle: 0.0,
                    imu_samples: 10,
                    now_ms: k * 10,
                },
            );
            if k % 20 == 19 {
                f.gnss_fix(
                    &c,
                    GnssFix {
                        x: 10.0,
                        y: -10.0,
                        measured_ms: k * 10,
                        rtk: true,
                    },
                );
            }
        }
        let p = f.pose();
        assert!(
            (p.x - 0.25).abs() < 1e-4 && (p.y + 0.25).abs() < 1e-4,
            "{p:?}"
        );
        assert_eq!(f.gps(), (10.0, -10.0));
    }

    #[test]
    fn non_rtk_fixes_do_not_correct_when_rtk_is_required() {
        let c = cfg();
        let mut f = FusedPosition::new(FirmwareVersion::V10_1);
        f.odometry_tick(
            &c,
            OdometryInput {
                tacho: 0,
                rpm: 0.0,
                imu_yaw: 0.0,
                steering_angle: 0.0,
                imu_samples: 10,
                now_ms: 0,
            },
        );
        f.gnss_fix(
            &c,
            GnssFix {
                x: 1.0,
                y: 1.0,
                measured_ms: 0,
                rtk: false,
            },
        );
        assert_eq!((f.pose().x, f.pose().y), (0.0, 0.0));
        assert_eq!(f.gps(), (1.0, 1.0));
    }

    #[test]
    fn latency_compensation_corrects_against_the_pose_at_fix_time() {
        let c = cfg();
        let mut f = FusedPosition::new(FirmwareVersion::V10_1);
        // Drive east at ~1 m/s for 0.5 s; a fix taken at t = 200 ms exactly where the car was.
        let mut tacho = 0;
        for k in 0..50u64 {
            f.odometry_tick(
                &c,
                OdometryInput {
                    tacho,
                    rpm: 1835.45,
                    imu_yaw: 0.0,
                    steering_angle: 0.0,
                    imu_samples: 10,
                    now_ms: k * 10,
                },
            );
            tacho += 2;
        }
        let at_200 = f.history_at(200).unwrap();
        let before = f.pose();
        let diff = f.gnss_fix(
            &c,
            GnssFix {
                x: at_200.px,
                y: at_200.py,
                measured_ms: 200,
                rtk: true,
            },
        );
        let after = f.pose();
        assert!((after.x - before.x).abs() < 1e-6 && (after.y - before.y).abs() < 1e-6);
        // The printed difference is against the pose at fix time, not the newest: 0 here, and
        // 0.3 m for a fix 0.3 m east of it.
        assert_eq!(diff, Some(0.0));
        let shifted = f.gnss_fix(
            &c,
            GnssFix {
                x: at_200.px + 0.3,
                y: at_200.py,
                measured_ms: 200,
                rtk: true,
            },
        );
        assert!((shifted.unwrap() - 0.3).abs() < 1e-5, "{shifted:?}");
    }

    #[test]
    fn heading_is_pulled_by_one_degree_per_metre_towards_the_gnss_track() {
        let c = cfg();
        let mut f = FusedPosition::new(FirmwareVersion::V10_1);
        f.odometry_tick(
            &c,
            OdometryInput {
                tacho: 0,
                rpm: 0.0,
                imu_yaw: 0.0,
                steering_angle: 0.0,
                imu_samples: 10,
                now_ms: 0,
            },
        );
        f.gnss_fix(
            &c,
            GnssFix {
                x: 0.0,
                y: 0.0,
                measured_ms: 0,
                rtk: true,
            },
        );
        let mut tacho = 0;
        for k in 1..=20u64 {
            tacho += 18; // ≈ 0.098 m per tick
            f.odometry_tick(
                &c,
                OdometryInput {
                    tacho,
                    rpm: 1835.45 * 10.0,
                    imu_yaw: 0.0,
                    steering_angle: 0.0,
                    imu_samples: 10,
                    now_ms: k * 10,
                },
            );
        }
        // The GNSS says the car went north-east (track −45°): the fused yaw moves towards it by at
        // most 1° per metre driven (~1.96 m).
        f.gnss_fix(
            &c,
            GnssFix {
                x: 1.39,
                y: 1.39,
                measured_ms: 200,
                rtk: true,
            },
        );
        f.odometry_tick(
            &c,
            OdometryInput {
                tacho,
                rpm: 0.0,
                imu_yaw: 0.0,
                steering_angle: 0.0,
                imu_samples: 10,
                now_ms: 210,
            },
        );
        let yaw = f.pose().yaw;
        assert!(yaw < -1.9 && yaw > -2.0, "yaw {yaw}");
    }
}
