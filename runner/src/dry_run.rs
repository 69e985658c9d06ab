//! `drivecheck run --dry-run`: everything a campaign does with a car before it moves, and
//! nothing after. Preflight as a campaign runs it (the firmware, the configuration switched and
//! read back, the anchors, fault injection, the car inside the fence, the link measured); then
//! the first test's route uploaded with the autopilot off and read back point by point, its
//! fault commands uploaded and listed back, and everything cleared again: the session ends as a
//! campaign's does, faults cleared and fault injection disabled, whether the dry run passed or
//! not (`session_end`). No route is started, so the car does not move; no run directory is
//! written.

use car_link::RoutePoint;
use car_link::fault::ListedFault;
use scenarios::Scenario;

use super::journal::Journal;
use super::preflight::Preflight;
use super::{CampaignObserver, RunConfig, RunError, retried};
use crate::vehicle::Vehicle;
use campaign::streaming::route_points;
use trajgen::Waypoint;

/// The most points the dry run uploads and reads back (the start route and as much of the
/// first test's route as fits).
const MAX_POINTS: usize = 60;
/// How far a point read back may be from the one sent, metres or m/s: the wire's position scale
/// rounds to millimetres, its speed to 1e-3 m/s.
const READ_BACK_TOLERANCE: f64 = 0.01;
/// Reads of the fault list that may be needed to see every fault (a lossy link drops parts).
const FAULT_LIST_READS: usize = 4;

/// What the dry run found: the car is ready, and these are the figures.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DryRun {
    /// The firmware version the car reported.
    pub firmware: String,
    /// The configuration fields preflight switched off (`ApRepeatRoutes (was 1)`).
    pub switched_off: Vec<String>,
    /// The median and 99th-percentile GET_STATE round trips, milliseconds.
    pub round_trip_ms: [f64; 2],
    /// The stale-telemetry limit the campaign would run with, milliseconds.
    pub stale_after_ms: f64,
    /// The route points uploaded and read back.
    pub route_points: usize,
    /// The largest difference between a point sent and read back (position m, speed m/s).
    pub route_read_back_error: f64,
    /// The first test's fault commands uploaded.
    pub faults_uploaded: usize,
    /// The faults the car listed back.
    pub faults_listed: usize,
}

/// Runs the dry run of a campaign of `config` in `scenario` against `car`. However it ends, it
/// ends the session as a campaign does ([`crate::end_session`]: the faults cleared, fault
/// injection disabled), and warns through `observer` when the car cannot be disarmed.
///
/// Timeout: every command is bounded by the link's timeouts, the session's end by
/// [`crate::session_end::DISARM_LIMIT`]. Cancellation: safe at any await; a dry run cut short
/// may leave route points or faults on the car, which the next preflight clears.
pub async fn dry_run<V: Vehicle>(
    car: &V,
    scenario: &Scenario,
    config: &RunConfig,
    observer: &dyn CampaignObserver,
) -> Result<DryRun, RunError> {
    let found = checks(car, scenario, config).await;
    crate::end_session(car, None, observer).await;
    found
}

/// The dry run's checks (see the module doc), leaving the session open.
async fn checks<V: Vehicle>(
    car: &V,
    scenario: &Scenario,
    config: &RunConfig,
) -> Result<DryRun, RunError> {
    let journal = Journal::without_recording(None);
    let preflight = Preflight::run(car, scenario, config, &journal).await?;
    let first = config.test_indices().first().copied().unwrap_or(0);
    let plan = super::TestSource::new(scenario, config)?.plan(first)?;
    let route = first_route(scenario, &plan);
    let sent = route_points(&route);
    let route_read_back_error = upload_and_read_back(car, &sent).await?;
    let faults: Vec<_> = plan.faults().map(|(_, f)| *f).collect();
    let faults_listed = upload_faults(car, &faults).await?;
    retried(|| car.reset_uwb_pos())
        .await
        .map_err(|e| RunError::car("resetting the UWB position", e))?;
    Ok(DryRun {
        firmware: car.version().to_string(),
        switched_off: preflight.switched_off.clone(),
        round_trip_ms: [
            preflight.rtt_p50.as_secs_f64() * 1e3,
            preflight.rtt_p99.as_secs_f64() * 1e3,
        ],
        stale_after_ms: preflight.stale_after.as_secs_f64() * 1e3,
        route_points: sent.len(),
        route_read_back_error,
        faults_uploaded: faults.len(),
        faults_listed,
    })
}

/// The start route and the first test's segments after it, at most [`MAX_POINTS`] points.
fn first_route(scenario: &Scenario, plan: &campaign::model::TestPlan) -> Vec<Waypoint> {
    let segments = plan.segments().flat_map(|(_, s)| {
        s.points
            .iter()
            .zip(&s.speeds)
            .map(|(&position, &speed)| Waypoint { position, speed })
    });
    scenario
        .start_route
        .points
        .iter()
        .copied()
        .chain(segments)
        .take(MAX_POINTS)
        .collect()
}

/// Uploads `sent` with the autopilot off, reads the route back and clears it; the largest
/// difference found. A point read back that differs by more than [`READ_BACK_TOLERANCE`] is an
/// error naming it.
async fn upload_and_read_back<V: Vehicle>(car: &V, sent: &[RoutePoint]) -> Result<f64, RunError> {
    retried(|| car.clear_route())
        .await
        .map_err(|e| RunError::car("clearing the route", e))?;
    car.add_points(sent)
        .await
        .map_err(|e| RunError::car("uploading the route", e))?;
    let mut read = Vec::with_capacity(sent.len());
    while read.len() < sent.len() {
        let first = i32::try_from(read.len()).unwrap_or(i32::MAX);
        let num = (sent.len() - read.len()).min(usize::from(car_link::message::MAX_ROUTE_PART));
        let part = retried(|| car.route_part(first, num as u8))
            .await
            .map_err(|e| RunError::car("reading the route back", e))?;
        if usize::try_from(part.route_len).unwrap_or(0) < sent.len() {
            return Err(RunError::Preflight(format!(
                "the car holds {} route points after {} were uploaded",
                part.route_len,
                sent.len()
            )));
        }
        if part.points.is_empty() {
            return Err(RunError::Preflight(format!(
                "the car sent no route points from point {first}"
            )));
        }
        read.extend(part.points);
    }
    retried(|| car.clear_route())
        .await
        .map_err(|e| RunError::car("clearing the route", e))?;
    let mut largest: f64 = 0.0;
    for (i, (s, r)) in sent.iter().zip(&read).enumerate() {
        let error = (s.px - r.px)
            .abs()
            .max((s.py - r.py).abs())
            .max((s.speed - r.speed).abs());
        if error.is_nan() || error > READ_BACK_TOLERANCE {
            return Err(RunError::Preflight(format!(
                "route point {i} read back as ({:.3}, {:.3}) at {:.3} m/s, sent as ({:.3}, {:.3}) at {:.3} m/s",
                r.px, r.py, r.speed, s.px, s.py, s.speed
            )));
        }
        largest = largest.max(error);
    }
    Ok(largest)
}

/// Uploads `faults`, lists the car's faults until all of them are seen (or
/// [`FAULT_LIST_READS`] reads), clears them; how many were listed. Fewer listed than uploaded is
/// an error.
async fn upload_faults<V: Vehicle>(
    car: &V,
    faults: &[campaign::model::Fault],
) -> Result<usize, RunError> {
    for (i, fault) in faults.iter().enumerate() {
        car.add_fault(
            &fault.probe,
            fault.kind,
            fault.param as f32,
            i32::try_from(fault.start).unwrap_or(i32::MAX),
            i32::try_from(fault.duration).unwrap_or(i32::MAX),
        )
        .await
        .map_err(|e| RunError::car(format!("uploading fault {i}"), e))?;
    }
    let mut listed: Vec<ListedFault> = Vec::new();
    for _ in 0..FAULT_LIST_READS {
        if listed.len() >= faults.len() {
            break;
        }
        for fault in retried(|| car.list_faults_part())
            .await
            .map_err(|e| RunError::car("listing the faults", e))?
        {
            if !listed.iter().any(|l| super::drive::same_fault(l, &fault)) {
                listed.push(fault);
            }
        }
    }
    retried(|| car.clear_faults())
        .await
        .map_err(|e| RunError::car("clearing the faults", e))?;
    if listed.len() < faults.len() {
        return Err(RunError::Preflight(format!(
            "{} faults uploaded, the car lists {}",
            faults.len(),
            listed.len()
        )));
    }
    Ok(listed.len())
}
