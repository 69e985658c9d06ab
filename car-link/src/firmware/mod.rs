//! The model of the reference firmware: every fact about the car that drivecheck relies on, in one
//! place. Its limits, rates and watchdog (the constants below), its versions and what each is like
//! ([`FirmwareVersion`], [`Generation`], [`FirmwareProfile`]), the laws its autopilot steers by
//! ([`steering`]) and its fault kinds ([`fault_kinds`], one row each in [`KINDS`]). `docs/firmware.md#where-the-code-keeps-these-facts` says where each is explained.
//!
//! The wire protocol (`crate::message`, `crate::version`, `crate::config`), the client, the
//! simulated car (`car-sim`), the campaign's fault placement and the runner's preflight and reset
//! take every version-dependent fact from a [`FirmwareProfile`]: no other code compares version
//! numbers. Adding a firmware generation is a [`Generation`] variant and its arm in
//! [`FirmwareVersion::profile`] (ARCHITECTURE.md, "Recipes").

use std::time::Duration;

use crate::fault::Probe;

pub mod fault_kinds;
mod profile;
pub mod steering;

pub use fault_kinds::{Defaults, KINDS, KindSpec, Param, Quantity};
pub use profile::{AnchorAdd, LookAheadLaw, RouteEnd, UwbEstimator, UwbReset, WatchdogBrake};
pub use profile::{FirmwareProfile, FirmwareVersion, Generation, UnknownVersion};

/// The communication watchdog: without a command that feeds it for this long, the car brakes and
/// stops its autopilot.
pub const WATCHDOG: Duration = Duration::from_millis(2000);

/// The longest a runner may go without telemetry before it stops the car itself: just under the
/// watchdog, so that drivecheck's own stop (and its record of why) comes before the car's.
pub const MAX_STALE_LIMIT: Duration = Duration::from_millis(1900);

/// Fault injection: the most probes that can hold faults at once (`Too many probes in use`).
pub const FAULT_PROBES: usize = 5;

/// Fault injection: the most faults one probe holds (`Too many faults on this probe`); slots are
/// freed only by `fi_clear_faults`.
pub const FAULTS_PER_PROBE: usize = 5;

/// The firmware's main loop tick.
pub const TICK: Duration = Duration::from_millis(10);

/// One slot of the UWB ranging round robin: one anchor is ranged per slot.
pub const RANGING_SLOT: Duration = Duration::from_millis(100);

/// The most UWB anchors the firmware keeps.
pub const MAX_ANCHORS: usize = 20;

/// The highest anchor id that can be ranged: the range request carries the id's low byte only, so
/// the replies of an anchor with a larger id never match it.
pub const MAX_RANGED_ANCHOR_ID: u16 = 255;

/// The UWB estimator's largest correction per range, metres: a compile-time constant of the
/// firmware (both generations), the method's "correction clamp" (`docs/firmware.md#uwb-positioning`).
pub const UWB_CORRECTION_CLAMP_M: f64 = 0.2;

/// The autopilot's top speed, km/h (8.33 m/s).
pub const MAX_SPEED_KMH: f64 = 30.0;

/// How often the fault-injection probes are called, which turns a fault's `start` and `duration`
/// (counted in probe calls) into time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProbeRates {
    /// One odometry tick ([`FirmwareProfile::odometry_tick`]): one call of `uwb_travel_dist` and
    /// `uwb_yaw`.
    pub odometry_tick: Duration,
    /// One ranging slot of the round robin (100 ms).
    pub ranging_slot: Duration,
    /// Anchors in range (the round robin's length; at least 1 is assumed).
    pub anchors_in_range: usize,
}

impl ProbeRates {
    /// The rates of firmware `version` with `anchors` anchors in range: its odometry tick
    /// ([`FirmwareProfile::odometry_tick`]) and one ranging slot per anchor.
    pub fn new(version: FirmwareVersion, anchors: usize) -> Self {
        Self {
            odometry_tick: version.profile().odometry_tick,
            ranging_slot: RANGING_SLOT,
            anchors_in_range: anchors,
        }
    }

    /// The time between two calls of `probe`: one odometry tick, a round of ranging for a range
    /// probe, a GET_STATE for `px` (counted here as one tick: it has no rate of its own).
    pub fn iteration(&self, probe: Probe) -> Duration {
        match probe {
            Probe::UwbRange(_) => self
                .ranging_slot
                .saturating_mul(u32::try_from(self.anchors_in_range.max(1)).unwrap_or(u32::MAX)),
            Probe::UwbTravelDist | Probe::UwbYaw | Probe::Px => self.odometry_tick,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stale_limit_comes_before_the_watchdog() {
        assert!(MAX_STALE_LIMIT < WATCHDOG);
    }

    #[test]
    fn a_range_probe_is_called_once_per_round_of_ranging() {
        let rates = ProbeRates::new(FirmwareVersion::V12_3, 2);
        assert_eq!(
            rates.iteration(Probe::UwbRange(50)),
            Duration::from_millis(200)
        );
        assert_eq!(rates.iteration(Probe::UwbYaw), Duration::from_millis(20));
        assert_eq!(
            ProbeRates::new(FirmwareVersion::V10_1, 0).iteration(Probe::UwbRange(1)),
            RANGING_SLOT
        );
    }
}
