//! When an injected fault applies, in time: probe iterations turned into durations.
//!
//! A fault's `start` and `duration` count calls of its probe
//! (`docs/firmware.md#when-a-fault-applies`, `docs/firmware.md#probe-rates`): it applies on calls
//! `start + 1 … start + duration` after it was added. One call of `uwb_travel_dist` or `uwb_yaw` is
//! one odometry tick (10 ms in firmware 10.x, about 20 ms in 12.x); one call of `uwb_range_<id>` is
//! one range measurement of that anchor, every `N × 100 ms` with `N` anchors in range. The car does
//! not report its probe counters, so these windows are estimates: good enough to say which faults
//! were probably applying during a segment, not to prove it.

use std::time::Duration;

pub use car_link::firmware::ProbeRates;

use super::command::Fault;

/// The estimated time a fault applies: from `from` to `to`, on the clock `added_at` was given on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FaultWindow {
    /// When it starts applying.
    pub from: Duration,
    /// When it stops.
    pub to: Duration,
}

impl FaultWindow {
    /// The window of `fault` added at `added_at`.
    pub fn of(fault: &Fault, added_at: Duration, rates: &ProbeRates) -> Self {
        let iteration = rates.iteration(fault.probe);
        let from = added_at.saturating_add(iteration.saturating_mul(fault.start));
        let to = from.saturating_add(iteration.saturating_mul(fault.duration));
        Self { from, to }
    }

    /// Whether it overlaps the interval `from..=to` (a segment's drive).
    pub fn overlaps(&self, from: Duration, to: Duration) -> bool {
        self.from <= to && from <= self.to
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::FaultKind;
    use crate::model::Probe;

    fn fault(probe: Probe, start: u32, duration: u32) -> Fault {
        Fault {
            probe,
            kind: FaultKind::Offset,
            param: 1.0,
            start,
            duration,
            at: None,
        }
    }

    #[test]
    fn an_anchor_fault_counts_ranges_of_the_round_robin() {
        // Two anchors at 10.x rates: one range of an anchor every 200 ms.
        let rates = ProbeRates::new(car_link::FirmwareVersion::V10_1, 2);
        let window = FaultWindow::of(
            &fault(Probe::UwbRange(50), 100, 8),
            Duration::from_secs(3),
            &rates,
        );
        assert_eq!(window.from, Duration::from_secs(23));
        assert_eq!(window.to, Duration::from_millis(24_600));
    }

    #[test]
    fn an_odometry_fault_counts_ticks() {
        let rates = ProbeRates::new(car_link::FirmwareVersion::V12_3, 2);
        let window = FaultWindow::of(&fault(Probe::UwbYaw, 50, 10), Duration::ZERO, &rates);
        assert_eq!(window.from, Duration::from_secs(1));
        assert_eq!(window.to, Duration::from_millis(1200));
        assert!(window.overlaps(Duration::from_millis(1100), Duration::from_secs(5)));
        assert!(window.overlaps(Duration::ZERO, Duration::from_secs(1)));
        assert!(!window.overlaps(Duration::from_millis(1201), Duration::from_secs(5)));
    }
}
