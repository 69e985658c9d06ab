//! A case's route on the map and in time: its segments' points, where a fault's place lies, and
//! when the car entered each segment (located on its route as the runner locates it).

use scenarios::Scenario;
use trajgen::{Point, Waypoint};

use super::data::Sample;
use campaign::case::{Case, CommandRecord};
use campaign::drive::start_route;
use campaign::streaming::locate;

/// The points of a case's segments, in order.
pub fn segments(case: &Case) -> Vec<Vec<Point>> {
    case.commands
        .iter()
        .filter_map(|c| match c {
            CommandRecord::RunSegments { points, .. } => {
                Some(points.iter().map(|p| Point::new(p.x, p.y)).collect())
            }
            CommandRecord::AddFault { .. } => None,
        })
        .collect()
}

/// Where segment `segment` starts: the end of the one before it, or of the start route.
fn segment_start(scenario: &Scenario, segments: &[Vec<Point>], segment: usize) -> Option<Point> {
    match segment.checked_sub(1) {
        None => scenario.start_route.points.last().map(|w| w.position),
        Some(before) => segments.get(before)?.last().copied(),
    }
}

/// The point `along_m` metres along segment `segment` from its start (the end of the route
/// before it), as a fault's place is measured; clamped to the segment's end.
pub fn point_along(
    scenario: &Scenario,
    segments: &[Vec<Point>],
    segment: usize,
    along_m: f64,
) -> Option<Point> {
    let start = segment_start(scenario, segments, segment)?;
    let points = segments.get(segment)?;
    let mut left = along_m.max(0.0);
    let mut from = start;
    for &to in points {
        let length = from.dist(to);
        if left <= length && length > 0.0 {
            return Some(from + (to - from) * (left / length));
        }
        left -= length;
        from = to;
    }
    Some(from)
}

/// A vertical line of the deviation plot: when the car entered a segment (or left the last one
/// judged).
#[derive(Debug, Clone, PartialEq)]
pub struct Boundary {
    /// Seconds since the test began.
    pub t_s: f64,
    /// Its label (`s3`, `end`).
    pub label: String,
}

/// When the car entered each judged segment, and when it left the last one: every sample from
/// the test's beginning is located on the test's route (the start route from where the car
/// stood, then the segments) with `campaign::streaming::locate`, from the last place found, as
/// the runner does; a segment begins on the stretch that leads to its first point, as the
/// runner's oracle counts it. Empty without samples.
pub fn boundaries(scenario: &Scenario, case: &Case, samples: &[Sample]) -> Vec<Boundary> {
    let Some(judged) = case.segments.iter().map(|s| s.segment_index).max() else {
        return Vec::new();
    };
    let driving: Vec<&Sample> = samples
        .iter()
        .filter(|s| s.t_s >= 0.0 && s.rtk.is_finite())
        .collect();
    let Some(standing) = driving.first().map(|s| s.rtk) else {
        return Vec::new();
    };
    let mut route: Vec<Waypoint> = start_route(&scenario.start_route, standing);
    let mut firsts = Vec::new();
    // The segment after the last judged one (if the case has it) shows when the car left it.
    for points in segments(case).into_iter().take(judged + 2) {
        firsts.push(route.len());
        route.extend(points.into_iter().map(|position| Waypoint {
            position,
            speed: 1.0,
        }));
    }
    let last_stretch = route.len().saturating_sub(2);
    let mut entered: Vec<Option<f64>> = vec![None; firsts.len()];
    let mut end = None;
    let mut stretch = 0;
    for sample in driving {
        let Some(progress) = locate(&route, sample.rtk, stretch) else {
            continue;
        };
        stretch = progress.segment;
        if let Some(k) = firsts.iter().rposition(|&first| first <= stretch + 1) {
            for slot in entered.iter_mut().take(k + 1) {
                slot.get_or_insert(sample.t_s);
            }
        }
        if stretch == last_stretch && progress.fraction >= 1.0 {
            end.get_or_insert(sample.t_s);
        }
    }
    let mut lines: Vec<Boundary> = entered
        .iter()
        .take(judged + 1)
        .enumerate()
        .filter_map(|(k, t)| {
            t.map(|t_s| Boundary {
                t_s,
                label: format!("s{k}"),
            })
        })
        .collect();
    let left = entered.get(judged + 1).copied().flatten().or(end);
    if let Some(t_s) = left {
        lines.push(Boundary {
            t_s,
            label: "end".to_owned(),
        });
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_place_is_measured_from_the_end_of_the_route_before_it() {
        let scenario = scenarios::bundled::load("courtyard").unwrap().scenario;
        let start = scenario.start_route.points.last().unwrap().position;
        let first = Point::new(start.x + 1.0, start.y);
        let second = Point::new(start.x + 1.0, start.y + 2.0);
        let segments = vec![vec![first, second]];
        let at = point_along(&scenario, &segments, 0, 0.5).unwrap();
        assert!(at.dist(Point::new(start.x + 0.5, start.y)) < 1e-9);
        let at = point_along(&scenario, &segments, 0, 2.0).unwrap();
        assert!(at.dist(Point::new(start.x + 1.0, start.y + 1.0)) < 1e-9);
        let beyond = point_along(&scenario, &segments, 0, 10.0).unwrap();
        assert_eq!(beyond, second);
        assert!(point_along(&scenario, &segments, 1, 0.0).is_none());
    }
}
