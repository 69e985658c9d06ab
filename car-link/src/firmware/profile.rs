//! Firmware versions and what each is like (`docs/firmware.md#firmware-generations`,
//! `docs/protocol.md#versions`): the one place that compares version numbers.

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use thiserror::Error;

use super::{
    FAULT_PROBES, FAULTS_PER_PROBE, MAX_STALE_LIMIT, TICK, UWB_CORRECTION_CLAMP_M, WATCHDOG,
};

/// A firmware version as reported by GET_STATE (`fw_major`, `fw_minor`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct FirmwareVersion {
    /// `fw_major`: 10, 11 or 12.
    pub major: u8,
    /// `fw_minor`.
    pub minor: u8,
}

impl FirmwareVersion {
    /// 10.1, the firmware of the published UWB experiments.
    pub const V10_1: FirmwareVersion = FirmwareVersion::new(10, 1);
    /// 10.2, the first with `clamp_imu_yaw_stationary`.
    pub const V10_2: FirmwareVersion = FirmwareVersion::new(10, 2);
    /// 11.0, the transitional version.
    pub const V11_0: FirmwareVersion = FirmwareVersion::new(11, 0);
    /// 12.0, the first with 24-byte route points.
    pub const V12_0: FirmwareVersion = FirmwareVersion::new(12, 0);
    /// 12.1, the first with the new numbering of ids 76–89.
    pub const V12_1: FirmwareVersion = FirmwareVersion::new(12, 1);
    /// 12.2, the first with 508-character PRINTF texts.
    pub const V12_2: FirmwareVersion = FirmwareVersion::new(12, 2);
    /// 12.3, the latest.
    pub const V12_3: FirmwareVersion = FirmwareVersion::new(12, 3);
    /// The latest version: what a client assumes of a car it has not heard from yet.
    pub const LATEST: FirmwareVersion = FirmwareVersion::V12_3;
    /// The versions the simulated car can be: one of each generation the method tests.
    pub const SIMULATED: [FirmwareVersion; 2] = [FirmwareVersion::V10_1, FirmwareVersion::V12_3];

    /// The version `major.minor`.
    pub const fn new(major: u8, minor: u8) -> Self {
        FirmwareVersion { major, minor }
    }

    /// Bytes per route point on the wire ([`FirmwareProfile::route_point_size`]); cheaper than the
    /// whole profile, for the codec.
    pub fn route_point_size(self) -> usize {
        if self >= FirmwareVersion::V12_0 {
            24
        } else {
            16
        }
    }

    /// Whether ids 76–89 use the new numbering ([`FirmwareProfile::new_command_ids`]).
    pub fn new_command_ids(self) -> bool {
        self >= FirmwareVersion::V12_1
    }

    /// Whether AP_SET_ACTIVE carries `reset_state` ([`FirmwareProfile::set_active_has_reset`]).
    pub fn set_active_has_reset(self) -> bool {
        self >= FirmwareVersion::V12_3
    }

    /// The longest PRINTF text ([`FirmwareProfile::max_printf_len`]).
    pub fn max_printf_len(self) -> usize {
        if self >= FirmwareVersion::V12_2 {
            508
        } else {
            252
        }
    }

    /// The generation this version belongs to; a version older than 10 is taken as 10.x and one
    /// newer than 12 as 12.x (their profiles say they are not [`supported`](FirmwareProfile::supported)).
    pub fn generation(self) -> Generation {
        match self.major {
            ..=10 => Generation::V10,
            11 => Generation::V11,
            12.. => Generation::V12,
        }
    }

    /// What this version is like: every version-dependent fact.
    pub fn profile(self) -> FirmwareProfile {
        let generation = self.generation();
        let known = (10..=12).contains(&self.major);
        // Facts that follow the generation.
        let g = match generation {
            // The transitional version: the 10.x layouts and autopilot, the 12.x reset and swap
            // (below, by version); the method does not test it.
            Generation::V11 => GenerationFacts {
                supported: false,
                ..Generation::V10.facts()
            },
            other => other.facts(),
        };
        FirmwareProfile {
            version: self,
            generation,
            supported: known && g.supported,
            simulated: FirmwareVersion::SIMULATED.contains(&self),
            route_point_size: self.route_point_size(),
            new_command_ids: self.new_command_ids(),
            set_active_has_reset: self.set_active_has_reset(),
            max_printf_len: self.max_printf_len(),
            route_capacity: g.route_capacity,
            odometry_tick: g.odometry_tick,
            watchdog: WATCHDOG,
            max_stale_limit: MAX_STALE_LIMIT,
            fault_probes: FAULT_PROBES,
            faults_per_probe: FAULTS_PER_PROBE,
            uwb_correction_clamp_m: UWB_CORRECTION_CLAMP_M,
            look_ahead: g.look_ahead,
            default_base_radius_m: g.default_base_radius_m,
            default_radius_time_ahead_s: 0.8,
            default_steering_ramp_time_s: g.default_steering_ramp_time_s,
            default_clamp_imu_yaw_stationary: self >= FirmwareVersion::V10_2,
            car_1_steering_center: g.car_1_steering_center,
            route_end: g.route_end,
            drives_to_start: g.drives_to_start,
            time_mode_replace: g.time_mode_replace,
            scan_stops_before_last_point: g.scan_stops_before_last_point,
            watchdog_brake: g.watchdog_brake,
            uwb_estimator: g.uwb_estimator,
            uwb_reset: if self >= FirmwareVersion::V11_0 {
                UwbReset::PositionOnly
            } else {
                UwbReset::PositionAndHeading
            },
            swaps_uwb_position: self >= FirmwareVersion::V11_0,
            gnss_antenna_y_flipped: g.gnss_antenna_y_flipped,
            anchor_add: g.anchor_add,
            terminal_set_id: g.terminal_set_id,
            selects_position_source: g.selects_position_source,
        }
    }
}

impl Default for FirmwareVersion {
    /// 10.1, the firmware of the published experiments: what the simulated car is unless told
    /// otherwise.
    fn default() -> Self {
        FirmwareVersion::V10_1
    }
}

impl fmt::Display for FirmwareVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}", self.major, self.minor)
    }
}

/// A firmware version that is not `MAJOR.MINOR` (or a generation's `MAJOR` alone).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("firmware {0:?} is not a version: write MAJOR.MINOR, for example 10.1 or 12.3")]
pub struct UnknownVersion(pub String);

impl FromStr for FirmwareVersion {
    type Err = UnknownVersion;

    /// `MAJOR.MINOR`, or `MAJOR` alone for its generation's [reference
    /// version](Generation::reference) (`10` is 10.1, `12` is 12.3).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let text = s.trim();
        let bad = || UnknownVersion(text.to_string());
        match text.split_once('.') {
            Some((major, minor)) => Ok(FirmwareVersion::new(
                major.parse().map_err(|_| bad())?,
                minor.parse().map_err(|_| bad())?,
            )),
            None => {
                let major: u8 = text.parse().map_err(|_| bad())?;
                let generation = FirmwareVersion::new(major, 0).generation();
                if generation.reference().major == major {
                    Ok(generation.reference())
                } else {
                    Err(bad())
                }
            }
        }
    }
}

/// A generation of the firmware: versions whose cars behave alike (`docs/firmware.md#firmware-generations`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Generation {
    /// 10.x, 2018, the firmware of the published UWB experiments.
    V10,
    /// 11.x, transitional.
    V11,
    /// 12.x, the latest, 2020.
    V12,
}

impl Generation {
    /// Every generation, oldest first.
    pub const ALL: [Generation; 3] = [Generation::V10, Generation::V11, Generation::V12];

    /// The version drivecheck takes as the generation's representative (what the simulated car is
    /// of it).
    pub fn reference(self) -> FirmwareVersion {
        match self {
            Generation::V10 => FirmwareVersion::V10_1,
            Generation::V11 => FirmwareVersion::V11_0,
            Generation::V12 => FirmwareVersion::V12_3,
        }
    }

    fn facts(self) -> GenerationFacts {
        match self {
            Generation::V10 | Generation::V11 => GenerationFacts {
                supported: true,
                route_capacity: 500,
                odometry_tick: TICK,
                look_ahead: LookAheadLaw::SpeedScaled,
                default_base_radius_m: 1.2,
                default_steering_ramp_time_s: 0.6,
                car_1_steering_center: 0.53,
                route_end: RouteEnd::StaysActiveBraking,
                drives_to_start: false,
                time_mode_replace: false,
                scan_stops_before_last_point: false,
                watchdog_brake: WatchdogBrake::Always,
                uwb_estimator: UwbEstimator::CopiedYaw,
                gnss_antenna_y_flipped: true,
                anchor_add: AnchorAdd::Append,
                terminal_set_id: false,
                selects_position_source: false,
            },
            Generation::V12 => GenerationFacts {
                supported: true,
                route_capacity: 1000,
                odometry_tick: TICK * 2,
                look_ahead: LookAheadLaw::TimeAhead,
                default_base_radius_m: 0.8,
                default_steering_ramp_time_s: 0.0,
                car_1_steering_center: 0.5,
                route_end: RouteEnd::DeactivatesAndResets,
                drives_to_start: true,
                time_mode_replace: true,
                scan_stops_before_last_point: true,
                watchdog_brake: WatchdogBrake::AboveSpeed { mps: 2.0 / 3.6 },
                uwb_estimator: UwbEstimator::TrackedYaw,
                gnss_antenna_y_flipped: false,
                anchor_add: AnchorAdd::UpdateExisting,
                terminal_set_id: true,
                selects_position_source: true,
            },
        }
    }
}

impl fmt::Display for Generation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let major = self.reference().major;
        write!(f, "{major}.x")
    }
}

/// What a firmware version is like: everything that differs between versions, from the bytes on
/// the wire to how its estimator corrects a range. Built by [`FirmwareVersion::profile`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FirmwareProfile {
    /// The version.
    pub version: FirmwareVersion,
    /// Its generation.
    pub generation: Generation,
    /// Whether the method tests it: a generation it knows (10.x, 12.x); the preflight refuses others.
    pub supported: bool,
    /// Whether the simulated car can be it ([`FirmwareVersion::SIMULATED`]).
    pub simulated: bool,

    // The wire (`docs/protocol.md#versions`).
    /// Bytes per route point in AP_ADD_POINTS and AP_REPLACE_ROUTE: 24 from 12.0, 16 before.
    pub route_point_size: usize,
    /// Whether ids 76–89 use the new numbering (12.1 and later).
    pub new_command_ids: bool,
    /// Whether AP_SET_ACTIVE carries the second byte `reset_state` (12.3 and later).
    pub set_active_has_reset: bool,
    /// The longest PRINTF text the firmware sends: 252 characters up to 12.1, 508 from 12.2.
    pub max_printf_len: usize,

    // Rates and limits.
    /// Points in the car's route ring (`docs/firmware.md#route-ring-and-points-left`): 1000 from
    /// 12.0, 500 before. Writing past it overwrites points not yet driven.
    pub route_capacity: usize,
    /// One odometry tick (a call of `uwb_travel_dist` and `uwb_yaw`): every 10 ms tick on the 10.x
    /// board, every second on the 12.x board (`docs/firmware.md#main-loop-and-rates`).
    pub odometry_tick: Duration,
    /// The communication watchdog ([`WATCHDOG`]).
    pub watchdog: Duration,
    /// The longest a runner may go without telemetry ([`MAX_STALE_LIMIT`]).
    pub max_stale_limit: Duration,
    /// Probes that can hold faults at once ([`FAULT_PROBES`]).
    pub fault_probes: usize,
    /// Faults one probe holds ([`FAULTS_PER_PROBE`]).
    pub faults_per_probe: usize,
    /// The UWB estimator's largest correction per range ([`UWB_CORRECTION_CLAMP_M`]).
    pub uwb_correction_clamp_m: f64,

    // The autopilot.
    /// How the look-ahead radius grows with the speed.
    pub look_ahead: LookAheadLaw,
    /// The factory `ap_base_rad`, metres.
    pub default_base_radius_m: f64,
    /// The factory `ap_rad_time_ahead`, seconds.
    pub default_radius_time_ahead_s: f64,
    /// The factory `car.steering_ramp_time`, seconds.
    pub default_steering_ramp_time_s: f64,
    /// The factory `car.clamp_imu_yaw_stationary` (the field exists from 10.2; off before).
    pub default_clamp_imu_yaw_stationary: bool,
    /// The factory `car.steering_center` of car id 1 (every other car: 0.5).
    pub car_1_steering_center: f64,
    /// What the autopilot does at the end of a route that does not repeat (and, for a 10.x car,
    /// with fewer than two points).
    pub route_end: RouteEnd,
    /// Whether an activated autopilot first drives to the route's start when it is farther than
    /// 1.5 look-ahead radii.
    pub drives_to_start: bool,
    /// Whether AP_REPLACE_ROUTE re-times the route in the time modes.
    pub time_mode_replace: bool,
    /// Whether the goal search stops one stretch before the route's last point.
    pub scan_stops_before_last_point: bool,
    /// When the expired watchdog brakes.
    pub watchdog_brake: WatchdogBrake,

    // Positioning.
    /// How the UWB estimator keeps its heading and corrects a range.
    pub uwb_estimator: UwbEstimator,
    /// What `pos_uwb_reset_pos` resets.
    pub uwb_reset: UwbReset,
    /// Whether GET_STATE swaps the fused and UWB positions when `use_uwb_pos` is set (11.0 and later).
    pub swaps_uwb_position: bool,
    /// Whether the GNSS antenna's y offset enters the fused position with the wrong sign (a 10.x quirk).
    pub gnss_antenna_y_flipped: bool,
    /// What ADD_UWB_ANCHOR does with an id the car already has.
    pub anchor_add: AnchorAdd,
    /// Whether the terminal knows `set_id` and `set_id_quiet`.
    pub terminal_set_id: bool,
    /// Whether the autopilot steers on the UWB pose when `use_uwb_pos` is set or a route point's
    /// attributes ask for it (12.x); else it always steers on the fused pose.
    pub selects_position_source: bool,
}

impl FirmwareProfile {
    /// The look-ahead radius at `speed` m/s with the factory settings, metres
    /// ([`steering::look_ahead_radius`](super::steering::look_ahead_radius)).
    pub fn look_ahead_radius_m(&self, speed: f64) -> f64 {
        super::steering::look_ahead_radius(
            self.look_ahead,
            self.default_base_radius_m,
            self.default_radius_time_ahead_s,
            speed,
        )
    }
}

/// The facts a profile takes from its generation.
#[derive(Debug, Clone, Copy)]
struct GenerationFacts {
    supported: bool,
    route_capacity: usize,
    odometry_tick: Duration,
    look_ahead: LookAheadLaw,
    default_base_radius_m: f64,
    default_steering_ramp_time_s: f64,
    car_1_steering_center: f64,
    route_end: RouteEnd,
    drives_to_start: bool,
    time_mode_replace: bool,
    scan_stops_before_last_point: bool,
    watchdog_brake: WatchdogBrake,
    uwb_estimator: UwbEstimator,
    gnss_antenna_y_flipped: bool,
    anchor_add: AnchorAdd,
    terminal_set_id: bool,
    selects_position_source: bool,
}

/// How the autopilot's look-ahead radius grows with the speed
/// (`docs/firmware.md#control-cycle`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LookAheadLaw {
    /// 10.x: `ap_base_rad · (1 + 0.05·|v|)²`.
    SpeedScaled,
    /// 12.x: `max(ap_rad_time_ahead · |v|, ap_base_rad)`.
    TimeAhead,
}

/// What the autopilot does at the end of a route that does not repeat.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RouteEnd {
    /// 10.x: stays active and brakes (10 A) on every cycle; a route of fewer than two points
    /// brakes the same way.
    StaysActiveBraking,
    /// 12.x: brakes once, deactivates and resets its progress; a route of fewer than two points
    /// does nothing.
    DeactivatesAndResets,
}

/// When the expired watchdog brakes (`docs/firmware.md#watchdog-and-braking`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WatchdogBrake {
    /// On every tick while expired, even standing (10.x).
    Always,
    /// Only while the car is faster than this, m/s (12.x: 2 km/h).
    AboveSpeed {
        /// The speed, m/s.
        mps: f32,
    },
}

/// How the UWB estimator keeps its heading and corrects a range
/// (`docs/firmware.md#uwb-estimator-10x`, `#uwb-estimator-12x`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UwbEstimator {
    /// 10.x: dead reckons with the fused yaw it copies; each range moves the estimate at most
    /// 0.2 m, behind a one-sided gate.
    CopiedYaw,
    /// 12.x: integrates the raw IMU yaw and estimates its offset from the ranges; a correction
    /// beyond `uwb_max_corr` jumps to 0.2 m; no gate.
    TrackedYaw,
}

/// What `pos_uwb_reset_pos` resets (`docs/firmware.md#resetting-the-estimate`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UwbReset {
    /// The fused position and heading (10.x).
    PositionAndHeading,
    /// The position only (11.0 and later): SET_POS sets the heading.
    PositionOnly,
}

/// What ADD_UWB_ANCHOR does with an id the car already has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnchorAdd {
    /// 10.x: appends a duplicate.
    Append,
    /// 12.x: updates the existing anchor.
    UpdateExisting,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_follow_the_version() {
        assert_eq!(FirmwareVersion::V11_0.profile().route_point_size, 16);
        assert_eq!(FirmwareVersion::V12_0.profile().route_point_size, 24);
        assert!(!FirmwareVersion::V12_2.profile().set_active_has_reset);
        assert!(FirmwareVersion::V12_3.profile().set_active_has_reset);
        assert_eq!(FirmwareVersion::V12_1.profile().max_printf_len, 252);
        assert_eq!(FirmwareVersion::V12_2.profile().max_printf_len, 508);
        assert_eq!(FirmwareVersion::V10_1.profile().route_capacity, 500);
        assert_eq!(FirmwareVersion::V12_0.profile().route_capacity, 1000);
    }

    #[test]
    fn the_method_tests_10x_and_12x_and_the_simulator_is_10_1_or_12_3() {
        let supported = |v: FirmwareVersion| v.profile().supported;
        assert!(supported(FirmwareVersion::V10_1));
        assert!(supported(FirmwareVersion::new(12, 7)));
        assert!(!supported(FirmwareVersion::V11_0));
        assert!(!supported(FirmwareVersion::new(9, 4)));
        assert!(!supported(FirmwareVersion::new(13, 0)));
        assert!(FirmwareVersion::V12_3.profile().simulated);
        assert!(!FirmwareVersion::V12_2.profile().simulated);
    }

    #[test]
    fn the_transitional_version_resets_and_swaps_like_12x_and_drives_like_10x() {
        let p = FirmwareVersion::V11_0.profile();
        assert_eq!(p.uwb_reset, UwbReset::PositionOnly);
        assert!(p.swaps_uwb_position);
        assert_eq!(p.look_ahead, LookAheadLaw::SpeedScaled);
        assert_eq!(p.odometry_tick, TICK);
        assert_eq!(
            FirmwareVersion::V10_1.profile().uwb_reset,
            UwbReset::PositionAndHeading
        );
    }

    #[test]
    fn the_defaults_round_to_the_firmware_s_single_precision_alike() {
        // The simulated car and the configuration record take these in `f32`: rounding the f64
        // once more gives the f32 literal the firmware has.
        for (v10, v12, p) in [
            (1.2f32, 0.8f32, 0),
            (0.6, 0.0, 1),
            (0.53, 0.5, 2),
            (0.8, 0.8, 3),
        ] {
            let get = |v: FirmwareVersion| {
                let p10 = v.profile();
                [
                    p10.default_base_radius_m,
                    p10.default_steering_ramp_time_s,
                    p10.car_1_steering_center,
                    p10.default_radius_time_ahead_s,
                ][p] as f32
            };
            assert_eq!(get(FirmwareVersion::V10_1), v10);
            assert_eq!(get(FirmwareVersion::V12_3), v12);
        }
    }

    #[test]
    fn versions_parse_whole_or_by_generation() {
        assert_eq!("10.1".parse(), Ok(FirmwareVersion::V10_1));
        assert_eq!(" 12.3 ".parse(), Ok(FirmwareVersion::V12_3));
        assert_eq!("12".parse(), Ok(FirmwareVersion::V12_3));
        assert_eq!("10".parse(), Ok(FirmwareVersion::V10_1));
        assert_eq!("11.0".parse(), Ok(FirmwareVersion::V11_0));
        assert!("13".parse::<FirmwareVersion>().is_err());
        assert!("12.x".parse::<FirmwareVersion>().is_err());
        assert!("".parse::<FirmwareVersion>().is_err());
        assert_eq!(FirmwareVersion::default().to_string(), "10.1");
        assert_eq!(Generation::V12.to_string(), "12.x");
    }
}
