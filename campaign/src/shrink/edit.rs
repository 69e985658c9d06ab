//! The edits a shrink tries, and how each one turns a case into a simpler one.

use std::fmt;

use std::collections::HashMap;

use recovery::{PlanConfig, Pose, ReturnRoute, SearchConfig};
use scenarios::Scenario;
use serde::{Deserialize, Serialize};
use thiserror::Error;
use trajgen::{Point, RouteTail};

use crate::files::{Case, CommandRecord, PlaceRecord, RoutePointRecord};
use crate::model::{FaultKind, ModelError, start_tail};

use super::Target;

/// A fault value a shrink moves toward neutral.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultField {
    /// The fault's parameter (offset → 0, amplification → 1).
    Param,
    /// Probe calls before it applies (→ 0).
    Start,
    /// Probe calls it applies for (→ 1).
    Duration,
}

impl FaultField {
    /// Sets this value of `command` to `value` (start and duration: whole probe calls); false
    /// when `command` is not a fault.
    pub fn set(self, command: &mut CommandRecord, value: f64) -> bool {
        let CommandRecord::AddFault {
            param,
            start,
            duration,
            ..
        } = command
        else {
            return false;
        };
        match self {
            Self::Param => *param = value,
            Self::Start => *start = value as u32,
            Self::Duration => *duration = value as u32,
        }
        true
    }

    fn name(self) -> &'static str {
        match self {
            Self::Param => "param",
            Self::Start => "start",
            Self::Duration => "duration",
        }
    }
}

/// One change a shrink tries on a case (segments are counted from 0 among the case's segments;
/// commands by their index in the case being changed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "edit", rename_all = "snake_case", deny_unknown_fields)]
pub enum Edit {
    /// Remove every segment after `after_segment` (the failing one) and the faults placed on
    /// them.
    CutTail {
        /// The last segment kept.
        after_segment: usize,
        /// Segments removed.
        segments_removed: usize,
    },
    /// Remove every fault command.
    DropAllFaults {
        /// Fault commands removed.
        faults: usize,
    },
    /// Remove one fault command.
    DropFault {
        /// Its index in the case.
        command_index: usize,
    },
    /// Remove segments `first..=last` and join the route before them to the segment after them
    /// with a route the return-route planner makes (turn and segment limits, clearance); the
    /// join becomes the start of that segment. Faults placed on a removed segment move to the
    /// start of the joined segment.
    DropSegments {
        /// The first segment removed.
        first: usize,
        /// The last segment removed.
        last: usize,
    },
    /// Move one value of a fault toward neutral.
    FaultValue {
        /// The fault command's index.
        command_index: usize,
        /// Which value.
        field: FaultField,
        /// Its value before.
        from: f64,
        /// Its value after.
        to: f64,
    },
    /// Drive a segment slower (every point's speed).
    SlowSegment {
        /// The segment.
        segment_index: usize,
        /// Its speed before, m/s (its first point's).
        from_mps: f64,
        /// Its speed after, m/s.
        to_mps: f64,
    },
    /// Drop the last points of a segment (its ahead margin is generated anew).
    TrimSegment {
        /// The segment (always the last one).
        segment_index: usize,
        /// Points before.
        from_points: usize,
        /// Points after.
        to_points: usize,
    },
}

impl fmt::Display for Edit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::CutTail {
                after_segment,
                segments_removed,
            } => write!(
                f,
                "cut the {segments_removed} segment(s) after segment {after_segment}"
            ),
            Self::DropAllFaults { faults } => write!(f, "drop all {faults} faults"),
            Self::DropFault { command_index } => write!(f, "drop fault commands[{command_index}]"),
            Self::DropSegments { first, last } if first == last => {
                write!(f, "drop segment {first}, joining its neighbours")
            }
            Self::DropSegments { first, last } => {
                write!(f, "drop segments {first}–{last}, joining their neighbours")
            }
            Self::FaultValue {
                command_index,
                field,
                from,
                to,
            } => write!(
                f,
                "commands[{command_index}].{} {} → {}",
                field.name(),
                short(from),
                short(to)
            ),
            Self::SlowSegment {
                segment_index,
                from_mps,
                to_mps,
            } => write!(
                f,
                "segment {segment_index} at {from_mps:.2} → {to_mps:.2} m/s"
            ),
            Self::TrimSegment {
                segment_index,
                from_points,
                to_points,
            } => write!(
                f,
                "segment {segment_index}: {from_points} → {to_points} points"
            ),
        }
    }
}

fn short(value: f64) -> String {
    let text = format!("{value:.3}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    text.to_owned()
}

/// The value a fault's field shrinks toward, if it has one (a parameter: its kind's neutral one,
/// from the fault table; set_to and bitflip have none).
pub(super) fn neutral(kind: FaultKind, field: FaultField) -> Option<f64> {
    match (field, kind) {
        (FaultField::Start, _) => Some(0.0),
        (FaultField::Duration, _) => Some(1.0),
        (FaultField::Param, kind) => kind.spec().neutral,
    }
}

/// `fraction` of the way from `from` to `to`, rounded to `step`; `None` when that is `from` or
/// `to` already.
pub(super) fn part_way(from: f64, to: f64, fraction: f64, step: f64) -> Option<f64> {
    let value = ((from + (to - from) * fraction) / step).round() * step;
    ((value - from).abs() >= step / 2.0 && (value - to).abs() >= step / 2.0).then_some(value)
}

/// The command indices of a case's segments, in order.
pub(super) fn segment_commands(case: &Case) -> Vec<usize> {
    case.commands
        .iter()
        .enumerate()
        .filter(|(_, c)| matches!(c, CommandRecord::RunSegments { .. }))
        .map(|(i, _)| i)
        .collect()
}

/// The segment a fault belongs to: its place's, or (without one) the segment before it.
fn home_segment(case: &Case, command_index: usize) -> Option<usize> {
    match &case.commands[command_index] {
        CommandRecord::AddFault { at: Some(at), .. } => Some(at.segment_index),
        CommandRecord::AddFault { at: None, .. } => case.commands[..command_index]
            .iter()
            .filter(|c| matches!(c, CommandRecord::RunSegments { .. }))
            .count()
            .checked_sub(1),
        CommandRecord::RunSegments { .. } => None,
    }
}

fn points_of(record: &CommandRecord) -> &[RoutePointRecord] {
    match record {
        CommandRecord::RunSegments { points, .. } => points,
        CommandRecord::AddFault { .. } => &[],
    }
}

fn polyline_length(points: &[Point]) -> f64 {
    points.windows(2).map(|w| w[0].dist(w[1])).sum()
}

/// Why an edit gives no case to drive (recorded as the step's `not_drivable`).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EditError {
    /// The edit names a command that is not a fault command.
    #[error("commands[{command_index}] is not a fault")]
    NotAFault {
        /// The command.
        command_index: usize,
    },
    /// Segments to drop have no segment after them to join to.
    #[error("no segment after segment {last} to join")]
    NothingToJoin {
        /// The last segment to drop.
        last: usize,
    },
    /// The return-route planner found no route joining the segments around the dropped ones.
    #[error("no joining route: {0}")]
    NoJoin(#[source] recovery::RecoveryError),
    /// The scenario's start route gives no route tail.
    #[error("the scenario's start route: {0}")]
    StartTail(#[source] ModelError),
}

/// Nodes a joining route's search may expand: a join that needs more is a long detour, not a
/// simpler test (a return route gets 20 000).
const JOIN_EXPANSIONS: u64 = 3_000;

/// The joining routes planned so far, by their inputs: a shrink tries the same join again after
/// every kept edit, and a failed search is the costliest thing it does.
#[derive(Debug, Default)]
pub(super) struct Joins(HashMap<Vec<u64>, Result<ReturnRoute, EditError>>);

impl Joins {
    /// The joining route from `from` to `route` (deterministic: seeded with `seed`).
    fn plan(
        &mut self,
        scenario: &Scenario,
        from: RouteTail,
        route: &[Point],
        seed: u64,
    ) -> Result<ReturnRoute, EditError> {
        let key: Vec<u64> = [from.end.x, from.end.y, from.heading]
            .into_iter()
            .chain(route.iter().flat_map(|p| [p.x, p.y]))
            .map(f64::to_bits)
            .chain([seed])
            .collect();
        self.0
            .entry(key)
            .or_insert_with(|| {
                let config = PlanConfig::default().with_search(SearchConfig {
                    max_expansions: JOIN_EXPANSIONS,
                    ..SearchConfig::default()
                });
                config
                    .plan(
                        &scenario.area,
                        Pose::new(from.end, from.heading),
                        route,
                        &scenario.constraints(),
                        &mut crate::seed::rng_for(seed, crate::seed::Purpose::ShrinkJoin),
                    )
                    .map_err(EditError::NoJoin)
            })
            .clone()
    }
}

/// What applying an edit gives: the changed case (results not yet cleared) and where the
/// failing segment now is.
pub(super) type Applied = Result<(Case, Target), EditError>;

impl Edit {
    /// Applies the edit to `case`, whose failing segment is `target`.
    pub(super) fn apply(
        &self,
        case: &Case,
        target: Target,
        scenario: &Scenario,
        seed: u64,
        joins: &mut Joins,
    ) -> Applied {
        let mut out = case.clone();
        match *self {
            Self::CutTail { after_segment, .. } => {
                let mut segments = 0usize;
                let mut keep = Vec::with_capacity(case.commands.len());
                for (i, command) in case.commands.iter().enumerate() {
                    let kept = match command {
                        CommandRecord::RunSegments { .. } => {
                            segments += 1;
                            segments - 1 <= after_segment
                        }
                        CommandRecord::AddFault { .. } => {
                            home_segment(case, i).is_none_or(|s| s <= after_segment)
                        }
                    };
                    if kept {
                        keep.push(command.clone());
                    }
                }
                out.commands = keep;
                Ok((out, target))
            }
            Self::DropAllFaults { .. } => {
                out.commands
                    .retain(|c| matches!(c, CommandRecord::RunSegments { .. }));
                Ok((out, target))
            }
            Self::DropFault { command_index } => {
                if !matches!(
                    case.commands.get(command_index),
                    Some(CommandRecord::AddFault { .. })
                ) {
                    return Err(EditError::NotAFault { command_index });
                }
                out.commands.remove(command_index);
                Ok((out, target))
            }
            Self::DropSegments { first, last } => {
                drop_segments(case, target, scenario, seed, joins, first, last)
            }
            Self::FaultValue {
                command_index,
                field,
                to,
                ..
            } => {
                let set = out
                    .commands
                    .get_mut(command_index)
                    .is_some_and(|command| field.set(command, to));
                if set {
                    Ok((out, target))
                } else {
                    Err(EditError::NotAFault { command_index })
                }
            }
            Self::SlowSegment {
                segment_index,
                to_mps,
                ..
            } => {
                let command = segment_commands(case)[segment_index];
                if let CommandRecord::RunSegments { points, .. } = &mut out.commands[command] {
                    for p in points {
                        p.speed = to_mps;
                    }
                }
                Ok((out, target))
            }
            Self::TrimSegment {
                segment_index,
                to_points,
                ..
            } => {
                let command = segment_commands(case)[segment_index];
                let tail = tail_before(case, scenario, segment_index)?;
                let mut length = 0.0;
                if let CommandRecord::RunSegments {
                    points,
                    margin,
                    intent,
                } = &mut out.commands[command]
                {
                    points.truncate(to_points);
                    margin.clear();
                    *intent = None;
                    let route: Vec<Point> = std::iter::once(tail.end)
                        .chain(points.iter().map(RoutePointRecord::position))
                        .collect();
                    length = polyline_length(&route);
                }
                for command in &mut out.commands {
                    if let CommandRecord::AddFault { at: Some(at), .. } = command
                        && at.segment_index == segment_index
                    {
                        at.along_m = at.along_m.min(length);
                    }
                }
                Ok((out, target))
            }
        }
    }
}

/// The route's tail before segment `segment_index` (the start route's end for segment 0).
fn tail_before(
    case: &Case,
    scenario: &Scenario,
    segment_index: usize,
) -> Result<RouteTail, EditError> {
    let mut tail = start_tail(scenario).map_err(EditError::StartTail)?;
    for &command in segment_commands(case).iter().take(segment_index) {
        let points: Vec<Point> = points_of(&case.commands[command])
            .iter()
            .map(RoutePointRecord::position)
            .collect();
        tail = tail.advanced(&points);
    }
    Ok(tail)
}

/// Removes segments `first..=last` and joins the route before them to segment `last + 1` with a
/// planned route (see [`Edit::DropSegments`]).
fn drop_segments(
    case: &Case,
    target: Target,
    scenario: &Scenario,
    seed: u64,
    joins: &mut Joins,
    first: usize,
    last: usize,
) -> Applied {
    let segments = segment_commands(case);
    let next = last + 1;
    if first > last || next >= segments.len() {
        return Err(EditError::NothingToJoin { last });
    }
    let from = tail_before(case, scenario, first)?;
    let before_next = tail_before(case, scenario, next)?.end;
    let next_points = points_of(&case.commands[segments[next]]);
    let recovery_route: Vec<Point> = std::iter::once(before_next)
        .chain(next_points.iter().map(RoutePointRecord::position))
        .collect();
    let route = joins.plan(scenario, from, &recovery_route, seed)?;
    let join = route.join;
    let speed = next_points[0].speed;
    // The merged segment: the joining route (without the car's position it starts from), then
    // the next segment from the point after the joint.
    let mut merged: Vec<RoutePointRecord> = route.points[1..]
        .iter()
        .map(|p| RoutePointRecord {
            x: p.x,
            y: p.y,
            speed,
        })
        .collect();
    merged.extend_from_slice(&next_points[join.segment..]);
    let join_length = polyline_length(&route.points);
    let removed_length = polyline_length(&recovery_route[..=join.segment])
        + recovery_route[join.segment].dist(join.point);
    let removed = next - first;
    let margin = match &case.commands[segments[next]] {
        CommandRecord::RunSegments { margin, .. } => margin.clone(),
        CommandRecord::AddFault { .. } => Vec::new(),
    };
    let mut commands = Vec::with_capacity(case.commands.len());
    let mut segment = 0usize;
    for command in &case.commands {
        match command {
            CommandRecord::RunSegments { .. } => {
                if segment == first {
                    commands.push(CommandRecord::RunSegments {
                        intent: None,
                        points: merged.clone(),
                        margin: margin.clone(),
                    });
                } else if !(first..=next).contains(&segment) {
                    commands.push(command.clone());
                }
                segment += 1;
            }
            CommandRecord::AddFault { .. } => {
                let mut command = command.clone();
                if let CommandRecord::AddFault { at: Some(at), .. } = &mut command {
                    *at = match at.segment_index {
                        s if s < first => *at,
                        s if s < next => PlaceRecord {
                            segment_index: first,
                            along_m: 0.0,
                        },
                        s if s == next => PlaceRecord {
                            segment_index: first,
                            along_m: join_length + (at.along_m - removed_length).max(0.0),
                        },
                        s => PlaceRecord {
                            segment_index: s - removed,
                            along_m: at.along_m,
                        },
                    };
                }
                commands.push(command);
            }
        }
    }
    let mut out = case.clone();
    out.commands = commands;
    Ok((out, target.moved_back(removed)))
}
