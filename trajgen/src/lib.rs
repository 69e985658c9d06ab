//! Area geometry and the random drivable trajectory generator.
//!
//! `trajgen` is pure: no I/O, no clocks, no threads. Every random choice takes an explicit RNG, so
//! the same seed gives the same trajectory.
//!
//! - [`geometry`]: points, waypoints (a point with a speed), closed polygons, the area (fence minus
//!   cutouts), exact predicates.
//! - [`constraints`]: what makes a route drivable, and the check.
//! - [`generator`]: extends a route by `n` points with the ahead margin
//!   (`docs/method.md#ahead-margin`).
//! - [`validation`]: drives one long trajectory through an area and gives a verdict
//!   (`docs/method.md#validating-an-area`).
//! - [`raster`]: the area on a square grid (which cells have a drivable centre).
//! - [`stats`]: the nearest-rank percentile every crate of the workspace reports with.
//!
//! ```
//! use rand::SeedableRng;
//! use trajgen::{Area, Generator, Point, Polygon, RouteTail};
//!
//! let fence = Polygon::new(vec![
//!     Point::new(0.0, 0.0),
//!     Point::new(20.0, 0.0),
//!     Point::new(20.0, 20.0),
//!     Point::new(0.0, 20.0),
//! ])
//! .unwrap();
//! let area = Area::new(fence, vec![]).unwrap();
//! let tail = RouteTail::from_points(&[Point::new(2.0, 2.0), Point::new(3.0, 3.0)]).unwrap();
//! let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
//! let extension = Generator::default().extend(&area, &tail, 5, &mut rng).unwrap();
//! assert_eq!(extension.points.len(), 5);
//! assert_eq!(extension.margin.len(), 20);
//! ```
//!
//! Not here: scenario files, drawing, timing, the CLI (see the `scenarios` and `orchestrator`
//! crates).

pub mod constraints;
pub mod generator;
pub mod geometry;
#[cfg(test)]
mod proptests;
pub mod raster;
pub mod stats;
#[cfg(any(test, feature = "test-areas"))]
#[doc(hidden)]
pub mod test_areas;
#[cfg(test)]
mod test_support;
pub mod validation;

pub use constraints::{Constraints, Violation, check_route, route_violations};
pub use generator::{
    Extension, ExtensionStats, GenerationError, Generator, GeneratorConfig, Pose, RouteTail,
    Strategy,
};
pub use geometry::{Area, AreaError, BBox, Point, Polygon, PolygonError, Waypoint};
pub use raster::Raster;
pub use validation::{
    AreaVerdict, CoverageGrid, FailureRecord, HotSpot, Progress, ValidationConfig, ValidationError,
    ValidationReport, validate_area,
};
