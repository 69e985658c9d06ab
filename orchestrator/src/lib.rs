//! The drivecheck orchestrator: the command line and what it drives.
//!
//! It runs campaigns against a car ([`runner`]: preflight, reset with a return route, streamed
//! segments, faults, the [`oracle`], the [`safety`] monitor, the run directory of [`case`] files),
//! on top of a pure core ([`model`], [`streaming`]) and a [`recording`] format; it also validates
//! test areas, generates routes and reads scenarios. The `drivecheck` binary in `src/main.rs` only
//! parses the command line and calls [`commands::run`].
//!
//! Not here: geometry and generation (`trajgen`), scenario files (`scenarios`), the wire protocol
//! (`car-link`).

pub mod cli;
pub mod commands;
pub mod recording;
pub mod runner;
mod scenario_arg;
mod seed;
mod svg;
