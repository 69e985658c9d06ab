//! The campaign core of drivecheck: what a campaign decides, with no I/O, no clock and no async
//! runtime. Time comes in as a `Duration` since the test began; the car's answers come in as
//! events. The orchestrator around it talks to the car, writes files and shows progress.
//!
//! - [`model`]: the abstract model of the car on `proptest` and the deterministic test planner
//!   (scenario, campaign seed, test index → a concrete test).
//! - [`oracle`]: |UWB − RTK| per sample, per segment, and the verdicts.
//! - [`safety`]: the runtime safety monitor (fence, cutouts, cross-track, stale telemetry).
//! - [`streaming`]: when to append the next segment so the car never reaches its route's end.
//! - [`drive`]: the test drive as a state machine fed with events (samples, answers, ticks) and
//!   returning actions (segments and faults to send, stops, brake): streaming, oracle bookkeeping,
//!   safety decisions and the safe stop.
//! - [`files`]: every JSON file drivecheck writes (case files, `campaign.json`, `replay.json`,
//!   `shrink.json`, `sweep.json`): their header, schema versions, record types and checks.
//! - [`replay`]: replay planning (the test a recorded case is driven as) and the comparison of a
//!   replay's runs.
//! - [`compare`]: two runs of the same tests compared (`drivecheck compare`): pairing, McNemar's
//!   exact test, the median change with a cluster bootstrap over tests, the breakdowns.
//! - [`seed`]: the one random number generator of every run.
//! - [`shard`]: the deterministic partition of a campaign's tests into shards.
//!
//! Not here: the wire protocol and the client (`car-link`; only its protocol layer and firmware
//! facts are used here), the run directory, the recording and the command line (`orchestrator`).

pub mod calibrate;
pub mod compare;
pub mod coverage;
pub mod drive;
pub mod explain;
pub mod files;
pub mod model;
pub mod oracle;
pub mod replay;
pub mod safety;
pub mod seed;
pub mod shard;
pub mod shrink;
pub mod streaming;
pub mod sweep;
pub mod twin;

/// The old path of [`files`], kept for the code that still names it.
pub use files as case;
