//! The firmware's route-following printouts, measured on a simulated car: a closed route driven
//! round and round (`ap_repeat_routes`, the factory default), recording what the real car prints
//! with `pos_gnss_corr_info 1` (at every GNSS correction, the distance between the pose history's
//! point closest to the fix time and the fix) and `ap_print_closest n` (every n-th autopilot
//! iteration, the distance from the car to the route). `drivecheck-dev bench fidelity` compares them
//! with the real car's published recordings (`docs/fidelity.md#route-following`).
//!
//! Like the rest of the crate: no I/O, no clock, the same options give the same printouts.

use crate::autopilot::RoutePoint;
use crate::car::{CarOptions, Placement, SimCar, TICK_MS};

/// Route points per AP_ADD_POINTS packet.
const POINTS_PER_PACKET: usize = 10;
/// How often the orchestrator's poll (GET_STATE) keeps the watchdog quiet, ms.
const POLL_MS: u64 = 100;

/// One drive of a closed route and what to record of it.
#[derive(Debug, Clone, PartialEq)]
pub struct RouteDrive {
    /// The car; its placement is replaced by the route's first point, heading to the second.
    pub options: CarOptions,
    /// The route, closed (its last point leads back to its first).
    pub route: Vec<RoutePoint>,
    /// Driving before anything is recorded (the fused estimate starts exact), ms.
    pub warm_up_ms: u64,
    /// GNSS corrections to record.
    pub corrections: usize,
    /// Route distances to record.
    pub prints: usize,
    /// `ap_print_closest`'s n: a route distance every n-th autopilot iteration.
    pub print_every: u32,
}

/// What the firmware would have printed.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Printouts {
    /// At each GNSS correction, the pose history's point closest to the fix time to the fix, m.
    pub gnss_diff_m: Vec<f64>,
    /// Every `print_every`-th autopilot iteration, the car's distance to the route, m.
    pub route_distance_m: Vec<f64>,
}

/// Why a route cannot be driven.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RouteDriveError {
    /// Fewer than two distinct points.
    #[error("the route needs two distinct points to start on")]
    TooShort,
    /// The car stopped printing (no GNSS, the autopilot stopped) before the series were full.
    #[error(
        "the car printed {corrections} GNSS corrections and {prints} route distances in {ms} ms"
    )]
    Stalled {
        /// Corrections recorded.
        corrections: usize,
        /// Route distances recorded.
        prints: usize,
        /// Simulated time driven, ms.
        ms: u64,
    },
}

/// Drives `drive.route` round and round and records the printouts.
pub fn drive(drive: &RouteDrive) -> Result<Printouts, RouteDriveError> {
    let first = drive.route.first().ok_or(RouteDriveError::TooShort)?;
    let next = drive
        .route
        .iter()
        .find(|p| (p.px, p.py) != (first.px, first.py))
        .ok_or(RouteDriveError::TooShort)?;
    let options = CarOptions {
        placement: Placement {
            x: f64::from(first.px),
            y: f64::from(first.py),
            heading: f64::from(next.py - first.py).atan2(f64::from(next.px - first.px)),
        },
        ..drive.options.clone()
    };
    let mut car = SimCar::new(options);
    for packet in drive.route.chunks(POINTS_PER_PACKET) {
        car.add_points(packet);
    }
    car.set_active(true, false);
    let print_every = drive.print_every.max(1);
    // Long enough for both series at a fix every 200 ms and an iteration every tick, twice over.
    let needed_ms = (drive.corrections as u64 * 200)
        .max(drive.prints as u64 * u64::from(print_every) * TICK_MS);
    let end_ms = drive.warm_up_ms + 2 * needed_ms + 10_000;
    let mut out = Printouts::default();
    let mut iteration: u64 = 0;
    while out.gnss_diff_m.len() < drive.corrections || out.route_distance_m.len() < drive.prints {
        if car.now_ms() >= end_ms {
            return Err(RouteDriveError::Stalled {
                corrections: out.gnss_diff_m.len(),
                prints: out.route_distance_m.len(),
                ms: car.now_ms(),
            });
        }
        car.step();
        let now = car.now_ms();
        if now.is_multiple_of(POLL_MS) {
            car.get_state();
        }
        if now <= drive.warm_up_ms {
            continue;
        }
        if let Some(c) = car.last_gnss_correction()
            && c.at_ms == now
            && out.gnss_diff_m.len() < drive.corrections
        {
            out.gnss_diff_m.push(f64::from(c.diff_m));
        }
        // The firmware counts the iterations that looked for the closest point and prints when
        // the count is a multiple of n, from 0.
        if let Some(d) = car.autopilot().closest_distance() {
            if iteration.is_multiple_of(u64::from(print_every))
                && out.route_distance_m.len() < drive.prints
            {
                out.route_distance_m.push(f64::from(d));
            }
            iteration += 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn circle(radius: f32, points: usize, speed: f32) -> Vec<RoutePoint> {
        (0..points)
            .map(|i| {
                let a = i as f32 / points as f32 * std::f32::consts::TAU;
                RoutePoint::at(radius * a.cos(), radius * a.sin(), speed)
            })
            .collect()
    }

    fn circle_drive(seed: u64) -> RouteDrive {
        RouteDrive {
            options: CarOptions {
                seed,
                ..CarOptions::default()
            },
            route: circle(10.0, 73, 1.1),
            warm_up_ms: 5_000,
            corrections: 100,
            prints: 100,
            print_every: 10,
        }
    }

    #[test]
    fn a_circle_is_followed_within_centimetres_and_printed_as_asked() {
        let p = drive(&circle_drive(3)).unwrap();
        assert_eq!((p.gnss_diff_m.len(), p.route_distance_m.len()), (100, 100));
        let worst = p.route_distance_m.iter().copied().fold(0.0, f64::max);
        assert!(worst > 0.0 && worst < 0.15, "{worst}");
        let worst_fix = p.gnss_diff_m.iter().copied().fold(0.0, f64::max);
        assert!(worst_fix > 0.0 && worst_fix < 0.15, "{worst_fix}");
        assert_eq!(drive(&circle_drive(3)).unwrap(), p);
    }

    #[test]
    fn without_gnss_the_drive_stalls_with_an_error() {
        let mut d = circle_drive(1);
        d.options.gnss.enabled = false;
        d.warm_up_ms = 0;
        assert!(matches!(
            drive(&d),
            Err(RouteDriveError::Stalled {
                corrections: 0,
                prints: 100,
                ..
            })
        ));
        d.route.truncate(1);
        assert_eq!(drive(&d), Err(RouteDriveError::TooShort));
    }
}
