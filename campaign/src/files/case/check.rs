//! The checks of a case's values and geometry: what replay relies on before a car is sent a
//! recorded command.

use car_link::firmware::MAX_RANGED_ANCHOR_ID;
use scenarios::Scenario;
use trajgen::{Point, check_route};

use super::{Case, CommandRecord, PlaceRecord, RoutePointRecord};
use crate::files::{CaseError, invalid};
use crate::model::{Probe, start_tail};

impl Case {
    /// Checks the values: finite coordinates, speeds within drivecheck's floor and the
    /// autopilot's top speed, non-empty segments whose intent agrees with their points, fault
    /// parameters within what a scenario's ranges may hold ([`scenarios::check_fault_param`]),
    /// fault start and duration within [`scenarios::limits::MAX_FAULT_ITERATIONS`], result
    /// indices in range, one result per segment in order, statistics that deviations can give
    /// (finite, non-negative, within what two positions on the wire can be apart, RMS and 95th
    /// percentile not above the largest), and verdicts that agree with them.
    pub fn check(&self) -> Result<(), CaseError> {
        let mut segments = 0;
        for (i, command) in self.commands.iter().enumerate() {
            check_command(i, command)?;
            match command {
                CommandRecord::RunSegments { .. } => segments += 1,
                CommandRecord::AddFault { at: Some(at), .. } => check_place(i, at, segments)?,
                CommandRecord::AddFault { at: None, .. } => {}
            }
        }
        check_route_points("return_route", &self.return_route)?;
        if let Some(clearance) = self.return_clearance_m
            && !(clearance.is_finite() && clearance >= 0.0)
        {
            return Err(invalid(
                "return_clearance_m",
                "must be finite and non-negative",
            ));
        }
        self.check_results()
    }

    fn check_results(&self) -> Result<(), CaseError> {
        let threshold = self.settings.as_ref().map(|s| s.oracle_threshold_m);
        let mut previous: Option<usize> = None;
        for (i, result) in self.segments.iter().enumerate() {
            // One result per segment, in the order they were driven: a result repeated would
            // count its segment many times.
            if previous.is_some_and(|p| result.command_index <= p) {
                return Err(invalid(
                    format!("segments[{i}].command_index"),
                    format!(
                        "{}, after a result of command {}: each segment has one result, in order",
                        result.command_index,
                        previous.unwrap_or_default()
                    ),
                ));
            }
            previous = Some(result.command_index);
            if let Some(stats) = &result.oracle.stats {
                check_stats(i, stats)?;
            }
            // Each segment's verdict is the oracle's on its own statistics and threshold, and
            // the threshold is the campaign's: an edited verdict or threshold is refused.
            let outcome = &result.oracle;
            if threshold.is_some_and(|t| t.to_bits() != outcome.threshold_m.to_bits()) {
                return Err(invalid(
                    format!("segments[{i}].oracle.threshold_m"),
                    format!(
                        "{} m, but the case's settings judge against {} m",
                        outcome.threshold_m,
                        threshold.unwrap_or_default()
                    ),
                ));
            }
            let judged = crate::oracle::judge(
                outcome.stats.as_ref(),
                outcome.invalid_uwb_samples,
                outcome.threshold_m,
            );
            if judged != outcome.verdict {
                return Err(invalid(
                    format!("segments[{i}].oracle.verdict"),
                    format!(
                        "`{}`, but its statistics (largest deviation {}, {} sample(s) without \
                         UWB) against {} m say `{}`",
                        verdict_name(outcome.verdict),
                        outcome
                            .stats
                            .as_ref()
                            .map_or_else(|| "none".to_owned(), |s| format!("{} m", s.max_m)),
                        outcome.invalid_uwb_samples,
                        outcome.threshold_m,
                        verdict_name(judged)
                    ),
                ));
            }
        }
        // A recorded verdict must agree with the case's own segment results: replay compares
        // with it, and a `passed` written over a failed segment would read as a pass.
        let failed = self
            .segments
            .iter()
            .any(|s| s.oracle.verdict == crate::oracle::SegmentVerdict::Failed);
        let all_passed = self
            .segments
            .iter()
            .all(|s| s.oracle.verdict == crate::oracle::SegmentVerdict::Passed);
        match self.verdict {
            Some(crate::oracle::Verdict::Passed) if !all_passed || self.segments.is_empty() => {
                return Err(invalid(
                    "verdict",
                    "`passed`, but not every segment in `segments` passed",
                ));
            }
            Some(crate::oracle::Verdict::Failed) if !failed => {
                return Err(invalid(
                    "verdict",
                    "`failed`, but no segment in `segments` failed",
                ));
            }
            _ => {}
        }
        for (i, result) in self.segments.iter().enumerate() {
            let is_segment = matches!(
                self.commands.get(result.command_index),
                Some(CommandRecord::RunSegments { .. })
            );
            if !is_segment {
                return Err(invalid(
                    format!("segments[{i}].command_index"),
                    "does not name a run_segments command",
                ));
            }
        }
        Ok(())
    }

    /// Checks that every segment (with its margin, when recorded) continues the route drivably
    /// from the end of `scenario`'s start route.
    pub fn check_route(&self, scenario: &Scenario) -> Result<(), CaseError> {
        let mut tail = start_tail(scenario)?;
        let constraints = scenario.constraints();
        for (command, record) in self.commands.iter().enumerate() {
            let CommandRecord::RunSegments { points, margin, .. } = record else {
                continue;
            };
            let driven: Vec<Point> = points.iter().map(RoutePointRecord::position).collect();
            let route: Vec<Point> = std::iter::once(tail.end)
                .chain(driven.iter().copied())
                .chain(margin.iter().map(|&p| Point::from(p)))
                .collect();
            check_route(&scenario.area, &route, &constraints, Some(tail.heading))
                .map_err(|violation| CaseError::NotDrivable { command, violation })?;
            tail = tail.advanced(&driven);
        }
        Ok(())
    }
}

fn check_command(i: usize, command: &CommandRecord) -> Result<(), CaseError> {
    let path = format!("commands[{i}]");
    match command {
        CommandRecord::AddFault {
            probe,
            kind,
            param,
            start,
            duration,
            ..
        } => {
            match probe {
                Probe::Px => {
                    return Err(invalid(
                        format!("{path}.probe"),
                        "px alters the position the car reports, which the safety monitor relies \
                         on: drivecheck injects faults into UWB probes only",
                    ));
                }
                Probe::UwbRange(id) if *id > MAX_RANGED_ANCHOR_ID => {
                    return Err(invalid(
                        format!("{path}.probe"),
                        format!(
                            "anchor {id} is never ranged: the firmware sends an anchor id's low byte, \
                             so ids above {MAX_RANGED_ANCHOR_ID} never answer"
                        ),
                    ));
                }
                _ => {}
            }
            if !param.is_finite() {
                return Err(invalid(format!("{path}.param"), "must be finite"));
            }
            // What a scenario's fault range may hold is what a case may send (a yaw of 1e308
            // would reach the car as an infinite binary32).
            scenarios::check_fault_param(*kind, probe.quantity(), *param).map_err(|problem| {
                invalid(
                    format!("{path}.param"),
                    format!("{problem} ({} on {probe})", kind.name()),
                )
            })?;
            for (name, value) in [("start", *start), ("duration", *duration)] {
                let most = scenarios::limits::MAX_FAULT_ITERATIONS;
                if value > most {
                    return Err(invalid(
                        format!("{path}.{name}"),
                        format!("{value} probe iterations is beyond drivecheck's limit of {most}"),
                    ));
                }
            }
            if *duration == 0 {
                return Err(invalid(
                    format!("{path}.duration"),
                    "0 would make the fault permanent",
                ));
            }
            Ok(())
        }
        CommandRecord::RunSegments {
            intent,
            points,
            margin,
        } => {
            if points.is_empty() {
                return Err(invalid(format!("{path}.points"), "a segment needs points"));
            }
            check_route_points(&format!("{path}.points"), points)?;
            if let Some(intent) = intent
                && intent.points != points.len()
            {
                return Err(invalid(
                    format!("{path}.intent.points"),
                    "differs from the number of points",
                ));
            }
            match margin.iter().position(|p| !Point::from(*p).is_finite()) {
                Some(j) => Err(invalid(format!("{path}.margin[{j}]"), "not finite")),
                None => Ok(()),
            }
        }
    }
}

/// A fault's place lies on a segment driven before the fault command (`segments` of them), at a
/// finite, non-negative distance along it (how far it may be is checked against the segment's
/// length when the case is planned for driving).
fn check_place(i: usize, at: &PlaceRecord, segments: usize) -> Result<(), CaseError> {
    let path = format!("commands[{i}].at");
    if at.segment_index >= segments {
        return Err(invalid(
            format!("{path}.segment_index"),
            format!(
                "segment {} is not driven before this fault (only {segments} segment(s) precede it)",
                at.segment_index
            ),
        ));
    }
    if !(at.along_m.is_finite() && at.along_m >= 0.0) {
        return Err(invalid(
            format!("{path}.along_m"),
            "must be finite and non-negative",
        ));
    }
    Ok(())
}

fn check_route_points(path: &str, points: &[RoutePointRecord]) -> Result<(), CaseError> {
    for (j, p) in points.iter().enumerate() {
        if !p.position().is_finite() {
            return Err(invalid(
                format!("{path}[{j}]"),
                "coordinates must be finite",
            ));
        }
        if !(p.speed.is_finite() && p.speed > 0.0) {
            return Err(invalid(
                format!("{path}[{j}].speed"),
                "must be positive and finite",
            ));
        }
        let floor = scenarios::limits::MIN_SPEED_KMH / 3.6;
        if p.speed < floor - 1e-9 {
            return Err(invalid(
                format!("{path}[{j}].speed"),
                format!(
                    "{} m/s is below drivecheck's limit of {floor:.3} m/s ({} km/h): slower, one \
                     segment takes minutes",
                    p.speed,
                    scenarios::limits::MIN_SPEED_KMH
                ),
            ));
        }
        let top = scenarios::limits::MAX_ROUTE_SPEED;
        if p.speed > top {
            return Err(invalid(
                format!("{path}[{j}].speed"),
                format!(
                    "{} m/s is beyond the firmware autopilot's top speed of {top:.3} m/s ({} km/h)",
                    readable(p.speed),
                    scenarios::MAX_SPEED_KMH
                ),
            ));
        }
    }
    Ok(())
}

/// A number as a person reads it: plain, or in exponent form when very large (`1e30`).
fn readable(x: f64) -> String {
    if x.abs() >= 1e9 {
        format!("{x:e}")
    } else {
        x.to_string()
    }
}

/// A segment verdict as case files write it.
/// The largest deviation two positions on the wire can have: each coordinate is an `f32`, so no
/// two are more than `2 × f32::MAX` apart on an axis (about 9.6e38 m in the plane).
const MAX_WIRE_DEVIATION_M: f64 = 2.0 * std::f64::consts::SQRT_2 * f32::MAX as f64;

/// A segment's statistics are what some deviations can give: finite, non-negative, within what
/// two positions on the wire can be apart, the RMS and the 95th percentile not above the
/// largest, and at least one sample.
fn check_stats(i: usize, stats: &crate::oracle::DeviationStats) -> Result<(), CaseError> {
    for (field, value) in [
        ("max_m", stats.max_m),
        ("rms_m", stats.rms_m),
        ("p95_m", stats.p95_m),
    ] {
        if !(value.is_finite() && (0.0..=MAX_WIRE_DEVIATION_M).contains(&value)) {
            return Err(invalid(
                format!("segments[{i}].oracle.stats.{field}"),
                format!(
                    "{value} m: a deviation is at least 0 and at most {MAX_WIRE_DEVIATION_M:e} m \
                     (two positions on the wire)"
                ),
            ));
        }
    }
    for (field, value) in [("rms_m", stats.rms_m), ("p95_m", stats.p95_m)] {
        // The RMS of values is at most their largest, up to rounding.
        if value > stats.max_m * (1.0 + 1e-12) {
            return Err(invalid(
                format!("segments[{i}].oracle.stats.{field}"),
                format!("{value} m, above the largest deviation {} m", stats.max_m),
            ));
        }
    }
    if stats.samples == 0 {
        return Err(invalid(
            format!("segments[{i}].oracle.stats.samples"),
            "0: statistics come from at least one sample",
        ));
    }
    Ok(())
}

fn verdict_name(verdict: crate::oracle::SegmentVerdict) -> &'static str {
    match verdict {
        crate::oracle::SegmentVerdict::Passed => "passed",
        crate::oracle::SegmentVerdict::Failed => "failed",
        crate::oracle::SegmentVerdict::NoSamples => "no_samples",
    }
}
