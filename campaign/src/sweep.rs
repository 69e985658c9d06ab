//! Sweeps (`drivecheck sweep`): a case driven for every value of one or more parameters — a
//! fault's values, or a setting of the simulated car — and the per-segment outcome of each.
//!
//! Pure: the parameters and their values (`--set NAME=V1,V2,…`), the grid, a case with fault
//! values set, and the result (`sweep.json`, the table). The command drives the runs.

use std::fmt;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::files::{Case, CaseError, CommandRecord, ScenarioRef};
use crate::oracle::{SegmentVerdict, Verdict};
use crate::shrink::{FaultField, RunResult};
use scenarios::limits::{MAX_FAULT_FACTOR, MAX_FAULT_ITERATIONS, MAX_FAULT_OFFSET};

pub use crate::files::SWEEP_FORMAT;

/// A `--set` that cannot be used.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("--set {arg}: {problem}")]
pub struct SweepError {
    /// The argument as given.
    pub arg: String,
    /// What is wrong with it.
    pub problem: SetProblem,
}

/// What is wrong with a `--set NAME=V1,V2,…`.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SetProblem {
    /// No `=`.
    #[error("expected NAME=V1,V2,…")]
    NoValues,
    /// A name that is neither a fault's value nor a simulator setting.
    #[error(
        "expected fault[i].param, fault[i].start, fault[i].duration or one of {}",
        SimSetting::ALL.map(|(_, n)| n).join(", ")
    )]
    UnknownName,
    /// `fault[i]` with an `i` that is not a number.
    #[error("`{0}` is not a fault index")]
    FaultIndex(String),
    /// `fault[i]` beyond the case's fault commands.
    #[error("the case has {faults} fault command(s): fault[0] to fault[{}]", .faults.saturating_sub(1))]
    NoSuchFault {
        /// The case's fault commands.
        faults: usize,
    },
    /// A value that is not a finite number.
    #[error("`{0}` is not a finite number")]
    NotANumber(String),
    /// More values than [`MAX_AXIS_VALUES`].
    #[error("{0} values: at most {MAX_AXIS_VALUES} per parameter")]
    TooManyValues(usize),
    /// A value out of the parameter's range.
    #[error("{value:?} is not a value for {parameter} ({})", expected(*.parameter))]
    OutOfRange {
        /// The parameter.
        parameter: Parameter,
        /// The value.
        value: f64,
    },
}

/// A setting of the simulated car a sweep can vary (none of them is a setting of the reference
/// firmware's protocol: simulation only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SimSetting {
    /// `sim.uwb_clamp_m`: the UWB estimator's largest correction per range (the firmware's
    /// compile-time 0.2 m).
    UwbClampM,
    /// `sim.anchor_error_m`: how far every anchor really stands from its surveyed position (the
    /// one the car is given), m, each in a direction of its own.
    AnchorErrorM,
    /// `sim.range_sigma_m`: the standard deviation of one UWB two-way exchange, m.
    RangeSigmaM,
}

impl SimSetting {
    const ALL: [(Self, &'static str); 3] = [
        (Self::UwbClampM, "sim.uwb_clamp_m"),
        (Self::AnchorErrorM, "sim.anchor_error_m"),
        (Self::RangeSigmaM, "sim.range_sigma_m"),
    ];

    fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(s, _)| *s == self)
            .map_or("sim.?", |(_, name)| name)
    }
}

/// What a `--set` varies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Parameter {
    /// `fault[i].param|start|duration`: a value of the case's i-th fault command (from 0, in
    /// command order).
    Fault {
        /// The fault's position among the case's fault commands.
        index: usize,
        /// Which value.
        field: FaultField,
    },
    /// `sim.…`: a setting of the simulated car.
    Sim {
        /// Which.
        setting: SimSetting,
    },
}

impl fmt::Display for Parameter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Fault { index, field } => {
                let field = match field {
                    FaultField::Param => "param",
                    FaultField::Start => "start",
                    FaultField::Duration => "duration",
                };
                write!(f, "fault[{index}].{field}")
            }
            Self::Sim { setting } => f.write_str(setting.name()),
        }
    }
}

/// The most values one `--set` may give.
pub const MAX_AXIS_VALUES: usize = 1_000;
/// The most points a sweep's grid may have (each is driven `--runs` times).
pub const MAX_GRID_POINTS: usize = 10_000;

/// The number of points of the grid of `axes`, or an error naming the limit when it is above
/// [`MAX_GRID_POINTS`] (checked before any point is made).
pub fn grid_size(axes: &[Axis]) -> Result<usize, GridTooLarge> {
    let mut points: usize = 1;
    for axis in axes {
        points = points
            .checked_mul(axis.values.len())
            .filter(|&p| p <= MAX_GRID_POINTS)
            .ok_or_else(|| GridTooLarge {
                sizes: axes.iter().map(|a| a.values.len()).collect(),
            })?;
    }
    Ok(points)
}

/// A grid above [`MAX_GRID_POINTS`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "the grid of {} value(s) has more than {MAX_GRID_POINTS} points (the limit): sweep fewer values",
    .sizes.iter().map(ToString::to_string).collect::<Vec<_>>().join(" × ")
)]
pub struct GridTooLarge {
    /// The values of each `--set`.
    pub sizes: Vec<usize>,
}

/// One `--set NAME=V1,V2,…`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Axis {
    /// The parameter.
    pub parameter: Parameter,
    /// Its values, in the order given.
    pub values: Vec<f64>,
}

impl Axis {
    /// Parses `NAME=V1,V2,…` for `case` (a fault parameter must name one of its faults).
    pub fn parse(arg: &str, case: &Case) -> Result<Self, SweepError> {
        let error = |problem: SetProblem| SweepError {
            arg: arg.to_owned(),
            problem,
        };
        let (name, values) = arg
            .split_once('=')
            .ok_or_else(|| error(SetProblem::NoValues))?;
        let parameter = parse_name(name.trim(), case).map_err(error)?;
        let values = values
            .split(',')
            .map(|v| {
                let v = v.trim();
                v.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| error(SetProblem::NotANumber(v.to_owned())))
            })
            .collect::<Result<Vec<f64>, _>>()?;
        if values.len() > MAX_AXIS_VALUES {
            return Err(error(SetProblem::TooManyValues(values.len())));
        }
        for &v in &values {
            check_value(parameter, v).map_err(error)?;
        }
        Ok(Self { parameter, values })
    }
}

fn parse_name(name: &str, case: &Case) -> Result<Parameter, SetProblem> {
    if let Some(&(setting, _)) = SimSetting::ALL.iter().find(|(_, n)| *n == name) {
        return Ok(Parameter::Sim { setting });
    }
    let rest = name.strip_prefix("fault[").ok_or(SetProblem::UnknownName)?;
    let (index, field) = rest.split_once("].").ok_or(SetProblem::UnknownName)?;
    let index: usize = index
        .parse()
        .map_err(|_| SetProblem::FaultIndex(index.to_owned()))?;
    let field = match field {
        "param" => FaultField::Param,
        "start" => FaultField::Start,
        "duration" => FaultField::Duration,
        _ => return Err(SetProblem::UnknownName),
    };
    let faults = fault_commands(case).len();
    if index >= faults {
        return Err(SetProblem::NoSuchFault { faults });
    }
    Ok(Parameter::Fault { index, field })
}

fn check_value(parameter: Parameter, v: f64) -> Result<(), SetProblem> {
    let ok = match parameter {
        Parameter::Fault {
            field: FaultField::Param,
            ..
        } => v.abs() <= MAX_FAULT_OFFSET.max(MAX_FAULT_FACTOR),
        Parameter::Fault {
            field: FaultField::Start,
            ..
        } => v >= 0.0 && v.fract() == 0.0 && v <= f64::from(MAX_FAULT_ITERATIONS),
        Parameter::Fault {
            field: FaultField::Duration,
            ..
        } => v >= 1.0 && v.fract() == 0.0 && v <= f64::from(MAX_FAULT_ITERATIONS),
        Parameter::Sim {
            setting: SimSetting::UwbClampM,
        } => v > 0.0 && v <= 10.0,
        Parameter::Sim { .. } => (0.0..=10.0).contains(&v),
    };
    if ok {
        Ok(())
    } else {
        Err(SetProblem::OutOfRange {
            parameter,
            value: v,
        })
    }
}

/// The values `parameter` takes, in words.
fn expected(parameter: Parameter) -> &'static str {
    match parameter {
        Parameter::Fault {
            field: FaultField::Param,
            ..
        } => "a fault parameter, at most 1000 either sign (drivecheck's limit)",
        Parameter::Fault {
            field: FaultField::Start,
            ..
        } => "a whole number of probe calls, 0 to 1000000",
        Parameter::Fault { .. } => "a whole number of probe calls, 1 to 1000000",
        Parameter::Sim {
            setting: SimSetting::UwbClampM,
        } => "metres, above 0 and at most 10",
        Parameter::Sim { .. } => "metres, 0 to 10",
    }
}

/// The command indices of `case`'s fault commands, in order.
pub fn fault_commands(case: &Case) -> Vec<usize> {
    case.commands
        .iter()
        .enumerate()
        .filter(|(_, c)| matches!(c, CommandRecord::AddFault { .. }))
        .map(|(i, _)| i)
        .collect()
}

/// Every combination of the axes' values (the first axis varies slowest).
pub fn grid(axes: &[Axis]) -> Vec<Vec<f64>> {
    axes.iter().fold(vec![Vec::new()], |points, axis| {
        points
            .iter()
            .flat_map(|point| {
                axis.values.iter().map(move |&v| {
                    let mut next = point.clone();
                    next.push(v);
                    next
                })
            })
            .collect()
    })
}

/// `case` with the fault values of `point` set (the simulator's settings are the caller's).
pub fn with_fault_values(case: &Case, axes: &[Axis], point: &[f64]) -> Case {
    let faults = fault_commands(case);
    let mut out = case.clone();
    for (axis, &value) in axes.iter().zip(point) {
        let Parameter::Fault { index, field } = axis.parameter else {
            continue;
        };
        if let Some(command) = faults.get(index).and_then(|&i| out.commands.get_mut(i)) {
            field.set(command, value);
        }
    }
    out
}

/// `case` without the effect of fault command `command_index`: it becomes a `NONE` fault, sent at
/// the same place and taking the same slot, so the other faults act as they did (a
/// counterfactual: what the test does without that fault). `case` itself when that command is
/// not a fault.
pub fn with_fault_silenced(case: &Case, command_index: usize) -> Case {
    let mut out = case.clone();
    if let Some(CommandRecord::AddFault { kind, .. }) = out.commands.get_mut(command_index) {
        *kind = car_link::FaultKind::None;
    }
    out
}

/// One segment over a point's runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentSweep {
    /// The segment.
    pub segment_index: usize,
    /// Each run's largest deviation in it, metres (`null` when that run did not judge it).
    pub max_m: Vec<Option<f64>>,
    /// Their median, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_max_m: Option<f64>,
    /// Runs in which it failed.
    pub failed_runs: usize,
}

/// One point of the grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Point {
    /// The value of each axis, in the axes' order.
    pub values: Vec<f64>,
    /// Each run.
    pub runs: Vec<RunResult>,
    /// Each segment.
    pub segments: Vec<SegmentSweep>,
}

impl Point {
    /// The point `values` from the cases its runs wrote (with their seeds).
    pub fn new(values: Vec<f64>, driven: &[(u64, Case)]) -> Self {
        let runs = driven.iter().map(|(s, c)| RunResult::of(*s, c)).collect();
        let segments_seen = driven
            .iter()
            .flat_map(|(_, c)| c.segments.iter().map(|s| s.segment_index + 1))
            .max()
            .unwrap_or(0);
        let segments = (0..segments_seen)
            .map(|k| {
                let results: Vec<_> = driven
                    .iter()
                    .map(|(_, c)| c.segments.iter().find(|s| s.segment_index == k))
                    .collect();
                let max_m: Vec<Option<f64>> = results
                    .iter()
                    .map(|r| r.and_then(|r| r.oracle.stats.as_ref().map(|s| s.max_m)))
                    .collect();
                let mut values: Vec<f64> = max_m.iter().flatten().copied().collect();
                values.sort_by(f64::total_cmp);
                SegmentSweep {
                    segment_index: k,
                    median_max_m: values.get(values.len() / 2).copied(),
                    max_m,
                    failed_runs: results
                        .iter()
                        .filter(|r| r.is_some_and(|r| r.oracle.verdict == SegmentVerdict::Failed))
                        .count(),
                }
            })
            .collect();
        Self {
            values,
            runs,
            segments,
        }
    }

    /// Runs that ended `failed`.
    pub fn failed_runs(&self) -> usize {
        self.runs
            .iter()
            .filter(|r| r.verdict == Some(Verdict::Failed))
            .count()
    }

    /// Runs that were aborted (a stop, a refused command, a lost link): neither passed nor
    /// failed, counted apart.
    pub fn aborted_runs(&self) -> usize {
        self.runs
            .iter()
            .filter(|r| r.verdict == Some(Verdict::Aborted))
            .count()
    }
}

/// `sweep.json` (see `docs/case-format.md#sweeping-a-case`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepReport {
    /// `drivecheck-sweep` ([`SWEEP_FORMAT`]), its schema version and the drivecheck version.
    #[serde(flatten)]
    pub header: crate::files::Header,
    /// The case file, as given.
    pub case: String,
    /// The scenario.
    pub scenario: ScenarioRef,
    /// Run k of every point has seed + k.
    pub seed: u64,
    /// Runs per point.
    pub runs_per_point: u32,
    /// The parameters swept and their values.
    pub axes: Vec<Axis>,
    /// Every point of the grid, in order.
    pub points: Vec<Point>,
}

impl SweepReport {
    /// As pretty-printed JSON.
    pub fn to_json(&self) -> Result<String, CaseError> {
        serde_json::to_string_pretty(self).map_err(CaseError::Write)
    }

    /// The table: a row per point, the median of each segment's largest deviation over the runs
    /// (`*` when it failed in a run), and how many runs failed and how many were aborted.
    pub fn table(&self) -> String {
        let segments = self
            .points
            .iter()
            .map(|p| p.segments.len())
            .max()
            .unwrap_or(0);
        let mut header: Vec<String> = self.axes.iter().map(|a| a.parameter.to_string()).collect();
        header.push("failed runs".to_owned());
        header.push("aborted runs".to_owned());
        header.extend((0..segments).map(|k| format!("seg {k} (m)")));
        let mut out = format!(
            "| {} |\n|{}\n",
            header.join(" | "),
            "---|".repeat(header.len())
        );
        for point in &self.points {
            let mut row: Vec<String> = point.values.iter().map(|v| format!("{v}")).collect();
            row.push(format!("{}/{}", point.failed_runs(), point.runs.len()));
            row.push(format!("{}/{}", point.aborted_runs(), point.runs.len()));
            for k in 0..segments {
                row.push(match point.segments.get(k) {
                    Some(s) => match s.median_max_m {
                        Some(m) if s.failed_runs > 0 => format!("{m:.2}*"),
                        Some(m) => format!("{m:.2}"),
                        None => "-".to_owned(),
                    },
                    None => "-".to_owned(),
                });
            }
            out.push_str(&format!("| {} |\n", row.join(" | ")));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::files::tests::doc_examples;

    fn case() -> Case {
        Case::from_json(doc_examples()[0]).unwrap()
    }

    #[test]
    fn names_and_values_are_parsed_and_checked() {
        let case = case();
        let axis = Axis::parse("fault[0].param=1, 2.5,4", &case).unwrap();
        assert_eq!(
            axis.parameter,
            Parameter::Fault {
                index: 0,
                field: FaultField::Param
            }
        );
        assert_eq!(axis.values, [1.0, 2.5, 4.0]);
        assert_eq!(
            Axis::parse("sim.uwb_clamp_m=0.1,0.4", &case)
                .unwrap()
                .parameter
                .to_string(),
            "sim.uwb_clamp_m"
        );
        let error = |arg: &str| Axis::parse(arg, &case).unwrap_err().to_string();
        assert!(error("fault[9].param=1").contains("fault command(s)"));
        assert!(error("fault[0].speed=1").contains("expected fault[i].param"));
        assert!(error("sim.clamp=1").contains("sim.uwb_clamp_m"));
        assert!(error("fault[0].duration=0").contains("1 to 1000000"));
        assert!(
            error("fault[0].param=1e39,2.0").contains("at most 1000 either sign"),
            "{}",
            error("fault[0].param=1e39")
        );
        let many = format!("fault[0].start={}", vec!["1"; 1001].join(","));
        assert!(error(&many).contains("1001 values: at most 1000 per parameter"));
        assert!(error("fault[0].start=1.5").contains("whole number"));
        assert!(error("sim.uwb_clamp_m=0").contains("above 0"));
        assert!(error("fault[0].param=x").contains("`x` is not a finite number"));
        assert!(error("fault[0].param").contains("NAME=V1"));
        let faults = fault_commands(&case).len();
        assert_eq!(
            Axis::parse("fault[9].param=1", &case).unwrap_err(),
            SweepError {
                arg: "fault[9].param=1".to_owned(),
                problem: SetProblem::NoSuchFault { faults }
            }
        );
    }

    #[test]
    fn the_table_counts_aborted_runs_apart_from_failed_ones() {
        let run = |verdict| RunResult {
            seed: 1,
            verdict: Some(verdict),
            first_failing_segment: None,
            max_deviation_m: None,
        };
        let case = case();
        let report = SweepReport {
            header: crate::files::Header::current(SWEEP_FORMAT, 1),
            case: "case.json".to_owned(),
            scenario: case.scenario.clone(),
            seed: 1,
            runs_per_point: 3,
            axes: vec![Axis::parse("fault[0].param=2", &case).unwrap()],
            points: vec![Point {
                values: vec![2.0],
                runs: vec![
                    run(Verdict::Aborted),
                    run(Verdict::Failed),
                    run(Verdict::Passed),
                ],
                segments: Vec::new(),
            }],
        };
        let table = report.table();
        assert!(
            table.starts_with("| fault[0].param | failed runs | aborted runs |"),
            "{table}"
        );
        assert!(table.contains("| 2 | 1/3 | 1/3 |"), "{table}");
    }

    #[test]
    fn a_grid_above_the_limit_is_refused_before_it_is_made() {
        let case = case();
        let values = |n: usize| (0..n).map(|k| k.to_string()).collect::<Vec<_>>().join(",");
        let axes: Vec<Axis> = (0..3)
            .map(|_| Axis::parse(&format!("fault[0].start={}", values(1000)), &case).unwrap())
            .collect();
        let error = grid_size(&axes).unwrap_err();
        assert_eq!(
            error.to_string(),
            "the grid of 1000 × 1000 × 1000 value(s) has more than 10000 points (the limit): \
             sweep fewer values"
        );
        assert_eq!(grid_size(&axes[..1]), Ok(1000));
        assert_eq!(grid_size(&[]), Ok(1));
    }

    #[test]
    fn the_grid_is_every_combination_first_axis_slowest() {
        let case = case();
        let axes = [
            Axis::parse("sim.uwb_clamp_m=0.1,0.2", &case).unwrap(),
            Axis::parse("fault[0].start=0,5,9", &case).unwrap(),
        ];
        let points = grid(&axes);
        assert_eq!(points.len(), 6);
        assert_eq!(points[0], [0.1, 0.0]);
        assert_eq!(points[1], [0.1, 5.0]);
        assert_eq!(points[5], [0.2, 9.0]);
        let changed = with_fault_values(&case, &axes, &points[4]);
        let first = fault_commands(&case)[0];
        assert!(matches!(
            changed.commands[first],
            CommandRecord::AddFault { start: 5, .. }
        ));
        assert_eq!(grid(&[]), vec![Vec::<f64>::new()]);
    }

    #[test]
    fn a_silenced_fault_keeps_its_place_and_does_nothing() {
        let case = case();
        let first = fault_commands(&case)[0];
        let silenced = with_fault_silenced(&case, first);
        let CommandRecord::AddFault {
            kind,
            probe,
            start,
            at,
            ..
        } = &silenced.commands[first]
        else {
            panic!("still a fault command");
        };
        assert_eq!(*kind, car_link::FaultKind::None);
        let CommandRecord::AddFault {
            probe: p0,
            start: s0,
            at: a0,
            ..
        } = &case.commands[first]
        else {
            panic!("a fault command");
        };
        assert_eq!((probe, start, at), (p0, s0, a0));
        assert_eq!(silenced.commands.len(), case.commands.len());
        // Not a fault: the case as it was.
        assert_eq!(with_fault_silenced(&case, 0).commands, case.commands);
    }
}
