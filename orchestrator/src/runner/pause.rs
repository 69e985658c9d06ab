//! A test seam for interruptions: `DRIVECHECK_PAUSE=in:K` pauses the campaign in the middle of
//! test K (its start route uploaded, the car driving), `before:K` before test K starts (a
//! campaign on the embedded simulator), until the campaign is interrupted (its cancellation
//! token: a signal) or 60 s pass. It says so on standard error first (`drivecheck: paused in
//! test K`), so that a test can send SIGINT or SIGTERM or `kill -9` at a known point of a
//! virtual-time campaign, which is over too fast for any timer (`orchestrator/tests/resume.rs`).
//! Unset, it costs one environment lookup per test.
//!
//! The pause blocks its thread: the test's own thread on the embedded simulator, a worker of the
//! multi-threaded runtime on a car behind a link; the signals are served on another.

use std::time::{Duration, Instant};

use tokio_util::sync::CancellationToken;

/// The environment variable.
pub const PAUSE_ENV: &str = "DRIVECHECK_PAUSE";

/// Where in a test the pause is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum At {
    /// Before the test starts.
    Before,
    /// In the middle of its drive.
    In,
}

/// Pauses here when `DRIVECHECK_PAUSE` names this place of test `test_index` (see the module
/// doc).
pub(crate) fn pause(at: At, test_index: usize, cancel: &CancellationToken) {
    let Ok(value) = std::env::var(PAUSE_ENV) else {
        return;
    };
    let wanted = match value.split_once(':') {
        Some(("before", k)) => (At::Before, k),
        Some(("in", k)) => (At::In, k),
        _ => return,
    };
    if wanted.0 != at || wanted.1.trim().parse::<usize>().ok() != Some(test_index) {
        return;
    }
    let place = match at {
        At::Before => "before",
        At::In => "in",
    };
    eprintln!("drivecheck: paused {place} test {test_index}");
    let until = Instant::now() + Duration::from_secs(60);
    while !cancel.is_cancelled() && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(5));
    }
}
