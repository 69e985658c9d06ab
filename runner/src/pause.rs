//! A test seam for interruptions: `DRIVECHECK_PAUSE=in:K` pauses the campaign in the middle of
//! test K (its start route uploaded, the car driving), `before:K` before test K starts (a
//! campaign on the embedded simulator), until the campaign is interrupted (its cancellation
//! token: a signal) or 60 s pass. It says so on standard error first (`drivecheck: paused in
//! test K`), so that a test can send SIGINT or SIGTERM or `kill -9` at a known point of a
//! virtual-time campaign, which is over too fast for any timer (`orchestrator/tests/drivecheck/realtime/resume.rs`).
//! Unset, it costs one environment lookup per test. Only a build with the `test-hooks` feature
//! has it (the crate's tests and the `drivecheck` package's, through its dev-dependency); in any
//! other build, the `drivecheck` a user installs among them, [`pause`] does nothing.
//!
//! `DRIVECHECK_PAUSE=PLACE:K` pauses a command that reads (`report:K` once test K's section is
//! drawn, `merge:K` once test K's case is merged, `score:K` as `explain --score` reads test K's
//! span, `counterfactual:K` and `twin:K` before the K-th
//! case is driven again) until a signal comes ([`note_signal`]) or 60 s pass
//! ([`pause_at`]), saying `drivecheck: paused in PLACE at K` first.
//!
//! The pause blocks its thread: the test's own thread on the embedded simulator, a worker of the
//! multi-threaded runtime on a car behind a link; the signals are served on another.

#[cfg(feature = "test-hooks")]
use std::time::{Duration, Instant};

use tokio_util::sync::CancellationToken;

/// The environment variable.
pub const PAUSE_ENV: &str = "DRIVECHECK_PAUSE";

/// Where in a test the pause is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum At {
    /// Before the test starts.
    Before,
    /// In the middle of its drive.
    In,
}

/// Without the `test-hooks` feature: nothing.
#[cfg(not(feature = "test-hooks"))]
pub fn pause(_at: At, _test_index: usize, _cancel: &CancellationToken) {}

/// Pauses here when `DRIVECHECK_PAUSE` names this place of test `test_index` (see the module
/// doc).
#[cfg(feature = "test-hooks")]
pub fn pause(at: At, test_index: usize, cancel: &CancellationToken) {
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

/// Whether a signal came ([`note_signal`]).
static SIGNALLED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// The command line says a signal came: a pause of [`pause_at`] ends.
pub fn note_signal() {
    SIGNALLED.store(true, std::sync::atomic::Ordering::SeqCst);
}

/// Without the `test-hooks` feature: nothing.
#[cfg(not(feature = "test-hooks"))]
pub fn pause_at(_place: &str, _k: usize) {}

/// Pauses here when `DRIVECHECK_PAUSE` is `PLACE:K` (see the module doc).
#[cfg(feature = "test-hooks")]
pub fn pause_at(place: &str, k: usize) {
    let Ok(value) = std::env::var(PAUSE_ENV) else {
        return;
    };
    if value.split_once(':') != Some((place, &k.to_string())) {
        return;
    }
    eprintln!("drivecheck: paused in {place} at {k}");
    let until = Instant::now() + Duration::from_secs(60);
    while !SIGNALLED.load(std::sync::atomic::Ordering::SeqCst) && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(5));
    }
}
