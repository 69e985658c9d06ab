//! The `drivecheck` command line: the shell over the engine's library crates.
//!
//! [`process::main`] parses the command line ([`cli`], clap's derive) and hands each subcommand
//! to its module in [`commands`], which reads files, resolves the settings once ([`settings`]) and
//! drives the engine:
//! the campaign runner, the vehicle seam and the run directory (`runner`), the recording
//! (`recording`), the report pages and explanations (`report`). The `drivecheck` binary in
//! `src/main.rs` calls [`process::main`] and nothing else.
//!
//! Not here: what a campaign decides (the pure core `campaign`: the test model and planner, the
//! oracle, the safety monitor, the streaming rule, the drive's state machine, the case format),
//! geometry and generation (`trajgen`), scenario files (`scenarios`), the wire protocol
//! (`car-link`), the development tools (`drivecheck-dev`, `devtools/`).

pub mod cli;
pub mod commands;
pub mod exit;
pub mod output;
pub mod process;
pub mod profile_arg;
pub mod scenario_arg;
pub mod seed;
pub mod settings;
