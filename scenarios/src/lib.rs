//! Scenario files: the test area, routes, anchors, environment, vehicle and campaign settings.

/// The area geometry of [`trajgen`], re-exported for crates that see scenarios but not the generator.
pub use trajgen::geometry;
