//! The comparison of a replay: a recorded case driven again N times after the same reset; per segment each run's maximum deviation, their mean, and each
//! run's difference from the mean (the repeatability measure); whether the verdict was the same
//! every time; and, for a replay without the fault commands, whether the failure disappeared.
//!
//! Segments are matched by their index among the test's segments (`segment_index`), which is the
//! same with and without the fault commands. A segment a run did not drive (the test stopped
//! earlier) has no value for that run and is left out of the mean.
//!
use crate::files::{
    Case, Comparison, Drove, Header, REPLAY_FORMAT, REPLAY_SCHEMA_VERSION, ReplayOf, ReplayRun,
    Reproduction, ScenarioRef, SegmentComparison, SegmentDifference,
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
    /// of a replay of `original`; the runs `drove` what it says (with [`Drove::SameTest`] each
    /// run is checked against the case segment by segment).
    pub fn new(
        original: &Case,
        replay_of: ReplayOf,
        scenario: ScenarioRef,
        runs: &[(ReplayRun, Option<Case>)],
        drove: Drove,
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
        let reproduction = (drove == Drove::SameTest && original.verdict.is_some()).then(|| {
            let differing: Vec<SegmentDifference> = segments
                .iter()
                .flat_map(|s| {
                    s.max_m.iter().enumerate().filter_map(|(k, &max_m)| {
                        // To the last digit: the same f64 (both absent alike).
                        let same = match (s.original_max_m, max_m) {
                            (Some(a), Some(b)) => a.to_bits() == b.to_bits(),
                            (a, b) => a.is_none() && b.is_none(),
                        };
                        (!same).then_some(SegmentDifference {
                            segment_index: s.segment_index,
                            run: k + 1,
                            original_max_m: s.original_max_m,
                            max_m,
                        })
                    })
                })
                .collect();
            Reproduction {
                identical: differing.is_empty() && same_as_original == Some(true),
                differing,
            }
        });
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
            drove: Some(drove),
            reproduction,
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
        let _ = write!(
            out,
            "case: {}; runs: {}",
            verdict(self.replay_of.verdict),
            verdicts.join(", ")
        );
        if let Some(same) = self.same_as_original {
            let _ = write!(out, "; same verdict as the case: {}", yes(same));
        }
        if self.runs.len() > 1 {
            let _ = write!(out, "; same verdict every run: {}", yes(self.same_verdict));
        }
        let _ = writeln!(out);
        if let Some(line) = self.drove_line() {
            let _ = writeln!(out, "{line}");
        }
        if self.runs.len() > 1 {
            let _ = writeln!(
                out,
                "spread: largest difference from the mean {} m",
                metres(self.max_abs_diff_m)
            );
        }
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

fn yes(b: bool) -> &'static str {
    if b { "yes" } else { "no" }
}

impl Comparison {
    /// What the runs drove and, for the case's own test, whether they reproduced it, in words.
    fn drove_line(&self) -> Option<String> {
        let metres = |m: Option<f64>| m.map_or_else(|| "-".to_owned(), |m| format!("{m:.3} m"));
        Some(match self.drove? {
            Drove::SameTest => match &self.reproduction {
                Some(r) if r.identical => {
                    "reproduced: every segment identical (the case's test: the same simulated \
                     car from the same start)"
                        .to_owned()
                }
                Some(r) if r.differing.is_empty() => {
                    "not reproduced: every segment identical, but not the verdict".to_owned()
                }
                Some(r) => {
                    let mut segments: Vec<usize> =
                        r.differing.iter().map(|d| d.segment_index).collect();
                    segments.dedup();
                    let listed: Vec<String> = r
                        .differing
                        .iter()
                        .map(|d| {
                            format!(
                                "segment {} case {}, run {} {}",
                                d.segment_index,
                                metres(d.original_max_m),
                                d.run,
                                metres(d.max_m)
                            )
                        })
                        .collect();
                    format!(
                        "not reproduced: {} segment(s) differ from the case (the case's test on \
                         the same simulated car from the same start): {}",
                        segments.len(),
                        listed.join("; ")
                    )
                }
                None => "the case's test on the same simulated car from the same start (the \
                         case has no results to reproduce)"
                    .to_owned(),
            },
            Drove::OtherCars => "the runs drove other simulated cars (--vary-seed): the spread \
                                 of the case's test over the simulator's noise, not a \
                                 reproduction"
                .to_owned(),
            Drove::Altered => "the case's test altered (--no-faults, another --seed or car \
                               profile): its figures need not be the case's"
                .to_owned(),
            Drove::WallClock => "the same simulated car against the wall clock: the timing \
                                 differs, so the figures need not be the case's"
                .to_owned(),
            Drove::RealCar => "on a real car: the same commands, the faults at the same places \
                               and the same seeds of the reset and the safe stop; not the same: \
                               the car's sensors and their noise, where it stands and the \
                               link's timing, so the figures need not be the case's"
                .to_owned(),
            Drove::OwnCampaign => "a case that names no campaign (written by hand): each run a \
                                   campaign of its own, nothing recorded to reproduce"
                .to_owned(),
        })
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
            simulator_seed: None,
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
        let c = Comparison::new(
            &original,
            of(false),
            original.scenario.clone(),
            &runs,
            Drove::OtherCars,
        );
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
        let c = Comparison::new(
            &original,
            of(false),
            original.scenario.clone(),
            &runs,
            Drove::OtherCars,
        );
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
        let c = Comparison::new(
            &original,
            of(true),
            original.scenario.clone(),
            &all,
            Drove::OtherCars,
        );
        assert_eq!(c.failure_disappeared, Some(true));
        assert!(c.table().contains("failure disappears"));
        let some = [run(1, &passed), run(2, &failed)];
        let c = Comparison::new(
            &original,
            of(true),
            original.scenario.clone(),
            &some,
            Drove::OtherCars,
        );
        assert_eq!(c.failure_disappeared, Some(false));
    }

    #[test]
    fn runs_of_the_same_test_reproduce_only_when_every_segment_is_the_cases_to_the_last_digit() {
        let original = case(&[1.006, 0.3], Verdict::Failed);
        let same = [run(1, &original)];
        let c = Comparison::new(
            &original,
            of(false),
            original.scenario.clone(),
            &same,
            Drove::SameTest,
        );
        let r = c.reproduction.as_ref().expect("the same test is checked");
        assert!(r.identical && r.differing.is_empty(), "{r:?}");
        assert!(
            c.table().contains("reproduced: every segment identical"),
            "{}",
            c.table()
        );
        // One ulp off in segment 0, segment 1 not driven, a segment 2 the case never drove.
        let close = case(&[f64::from_bits(1.006_f64.to_bits() + 1)], Verdict::Failed);
        let other = case(&[0.98, 0.3, 1.47], Verdict::Failed);
        let runs = [run(1, &close), run(2, &other)];
        let c = Comparison::new(
            &original,
            of(false),
            original.scenario.clone(),
            &runs,
            Drove::SameTest,
        );
        let r = c.reproduction.as_ref().unwrap();
        assert!(!r.identical);
        let listed: Vec<(usize, usize)> = r
            .differing
            .iter()
            .map(|d| (d.segment_index, d.run))
            .collect();
        assert_eq!(listed, vec![(0, 1), (0, 2), (1, 1), (2, 2)]);
        assert_eq!(r.differing[3].original_max_m, None);
        assert_eq!(r.differing[3].max_m, Some(1.47));
        let table = c.table();
        assert!(
            table.contains("not reproduced: 3 segment(s) differ")
                && table.contains("segment 0 case 1.006 m, run 2 0.980 m")
                && table.contains("segment 2 case -, run 2 1.470 m"),
            "{table}"
        );
        assert!(!table.contains("same verdict every time"), "{table}");
        assert_eq!(Comparison::from_json(&c.to_json().unwrap()).unwrap(), c);
        // Other cars are not checked against the case: their spread is the point.
        let c = Comparison::new(
            &original,
            of(false),
            original.scenario.clone(),
            &runs,
            Drove::OtherCars,
        );
        assert_eq!(c.reproduction, None);
        assert!(c.table().contains("other simulated cars"), "{}", c.table());
    }
}
