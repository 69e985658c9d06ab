//! The end of a session on a car: whatever ended it (the campaign's end, an error, a refusal, an
//! interrupt, the dry run's end or its error), the car is left with its faults cleared
//! (`fi_clear_faults`) and fault injection disabled (`fi_set_enabled 0`), so that no fault stays
//! armed on a car that is driven next by anyone else. Best effort within [`DISARM_LIMIT`]: a car
//! that cannot be reached (its link lost) is left as it is, and the caller says so
//! ([`CampaignObserver::warning`]). Not recorded: the session's recording ends with its last test.
//!
//! The embedded simulator's fresh cars (`fresh`) end with their test and are dropped; the cars a
//! session is opened on (`run_campaign`, `lab`, `dry_run`) end here. After the operator's second
//! signal the emergency stop brakes and disarms the cars a command registered (`emergency`).

use std::time::Duration;

use car_link::CarError;
use thiserror::Error;

use super::{CampaignObserver, retried};
use crate::vehicle::Vehicle;

/// The longest a session's end waits for the car to clear its faults and disable fault
/// injection, both commands with their retries.
pub const DISARM_LIMIT: Duration = Duration::from_secs(3);

/// A car whose fault injection could not be disabled, or whose faults could not be cleared.
#[derive(Debug, Error, PartialEq, Eq)]
#[error("fault injection could not be disabled on the car: {0}")]
pub struct NotDisarmed(pub String);

/// Clears `car`'s faults and disables its fault injection, within `limit` (see the module doc).
/// Every step is tried even when one before it failed, a lost link excepted.
///
/// Timeout: `limit`. Cancellation: safe; the car may be left armed.
pub async fn disarm<V: Vehicle>(car: &V, limit: Duration) -> Result<(), NotDisarmed> {
    let steps = async {
        let mut failed: Vec<String> = Vec::new();
        let cleared = retried(|| car.clear_faults()).await;
        if let Err(error) = &cleared {
            failed.push(format!("clearing the faults: {error}"));
        }
        if !matches!(cleared, Err(CarError::LinkLost))
            && let Err(error) = retried(|| car.set_fi_enabled(false)).await
        {
            failed.push(format!("disabling it: {error}"));
        }
        failed
    };
    match tokio::time::timeout(limit, steps).await {
        Ok(failed) if failed.is_empty() => Ok(()),
        Ok(failed) => Err(NotDisarmed(failed.join("; "))),
        Err(_) => Err(NotDisarmed(format!(
            "the car did not answer within {}",
            humantime_secs(limit)
        ))),
    }
}

/// Ends the session on `car` ([`disarm`] within [`DISARM_LIMIT`]) and warns through `observer`
/// when it cannot; `car_name` names the car of a campaign on several.
pub async fn end_session<V: Vehicle>(
    car: &V,
    car_name: Option<&str>,
    observer: &dyn CampaignObserver,
) {
    if let Err(error) = disarm(car, DISARM_LIMIT).await {
        tracing::warn!(%error, "session ended with the car armed");
        observer.warning(&match car_name {
            Some(name) => format!("car {name}: {error}"),
            None => error.to_string(),
        });
    }
}

fn humantime_secs(limit: Duration) -> String {
    format!("{} s", limit.as_secs_f64())
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use super::*;
    use crate::{RunConfig, RunError, run_campaign};
    use campaign::model::Campaign;
    use campaign::oracle::Verdict;
    use car_sim::{FaultInjectionView, SimConfig};
    use scenarios::Scenario;
    use tokio_util::sync::CancellationToken;

    /// An observer that keeps the warnings.
    #[derive(Default)]
    struct Warnings(Mutex<Vec<String>>);

    impl CampaignObserver for Warnings {
        fn note(&self, _text: &str) {}
        fn warning(&self, text: &str) {
            self.0.lock().unwrap().push(text.to_owned());
        }
        fn tests_planned(&self, _tests: usize) {}
        fn test_started(&self, _test_index: usize) {}
        fn test_finished(&self, _test_index: usize, _verdict: Option<Verdict>) {}
    }

    impl Warnings {
        fn taken(&self) -> Vec<String> {
            std::mem::take(&mut self.0.lock().unwrap())
        }
    }

    fn scenario() -> Scenario {
        scenarios::bundled::load("parking-lot-2anchors")
            .unwrap()
            .scenario
    }

    const DISARMED: FaultInjectionView = FaultInjectionView {
        enabled: false,
        faults_armed: 0,
    };

    /// The simulator's fault injection once it has run a few ticks after `sim` was last told
    /// anything (its handle's view is published on the simulator's ticks).
    async fn settled(sim: &car_sim::SimHandle) -> FaultInjectionView {
        tokio::time::sleep(Duration::from_millis(200)).await;
        sim.fault_injection()
    }

    fn config(dir: &std::path::Path, tests: usize) -> RunConfig {
        RunConfig::new(
            Campaign {
                seed: 7,
                tests,
                no_faults: false,
            },
            dir.join("run"),
            "sim",
        )
    }

    #[tokio::test(start_paused = true)]
    async fn a_campaign_that_ends_leaves_the_car_disarmed() {
        let scenario = scenario();
        let dir = tempfile::tempdir().unwrap();
        let (car, sim) = crate::vehicle::connect_sim(&SimConfig::from_scenario(&scenario))
            .await
            .unwrap();
        let config = config(dir.path(), 2);
        let warnings = Warnings::default();
        let report = run_campaign(
            &car,
            &scenario,
            &config,
            &CancellationToken::new(),
            &warnings,
            Some(&sim),
        )
        .await
        .expect("the campaign ran");
        assert_eq!(report.record.summary.as_ref().unwrap().tests, 2);
        let cases: Vec<_> = report.cases().map(Result::unwrap).collect();
        assert!(
            cases.iter().any(|c| !c.fault_places.is_empty()),
            "the campaign added faults, so they were armed"
        );
        assert_eq!(settled(&sim).await, DISARMED);
        assert_eq!(warnings.taken(), Vec::<String>::new());
    }

    #[tokio::test(start_paused = true)]
    async fn an_interrupted_campaign_leaves_the_car_disarmed() {
        let scenario = scenario();
        let dir = tempfile::tempdir().unwrap();
        let (car, sim) = crate::vehicle::connect_sim(&SimConfig::from_scenario(&scenario))
            .await
            .unwrap();
        let config = config(dir.path(), 50);
        let cancel = CancellationToken::new();
        let interrupt = async {
            // Into the first tests, with faults on the car.
            tokio::time::sleep(Duration::from_secs(90)).await;
            cancel.cancel();
        };
        let warnings = Warnings::default();
        let (failure, ()) = tokio::join!(
            run_campaign(&car, &scenario, &config, &cancel, &warnings, Some(&sim)),
            interrupt
        );
        let failure = failure.expect_err("interrupted");
        assert!(
            matches!(failure.error, RunError::Interrupted { .. }),
            "{}",
            failure.error
        );
        assert_eq!(settled(&sim).await, DISARMED);
        assert_eq!(warnings.taken(), Vec::<String>::new());
    }

    #[tokio::test(start_paused = true)]
    async fn a_car_that_cannot_be_reached_is_named_armed() {
        let scenario = scenario();
        let (car, sim) = crate::vehicle::connect_sim(&SimConfig::from_scenario(&scenario))
            .await
            .unwrap();
        car.set_fi_enabled(true).await.unwrap();
        sim.shutdown();
        let warnings = Warnings::default();
        end_session(&car, Some("A"), &warnings).await;
        let said = warnings.taken();
        assert_eq!(said.len(), 1, "{said:?}");
        assert!(
            said[0].starts_with("car A: fault injection could not be disabled on the car: "),
            "{said:?}"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn the_dry_run_that_does_not_recognise_a_fault_reply_says_it_and_disarms() {
        let scenario = scenario();
        let dir = tempfile::tempdir().unwrap();
        let (car, sim) = crate::vehicle::connect_sim(&SimConfig {
            misname_fault_probe: true,
            ..SimConfig::from_scenario(&scenario)
        })
        .await
        .unwrap();
        // A test with faults first.
        let config = config(dir.path(), 1);
        let warnings = Warnings::default();
        let error = crate::dry_run(&car, &scenario, &config, &warnings)
            .await
            .expect_err("the reply names another probe");
        let text = error.to_string();
        assert!(text.starts_with("uploading fault 0: "), "{text}");
        assert!(
            text.contains("the car answered") && text.contains("successfully added to probe"),
            "the error says what the car answered: {text}"
        );
        assert!(!text.contains("no reply"), "{text}");
        assert_eq!(settled(&sim).await, DISARMED);
        assert_eq!(warnings.taken(), Vec::<String>::new());
    }

    #[tokio::test(start_paused = true)]
    async fn a_dry_run_that_passes_leaves_the_car_disarmed() {
        let scenario = scenario();
        let dir = tempfile::tempdir().unwrap();
        let (car, sim) = crate::vehicle::connect_sim(&SimConfig::from_scenario(&scenario))
            .await
            .unwrap();
        let warnings = Warnings::default();
        let found = crate::dry_run(&car, &scenario, &config(dir.path(), 1), &warnings)
            .await
            .expect("the dry run passes");
        assert!(found.faults_uploaded > 0, "{found:?}");
        assert_eq!(settled(&sim).await, DISARMED);
    }
}
