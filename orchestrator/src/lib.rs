//! The drivecheck orchestrator: command-line front end, campaigns, streaming, oracle, recording.
