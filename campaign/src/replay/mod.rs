//! Replay (`drivecheck replay`, `docs/method.md#replay-and-shrinking`): a recorded case driven
//! again.
//!
//! - planning ([`Case::replay_plan`](crate::files::Case::replay_plan)): the test a case is driven
//!   as: its recorded commands (without the fault commands when asked) from the end of the
//!   scenario's start route, after the case's values and geometry are checked, with an ahead
//!   margin generated for every segment written without one;
//! - the comparison of the runs ([`Comparison`]): per segment each run's maximum deviation,
//!   their mean and each run's difference from it, whether the verdict was the same every time,
//!   and whether a failure disappeared without the faults (`replay.json`).
//!
//! Pure: built from case files and the scenario, no clock, no I/O (the command reads the case and
//! writes `replay.json`).

mod compare;
mod plan;

pub use crate::files::{
    Comparison, Drove, REPLAY_FORMAT, ReplayRun, Reproduction, SegmentComparison, SegmentDifference,
};
pub use compare::REPLAY_FILE;
