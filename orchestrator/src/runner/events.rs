//! What the runner tells the world while a campaign runs, and what it records of the
//! simulator: two small traits, so that the runner names neither a terminal UI nor the simulator.
//!
//! - [`CampaignObserver`]: progress (preflight notes, tests planned, each test's start and
//!   verdict). The command line shows it as a progress bar; tests and replays pass [`Silent`].
//! - [`SimulatorView`]: the embedded simulator's debug view (its hidden truth and debug events),
//!   which the journal records beside every state sample of a simulated run. The command line
//!   implements it for the simulator's handle.

use car_sim::{DebugEvent, Truth};

use campaign::oracle::Verdict;

/// Progress of a campaign, as the runner reports it.
pub trait CampaignObserver: Sync {
    /// Something the operator should know that is not an error (`preflight: switched off …`).
    fn note(&self, text: &str);
    /// What is true of every run and worth saying only when asked (`-v`): the embedded
    /// simulator's fresh cars start from the firmware's factory configuration, so preflight
    /// switches off the same fields on every run.
    fn detail(&self, text: &str) {
        let _ = text;
    }
    /// The campaign will run `tests` tests (after preflight).
    fn tests_planned(&self, tests: usize);
    /// Test `test_index` starts (its reset, then its drive).
    fn test_started(&self, test_index: usize);
    /// Test `test_index` starts on car `car` of a campaign on several cars.
    fn test_started_on(&self, test_index: usize, car: &str) {
        let _ = car;
        self.test_started(test_index);
    }
    /// Car `car` left a campaign on several cars for `reason`; the others go on.
    fn car_left(&self, car: &str, reason: &str) {
        self.note(&format!("car {car} left the campaign: {reason}"));
    }
    /// Test `test_index` ended with `verdict` (`None`: it did not run to one); its case file is
    /// written.
    fn test_finished(&self, test_index: usize, verdict: Option<Verdict>);
}

/// An observer that reports nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl CampaignObserver for Silent {
    fn note(&self, _text: &str) {}
    fn tests_planned(&self, _tests: usize) {}
    fn test_started(&self, _test_index: usize) {}
    fn test_finished(&self, _test_index: usize, _verdict: Option<Verdict>) {}
}

/// The embedded simulator's debug view, recorded beside every state sample of a simulated run.
pub trait SimulatorView: Sync {
    /// The simulator's hidden truth now.
    fn truth(&self) -> Truth;
    /// The debug events since the last call.
    fn take_events(&self) -> Vec<DebugEvent>;
}
