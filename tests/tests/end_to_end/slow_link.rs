//! Slow and lossy links, simulated in virtual time: a campaign over 500 ms each way drives its
//! tests, one at 30 % loss ends every test judged or with a clear reason, and fault commands for
//! different probes share a round trip. Never an error that reads like a firmware fault (before,
//! 500 ms each way died in the first upload: "the car did not store route point 0 as sent").

use crate::common;

use std::time::Duration;

use campaign::model::Campaign;
use campaign::oracle::Verdict;
use car_link::Car;
use car_sim::{LinkImpairment, SimConfig};
use runner::{CampaignReport, RunConfig};

#[tokio::test(start_paused = true)]
async fn a_campaign_over_half_a_second_each_way_drives_its_tests() {
    let link = LinkImpairment {
        latency: Duration::from_millis(500),
        ..LinkImpairment::default()
    };
    let (car, report) = campaign_over(link, 5, 2, None).await;
    // Round trips of a little over 1 s: 2 × p99 + 100 ms per try (before, the late replies of
    // 1 s tries made them read 0.4 s, and the read-back of an upload compared the wrong points).
    let per_try = car.request_timeout();
    assert!(
        (Duration::from_millis(2100)..Duration::from_millis(2400)).contains(&per_try),
        "{per_try:?}"
    );
    assert_eq!(report.tests.len(), 2);
    for case in &report.tests {
        // Judged, not aborted: the lead time (about 5 s) fits the route the segments give.
        assert!(
            matches!(case.verdict, Some(Verdict::Passed | Verdict::Failed)),
            "{:?}: {:?}",
            case.verdict,
            case.reason
        );
    }
}

/// At 30 % loss each way (half the round trips fail) on a fast link, a 3-test campaign starts
/// (preflight measures the round trip from the probes that were answered) and ends with every
/// test judged or aborted with a reason that says what happened, never a misread reply. Before,
/// preflight gave up ("no reply to GetState after 1 tries"), then tests aborted on a partly lost
/// fault reply ("unexpected fault-injection reply \" \"") and on a fault added twice ("too many
/// faults on this probe", after a fault list that lost a line looked complete).
#[tokio::test(start_paused = true)]
async fn a_campaign_at_thirty_percent_loss_ends_every_test_judged_or_with_a_clear_reason() {
    for seed in [1, 2] {
        let link = LinkImpairment {
            loss: 0.3,
            ..LinkImpairment::default()
        };
        let (_, report) = campaign_over(link, seed, 3, Some(Duration::from_secs(1))).await;
        assert_eq!(report.tests.len(), 3);
        let judged = report
            .tests
            .iter()
            .filter(|c| matches!(c.verdict, Some(Verdict::Passed | Verdict::Failed)))
            .count();
        // Every one today; before, one or two of three aborted.
        assert!(judged >= 2, "seed {seed}: {judged} of 3 judged");
        for case in &report.tests {
            match case.verdict {
                Some(Verdict::Passed | Verdict::Failed) => {}
                Some(Verdict::Aborted) => {
                    let reason = case.reason.as_deref().unwrap_or_default();
                    assert!(
                        !reason.contains("unexpected") && !reason.contains("too many faults"),
                        "seed {seed}: {reason}"
                    );
                }
                None => panic!("seed {seed}: a test without a verdict"),
            }
        }
    }
}

/// A campaign of `tests` tests (seed 5) on a fresh embedded simulated car seeded with `seed`
/// behind `link`, over a link configured as drivecheck's commands configure it; the car (for its
/// per-try timeout) and the report.
async fn campaign_over(
    link: LinkImpairment,
    seed: u64,
    tests: usize,
    stale_after: Option<Duration>,
) -> (Car, CampaignReport) {
    let scenario = scenarios::bundled::load("parking-lot-2anchors")
        .unwrap()
        .scenario;
    let sim_config = SimConfig {
        seed,
        link,
        ..SimConfig::from_scenario(&scenario)
    };
    let (car, sim) = common::sim_car(&sim_config).await;
    let dir = tempfile::tempdir().unwrap();
    let campaign = Campaign {
        seed: 5,
        tests,
        no_faults: false,
    };
    let mut config = RunConfig::new(campaign, dir.path().join("run"), "sim");
    if let Some(stale_after) = stale_after {
        config.safety.stale_after = stale_after;
    }
    let report = common::drive(&car, &sim, &scenario, &config)
        .await
        .unwrap_or_else(|failure| panic!("seed {seed}: {}", failure.error));
    (car, report)
}

/// A simulated car of the two-anchor lot, 150 ms away each way, with fault injection on.
async fn car_150ms_away() -> (Car, car_sim::SimHandle) {
    let scenario = scenarios::bundled::load("parking-lot-2anchors")
        .unwrap()
        .scenario;
    let sim_config = SimConfig {
        link: LinkImpairment {
            latency: Duration::from_millis(150),
            ..LinkImpairment::default()
        },
        ..SimConfig::from_scenario(&scenario)
    };
    let (car, sim) = common::sim_car(&sim_config).await;
    car.set_fi_enabled(true).await.unwrap();
    (car, sim)
}

/// Fault commands for two probes are in flight together: on a link of 150 ms each way both are
/// added within one round trip, not two (before, the second waited for the first's reply, and a
/// fault placed 0.7 m after another on a 2.5 m/s segment was added 0.44 m late).
#[tokio::test(start_paused = true)]
async fn fault_commands_for_two_probes_take_one_round_trip() {
    use car_link::{FaultKind, Probe};
    let (car, _sim) = car_150ms_away().await;
    let started = tokio::time::Instant::now();
    let (range, yaw) = tokio::join!(
        car.add_fault(&Probe::UwbRange(50), FaultKind::Offset, 1.0, 1000, 1),
        car.add_fault(&Probe::UwbYaw, FaultKind::Offset, 5.0, 1000, 1),
    );
    let took = started.elapsed();
    range.unwrap();
    yaw.unwrap();
    assert!(took < Duration::from_millis(450), "{took:?}");
    let listed = car.list_faults().await.unwrap();
    assert_eq!(listed.len(), 2, "{listed:?}");
}

/// Fault commands for one probe are in flight together too, and each gets its own reply: the car
/// answers them in the order they arrive. Six on one probe over 150 ms each way take one round
/// trip; the car refuses the sixth (five faults per probe), and that refusal is the sixth's.
#[tokio::test(start_paused = true)]
async fn fault_commands_for_one_probe_take_one_round_trip_and_their_own_replies() {
    use car_link::fault::{FaultError, FaultRejection};
    use car_link::{CarError, FaultKind, Probe};
    let (car, _sim) = car_150ms_away().await;
    let probe = Probe::UwbRange(50);
    let started = tokio::time::Instant::now();
    let add = |k: u64| {
        let (car, probe) = (&car, &probe);
        async move {
            // Each later command is sent 10 ms after the one before, all before the first reply.
            tokio::time::sleep(Duration::from_millis(10 * k)).await;
            car.add_fault(probe, FaultKind::Offset, k as f32, 1000, 1)
                .await
        }
    };
    let (r1, r2, r3, r4, r5, r6) = tokio::join!(add(1), add(2), add(3), add(4), add(5), add(6));
    let results = [r1, r2, r3, r4, r5, r6];
    let took = started.elapsed();
    for (k, result) in results.iter().enumerate().take(5) {
        assert!(result.is_ok(), "command {}: {result:?}", k + 1);
    }
    assert!(
        matches!(&results[5], Err(CarError::Fault(FaultError::Rejected(r))) if r == &[FaultRejection::TooManyFaults]),
        "{:?}",
        results[5]
    );
    assert!(took < Duration::from_millis(500), "{took:?}");
    let listed = car.list_faults().await.unwrap();
    let params: Vec<f32> = listed.iter().map(|f| f.param).collect();
    assert_eq!(params, [1.0, 2.0, 3.0, 4.0, 5.0]);
}
