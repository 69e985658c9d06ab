//! The method's two thresholds from a fault-free run, at a false-alarm budget
//! (`drivecheck explain --calibrate`, `docs/explain.md`): the **nominal level** is the `1 − budget`
//! quantile of the run's |UWB − RTK| samples; the **least growth** the `1 − budget` quantile,
//! over its judged segments, of the largest growth any cause gets with that nominal level and no
//! least growth. Both quantiles are the nearest rank (`trajgen::stats::nearest_rank`).
//!
//! The explaining is the caller's: [`calibrate`] is given a function that explains every judged
//! segment of the run with the configuration it is handed.

use serde::{Deserialize, Serialize};
use thiserror::Error;
use trajgen::stats::nearest_rank;

use super::{ExplainConfig, SegmentExplanation, Source};
use crate::case::{Case, CommandRecord};

/// Thresholds for [`super::explain_segment`] from a fault-free run, at a false-alarm budget.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Samples of |UWB − RTK| read.
    pub samples: usize,
    /// Judged segments read.
    pub segments: usize,
    /// The budget: the share of fault-free samples above `nominal_m`, and of fault-free segments
    /// with a cause above `min_growth_m`.
    pub budget: f64,
    /// The error level `1 − budget` of the fault-free samples stay at or below, metres.
    pub nominal_m: f64,
    /// The growth a cause of `1 − budget` of the fault-free segments stays below (with that
    /// nominal level), metres.
    pub min_growth_m: f64,
}

/// Why a run could not be calibrated on.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CalibrationError<E> {
    /// The budget is not a share strictly between 0 and 1.
    #[error("the false-alarm budget {0} is not between 0 and 1")]
    Budget(f64),
    /// A test of the run has fault commands.
    #[error(
        "the run has fault commands: calibrate on a fault-free run (drivecheck run --no-faults)"
    )]
    Faults,
    /// The run has no deviation samples.
    #[error("the recording has no samples to calibrate on")]
    NoSamples,
    /// Explaining the run's segments failed.
    #[error("{0}")]
    Explain(E),
}

/// Calibrates on a fault-free run (see the module doc): its tests' `cases`, the |UWB − RTK| of
/// every sample of its tests (`deviations`, in any order), and `explain`, which explains every
/// judged segment of the run with the configuration it is given (called once, after the checks).
pub fn calibrate<'a, E>(
    cases: impl IntoIterator<Item = &'a Case>,
    deviations: impl IntoIterator<Item = f64>,
    budget: f64,
    explain: impl FnOnce(&ExplainConfig) -> Result<Vec<SegmentExplanation>, E>,
) -> Result<Calibration, CalibrationError<E>> {
    if !(budget > 0.0 && budget < 1.0) {
        return Err(CalibrationError::Budget(budget));
    }
    if cases.into_iter().any(|case| {
        case.commands
            .iter()
            .any(|c| matches!(c, CommandRecord::AddFault { .. }))
    }) {
        return Err(CalibrationError::Faults);
    }
    let mut errors: Vec<f64> = deviations.into_iter().collect();
    errors.sort_by(f64::total_cmp);
    let nominal_m = nearest_rank(&errors, 1.0 - budget).ok_or(CalibrationError::NoSamples)?;
    let config = ExplainConfig {
        nominal_m,
        min_growth_m: 0.0,
        ..ExplainConfig::default()
    };
    let explained = explain(&config).map_err(CalibrationError::Explain)?;
    let mut largest: Vec<f64> = explained.iter().map(largest_growth).collect();
    largest.sort_by(f64::total_cmp);
    Ok(Calibration {
        samples: errors.len(),
        segments: largest.len(),
        budget,
        nominal_m,
        min_growth_m: nearest_rank(&largest, 1.0 - budget).unwrap_or(0.0),
    })
}

/// The largest growth any named cause of `segment` gets, metres (0 with none).
fn largest_growth(segment: &SegmentExplanation) -> f64 {
    segment
        .causes
        .iter()
        .filter(|c| c.source != Source::Unexplained)
        .map(|c| c.growth_m)
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::explain::Cause;
    use proptest::prelude::*;

    fn case(with_fault: bool) -> Case {
        let commands = if with_fault {
            serde_json::json!([{
                "command": "add_fault", "probe": "uwb_yaw", "kind": "offset",
                "param": 10.0, "start": 0, "duration": 10
            }])
        } else {
            serde_json::json!([])
        };
        let json = serde_json::json!({
            "format": "drivecheck-case", "schema_version": 2, "scenario": {"name": "s"},
            "commands": commands
        });
        Case::from_json(&json.to_string()).unwrap()
    }

    /// A judged segment whose causes grew the error by these amounts.
    fn segment(growths: &[(Source, f64)]) -> SegmentExplanation {
        SegmentExplanation {
            segment_index: 0,
            verdict: "passed".to_owned(),
            from_s: 0.0,
            to_s: 1.0,
            error_from_m: 0.3,
            error_to_m: 0.4,
            carried_over: false,
            causes: growths
                .iter()
                .map(|&(source, growth_m)| Cause {
                    source,
                    share: 0.5,
                    growth_m,
                    steps: 3,
                    kind: None,
                    ambiguous_with: None,
                })
                .collect(),
        }
    }

    #[test]
    fn the_levels_are_the_quantiles_at_the_budget() {
        // 200 samples 0.01..=2.00 m: the 99th percentile is the 198th.
        let deviations = (1..=200).map(|k| f64::from(k) / 100.0);
        let mut asked = None;
        let c = calibrate([&case(false)], deviations, 0.01, |config| {
            asked = Some(*config);
            Ok::<_, ()>(vec![
                segment(&[(Source::Odometry, 0.05), (Source::Unexplained, 0.9)]),
                segment(&[(Source::Anchor { anchor_id: 50 }, 0.08)]),
                segment(&[]),
            ])
        })
        .unwrap();
        assert_eq!(c.samples, 200);
        assert!((c.nominal_m - 1.98).abs() < 1e-12, "{c:?}");
        // The segments are explained at that nominal level, every cause counted.
        let asked = asked.unwrap();
        assert_eq!(asked.nominal_m, c.nominal_m);
        assert_eq!(asked.min_growth_m, 0.0);
        // Largest growths 0.05, 0.08 and 0 (unexplained does not count): the 99th is 0.08.
        assert_eq!(c.segments, 3);
        assert_eq!(c.min_growth_m, 0.08);
        assert_eq!(c.budget, 0.01);
    }

    #[test]
    fn a_run_with_faults_or_no_samples_or_a_bad_budget_is_refused_before_explaining() {
        let never = |_: &ExplainConfig| -> Result<Vec<SegmentExplanation>, ()> {
            panic!("explained a run that is refused")
        };
        assert_eq!(
            calibrate([&case(false), &case(true)], [0.1], 0.01, never),
            Err(CalibrationError::Faults)
        );
        assert_eq!(
            calibrate([&case(false)], [], 0.01, never),
            Err(CalibrationError::NoSamples)
        );
        for budget in [0.0, 1.0, f64::NAN, -0.5] {
            assert!(matches!(
                calibrate([&case(false)], [0.1], budget, never),
                Err(CalibrationError::Budget(_))
            ));
        }
        // No segments: no least growth.
        let c = calibrate([&case(false)], [0.2, 0.3], 0.5, |_| Ok::<_, ()>(Vec::new())).unwrap();
        assert_eq!((c.nominal_m, c.segments, c.min_growth_m), (0.2, 0, 0.0));
        // The explaining's error is passed on.
        assert_eq!(
            calibrate([&case(false)], [0.2], 0.5, |_| Err::<Vec<_>, _>(
                "unreadable"
            )),
            Err(CalibrationError::Explain("unreadable"))
        );
    }

    proptest! {
        /// The nominal level is one of the samples, and at most the budget's share of the samples
        /// lie above it (the false alarms it allows), while more than that lie at or above it.
        #[test]
        fn at_most_the_budget_of_the_samples_lie_above_the_nominal_level(
            deviations in prop::collection::vec(0.0f64..3.0, 1..300),
            budget in 0.001f64..0.5,
        ) {
            let c = calibrate([&case(false)], deviations.iter().copied(), budget, |_| {
                Ok::<_, ()>(Vec::new())
            })
            .unwrap();
            prop_assert!(deviations.contains(&c.nominal_m));
            let n = deviations.len() as f64;
            let above = deviations.iter().filter(|&&d| d > c.nominal_m).count() as f64;
            let at_or_above = deviations.iter().filter(|&&d| d >= c.nominal_m).count() as f64;
            prop_assert!(above <= budget * n + 1e-9, "{} above of {}", above, n);
            prop_assert!(at_or_above >= budget * n - 1e-9, "{} at or above of {}", at_or_above, n);
        }
    }
}
