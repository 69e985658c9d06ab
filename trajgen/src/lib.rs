//! Area geometry and the random drivable trajectory generator.
//!
//! `trajgen` is pure: no I/O, no clocks, no threads. Every random choice takes an explicit RNG, so
//! the same seed gives the same trajectory.

pub mod constraints;
pub mod geometry;

pub use constraints::{Constraints, Violation, check_route, route_violations};
pub use geometry::{Area, AreaError, BBox, Point, Polygon, PolygonError};
