//! Planning a return route: the planners, their configuration, the result and its quality numbers.

use std::fmt;
use std::str::FromStr;

use rand::Rng;
use thiserror::Error;
use trajgen::{Area, Constraints, Point, Pose, check_route};

use crate::arcs::ArcConnector;
use crate::connect::{Connect, Scene};
use crate::dubins::{DubinsConnector, lower_bound};
use crate::error::{RecoveryError, Tried};
use crate::join::{Join, RecoveryRoute};
use crate::polyline::length;
use crate::reference::{self, ReferenceConfig};
use crate::search::{self, Found, SearchConfig};
use crate::shorten::{Draft, Shortcuts, Shortening};

/// Most Dubins paths checked per shortcut, shortest first.
const SHORTCUT_TRIES: usize = 12;

/// How far (in points) the Dubins planner's Dubins shortcuts reach.
const DUBINS_WINDOW: usize = 16;

/// How far (in points) the Dubins planner's tight-arc shortcuts reach: they tighten turns, the
/// Dubins shortcuts do the long stretches.
const TIGHT_ARCS_WINDOW: usize = 16;

/// The clearances [`PlanConfig::plan_with_fallback`] tries, as fractions of the constraints'
/// clearance, in order: all of it, half, none.
pub const FALLBACK_CLEARANCE_FRACTIONS: [f64; 3] = [1.0, 0.5, 0.0];

/// Most segments of a reference arc (a sanity limit on the configuration).
const MAX_ARC_STEPS: usize = 1000;

/// Which planner to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum PlannerKind {
    /// Hybrid A* over poses with Dubins shots to any joinable point of the recovery route, then
    /// the shortening pass with Dubins and tight-arc shortcuts (the default: shorter routes, a
    /// bounded worst case). Uses no randomness.
    #[default]
    Dubins,
    /// The reference method (`docs/method.md#return-routes`): arcs and a line, random extensions,
    /// best of N attempts, then the shortening pass with arc shortcuts; aims at the recovery
    /// route's earliest joinable point.
    Reference,
}

impl PlannerKind {
    /// Every planner.
    pub const ALL: [PlannerKind; 2] = [PlannerKind::Dubins, PlannerKind::Reference];

    /// The name used on the command line (`--planner NAME`).
    pub fn name(self) -> &'static str {
        match self {
            PlannerKind::Dubins => "dubins",
            PlannerKind::Reference => "reference",
        }
    }
}

impl fmt::Display for PlannerKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Where a return route may join the recovery route.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum JoinPolicy {
    /// Anywhere it can be joined: the Dubins planner minimises the distance to the start route
    /// (the return route plus the recovery route left after the joint). The default.
    #[default]
    Anywhere,
    /// Only at its earliest joinable point, as the method does (the car then drives the whole
    /// recovery route); the reference planner always does this.
    Earliest,
}

/// A planner name that is not one of [`PlannerKind::ALL`].
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("unknown planner {name:?}: expected one of dubins, reference")]
pub struct UnknownPlanner {
    /// The name given.
    pub name: String,
}

impl FromStr for PlannerKind {
    type Err = UnknownPlanner;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        PlannerKind::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| UnknownPlanner { name: s.to_owned() })
    }
}

/// How good a return route is. Lengths in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quality {
    /// Length of the return route (car to joining point).
    pub length: f64,
    /// A proven lower bound on that length for any drivable route from the car's pose to the
    /// joint's pose: the longer of the straight line and `Dubins(from − a, to + a) − 2a` with
    /// `a = min_segment / 2` and radius `a / tan(max_turn / 2)` (1.12 m by default), the poses
    /// shifted by `a` backwards from the car and forwards from the joint. (The plain Dubins length
    /// with radius `min_segment / (2 sin(max_turn / 2))` between the unshifted poses is *not* a
    /// bound: a polyline may turn just under the limit at its very first and last point and cuts
    /// its corners; measured routes came out 5 % shorter than it.)
    pub lower_bound: f64,
    /// `length / lower_bound`.
    pub ratio: f64,
    /// Length of the return route before the shortening pass.
    pub length_before_shortening: f64,
    /// Length of the return route plus the recovery route left after the joint: the distance
    /// to the start route.
    pub total_length: f64,
    /// Lower bound on `total_length` over every point of the recovery route the car could join.
    pub total_lower_bound: f64,
    /// `total_length / total_lower_bound`.
    pub total_ratio: f64,
    /// What the planner tried (attempts, expansions, connections checked, shortening included).
    pub tried: Tried,
}

/// A planned return route.
#[derive(Debug, Clone, PartialEq)]
pub struct ReturnRoute {
    /// The route: the car's position first, the joining point last. Its first segment turns less
    /// than the limit from the car's heading; `points` followed by [`Join::next`] passes
    /// [`trajgen::check_route`] with the car's heading and [`ReturnRoute::clearance`] (see
    /// [`ReturnRoute::checked_points`]).
    pub points: Vec<Point>,
    /// Where it joins the recovery route.
    pub join: Join,
    /// The quality numbers.
    pub quality: Quality,
    /// The planner that made it.
    pub planner: PlannerKind,
    /// The clearance from every edge the route keeps, metres: the constraints' own, or less when
    /// [`PlanConfig::plan_with_fallback`] had to relax it. `points` followed by [`Join::next`]
    /// passes [`trajgen::check_route`] with the constraints and this clearance.
    pub clearance: f64,
}

impl ReturnRoute {
    /// The route with the joint: `points` then the recovery point after the joining point. This is
    /// what is checked end to end.
    pub fn checked_points(&self) -> Vec<Point> {
        let mut points = self.points.clone();
        points.push(self.join.next);
        points
    }

    /// The route the car drives to the start route: `points`, then the recovery route from the
    /// point after the joint to its end.
    pub fn joined(&self, recovery_route: &[Point]) -> Vec<Point> {
        let mut points = self.points.clone();
        points.extend(recovery_route.iter().skip(self.join.segment + 1));
        points
    }
}

/// A planner and its budgets. Build with [`PlanConfig::default`] and the `with_` methods.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PlanConfig {
    /// The planner to run.
    pub planner: PlannerKind,
    /// Where the route may join the recovery route (the reference planner: always the earliest
    /// joinable point).
    pub join_policy: JoinPolicy,
    /// The reference planner's constants.
    pub reference: ReferenceConfig,
    /// The Dubins planner's constants.
    pub search: SearchConfig,
    /// The shortening pass's constants.
    pub shortening: Shortening,
}

impl PlanConfig {
    /// This configuration with another planner.
    pub fn with_planner(self, planner: PlannerKind) -> Self {
        Self { planner, ..self }
    }

    /// This configuration with another join policy.
    pub fn with_join_policy(self, join_policy: JoinPolicy) -> Self {
        Self {
            join_policy,
            ..self
        }
    }

    /// This configuration with other reference-planner constants.
    pub fn with_reference(self, reference: ReferenceConfig) -> Self {
        Self { reference, ..self }
    }

    /// This configuration with other Dubins-planner constants.
    pub fn with_search(self, search: SearchConfig) -> Self {
        Self { search, ..self }
    }

    /// This configuration with other shortening constants.
    pub fn with_shortening(self, shortening: Shortening) -> Self {
        Self { shortening, ..self }
    }

    /// Plans a return route from `from` to `recovery_route` in `area` (see [`crate::plan`]).
    pub fn plan<R: Rng + ?Sized>(
        &self,
        area: &Area,
        from: Pose,
        recovery_route: &[Point],
        constraints: &Constraints,
        rng: &mut R,
    ) -> Result<ReturnRoute, RecoveryError> {
        check_constraints(constraints)?;
        self.check()?;
        check_pose(area, from)?;
        let recovery = match (self.planner, self.join_policy) {
            (PlannerKind::Dubins, JoinPolicy::Anywhere) => {
                RecoveryRoute::new(area, recovery_route, constraints)?
            }
            _ => RecoveryRoute::new(area, recovery_route, constraints)?.only_earliest(),
        };
        let scene = Scene { area, constraints };
        let (found, tried) = match self.planner {
            PlannerKind::Dubins => search::search(scene, &recovery, &self.search, from),
            PlannerKind::Reference => {
                let target = *recovery.earliest();
                reference::search(scene, from, target, &self.reference, rng)
            }
        };
        let found = found.ok_or(RecoveryError::NoRoute {
            planner: self.planner,
            tried,
        })?;
        let route = self.finish(scene, from, &recovery, found, tried);
        check_route(
            area,
            &route.checked_points(),
            constraints,
            Some(from.heading),
        )
        .map_err(|violation| RecoveryError::PlannedRouteInvalid { violation })?;
        Ok(route)
    }

    /// Plans like [`PlanConfig::plan`], relaxing the clearance when no route keeps it: tries
    /// the constraints' clearance, then half of it, then none ([`FALLBACK_CLEARANCE_FRACTIONS`]),
    /// and returns the first route found; its [`ReturnRoute::clearance`] says which one it keeps.
    ///
    /// This is for a car that stopped inside the clearance band (nearer an edge than the
    /// clearance, e.g. after cutting a corner): no route can start there and keep the clearance,
    /// since its first point is the car's position. A clearance larger than the car's distance to
    /// the nearest edge is skipped without planning. Only [`RecoveryError::NoRoute`] and
    /// [`RecoveryError::InvalidRecoveryRoute`] (nothing joinable with that clearance) move on to
    /// the next clearance; any other error is returned at once, and when every clearance fails
    /// the error of the last (no clearance) is returned.
    pub fn plan_with_fallback<R: Rng + ?Sized>(
        &self,
        area: &Area,
        from: Pose,
        recovery_route: &[Point],
        constraints: &Constraints,
        rng: &mut R,
    ) -> Result<ReturnRoute, RecoveryError> {
        check_constraints(constraints)?;
        check_pose(area, from)?;
        let room = area.boundary_distance(from.position);
        let mut clearances: Vec<f64> = FALLBACK_CLEARANCE_FRACTIONS
            .iter()
            .map(|fraction| constraints.clearance * fraction)
            .filter(|&clearance| clearance <= room || clearance == 0.0)
            .collect();
        clearances.dedup();
        let relaxed = |clearance: f64| Constraints {
            clearance,
            ..*constraints
        };
        let Some((&last, first)) = clearances.split_last() else {
            return self.plan(area, from, recovery_route, constraints, rng);
        };
        for &clearance in first {
            match self.plan(area, from, recovery_route, &relaxed(clearance), rng) {
                Err(error) if a_smaller_clearance_may_help(&error) => {}
                result => return result,
            }
        }
        self.plan(area, from, recovery_route, &relaxed(last), rng)
    }

    /// Checks that the constants make sense.
    pub fn check(&self) -> Result<(), RecoveryError> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let s = &self.search;
        let r = &self.reference;
        let reason = if !positive(s.cell) || !positive(s.grid_cell) || s.heading_bins == 0 {
            Some("search cells and heading bins must be positive")
        } else if s.step_lengths.is_empty() || s.turn_fractions.is_empty() || s.radii.is_empty() {
            Some("the search needs step lengths, turn fractions and radii")
        } else if !s.weight.is_finite() || s.weight < 0.0 {
            Some("the search weight must be finite and non-negative")
        } else if !positive(self.shortening.max_piece) || !positive(self.shortening.min_gain) {
            Some("the shortening's max_piece and min_gain must be positive")
        } else if !positive(r.arcs.step) || !r.arcs.turn.is_finite() || r.arcs.steps > MAX_ARC_STEPS
        {
            Some("reference arcs need a positive step, a finite turn and at most 1000 steps")
        } else if r.extension_points.0 == 0 {
            Some("reference extensions need at least one point")
        } else {
            None
        };
        reason.map_or(Ok(()), |reason| {
            Err(RecoveryError::InvalidConfig { reason })
        })
    }

    /// Shortens the route found and measures it.
    fn finish(
        &self,
        scene: Scene<'_>,
        from: Pose,
        recovery: &RecoveryRoute,
        found: Found,
        mut tried: Tried,
    ) -> ReturnRoute {
        let length_before_shortening = length(&found.points);
        let mut draft = Draft {
            scene,
            start: from,
            points: found.points,
            next: found.join.next,
            checks: 0,
        };
        let dubins = DubinsConnector::new(&self.search.radii, scene.constraints, SHORTCUT_TRIES);
        let tight_arcs = ArcConnector::tight(scene.constraints);
        let shortcuts = match self.planner {
            PlannerKind::Dubins => vec![
                Shortcuts {
                    connector: &dubins as &dyn Connect,
                    window: DUBINS_WINDOW,
                },
                Shortcuts {
                    connector: &tight_arcs,
                    window: TIGHT_ARCS_WINDOW,
                },
            ],
            PlannerKind::Reference => vec![Shortcuts {
                connector: &self.reference.arcs,
                window: usize::MAX,
            }],
        };
        draft.shorten(&shortcuts, &self.shortening);
        tried.connections += draft.checks;
        let points = draft.points;
        let quality = measure(
            scene.constraints,
            from,
            recovery,
            &points,
            found.join,
            tried,
        );
        ReturnRoute {
            points,
            join: found.join,
            quality: Quality {
                length_before_shortening,
                ..quality
            },
            planner: self.planner,
            clearance: scene.constraints.clearance,
        }
    }
}

/// The quality numbers of `points` (before-shortening length left for the caller to fill in).
fn measure(
    c: &Constraints,
    from: Pose,
    recovery: &RecoveryRoute,
    points: &[Point],
    join: Join,
    tried: Tried,
) -> Quality {
    let route_length = length(points);
    let bound = lower_bound(from, join.pose(), c);
    let total_length = route_length + join.remaining;
    let total_lower_bound = recovery
        .samples
        .iter()
        .map(|(pose, remaining)| lower_bound(from, *pose, c) + remaining)
        .fold(f64::INFINITY, f64::min);
    Quality {
        length: route_length,
        lower_bound: bound,
        ratio: route_length / bound.max(f64::MIN_POSITIVE),
        length_before_shortening: route_length,
        total_length,
        total_lower_bound,
        total_ratio: total_length / total_lower_bound.max(f64::MIN_POSITIVE),
        tried,
    }
}

/// Whether `error` may go away with a smaller clearance: no route found, or nothing of the
/// recovery route joinable with this one.
fn a_smaller_clearance_may_help(error: &RecoveryError) -> bool {
    matches!(
        error,
        RecoveryError::NoRoute { .. } | RecoveryError::InvalidRecoveryRoute { .. }
    )
}

fn check_constraints(c: &Constraints) -> Result<(), RecoveryError> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    let reason = if !positive(c.min_segment) || !positive(c.max_segment) {
        Some("segment lengths must be positive and finite")
    } else if c.min_segment > c.max_segment {
        Some("min_segment must not exceed max_segment")
    } else if !positive(c.max_turn) || c.max_turn >= std::f64::consts::PI {
        Some("max_turn must be in (0, π)")
    } else if !c.clearance.is_finite() || c.clearance < 0.0 {
        Some("clearance must be finite and non-negative")
    } else {
        None
    };
    reason.map_or(Ok(()), |reason| {
        Err(RecoveryError::InvalidConstraints { reason })
    })
}

fn check_pose(area: &Area, pose: Pose) -> Result<(), RecoveryError> {
    let p = pose.position;
    if !p.is_finite() || !pose.heading.is_finite() {
        return Err(RecoveryError::NonFinitePose);
    }
    if area.contains_point(p) {
        return Ok(());
    }
    if !area.fence().contains(p) {
        return Err(RecoveryError::PoseOutside { x: p.x, y: p.y });
    }
    match area.cutouts().iter().position(|c| c.contains(p)) {
        Some(cutout) => Err(RecoveryError::PoseInCutout {
            cutout,
            x: p.x,
            y: p.y,
        }),
        None => Err(RecoveryError::PoseOnEdge { x: p.x, y: p.y }),
    }
}
