//! The `drivecheck` binary as a user runs it: every command, its output, files and exit status
//! (one integration-test binary: each module was a test binary of its own; `common` is what they
//! share). Snapshots of what a user reads are in `snapshots/` (`user_output`).

mod calibrate;
mod car_profile;
mod cases_from;
mod cli;
mod common;
mod compare_command;
mod estimator_differential;
mod exit_status;
mod explain;
mod fault_places;
mod fault_values;
mod firmware_in_the_loop;
mod json_everywhere;
mod junit;
mod logging;
mod old_recordings;
mod progress;
mod quiet_everywhere;
mod replay_command;
mod replay_reproduces;
mod report_command;
mod resume_checks;
mod run_command;
mod scenario_fuzz;
mod shrink_command;
mod sweep_command;
mod user_output;
mod vehicle_seam;

/// The real-time tests: campaigns against the wall clock (signals, several cars over TCP, the
/// live view, interruptions, the scaling runs, the Slurm cluster). They are a group of their
/// own, `realtime::`, so that CI runs them apart from the CPU-bound tests (`.ci/run`).
mod realtime {
    mod cars;
    mod live;
    mod resume;
    mod scaling;
    mod signals;
    mod slurm;
}
