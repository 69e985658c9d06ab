//! The drivecheck orchestrator: the command line and what it drives.
//!
//! It runs campaigns against a car ([`runner`]: preflight, reset with a return route, the test
//! drive's loop, the run directory of case files), driven through the seam [`vehicle::Vehicle`],
//! and writes a [`recording`]; it also validates test areas, generates routes and reads
//! scenarios. The `drivecheck` binary in `src/main.rs` only
//! parses the command line and calls [`commands::run`].
//!
//! Not here: what a campaign decides (the pure core [`campaign`]: the test model and planner, the
//! oracle, the safety monitor, the streaming rule, the drive's state machine, the case format),
//! geometry and generation (`trajgen`), scenario files (`scenarios`), the wire protocol
//! (`car-link`).

pub mod atomic;
pub mod cli;
pub mod commands;
pub mod exit;
pub mod junit;
pub mod output;
pub mod profile_arg;
pub mod recording;
pub mod report;
pub mod runner;
mod scenario_arg;
mod seed;
mod svg;
pub mod vehicle;
