//! Why no return route was planned: bad input, or no route within the budget.

use std::fmt;

use thiserror::Error;

use trajgen::Violation;

use crate::planner::PlannerKind;

/// Why [`plan`](crate::plan) returned no route.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RecoveryError {
    /// The car's position or heading is NaN or infinite.
    #[error("the car's pose has a non-finite position or heading")]
    NonFinitePose,
    /// The car stands outside the fence.
    #[error("the car at ({x:.3}, {y:.3}) is outside the fence")]
    PoseOutside {
        /// East coordinate.
        x: f64,
        /// North coordinate.
        y: f64,
    },
    /// The car stands inside a cutout.
    #[error("the car at ({x:.3}, {y:.3}) is inside cutout {cutout}")]
    PoseInCutout {
        /// Index of the cutout in [`trajgen::Area::cutouts`].
        cutout: usize,
        /// East coordinate.
        x: f64,
        /// North coordinate.
        y: f64,
    },
    /// The car stands exactly on a boundary edge.
    #[error("the car at ({x:.3}, {y:.3}) stands on the fence or a cutout's edge")]
    PoseOnEdge {
        /// East coordinate.
        x: f64,
        /// North coordinate.
        y: f64,
    },
    /// The recovery route cannot be joined.
    #[error("invalid recovery route: {reason}")]
    InvalidRecoveryRoute {
        /// What is wrong.
        reason: &'static str,
    },
    /// The constraints make no sense (non-positive lengths, turn limit outside (0°, 180°), ...).
    #[error("invalid constraints: {reason}")]
    InvalidConstraints {
        /// What is wrong.
        reason: &'static str,
    },
    /// A planner's constants make no sense (a non-positive cell size, no step lengths, ...).
    #[error("invalid planner configuration: {reason}")]
    InvalidConfig {
        /// What is wrong.
        reason: &'static str,
    },
    /// The planned route failed the final check: a bug in this crate, reported rather than
    /// returned as a route.
    #[error("the planned route is not drivable ({violation}): this is a bug")]
    PlannedRouteInvalid {
        /// The first violation found.
        violation: Violation,
    },
    /// The planner found no route within its budget.
    #[error("the {planner} planner found no return route: {tried}")]
    NoRoute {
        /// The planner that gave up.
        planner: PlannerKind,
        /// What it tried.
        tried: Tried,
    },
}

/// What a planner tried, as counts (the planner's budget is counted, never timed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Tried {
    /// Reference planner: attempts (each a chain of random extensions); Dubins planner: searches
    /// run (1, plus one per refinement after the reachable cells ran out).
    pub attempts: u32,
    /// Random extensions generated (reference) or search nodes expanded (Dubins).
    pub expansions: u64,
    /// Candidate connections to the recovery route (or shortcuts) checked for validity.
    pub connections: u64,
}

impl fmt::Display for Tried {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} attempts, {} expansions, {} connections checked",
            self.attempts, self.expansions, self.connections
        )
    }
}
