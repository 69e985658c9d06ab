//! Return routes: from the car's pose after a test back to the recovery route, and their shortening.
//!
//! After each test the car stands at some pose; before the next test it must drive back and join
//! the recovery route (which leads into the start route) with the right heading, so that every
//! test starts from the same state (`docs/method.md#return-routes`). [`plan`] computes such a
//! route:
//!
//! - it starts at the car's position, its first segment within the turn limit of the car's
//!   heading;
//! - every segment is `min_segment..=max_segment` long, every turn below `max_turn`, everything
//!   inside the fence and outside the cutouts (the [`Constraints`]);
//! - it ends at a point `J` of a recovery segment `k` such that `J → recovery point k + 1` is a
//!   valid segment and the turn into it is below the limit: the route followed by
//!   [`Join::next`] passes [`trajgen::check_route`] end to end, the joint included
//!   ([`ReturnRoute::checked_points`]); the car then drives on along the recovery route
//!   ([`ReturnRoute::joined`]).
//!
//! Two planners ([`PlannerKind`]): [`PlannerKind::Dubins`] (the default) searches poses with a hybrid A*
//! and shoots discretised Dubins paths at every joinable point of the recovery route, minimising
//! the distance to the start route; [`PlannerKind::Reference`] is the method's own (arcs and a line,
//! random extensions, best of 100 attempts), kept as a baseline. Both end with the method's
//! shortening pass. Every plan carries its [`Quality`]: length, a lower bound, their ratio, and
//! what was tried.
//!
//! A car that stopped nearer an edge than the constraints' clearance cannot start a route that
//! keeps it: [`PlanConfig::plan_with_fallback`] then plans with half the clearance, or none, and
//! the route says which it keeps ([`ReturnRoute::clearance`]).
//!
//! ```
//! use rand::SeedableRng;
//! use trajgen::{Area, Constraints, Point, Polygon, Pose};
//!
//! let square = |x0: f64, y0: f64, side: f64| {
//!     Polygon::new(vec![
//!         Point::new(x0, y0),
//!         Point::new(x0 + side, y0),
//!         Point::new(x0 + side, y0 + side),
//!         Point::new(x0, y0 + side),
//!     ])
//!     .unwrap()
//! };
//! let area = Area::new(square(0.0, 0.0, 30.0), vec![square(12.0, 12.0, 6.0)]).unwrap();
//! let recovery_route = [Point::new(3.0, 3.0), Point::new(5.0, 3.0), Point::new(7.0, 3.0)];
//! let car = Pose::new(Point::new(25.0, 25.0), 90f64.to_radians());
//! let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
//! let c = Constraints::default();
//! let route = recovery::plan(&area, car, &recovery_route, &c, &mut rng).unwrap();
//! assert!(trajgen::check_route(&area, &route.checked_points(), &c, Some(car.heading)).is_ok());
//! assert!(route.quality.ratio >= 1.0);
//! ```
//!
//! `recovery` is pure: no I/O, clocks or threads; the same inputs and RNG seed give the same route.
//! It does not time itself (callers measure plan time), read scenario files, or drive the car.

mod arcs;
mod connect;
mod dubins;
mod error;
mod grid;
mod join;
mod planner;
mod polyline;
mod reference;
mod search;
mod shorten;
#[cfg(test)]
mod tests;

pub use arcs::{ArcConnector, can_turn_around};
pub use error::{RecoveryError, Tried};
pub use join::Join;
pub use planner::{
    FALLBACK_CLEARANCE_FRACTIONS, JoinPolicy, PlanConfig, PlannerKind, Quality, ReturnRoute,
    UnknownPlanner,
};
pub use reference::ReferenceConfig;
pub use search::SearchConfig;
pub use shorten::Shortening;
pub use trajgen::{Constraints, Pose};

use rand::Rng;
use trajgen::{Area, Point};

/// Plans a return route from the car's pose `from` to `recovery_route` in `area` with the default
/// planner ([`PlannerKind::Dubins`]) and budgets; see [`PlanConfig`] to choose others.
///
/// Errors: the pose is non-finite, outside the fence, inside a cutout or on an edge; the recovery
/// route has fewer than two points or nothing joinable; the constraints make no sense; no route
/// was found within the budget ([`RecoveryError::NoRoute`] says what was tried).
pub fn plan<R: Rng + ?Sized>(
    area: &Area,
    from: Pose,
    recovery_route: &[Point],
    constraints: &Constraints,
    rng: &mut R,
) -> Result<ReturnRoute, RecoveryError> {
    PlanConfig::default().plan(area, from, recovery_route, constraints, rng)
}
