//! Area geometry and the random drivable trajectory generator.
//!
//! `trajgen` is pure: no I/O, no clocks, no threads. Every random choice takes an explicit RNG, so
//! the same seed gives the same trajectory.

pub mod geometry;

pub use geometry::{Area, AreaError, BBox, Point, Polygon, PolygonError};
