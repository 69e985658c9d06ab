//! The comparison of a replay: a recorded case driven again N times after the same reset; per segment each run's maximum deviation, their mean, and each
//! run's difference from the mean (the repeatability measure); whether the verdict was the same
//! every time; and, for a replay without the fault commands, whether the failure disappeared.
//!
//! Segments are matched by their index among the test's segments (`segment_index`), which is the
//! same with and without the fault commands. A segment a run did not drive (the test stopped
//! earlier) has no value for that run and is left out of the mean.
//!
use crate::files::{
    Case, Comparison, Header, REPLAY_FORMAT, REPLAY_SCHEMA_VERSION, ReplayOf, ReplayRun,
    ScenarioRef, SegmentComparison,
};
use crate::oracle::Verdict;

/// The file name of the comparison in a replay directory.
pub const REPLAY_FILE: &str = "replay.json";

/// The largest deviation of segment `segment_index` in `case`, if driven with samples.
fn segment_max(case: &Case, segment_index: usize) -> Option<f64> {
    case.segments
        .iter()
        .find(|s| s.segment_index == segment_index)
        .and_then(|s| s.oracle.stats)
        .map(|stats| stats.max_m)
}

impl Comparison {
    /// Compares `runs` (each run's descriptor and its case, `None` when it never produced one)
    /// of a replay of `original`.
    pub fn new(
        original: &Case,
        replay_of: ReplayOf,
        scenario: ScenarioRef,
        runs: &[(ReplayRun, Option<Case>)],
    ) -> Self {
        let indices: std::collections::BTreeSet<usize> = std::iter::once(original)
            .chain(runs.iter().filter_map(|(_, case)| case.as_ref()))
            .flat_map(|case| case.segments.iter().map(|s| s.segment_index))
            .collect();
        let segments: Vec<SegmentComparison> = indices
            .into_iter()
            .map(|index| {
                let max_m: Vec<Option<f64>> = runs
                    .iter()
                    .map(|(_, case)| case.as_ref().and_then(|c| segment_max(c, index)))
                    .collect();
                let present: Vec<f64> = max_m.iter().flatten().copied().collect();
                let mean_m = (!present.is_empty())
                    .then(|| present.iter().sum::<f64>() / present.len() as f64);
                let diff_from_mean_m = max_m
                    .iter()
                    .map(|m| m.zip(mean_m).map(|(m, mean)| m - mean))
                    .collect();
                SegmentComparison {
                    segment_index: index,
                    original_max_m: segment_max(original, index),
                    max_m,
                    mean_m,
                    diff_from_mean_m,
                }
            })
            .collect();
        let max_abs_diff_m = segments
            .iter()
            .flat_map(|s| s.diff_from_mean_m.iter().flatten())
            .map(|d| d.abs())
            .max_by(f64::total_cmp);
        let verdicts: Vec<Option<Verdict>> = runs.iter().map(|(run, _)| run.verdict).collect();
        let same_verdict = verdicts.windows(2).all(|w| w[0] == w[1]);
        let same_as_original = original
            .verdict
            .map(|v| verdicts.iter().all(|&r| r == Some(v)));
        let failure_disappeared = (replay_of.no_faults
            && matches!(original.verdict, Some(Verdict::Failed)))
        .then(|| verdicts.iter().all(|&r| r == Some(Verdict::Passed)));
        Self {
            header: Header::untooled(REPLAY_FORMAT, REPLAY_SCHEMA_VERSION),
            replay_of,
            scenario,
            runs: runs.iter().map(|(run, _)| run.clone()).collect(),
            segments,
            max_abs_diff_m,
            same_verdict,
            same_as_original,
            failure_disappeared,
        }
    }

    /// The comparison as a Markdown table with a summary below it.
    pub fn table(&self) -> String {
        use std::fmt::Write as _;
        let metres = |m: Option<f64>| m.map_or_else(|| "-".to_owned(), |m| format!("{m:.3}"));
        let signed = |m: Option<f64>| m.map_or_else(|| "-".to_owned(), |m| format!("{m:+.3}"));
        let mut out = String::new();
        let mut header = "| segment | original max (m) |".to_owned();
        let mut rule = "|---|---|".to_owned();
        for i in 1..=self.runs.len() {
            let _ = write!(header, " run {i} max (m) | run {i} − mean (m) |");
            rule.push_str("---|---|");
        }
        header.push_str(" mean (m) |");
        rule.push_str("---|");
        let _ = writeln!(out, "{header}\n{rule}");
        for s in &self.segments {
            let mut row = format!("| {} | {} |", s.segment_index, metres(s.original_max_m));
            for (m, d) in s.max_m.iter().zip(&s.diff_from_mean_m) {
                let _ = write!(row, " {} | {} |", metres(*m), signed(*d));
            }
            let _ = write!(row, " {} |", metres(s.mean_m));
            let _ = writeln!(out, "{row}");
        }
        let _ = writeln!(out);
        let verdict = |v: Option<Verdict>| v.map_or("not run", Verdict::as_str);
        let verdicts: Vec<&str> = self.runs.iter().map(|r| verdict(r.verdict)).collect();
        let _ = writeln!(
            out,
            "original: {}; runs: {}; same verdict every time: {}",
            verdict(self.replay_of.verdict),
            verdicts.join(", "),
            if self.same_verdict { "yes" } else { "no" }
        );
        let _ = writeln!(
            out,
            "largest difference from the mean: {} m",
            metres(self.max_abs_diff_m)
        );
        if let Some(gone) = self.failure_disappeared {
            let _ = writeln!(
                out,
                "without the faults the failure {}",
                if gone { "disappears" } else { "remains" }
            );
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::files::{CASE_FORMAT, CommandRecord, RoutePointRecord, SegmentResult};
    use crate::oracle::SegmentOracle;
    use trajgen::Point;

    fn case(maxima: &[f64], verdict: Verdict) -> Case {
        let segments = maxima
            .iter()
            .enumerate()
            .map(|(i, &m)| {
                let mut oracle = SegmentOracle::new();
                oracle.push(Point::new(m, 0.0), Point::new(0.0, 0.0));
                SegmentResult {
                    segment_index: i,
                    command_index: i,
                    faults_preceding: vec![],
                    faults_active: vec![],
                    oracle: oracle.result(1.0),
                }
            })
            .collect();
        Case {
            header: Header::untooled(CASE_FORMAT, 1),
            campaign_seed: Some(1),
            test_index: Some(0),
            scenario: ScenarioRef {
                name: "s".to_owned(),
                hash: None,
            },
            settings: None,
            car_profile: None,
            car: None,
            no_faults: false,
            commands: vec![CommandRecord::RunSegments {
                intent: None,
                points: vec![RoutePointRecord {
                    x: 1.0,
                    y: 0.0,
                    speed: 1.0,
                }],
                margin: vec![],
            }],
            return_route: vec![],
            return_clearance_m: None,
            segments,
            verdict: Some(verdict),
            reason: None,
            abort: None,
            streaming: None,
            fault_places: Vec::new(),
            timing: None,
            explanation: Vec::new(),
        }
    }

    fn of(no_faults: bool) -> ReplayOf {
        ReplayOf {
            case: "case-000.json".to_owned(),
            campaign_seed: Some(1),
            test_index: Some(0),
            verdict: Some(Verdict::Failed),
            no_faults,
        }
    }

    fn run(i: usize, case: &Case) -> (ReplayRun, Option<Case>) {
        let run = ReplayRun {
            dir: format!("run-{i}"),
            seed: 1,
            verdict: case.verdict,
            reason: None,
        };
        (run, Some(case.clone()))
    }

    #[test]
    fn differences_from_the_mean_per_segment_and_run() {
        let original = case(&[0.5, 1.2], Verdict::Failed);
        let runs = [
            run(1, &case(&[0.4, 1.1], Verdict::Failed)),
            run(2, &case(&[0.6, 1.3], Verdict::Failed)),
        ];
        let c = Comparison::new(&original, of(false), original.scenario.clone(), &runs);
        assert_eq!(c.segments.len(), 2);
        let s = &c.segments[1];
        assert_eq!(s.original_max_m, Some(1.2));
        assert!((s.mean_m.unwrap() - 1.2).abs() < 1e-12);
        assert!((s.diff_from_mean_m[0].unwrap() + 0.1).abs() < 1e-12);
        assert!((s.diff_from_mean_m[1].unwrap() - 0.1).abs() < 1e-12);
        assert!((c.max_abs_diff_m.unwrap() - 0.1).abs() < 1e-12);
        assert!(c.same_verdict);
        assert_eq!(c.same_as_original, Some(true));
        assert_eq!(c.failure_disappeared, None);
        let table = c.table();
        assert!(
            table.contains("| 1 | 1.200 | 1.100 | -0.100 | 1.300 | +0.100 | 1.200 |"),
            "{table}"
        );
        assert_eq!(Comparison::from_json(&c.to_json().unwrap()).unwrap(), c);
    }

    #[test]
    fn a_segment_not_driven_is_left_out_of_the_mean() {
        let original = case(&[0.5, 1.2], Verdict::Failed);
        let runs = [
            run(1, &case(&[1.4], Verdict::Failed)),
            run(2, &case(&[0.6, 0.7], Verdict::Passed)),
        ];
        let c = Comparison::new(&original, of(false), original.scenario.clone(), &runs);
        assert_eq!(c.segments[1].max_m, vec![None, Some(0.7)]);
        assert_eq!(c.segments[1].mean_m, Some(0.7));
        assert_eq!(c.segments[1].diff_from_mean_m, vec![None, Some(0.0)]);
        assert!(!c.same_verdict);
        assert_eq!(c.same_as_original, Some(false));
    }

    #[test]
    fn without_faults_a_failure_disappears_only_when_every_run_passes() {
        let original = case(&[0.5, 1.2], Verdict::Failed);
        let passed = case(&[0.5, 0.6], Verdict::Passed);
        let failed = case(&[0.5, 1.6], Verdict::Failed);
        let all = [run(1, &passed), run(2, &passed)];
        let c = Comparison::new(&original, of(true), original.scenario.clone(), &all);
        assert_eq!(c.failure_disappeared, Some(true));
        assert!(c.table().contains("failure disappears"));
        let some = [run(1, &passed), run(2, &failed)];
        let c = Comparison::new(&original, of(true), original.scenario.clone(), &some);
        assert_eq!(c.failure_disappeared, Some(false));
    }
}
