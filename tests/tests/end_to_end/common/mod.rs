//! What the end-to-end tests on the embedded simulated car share: a car behind an in-process link
//! configured as `drivecheck` configures it, and a campaign on it.

#![allow(dead_code)] // each test file uses its own part

use std::time::Duration;

use car_link::{Car, LinkConfig};
use car_sim::{SimConfig, SimHandle};
use runner::vehicle::SimulatorView;
use runner::{CampaignFailure, CampaignReport, RunConfig, Silent, run_campaign};
use scenarios::Scenario;
use tokio_util::sync::CancellationToken;

/// A fresh embedded simulated car with `config`, and a link to it with the binary's settings
/// (1 s per try, 2 s for a terminal reply, 10 tries).
pub async fn sim_car(config: &SimConfig) -> (Car, SimHandle) {
    let (stream, sim) = car_sim::spawn_in_process(config);
    let link_config = LinkConfig {
        request_timeout: Duration::from_secs(1),
        terminal_timeout: Duration::from_secs(2),
        tries: 10,
        ..LinkConfig::default()
    };
    let car = Car::over_stream(stream, link_config).await.unwrap();
    (car, sim)
}

/// Runs `config` in `scenario` on `car`, the simulated car `sim`, uninterrupted and silent.
pub async fn drive(
    car: &Car,
    sim: &SimHandle,
    scenario: &Scenario,
    config: &RunConfig,
) -> Result<CampaignReport, CampaignFailure> {
    run_campaign(
        car,
        scenario,
        config,
        &CancellationToken::new(),
        &Silent,
        Some(sim as &dyn SimulatorView),
    )
    .await
}
