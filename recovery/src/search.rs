//! The Dubins planner's search: a hybrid A* over poses with analytic Dubins shots to the joins.
//!
//! Nodes are poses (a point and the heading of the segment that reached it). A node is expanded
//! by straight segments of a few lengths turning a few fixed fractions of the turn limit, so every
//! edge keeps the constraints by construction; poses falling in an already reached cell (position
//! grid × heading bins) with no shorter path are dropped. The heuristic is the distance to go
//! around the obstacles ([`DistanceGrid`]). From every expanded node with a clear view of the
//! recovery route (grid distance close to the straight-line distance), discretised Dubins paths
//! are shot at the most promising joins; the best route found is kept and the search goes on for a
//! bounded number of expansions, pruning nodes that cannot beat it (by the straight-line distance
//! to go).
//! When the reachable cells run out without a route (a tight spot where the cells merged poses
//! that mattered), the search is repeated with cells half as big and twice the heading bins.

use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

use trajgen::{Point, Pose};

use crate::connect::{Connect, Scene};
use crate::dubins::{DubinsConnector, lower_bound};
use crate::error::Tried;
use crate::grid::DistanceGrid;
use crate::join::{Join, RecoveryRoute};
use crate::polyline::{distance, length, segment_is_clear};

/// The constants of the Dubins planner's search.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchConfig {
    /// Most nodes expanded before giving up (20 000).
    pub max_expansions: u64,
    /// Nodes expanded after the first route is found, looking for a shorter one (100).
    pub extra_expansions: u64,
    /// Weight of the heuristic (1.5: greedier and faster than 1).
    pub weight: f64,
    /// Side of a position cell of the closed set, metres (0.4).
    pub cell: f64,
    /// Heading bins of the closed set (24: 15° each).
    pub heading_bins: u32,
    /// Lengths of the expansion segments, metres (0.612 and 1.25; the shorter is the tightest
    /// arcs' step, see [`crate::ArcConnector::tight`]).
    pub step_lengths: Vec<f64>,
    /// Turns of the expansion segments as fractions of the turn limit (0, ±0.5, ±0.99).
    pub turn_fractions: Vec<f64>,
    /// Radii of the Dubins paths shot at the joins, metres (1.5, 2, 3, 4.5).
    pub radii: Vec<f64>,
    /// Recovery segments shot at from each node, most promising first (3).
    pub shots_per_node: usize,
    /// Side of the cells of the distance-to-go grid, metres (0.5).
    pub grid_cell: f64,
    /// A node shoots only when its grid distance to go is at most this factor times the
    /// straight-line distance to go, plus [`SearchConfig::shot_slack`] (1.3).
    pub shot_detour: f64,
    /// See [`SearchConfig::shot_detour`], metres (1.5).
    pub shot_slack: f64,
    /// Repeats with finer cells when the reachable cells run out (2).
    pub refinements: u32,
}

impl SearchConfig {
    /// The configuration for refinement `level`: cells `2^level` times smaller, heading bins
    /// `2^level` times more.
    fn refined(&self, level: u32) -> Self {
        let factor = 2f64.powi(level as i32);
        Self {
            cell: self.cell / factor,
            heading_bins: self.heading_bins.saturating_mul(1 << level.min(8)),
            ..self.clone()
        }
    }
}

impl Default for SearchConfig {
    fn default() -> Self {
        Self {
            max_expansions: 20_000,
            extra_expansions: 100,
            weight: 1.5,
            cell: 0.4,
            heading_bins: 24,
            step_lengths: vec![0.612, 1.25],
            turn_fractions: vec![0.0, 0.5, -0.5, 0.99, -0.99],
            radii: vec![1.5, 2.0, 3.0, 4.5],
            shots_per_node: 3,
            grid_cell: 0.5,
            shot_detour: 1.3,
            shot_slack: 1.5,
            refinements: 2,
        }
    }
}

/// Runs the search from `start`, refining on exhaustion; the best route found and what was tried.
pub(crate) fn search(
    scene: Scene<'_>,
    recovery: &RecoveryRoute,
    config: &SearchConfig,
    start: Pose,
) -> (Option<Found>, Tried) {
    let grid = DistanceGrid::new(scene.area, &recovery.joins, config.grid_cell);
    let mut tried = Tried::default();
    for level in 0..=config.refinements {
        let refined = config.refined(level);
        let budget = config.max_expansions.saturating_sub(tried.expansions);
        let search = Search::new(scene, recovery, &refined, &grid, start, budget);
        let (found, level_tried, exhausted) = search.run();
        tried.attempts += 1;
        tried.expansions += level_tried.expansions;
        tried.connections += level_tried.connections;
        if found.is_some() || !exhausted {
            return (found, tried);
        }
    }
    (None, tried)
}

/// A route found by the search.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Found {
    /// The car's position first, the joining point last.
    pub points: Vec<Point>,
    /// The join.
    pub join: Join,
}

#[derive(Debug, Clone, Copy)]
struct Node {
    pose: Pose,
    g: f64,
    parent: Option<usize>,
}

/// An open-list entry, ordered by `f` (smallest first), then by insertion order.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Open {
    f: f64,
    seq: u64,
    node: usize,
}

impl Eq for Open {}

impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .f
            .total_cmp(&self.f)
            .then_with(|| other.seq.cmp(&self.seq))
    }
}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// The best route so far: its total cost (route + recovery left), the node it leaves the search
/// tree from, the Dubins piece and the join.
struct Best {
    cost: f64,
    node: usize,
    piece: Vec<Point>,
    join: Join,
}

/// One search from the car's pose.
struct Search<'a> {
    scene: Scene<'a>,
    recovery: &'a RecoveryRoute,
    config: &'a SearchConfig,
    grid: &'a DistanceGrid,
    budget: u64,
    connector: DubinsConnector,
    nodes: Vec<Node>,
    open: BinaryHeap<Open>,
    closed: HashMap<(i64, i64, i64), f64>,
    best: Option<Best>,
    tried: Tried,
}

impl<'a> Search<'a> {
    /// A search from `start` to `recovery` expanding at most `budget` nodes.
    fn new(
        scene: Scene<'a>,
        recovery: &'a RecoveryRoute,
        config: &'a SearchConfig,
        grid: &'a DistanceGrid,
        start: Pose,
        budget: u64,
    ) -> Self {
        let mut search = Self {
            scene,
            recovery,
            config,
            grid,
            budget,
            connector: DubinsConnector::new(&config.radii, scene.constraints, usize::MAX),
            nodes: Vec::new(),
            open: BinaryHeap::new(),
            closed: HashMap::new(),
            best: None,
            tried: Tried::default(),
        };
        search.push(start, 0.0, None);
        search
    }

    /// Runs the search: the best route found, what was tried, and whether the reachable cells
    /// ran out (rather than the budget or the search after the first route).
    fn run(mut self) -> (Option<Found>, Tried, bool) {
        let mut since_best = 0;
        let mut exhausted = true;
        while let Some(open) = self.open.pop() {
            if self.tried.expansions >= self.budget {
                exhausted = false;
                break;
            }
            let node = self.nodes[open.node];
            if let Some(best) = &self.best {
                if node.g + self.straight_to_go(node.pose.position) >= best.cost {
                    continue;
                }
                if since_best >= self.config.extra_expansions {
                    exhausted = false;
                    break;
                }
                since_best += 1;
            }
            self.tried.expansions += 1;
            if self.has_clear_view(node.pose.position) && self.shoot(open.node) {
                since_best = 0;
            }
            self.expand(open.node);
        }
        let found = self.best.as_ref().map(|b| self.route(b));
        (found, self.tried, exhausted)
    }

    /// The search's estimate of the cost left from `p`: the grid's distance to go, or the
    /// straight-line one where the grid has none.
    fn heuristic(&self, p: Point) -> f64 {
        let around = self.grid.at(p);
        if around.is_finite() {
            around
        } else {
            self.straight_to_go(p)
        }
    }

    /// Whether the grid's distance to go from `p` is close to the straight-line one: nothing big
    /// in between, so a Dubins shot has a chance.
    fn has_clear_view(&self, p: Point) -> bool {
        let straight = self.straight_to_go(p);
        let around = self.grid.at(p);
        !around.is_finite() || around <= self.config.shot_detour * straight + self.config.shot_slack
    }

    /// Lower bound on the cost left from `p`: straight to a join, then the recovery route.
    fn straight_to_go(&self, p: Point) -> f64 {
        self.recovery
            .joins
            .iter()
            .map(|j| distance(p, j.point) + j.remaining)
            .fold(f64::INFINITY, f64::min)
    }

    fn push(&mut self, pose: Pose, g: f64, parent: Option<usize>) {
        let key = self.cell_of(pose);
        if let Some(&known) = self.closed.get(&key)
            && known <= g
        {
            return;
        }
        self.closed.insert(key, g);
        let node = self.nodes.len();
        self.nodes.push(Node { pose, g, parent });
        let f = g + self.config.weight * self.heuristic(pose.position);
        self.open.push(Open {
            f,
            seq: node as u64,
            node,
        });
    }

    fn cell_of(&self, pose: Pose) -> (i64, i64, i64) {
        let bins = f64::from(self.config.heading_bins);
        let turn = pose.heading.rem_euclid(std::f64::consts::TAU);
        (
            (pose.position.x / self.config.cell).floor() as i64,
            (pose.position.y / self.config.cell).floor() as i64,
            (turn / std::f64::consts::TAU * bins).floor() as i64,
        )
    }

    /// Children: every step length and turn fraction whose segment stays in the area.
    fn expand(&mut self, index: usize) {
        let node = self.nodes[index];
        let c = self.scene.constraints;
        let steps = self.config.step_lengths.iter().copied();
        let steps = steps.filter(|s| (c.min_segment..=c.max_segment).contains(s));
        for step in steps {
            let fractions = self.config.turn_fractions.iter().copied();
            for fraction in fractions.filter(|f| f.abs() < 1.0) {
                let heading = node.pose.heading + fraction * c.max_turn;
                let p = node.pose.position + Point::from_heading(heading) * step;
                if segment_is_clear(
                    self.scene.area,
                    self.scene.constraints,
                    node.pose.position,
                    p,
                ) {
                    self.push(Pose::new(p, heading), node.g + step, Some(index));
                }
            }
        }
    }

    /// Shoots Dubins paths from node `index` at the best join of the most promising recovery
    /// segments; whether a better route was found.
    fn shoot(&mut self, index: usize) -> bool {
        let node = self.nodes[index];
        let mut improved = false;
        for join in self.promising_joins(node.pose.position) {
            let budget = self.best.as_ref().map_or(f64::INFINITY, |b| b.cost);
            let max_length = budget - node.g - join.remaining;
            if distance(node.pose.position, join.point) >= max_length
                || lower_bound(node.pose, join.pose(), self.scene.constraints) >= max_length
            {
                continue;
            }
            let Some(piece) = self.connector.connect(
                self.scene,
                node.pose,
                join.target(),
                max_length,
                &mut self.tried.connections,
            ) else {
                continue;
            };
            let cost =
                node.g + distance(node.pose.position, piece[0]) + length(&piece) + join.remaining;
            self.best = Some(Best {
                cost,
                node: index,
                piece,
                join,
            });
            improved = true;
        }
        improved
    }

    /// For each recovery segment its join with the smallest straight-line cost from `p`; the
    /// `shots_per_node` best.
    fn promising_joins(&self, p: Point) -> Vec<Join> {
        let mut per_segment: Vec<(f64, Join)> = Vec::new();
        for join in &self.recovery.joins {
            let cost = distance(p, join.point) + join.remaining;
            match per_segment
                .iter_mut()
                .find(|(_, j)| j.segment == join.segment)
            {
                Some(slot) if cost < slot.0 => *slot = (cost, *join),
                Some(_) => {}
                None => per_segment.push((cost, *join)),
            }
        }
        per_segment.sort_by(|a, b| a.0.total_cmp(&b.0));
        per_segment
            .into_iter()
            .take(self.config.shots_per_node)
            .map(|(_, j)| j)
            .collect()
    }

    /// The route of `best`: the tree path to its node, then its Dubins piece.
    fn route(&self, best: &Best) -> Found {
        let mut points = Vec::new();
        let mut at = Some(best.node);
        while let Some(i) = at {
            points.push(self.nodes[i].pose.position);
            at = self.nodes[i].parent;
        }
        points.reverse();
        points.extend_from_slice(&best.piece);
        Found {
            points,
            join: best.join,
        }
    }
}
