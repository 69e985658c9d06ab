//! The reference state of the model: what the car has been told so far in a test.
//!
//! It holds the route tail the next segment must extend, the faults in flight, and the firmware's
//! fault slots. The slots mirror the firmware exactly
//! (`docs/firmware.md#probes-and-slots`): 5 probes of 5 slots each, a slot is taken by every added
//! fault and never freed except by clearing all faults, which every test's reset does. The
//! preconditions keep generated tests inside those limits, so no fault is ever silently dropped by
//! a full probe.

use thiserror::Error;
use trajgen::{Area, Constraints, Point, RouteTail, check_route};

use car_link::firmware::{FAULT_PROBES, FAULTS_PER_PROBE};

use super::command::{Command, Fault, Probe, Segment};

/// How far past a segment's computed length a place may lie (rounding of the written place).
const PLACE_TOLERANCE_M: f64 = 1e-3;

/// Why a fault cannot be added.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum SlotError {
    /// All five slots of the probe hold a fault (expired faults keep theirs).
    #[error("all {FAULTS_PER_PROBE} fault slots of probe {0} are taken")]
    ProbeFull(Probe),
    /// Five other probes are in use.
    #[error("no free probe for {0}: {FAULT_PROBES} probes are in use")]
    NoFreeProbe(Probe),
}

/// The firmware's fault slots as the model tracks them: per probe id, how many slots are taken.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct FaultSlots {
    used: Vec<(Probe, usize)>,
}

impl FaultSlots {
    /// Empty slots, as after `fi_clear_faults`.
    pub fn new() -> Self {
        Self::default()
    }

    /// Slots taken on `probe`.
    pub fn used(&self, probe: Probe) -> usize {
        self.used
            .iter()
            .find(|(p, _)| *p == probe)
            .map_or(0, |(_, n)| *n)
    }

    /// Whether a fault on `probe` would find a free slot.
    pub fn check(&self, probe: Probe) -> Result<(), SlotError> {
        match self.used.iter().find(|(p, _)| *p == probe) {
            Some((_, n)) if *n >= FAULTS_PER_PROBE => Err(SlotError::ProbeFull(probe)),
            Some(_) => Ok(()),
            None if self.used.len() >= FAULT_PROBES => Err(SlotError::NoFreeProbe(probe)),
            None => Ok(()),
        }
    }

    /// Takes a slot on `probe`, as the firmware does when a fault is added.
    pub fn take(&mut self, probe: Probe) -> Result<(), SlotError> {
        self.check(probe)?;
        match self.used.iter_mut().find(|(p, _)| *p == probe) {
            Some((_, n)) => *n += 1,
            None => self.used.push((probe, 1)),
        }
        Ok(())
    }

    /// Frees every slot (`fi_clear_faults`).
    pub fn clear(&mut self) {
        self.used.clear();
    }
}

/// A fault the model has injected in this test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultInFlight {
    /// Index of its `AddFault` command in the test.
    pub command_index: usize,
    /// The fault.
    pub fault: Fault,
}

/// What the model knows of the car during a test.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceState {
    /// The end of the route planned so far: what the next segment must extend.
    pub tail: RouteTail,
    /// Faults injected so far in this test (slots are never freed during a test).
    pub faults: Vec<FaultInFlight>,
    /// The firmware's fault slots.
    pub slots: FaultSlots,
    /// Commands applied so far.
    pub commands: usize,
    /// `RunSegments` commands applied so far.
    pub segments: usize,
    /// Length of the last segment applied, metres (0 before the first).
    pub last_segment_m: f64,
}

impl ReferenceState {
    /// The state at the start of a test: the route ends in `tail`, no faults.
    pub fn new(tail: RouteTail) -> Self {
        Self {
            tail,
            faults: Vec::new(),
            slots: FaultSlots::new(),
            commands: 0,
            segments: 0,
            last_segment_m: 0.0,
        }
    }

    /// The state after `command` (which must satisfy the preconditions).
    pub fn apply(mut self, command: &Command) -> Self {
        match command {
            Command::RunSegments(segment) => {
                self.last_segment_m = segment.length_from(self.tail.end);
                self.tail = self.tail.advanced(&segment.points);
                self.segments += 1;
            }
            Command::AddFault(fault) => {
                // The precondition guarantees a free slot; a full probe leaves the slots as they are.
                let _ = self.slots.take(fault.probe);
                self.faults.push(FaultInFlight {
                    command_index: self.commands,
                    fault: *fault,
                });
            }
        }
        self.commands += 1;
        self
    }
}

/// What the preconditions check commands against: the area, the constraints, the anchors.
#[derive(Debug, Clone, PartialEq)]
pub struct Preconditions {
    /// The drivable region.
    pub area: Area,
    /// Segment lengths and turn limit.
    pub constraints: Constraints,
    /// Points a segment's ahead margin must have.
    pub ahead_margin: usize,
    /// The scenario's anchor ids.
    pub anchors: Vec<u8>,
}

impl Preconditions {
    /// Whether `command` may run in `state`.
    pub fn allow(&self, state: &ReferenceState, command: &Command) -> bool {
        match command {
            Command::RunSegments(segment) => self.segment_continues(&state.tail, segment),
            Command::AddFault(fault) => self.fault_fits(state, fault),
        }
    }

    /// A segment may run when it has its intended number of points at a positive speed and its
    /// points and full ahead margin form a drivable continuation of the tail.
    pub fn segment_continues(&self, tail: &RouteTail, segment: &Segment) -> bool {
        if segment.points.is_empty()
            || segment.speeds.len() != segment.points.len()
            || segment
                .intent
                .is_some_and(|intent| intent.points != segment.points.len())
        {
            return false;
        }
        if !segment.speeds.iter().all(|v| v.is_finite() && *v > 0.0) {
            return false;
        }
        if segment.margin.len() != self.ahead_margin {
            return false;
        }
        let route: Vec<Point> = std::iter::once(tail.end)
            .chain(segment.points.iter().copied())
            .chain(segment.margin.iter().copied())
            .collect();
        check_route(&self.area, &route, &self.constraints, Some(tail.heading)).is_ok()
    }

    /// A fault may be added once the test drives a generated segment (so every test has a
    /// segment for the oracle to judge, and no fault is spent on the start route), when its probe
    /// has a free slot, its anchor exists and its parameter is finite.
    pub fn fault_fits(&self, state: &ReferenceState, fault: &Fault) -> bool {
        if state.segments == 0 || !fault.param.is_finite() || fault.duration == 0 {
            return false;
        }
        if let Probe::UwbRange(anchor) = fault.probe
            && !self.anchors.iter().any(|&a| u16::from(a) == anchor)
        {
            return false;
        }
        // A generated fault is sent on the segment just planned, somewhere along it.
        if let Some(at) = fault.at
            && (at.segment_index + 1 != state.segments
                || !(0.0..=state.last_segment_m + PLACE_TOLERANCE_M).contains(&at.along_m))
        {
            return false;
        }
        state.slots.check(fault.probe).is_ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_probe_holds_five_faults_and_never_frees_them() {
        let mut slots = FaultSlots::new();
        for _ in 0..FAULTS_PER_PROBE {
            assert_eq!(slots.take(Probe::UwbYaw), Ok(()));
        }
        assert_eq!(
            slots.take(Probe::UwbYaw),
            Err(SlotError::ProbeFull(Probe::UwbYaw))
        );
        assert_eq!(slots.used(Probe::UwbYaw), 5);
        slots.clear();
        assert_eq!(slots.take(Probe::UwbYaw), Ok(()));
    }

    #[test]
    fn a_sixth_probe_finds_no_room() {
        let mut slots = FaultSlots::new();
        for anchor in 0..FAULT_PROBES as u16 {
            assert_eq!(slots.take(Probe::UwbRange(anchor)), Ok(()));
        }
        assert_eq!(
            slots.check(Probe::UwbYaw),
            Err(SlotError::NoFreeProbe(Probe::UwbYaw))
        );
        assert_eq!(slots.check(Probe::UwbRange(0)), Ok(()));
    }
}
