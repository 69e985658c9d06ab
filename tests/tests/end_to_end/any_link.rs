//! A case is the same test on any link: a failing case found in a virtual-time campaign, replayed
//! once over a direct in-process link and once over a slow, jittery one (150 ms ± 40 ms each way,
//! simulated in virtual time), gets the same verdict on every segment, with maximum deviations
//! within 0.2 m, because each fault is sent at its place on the route, not at a time.

use crate::common;

use std::path::Path;
use std::time::Duration;

use campaign::files::{Case, ReplayOf};
use campaign::model::Campaign;
use campaign::oracle::Verdict;
use car_sim::{LinkImpairment, SimConfig};
use runner::{ReplaySource, RunConfig, Tests};
use scenarios::Scenario;
use trajgen::{Generator, Strategy};

const SEED: u64 = 2;

fn scenario() -> Scenario {
    scenarios::bundled::load("parking-lot-2anchors")
        .unwrap()
        .scenario
}

/// Runs `config` on a fresh embedded simulated car seeded with [`SEED`] behind `link`; returns
/// the cases.
async fn run(scenario: &Scenario, config: &RunConfig, link: LinkImpairment) -> Vec<Case> {
    let sim_config = SimConfig {
        seed: SEED,
        link,
        ..SimConfig::from_scenario(scenario)
    };
    let (car, sim) = common::sim_car(&sim_config).await;
    let report = common::drive(&car, &sim, scenario, config).await.unwrap();
    report.cases().collect::<Result<_, _>>().unwrap()
}

fn replay_config(case: &Case, scenario: &Scenario, out: &Path) -> RunConfig {
    let generator = Generator::new(scenario.generator.generator_config(Strategy::Wedge)).unwrap();
    let plan = case
        .replay_plan(scenario, &generator, SEED, false, 0)
        .unwrap();
    let campaign = Campaign {
        seed: SEED,
        tests: 1,
        no_faults: false,
    };
    let mut config = RunConfig::new(campaign, out.to_owned(), "sim");
    config.tests = Tests::Replay(ReplaySource {
        plan,
        of: ReplayOf {
            case: "failing case".to_owned(),
            campaign_seed: case.campaign_seed,
            test_index: case.test_index,
            verdict: case.verdict,
            no_faults: false,
        },
        as_test: None,
    });
    config
}

#[tokio::test(start_paused = true)]
async fn a_failing_case_is_the_same_test_over_a_slow_jittery_link() {
    let scenario = scenario();
    let dir = tempfile::tempdir().unwrap();
    let found = Campaign {
        seed: SEED,
        tests: 10,
        no_faults: false,
    };
    let config = RunConfig::new(found, dir.path().join("campaign"), "sim");
    let cases = run(&scenario, &config, LinkImpairment::default()).await;
    let case = cases
        .into_iter()
        .find(|c| c.verdict == Some(Verdict::Failed))
        .expect("seed 2 finds a failure in 10 tests");

    let direct = run(
        &scenario,
        &replay_config(&case, &scenario, &dir.path().join("direct")),
        LinkImpairment::default(),
    )
    .await;
    let slow = LinkImpairment {
        latency: Duration::from_millis(150),
        jitter: Duration::from_millis(40),
        ..LinkImpairment::default()
    };
    let delayed = run(
        &scenario,
        &replay_config(&case, &scenario, &dir.path().join("delayed")),
        slow,
    )
    .await;
    let (direct, delayed) = (&direct[0], &delayed[0]);
    assert_eq!(direct.verdict, delayed.verdict);
    assert_eq!(direct.segments.len(), delayed.segments.len());
    for (a, b) in direct.segments.iter().zip(&delayed.segments) {
        assert_eq!(
            a.oracle.verdict, b.oracle.verdict,
            "segment {}",
            a.segment_index
        );
        let (Some(sa), Some(sb)) = (a.oracle.stats, b.oracle.stats) else {
            panic!("segment {} was judged on samples", a.segment_index);
        };
        assert!(
            (sa.max_m - sb.max_m).abs() <= 0.2,
            "segment {}: {} m direct, {} m delayed",
            a.segment_index,
            sa.max_m,
            sb.max_m
        );
    }
    // Every fault was added within 0.2 m of its place, on both links.
    assert!(!delayed.fault_places.is_empty());
    for place in direct.fault_places.iter().chain(&delayed.fault_places) {
        let error = place.error_m.expect("a sample came after the fault");
        assert!(error.abs() <= 0.2, "{place:?}");
    }
}
