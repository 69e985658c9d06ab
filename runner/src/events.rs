//! What the runner tells the world while a campaign runs: [`CampaignObserver`], progress
//! (preflight notes, tests planned, each test's start and verdict), so that the runner names no
//! terminal UI. The command line shows it as a progress bar; tests and replays pass [`Silent`].
//! What the runner records of the simulator, its debug view, is the seam's
//! (`crate::vehicle::SimulatorView`).

use campaign::oracle::Verdict;

/// Progress of a campaign, as the runner reports it.
pub trait CampaignObserver: Sync {
    /// Something the operator should know that is not an error (`preflight: switched off …`).
    fn note(&self, text: &str);
    /// Something the operator must know even when told to be quiet, such as a car left with
    /// fault injection enabled (`fault injection could not be disabled on the car: …`). By
    /// default a note.
    fn warning(&self, text: &str) {
        self.note(text);
    }
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
