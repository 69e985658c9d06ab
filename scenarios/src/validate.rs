//! The checks a typed scenario must pass (errors) and the soft problems it may have (warnings).
//!
//! Hard rules: settings in range; each route has at least 2 points, positive speeds, every point
//! and segment inside the area; the recovery route ends within 1.5 × `segment_max_m` of the start
//! route's first point and the step between them stays inside the area; at most 20 anchors with
//! unique ids; named obstacles and walls of non-zero length.
//!
//! Soft rules (warnings): no anchors; hand-drawn routes (recovery route, the join, start route)
//! whose turns or segment lengths are outside the generator's limits, or that come closer to an
//! edge than the generator's clearance.

use trajgen::geometry::turn_angle;
use trajgen::{Area, Point, Polygon, Waypoint};

use crate::error::{BeyondLimit, Problem, ScenarioError, Warning, WarningKind};
use crate::limits::{
    MAX_AHEAD_MARGIN, MAX_CLEARANCE_M, MAX_COORDINATE_M, MAX_FAULT_FACTOR, MAX_FAULT_ITERATIONS,
    MAX_FAULT_OFFSET, MAX_INNER_TRIES, MAX_OUTER_TRIES, MAX_POINTS_PER_SEGMENT, MAX_ROUTE_SPEED,
    MAX_SEGMENT_M, MAX_TEST_SIZE, MIN_SPEED_KMH,
};
use crate::model::{Route, Scenario};
use crate::settings::{
    CampaignSettings, FaultKind, FaultTarget, GeneratorSettings, Interval, SHARED_PARAM_KEY,
    Vehicle,
};
use car_link::firmware::{Param, Quantity};

pub use car_link::firmware::{MAX_ANCHORS, MAX_SPEED_KMH};

/// A failed check: the field path and the problem.
type Check = Result<(), (String, Problem)>;

/// Checks `scenario` and returns its warnings, or the first error found.
pub(crate) fn validate(
    scenario: &Scenario,
    source_name: &str,
) -> Result<Vec<Warning>, ScenarioError> {
    check(scenario)
        .map_err(|(field, problem)| ScenarioError::in_field(source_name, field, problem))?;
    Ok(warnings(scenario, source_name))
}

fn check(s: &Scenario) -> Check {
    if s.name.trim().is_empty() {
        return Err(("name".into(), Problem::Empty));
    }
    if let Some(origin) = &s.origin {
        within(origin.lat, -90.0, 90.0, "origin.lat")?;
        within(origin.lon, -180.0, 180.0, "origin.lon")?;
        coordinate(origin.height, "origin.height")?;
    }
    check_coordinates(s)?;
    check_vehicle(&s.vehicle)?;
    check_generator(&s.generator)?;
    check_campaign(&s.campaign)?;
    check_threshold(s)?;
    check_route(&s.area, &s.start_route, "start_route")?;
    check_route(&s.area, &s.recovery_route, "recovery_route")?;
    check_join(s)?;
    check_anchors(s)?;
    check_environment(s)
}

fn finite(value: f64, field: &str) -> Check {
    if value.is_finite() {
        Ok(())
    } else {
        Err((field.into(), Problem::NotFinite))
    }
}

fn positive(value: f64, field: &str) -> Check {
    finite(value, field)?;
    if value > 0.0 {
        Ok(())
    } else {
        Err((field.into(), Problem::NotPositive(value)))
    }
}

fn non_negative(value: f64, field: &str) -> Check {
    finite(value, field)?;
    if value >= 0.0 {
        Ok(())
    } else {
        Err((field.into(), Problem::Negative(value)))
    }
}

fn within(value: f64, low: f64, high: f64, field: &str) -> Check {
    finite(value, field)?;
    if (low..=high).contains(&value) {
        Ok(())
    } else {
        Err((field.into(), Problem::OutOfRange { value, low, high }))
    }
}

fn at_least_one(value: usize, field: &str) -> Check {
    if value >= 1 {
        Ok(())
    } else {
        Err((field.into(), Problem::NotPositive(0.0)))
    }
}

/// An interval of finite numbers with `min <= max`.
fn ordered(interval: Interval<f64>, field: &str) -> Check {
    finite(interval.min, &format!("{field}.min"))?;
    finite(interval.max, &format!("{field}.max"))?;
    if interval.min <= interval.max {
        Ok(())
    } else {
        Err((
            field.into(),
            Problem::MinAboveMax {
                min: interval.min,
                max: interval.max,
            },
        ))
    }
}

fn as_f64<T: Into<f64> + Copy>(interval: Interval<T>) -> Interval<f64> {
    Interval::new(interval.min.into(), interval.max.into())
}

/// A count interval with `1 <= min <= max`.
fn counts(interval: Interval<usize>, field: &str) -> Check {
    at_least_one(interval.min, &format!("{field}.min"))?;
    ordered(
        Interval::new(interval.min as f64, interval.max as f64),
        field,
    )
}

/// `value` at most `limit` ([`crate::limits`]).
fn at_most(value: f64, limit: f64, why: &'static str, field: &str) -> Check {
    beyond_unless(value <= limit, (value, "at most", limit), why, field)
}

/// `value` at least `limit` ([`crate::limits`]; a tolerance of 1e-9 for unit conversions).
fn at_least(value: f64, limit: f64, why: &'static str, field: &str) -> Check {
    beyond_unless(
        value >= limit - 1e-9,
        (value, "at least", limit),
        why,
        field,
    )
}

/// A [`Problem::BeyondLimit`] of `field` unless `within`.
fn beyond_unless(
    within: bool,
    (value, bound, limit): (f64, &'static str, f64),
    why: &'static str,
    field: &str,
) -> Check {
    if within {
        return Ok(());
    }
    Err((
        field.into(),
        Problem::BeyondLimit(Box::new(BeyondLimit {
            value,
            bound,
            limit,
            why,
        })),
    ))
}

/// Why coordinates have a bound ([`MAX_COORDINATE_M`]).
const LOCAL: &str = "coordinates are local metres around the origin; the car's protocol carries a \
                     position of at most 214748 m";

/// Why route speeds have a ceiling ([`MAX_ROUTE_SPEED`]).
const TOP_SPEED: &str = "the firmware autopilot's top speed, 30 km/h";

/// A finite coordinate or height within ±[`MAX_COORDINATE_M`].
pub(crate) fn coordinate(value: f64, field: &str) -> Check {
    finite(value, field)?;
    beyond_unless(
        value.abs() <= MAX_COORDINATE_M,
        (value, "in magnitude at most", MAX_COORDINATE_M),
        LOCAL,
        field,
    )
}

/// A route point's speed, m/s: finite, at least [`MIN_SPEED_KMH`] and at most the top speed.
pub(crate) fn route_speed(speed: f64, field: &str) -> Check {
    positive(speed, field)?;
    at_least(speed, MIN_SPEED_KMH / 3.6, SLOW, field)?;
    at_most(speed, MAX_ROUTE_SPEED, TOP_SPEED, field)
}

fn point_within(p: Point, field: &str) -> Check {
    coordinate(p.x, &format!("{field}.x"))?;
    coordinate(p.y, &format!("{field}.y"))
}

fn polygon_within(polygon: &Polygon, field: &str) -> Check {
    for (i, &p) in polygon.vertices().iter().enumerate() {
        point_within(p, &format!("{field}[{i}]"))?;
    }
    Ok(())
}

/// Every coordinate (and an anchor's height) within ±[`MAX_COORDINATE_M`]; a scenario read from a
/// file was checked as it was read, a scenario built by hand is checked here.
fn check_coordinates(s: &Scenario) -> Check {
    polygon_within(s.area.fence(), "fence")?;
    for (k, cutout) in s.area.cutouts().iter().enumerate() {
        polygon_within(cutout, &format!("cutouts[{k}]"))?;
    }
    for (route, field) in [
        (&s.start_route, "start_route"),
        (&s.recovery_route, "recovery_route"),
    ] {
        for (i, p) in route.points.iter().enumerate() {
            point_within(p.position, &format!("{field}[{i}]"))?;
        }
    }
    for (i, a) in s.anchors.iter().enumerate() {
        coordinate(a.x, &format!("anchors[{i}].x"))?;
        coordinate(a.y, &format!("anchors[{i}].y"))?;
        coordinate(a.height, &format!("anchors[{i}].height"))?;
    }
    for (i, o) in s.environment.obstacles.iter().enumerate() {
        polygon_within(&o.polygon, &format!("environment.obstacles[{i}].polygon"))?;
    }
    for (i, w) in s.environment.walls.iter().enumerate() {
        point_within(w.a, &format!("environment.walls[{i}].a"))?;
        point_within(w.b, &format!("environment.walls[{i}].b"))?;
    }
    Ok(())
}

/// How far the limits are from any real use.
const FAR: &str = "far beyond any real test; a larger value only exhausts memory or time";

/// Why speeds have a floor.
const SLOW: &str = "slower, one segment of a test takes minutes";

fn check_vehicle(v: &Vehicle) -> Check {
    positive(v.wheelbase_m, "vehicle.wheelbase_m")?;
    positive(v.max_steering_angle_rad, "vehicle.max_steering_angle_rad")?;
    within(
        v.max_steering_angle_rad,
        0.0,
        std::f64::consts::FRAC_PI_2,
        "vehicle.max_steering_angle_rad",
    )?;
    positive(v.width_m, "vehicle.width_m")
}

fn check_generator(g: &GeneratorSettings) -> Check {
    positive(g.segment_min_m, "generator.segment_min_m")?;
    positive(g.segment_max_m, "generator.segment_max_m")?;
    if g.segment_min_m > g.segment_max_m {
        return Err((
            "generator.segment_min_m".into(),
            Problem::MinAboveMax {
                min: g.segment_min_m,
                max: g.segment_max_m,
            },
        ));
    }
    positive(g.max_turn_deg, "generator.max_turn_deg")?;
    within(g.max_turn_deg, 0.0, 180.0, "generator.max_turn_deg")?;
    at_most(
        g.segment_max_m,
        MAX_SEGMENT_M,
        FAR,
        "generator.segment_max_m",
    )?;
    at_least_one(g.ahead_margin, "generator.ahead_margin")?;
    at_least_one(g.recovery_ahead_margin, "generator.recovery_ahead_margin")?;
    at_least_one(g.inner_tries, "generator.inner_tries")?;
    at_least_one(g.outer_tries, "generator.outer_tries")?;
    for (value, limit, field) in [
        (g.ahead_margin, MAX_AHEAD_MARGIN, "generator.ahead_margin"),
        (
            g.recovery_ahead_margin,
            MAX_AHEAD_MARGIN,
            "generator.recovery_ahead_margin",
        ),
        (g.inner_tries, MAX_INNER_TRIES, "generator.inner_tries"),
        (g.outer_tries, MAX_OUTER_TRIES, "generator.outer_tries"),
    ] {
        at_most(value as f64, limit as f64, FAR, field)?;
    }
    non_negative(g.clearance_m, "generator.clearance_m")?;
    at_most(g.clearance_m, MAX_CLEARANCE_M, FAR, "generator.clearance_m")
}

fn check_campaign(c: &CampaignSettings) -> Check {
    at_least_one(c.tests, "campaign.tests")?;
    if c.tests > crate::MAX_TESTS {
        return Err((
            "campaign.tests".into(),
            Problem::TooMany {
                count: c.tests,
                max: crate::MAX_TESTS,
            },
        ));
    }
    counts(c.test_size, "campaign.test_size")?;
    at_most(
        c.test_size.max as f64,
        MAX_TEST_SIZE as f64,
        FAR,
        "campaign.test_size.max",
    )?;
    counts(c.points_per_segment, "campaign.points_per_segment")?;
    at_most(
        c.points_per_segment.max as f64,
        MAX_POINTS_PER_SEGMENT as f64,
        FAR,
        "campaign.points_per_segment.max",
    )?;
    ordered(c.speed_kmh, "campaign.speed_kmh")?;
    positive(c.speed_kmh.min, "campaign.speed_kmh.min")?;
    at_least(
        c.speed_kmh.min,
        MIN_SPEED_KMH,
        SLOW,
        "campaign.speed_kmh.min",
    )?;
    within(
        c.speed_kmh.max,
        0.0,
        MAX_SPEED_KMH,
        "campaign.speed_kmh.max",
    )?;
    positive(c.oracle_threshold_m, "campaign.oracle_threshold_m")?;
    if c.weights.run_segments == 0 {
        return Err((
            "campaign.weights.run_segments".into(),
            Problem::NotPositive(0.0),
        ));
    }
    check_faults(c)
}

/// A probe's list of fault kinds: not empty, no kind twice, no `none` (it does nothing).
fn fault_kinds(kinds: &[FaultKind], field: &str) -> Check {
    if kinds.is_empty() {
        return Err((format!("{field}.kinds"), Problem::Empty));
    }
    for (i, &kind) in kinds.iter().enumerate() {
        if kind.spec().param == Param::Unused {
            return Err((format!("{field}.kinds[{i}]"), Problem::NoneKind));
        }
        if kinds[..i].contains(&kind) {
            return Err((
                format!("{field}.kinds[{i}]"),
                Problem::DuplicateKind(kind.name()),
            ));
        }
    }
    Ok(())
}

/// Every fault section: its kinds, every kind's range as its parameter needs (a yaw within
/// ±180°), start and duration.
fn check_faults(c: &CampaignSettings) -> Check {
    for target in FaultTarget::ALL {
        let f = c.faults.get(target);
        let field = format!("campaign.faults.{}", target.section());
        fault_kinds(&f.kinds, &field)?;
        let shared = f.shares_param(target);
        for kind in FaultKind::drawable() {
            // The first form's one `param` was shared by the method's range faults: the kinds
            // drawn on a range by default (offset and amplification).
            let key = if shared && kind.drawn_by_default(Quantity::Range) {
                SHARED_PARAM_KEY.into()
            } else {
                target.key(kind).unwrap_or_default()
            };
            let field = format!("{field}.{key}");
            let range = f.range(kind);
            // Only a neutral value: every fault drawn would do nothing (a range that merely
            // includes it has its neutral draws drawn again by the generator).
            if let Some(neutral) = kind.spec().neutral
                && f.kinds.contains(&kind)
                && range.min == neutral
                && range.max == neutral
            {
                return Err((field, Problem::OnlyNeutral { neutral }));
            }
            ordered(range, &field)?;
            let quantity = target.quantity();
            for (end, v) in [("min", range.min), ("max", range.max)] {
                check_fault_param(kind, quantity, v).map_err(|problem| {
                    // A bound on the magnitude names the value it compared.
                    let absolute = matches!(problem, Problem::BeyondLimit(_));
                    let suffix = if absolute { " (absolute)" } else { "" };
                    (format!("{field}.{end}{suffix}"), problem)
                })?;
            }
        }
        probe_window(f.start, f.duration, &field)?;
    }
    Ok(())
}

/// Checks one parameter of a fault of `kind` on a probe carrying `quantity`: what a scenario's
/// fault range may hold and what a case file's fault may send. A bit (`bitflip`) is a whole
/// number within 0–31 (a binary32 value's bits); a yaw value (offset, set-to) within ±180°;
/// another value within ±[`MAX_FAULT_OFFSET`] in its unit; a factor within
/// ±[`MAX_FAULT_FACTOR`]; a kind without a parameter (`none`) takes any finite number.
pub fn check_fault_param(kind: FaultKind, quantity: Quantity, param: f64) -> Result<(), Problem> {
    let checked = match kind.spec().param {
        Param::Bit if param.is_finite() && param.fract() != 0.0 => {
            Err((String::new(), Problem::NotWhole(param)))
        }
        Param::Bit => within(param, 0.0, 31.0, ""),
        Param::Value if quantity == Quantity::Yaw => within(param, -180.0, 180.0, ""),
        Param::Value => {
            finite(param, "").and_then(|()| at_most(param.abs(), MAX_FAULT_OFFSET, FAR, ""))
        }
        Param::Factor => {
            finite(param, "").and_then(|()| at_most(param.abs(), MAX_FAULT_FACTOR, FAR, ""))
        }
        Param::Unused => finite(param, ""),
    };
    checked.map_err(|(_, problem)| problem)
}

/// Start and duration intervals of a fault, in probe iterations: ordered, duration at least 1.
fn probe_window(start: Interval<u32>, duration: Interval<u32>, field: &str) -> Check {
    ordered(as_f64(start), &format!("{field}.start"))?;
    if duration.min == 0 {
        return Err((format!("{field}.duration.min"), Problem::NotPositive(0.0)));
    }
    ordered(as_f64(duration), &format!("{field}.duration"))?;
    for (value, name) in [(start.max, "start.max"), (duration.max, "duration.max")] {
        at_most(
            f64::from(value),
            f64::from(MAX_FAULT_ITERATIONS),
            FAR,
            &format!("{field}.{name}"),
        )?;
    }
    Ok(())
}

fn check_route(area: &Area, route: &Route, field: &str) -> Check {
    if route.points.len() < 2 {
        return Err((
            field.into(),
            Problem::RouteTooShort {
                found: route.points.len(),
            },
        ));
    }
    for (i, p) in route.points.iter().enumerate() {
        route_speed(p.speed, &format!("{field}[{i}].speed"))?;
        if !area.contains_point(p.position) {
            return Err((
                format!("{field}[{i}]"),
                Problem::PointOutsideArea {
                    x: p.position.x,
                    y: p.position.y,
                },
            ));
        }
    }
    let points = route.positions();
    for (segment, w) in points.windows(2).enumerate() {
        if w[0] == w[1] {
            return Err((
                format!("{field}[{segment}]"),
                Problem::ZeroLengthSegment { segment },
            ));
        }
        if area.segment_meets_boundary(w[0], w[1]) {
            return Err((
                format!("{field}[{segment}]"),
                Problem::SegmentLeavesArea { segment },
            ));
        }
    }
    Ok(())
}

/// A threshold at least the area's diameter (its fence's bounding-box diagonal) tests nothing: no
/// UWB estimate inside the area can be that far from RTK, so every test would pass.
fn check_threshold(s: &Scenario) -> Check {
    let Some(bbox) = trajgen::BBox::around(s.area.fence().vertices().iter().copied()) else {
        return Ok(());
    };
    let diameter = bbox.min.dist(bbox.max);
    let threshold = s.campaign.oracle_threshold_m;
    if threshold >= diameter {
        return Err((
            "campaign.oracle_threshold_m".into(),
            Problem::ThresholdTestsNothing {
                threshold,
                diameter,
            },
        ));
    }
    Ok(())
}

/// A recovery route that ends near the start route's first point joins it by a straight step,
/// which must stay inside the area. One that ends farther away is joined by a planned route (the
/// runner plans it with the return-route planner; a warning says so).
fn check_join(s: &Scenario) -> Check {
    let (Some(end), Some(start)) = (s.recovery_route.last(), s.start_route.first()) else {
        return Ok(());
    };
    let (end, start) = (end.position, start.position);
    let gap = end.dist(start);
    if needs_planned_join(s) {
        return Ok(());
    }
    if gap > 0.0 && s.area.segment_meets_boundary(end, start) {
        return Err(("recovery_route".into(), Problem::JoinLeavesArea));
    }
    Ok(())
}

fn check_anchors(s: &Scenario) -> Check {
    if s.anchors.len() > MAX_ANCHORS {
        return Err(("anchors".into(), Problem::TooManyAnchors(s.anchors.len())));
    }
    for (i, anchor) in s.anchors.iter().enumerate() {
        finite(anchor.x, &format!("anchors[{i}].x"))?;
        finite(anchor.y, &format!("anchors[{i}].y"))?;
        finite(anchor.height, &format!("anchors[{i}].height"))?;
        if let Some(first) = s.anchors[..i].iter().position(|a| a.id == anchor.id) {
            return Err((
                format!("anchors[{i}].id"),
                Problem::DuplicateAnchorId {
                    id: anchor.id,
                    first,
                },
            ));
        }
    }
    Ok(())
}

fn check_environment(s: &Scenario) -> Check {
    for (i, obstacle) in s.environment.obstacles.iter().enumerate() {
        if obstacle.name.trim().is_empty() {
            return Err((format!("environment.obstacles[{i}].name"), Problem::Empty));
        }
    }
    for (i, wall) in s.environment.walls.iter().enumerate() {
        if wall.name.trim().is_empty() {
            return Err((format!("environment.walls[{i}].name"), Problem::Empty));
        }
        for (end, p) in [("a", wall.a), ("b", wall.b)] {
            finite(p.x, &format!("environment.walls[{i}].{end}.x"))?;
            finite(p.y, &format!("environment.walls[{i}].{end}.y"))?;
        }
        if wall.a == wall.b {
            return Err((
                format!("environment.walls[{i}]"),
                Problem::WallWithoutLength,
            ));
        }
    }
    Ok(())
}

/// One vertex of the hand-drawn approach (recovery route, then start route).
#[derive(Debug, Clone, Copy)]
struct Vertex {
    position: Point,
    /// `true` on the start route, `false` on the recovery route.
    on_start: bool,
    /// Index within its route.
    index: usize,
}

impl Vertex {
    fn field(&self) -> String {
        let route = if self.on_start {
            "start_route"
        } else {
            "recovery_route"
        };
        format!("{route}[{}]", self.index)
    }
}

/// The recovery route followed by the start route, as the car drives them, and the index of the
/// join segment (from the recovery route's last point to the start route's first) if there is one:
/// a recovery route that ends exactly on the start route's first point does not repeat it.
fn approach(s: &Scenario) -> (Vec<Vertex>, Option<usize>) {
    let vertex = |on_start: bool| {
        move |(index, p): (usize, &Waypoint)| Vertex {
            position: p.position,
            on_start,
            index,
        }
    };
    let mut chain: Vec<Vertex> = s
        .recovery_route
        .points
        .iter()
        .enumerate()
        .map(vertex(false))
        .collect();
    let mut start = s.start_route.points.iter().enumerate().map(vertex(true));
    let mut join = None;
    if let Some(first) = start.next() {
        if chain
            .last()
            .is_some_and(|last| last.position == first.position)
        {
            chain.pop();
        } else if !chain.is_empty() {
            join = Some(chain.len() - 1);
        }
        chain.push(first);
    }
    chain.extend(start);
    (chain, join)
}

/// Whether the recovery route ends farther from the start route's first point than
/// [`GeneratorSettings::recovery_join_max_m`]: the runner then plans the join (a warning says so).
pub fn needs_planned_join(s: &Scenario) -> bool {
    match (s.recovery_route.last(), s.start_route.first()) {
        (Some(end), Some(start)) => {
            end.position.dist(start.position) > s.generator.recovery_join_max_m()
        }
        _ => false,
    }
}

/// The soft problems of a valid scenario, in order: anchors, then along the approach.
pub(crate) fn warnings(s: &Scenario, source_name: &str) -> Vec<Warning> {
    let mut found: Vec<(String, WarningKind)> = Vec::new();
    if s.anchors.is_empty() {
        found.push(("anchors".into(), WarningKind::NoAnchors));
    }
    let planned = needs_planned_join(s);
    let (chain, join) = approach(s);
    for k in 0..chain.len() {
        let around_join = join.is_some_and(|j| k == j || k == j + 1);
        if k > 0 && k + 1 < chain.len() && !(planned && around_join) {
            found.extend(turn_warning(&s.generator, &chain[k - 1..=k + 1]));
        }
        if k + 1 < chain.len() {
            if planned && join == Some(k) {
                let gap = chain[k].position.dist(chain[k + 1].position);
                let limit = s.generator.recovery_join_max_m();
                found.push((chain[k].field(), WarningKind::JoinPlanned { gap, limit }));
            } else {
                found.extend(segment_warnings(s, chain[k], chain[k + 1], join == Some(k)));
            }
        }
    }
    found
        .into_iter()
        .map(|(field, kind)| Warning {
            source_name: source_name.to_owned(),
            field,
            kind,
        })
        .collect()
}

fn turn_warning(g: &GeneratorSettings, three: &[Vertex]) -> Option<(String, WarningKind)> {
    let before = (three[1].position - three[0].position).heading();
    let after = (three[2].position - three[1].position).heading();
    let turn_deg = turn_angle(before, after).abs().to_degrees();
    (turn_deg >= g.max_turn_deg).then(|| {
        (
            three[1].field(),
            WarningKind::SharpTurn {
                turn_deg,
                max_deg: g.max_turn_deg,
            },
        )
    })
}

fn segment_warnings(
    s: &Scenario,
    from: Vertex,
    to: Vertex,
    is_join: bool,
) -> Vec<(String, WarningKind)> {
    let g = &s.generator;
    let mut found = Vec::new();
    let length = from.position.dist(to.position);
    let (min, max) = (g.segment_min_m, g.segment_max_m);
    if !(min..=max).contains(&length) {
        let kind = if is_join {
            WarningKind::JoinLength { length, min, max }
        } else {
            WarningKind::SegmentLength {
                segment: from.index,
                length,
                min,
                max,
            }
        };
        found.push((from.field(), kind));
    }
    if g.clearance_m > 0.0 {
        let distance = s.area.segment_boundary_distance(from.position, to.position);
        if distance < g.clearance_m {
            let kind = WarningKind::NearEdge {
                distance,
                clearance: g.clearance_m,
            };
            found.push((from.field(), kind));
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use crate::tests::SQUARE;
    use crate::{Problem, WarningKind, from_toml_str};

    fn kinds(text: &str) -> Vec<(String, WarningKind)> {
        let loaded = from_toml_str(text, "s.toml").unwrap();
        loaded
            .warnings
            .into_iter()
            .map(|w| (w.field, w.kind))
            .collect()
    }

    #[test]
    fn a_clearance_warns_about_hand_drawn_segments_near_an_edge() {
        let text = format!("{SQUARE}\n[generator]\nclearance_m = 2.5\n");
        let near: Vec<String> = kinds(&text)
            .into_iter()
            .filter(|(_, k)| matches!(k, WarningKind::NearEdge { .. }))
            .map(|(field, _)| field)
            .collect();
        // Every segment runs 2 m from the fence: the recovery route, the join, the start route.
        assert_eq!(
            near,
            [
                "recovery_route[0]",
                "recovery_route[1]",
                "recovery_route[2]",
                "start_route[0]",
                "start_route[1]"
            ]
        );
    }

    #[test]
    fn a_recovery_route_ending_on_the_start_route_has_no_join() {
        let text = SQUARE.replace(
            "{ x = 2.0, y = 3.2, speed = 1.0 }",
            "{ x = 2.0, y = 2.0, speed = 1.0 }",
        );
        let found = kinds(&text);
        assert!(
            !found
                .iter()
                .any(|(_, k)| matches!(k, WarningKind::JoinLength { .. })),
            "{found:?}"
        );
        assert!(found.iter().any(|(f, k)| f == "recovery_route[1]"
            && matches!(k, WarningKind::SegmentLength { segment: 1, .. })));
        // The right-angle turn is now at the shared point, reported on the start route.
        assert!(
            found
                .iter()
                .any(|(f, k)| f == "start_route[0]" && matches!(k, WarningKind::SharpTurn { .. }))
        );
    }

    #[test]
    fn a_recovery_route_ending_far_from_the_start_route_is_accepted_with_a_planned_join() {
        // The recovery route ends 3.5 m from start_route[0] (the limit is 3 m), across a cutout
        // that a straight step would cross: the runner plans the join.
        let text = SQUARE
            .replace(
                "    { x = 2.0, y = 4.5, speed = 1.0 },\n    { x = 2.0, y = 3.2, speed = 1.0 },\n",
                "",
            )
            .replace(
                "{ x = 2.0, y = 6.0, speed = 1.0 }",
                "{ x = 4.0, y = 7.0, speed = 1.0 },\n    { x = 2.0, y = 5.5, speed = 1.0 }",
            )
            + "cutouts = [[{ x = 1.5, y = 3.5 }, { x = 2.5, y = 3.5 }, { x = 2.5, y = 3.8 }]]\n";
        let loaded = from_toml_str(&text, "s.toml").unwrap();
        assert!(crate::needs_planned_join(&loaded.scenario));
        let found: Vec<(String, WarningKind)> = loaded
            .warnings
            .into_iter()
            .map(|w| (w.field, w.kind))
            .collect();
        assert!(
            found.iter().any(|(f, k)| f == "recovery_route[1]"
                && matches!(k, WarningKind::JoinPlanned { gap, limit }
                    if (gap - 3.5).abs() < 1e-9 && (limit - 3.0).abs() < 1e-9)),
            "{found:?}"
        );
        assert!(
            !found
                .iter()
                .any(|(_, k)| matches!(k, WarningKind::JoinLength { .. })),
            "{found:?}"
        );
    }

    #[test]
    fn a_join_through_a_cutout_is_refused() {
        let text = format!(
            "{SQUARE}\ncutouts = [[{{ x = 1.5, y = 2.5 }}, {{ x = 2.5, y = 2.5 }}, {{ x = 2.5, y = 2.8 }}]]\n"
        );
        // The cutout sits between the recovery route's end (2, 3.2) and the start (2, 2).
        let error = from_toml_str(&text, "s.toml").unwrap_err();
        assert!(matches!(error.problem, Problem::JoinLeavesArea), "{error}");
    }

    /// The message of a coordinate beyond the bound.
    fn beyond(value: &str) -> String {
        format!(
            "{value} is beyond drivecheck's limit: in magnitude at most 100000 (coordinates are \
             local metres around the origin; the car's protocol carries a position of at most \
             214748 m)"
        )
    }

    #[test]
    fn coordinates_beyond_the_bound_are_refused_from_every_format_naming_the_field() {
        // TOML: a fence vertex (its area overflowed to NaN and the raster panicked), an anchor
        // (refused only when `run` uploaded it as a binary32), an anchor's height, a route point.
        let fence_vertex = SQUARE.replacen("{ x = 10.0, y = 0.0 }", "{ x = 1e155, y = 0.0 }", 1);
        let anchor = |x: &str, height: &str| {
            format!("{SQUARE}\n[[anchors]]\nid = 1\nx = {x}\ny = 0.0\nheight = {height}\n")
        };
        let cases = [
            (fence_vertex, "fence[1].x", beyond("1e155")),
            (anchor("1e308", "1.0"), "anchors[0].x", beyond("1e308")),
            (
                anchor("-3.0", "-1e300"),
                "anchors[0].height",
                beyond("-1e300"),
            ),
            (
                SQUARE.replacen("x = 5.0, y = 2.0", "x = 5.0, y = -2e5", 1),
                "start_route[2].y",
                beyond("-200000"),
            ),
            (
                format!(
                    "{SQUARE}\n[[environment.walls]]\nname = \"w\"\na = {{ x = 0.0, y = -1.0 }}\n\
                     b = {{ x = 1e300, y = -1.0 }}\n"
                ),
                "environment.walls[0].b.x",
                beyond("1e300"),
            ),
        ];
        for (text, field, message) in cases {
            let error = from_toml_str(&text, "s.toml").unwrap_err();
            assert_eq!(error.field(), Some(field), "{error}");
            assert!(error.place.location.is_some(), "{error}");
            assert!(error.to_string().ends_with(&message), "{error}");
        }
        // Just within the bound loads.
        from_toml_str(&anchor("-100000.0", "100000.0"), "s.toml").unwrap();

        // The reference XML.
        let route = |id: u8, points: &[(&str, &str)]| {
            let points: String = points
                .iter()
                .map(|(x, y)| format!("<point><x>{x}</x><y>{y}</y><speed>0.5</speed></point>"))
                .collect();
            format!("<route><id>{id}</id>{points}</route>")
        };
        let xml = format!(
            "<routes>{}{}{}</routes>",
            route(2, &[("0", "0"), ("1e155", "0"), ("10", "10"), ("0", "10")]),
            route(0, &[("2", "2"), ("3.5", "2"), ("5", "2")]),
            route(1, &[("2", "6"), ("2", "4.5"), ("2", "3.2")]),
        );
        let error = crate::from_xml_str(&xml, "s.xml", "s").unwrap_err();
        assert_eq!(error.field(), Some("fence[1].x"), "{error}");
        assert!(error.to_string().ends_with(&beyond("1e155")), "{error}");

        // GeoJSON in local metres.
        let line = |role: &str, points: &str| {
            format!(
                r#"{{"type": "Feature", "properties": {{"drivecheck": "route", "route": "{role}",
                "speeds": [1, 1, 1]}}, "geometry": {{"type": "LineString", "coordinates": {points}}}}}"#
            )
        };
        let geojson = format!(
            r#"{{"type": "FeatureCollection", "drivecheck": {{"version": 1, "crs": "local-enu-m"}},
            "features": [
              {{"type": "Feature", "properties": {{"drivecheck": "fence"}}, "geometry":
                {{"type": "Polygon", "coordinates": [[[0, 0], [1e155, 0], [10, 10], [0, 10], [0, 0]]]}}}},
              {}, {}]}}"#,
            line("start", "[[2, 2], [3.5, 2], [5, 2]]"),
            line("recovery", "[[2, 6], [2, 4.5], [2, 3.2]]"),
        );
        let options = crate::geojson::ReadOptions::default();
        let error =
            crate::geojson::from_geojson_str(&geojson, "s.geojson", "s", &options).unwrap_err();
        assert!(
            error.field().is_some_and(|f| f.contains("fence[1].x")),
            "{error}"
        );
        assert!(error.to_string().ends_with(&beyond("1e155")), "{error}");
    }

    #[test]
    fn route_speeds_beyond_the_autopilots_top_speed_are_refused() {
        let text = SQUARE.replacen(
            "x = 3.5, y = 2.0, speed = 1.0",
            "x = 3.5, y = 2.0, speed = 1e30",
            1,
        );
        let error = from_toml_str(&text, "s.toml").unwrap_err();
        assert_eq!(error.field(), Some("start_route[1].speed"));
        assert!(
            error.to_string().ends_with(
                "1e30 is beyond drivecheck's limit: at most 8.333333333333334 (the firmware \
                 autopilot's top speed, 30 km/h)"
            ),
            "{error}"
        );
        let text = SQUARE.replacen(
            "x = 3.5, y = 2.0, speed = 1.0",
            "x = 3.5, y = 2.0, speed = 8.3",
            1,
        );
        from_toml_str(&text, "s.toml").unwrap();
    }

    #[test]
    fn a_hand_built_scenario_is_checked_like_a_loaded_one() {
        let mut scenario = from_toml_str(SQUARE, "s.toml").unwrap().scenario;
        scenario.anchors.push(crate::Anchor {
            id: 3,
            x: f64::NAN,
            y: 0.0,
            height: 1.0,
        });
        let error = scenario.validate("built").unwrap_err();
        assert_eq!(
            error.to_string(),
            "built: anchors[0].x: not a finite number"
        );
        scenario.anchors.clear();
        scenario.start_route.points[1].position.x = f64::INFINITY;
        let error = scenario.validate("built").unwrap_err();
        assert_eq!(error.field(), Some("start_route[1].x"));
        // A fence built by hand far away: refused, where loading refuses it.
        let far = trajgen::Polygon::new(vec![
            crate::Point::new(0.0, 0.0),
            crate::Point::new(1e155, 0.0),
            crate::Point::new(0.0, 10.0),
        ])
        .unwrap();
        scenario.area = trajgen::Area::new(far, vec![]).unwrap();
        let error = scenario.validate("built").unwrap_err();
        assert_eq!(error.field(), Some("fence[1].x"));
    }

    #[test]
    fn fault_ranges_load_from_the_first_form_and_from_the_tables_keys() {
        use crate::settings::{FaultKind, FaultTarget, Interval};
        // The format's first form: one `param` for an anchor's offset and amplification.
        let old = "[campaign.faults.anchor_range]\nparam = { min = 0.5, max = 2.0 }\n\
                   [campaign.faults.wheel_slip]\noffset_m = { min = 0.0, max = 0.01 }";
        let loaded = from_toml_str(&format!("{SQUARE}\n{old}\n"), "s.toml").unwrap();
        let faults = &loaded.scenario.campaign.faults;
        for kind in [FaultKind::Offset, FaultKind::Amplification] {
            assert_eq!(faults.anchor_range.range(kind), Interval::new(0.5, 2.0));
        }
        assert_eq!(
            faults.wheel_slip.range(FaultKind::Offset),
            Interval::new(0.0, 0.01)
        );
        // Each kind under its own key; the canonical form writes them apart while they differ.
        let new = "[campaign.faults.anchor_range]\noffset_m = { min = 0.5, max = 2.0 }\n\
                   amplification = { min = 1.0, max = 3.0 }";
        let loaded = from_toml_str(&format!("{SQUARE}\n{new}\n"), "s.toml").unwrap();
        let anchor = loaded
            .scenario
            .campaign
            .faults
            .get(FaultTarget::AnchorRange);
        assert_eq!(anchor.range(FaultKind::Offset), Interval::new(0.5, 2.0));
        assert_eq!(
            anchor.range(FaultKind::Amplification),
            Interval::new(1.0, 3.0)
        );
        let text = crate::to_toml(&loaded.scenario);
        assert!(
            text.contains("offset_m = { min = 0.5, max = 2.0 }"),
            "{text}"
        );
        assert!(!text.contains("param ="), "{text}");
        assert_eq!(
            from_toml_str(&text, "again.toml").unwrap().scenario,
            loaded.scenario
        );
    }

    #[test]
    fn origin_and_settings_are_range_checked() {
        let cases = [
            (
                "[origin]\nlat = 91.0\nlon = 0.0\nheight = 0.0",
                "origin.lat: 91 is outside -90..=90",
            ),
            (
                "[vehicle]\nwidth_m = -0.5",
                "vehicle.width_m: must be greater than 0, found -0.5",
            ),
            (
                "[generator]\nclearance_m = -1.0",
                "generator.clearance_m: must not be negative, found -1",
            ),
            (
                "[generator]\nmax_turn_deg = inf",
                "generator.max_turn_deg: not a finite number",
            ),
            (
                "[campaign]\nspeed_kmh = { min = 3.0, max = 40.0 }",
                "campaign.speed_kmh.max: 40 is outside 0..=30",
            ),
            (
                "[campaign]\ntest_size = { min = 0, max = 3 }",
                "campaign.test_size.min: must be greater than 0, found 0",
            ),
            (
                "[campaign.faults.yaw]\nduration = { min = 0, max = 3 }",
                "campaign.faults.yaw.duration.min: must be greater than 0, found 0",
            ),
            (
                "[campaign.faults.anchor_range]\nkinds = []",
                "campaign.faults.anchor_range.kinds: must not be empty",
            ),
            (
                "[campaign.faults.wheel_slip]\nkinds = [\"amplification\", \"none\"]",
                "campaign.faults.wheel_slip.kinds[1]: `none` does nothing (it only occupies a fault slot): leave it out",
            ),
            (
                "[campaign.faults.yaw]\nkinds = [\"set_to\", \"set_to\"]",
                "campaign.faults.yaw.kinds[1]: `set_to` is listed twice",
            ),
            (
                "[campaign.faults.anchor_range]\nkinds = [\"bitflip\"]\nbitflip_bits = { min = 20, max = 32 }",
                "campaign.faults.anchor_range.bitflip_bits.max: 32 is outside 0..=31",
            ),
            (
                "[campaign.faults.yaw]\nkinds = [\"bitflip\"]\nbitflip_bits = { min = 20.5, max = 30 }",
                "campaign.faults.yaw.bitflip_bits.min: must be a whole number, found 20.5",
            ),
            (
                "[campaign.faults.yaw]\nset_to_deg = { min = -190.0, max = 0.0 }",
                "campaign.faults.yaw.set_to_deg.min: -190 is outside -180..=180",
            ),
            (
                "[campaign.faults.anchor_range]\noffset_m = { min = 2.0, max = 1.0 }",
                "campaign.faults.anchor_range.offset_m: min 2 is greater than max 1",
            ),
            (
                "[campaign.faults.wheel_slip]\noffset_deg = { min = 0.0, max = 1.0 }",
                "campaign.faults: unknown field `offset_deg` in wheel_slip, expected one of \
                 `kinds`, `start`, `duration`, `offset_m`, `amplification`, `set_to_m`, \
                 `bitflip_bits`",
            ),
            (
                "[campaign.faults.anchor_range]\nparam = { min = 0.0, max = 1.0 }\namplification = { min = 1.0, max = 2.0 }",
                "campaign.faults: anchor_range.amplification and anchor_range.param both give the \
                 range of amplification",
            ),
            (
                "[generator]\nahead_margin = 4000000000",
                "generator.ahead_margin: 4e9 is beyond drivecheck's limit: at most 200 (far \
                 beyond any real test; a larger value only exhausts memory or time)",
            ),
            (
                "[campaign]\ntest_size = { min = 5, max = 100000000 }",
                "campaign.test_size.max: 100000000 is beyond drivecheck's limit: at most 1000 (far \
                 beyond any real test; a larger value only exhausts memory or time)",
            ),
            (
                "[campaign]\npoints_per_segment = { min = 4, max = 100000000 }",
                "campaign.points_per_segment.max: 100000000 is beyond drivecheck's limit: at most \
                 100 (far beyond any real test; a larger value only exhausts memory or time)",
            ),
            (
                "[campaign]\nspeed_kmh = { min = 1e-9, max = 3.0 }",
                "campaign.speed_kmh.min: 1e-9 is beyond drivecheck's limit: at least 0.5 \
                 (slower, one segment of a test takes minutes)",
            ),
            (
                "[campaign.faults.anchor_range]\noffset_m = { min = 0.5, max = 1e300 }",
                "campaign.faults.anchor_range.offset_m.max (absolute): 1e300 is beyond \
                 drivecheck's limit: at most 1000 (far beyond any real test; a larger value only \
                 exhausts memory or time)",
            ),
            (
                "[campaign.faults.wheel_slip]\namplification = { min = -1e300, max = 2.0 }",
                "campaign.faults.wheel_slip.amplification.min (absolute): 1e300 is beyond \
                 drivecheck's limit: at most 1000 (far beyond any real test; a larger value only \
                 exhausts memory or time)",
            ),
            (
                "[campaign.faults.wheel_slip]\namplification = { min = 1.0, max = 1.0 }",
                "campaign.faults.wheel_slip.amplification: holds only 1, which leaves the probe's \
                 value as it is: a fault that does nothing (widen the range or leave the kind out)",
            ),
            (
                "[[environment.obstacles]]\nname = \" \"\npolygon = [{ x = 0.0, y = -1.0 }, { x = 1.0, y = -1.0 }, { x = 1.0, y = -2.0 }]",
                "environment.obstacles[0].name: must not be empty",
            ),
        ];
        for (section, expected) in cases {
            let text = format!("{SQUARE}\n{section}\n");
            let mut error = from_toml_str(&text, "s.toml").unwrap_err();
            // The error points into the section that holds the field.
            let line = error.place.location.expect("located").line;
            assert!(line > SQUARE.lines().count(), "{error}");
            error.place.location = None;
            assert_eq!(error.to_string(), format!("s.toml: {expected}"));
        }
    }
}
