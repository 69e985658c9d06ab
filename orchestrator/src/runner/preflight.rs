//! Preflight, once per campaign: is this car fit for the method, and how fast is its link?
//!
//! Checks and settings, in order: the firmware generation (10.x or 12.x, the ones whose
//! behaviour the method knows); the main configuration (routes not repeated, speed mode, the
//! fused position reported: switched by a read-modify-write, then read back, and refused with a
//! clear message if it still deviates); the scenario's anchors uploaded; fault injection enabled
//! with every slot cleared; the car inside the fence; the UWB estimate reset to the RTK one; and
//! the round trip of GET_STATE measured over a few requests. The fault-injection and UWB
//! commands and the state samples are recorded in the campaign's journal.

use std::time::Duration;

use car_link::Car;
use car_link::message::Anchor;
use scenarios::Scenario;
use trajgen::Point;

use super::journal::Journal;
use super::{RunConfig, RunError, retried};
use crate::model::ProbeRates;
use crate::recording::CarCommand;
use crate::safety::SafetyConfig;

/// GET_STATE requests the round trip is measured over.
const RTT_PROBES: usize = 20;
/// The car's watchdog brakes after 2 s without commands: staleness must be noticed before.
const MAX_STALE: Duration = Duration::from_millis(1900);

/// What preflight learned about the car and its link.
#[derive(Debug, Clone, PartialEq)]
pub struct Preflight {
    /// The configuration fields preflight switched off, with their old values (`ApRepeatRoutes
    /// (was 1)`); empty when the car was ready.
    pub switched_off: Vec<String>,
    /// The 99th-percentile GET_STATE round trip measured.
    pub rtt_p99: Duration,
    /// How long one state request may take before the next tick asks again:
    /// `max(150 ms, rtt_p99 + 100 ms)` (a lost request is asked again soon, so that a few losses
    /// in a row stay within the stale-telemetry limit).
    pub sample_timeout: Duration,
    /// The safety limits in force: the configured ones, with the stale-telemetry limit raised to
    /// `state period + 5 × rtt_p99` (at most 1.9 s) on a slow link, since samples cannot come
    /// faster than one per round trip.
    pub safety: SafetyConfig,
    /// The fault probes' call rates of this firmware with the scenario's anchors.
    pub rates: ProbeRates,
}

impl Preflight {
    /// Runs the preflight (see the module doc).
    ///
    /// Timeout: each command as bounded by the car's link configuration. Cancellation: the car
    /// may be left partly prepared; run the preflight again.
    pub(crate) async fn run(
        car: &Car,
        scenario: &Scenario,
        config: &RunConfig,
        journal: &Journal<'_>,
    ) -> Result<Self, RunError> {
        let version = car.version();
        let rates = match version.major {
            10 => ProbeRates::firmware_10(scenario.anchors.len()),
            12 => ProbeRates::firmware_12(scenario.anchors.len()),
            _ => {
                return Err(RunError::Preflight(format!(
                    "firmware {version}: the method knows 10.x and 12.x only"
                )));
            }
        };
        let switched_off = prepare_configuration(car).await?;
        let anchors = anchors(scenario);
        retried(|| car.upload_anchors(&anchors))
            .await
            .map_err(|e| RunError::car("uploading the anchors", e))?;
        let enable = CarCommand::SetFaultInjection { enabled: true };
        retried(|| journal.call(None, enable.clone(), car.set_fi_enabled(true)))
            .await
            .map_err(|e| RunError::car("enabling fault injection", e))?;
        retried(|| journal.call(None, CarCommand::ClearFaults, car.clear_faults()))
            .await
            .map_err(|e| RunError::car("clearing the faults", e))?;
        check_inside_fence(car, scenario, journal).await?;
        retried(|| journal.call(None, CarCommand::ResetUwbPos, car.reset_uwb_pos()))
            .await
            .map_err(|e| RunError::car("resetting the UWB position", e))?;
        let rtt_p99 = measure_round_trip(car, journal).await?;
        Ok(Self::from_round_trip(rtt_p99, config, rates, switched_off))
    }

    fn from_round_trip(
        rtt_p99: Duration,
        config: &RunConfig,
        rates: ProbeRates,
        switched_off: Vec<String>,
    ) -> Self {
        let sample_timeout = Duration::from_millis(150).max(rtt_p99 + Duration::from_millis(100));
        let link_stale = (config.state_period + rtt_p99 * 5).min(MAX_STALE);
        let safety = SafetyConfig {
            stale_after: config.safety.stale_after.max(link_stale),
            ..config.safety
        };
        Self {
            switched_off,
            rtt_p99,
            sample_timeout,
            safety,
            rates,
        }
    }
}

async fn prepare_configuration(car: &Car) -> Result<Vec<String>, RunError> {
    let changed = car.prepare_for_test_drive().await.map_err(|e| {
        RunError::Preflight(format!(
            "cannot switch off repeated routes (and time mode, UWB-reported position): {e}"
        ))
    })?;
    let config = car
        .main_config()
        .await
        .map_err(|e| RunError::car("reading the main configuration back", e))?;
    let left = config
        .test_drive_deviations()
        .map_err(|e| RunError::Preflight(e.to_string()))?;
    if !left.is_empty() {
        return Err(RunError::Preflight(format!(
            "the car keeps {left:?} after being told to switch them off: set repeat routes off \
             (and time mode, use_uwb_pos) in its configuration and try again"
        )));
    }
    Ok(changed
        .iter()
        .map(|(field, old)| format!("{field:?} (was {old})"))
        .collect())
}

fn anchors(scenario: &Scenario) -> Vec<Anchor> {
    scenario
        .anchors
        .iter()
        .map(|a| Anchor {
            id: i16::from(a.id),
            px: a.x as f32,
            py: a.y as f32,
            height: a.height as f32,
        })
        .collect()
}

async fn check_inside_fence(
    car: &Car,
    scenario: &Scenario,
    journal: &Journal<'_>,
) -> Result<(), RunError> {
    let sample = retried(|| car.state())
        .await
        .map_err(|e| RunError::car("reading the car's state", e))?;
    journal.state(&sample);
    let at = Point::new(sample.state.px, sample.state.py);
    if !at.is_finite() || !scenario.area.contains_point(at) {
        return Err(RunError::Preflight(format!(
            "the car is at ({:.2}, {:.2}), not inside the fence of {}: drive it into the area",
            at.x, at.y, scenario.name
        )));
    }
    Ok(())
}

async fn measure_round_trip(car: &Car, journal: &Journal<'_>) -> Result<Duration, RunError> {
    let mut rtts = Vec::with_capacity(RTT_PROBES);
    for _ in 0..RTT_PROBES {
        let sample = retried(|| car.state())
            .await
            .map_err(|e| RunError::car("measuring the round trip", e))?;
        journal.state(&sample);
        rtts.push(sample.rtt());
    }
    rtts.sort_unstable();
    let rank = (rtts.len() * 99).div_ceil(100).clamp(1, rtts.len());
    Ok(rtts[rank - 1])
}
