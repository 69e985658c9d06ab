//! The drivecheck orchestrator: the command line and what it drives.
//!
//! Today it validates test areas, generates routes and reads scenarios; campaigns, streaming,
//! faults, the oracle and recording arrive with the campaign runner. The `drivecheck` binary in
//! `src/main.rs` only parses the command line and calls [`commands::run`].
//!
//! Not here: geometry and generation (`trajgen`), scenario files (`scenarios`), the wire protocol
//! (`car-link`).

pub mod case;
pub mod cli;
pub mod commands;
pub mod model;
pub mod oracle;
pub mod recording;
pub mod safety;
mod scenario_arg;
mod seed;
pub mod streaming;
mod svg;
