//! The oracle (`docs/method.md#the-oracle`): the UWB position against the RTK-GNSS reference.
//!
//! Every state sample gives a deviation |UWB − RTK|. Per segment the oracle keeps every
//! deviation and reports the maximum, the RMS, the 95th percentile and the sample count; a
//! segment fails when its maximum is above the threshold (the scenario's `oracle_threshold_m`,
//! 1.0 m by default). A segment without usable samples is never a pass: it is
//! [`SegmentVerdict::NoSamples`], which makes the test aborted, not passed.
//!
//! Samples whose RTK position is not finite cannot be judged and are counted apart; samples with
//! a finite RTK position but a non-finite UWB position are counted as invalid and fail the
//! segment (the system under test produced no position).
//!
//! Pure functions over samples: no clock, no I/O.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use trajgen::Point;
use trajgen::stats::nearest_rank;

/// The method's threshold, metres.
pub const DEFAULT_THRESHOLD_M: f64 = 1.0;

/// What to do when a segment fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FailurePolicy {
    /// Stop the test at the failing segment: safe stop, then the next test (the default).
    #[default]
    StopAtFailingSegment,
    /// Drive the rest of the test and record every segment.
    ContinueAndRecord,
}

impl FailurePolicy {
    /// Whether the test goes on after a segment with `verdict`.
    pub fn continue_after(self, verdict: SegmentVerdict) -> bool {
        match verdict {
            SegmentVerdict::Passed => true,
            SegmentVerdict::Failed | SegmentVerdict::NoSamples => self == Self::ContinueAndRecord,
        }
    }
}

/// Deviation statistics of one segment, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct DeviationStats {
    /// Judged samples (finite UWB and RTK positions).
    pub samples: usize,
    /// Largest deviation.
    pub max_m: f64,
    /// Root mean square deviation.
    pub rms_m: f64,
    /// 95th percentile (nearest rank: the smallest deviation at least 95 % of samples do not
    /// exceed).
    pub p95_m: f64,
}

/// The oracle's judgement of one segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SegmentVerdict {
    /// Every deviation at or below the threshold.
    Passed,
    /// A deviation above the threshold, or a sample without a UWB position.
    Failed,
    /// No sample could be judged: never a pass.
    NoSamples,
}

/// The deviation of one state sample: |UWB − RTK|, metres. `None` when the RTK reference is not
/// finite (the sample cannot be judged); infinite when only the UWB position is not finite.
pub fn deviation(uwb: Point, rtk: Point) -> Option<f64> {
    if !rtk.is_finite() {
        return None;
    }
    if !uwb.is_finite() {
        return Some(f64::INFINITY);
    }
    Some(uwb.dist(rtk))
}

/// Statistics of finite deviations; `None` for none. Non-finite values are ignored.
pub fn stats(deviations: &[f64]) -> Option<DeviationStats> {
    let mut sorted: Vec<f64> = deviations
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .collect();
    if sorted.is_empty() {
        return None;
    }
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    let mean_square = sorted.iter().map(|d| d * d).sum::<f64>() / n as f64;
    Some(DeviationStats {
        samples: n,
        max_m: sorted[n - 1],
        rms_m: mean_square.sqrt(),
        p95_m: nearest_rank(&sorted, 0.95).unwrap_or(sorted[n - 1]),
    })
}

/// Collects one segment's samples and judges it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SegmentOracle {
    deviations: Vec<f64>,
    invalid_uwb: usize,
    unjudged: usize,
}

impl SegmentOracle {
    /// An oracle with no samples yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one state sample.
    pub fn push(&mut self, uwb: Point, rtk: Point) {
        match deviation(uwb, rtk) {
            None => self.unjudged += 1,
            Some(d) if d.is_finite() => self.deviations.push(d),
            Some(_) => self.invalid_uwb += 1,
        }
    }

    /// The deviations so far, in sample order (for time series).
    pub fn deviations(&self) -> &[f64] {
        &self.deviations
    }

    /// The segment's result against `threshold_m`.
    pub fn result(&self, threshold_m: f64) -> SegmentOutcome {
        let stats = stats(&self.deviations);
        let verdict = judge(stats.as_ref(), self.invalid_uwb, threshold_m);
        SegmentOutcome {
            stats,
            invalid_uwb_samples: self.invalid_uwb,
            unjudged_samples: self.unjudged,
            threshold_m,
            verdict,
        }
    }
}

/// What the oracle says about one segment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SegmentOutcome {
    /// Statistics of the judged samples (`None`, and left out of files, without any).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stats: Option<DeviationStats>,
    /// Samples with a reference but no finite UWB position (each fails the segment).
    pub invalid_uwb_samples: usize,
    /// Samples without a finite RTK reference (not judged).
    pub unjudged_samples: usize,
    /// The threshold judged against, metres.
    pub threshold_m: f64,
    /// The judgement.
    pub verdict: SegmentVerdict,
}

/// The verdict for statistics `stats`, `invalid_uwb` samples without a UWB position, and a
/// threshold (a deviation equal to the threshold passes).
pub fn judge(
    stats: Option<&DeviationStats>,
    invalid_uwb: usize,
    threshold_m: f64,
) -> SegmentVerdict {
    if invalid_uwb > 0 {
        return SegmentVerdict::Failed;
    }
    match stats {
        None => SegmentVerdict::NoSamples,
        Some(s) if s.max_m > threshold_m => SegmentVerdict::Failed,
        Some(_) => SegmentVerdict::Passed,
    }
}

/// A test's verdict.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Every segment driven passed and the test ran to its end.
    Passed,
    /// A segment's deviation was above the threshold (or UWB gave no position).
    Failed,
    /// The test could not be judged to its end: the safety monitor stopped it, the link was
    /// lost, a segment had no samples, or the campaign was interrupted. Never a pass.
    Aborted,
}

impl Verdict {
    /// The verdict's name (`passed`, `failed`, `aborted`).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Passed => "passed",
            Self::Failed => "failed",
            Self::Aborted => "aborted",
        }
    }
}

/// One judged segment of a test, for [`test_verdict`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JudgedSegment {
    /// The segment's index among the test's segments (from 0).
    pub segment_index: usize,
    /// Its command index in the test.
    pub command_index: usize,
    /// The oracle's result.
    pub outcome: SegmentOutcome,
}

/// A verdict and the reason a person reads (none for a pass).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TestVerdict {
    /// The verdict.
    pub verdict: Verdict,
    /// Why, in words; `None` when passed.
    pub reason: Option<String>,
}

/// The verdict of a test from its judged segments and, when it ended early, the abort reason.
///
/// A failed segment makes the test failed even when it was aborted later (the failure is the
/// finding; the abort reason is appended). Otherwise an abort, or a segment without samples,
/// makes it aborted. Only a test with at least one judged segment, all passed, and no abort
/// passes.
pub fn test_verdict(segments: &[JudgedSegment], abort: Option<&str>) -> TestVerdict {
    let failed = segments
        .iter()
        .find(|s| s.outcome.verdict == SegmentVerdict::Failed);
    if let Some(segment) = failed {
        let mut reason = failure_reason(segment);
        if let Some(abort) = abort {
            reason.push_str(&format!("; then aborted: {abort}"));
        }
        return TestVerdict {
            verdict: Verdict::Failed,
            reason: Some(reason),
        };
    }
    let reason = match (
        abort,
        segments
            .iter()
            .find(|s| s.outcome.verdict == SegmentVerdict::NoSamples),
    ) {
        (Some(abort), _) => Some(abort.to_owned()),
        (None, Some(s)) => Some(format!(
            "segment {} (command {}): no state sample could be judged",
            s.segment_index, s.command_index
        )),
        (None, None) if segments.is_empty() => Some("no segment was driven".to_owned()),
        (None, None) => None,
    };
    match reason {
        Some(reason) => TestVerdict {
            verdict: Verdict::Aborted,
            reason: Some(reason),
        },
        None => TestVerdict {
            verdict: Verdict::Passed,
            reason: None,
        },
    }
}

fn failure_reason(segment: &JudgedSegment) -> String {
    let outcome = &segment.outcome;
    let place = format!(
        "segment {} (command {})",
        segment.segment_index, segment.command_index
    );
    match outcome.stats {
        Some(stats) if stats.max_m > outcome.threshold_m => format!(
            "{place}: deviation {:.2} m above {:.2} m",
            stats.max_m, outcome.threshold_m
        ),
        _ => format!(
            "{place}: {} samples without a UWB position",
            outcome.invalid_uwb_samples
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn stats_match_hand_computed_values() {
        // 3-4-5: deviations 0.3, 0.4, 0.5, 1.2 → mean square (0.09+0.16+0.25+1.44)/4 = 0.485.
        let s = stats(&[0.5, 0.3, 1.2, 0.4]).unwrap();
        assert_eq!(s.samples, 4);
        assert!(close(s.max_m, 1.2));
        assert!(close(s.rms_m, 0.485_f64.sqrt()));
        // Nearest rank: ceil(0.95 · 4) = 4 → the largest.
        assert!(close(s.p95_m, 1.2));
    }

    #[test]
    fn p95_is_the_nearest_rank() {
        // 1..=100 cm: ceil(95) = 95th value = 0.95 m.
        let d: Vec<f64> = (1..=100).map(|i| f64::from(i) / 100.0).collect();
        let s = stats(&d).unwrap();
        assert!(close(s.p95_m, 0.95));
        assert!(close(s.max_m, 1.0));
        // 1..=20: ceil(19) = 19th value.
        let d: Vec<f64> = (1..=20).map(f64::from).collect();
        assert!(close(stats(&d).unwrap().p95_m, 19.0));
        assert!(close(stats(&[0.7]).unwrap().p95_m, 0.7));
    }

    #[test]
    fn no_deviation_gives_no_stats() {
        assert_eq!(stats(&[]), None);
        assert_eq!(stats(&[f64::NAN]), None);
    }

    #[test]
    fn deviation_is_the_distance_between_uwb_and_rtk() {
        let d = deviation(Point::new(3.0, 4.0), Point::new(0.0, 0.0));
        assert_eq!(d, Some(5.0));
        assert_eq!(
            deviation(Point::new(0.0, 0.0), Point::new(f64::NAN, 0.0)),
            None
        );
        assert_eq!(
            deviation(Point::new(f64::NAN, 0.0), Point::new(0.0, 0.0)),
            Some(f64::INFINITY)
        );
    }

    #[test]
    fn a_segment_fails_above_the_threshold_and_passes_at_it() {
        let mut oracle = SegmentOracle::new();
        oracle.push(Point::new(1.0, 0.0), Point::new(0.0, 0.0));
        assert_eq!(oracle.result(1.0).verdict, SegmentVerdict::Passed);
        oracle.push(Point::new(1.01, 0.0), Point::new(0.0, 0.0));
        let outcome = oracle.result(1.0);
        assert_eq!(outcome.verdict, SegmentVerdict::Failed);
        assert!(close(outcome.stats.unwrap().max_m, 1.01));
    }

    #[test]
    fn a_segment_without_samples_is_never_a_pass() {
        let mut oracle = SegmentOracle::new();
        assert_eq!(oracle.result(1.0).verdict, SegmentVerdict::NoSamples);
        oracle.push(Point::new(0.0, 0.0), Point::new(f64::NAN, f64::NAN));
        let outcome = oracle.result(1.0);
        assert_eq!(outcome.verdict, SegmentVerdict::NoSamples);
        assert_eq!(outcome.unjudged_samples, 1);
    }

    #[test]
    fn a_missing_uwb_position_fails_the_segment() {
        let mut oracle = SegmentOracle::new();
        oracle.push(Point::new(0.1, 0.0), Point::new(0.0, 0.0));
        oracle.push(Point::new(f64::INFINITY, 0.0), Point::new(0.0, 0.0));
        let outcome = oracle.result(1.0);
        assert_eq!(outcome.verdict, SegmentVerdict::Failed);
        assert_eq!(outcome.invalid_uwb_samples, 1);
        assert_eq!(outcome.stats.unwrap().samples, 1);
    }

    fn judged(index: usize, max: Option<f64>) -> JudgedSegment {
        let mut oracle = SegmentOracle::new();
        if let Some(max) = max {
            oracle.push(Point::new(max, 0.0), Point::new(0.0, 0.0));
        }
        JudgedSegment {
            segment_index: index,
            command_index: 2 * index,
            outcome: oracle.result(1.0),
        }
    }

    #[test]
    fn a_test_passes_only_when_every_segment_passed_and_nothing_aborted() {
        let ok = [judged(0, Some(0.3)), judged(1, Some(0.9))];
        assert_eq!(test_verdict(&ok, None).verdict, Verdict::Passed);
        assert_eq!(test_verdict(&ok, None).reason, None);
        let lost = test_verdict(&ok, Some("link lost"));
        assert_eq!(lost.verdict, Verdict::Aborted);
        assert_eq!(lost.reason.as_deref(), Some("link lost"));
        assert_eq!(test_verdict(&[], None).verdict, Verdict::Aborted);
        let empty = test_verdict(&[judged(0, Some(0.3)), judged(1, None)], None);
        assert_eq!(empty.verdict, Verdict::Aborted);
    }

    #[test]
    fn a_failure_names_the_segment_and_survives_a_later_abort() {
        let segments = [judged(0, Some(0.3)), judged(1, Some(1.42))];
        let verdict = test_verdict(&segments, Some("link lost"));
        assert_eq!(verdict.verdict, Verdict::Failed);
        assert_eq!(
            verdict.reason.as_deref(),
            Some("segment 1 (command 2): deviation 1.42 m above 1.00 m; then aborted: link lost")
        );
    }

    proptest::proptest! {
        #[test]
        fn stats_are_ordered_min_p95_max_and_rms_within(
            deviations in proptest::collection::vec(0.0f64..10.0, 1..300),
        ) {
            let s = stats(&deviations).unwrap();
            let min = deviations.iter().copied().fold(f64::INFINITY, f64::min);
            proptest::prop_assert_eq!(s.samples, deviations.len());
            proptest::prop_assert!(min <= s.p95_m && s.p95_m <= s.max_m);
            proptest::prop_assert!(min <= s.rms_m + 1e-12 && s.rms_m <= s.max_m + 1e-12);
            proptest::prop_assert!(deviations.contains(&s.p95_m));
        }
    }

    #[test]
    fn the_default_policy_stops_at_the_failing_segment() {
        let stop = FailurePolicy::default();
        assert!(stop.continue_after(SegmentVerdict::Passed));
        assert!(!stop.continue_after(SegmentVerdict::Failed));
        assert!(!stop.continue_after(SegmentVerdict::NoSamples));
        assert!(FailurePolicy::ContinueAndRecord.continue_after(SegmentVerdict::Failed));
    }
}
