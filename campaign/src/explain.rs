//! Why a segment failed: the ranked causes of the growth of its UWB error, from residuals.
//!
//! Inputs are what a real car reports and what the campaign knows: the state samples (RTK and
//! UWB positions; the heading is the direction the RTK track moves), the anchors, and the fault
//! schedule (each fault's estimated window, from its place and the probe's call rate). The
//! simulated car's hidden truth is never used here (only to score the result, elsewhere).
//!
//! **The method.** The UWB error is `e(t) = UWB − RTK`. The firmware's estimator moves the
//! estimate in three kinds of direction, so each kind of cause leaves its own signature in how
//! `e` changes from one sample to the next:
//!
//! - a range from anchor *A* corrects the estimate along the line from *A* (at most 0.2 m a
//!   correction): a wrong range (a reflection, a range fault) moves `e` along `u_A`, the unit
//!   vector from *A* to the estimate;
//! - a wrong travelled distance (wheel slip, an odometry fault) moves it along the heading `h`;
//! - a wrong yaw (a yaw fault, a heading error) moves it across the heading, along `n`.
//!
//! For a failing segment the growth interval is the stretch before the first sample above the
//! threshold during which the error grew from its last nominal level, however long before (a
//! segment whose error never came back from an earlier failure fails for what made it grow
//! then). Each step between two samples in which the error grows
//! (`Δe · e/|e| > 0`) gives its growth to the direction its `Δe` is most aligned with, when that
//! alignment (|cos|) reaches [`ExplainConfig::min_alignment`]; otherwise to `unexplained`. The
//! injected faults come first: a step goes to a fault whose window (widened by
//! [`ExplainConfig::window_slack_s`]) covers it when the step is aligned, at least that well,
//! with the direction the fault moves the estimate in (a range fault on *A* along `u_A`, a
//! `uwb_travel_dist` fault along `h`, a `uwb_yaw` fault across it: a yaw offset of α degrees
//! turns the dead-reckoned track by α, which moves `e` along `n` turned by −α/2, the firmware's
//! yaw being clockwise), the best aligned of them if several; the schedule says the fault is
//! acting, which an unfaulted direction, even better aligned by a few degrees, cannot claim.
//! Otherwise the step goes to the best-aligned of the anchors' ranges, the odometry and the
//! heading, and to a fault on that direction's probe whose window covers it. Either way, the
//! faults on that probe whose windows cover the step as well act together: the step is shared
//! among them by how much each changes the probe's value (|offset|, |factor − 1|; equally when
//! their kinds differ). A cause's share is its growth
//! over the whole growth; causes below [`ExplainConfig::min_growth_m`] are left to
//! `unexplained` (the threshold a fault-free calibration sets: see `docs/explain.md`).
//!
//! **Directions that coincide.** An anchor straight ahead or behind moves the estimate along the
//! heading, as odometry does; one abeam across it, as the heading does. When a step cannot tell
//! such an anchor from the drift by direction, it tells them by time: a range corrects the
//! estimate in one jump at its anchor's ranging instant, dead reckoning a little at every tick, so
//! the step is the anchor's when it holds more growth in its direction than the two steps each
//! side of it together (less than one ranging period), the drift's otherwise. The cause still
//! records the other in `ambiguous_with`.
//! Growth that happened before the growth interval (a standing offset) is not explained.
//!
//! **How well it does, and its thresholds.** [`score`] scores an explanation against a simulated
//! run's hidden truth, [`counterfactual`] settles which of several faults was the truth by
//! driving the case again without each (the driving is the caller's), and [`calibrate`] sets the
//! thresholds from a fault-free run (the explaining is the caller's).

pub mod calibrate;
pub mod counterfactual;
pub mod score;

use serde::{Deserialize, Serialize};
use trajgen::Point;

use car_link::{FaultKind, Probe};

use crate::files::{CauseRecord, SegmentExplanationRecord, SourceRecord};

/// One state sample on the test's clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExplainSample {
    /// Seconds since the test began.
    pub t_s: f64,
    /// The RTK (fused) position.
    pub rtk: Point,
    /// The UWB position.
    pub uwb: Point,
}

/// An anchor of the area.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExplainAnchor {
    /// Its id.
    pub id: u16,
    /// Its position.
    pub position: Point,
}

/// An injected fault and when it is estimated to act.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExplainFault {
    /// Its command's index in the case.
    pub command_index: usize,
    /// The probe it acts on.
    pub probe: Probe,
    /// What it does (a yaw offset turns the direction it moves the estimate in).
    pub kind: FaultKind,
    /// Its parameter (degrees for a yaw offset).
    pub param: f64,
    /// When it is estimated to begin acting, seconds since the test began.
    pub acts_from_s: f64,
    /// When it is estimated to stop.
    pub acts_to_s: f64,
}

/// A segment to explain: when the car drove it and how the oracle judged it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExplainSegment {
    /// Its index among the test's segments.
    pub segment_index: usize,
    /// When the car entered it, seconds since the test began.
    pub from_s: f64,
    /// When it left it (or the test ended).
    pub to_s: f64,
    /// Whether the oracle failed it.
    pub failed: bool,
}

/// The method's settings (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ExplainConfig {
    /// The oracle's threshold, metres.
    pub threshold_m: f64,
    /// The error level taken as nominal: the growth interval starts where the error last was
    /// at or below it, metres. The default, 0.49 m, is the calibration (`drivecheck explain
    /// --calibrate`, 1 % budget) on 100 fault-free tests of the bundled two-anchor lot (seed 1:
    /// 0.486 m; seed 2: 0.483 m).
    pub nominal_m: f64,
    /// The least |cos| between a step's `Δe` and a direction for the step to count for it.
    pub min_alignment: f64,
    /// How much wider than its estimated window a fault is taken to act, seconds each side (the
    /// window is estimated from probe rates; a range probe is called only when a range arrives).
    pub window_slack_s: f64,
    /// A cause below this growth, metres, is left to `unexplained`. The default, 0.08 m, is the
    /// same calibration's (seed 1: 0.076 m; seed 2: 0.081 m).
    pub min_growth_m: f64,
    /// Directions closer than this |cos| to the best one are named as ambiguous with it.
    pub ambiguity_cos: f64,
}

impl Default for ExplainConfig {
    fn default() -> Self {
        Self {
            threshold_m: 1.0,
            nominal_m: 0.49,
            min_alignment: 0.8,
            window_slack_s: 1.0,
            min_growth_m: 0.08,
            ambiguity_cos: 0.95,
        }
    }
}

/// Where a cause comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "source")]
pub enum Source {
    /// An injected fault.
    Fault {
        /// Its command's index in the case.
        command_index: usize,
    },
    /// An anchor's ranges (a reflection, a blocked line of sight, a wrong survey).
    Anchor {
        /// Its id.
        anchor_id: u16,
    },
    /// The travelled distance fed to dead reckoning (wheel slip).
    Odometry,
    /// The yaw fed to dead reckoning.
    Heading,
    /// What no direction explains, and what stays below the threshold.
    Unexplained,
}

/// One cause of a segment's error growth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cause {
    /// Where it comes from.
    #[serde(flatten)]
    pub source: Source,
    /// Its share of the growth, 0–1.
    pub share: f64,
    /// The growth it explains, metres.
    pub growth_m: f64,
    /// Steps credited to it.
    pub steps: usize,
    /// For an anchor or a fault on a range probe: `range`; odometry `travel`; heading `yaw`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kind: Option<String>,
    /// Another cause whose direction was nearly the same in a step credited to this one (it
    /// cannot be told apart there), the most often such.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambiguous_with: Option<Source>,
}

/// A segment's explanation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentExplanation {
    /// The segment's index.
    pub segment_index: usize,
    /// `failed` or `passed`.
    pub verdict: String,
    /// The growth interval, seconds since the test began.
    pub from_s: f64,
    /// Its end: the first sample above the threshold (or the segment's largest error).
    pub to_s: f64,
    /// |e| at the start of the interval, metres.
    pub error_from_m: f64,
    /// |e| at its end.
    pub error_to_m: f64,
    /// The error was above the nominal level when the car entered the segment: it carried over
    /// from before, and the growth interval begins before the segment.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub carried_over: bool,
    /// The causes, most growth first; `unexplained` last.
    pub causes: Vec<Cause>,
}

impl SegmentExplanation {
    /// The first cause, if any is not `unexplained`.
    pub fn top(&self) -> Option<&Cause> {
        self.causes
            .first()
            .filter(|c| c.source != Source::Unexplained)
    }
}

impl From<Source> for SourceRecord {
    fn from(source: Source) -> Self {
        match source {
            Source::Fault { command_index } => SourceRecord::Fault { command_index },
            Source::Anchor { anchor_id } => SourceRecord::Anchor { anchor_id },
            Source::Odometry => SourceRecord::Odometry,
            Source::Heading => SourceRecord::Heading,
            Source::Unexplained => SourceRecord::Unexplained,
        }
    }
}

/// A case file's cause source, read back.
impl From<SourceRecord> for Source {
    fn from(source: SourceRecord) -> Self {
        match source {
            SourceRecord::Fault { command_index } => Source::Fault { command_index },
            SourceRecord::Anchor { anchor_id } => Source::Anchor { anchor_id },
            SourceRecord::Odometry => Source::Odometry,
            SourceRecord::Heading => Source::Heading,
            SourceRecord::Unexplained => Source::Unexplained,
        }
    }
}

impl From<&Cause> for CauseRecord {
    fn from(cause: &Cause) -> Self {
        Self {
            source: cause.source.into(),
            share: cause.share,
            growth_m: cause.growth_m,
            steps: cause.steps,
            kind: cause.kind.clone(),
            ambiguous_with: cause.ambiguous_with.map(Into::into),
        }
    }
}

/// The record a case file keeps (`explanation`).
impl From<&SegmentExplanation> for SegmentExplanationRecord {
    fn from(segment: &SegmentExplanation) -> Self {
        Self {
            segment_index: segment.segment_index,
            verdict: segment.verdict.clone(),
            from_s: segment.from_s,
            to_s: segment.to_s,
            error_from_m: segment.error_from_m,
            error_to_m: segment.error_to_m,
            carried_over: segment.carried_over,
            causes: segment.causes.iter().map(Into::into).collect(),
        }
    }
}

/// The directions a step's error change is compared with, and the sources behind them.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Direction {
    Anchor(u16),
    Travel,
    Yaw,
}

impl Direction {
    fn kind(self) -> &'static str {
        match self {
            Direction::Anchor(_) => "range",
            Direction::Travel => "travel",
            Direction::Yaw => "yaw",
        }
    }

    /// Whether `probe` moves the estimate in this direction.
    fn moved_by(self, probe: Probe) -> bool {
        match (self, probe) {
            (Direction::Anchor(id), Probe::UwbRange(p)) => id == p,
            (Direction::Travel, Probe::UwbTravelDist) => true,
            (Direction::Yaw, Probe::UwbYaw) => true,
            _ => false,
        }
    }
}

/// Explains `segment` from the test's `samples` (time order), its `anchors` and `faults`.
/// `None` without samples in the segment.
pub fn explain_segment(
    segment: &ExplainSegment,
    samples: &[ExplainSample],
    anchors: &[ExplainAnchor],
    faults: &[ExplainFault],
    config: &ExplainConfig,
) -> Option<SegmentExplanation> {
    let error = |s: &ExplainSample| (s.uwb - s.rtk).norm();
    let usable: Vec<&ExplainSample> = samples
        .iter()
        .filter(|s| s.rtk.is_finite() && s.uwb.is_finite())
        .collect();
    let inside: Vec<usize> = (0..usable.len())
        .filter(|&i| (segment.from_s..=segment.to_s).contains(&usable[i].t_s))
        .collect();
    inside.first()?;
    let last = *inside.last()?;
    // The end: the first sample above the threshold, else the segment's largest error.
    let end = inside
        .iter()
        .copied()
        .find(|&i| error(usable[i]) > config.threshold_m)
        .unwrap_or_else(|| {
            inside
                .iter()
                .copied()
                .max_by(|&a, &b| error(usable[a]).total_cmp(&error(usable[b])))
                .unwrap_or(last)
        });
    // The start: where the error last was nominal, however long before. A segment whose error
    // never came back from an earlier failure (the estimate lost and not recovered) fails for
    // what made it grow then.
    let mut start = end;
    while start > 0 && error(usable[start]) > config.nominal_m {
        start -= 1;
    }
    let mut credit: Vec<Credit> = Vec::new();
    let mut unexplained = 0.0;
    let mut unexplained_steps = 0;
    for j in start..end {
        let (a, b) = (usable[j], usable[j + 1]);
        let e0 = a.uwb - a.rtk;
        let e1 = b.uwb - b.rtk;
        let de = e1 - e0;
        let norm0 = e0.norm();
        if norm0 <= 1e-9 || de.norm() <= 1e-9 {
            continue;
        }
        let growth = de.dot(e0) / norm0;
        if growth <= 0.0 {
            continue;
        }
        let Some(heading) = heading_at(&usable, j) else {
            unexplained += growth;
            unexplained_steps += 1;
            continue;
        };
        let mid_t = (a.t_s + b.t_s) / 2.0;
        let mut directions: Vec<(Direction, Point)> = anchors
            .iter()
            .filter_map(|anchor| {
                let away = b.uwb - anchor.position;
                let length = away.norm();
                (length > 1e-6).then(|| (Direction::Anchor(anchor.id), away * (1.0 / length)))
            })
            .collect();
        directions.push((Direction::Travel, heading));
        directions.push((Direction::Yaw, Point::new(-heading.y, heading.x)));
        let length = de.norm();
        let mut ranked: Vec<(Direction, f64)> = directions
            .iter()
            .map(|&(d, u)| (d, (de.dot(u) / length).abs()))
            .collect();
        ranked.sort_by(|x, y| y.1.total_cmp(&x.1));
        let (mut best, mut best_alignment) = ranked[0];
        // An anchor's line and the heading (or its normal) that the step cannot tell apart by
        // direction: a range corrects the estimate in one jump at its anchor's ranging instant,
        // dead reckoning drifts it a little at every odometry tick. The step is the anchor's when
        // it holds more of the growth in its direction than the steps around it together, the
        // drift's otherwise.
        if let Some(&(other, cos)) = ranked.get(1)
            && cos >= config.ambiguity_cos
            && best_alignment - cos < AMBIGUITY_GAP
            && matches!(best, Direction::Anchor(_)) != matches!(other, Direction::Anchor(_))
            && is_jump(&usable, j, de) != matches!(best, Direction::Anchor(_))
        {
            (best, best_alignment) = (other, cos);
        }
        // Of the faults acting in this direction whose widened window covers the step, the
        // one whose estimated window is nearest (inside it: distance 0).
        let window_distance =
            |f: &ExplainFault| (f.acts_from_s - mid_t).max(mid_t - f.acts_to_s).max(0.0);
        let fault_of = |d: Direction| {
            faults
                .iter()
                .filter(|f| d.moved_by(f.probe))
                .map(|f| (f, window_distance(f)))
                .filter(|(_, distance)| *distance <= config.window_slack_s)
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(f, _)| f)
        };
        let source_of = |d: Direction| {
            fault_of(d).map_or(
                match d {
                    Direction::Anchor(id) => Source::Anchor { anchor_id: id },
                    Direction::Travel => Source::Odometry,
                    Direction::Yaw => Source::Heading,
                },
                |f| Source::Fault {
                    command_index: f.command_index,
                },
            )
        };
        // An acting fault the step is aligned with comes first: the best aligned; among equals
        // the nearest window.
        let acting = faults
            .iter()
            .filter(|f| window_distance(f) <= config.window_slack_s)
            .filter_map(|f| {
                let (direction, u) = fault_direction(f, &directions)?;
                let cos = (de.dot(u) / length).abs();
                (cos >= config.min_alignment).then_some((f, direction, cos))
            })
            .max_by(|a, b| {
                a.2.total_cmp(&b.2)
                    .then(window_distance(b.0).total_cmp(&window_distance(a.0)))
            });
        let (fault, direction, alignment) = match acting {
            Some((f, direction, cos)) => (Some(f), direction, cos),
            None if best_alignment >= config.min_alignment => {
                (fault_of(best), best, best_alignment)
            }
            None => {
                unexplained += growth;
                unexplained_steps += 1;
                continue;
            }
        };
        let source = fault.map_or_else(
            || source_of(direction),
            |f| Source::Fault {
                command_index: f.command_index,
            },
        );
        // The runner-up is as well aligned: this step cannot tell the two apart.
        let ambiguous = ranked
            .iter()
            .filter(|(d, _)| *d != direction)
            .find(|(_, cos)| *cos >= config.ambiguity_cos && alignment - cos < AMBIGUITY_GAP)
            .map(|&(d, _)| source_of(d))
            .filter(|s| *s != source);
        // Faults on the chosen fault's probe acting as surely (their windows as near) act
        // together: the step is theirs in proportion to how much each changes the probe's value
        // (see [`together_weights`]).
        let together: Vec<(Source, f64)> = match fault {
            Some(f) => together_weights(
                faults
                    .iter()
                    .filter(|g| g.probe == f.probe && window_distance(g) <= window_distance(f)),
            ),
            None => vec![(source, 1.0)],
        };
        for (source, weight) in together {
            let index = match credit.iter().position(|c| c.source == source) {
                Some(index) => index,
                None => {
                    credit.push(Credit {
                        source,
                        growth: 0.0,
                        steps: 0,
                        ambiguous: Vec::new(),
                        kind: direction.kind(),
                    });
                    credit.len() - 1
                }
            };
            let c = &mut credit[index];
            c.growth += growth * weight;
            c.steps += 1;
            if let Some(other) = ambiguous {
                match c.ambiguous.iter_mut().find(|a| a.0 == other) {
                    Some(a) => a.1 += 1,
                    None => c.ambiguous.push((other, 1)),
                }
            }
        }
    }
    let total: f64 = credit.iter().map(|c| c.growth).sum::<f64>() + unexplained;
    let mut causes: Vec<Cause> = Vec::new();
    for c in credit {
        if c.growth < config.min_growth_m {
            unexplained += c.growth;
            unexplained_steps += c.steps;
            continue;
        }
        // Named when at least half of the cause's steps could not tell it from that one.
        let ambiguous_with = c
            .ambiguous
            .iter()
            .max_by_key(|a| a.1)
            .filter(|a| 2 * a.1 >= c.steps)
            .map(|a| a.0);
        causes.push(Cause {
            source: c.source,
            share: share(c.growth, total),
            growth_m: c.growth,
            steps: c.steps,
            kind: Some(c.kind.to_owned()),
            ambiguous_with,
        });
    }
    causes.sort_by(|a, b| b.growth_m.total_cmp(&a.growth_m));
    if unexplained > 0.0 || causes.is_empty() {
        causes.push(Cause {
            source: Source::Unexplained,
            share: share(unexplained, total),
            growth_m: unexplained,
            steps: unexplained_steps,
            kind: None,
            ambiguous_with: None,
        });
    }
    Some(SegmentExplanation {
        segment_index: segment.segment_index,
        verdict: if segment.failed { "failed" } else { "passed" }.to_owned(),
        from_s: usable[start].t_s,
        to_s: usable[end].t_s,
        error_from_m: error(usable[start]),
        error_to_m: error(usable[end]),
        carried_over: inside.first().is_some_and(|&first| start < first),
        causes,
    })
}

/// The shares of a step among faults acting together on one probe: in proportion to how much
/// each changes the probe's value, where their kinds make that comparable without the value
/// itself (all offsets: |offset|; all amplifications: |factor − 1|, times the same value); in
/// equal parts otherwise (mixed kinds, set_to, bitflip).
fn together_weights<'a>(faults: impl Iterator<Item = &'a ExplainFault>) -> Vec<(Source, f64)> {
    let faults: Vec<&ExplainFault> = faults.collect();
    let size = |f: &ExplainFault| f.kind.size(f.param).unwrap_or(f64::NAN);
    let comparable = faults.windows(2).all(|w| w[0].kind == w[1].kind);
    let sizes: Vec<f64> = faults.iter().map(|f| size(f)).collect();
    let total: f64 = sizes.iter().sum();
    let weights: Vec<f64> = if comparable && total.is_finite() && total > 0.0 {
        sizes.iter().map(|s| s / total).collect()
    } else {
        vec![1.0 / faults.len().max(1) as f64; faults.len()]
    };
    faults
        .iter()
        .zip(weights)
        .map(|(f, w)| {
            (
                Source::Fault {
                    command_index: f.command_index,
                },
                w,
            )
        })
        .collect()
}

/// How much less aligned than the best a direction may be to be named as ambiguous with it.
const AMBIGUITY_GAP: f64 = 0.03;

/// What a source has been credited with so far.
struct Credit {
    source: Source,
    growth: f64,
    steps: usize,
    /// Other sources a step could not tell this one from, with how many steps.
    ambiguous: Vec<(Source, usize)>,
    kind: &'static str,
}

fn share(part: f64, total: f64) -> f64 {
    if total > 0.0 { part / total } else { 0.0 }
}

/// How many steps each side [`is_jump`] compares a step with: two, 100 ms at 20 samples a
/// second, less than an anchor's ranging period (100 ms per anchor in range, so 200 ms with
/// two): the steps around a range's correction hold no other correction from that anchor.
const JUMP_NEIGHBOURS: usize = 2;

/// Whether step `j` (from sample `j` to `j + 1`, its error change `de`) holds more growth along
/// `de` than the [`JUMP_NEIGHBOURS`] steps each side of it together: a jump (a range's
/// correction), not a drift (dead reckoning's, which grows the error at every step alike).
fn is_jump(samples: &[&ExplainSample], j: usize, de: Point) -> bool {
    let length = de.norm();
    if length <= 0.0 || samples.len() < 2 {
        return false;
    }
    let u = de * (1.0 / length);
    let along = |i: usize| {
        let (a, b) = (samples[i], samples[i + 1]);
        ((b.uwb - b.rtk) - (a.uwb - a.rtk)).dot(u).max(0.0)
    };
    let last = samples.len() - 2;
    let around: f64 = (j.saturating_sub(JUMP_NEIGHBOURS)..=(j + JUMP_NEIGHBOURS).min(last))
        .filter(|&i| i != j)
        .map(along)
        .sum();
    length > around
}

/// The direction `fault` moves the estimate in, among a step's `directions` (the anchors' lines,
/// the heading, across it): its probe's, a yaw offset's turned by −α/2 (see the module doc).
/// `None` for a range fault on an anchor the area does not have.
fn fault_direction(
    fault: &ExplainFault,
    directions: &[(Direction, Point)],
) -> Option<(Direction, Point)> {
    let &(direction, u) = directions.iter().find(|(d, _)| d.moved_by(fault.probe))?;
    if direction != Direction::Yaw
        || !fault.kind.spec().turns_heading_by_param
        || !fault.param.is_finite()
    {
        return Some((direction, u));
    }
    let (sin, cos) = (-fault.param.to_radians() / 2.0).sin_cos();
    Some((
        direction,
        Point::new(u.x * cos - u.y * sin, u.x * sin + u.y * cos),
    ))
}

/// The unit heading of the RTK track around sample `j`: from the sample before to the one after
/// (`None` while the car stands).
fn heading_at(samples: &[&ExplainSample], j: usize) -> Option<Point> {
    let before = samples[j.saturating_sub(1)].rtk;
    let after = samples[(j + 2).min(samples.len() - 1)].rtk;
    let moved = after - before;
    let length = moved.norm();
    (length > 0.02).then(|| moved * (1.0 / length))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A car driving east at 1 m/s, 20 samples a second, for `seconds`, with the UWB error that
    /// `error` gives at each time.
    fn drive(seconds: f64, error: impl Fn(f64) -> Point) -> Vec<ExplainSample> {
        (0..=(seconds * 20.0) as usize)
            .map(|k| {
                let t = k as f64 / 20.0;
                let rtk = Point::new(t, 0.0);
                ExplainSample {
                    t_s: t,
                    rtk,
                    uwb: rtk + error(t),
                }
            })
            .collect()
    }

    fn segment(to_s: f64) -> ExplainSegment {
        ExplainSegment {
            segment_index: 2,
            from_s: 0.0,
            to_s,
            failed: true,
        }
    }

    /// An anchor due north of the track, far away: its direction is across the heading (as the
    /// yaw's); one due east, ahead: along it (as the odometry's).
    fn anchors() -> Vec<ExplainAnchor> {
        vec![
            ExplainAnchor {
                id: 50,
                position: Point::new(3.0, -40.0),
            },
            ExplainAnchor {
                id: 234,
                position: Point::new(-30.0, 30.0),
            },
        ]
    }

    /// Command 3: a ×2.5 wheel slip acting from 2 s to 4 s.
    fn slip_2_to_4_s() -> ExplainFault {
        ExplainFault {
            command_index: 3,
            probe: Probe::UwbTravelDist,
            kind: FaultKind::Amplification,
            param: 2.5,
            acts_from_s: 2.0,
            acts_to_s: 4.0,
        }
    }

    #[test]
    fn an_error_growing_along_the_heading_in_a_slip_faults_window_names_the_fault() {
        // 0.3 m of standing error across, then from 2 s to 4 s 0.5 m/s of drift ahead.
        let samples = drive(6.0, |t| {
            Point::new(0.0, 0.3) + Point::new(0.5 * (t - 2.0).clamp(0.0, 2.0), 0.0)
        });
        let slip = slip_2_to_4_s();
        let explained = explain_segment(
            &segment(6.0),
            &samples,
            &anchors(),
            &[slip],
            &ExplainConfig::default(),
        )
        .unwrap();
        assert_eq!(
            explained.top().map(|c| c.source),
            Some(Source::Fault { command_index: 3 }),
            "{explained:?}"
        );
        assert!(!explained.carried_over);
        // Without the fault, the same growth is the odometry's.
        let unfaulted = explain_segment(
            &segment(6.0),
            &samples,
            &anchors(),
            &[],
            &ExplainConfig::default(),
        )
        .unwrap();
        assert_eq!(unfaulted.top().map(|c| c.source), Some(Source::Odometry));
        assert!(unfaulted.top().unwrap().share > 0.9, "{unfaulted:?}");
    }

    #[test]
    fn a_segment_that_never_recovered_from_an_earlier_failure_is_explained_by_its_cause() {
        // A slip from 2 s to 4 s pushes the error ahead past 1 m; it never comes back, and creeps
        // across at 2 cm/s after. The segment from 15 s fails from its first sample: for the slip,
        // 11 s before, not for the creep.
        let samples = drive(20.0, |t| {
            Point::new(
                0.5 * (t - 2.0).clamp(0.0, 2.0),
                0.3 + 0.02 * (t - 4.0).max(0.0),
            )
        });
        let slip = slip_2_to_4_s();
        let late = ExplainSegment {
            segment_index: 6,
            from_s: 15.0,
            to_s: 20.0,
            failed: true,
        };
        let explained = explain_segment(
            &late,
            &samples,
            &anchors(),
            &[slip],
            &ExplainConfig::default(),
        )
        .unwrap();
        assert!(explained.from_s < 4.0, "{explained:?}");
        assert!(explained.carried_over);
        assert_eq!(
            explained.top().map(|c| c.source),
            Some(Source::Fault { command_index: 3 }),
            "{explained:?}"
        );
    }

    #[test]
    fn a_yaw_offset_turns_the_direction_its_fault_is_recognised_in() {
        // A yaw offset of 80° (clockwise, as the firmware's yaw) turns the dead-reckoned track
        // 80° to the right of the true one, east at 1 m/s: e grows along (cos 80° − 1, −sin 80°),
        // the line at 50°, which no anchor, the heading nor the normal to it (90°) is within
        // |cos| 0.8 of.
        let alpha = 80f64.to_radians();
        let drift = Point::new(alpha.cos() - 1.0, -alpha.sin());
        let unit = drift * (1.0 / drift.norm());
        let samples = drive(6.0, |t| unit * 0.3 + drift * (t - 2.0).clamp(0.0, 2.0));
        let yaw = |param: f64| ExplainFault {
            command_index: 4,
            probe: Probe::UwbYaw,
            kind: FaultKind::Offset,
            param,
            acts_from_s: 2.0,
            acts_to_s: 4.0,
        };
        let explain = |faults: &[ExplainFault]| {
            explain_segment(
                &segment(6.0),
                &samples,
                &anchors(),
                faults,
                &ExplainConfig::default(),
            )
            .unwrap()
        };
        let explained = explain(&[yaw(80.0)]);
        assert_eq!(
            explained.top().map(|c| c.source),
            Some(Source::Fault { command_index: 4 }),
            "{explained:?}"
        );
        assert!(explained.top().unwrap().share > 0.9, "{explained:?}");
        // The same offset the other way turns the other way: it did not do this.
        let first = |e: SegmentExplanation| e.causes.first().map(|c| c.source);
        assert_eq!(first(explain(&[yaw(-80.0)])), Some(Source::Unexplained));
        assert_eq!(first(explain(&[])), Some(Source::Unexplained));
    }

    #[test]
    fn an_acting_fault_aligned_with_the_step_comes_before_a_better_aligned_anchor() {
        // The error grows along the line 20° off the heading (|cos| 0.94 with it); anchor 50's
        // line is 15° off the heading, so the step is better aligned with the anchor (0.996).
        let line = 20f64.to_radians();
        let drift = Point::new(line.cos(), line.sin()) * 0.5;
        let samples = drive(6.0, |t| drift * 0.6 + drift * (t - 2.0).clamp(0.0, 2.0));
        let anchors = [ExplainAnchor {
            id: 50,
            // Seen from the track's middle, along the line at 15°: better aligned than the
            // heading.
            position: Point::new(
                3.0 + 100.0 * 15f64.to_radians().cos(),
                100.0 * 15f64.to_radians().sin(),
            ),
        }];
        let slip = ExplainFault {
            command_index: 2,
            probe: Probe::UwbTravelDist,
            kind: FaultKind::Amplification,
            param: 2.0,
            acts_from_s: 2.0,
            acts_to_s: 4.0,
        };
        let config = ExplainConfig::default();
        let with = explain_segment(&segment(6.0), &samples, &anchors, &[slip], &config).unwrap();
        assert_eq!(
            with.top().map(|c| c.source),
            Some(Source::Fault { command_index: 2 }),
            "{with:?}"
        );
        let without = explain_segment(&segment(6.0), &samples, &anchors, &[], &config).unwrap();
        assert_eq!(
            without.top().map(|c| c.source),
            Some(Source::Anchor { anchor_id: 50 }),
            "{without:?}"
        );
    }

    #[test]
    fn faults_on_one_probe_acting_together_share_the_growth() {
        // Drift ahead at 0.2 m/s from 2 s to 5 s (the error passes the nominal level at 2.95 s).
        let samples = drive(6.0, |t| {
            Point::new(0.3 + 0.2 * (t - 2.0).clamp(0.0, 3.0), 0.0)
        });
        let slip = |command_index, param, acts_to_s| ExplainFault {
            command_index,
            probe: Probe::UwbTravelDist,
            kind: FaultKind::Amplification,
            param,
            acts_from_s: 2.0,
            acts_to_s,
        };
        let config = ExplainConfig {
            window_slack_s: 0.0,
            ..ExplainConfig::default()
        };
        let explain = |faults: &[ExplainFault]| {
            let explained = explain_segment(&segment(6.0), &samples, &[], faults, &config).unwrap();
            let shares: Vec<(Source, f64)> = explained
                .causes
                .iter()
                .map(|c| (c.source, c.share))
                .collect();
            shares
        };
        let fault = |command_index| Source::Fault { command_index };
        // Alike, one over 2–4 s and one over 2–5 s: together for about 1 s, then the second
        // alone for 1 s, so it acted over more of the growth.
        let shares = explain(&[slip(3, 2.0, 4.0), slip(5, 2.0, 5.0)]);
        assert_eq!(shares[0].0, fault(5), "{shares:?}");
        assert!((shares[0].1 - 0.75).abs() < 0.05, "{shares:?}");
        // Over the same window, by how much each changes the travelled distance: ×1.5 adds a
        // half, ×3 twice as much again (a fifth and four fifths).
        let shares = explain(&[slip(3, 1.5, 5.0), slip(5, 3.0, 5.0)]);
        assert_eq!(shares[0].0, fault(5), "{shares:?}");
        assert!((shares[0].1 - 0.8).abs() < 0.02, "{shares:?}");
        assert!((shares[1].1 - 0.2).abs() < 0.02, "{shares:?}");
        // Kinds that cannot be compared without the value itself share equally.
        let mut set_to = slip(5, 0.4, 5.0);
        set_to.kind = FaultKind::SetTo;
        let shares = explain(&[slip(3, 3.0, 5.0), set_to]);
        assert!((shares[0].1 - 0.5).abs() < 0.02, "{shares:?}");
        assert!((shares[1].1 - 0.5).abs() < 0.02, "{shares:?}");
    }

    #[test]
    fn yaw_faults_acting_together_share_a_step_across_the_heading_by_their_offsets() {
        // The error grows straight across the heading (north while driving east): the plain
        // heading direction, which neither offset's turned direction (−40° and +50°) is within
        // |cos| 0.8 of. Both faults act over the whole growth; the step is theirs by offset,
        // not the first listed's alone.
        let samples = drive(6.0, |t| {
            Point::new(0.0, 0.3 + 0.3 * (t - 2.0).clamp(0.0, 3.0))
        });
        let yaw = |command_index, param| ExplainFault {
            command_index,
            probe: Probe::UwbYaw,
            kind: FaultKind::Offset,
            param,
            acts_from_s: 2.0,
            acts_to_s: 5.0,
        };
        let explained = explain_segment(
            &segment(6.0),
            &samples,
            &[],
            &[yaw(1, 80.0), yaw(2, -100.0)],
            &ExplainConfig::default(),
        )
        .unwrap();
        let shares: Vec<(Source, f64)> = explained
            .causes
            .iter()
            .map(|c| (c.source, c.share))
            .collect();
        assert_eq!(
            shares[0].0,
            Source::Fault { command_index: 2 },
            "{shares:?}"
        );
        assert!((shares[0].1 - 100.0 / 180.0).abs() < 0.02, "{shares:?}");
        assert!((shares[1].1 - 80.0 / 180.0).abs() < 0.02, "{shares:?}");
    }

    #[test]
    fn an_anchor_on_the_heading_line_is_told_from_odometry_by_jumps() {
        // Anchor 7 far behind the track, on its line: its range moves the estimate along the
        // heading, as odometry does.
        let behind = [ExplainAnchor {
            id: 7,
            position: Point::new(-100.0, 0.0),
        }];
        let explain = |samples: &[ExplainSample]| {
            let explained = explain_segment(
                &segment(4.0),
                samples,
                &behind,
                &[],
                &ExplainConfig::default(),
            )
            .unwrap();
            explained.top().map(|c| c.source)
        };
        // A too-long range corrected once per ranging period (0.2 s): 0.1 m jumps.
        let jumps = drive(4.0, |t| {
            Point::new(0.2 + 0.1 * (t / 0.2).floor().min(12.0), 0.0)
        });
        assert_eq!(explain(&jumps), Some(Source::Anchor { anchor_id: 7 }));
        // The odometry over-reading: the same growth at every step.
        let drift = drive(4.0, |t| Point::new(0.2 + 0.5 * t.min(2.4), 0.0));
        assert_eq!(explain(&drift), Some(Source::Odometry));
    }

    #[test]
    fn corrections_pushing_the_estimate_away_from_an_anchor_name_that_anchors_range() {
        // Steps of 0.1 m every 0.2 s away from anchor 234 (north-west of the track): a reflected,
        // too long range corrected a little at a time.
        let samples = drive(4.0, |t| {
            let steps = (t / 0.2).floor().min(12.0);
            let away = Point::new(1.0, -1.0) * (1.0 / 2f64.sqrt());
            Point::new(0.2, 0.0) + away * (0.1 * steps)
        });
        let explained = explain_segment(
            &segment(4.0),
            &samples,
            &anchors(),
            &[],
            &ExplainConfig::default(),
        )
        .unwrap();
        let top = explained.top().unwrap();
        assert_eq!(
            top.source,
            Source::Anchor { anchor_id: 234 },
            "{explained:?}"
        );
        assert_eq!(top.kind.as_deref(), Some("range"));
        assert!(explained.error_to_m > 1.0);
    }

    #[test]
    fn noise_below_the_threshold_is_unexplained() {
        // A wobble of a few centimetres: no cause reaches the least growth.
        let samples = drive(4.0, |t| Point::new(0.3 + 0.03 * (t * 7.0).sin(), 0.2));
        let explained = explain_segment(
            &ExplainSegment {
                failed: false,
                ..segment(4.0)
            },
            &samples,
            &anchors(),
            &[],
            &ExplainConfig::default(),
        )
        .unwrap();
        assert_eq!(explained.top(), None, "{explained:?}");
        assert_eq!(explained.verdict, "passed");
    }
}
