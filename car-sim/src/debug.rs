//! The debug view: what an orchestrator cannot see (true pose, each range's fate, fault
//! activations), for tests and recordings.

use crate::autopilot::FwPose;
use crate::uwb::RangeResult;
use crate::world::RadioPath;

/// The car's true state and the estimates, at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// Simulation time since boot, ms.
    pub time_ms: u64,
    /// True east of the reference point (rear axle centre), m.
    pub x: f64,
    /// True north, m.
    pub y: f64,
    /// True heading, radians counter-clockwise from east.
    pub heading: f64,
    /// True speed, m/s (signed).
    pub speed: f64,
    /// True steering angle, rad (positive left).
    pub steering_angle: f64,
    /// The fused (RTK) estimate as the firmware holds it.
    pub fused: FwPose,
    /// The UWB estimate as the firmware holds it.
    pub uwb: FwPose,
}

/// Something that happened inside the simulated car.
#[derive(Debug, Clone, PartialEq)]
pub enum DebugEvent {
    /// A UWB range request and its fate.
    Range {
        /// When the request was made, ms.
        at_ms: u64,
        /// The address (anchor id low byte).
        anchor: u8,
        /// The radio path (line of sight, reflected, blocked), when an anchor answers.
        path: Option<RadioPath>,
        /// The true direct slant range, m.
        true_range: Option<f64>,
        /// What the module returned.
        result: RangeResult,
    },
    /// A range reply reached the estimator.
    RangeFused {
        /// When the reply was processed, ms.
        at_ms: u64,
        /// The address.
        anchor: u8,
        /// The range after the `uwb_range_<id>` probe, m.
        range: f32,
        /// Whether the estimate moved (10.x gate, unknown anchor id).
        moved: bool,
    },
    /// One or more faults applied at a probe.
    Fault {
        /// When, ms.
        at_ms: u64,
        /// The probe id.
        probe: String,
        /// Bit mask of the slots that applied.
        slots: u8,
        /// The probe's iteration.
        iteration: i32,
        /// The value before.
        before: f32,
        /// The value after.
        after: f32,
    },
    /// The communication watchdog expired (the first tick of an expiry).
    WatchdogExpired {
        /// When, ms.
        at_ms: u64,
    },
    /// The firmware's anchor walk would hang here (`docs/firmware.md#ranging-schedule`; fixed: the
    /// round is skipped).
    AnchorWalkWouldHang {
        /// When, ms.
        at_ms: u64,
    },
    /// The autopilot window held a zero-length segment (guarded:
    /// `docs/firmware.md#uploading-points`).
    ZeroLengthSegment {
        /// When, ms.
        at_ms: u64,
    },
    /// The route ring overflowed (`docs/firmware.md#route-ring-and-points-left`: old points are
    /// overwritten).
    RouteRingOverflow {
        /// When, ms.
        at_ms: u64,
    },
    /// A route packet repeated the previous packet's first point and was dropped
    /// (`docs/firmware.md#uploading-points`).
    DuplicatePacketDropped {
        /// When, ms.
        at_ms: u64,
    },
}
