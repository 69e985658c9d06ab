//! The reference planner (`docs/method.md#return-routes`): arcs and a line from the car, else
//! random extensions from the car and arcs and a line from their end; best of N attempts with
//! pruning.
//!
//! It aims at a single target, the earliest joinable point of the recovery route, as the method
//! does (the car then drives the whole recovery route).

use rand::{Rng, RngExt};
use trajgen::{Generator, GeneratorConfig, Point, Pose, RouteTail};

use crate::arcs::ArcConnector;
use crate::connect::{Connect, Scene};
use crate::error::Tried;
use crate::join::Join;
use crate::polyline::length;
use crate::search::Found;

/// The constants of the reference planner. The defaults are the method's.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceConfig {
    /// Attempts, each a chain of random extensions; the shortest route wins (100).
    pub attempts: u32,
    /// Fewest and most random extensions per attempt, drawn per attempt (80 and 120).
    pub extensions: (u32, u32),
    /// Fewest and most points per random extension, drawn per extension (4 and 5).
    pub extension_points: (usize, usize),
    /// The generator's ahead margin for the random extensions (15).
    pub ahead_margin: usize,
    /// The arcs-and-line connector.
    pub arcs: ArcConnector,
}

impl Default for ReferenceConfig {
    fn default() -> Self {
        Self {
            attempts: 100,
            extensions: (80, 120),
            extension_points: (4, 5),
            ahead_margin: 15,
            arcs: ArcConnector::default(),
        }
    }
}

/// Runs the reference search from `start` to `join`.
pub(crate) fn search<R: Rng + ?Sized>(
    scene: Scene<'_>,
    start: Pose,
    join: Join,
    config: &ReferenceConfig,
    rng: &mut R,
) -> (Option<Found>, Tried) {
    let mut tried = Tried::default();
    let direct = config.arcs.connect(
        scene,
        start,
        join.target(),
        f64::INFINITY,
        &mut tried.connections,
    );
    if let Some(piece) = direct {
        tried.attempts = 1;
        let mut points = vec![start.position];
        points.extend(piece);
        return (Some(Found { points, join }), tried);
    }
    let generator = match Generator::new(
        GeneratorConfig::default()
            .with_constraints(*scene.constraints)
            .with_ahead_margin(config.ahead_margin),
    ) {
        Ok(generator) => generator,
        Err(_) => return (None, tried),
    };
    let mut best: Option<Vec<Point>> = None;
    for _ in 0..config.attempts {
        tried.attempts += 1;
        let bound = best.as_deref().map_or(f64::INFINITY, length);
        let attempt = Attempt {
            scene,
            join,
            config,
            generator: &generator,
        };
        if let Some(route) = attempt.run(start, bound, rng, &mut tried) {
            best = Some(route);
        }
    }
    (best.map(|points| Found { points, join }), tried)
}

/// One attempt: random extensions from the car until arcs and a line reach the target.
struct Attempt<'a> {
    scene: Scene<'a>,
    join: Join,
    config: &'a ReferenceConfig,
    generator: &'a Generator,
}

impl Attempt<'_> {
    /// A route shorter than `bound`, or `None` (pruned, stuck or out of extensions).
    fn run<R: Rng + ?Sized>(
        &self,
        start: Pose,
        bound: f64,
        rng: &mut R,
        tried: &mut Tried,
    ) -> Option<Vec<Point>> {
        let (low, high) = self.config.extensions;
        let extensions = rng.random_range(low..=high.max(low));
        let mut route = vec![start.position];
        let mut tail = RouteTail::from_pose(start);
        for _ in 0..extensions {
            let (low, high) = self.config.extension_points;
            let n = rng.random_range(low..=high.max(low));
            tried.expansions += 1;
            let extension = self.generator.extend(self.scene.area, &tail, n, rng).ok()?;
            route.extend_from_slice(&extension.points);
            tail = extension.next_tail;
            let so_far = length(&route);
            if so_far >= bound {
                return None;
            }
            let piece = self.config.arcs.connect(
                self.scene,
                tail.pose(),
                self.join.target(),
                bound - so_far,
                &mut tried.connections,
            );
            if let Some(piece) = piece {
                route.extend(piece);
                return Some(route);
            }
        }
        None
    }
}
