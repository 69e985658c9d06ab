//! How far a simulated car can be trusted: a recorded case against the same case driven again on
//! a simulated car (`drivecheck twin check`, `docs/twin.md`).
//!
//! Per segment the recorded largest deviation is set against the simulated runs' (their median)
//! and the recorded verdict against each run's. Over a campaign: the share of (segment, run)
//! verdicts that agree with the recording and the median and p90 of |recorded − simulated
//! median|. Only segments the recording and a run both drove with judged samples count: a run
//! that stopped at an earlier failing segment says nothing of the later ones. Pure: the driving is
//! the caller's.

use trajgen::stats::nearest_rank;

/// The file a twin check writes into the run directory it checked.
pub const TWIN_FILE: &str = "twin.json";

use crate::files::{Case, TwinSegment, TwinSummary};
use crate::oracle::SegmentVerdict;

/// The largest deviation and verdict of each segment of `case` that was judged, by segment index.
fn judged(case: &Case) -> Vec<(usize, f64, SegmentVerdict)> {
    case.segments
        .iter()
        .filter_map(|s| {
            let stats = s.oracle.stats?;
            (s.oracle.verdict != SegmentVerdict::NoSamples).then_some((
                s.segment_index,
                stats.max_m,
                s.oracle.verdict,
            ))
        })
        .collect()
}

/// The median of `values` (the mean of the two middle ones for an even count); `None` for none.
fn median(values: &[f64]) -> Option<f64> {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(sorted[n / 2]),
        _ => Some((sorted[n / 2 - 1] + sorted[n / 2]) / 2.0),
    }
}

/// Each segment of `recorded` set against the `simulated` runs of the same case (`test_index`
/// names the case in the result).
pub fn compare_case(test_index: usize, recorded: &Case, simulated: &[Case]) -> Vec<TwinSegment> {
    let runs: Vec<Vec<(usize, f64, SegmentVerdict)>> = simulated.iter().map(judged).collect();
    judged(recorded)
        .into_iter()
        .filter_map(|(segment_index, recorded_max_m, verdict)| {
            let driven: Vec<(f64, SegmentVerdict)> = runs
                .iter()
                .filter_map(|run| {
                    run.iter()
                        .find(|(i, _, _)| *i == segment_index)
                        .map(|&(_, m, v)| (m, v))
                })
                .collect();
            let maxima: Vec<f64> = driven.iter().map(|&(m, _)| m).collect();
            let simulated_median_m = median(&maxima)?;
            Some(TwinSegment {
                test_index,
                segment_index,
                recorded_max_m,
                recorded_failed: verdict == SegmentVerdict::Failed,
                simulated_max_m: maxima,
                simulated_median_m,
                runs_agreeing: driven.iter().filter(|&&(_, v)| v == verdict).count(),
            })
        })
        .collect()
}

/// The agreement over `segments`.
pub fn summarise(segments: &[TwinSegment]) -> TwinSummary {
    let runs: usize = segments.iter().map(|s| s.simulated_max_m.len()).sum();
    let agreeing: usize = segments.iter().map(|s| s.runs_agreeing).sum();
    let mut deltas: Vec<f64> = segments
        .iter()
        .map(|s| (s.recorded_max_m - s.simulated_median_m).abs())
        .collect();
    deltas.sort_by(f64::total_cmp);
    TwinSummary {
        segments: segments.len(),
        segment_runs: runs,
        verdicts_agreed: if runs == 0 {
            None
        } else {
            Some(agreeing as f64 / runs as f64)
        },
        median_abs_delta_m: median(&deltas),
        p90_abs_delta_m: nearest_rank(&deltas, 0.9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::files::tests::case_with_segments;

    #[test]
    fn agreement_counts_runs_per_segment_and_skips_what_a_run_did_not_drive() {
        // Recorded: segment 0 passed at 0.4 m, segment 1 failed at 1.3 m.
        let recorded = case_with_segments(&[0.4, 1.3]);
        // Run A agrees on both (0.5, 1.1); run B failed early at segment 0 (1.2) and never drove 1.
        let a = case_with_segments(&[0.5, 1.1]);
        let b = case_with_segments(&[1.2]);
        let segments = compare_case(7, &recorded, &[a, b]);
        assert_eq!(segments.len(), 2);
        assert_eq!(segments[0].simulated_max_m, vec![0.5, 1.2]);
        assert_eq!(segments[0].runs_agreeing, 1);
        assert!((segments[0].simulated_median_m - 0.85).abs() < 1e-12);
        assert_eq!(segments[1].simulated_max_m, vec![1.1]);
        assert_eq!(segments[1].runs_agreeing, 1);
        let summary = summarise(&segments);
        assert_eq!(summary.segment_runs, 3);
        assert!((summary.verdicts_agreed.unwrap() - 2.0 / 3.0).abs() < 1e-12);
        // |0.4 − 0.85| = 0.45 and |1.3 − 1.1| = 0.2: median 0.325, p90 0.45.
        assert!((summary.median_abs_delta_m.unwrap() - 0.325).abs() < 1e-12);
        assert!((summary.p90_abs_delta_m.unwrap() - 0.45).abs() < 1e-12);
    }

    #[test]
    fn nothing_to_compare_gives_no_figures() {
        let summary = summarise(&compare_case(0, &case_with_segments(&[0.4]), &[]));
        assert_eq!(summary.segments, 0);
        assert_eq!(summary.verdicts_agreed, None);
        assert_eq!(summary.median_abs_delta_m, None);
    }
}
