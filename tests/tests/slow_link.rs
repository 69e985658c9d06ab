//! A slow link (500 ms each way, simulated in virtual time): the campaign either drives or is
//! refused in preflight with what was measured; never an error that reads like a firmware fault
//! (before, it died in the first upload: "the car did not store route point 0 as sent").

use std::time::Duration;

use campaign::model::Campaign;
use campaign::oracle::Verdict;
use car_link::{Car, LinkConfig};
use car_sim::{LinkImpairment, SimConfig};
use orchestrator::runner::{RunConfig, Silent, SimulatorView, run_campaign};
use tokio_util::sync::CancellationToken;

#[tokio::test(start_paused = true)]
async fn a_campaign_over_half_a_second_each_way_drives_its_tests() {
    let scenario = scenarios::bundled::load("parking-lot-2anchors")
        .unwrap()
        .scenario;
    let sim_config = SimConfig {
        seed: 5,
        link: LinkImpairment {
            latency: Duration::from_millis(500),
            ..LinkImpairment::default()
        },
        ..SimConfig::from_scenario(&scenario)
    };
    let (stream, sim) = car_sim::spawn_in_process(&sim_config);
    let link_config = LinkConfig {
        request_timeout: Duration::from_secs(1),
        terminal_timeout: Duration::from_secs(2),
        tries: 10,
        ..LinkConfig::default()
    };
    let car = Car::over_stream(stream, link_config).await.unwrap();
    let dir = tempfile::tempdir().unwrap();
    let campaign = Campaign {
        seed: 5,
        tests: 2,
        no_faults: false,
    };
    let config = RunConfig::new(campaign, dir.path().join("run"), "sim");
    let report = run_campaign(
        &car,
        &scenario,
        &config,
        &CancellationToken::new(),
        &Silent,
        Some(&sim as &dyn SimulatorView),
    )
    .await
    .unwrap_or_else(|failure| panic!("{}", failure.error));
    // Round trips of a little over 1 s: 2 × p99 + 100 ms per try (before, the late replies of
    // 1 s tries made them read 0.4 s, and the read-back of an upload compared the wrong points).
    let per_try = car.request_timeout();
    assert!(
        (Duration::from_millis(2100)..Duration::from_millis(2400)).contains(&per_try),
        "{per_try:?}"
    );
    assert_eq!(report.cases.len(), 2);
    for case in &report.cases {
        // Judged, not aborted: the lead time (about 5 s) fits the route the segments give.
        assert!(
            matches!(case.verdict, Some(Verdict::Passed | Verdict::Failed)),
            "{:?}: {:?}",
            case.verdict,
            case.reason
        );
    }
}
