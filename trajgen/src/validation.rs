//! Area validation (`docs/method.md#validating-an-area`): drive one very long trajectory through an
//! area and judge it.
//!
//! [`validate_area`] continues the start route with one continuous trajectory of
//! [`ValidationConfig::km`] kilometres, in extensions of [`ValidationConfig::extension_points`]
//! points, each generated with the ahead margin. The [`ValidationReport`] gives the outer tries per
//! extension (max, mean, p99), the failures, the worst places ([`HotSpot`]s), the coverage of the
//! drivable area and a downsampled trajectory for drawing. The verdict is [`AreaVerdict::Safe`] iff the
//! run completed, no extension failed and no extension needed more than half the outer-try limit.
//!
//! **After a failure** (an extension that used every outer try): the failure is counted, the
//! extension counts with the full limit in the outer-try statistics, and its place (the end of the
//! route it could not continue) becomes a hot-spot candidate. Then the run *backs up*: it removes
//! the last `extension_points × 2^k` points of the trajectory (k = failures since the trajectory
//! last grew past the failed point; never the start route) and continues from there, so the run
//! goes on and every failure is counted once. The kilometres are those of the trajectory as kept.
//! If the start route itself cannot be continued, or more than [`ValidationConfig::max_failures`]
//! failures occur, the run stops early and the report says `completed: false`.
//!
//! **Coverage** is measured on a grid of [`ValidationConfig::cell_size`] cells over the fence's
//! bounding box ([`Raster`]): a cell is *drivable* when its centre is strictly inside the drivable
//! region, and *visited* when a segment of the final trajectory (start route excluded) passes
//! through it (exact grid traversal). Coverage = visited drivable cells / drivable cells.
//!
//! **Hot spots** are the places (route ends) of the hardest extensions — failures first, then most
//! outer tries, then most inner tries (candidate points drawn, which still ranks tight places when
//! no extension met a dead end) — chosen greedily so that no two are closer than
//! [`ValidationConfig::hotspot_radius`]: the five are five different places.
//!
//! No clocks here: the caller measures wall time; progress goes to a callback.

use rand::Rng;
use thiserror::Error;

use crate::generator::{ExtensionStats, GenerationError, Generator, GeneratorConfig, RouteTail};
use crate::geometry::{Area, Point};
use crate::raster::Raster;
use crate::stats::nearest_rank;

/// What to validate and how.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValidationConfig {
    /// Length of the trajectory, kilometres (100).
    pub km: f64,
    /// Points per extension (5).
    pub extension_points: usize,
    /// The generator (its ahead margin is the method's 20 by default).
    pub generator: GeneratorConfig,
    /// Side of a coverage cell, metres (0.5).
    pub cell_size: f64,
    /// How many hot spots to report (5).
    pub hotspots: usize,
    /// Hot spots closer than this are the same place, metres (3.0).
    pub hotspot_radius: f64,
    /// Stop early after this many failures (100).
    pub max_failures: u64,
    /// Most points in the downsampled trajectory of the report (5000).
    pub sample_points: usize,
    /// Report progress every this many kilometres (0.1).
    pub progress_step_km: f64,
}

impl Default for ValidationConfig {
    fn default() -> Self {
        Self {
            km: 100.0,
            extension_points: 5,
            generator: GeneratorConfig::default(),
            cell_size: 0.5,
            hotspots: 5,
            hotspot_radius: 3.0,
            max_failures: 100,
            sample_points: 5000,
            progress_step_km: 0.1,
        }
    }
}

impl ValidationConfig {
    /// This configuration with another length.
    pub fn with_km(self, km: f64) -> Self {
        Self { km, ..self }
    }

    /// This configuration with another generator.
    pub fn with_generator(self, generator: GeneratorConfig) -> Self {
        Self { generator, ..self }
    }
}

/// How far a validation run has come; passed to the progress callback.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Kilometres of trajectory so far.
    pub km: f64,
    /// Kilometres to drive.
    pub target_km: f64,
    /// Extensions attempted so far.
    pub extensions: u64,
    /// Failed extensions so far.
    pub failures: u64,
    /// Most outer tries of one extension so far.
    pub max_outer_tries: u32,
}

/// The method's judgement of an area.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AreaVerdict {
    /// Completed, no failure, and no extension needed more than half the outer-try limit.
    Safe,
    /// Anything else.
    Unsafe,
}

impl AreaVerdict {
    /// `"safe"` or `"unsafe"`.
    pub fn as_str(self) -> &'static str {
        match self {
            AreaVerdict::Safe => "safe",
            AreaVerdict::Unsafe => "unsafe",
        }
    }
}

impl std::fmt::Display for AreaVerdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One of the worst places of the run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HotSpot {
    /// East, metres: where the route stood when the hardest extension there was generated.
    pub x: f64,
    /// North, metres.
    pub y: f64,
    /// Most outer tries of an extension at this place (the limit for a failure).
    pub outer_tries: u32,
    /// Inner tries (candidate points drawn) of that extension.
    pub inner_tries: u64,
    /// Failed extensions within the hot-spot radius.
    pub failures: u32,
    /// Extensions with at least one dead end within the hot-spot radius.
    pub hard_extensions: u32,
}

/// A failed extension of the run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FailureRecord {
    /// Where the route stood (the end it could not continue).
    pub at: Point,
    /// Kilometres driven when it happened.
    pub km: f64,
    /// Most points placed by any attempt.
    pub reached: usize,
}

/// Visits per cell of the area's [`Raster`], for coverage and a heat map.
#[derive(Debug, Clone, PartialEq)]
pub struct CoverageGrid {
    /// The cells over the fence's bounding box and which of them are drivable.
    pub raster: Raster,
    /// Per cell (row-major, `row * cols + col`): how many trajectory segments pass through it.
    pub visits: Vec<u32>,
}

impl CoverageGrid {
    /// An empty grid over `area`'s fence bounding box.
    pub fn new(area: &Area, cell_size: f64) -> Self {
        let raster = Raster::new(area, cell_size);
        Self {
            visits: vec![0; raster.drivable.len()],
            raster,
        }
    }

    /// Number of drivable cells visited at least once.
    pub fn visited_cells(&self) -> usize {
        self.raster
            .drivable
            .iter()
            .zip(&self.visits)
            .filter(|&(&d, &v)| d && v > 0)
            .count()
    }

    /// Visited drivable cells / drivable cells (0 when none is drivable).
    pub fn coverage(&self) -> f64 {
        let drivable = self.raster.drivable_cells();
        if drivable == 0 {
            0.0
        } else {
            self.visited_cells() as f64 / drivable as f64
        }
    }

    fn mark(&mut self, col: i64, row: i64) {
        if let Some(i) = self.raster.index(col, row) {
            self.visits[i] = self.visits[i].saturating_add(1);
        }
    }

    /// The part of the segment `a → b` over the grid (Liang–Barsky clipping; an end inside the
    /// grid is kept exactly as it is), `None` when it misses the grid or is not finite.
    fn within_grid(&self, a: Point, b: Point) -> Option<(Point, Point)> {
        let d = b - a;
        if !(a.is_finite() && b.is_finite() && d.is_finite()) {
            return None;
        }
        let r = &self.raster;
        let low = r.origin;
        let high = low + Point::new(r.cols as f64 * r.cell_size, r.rows as f64 * r.cell_size);
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for (p, q) in [
            (-d.x, a.x - low.x),
            (d.x, high.x - a.x),
            (-d.y, a.y - low.y),
            (d.y, high.y - a.y),
        ] {
            if p == 0.0 {
                if q < 0.0 {
                    return None;
                }
            } else if p < 0.0 {
                t0 = t0.max(q / p);
            } else {
                t1 = t1.min(q / p);
            }
        }
        if t0 > t1 {
            return None;
        }
        let from = if t0 > 0.0 { a + d * t0 } else { a };
        let to = if t1 < 1.0 { a + d * t1 } else { b };
        Some((from, to))
    }

    /// Counts one visit in every cell the segment `a → b` passes through (Amanatides–Woo
    /// traversal). The segment is clipped to the grid first, so any two points (far outside, not
    /// finite) take at most as many steps as the grid has columns and rows.
    pub fn visit_segment(&mut self, a: Point, b: Point) {
        let Some((a, b)) = self.within_grid(a, b) else {
            return;
        };
        let (mut col, mut row) = self.raster.cell_of(a);
        let (end_col, end_row) = self.raster.cell_of(b);
        let (origin, cell_size) = (self.raster.origin, self.raster.cell_size);
        let d = b - a;
        let axis = |start: f64, origin: f64, index: i64, delta: f64| -> (i64, f64, f64) {
            if delta > 0.0 {
                let boundary = origin + index.saturating_add(1) as f64 * cell_size;
                (1, (boundary - start) / delta, cell_size / delta)
            } else if delta < 0.0 {
                let boundary = origin + index as f64 * cell_size;
                (-1, (boundary - start) / delta, -cell_size / delta)
            } else {
                (0, f64::INFINITY, f64::INFINITY)
            }
        };
        let (step_x, mut t_x, dt_x) = axis(a.x, origin.x, col, d.x);
        let (step_y, mut t_y, dt_y) = axis(a.y, origin.y, row, d.y);
        self.mark(col, row);
        let most = (self.raster.cols + self.raster.rows) as i64 + 2;
        let steps = (end_col.saturating_sub(col).saturating_abs())
            .saturating_add(end_row.saturating_sub(row).saturating_abs())
            .min(most);
        for _ in 0..steps {
            if t_x < t_y {
                col += step_x;
                t_x += dt_x;
            } else {
                row += step_y;
                t_y += dt_y;
            }
            self.mark(col, row);
        }
    }
}

/// The outcome of a validation run.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidationReport {
    /// Safe iff completed, no failure, max outer tries ≤ half the limit.
    pub verdict: AreaVerdict,
    /// Kilometres of trajectory driven (as kept, start route excluded).
    pub km: f64,
    /// Kilometres asked for.
    pub target_km: f64,
    /// Whether the run reached `target_km` (false: the start route could not be continued, or too
    /// many failures).
    pub completed: bool,
    /// Extensions attempted (successful and failed).
    pub extensions: u64,
    /// Extensions that used every outer try.
    pub failures: u64,
    /// Most outer tries of one extension.
    pub max_outer_tries: u32,
    /// Mean outer tries per extension.
    pub mean_outer_tries: f64,
    /// 99th percentile (nearest rank) of outer tries per extension.
    pub p99_outer_tries: u32,
    /// The outer-try limit of the generator.
    pub outer_tries_limit: u32,
    /// Visited drivable cells / drivable cells (see the module doc).
    pub coverage: f64,
    /// The worst places, worst first, at most `hotspots`, pairwise farther apart than the radius.
    pub hotspots: Vec<HotSpot>,
    /// Every failure, in order.
    pub failure_records: Vec<FailureRecord>,
    /// The trajectory (start route included), downsampled to at most `sample_points` points.
    pub trajectory_sample: Vec<Point>,
    /// The coverage grid, for a heat map.
    pub grid: CoverageGrid,
    /// Summed generator statistics over all extensions.
    pub stats: ExtensionStats,
}

/// Why a validation could not run at all.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ValidationError {
    /// The start route cannot be continued (too short, or it ends outside the area).
    #[error("the start route cannot be continued: {0}")]
    StartRoute(GenerationError),
    /// The configuration makes no sense.
    #[error("invalid validation configuration: {0}")]
    InvalidConfig(&'static str),
    /// The generator configuration makes no sense.
    #[error(transparent)]
    Generator(GenerationError),
}

/// One extension's difficulty and place, a hot-spot candidate.
#[derive(Debug, Clone, Copy)]
struct Attempt {
    at: Point,
    outer_tries: u32,
    inner_tries: u64,
    failed: bool,
}

/// The state of a run.
struct Run<'a> {
    area: &'a Area,
    config: &'a ValidationConfig,
    generator: Generator,
    /// Start route followed by the generated trajectory.
    points: Vec<Point>,
    /// Length of the generated trajectory up to each point (0 along the start route).
    lengths: Vec<f64>,
    start_len: usize,
    tries: Vec<u32>,
    attempts: Vec<Attempt>,
    failures: Vec<FailureRecord>,
    stats: ExtensionStats,
}

impl Run<'_> {
    fn km(&self) -> f64 {
        self.lengths.last().copied().unwrap_or(0.0) / 1000.0
    }

    fn tail(&self) -> RouteTail {
        RouteTail::from_points(&self.points).expect("the route keeps at least the start route")
    }

    fn append(&mut self, new: &[Point]) {
        for &q in new {
            let (p, l) = (
                self.points[self.points.len() - 1],
                self.lengths[self.lengths.len() - 1],
            );
            self.points.push(q);
            self.lengths.push(l + p.dist(q));
        }
    }

    fn truncate(&mut self, len: usize) {
        self.points.truncate(len);
        self.lengths.truncate(len);
    }

    fn progress(&self) -> Progress {
        Progress {
            km: self.km(),
            target_km: self.config.km,
            extensions: self.tries.len() as u64,
            failures: self.failures.len() as u64,
            max_outer_tries: self.tries.iter().copied().max().unwrap_or(0),
        }
    }
}

/// Validates `area` by one continuous trajectory continuing `start_route`
/// (`docs/method.md#validating-an-area`).
///
/// `progress` is called every [`ValidationConfig::progress_step_km`] and once at the end.
pub fn validate_area<R: Rng + ?Sized>(
    area: &Area,
    start_route: &[Point],
    config: &ValidationConfig,
    rng: &mut R,
    progress: &mut dyn FnMut(&Progress),
) -> Result<ValidationReport, ValidationError> {
    check_config(config)?;
    let generator = Generator::new(config.generator).map_err(ValidationError::Generator)?;
    let tail = RouteTail::from_points(start_route).map_err(ValidationError::StartRoute)?;
    if !area.contains_point(tail.end) {
        return Err(ValidationError::StartRoute(GenerationError::TailOutside {
            at: tail.end,
        }));
    }
    let mut run = Run {
        area,
        config,
        generator,
        points: start_route.to_vec(),
        lengths: vec![0.0; start_route.len()],
        start_len: start_route.len(),
        tries: Vec::new(),
        attempts: Vec::new(),
        failures: Vec::new(),
        stats: ExtensionStats::default(),
    };
    let completed = drive(&mut run, rng, progress);
    progress(&run.progress());
    Ok(report(run, completed))
}

fn check_config(config: &ValidationConfig) -> Result<(), ValidationError> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !positive(config.km) {
        return Err(ValidationError::InvalidConfig("km must be positive"));
    }
    if !positive(config.cell_size) || !positive(config.progress_step_km) {
        return Err(ValidationError::InvalidConfig(
            "cell_size and progress_step_km must be positive",
        ));
    }
    if config.extension_points == 0 || config.sample_points < 2 {
        return Err(ValidationError::InvalidConfig(
            "extension_points must be at least 1 and sample_points at least 2",
        ));
    }
    if !config.hotspot_radius.is_finite() || config.hotspot_radius < 0.0 {
        return Err(ValidationError::InvalidConfig(
            "hotspot_radius must be finite and non-negative",
        ));
    }
    Ok(())
}

/// Drives until the target length; returns whether it got there.
fn drive<R: Rng + ?Sized>(
    run: &mut Run<'_>,
    rng: &mut R,
    progress: &mut dyn FnMut(&Progress),
) -> bool {
    let limit = run.generator.config().outer_tries;
    let mut next_report = run.config.progress_step_km;
    // Failures since the trajectory last grew past the place of the latest failure.
    let mut level = 0u32;
    let mut failed_at_len = 0usize;
    while run.km() < run.config.km {
        let tail = run.tail();
        match run
            .generator
            .extend(run.area, &tail, run.config.extension_points, rng)
        {
            Ok(ext) => {
                run.stats.absorb(&ext.stats);
                run.tries.push(ext.stats.outer_tries);
                run.attempts.push(Attempt {
                    at: tail.end,
                    outer_tries: ext.stats.outer_tries,
                    inner_tries: ext.stats.inner_tries,
                    failed: false,
                });
                run.append(&ext.points);
                if run.points.len() > failed_at_len {
                    level = 0;
                }
            }
            Err(GenerationError::GenerationFailed { reached, stats, .. }) => {
                run.stats.absorb(&stats);
                run.tries.push(limit);
                run.attempts.push(Attempt {
                    at: tail.end,
                    outer_tries: limit,
                    inner_tries: stats.inner_tries,
                    failed: true,
                });
                run.failures.push(FailureRecord {
                    at: tail.end,
                    km: run.km(),
                    reached,
                });
                let generated = run.points.len() - run.start_len;
                if generated == 0 || run.failures.len() as u64 > run.config.max_failures {
                    return false;
                }
                failed_at_len = failed_at_len.max(run.points.len());
                let back = run.config.extension_points << level.min(20);
                run.truncate(run.points.len() - back.min(generated));
                level += 1;
            }
            // The tail is always inside and valid: anything else is a bug in the generator.
            Err(_) => return false,
        }
        if run.km() >= next_report {
            progress(&run.progress());
            next_report = (run.km() / run.config.progress_step_km).floor()
                * run.config.progress_step_km
                + run.config.progress_step_km;
        }
    }
    true
}

fn report(run: Run<'_>, completed: bool) -> ValidationReport {
    let limit = run.generator.config().outer_tries;
    let mut sorted = run.tries.clone();
    sorted.sort_unstable();
    let max_outer_tries = sorted.last().copied().unwrap_or(0);
    let mean_outer_tries = if sorted.is_empty() {
        0.0
    } else {
        sorted.iter().map(|&t| f64::from(t)).sum::<f64>() / sorted.len() as f64
    };
    let p99_outer_tries = nearest_rank(&sorted, 0.99).unwrap_or(0);
    let failures = run.failures.len() as u64;
    let safe = completed && failures == 0 && max_outer_tries <= limit / 2;
    let mut grid = CoverageGrid::new(run.area, run.config.cell_size);
    for w in run.points[run.start_len - 1..].windows(2) {
        grid.visit_segment(w[0], w[1]);
    }
    ValidationReport {
        verdict: if safe {
            AreaVerdict::Safe
        } else {
            AreaVerdict::Unsafe
        },
        km: run.km(),
        target_km: run.config.km,
        completed,
        extensions: sorted.len() as u64,
        failures,
        max_outer_tries,
        mean_outer_tries,
        p99_outer_tries,
        outer_tries_limit: limit,
        coverage: grid.coverage(),
        hotspots: hotspots(
            &run.attempts,
            run.config.hotspots,
            run.config.hotspot_radius,
        ),
        failure_records: run.failures,
        trajectory_sample: downsample(&run.points, run.config.sample_points),
        grid,
        stats: run.stats,
    }
}

/// The `count` worst places, failures first, then by outer tries, then by inner tries, pairwise
/// at least `radius` apart.
fn hotspots(attempts: &[Attempt], count: usize, radius: f64) -> Vec<HotSpot> {
    let mut order: Vec<&Attempt> = attempts.iter().collect();
    order.sort_by_key(|h| std::cmp::Reverse((h.failed, h.outer_tries, h.inner_tries)));
    let mut spots: Vec<HotSpot> = Vec::with_capacity(count);
    for h in order {
        if spots.len() == count {
            break;
        }
        if spots
            .iter()
            .all(|s| Point::new(s.x, s.y).dist(h.at) >= radius)
        {
            spots.push(HotSpot {
                x: h.at.x,
                y: h.at.y,
                outer_tries: h.outer_tries,
                inner_tries: h.inner_tries,
                failures: 0,
                hard_extensions: 0,
            });
        }
    }
    for h in attempts.iter().filter(|h| h.outer_tries > 1) {
        if let Some(s) = spots
            .iter_mut()
            .find(|s| Point::new(s.x, s.y).dist(h.at) < radius.max(f64::MIN_POSITIVE))
        {
            s.hard_extensions += 1;
            s.failures += u32::from(h.failed);
        }
    }
    spots
}

/// At most `max` points of `points`, evenly strided, first and last kept.
fn downsample(points: &[Point], max: usize) -> Vec<Point> {
    if points.len() <= max {
        return points.to_vec();
    }
    let stride = points.len().div_ceil(max - 1);
    let mut sample: Vec<Point> = points.iter().step_by(stride).copied().collect();
    if sample.last() != points.last() {
        sample.extend(points.last());
    }
    sample
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_pcg::Pcg64Mcg;

    use super::*;
    use crate::generator::Strategy;
    use crate::geometry::Polygon;
    use crate::test_support::{narrow_corridor, real_areas, rect, square_with_cutouts};

    fn rng(seed: u64) -> Pcg64Mcg {
        Pcg64Mcg::seed_from_u64(seed)
    }

    /// An 8 m room with a 2 m wide, 30 m long dead-end corridor going east: too narrow to turn
    /// in, longer than the ahead margin (the method's problematic area).
    fn room_with_trap() -> (Area, Vec<Point>) {
        let fence = Polygon::new(
            [
                [0., 0.],
                [8., 0.],
                [8., 3.],
                [38., 3.],
                [38., 5.],
                [8., 5.],
                [8., 8.],
                [0., 8.],
            ]
            .into_iter()
            .map(Point::from)
            .collect(),
        )
        .unwrap();
        let area = Area::new(fence, vec![]).unwrap();
        (area, vec![Point::new(2.0, 4.0), Point::new(3.0, 4.0)])
    }

    #[test]
    fn every_real_area_is_safe_at_10_km() {
        for fixture in real_areas() {
            let config = ValidationConfig::default().with_km(10.0);
            let report = validate_area(
                &fixture.area,
                &fixture.start_route,
                &config,
                &mut rng(1),
                &mut |_| {},
            )
            .unwrap();
            assert_eq!(
                report.verdict,
                AreaVerdict::Safe,
                "{}: {report:?}",
                fixture.name
            );
            assert!(report.completed && report.km >= 10.0);
            assert_eq!(report.failures, 0);
            assert!(
                report.coverage > 0.8,
                "{}: coverage {}",
                fixture.name,
                report.coverage
            );
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_report() {
        let fixture = square_with_cutouts();
        let config = ValidationConfig::default().with_km(0.5);
        let run = || {
            validate_area(
                &fixture.area,
                &fixture.start_route,
                &config,
                &mut rng(9),
                &mut |_| {},
            )
            .unwrap()
        };
        assert_eq!(run(), run());
    }

    #[test]
    fn progress_is_reported_until_the_end() {
        let fixture = square_with_cutouts();
        let config = ValidationConfig::default().with_km(0.5);
        let mut seen = Vec::new();
        let report = validate_area(
            &fixture.area,
            &fixture.start_route,
            &config,
            &mut rng(2),
            &mut |p| seen.push(*p),
        )
        .unwrap();
        assert!(seen.len() >= 5);
        assert!(seen.windows(2).all(|w| w[0].km <= w[1].km));
        let last = seen.last().unwrap();
        assert_eq!(last.km, report.km);
        assert_eq!(last.extensions, report.extensions);
    }

    #[test]
    fn the_reference_gets_trapped_in_a_dead_end_corridor_and_the_hot_spot_is_there() {
        let (area, start) = room_with_trap();
        let generator = GeneratorConfig {
            outer_tries: 100,
            ..GeneratorConfig::default().with_strategy(Strategy::Reference)
        };
        let config = ValidationConfig {
            max_failures: 20,
            ..ValidationConfig::default()
                .with_km(2.0)
                .with_generator(generator)
        };
        let report = validate_area(&area, &start, &config, &mut rng(1), &mut |_| {}).unwrap();
        assert_eq!(report.verdict, AreaVerdict::Unsafe);
        assert!(report.failures > 0);
        assert_eq!(report.failure_records.len() as u64, report.failures);
        let worst = report.hotspots[0];
        assert_eq!(worst.outer_tries, 100);
        assert!(
            worst.x > 8.0,
            "the worst place is in the corridor: {worst:?}"
        );
        // Distinct places.
        for (i, a) in report.hotspots.iter().enumerate() {
            for b in &report.hotspots[i + 1..] {
                assert!(Point::new(a.x, a.y).dist(Point::new(b.x, b.y)) >= config.hotspot_radius);
            }
        }
    }

    /// The wedge generator prefers states from which the car could circle, so it does not drive
    /// into a corridor too narrow to turn in: it is safe, and the coverage shows what it left out.
    #[test]
    fn the_wedge_generator_stays_out_of_the_trap_and_the_coverage_shows_it() {
        let (area, start) = room_with_trap();
        let config = ValidationConfig::default().with_km(2.0);
        let report = validate_area(&area, &start, &config, &mut rng(1), &mut |_| {}).unwrap();
        assert_eq!(report.verdict, AreaVerdict::Safe, "{report:?}");
        let (raster, visits) = (&report.grid.raster, &report.grid.visits);
        let corridor: Vec<usize> = (0..visits.len())
            .filter(|&i| {
                raster.drivable[i] && raster.cell_centre(i % raster.cols, i / raster.cols).x > 9.0
            })
            .collect();
        assert!(corridor.iter().all(|&i| visits[i] == 0));
        assert!(report.coverage < 0.6, "coverage {}", report.coverage);
    }

    #[test]
    fn a_start_route_that_cannot_be_continued_stops_the_run_as_unsafe() {
        let area = narrow_corridor();
        let start = vec![Point::new(31.0, 0.75), Point::new(32.0, 0.75)];
        let config = ValidationConfig {
            generator: GeneratorConfig {
                outer_tries: 50,
                ..GeneratorConfig::default()
            },
            ..ValidationConfig::default().with_km(1.0)
        };
        let report = validate_area(&area, &start, &config, &mut rng(1), &mut |_| {}).unwrap();
        assert!(!report.completed);
        assert_eq!(report.verdict, AreaVerdict::Unsafe);
        assert_eq!(report.failures, 1);
        assert_eq!(report.hotspots[0].x, 32.0);
    }

    #[test]
    fn a_start_route_outside_the_area_is_an_error() {
        let fixture = square_with_cutouts();
        let start = [Point::new(5.5, 6.0), Point::new(6.5, 6.0)];
        let err = validate_area(
            &fixture.area,
            &start,
            &ValidationConfig::default(),
            &mut rng(1),
            &mut |_| {},
        )
        .unwrap_err();
        assert!(matches!(err, ValidationError::StartRoute(_)));
    }

    #[test]
    fn a_segment_visits_every_cell_it_passes_through() {
        let area = Area::new(rect(0.0, 0.0, 4.0, 4.0), vec![]).unwrap();
        let mut grid = CoverageGrid::new(&area, 1.0);
        let raster = &grid.raster;
        assert_eq!(
            (raster.cols, raster.rows, raster.drivable_cells()),
            (4, 4, 16)
        );
        grid.visit_segment(Point::new(0.5, 0.5), Point::new(2.5, 1.5));
        let visited: Vec<(usize, usize)> = (0..16)
            .filter(|&i| grid.visits[i] > 0)
            .map(|i| (i % 4, i / 4))
            .collect();
        // Crosses x = 1 at y = 0.75, then y = 1 at x = 1.5, then x = 2 at y = 1.25.
        assert_eq!(visited, vec![(0, 0), (1, 0), (1, 1), (2, 1)]);
        assert!((grid.coverage() - 4.0 / 16.0).abs() < 1e-12);
    }

    #[test]
    fn only_cells_with_a_drivable_centre_count() {
        let area = Area::new(rect(0.0, 0.0, 4.0, 4.0), vec![rect(1.0, 1.0, 3.0, 3.0)]).unwrap();
        let mut grid = CoverageGrid::new(&area, 1.0);
        grid.visit_segment(Point::new(0.5, 0.5), Point::new(3.5, 0.5));
        grid.visit_segment(Point::new(1.5, 1.5), Point::new(2.5, 2.5));
        // 4 of the 12 drivable cells; the cutout's cells do not count.
        assert!((grid.coverage() - 4.0 / 12.0).abs() < 1e-12);
    }

    #[test]
    fn hot_spots_are_distinct_places_failures_first() {
        let hard = |x: f64, outer_tries: u32, failed: bool| Attempt {
            at: Point::new(x, 0.0),
            outer_tries,
            inner_tries: 10,
            failed,
        };
        let list = [
            hard(0.0, 900, false),
            hard(0.5, 950, false),
            hard(10.0, 5000, true),
            hard(20.0, 40, false),
            hard(10.2, 300, false),
        ];
        let spots = hotspots(&list, 5, 3.0);
        let xs: Vec<f64> = spots.iter().map(|s| s.x).collect();
        assert_eq!(xs, vec![10.0, 0.5, 20.0]);
        assert_eq!((spots[0].failures, spots[0].hard_extensions), (1, 2));
        assert_eq!(spots[1].hard_extensions, 2);
    }

    #[test]
    fn downsampling_keeps_the_ends_and_the_bound() {
        let points: Vec<Point> = (0..10_001).map(|i| Point::new(i as f64, 0.0)).collect();
        let sample = downsample(&points, 500);
        assert!(sample.len() <= 500);
        assert_eq!(sample[0], points[0]);
        assert_eq!(sample.last(), points.last());
    }
}
