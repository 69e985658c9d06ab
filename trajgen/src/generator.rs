//! The random drivable trajectory generator of the method (`docs/method.md#drivable-trajectories`),
//! with the ahead margin.
//!
//! A [`Generator`] extends a route (given by its [`RouteTail`]: the last point and the heading of
//! the last segment, or a car's [`Pose`]) by `n` points. It generates `n + ahead_margin` points and
//! keeps the first `n`: the rest is the [`Extension::margin`], the proof that a drivable
//! continuation exists after what is sent to the car. Every point satisfies the [`Constraints`],
//! including the turn at the joint with the existing route. When no extension is found within the
//! configured tries the result is [`GenerationError::GenerationFailed`] — never a short or empty
//! extension.
//!
//! Two strategies ([`Strategy`]):
//! - [`Strategy::Reference`]: the method's algorithm as written — three rays clipped at the closest
//!   boundary hit, the bounding box of their ends, uniform sampling in the box, `inner_tries` per
//!   point, and on a dead end a restart of the whole `n + margin` extension (an *outer try*) — with
//!   the reference implementation's defects fixed (closing edges tested, closest hit, the whole
//!   segment tested, exact length limits).
//! - [`Strategy::Wedge`] (the default): samples a heading in the open ±`max_turn` wedge, clips the
//!   ray in that direction at the boundary and samples the length in the part of the
//!   `min_segment..=max_segment` annulus that is free, so almost every sample is valid. Among
//!   valid candidates it prefers *loopable* ones: points from which the car could circle forever
//!   on the sharpest allowed circle (0.6 m chords turning just under 30°, radius ≈ 1.16 m) because
//!   that circle's disc is free of every edge; when none of the first few candidates is loopable
//!   it follows that circle for one point. The margin is closed as soon as its state is loopable,
//!   by the circle itself (every margin segment is checked like any other); otherwise the margin
//!   search continues, steered towards open space (the best of a few candidates by free distance
//!   along a longer probe ray). When the first candidates are all blocked, a fan of rays across
//!   the wedge tells whether the point is stuck in a corner (a dead end at once; at the route's
//!   own end, a failure at once, since no retry can change it). A dead end backtracks 1, 2, 4, …
//!   points (the step resets when a new deepest point is reached) instead of restarting the whole
//!   extension.
//!
//!   Consequence: from a loopable tail a continuation of any length always exists (the circle) and
//!   the search finds one without dead ends, so on the real areas every extension needs one outer
//!   try. The price: the generator does not enter places where the car could not turn around (a
//!   dead-end corridor narrower than ≈ 2.3 m) when it has a choice; area validation's coverage
//!   shows such places. In an area without loopable states (a narrow corridor) it falls back to
//!   random search with backtracking.
//!
//! In both strategies an *outer try* is one attempt that ends in a dead end or in success:
//! `outer_tries == 1` means no dead end was met. The limit `outer_tries` bounds the dead ends.
//!
//! Everything is deterministic given the RNG; nothing here allocates per sample.

use rand::{Rng, RngExt};
use thiserror::Error;

use crate::constraints::{Constraints, turn_violation};
use crate::geometry::{Area, Point};

/// How points are sampled and what happens at a dead end.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Strategy {
    /// The method's algorithm as written (box sampling, restart the whole extension on a dead
    /// end), with the reference implementation's defects fixed. Kept for comparison.
    Reference,
    /// Wedge-and-annulus sampling clipped to the area, preferring points from which the car could
    /// circle forever, margins closed by that circle, backtracking on dead ends (see the module
    /// doc).
    #[default]
    Wedge,
}

/// The generator's named constants. The defaults are the method's
/// (`docs/method.md#drivable-trajectories`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeneratorConfig {
    /// Segment lengths, turn limit and clearance every generated segment respects.
    pub constraints: Constraints,
    /// Reference strategy: length of the three rays cast from the last point, metres (2.0).
    pub ray_length: f64,
    /// Reference strategy: a sampling box with a shorter diagonal means "stuck in a corner",
    /// metres (0.6).
    pub stuck_diagonal: f64,
    /// Candidate points tried for one point before the attempt is a dead end (50).
    pub inner_tries: u32,
    /// Most attempts (outer tries) per extension before [`GenerationError::GenerationFailed`]
    /// (5000).
    pub outer_tries: u32,
    /// Points generated after the kept ones to prove a continuation exists (20; recovery routes
    /// use 15).
    pub ahead_margin: usize,
    /// Wedge strategy: length of the probe ray that scores margin candidates by free distance,
    /// metres (4.0).
    pub margin_probe: f64,
    /// Wedge strategy: valid candidates compared for each margin point (3; 1 = no steering).
    pub margin_candidates: u32,
    /// Wedge strategy: after this many margin points, try to finish the margin by circling at
    /// the sharpest turn (a state from which the car can circle forever); `None`: never.
    pub margin_loop_after: Option<usize>,
    /// Wedge strategy: prefer points from which the car could circle forever (a disc of the
    /// sharpest turning circle is free beside it) among the first `loop_preference_tries`
    /// candidates, and follow that circle when no random candidate qualifies. Keeps the random
    /// walk out of states that can only end at a wall (true).
    pub prefer_loopable: bool,
    /// Wedge strategy: candidates tried for a loopable point before settling for any valid one
    /// (12).
    pub loop_preference_tries: u32,
    /// The sampling strategy.
    pub strategy: Strategy,
}

impl Default for GeneratorConfig {
    fn default() -> Self {
        Self {
            constraints: Constraints::default(),
            ray_length: 2.0,
            stuck_diagonal: 0.6,
            inner_tries: 50,
            outer_tries: 5000,
            ahead_margin: 20,
            margin_probe: 4.0,
            margin_candidates: 3,
            margin_loop_after: Some(0),
            prefer_loopable: true,
            loop_preference_tries: 12,
            strategy: Strategy::default(),
        }
    }
}

impl GeneratorConfig {
    /// This configuration with another strategy.
    pub fn with_strategy(self, strategy: Strategy) -> Self {
        Self { strategy, ..self }
    }

    /// This configuration with another ahead margin.
    pub fn with_ahead_margin(self, ahead_margin: usize) -> Self {
        Self {
            ahead_margin,
            ..self
        }
    }

    /// This configuration with other constraints.
    pub fn with_constraints(self, constraints: Constraints) -> Self {
        Self {
            constraints,
            ..self
        }
    }

    /// Checks that the constants make sense (positive, finite, `min_segment ≤ max_segment`, turn
    /// limit in (0, π), at least one inner and one outer try).
    pub fn check(&self) -> Result<(), GenerationError> {
        let c = &self.constraints;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let reason = if !positive(c.min_segment) || !positive(c.max_segment) {
            Some("segment lengths must be positive and finite")
        } else if c.min_segment > c.max_segment {
            Some("min_segment must not exceed max_segment")
        } else if !positive(c.max_turn) || c.max_turn >= std::f64::consts::PI {
            Some("max_turn must be in (0, π)")
        } else if !c.clearance.is_finite() || c.clearance < 0.0 {
            Some("clearance must be finite and non-negative")
        } else if !positive(self.ray_length) || !positive(self.margin_probe) {
            Some("ray_length and margin_probe must be positive and finite")
        } else if !self.stuck_diagonal.is_finite() || self.stuck_diagonal < 0.0 {
            Some("stuck_diagonal must be finite and non-negative")
        } else if self.inner_tries == 0 || self.outer_tries == 0 || self.margin_candidates == 0 {
            Some("inner_tries, outer_tries and margin_candidates must be at least 1")
        } else {
            None
        };
        match reason {
            Some(reason) => Err(GenerationError::InvalidConfig { reason }),
            None => Ok(()),
        }
    }
}

/// A car's pose: where it stands and where it points.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// Position, local ENU metres.
    pub position: Point,
    /// Heading, radians counter-clockwise from east.
    pub heading: f64,
}

impl Pose {
    /// A pose from a position and a heading.
    pub const fn new(position: Point, heading: f64) -> Self {
        Self { position, heading }
    }
}

/// What an extension continues from: the route's last point and the heading of its last segment
/// (or a car's pose). The first generated segment must turn less than `max_turn` from `heading`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RouteTail {
    /// The last point of the route.
    pub end: Point,
    /// Heading of the last segment (or the car), radians counter-clockwise from east.
    pub heading: f64,
}

impl RouteTail {
    /// The tail of a route: its last point and the heading of its last segment. Needs at least two
    /// points, finite, the last two distinct.
    pub fn from_points(points: &[Point]) -> Result<Self, GenerationError> {
        let [.., prev, end] = points else {
            return Err(GenerationError::InvalidTail {
                reason: "a route tail needs at least two points",
            });
        };
        if !prev.is_finite() || !end.is_finite() {
            return Err(GenerationError::InvalidTail {
                reason: "the route tail has a non-finite coordinate",
            });
        }
        if prev == end {
            return Err(GenerationError::InvalidTail {
                reason: "the last two points of the route coincide",
            });
        }
        Ok(Self {
            end: *end,
            heading: (*end - *prev).heading(),
        })
    }

    /// The tail of a car standing at `pose`.
    pub fn from_pose(pose: Pose) -> Self {
        Self {
            end: pose.position,
            heading: pose.heading,
        }
    }

    /// The tail after appending `points` to the route (unchanged when `points` is empty).
    pub fn advanced(&self, points: &[Point]) -> Self {
        match points {
            [] => *self,
            [only] => Self {
                end: *only,
                heading: (*only - self.end).heading(),
            },
            [.., prev, end] => Self {
                end: *end,
                heading: (*end - *prev).heading(),
            },
        }
    }

    /// The tail as a pose.
    pub fn pose(&self) -> Pose {
        Pose::new(self.end, self.heading)
    }
}

impl From<Pose> for RouteTail {
    fn from(pose: Pose) -> Self {
        Self::from_pose(pose)
    }
}

/// What one call of [`Generator::extend`] cost.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ExtensionStats {
    /// Attempts: 1 + the number of dead ends met (each dead end restarts the extension in the
    /// reference strategy, backtracks a few points in the wedge strategy).
    pub outer_tries: u32,
    /// Candidate points drawn, over all attempts.
    pub inner_tries: u64,
    /// Candidate points accepted (placed), including ones later discarded.
    pub samples: u64,
    /// Placed points discarded by restarts or backtracking.
    pub backtracks: u64,
    /// Rays clipped against the area.
    pub rays: u64,
    /// Dead ends because the route's end was stuck in a corner: the reference's sampling box was
    /// too small, or every ray of a fan across the wedge was blocked within `min_segment`.
    pub stuck: u32,
    /// Wedge strategy: points placed on the sharpest circle because no random candidate kept the
    /// car able to circle (including ones later discarded).
    pub loop_steps: u64,
    /// Wedge strategy: margins finished by a verified loop.
    pub margin_loops: u32,
}

impl ExtensionStats {
    /// Adds `other` to these statistics (for sums over several extensions).
    pub fn absorb(&mut self, other: &ExtensionStats) {
        self.outer_tries += other.outer_tries;
        self.inner_tries += other.inner_tries;
        self.samples += other.samples;
        self.backtracks += other.backtracks;
        self.rays += other.rays;
        self.stuck += other.stuck;
        self.loop_steps += other.loop_steps;
        self.margin_loops += other.margin_loops;
    }
}

/// A successful extension: exactly `n` points to send, and the margin that proves a continuation.
#[derive(Debug, Clone, PartialEq)]
pub struct Extension {
    /// The new points, exactly `n`, continuing the tail.
    pub points: Vec<Point>,
    /// The ahead-margin continuation after `points`, exactly `ahead_margin` points; discarded, it
    /// only proves the route can go on.
    pub margin: Vec<Point>,
    /// The tail after `points` (what the next extension continues from).
    pub next_tail: RouteTail,
    /// What it cost.
    pub stats: ExtensionStats,
}

/// Why no extension was produced.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GenerationError {
    /// Every outer try met a dead end.
    #[error(
        "no drivable extension of {needed} points from ({x:.3}, {y:.3}) after {outer_tries} outer \
         tries ({inner_tries} inner tries; at most {reached} points placed)",
        x = at.x,
        y = at.y
    )]
    GenerationFailed {
        /// Outer tries used: the limit, or fewer when the route's own end is stuck in a corner
        /// (wedge strategy: every ray across the turn wedge blocked within `min_segment`), which
        /// no retry can change.
        outer_tries: u32,
        /// Candidate points drawn over all attempts.
        inner_tries: u64,
        /// Where the route stands: the tail's end.
        at: Point,
        /// Most points placed in any attempt.
        reached: usize,
        /// Points needed (`n + ahead_margin`).
        needed: usize,
        /// Full statistics of the failed call.
        stats: ExtensionStats,
    },
    /// The tail's end is not strictly inside the drivable region.
    #[error("the route ends at ({x:.3}, {y:.3}), outside the area", x = at.x, y = at.y)]
    TailOutside {
        /// The tail's end.
        at: Point,
    },
    /// The tail cannot be continued (too few points, coinciding or non-finite points).
    #[error("invalid route tail: {reason}")]
    InvalidTail {
        /// What is wrong.
        reason: &'static str,
    },
    /// The request or configuration makes no sense.
    #[error("invalid generator configuration: {reason}")]
    InvalidConfig {
        /// What is wrong.
        reason: &'static str,
    },
}

/// The trajectory generator: a checked [`GeneratorConfig`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Generator {
    config: GeneratorConfig,
}

/// The route being built: the tail, the points placed so far and their headings.
struct Buffer {
    tail: RouteTail,
    points: Vec<Point>,
    headings: Vec<f64>,
}

impl Buffer {
    fn new(tail: RouteTail, capacity: usize) -> Self {
        Self {
            tail,
            points: Vec::with_capacity(capacity),
            headings: Vec::with_capacity(capacity),
        }
    }

    fn len(&self) -> usize {
        self.points.len()
    }

    /// The last point and the heading of the last segment.
    fn head(&self) -> (Point, f64) {
        match (self.points.last(), self.headings.last()) {
            (Some(&p), Some(&h)) => (p, h),
            _ => (self.tail.end, self.tail.heading),
        }
    }

    fn push(&mut self, q: Point) {
        let (p, _) = self.head();
        self.headings.push((q - p).heading());
        self.points.push(q);
    }

    fn truncate(&mut self, len: usize) {
        self.points.truncate(len);
        self.headings.truncate(len);
    }
}

impl Generator {
    /// A generator with checked constants.
    pub fn new(config: GeneratorConfig) -> Result<Self, GenerationError> {
        config.check()?;
        Ok(Self { config })
    }

    /// The constants.
    pub fn config(&self) -> &GeneratorConfig {
        &self.config
    }

    /// Extends the route ending in `tail` by exactly `n ≥ 1` points, with the ahead margin.
    ///
    /// Every returned point (and margin point) keeps the constraints: segment lengths within
    /// `min_segment..=max_segment`, turns (including the first, from `tail.heading`) below
    /// `max_turn`, every segment inside the fence and outside the cutouts with the clearance.
    pub fn extend<R: Rng + ?Sized>(
        &self,
        area: &Area,
        tail: &RouteTail,
        n: usize,
        rng: &mut R,
    ) -> Result<Extension, GenerationError> {
        if n == 0 {
            return Err(GenerationError::InvalidConfig {
                reason: "an extension needs at least one point",
            });
        }
        if !tail.end.is_finite() || !tail.heading.is_finite() {
            return Err(GenerationError::InvalidTail {
                reason: "the route tail has a non-finite coordinate or heading",
            });
        }
        if !area.contains_point(tail.end) {
            return Err(GenerationError::TailOutside { at: tail.end });
        }
        let total = n + self.config.ahead_margin;
        let mut buffer = Buffer::new(*tail, total);
        let mut stats = ExtensionStats::default();
        let outcome = match self.config.strategy {
            Strategy::Reference => self.search_reference(area, &mut buffer, total, rng, &mut stats),
            Strategy::Wedge => self.search_wedge(area, &mut buffer, n, total, rng, &mut stats),
        };
        match outcome {
            Ok(()) => {
                let mut points = buffer.points;
                let margin = points.split_off(n);
                Ok(Extension {
                    next_tail: tail.advanced(&points),
                    points,
                    margin,
                    stats,
                })
            }
            Err(reached) => Err(GenerationError::GenerationFailed {
                outer_tries: stats.outer_tries,
                inner_tries: stats.inner_tries,
                at: tail.end,
                reached,
                needed: total,
                stats,
            }),
        }
    }

    /// Extends from a car standing at `pose` (a return route's start): the first segment turns
    /// less than `max_turn` from the car's heading.
    pub fn extend_from_pose<R: Rng + ?Sized>(
        &self,
        area: &Area,
        pose: Pose,
        n: usize,
        rng: &mut R,
    ) -> Result<Extension, GenerationError> {
        self.extend(area, &RouteTail::from_pose(pose), n, rng)
    }

    /// Generates `points` in extensions of `n` each (the last one shorter if needed), continuing
    /// each from the previous; the returned extension has all points, the last margin and the
    /// summed statistics.
    pub fn extend_many<R: Rng + ?Sized>(
        &self,
        area: &Area,
        tail: &RouteTail,
        points: usize,
        n: usize,
        rng: &mut R,
    ) -> Result<Extension, GenerationError> {
        if points == 0 || n == 0 {
            return Err(GenerationError::InvalidConfig {
                reason: "an extension needs at least one point",
            });
        }
        let mut all = Vec::with_capacity(points);
        let mut current = *tail;
        let mut stats = ExtensionStats::default();
        let mut margin = Vec::new();
        while all.len() < points {
            let ext = self.extend(area, &current, n.min(points - all.len()), rng)?;
            stats.absorb(&ext.stats);
            all.extend_from_slice(&ext.points);
            current = ext.next_tail;
            margin = ext.margin;
        }
        Ok(Extension {
            points: all,
            margin,
            next_tail: current,
            stats,
        })
    }

    /// Whether the segment `p → q`, continuing heading `heading`, keeps every constraint. Uses the
    /// same arithmetic as [`crate::check_route`], so accepted points always pass it.
    fn accepts(&self, area: &Area, p: Point, heading: f64, q: Point) -> bool {
        let c = &self.config.constraints;
        let length = p.dist(q);
        if !(length >= c.min_segment && length <= c.max_segment) {
            return false;
        }
        if turn_violation(0, heading, (q - p).heading(), c).is_some() {
            return false;
        }
        if area.segment_meets_boundary(p, q) {
            return false;
        }
        c.clearance <= 0.0
            || area
                .segment_boundary_distance_below(p, q, c.clearance)
                .is_none()
    }

    /// The reference search: restart the whole extension on a dead end. On failure returns the
    /// most points placed in one attempt.
    fn search_reference<R: Rng + ?Sized>(
        &self,
        area: &Area,
        buffer: &mut Buffer,
        total: usize,
        rng: &mut R,
        stats: &mut ExtensionStats,
    ) -> Result<(), usize> {
        let mut reached = 0;
        for outer in 1..=self.config.outer_tries {
            stats.outer_tries = outer;
            buffer.truncate(0);
            while buffer.len() < total {
                let (p, h) = buffer.head();
                match self.reference_point(area, p, h, rng, stats) {
                    Some(q) => buffer.push(q),
                    None => break,
                }
            }
            if buffer.len() == total {
                return Ok(());
            }
            reached = reached.max(buffer.len());
            stats.backtracks += buffer.len() as u64;
        }
        Err(reached)
    }

    /// One point by the reference method: three clipped rays, their box, uniform box sampling.
    fn reference_point<R: Rng + ?Sized>(
        &self,
        area: &Area,
        p: Point,
        heading: f64,
        rng: &mut R,
        stats: &mut ExtensionStats,
    ) -> Option<Point> {
        let turn = self.config.constraints.max_turn;
        let (mut min, mut max) = (p, p);
        for angle in [heading, heading + turn, heading - turn] {
            let end = area.clip_ray(p, p + Point::from_heading(angle) * self.config.ray_length);
            stats.rays += 1;
            min = Point::new(min.x.min(end.x), min.y.min(end.y));
            max = Point::new(max.x.max(end.x), max.y.max(end.y));
        }
        if min.dist(max) < self.config.stuck_diagonal {
            stats.stuck += 1;
            return None;
        }
        let size = max - min;
        for _ in 0..self.config.inner_tries {
            stats.inner_tries += 1;
            let q = Point::new(
                min.x + rng.random::<f64>() * size.x,
                min.y + rng.random::<f64>() * size.y,
            );
            if self.accepts(area, p, heading, q) {
                stats.samples += 1;
                return Some(q);
            }
        }
        None
    }

    /// The wedge search: backtrack 1, 2, 4, … points on a dead end (the step resets whenever a
    /// new deepest point is reached). On failure returns the most points placed.
    fn search_wedge<R: Rng + ?Sized>(
        &self,
        area: &Area,
        buffer: &mut Buffer,
        n: usize,
        total: usize,
        rng: &mut R,
        stats: &mut ExtensionStats,
    ) -> Result<(), usize> {
        stats.outer_tries = 1;
        let mut reached = 0;
        let mut step = 1;
        while buffer.len() < total {
            let loop_from = self.config.margin_loop_after.map(|k| n + k);
            if loop_from.is_some_and(|from| buffer.len() >= from)
                && self.close_with_loop(area, buffer, total, rng)
            {
                stats.margin_loops += 1;
                break;
            }
            let (p, h) = buffer.head();
            let steer = buffer.len() >= n && self.config.margin_candidates > 1;
            let stuck_before = stats.stuck;
            if let Some(q) = self.wedge_point(area, p, h, steer, rng, stats) {
                buffer.push(q);
                if buffer.len() > reached {
                    reached = buffer.len();
                    step = 1;
                }
                continue;
            }
            // Stuck at the route's own end: retrying cannot change a blocked wedge.
            if buffer.len() == 0
                && (stats.stuck > stuck_before || self.wedge_blocked(area, p, h, stats))
            {
                return Err(reached);
            }
            if stats.outer_tries >= self.config.outer_tries {
                return Err(reached);
            }
            stats.outer_tries += 1;
            let back = step.min(buffer.len());
            buffer.truncate(buffer.len() - back);
            stats.backtracks += back as u64;
            step = (step * 2).min(total);
        }
        Ok(())
    }

    /// Whether every ray of a fan across the turn wedge meets the boundary (or comes within the
    /// clearance of it) before `min_segment`: the route's end is stuck in a corner, like the
    /// reference's too-small box. Deterministic; counts in [`ExtensionStats::stuck`] when true.
    fn wedge_blocked(
        &self,
        area: &Area,
        p: Point,
        heading: f64,
        stats: &mut ExtensionStats,
    ) -> bool {
        let c = &self.config.constraints;
        let half = c.max_turn * (1.0 - 1e-9);
        let reach = c.min_segment + c.clearance + 1e-9;
        let blocked = (0..BLOCKED_FAN).all(|k| {
            let angle = heading + half * (2.0 * k as f64 / (BLOCKED_FAN - 1) as f64 - 1.0);
            let far = p + Point::from_heading(angle) * reach;
            stats.rays += 1;
            area.clip_ray(p, far) != far
        });
        stats.stuck += u32::from(blocked);
        blocked
    }

    /// The sharpest circle the car can drive: (turn per point, segment length, circumradius).
    /// The turn and length are a hair inside the limits so that float rounding never breaks them.
    fn loop_shape(&self) -> (f64, f64, f64) {
        let c = &self.config.constraints;
        let turn = c.max_turn * (1.0 - 1e-6);
        let length = c.min_segment + (c.max_segment - c.min_segment) * 1e-6;
        (turn, length, length / (2.0 * (turn / 2.0).sin()))
    }

    /// Whether the car at `q`, having arrived with `heading`, can circle forever turning to
    /// `side` (+1 left, −1 right): the disc of the loop's circumcircle (through `q`, tangent
    /// halfway between the incoming and outgoing chords) keeps the clearance from every edge.
    /// A sufficient test: the disc is connected and contains `q`, so it lies in the area.
    fn can_loop(&self, area: &Area, q: Point, heading: f64, side: f64) -> bool {
        let (turn, _, radius) = self.loop_shape();
        let normal = heading + side * (turn / 2.0 + std::f64::consts::FRAC_PI_2);
        let centre = q + Point::from_heading(normal) * radius;
        disc_is_free(
            area,
            centre,
            radius + self.config.constraints.clearance + 1e-6,
        )
    }

    /// Whether the car at `q` with `heading` can circle forever to either side.
    fn loopable(&self, area: &Area, q: Point, heading: f64) -> bool {
        self.can_loop(area, q, heading, 1.0) || self.can_loop(area, q, heading, -1.0)
    }

    /// The next point on the sharpest circle from `p`, on a side where the circle fits.
    fn loop_step(&self, area: &Area, p: Point, heading: f64) -> Option<Point> {
        let (turn, length, _) = self.loop_shape();
        [1.0, -1.0]
            .into_iter()
            .filter(|&side| self.can_loop(area, p, heading, side))
            .map(|side| p + Point::from_heading(heading + side * turn) * length)
            .find(|&q| self.accepts(area, p, heading, q))
    }

    /// Tries to finish the margin by circling at (almost) the sharpest turn with the shortest
    /// segments, on a side where the circle fits (random side first when both do). A state from
    /// which such a loop fits can be continued forever, so a margin that ends in one proves that
    /// the next extension exists too. Every loop segment is checked like any other; on success
    /// the buffer is full.
    fn close_with_loop<R: Rng + ?Sized>(
        &self,
        area: &Area,
        buffer: &mut Buffer,
        total: usize,
        rng: &mut R,
    ) -> bool {
        let (turn, length, _) = self.loop_shape();
        let start = buffer.len();
        let (p0, h0) = buffer.head();
        let first = if rng.random::<bool>() { 1.0 } else { -1.0 };
        for side in [first, -first] {
            if !self.can_loop(area, p0, h0, side) {
                continue;
            }
            let mut ok = true;
            while buffer.len() < total {
                let (p, h) = buffer.head();
                let q = p + Point::from_heading(h + side * turn) * length;
                if !self.accepts(area, p, h, q) {
                    ok = false;
                    break;
                }
                buffer.push(q);
            }
            if ok {
                return true;
            }
            buffer.truncate(start);
        }
        false
    }

    /// One point by wedge sampling: a heading in the open turn wedge, the ray in that direction
    /// clipped at the boundary, a length in the free part of the annulus. With `steer`, the best
    /// of `margin_candidates` valid candidates by free distance along the probe ray.
    fn wedge_point<R: Rng + ?Sized>(
        &self,
        area: &Area,
        p: Point,
        heading: f64,
        steer: bool,
        rng: &mut R,
        stats: &mut ExtensionStats,
    ) -> Option<Point> {
        let c = &self.config.constraints;
        // Strictly inside the wedge: a turn must be smaller than the limit.
        let half = c.max_turn * (1.0 - 1e-9);
        let reach = if steer {
            self.config.margin_probe.max(c.max_segment)
        } else {
            c.max_segment
        };
        let mut best: Option<(Point, f64)> = None;
        let mut found = 0;
        let mut fallback = None;
        for tries in 1..=self.config.inner_tries {
            stats.inner_tries += 1;
            let dir = Point::from_heading(heading + (2.0 * rng.random::<f64>() - 1.0) * half);
            let far = p + dir * reach;
            let hit = area.clip_ray(p, far);
            stats.rays += 1;
            let free = if hit == far {
                f64::INFINITY
            } else {
                p.dist(hit) - c.clearance - 1e-9
            };
            let longest = c.max_segment.min(free);
            if longest < c.min_segment {
                if tries == BLOCKED_CHECK_AFTER
                    && fallback.is_none()
                    && best.is_none()
                    && self.wedge_blocked(area, p, heading, stats)
                {
                    return None;
                }
                continue;
            }
            let length = c.min_segment + rng.random::<f64>() * (longest - c.min_segment);
            let q = p + dir * length;
            if !self.accepts(area, p, heading, q) {
                continue;
            }
            stats.samples += 1;
            if !steer {
                if !self.config.prefer_loopable || self.loopable(area, q, (q - p).heading()) {
                    return Some(q);
                }
                fallback.get_or_insert(q);
                if tries >= self.config.loop_preference_tries {
                    break;
                }
                continue;
            }
            if best.is_none_or(|(_, f)| free > f) {
                best = Some((q, free));
            }
            found += 1;
            if found >= self.config.margin_candidates {
                break;
            }
        }
        if steer {
            return best.map(|(q, _)| q);
        }
        if self.config.prefer_loopable
            && let Some(q) = self.loop_step(area, p, heading)
        {
            stats.samples += 1;
            stats.loop_steps += 1;
            return Some(q);
        }
        fallback
    }
}

/// Rays in the fan of [`Generator::wedge_blocked`] (every 7.5° of a ±30° wedge).
const BLOCKED_FAN: u32 = 9;

/// Wedge strategy: after this many candidates without a valid one, check whether the whole wedge
/// is blocked before drawing more.
const BLOCKED_CHECK_AFTER: u32 = 8;

/// Whether no boundary edge comes within `radius` of `centre`.
fn disc_is_free(area: &Area, centre: Point, radius: f64) -> bool {
    let r2 = radius * radius;
    area.edges().iter().all(|e| {
        let outside_box = centre.x < e.bbox.min.x - radius
            || centre.x > e.bbox.max.x + radius
            || centre.y < e.bbox.min.y - radius
            || centre.y > e.bbox.max.y + radius;
        outside_box || squared_distance(centre, e.a, e.b) > r2
    })
}

/// Squared distance from `p` to the segment `a–b`.
fn squared_distance(p: Point, a: Point, b: Point) -> f64 {
    let ab = b - a;
    let len2 = ab.dot(ab);
    let t = if len2 == 0.0 {
        0.0
    } else {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    };
    let d = p - (a + ab * t);
    d.dot(d)
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_pcg::Pcg64Mcg;

    use super::*;
    use crate::constraints::check_route;
    use crate::geometry::Polygon;
    use crate::test_support::{narrow_corridor, real_areas, rect, square_with_cutouts};

    fn rng(seed: u64) -> Pcg64Mcg {
        Pcg64Mcg::seed_from_u64(seed)
    }

    fn east(x: f64, y: f64) -> RouteTail {
        RouteTail::from_pose(Pose::new(Point::new(x, y), 0.0))
    }

    #[test]
    fn nonsense_constants_are_refused() {
        let bad = [
            GeneratorConfig {
                inner_tries: 0,
                ..GeneratorConfig::default()
            },
            GeneratorConfig::default().with_constraints(Constraints {
                min_segment: 2.5,
                ..Constraints::default()
            }),
            GeneratorConfig::default().with_constraints(Constraints {
                max_turn: 4.0,
                ..Constraints::default()
            }),
            GeneratorConfig {
                ray_length: f64::NAN,
                ..GeneratorConfig::default()
            },
        ];
        for config in bad {
            assert!(matches!(
                Generator::new(config),
                Err(GenerationError::InvalidConfig { .. })
            ));
        }
    }

    #[test]
    fn a_tail_needs_two_distinct_points() {
        let p = Point::new(1.0, 1.0);
        assert!(RouteTail::from_points(&[p]).is_err());
        assert!(RouteTail::from_points(&[p, p]).is_err());
        let tail = RouteTail::from_points(&[Point::new(0.0, 0.0), p]).unwrap();
        assert_eq!(tail.end, p);
        assert!((tail.heading - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        let next = tail.advanced(&[Point::new(1.0, 2.0)]);
        assert!((next.heading - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn bad_requests_are_typed_errors() {
        let area = square_with_cutouts().area;
        let g = Generator::default();
        assert!(matches!(
            g.extend(&area, &east(2.0, 2.0), 0, &mut rng(1)),
            Err(GenerationError::InvalidConfig { .. })
        ));
        assert!(matches!(
            g.extend(&area, &east(6.0, 6.0), 5, &mut rng(1)),
            Err(GenerationError::TailOutside { .. })
        ));
        assert!(matches!(
            g.extend(&area, &east(30.0, 6.0), 5, &mut rng(1)),
            Err(GenerationError::TailOutside { .. })
        ));
    }

    #[test]
    fn an_area_too_small_to_drive_in_is_a_typed_failure_never_a_short_extension() {
        let area = Area::new(rect(0.0, 0.0, 1.0, 1.0), vec![]).unwrap();
        for strategy in [Strategy::Wedge, Strategy::Reference] {
            let g = Generator::new(GeneratorConfig::default().with_strategy(strategy)).unwrap();
            match g.extend(&area, &east(0.2, 0.5), 5, &mut rng(7)) {
                Err(GenerationError::GenerationFailed {
                    outer_tries,
                    at,
                    needed,
                    ..
                }) => {
                    assert_eq!(outer_tries, 5000);
                    assert_eq!(at, Point::new(0.2, 0.5));
                    assert_eq!(needed, 25);
                }
                other => panic!("{strategy:?}: expected GenerationFailed, got {other:?}"),
            }
        }
    }

    #[test]
    fn a_corridor_too_narrow_to_turn_in_is_driven_to_its_end_and_no_further() {
        let area = narrow_corridor();
        let g = Generator::default();
        // 38 m ahead: 25 points fit (the random search, since no loop fits here).
        let ext = g.extend(&area, &east(2.0, 0.75), 5, &mut rng(3)).unwrap();
        assert_eq!(ext.stats.margin_loops, 0);
        let mut route = vec![Point::new(2.0, 0.75)];
        route.extend(ext.points.iter().chain(&ext.margin));
        assert_eq!(
            check_route(&area, &route, &g.config().constraints, Some(0.0)),
            Ok(())
        );
        // 8 m ahead: 25 points of at least 0.6 m cannot fit.
        let small = GeneratorConfig {
            outer_tries: 300,
            ..GeneratorConfig::default()
        };
        let err = Generator::new(small)
            .unwrap()
            .extend(&area, &east(32.0, 0.75), 5, &mut rng(3))
            .unwrap_err();
        assert!(matches!(
            err,
            GenerationError::GenerationFailed {
                outer_tries: 300,
                ..
            }
        ));
    }

    #[test]
    fn a_car_facing_a_wall_is_stuck_at_once_not_after_every_outer_try() {
        let area = square_with_cutouts().area;
        // 0.3 m from the east fence, facing it.
        let err = Generator::default()
            .extend(&area, &east(19.7, 10.0), 5, &mut rng(1))
            .unwrap_err();
        match err {
            GenerationError::GenerationFailed {
                outer_tries,
                reached,
                stats,
                ..
            } => {
                assert_eq!((outer_tries, reached, stats.stuck), (1, 0, 1));
            }
            other => panic!("expected GenerationFailed, got {other:?}"),
        }
    }

    #[test]
    fn the_reference_box_sampling_never_exceeds_the_segment_limits() {
        let area = Area::new(rect(0.0, 0.0, 30.0, 30.0), vec![]).unwrap();
        let g =
            Generator::new(GeneratorConfig::default().with_strategy(Strategy::Reference)).unwrap();
        let ext = g
            .extend_many(&area, &east(15.0, 15.0), 400, 5, &mut rng(11))
            .unwrap();
        let lengths: Vec<f64> = std::iter::once(Point::new(15.0, 15.0))
            .chain(ext.points.iter().copied())
            .collect::<Vec<_>>()
            .windows(2)
            .map(|w| w[0].dist(w[1]))
            .collect();
        assert!(lengths.iter().all(|&l| (0.6..=2.0).contains(&l)));
        assert!(lengths.iter().any(|&l| l > 1.9), "the whole range is used");
    }

    #[test]
    fn in_open_space_the_margin_is_a_verified_loop_and_costs_one_outer_try() {
        let fixture = square_with_cutouts();
        let tail = RouteTail::from_points(&fixture.start_route).unwrap();
        let ext = Generator::default()
            .extend(&fixture.area, &tail, 5, &mut rng(5))
            .unwrap();
        assert_eq!(ext.stats.outer_tries, 1);
        assert_eq!(ext.stats.margin_loops, 1);
        assert_eq!(ext.margin.len(), 20);
    }

    #[test]
    fn the_polygon_closing_edge_bounds_the_generator() {
        // A triangle: its closing edge is the hypotenuse; every point must stay on the near side.
        let fence = Polygon::new(vec![
            Point::new(0.0, 0.0),
            Point::new(20.0, 0.0),
            Point::new(0.0, 20.0),
        ])
        .unwrap();
        let area = Area::new(fence, vec![]).unwrap();
        for strategy in [Strategy::Wedge, Strategy::Reference] {
            let g = Generator::new(GeneratorConfig::default().with_strategy(strategy)).unwrap();
            let ext = g
                .extend_many(&area, &east(2.0, 2.0), 200, 5, &mut rng(2))
                .unwrap();
            assert!(ext.points.iter().all(|p| p.x + p.y < 20.0));
        }
    }

    #[test]
    fn a_return_route_can_start_at_each_real_recovery_route_start() {
        for (fixture, real) in real_areas().iter().zip(crate::test_areas::REAL_AREAS) {
            let route = crate::test_support::points(real.recovery_route);
            let pose = Pose::new(route[0], (route[1] - route[0]).heading());
            let g = Generator::new(GeneratorConfig::default().with_ahead_margin(15)).unwrap();
            let ext = g
                .extend_from_pose(&fixture.area, pose, 5, &mut rng(4))
                .unwrap();
            assert_eq!(
                (ext.points.len(), ext.margin.len()),
                (5, 15),
                "{}",
                fixture.name
            );
        }
    }
}
