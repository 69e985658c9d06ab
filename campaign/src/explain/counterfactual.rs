//! Which of several faults made a segment fail, by a counterfactual: where two or more faults
//! moved the estimate ([`SegmentScore::needs_counterfactual`]), how far each pushed its probe does
//! not say which caused the failure (a push while the error pointed across the track, or while
//! the ranges pulled it back, grows the error little). So the case is driven again as it was and
//! once without each of those faults (a `NONE` fault in its place and slot,
//! [`crate::sweep::with_fault_silenced`], so the others act as they did), and the truth is the
//! fault whose absence lowers the segment's largest deviation most: the median over the runs of
//! the run-by-run drop ([`median_drop`]).
//!
//! The driving is the caller's: [`settle`] is given a function that drives a case its runs (on
//! fresh simulated cars, the same seeds for every variant of the case) and returns each run's
//! case with its results, in run order.

use std::collections::{BTreeMap, BTreeSet};

use super::Source;
use super::score::{FAULT_MOVED_M, FaultEffect, SegmentScore, TrueCause, is_right, truth_class};
use crate::case::Case;
use crate::sweep::with_fault_silenced;

/// Two faults whose absence lowers a segment's largest deviation by amounts this close are
/// equally its cause, metres: 2 % of the method's 1 m threshold, far below what decides a verdict.
pub const COUNTERFACTUAL_TIE_M: f64 = 0.02;

/// Settles the truth of `case`'s `scores` that need it ([`SegmentScore::needs_counterfactual`];
/// the others are left as they are): `drive` drives a case its runs and returns each run's case
/// (see the module doc); it is called for `case` as it was, then without each fault that moved
/// the estimate in one of those segments, in command order, and not at all when none needs it.
/// Each fault's effect is the [`median_drop`] of the segment without it ([`settle_by_drops`]).
pub fn settle<E>(
    case: &Case,
    scores: &mut [&mut SegmentScore],
    mut drive: impl FnMut(&Case) -> Result<Vec<Case>, E>,
) -> Result<(), E> {
    let faults: BTreeSet<usize> = scores
        .iter()
        .filter(|s| s.needs_counterfactual())
        .flat_map(|s| s.moved.iter().map(|m| m.command_index))
        .collect();
    if faults.is_empty() {
        return Ok(());
    }
    let base = drive(case)?;
    let mut without = BTreeMap::new();
    for &k in &faults {
        without.insert(k, drive(&with_fault_silenced(case, k))?);
    }
    for score in scores.iter_mut().filter(|s| s.needs_counterfactual()) {
        let drops = score
            .moved
            .iter()
            .filter_map(|m| {
                let driven = without.get(&m.command_index)?;
                Some(FaultEffect {
                    command_index: m.command_index,
                    metres: median_drop(&base, driven, score.segment_index)?,
                })
            })
            .collect();
        settle_by_drops(score, case, drops);
    }
    Ok(())
}

/// The median over the runs of how much lower segment `segment`'s largest deviation is in
/// `without` than in `base`, run by run (`None` when no run judged it in both). Of an even
/// number of runs, the upper of the two middle drops.
pub fn median_drop(base: &[Case], without: &[Case], segment: usize) -> Option<f64> {
    let max = |case: &Case| {
        case.segments
            .iter()
            .find(|s| s.segment_index == segment)
            .and_then(|s| s.oracle.stats.as_ref())
            .map(|stats| stats.max_m)
    };
    let mut drops: Vec<f64> = base
        .iter()
        .zip(without)
        .filter_map(|(a, b)| Some(max(a)? - max(b)?))
        .collect();
    drops.sort_by(f64::total_cmp);
    drops.get(drops.len() / 2).copied()
}

/// Settles which of several faults that moved the estimate is the truth by what the segment's
/// largest deviation came to without each (`drops`: how much lower it was, per fault): the one
/// whose absence lowered it most.
///
/// Faults whose absence lowered it as much, within [`COUNTERFACTUAL_TIE_M`], are each as much the
/// cause (often each alone was needed: without either the segment comes out the same), and naming
/// any of them is right. When no fault's absence lowered it by [`FAULT_MOVED_M`], none of them
/// alone made it fail and the truth stays the push's. Either way the drops (finite ones, most
/// first) are kept in [`SegmentScore::counterfactual`].
pub fn settle_by_drops(score: &mut SegmentScore, case: &Case, mut drops: Vec<FaultEffect>) {
    drops.retain(|d| d.metres.is_finite());
    drops.sort_by(|a, b| b.metres.total_cmp(&a.metres));
    if let Some(first) = drops.first().filter(|d| d.metres >= FAULT_MOVED_M) {
        score.truth = TrueCause::Fault {
            command_index: first.command_index,
        };
        score.tied_with = drops[1..]
            .iter()
            .filter(|d| first.metres - d.metres <= COUNTERFACTUAL_TIE_M)
            .map(|d| d.command_index)
            .collect();
        score.truth_class = truth_class(case, score.truth);
        score.right = is_right(score.truth, score.named)
            || score.named.is_some_and(|named| {
                score
                    .tied_with
                    .iter()
                    .any(|&command_index| named == Source::Fault { command_index })
            });
    }
    score.counterfactual = drops;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::case::SegmentResult;
    use crate::oracle::{DeviationStats, SegmentOutcome, SegmentVerdict};
    use car_link::FaultKind;
    use proptest::prelude::*;

    /// A case with wheel-slip faults 0, 1 and 2 (×1.5, ×3, ×2).
    fn three_slips() -> Case {
        let place = |command_index: usize| {
            serde_json::json!({
                "command_index": command_index, "rule": "planned", "segment_index": 0,
                "planned_along_m": 1.0, "sent_s": 1.0, "added_s": 1.0,
                "acts_from_s": 1.0, "acts_to_s": 2.0
            })
        };
        let fault = |param: f64| {
            serde_json::json!({
                "command": "add_fault", "probe": "uwb_travel_dist", "kind": "amplification",
                "param": param, "start": 0, "duration": 100
            })
        };
        let json = serde_json::json!({
            "format": "drivecheck-case", "schema_version": 2, "scenario": {"name": "s"},
            "commands": [fault(1.5), fault(3.0), fault(2.0)],
            "fault_places": [place(0), place(1), place(2)]
        });
        Case::from_json(&json.to_string()).unwrap()
    }

    /// Segment 1 of the case failed; the explanation named fault `named`; the push ranks
    /// `pushed` (command, metres) most first.
    fn score(named: usize, pushed: &[(usize, f64)]) -> SegmentScore {
        SegmentScore {
            segment_index: 1,
            named: Some(Source::Fault {
                command_index: named,
            }),
            truth: TrueCause::Fault {
                command_index: pushed[0].0,
            },
            truth_class: "wheel slip".to_owned(),
            right: named == pushed[0].0,
            moved: effects(pushed),
            counterfactual: Vec::new(),
            tied_with: Vec::new(),
        }
    }

    fn effects(pairs: &[(usize, f64)]) -> Vec<FaultEffect> {
        pairs
            .iter()
            .map(|&(command_index, metres)| FaultEffect {
                command_index,
                metres,
            })
            .collect()
    }

    /// `case` as a run wrote it: segment 1's largest deviation `max_m`.
    fn ran(case: &Case, max_m: f64) -> Case {
        let mut out = case.clone();
        out.segments = vec![SegmentResult {
            segment_index: 1,
            command_index: 0,
            faults_preceding: Vec::new(),
            faults_active: Vec::new(),
            oracle: SegmentOutcome {
                stats: Some(DeviationStats {
                    samples: 20,
                    max_m,
                    rms_m: max_m / 2.0,
                    p95_m: max_m,
                }),
                invalid_uwb_samples: 0,
                unjudged_samples: 0,
                threshold_m: 1.0,
                verdict: if max_m > 1.0 {
                    SegmentVerdict::Failed
                } else {
                    SegmentVerdict::Passed
                },
            },
        }];
        out
    }

    /// A fake drive: three runs; segment 1's largest deviation is `base` (plus 0.1 m in run 2)
    /// less `without[k]` for every fault `k` silenced. Records what it was asked to drive.
    fn fake_drive<'a>(
        base: f64,
        without: &'a [f64],
        asked: &'a mut Vec<Vec<usize>>,
    ) -> impl FnMut(&Case) -> Result<Vec<Case>, std::convert::Infallible> + 'a {
        move |case: &Case| {
            let silenced: Vec<usize> = case
                .commands
                .iter()
                .enumerate()
                .filter(|(_, c)| {
                    matches!(
                        c,
                        crate::case::CommandRecord::AddFault {
                            kind: FaultKind::None,
                            ..
                        }
                    )
                })
                .map(|(k, _)| k)
                .collect();
            let max = base - silenced.iter().map(|&k| without[k]).sum::<f64>();
            asked.push(silenced);
            Ok((0..3)
                .map(|run| ran(case, max + if run == 2 { 0.1 } else { 0.0 }))
                .collect())
        }
    }

    #[test]
    fn the_fault_whose_absence_lowers_the_deviation_most_is_the_truth() {
        let case = three_slips();
        // Fault 0 pushed more, but without fault 1 the segment comes out 1.4 m lower.
        let mut s = score(1, &[(0, 1.7), (1, 0.4)]);
        assert!(s.needs_counterfactual());
        let mut asked = Vec::new();
        settle(
            &case,
            &mut [&mut s],
            fake_drive(2.5, &[0.9, 1.4, 2.0], &mut asked),
        )
        .unwrap();
        // The case as it was, then without each fault that moved it, in command order; not
        // without fault 2, which did not move it.
        assert_eq!(asked, [vec![], vec![0], vec![1]]);
        assert_eq!(s.truth, TrueCause::Fault { command_index: 1 });
        assert!(s.right);
        let drops: Vec<(usize, f64)> = s
            .counterfactual
            .iter()
            .map(|d| (d.command_index, d.metres))
            .collect();
        assert_eq!(drops.len(), 2);
        assert_eq!((drops[0].0, drops[1].0), (1, 0));
        assert!((drops[0].1 - 1.4).abs() < 1e-9 && (drops[1].1 - 0.9).abs() < 1e-9);
        assert!(s.tied_with.is_empty());
    }

    #[test]
    fn a_segment_that_needs_no_counterfactual_drives_nothing() {
        let case = three_slips();
        let mut one = score(0, &[(0, 1.7)]);
        let before = one.clone();
        let mut asked = Vec::new();
        settle(
            &case,
            &mut [&mut one],
            fake_drive(2.5, &[0.9, 1.4, 2.0], &mut asked),
        )
        .unwrap();
        assert!(asked.is_empty());
        assert_eq!(one, before);
        // A drive that fails is the caller's error.
        let mut two = score(0, &[(0, 1.7), (2, 0.3)]);
        let failed = settle(&case, &mut [&mut two], |_: &Case| Err("no simulator"));
        assert_eq!(failed, Err("no simulator"));
    }

    #[test]
    fn faults_needed_as_much_are_each_right_and_too_small_a_drop_settles_nothing() {
        let case = three_slips();
        // Without either it comes out the same: each was needed, naming either is right.
        let mut s = score(1, &[(0, 1.7), (1, 0.4)]);
        settle_by_drops(&mut s, &case, effects(&[(0, 0.65), (1, 0.64)]));
        assert_eq!(s.truth, TrueCause::Fault { command_index: 0 });
        assert_eq!(s.tied_with, [1]);
        assert!(s.right);
        // Neither's absence changes it: not settled, the push's truth stays.
        let mut s = score(1, &[(0, 1.7), (1, 0.4)]);
        settle_by_drops(&mut s, &case, effects(&[(0, 0.0), (1, 0.01)]));
        assert_eq!(s.truth, TrueCause::Fault { command_index: 0 });
        assert!(!s.right);
        assert_eq!(s.counterfactual.len(), 2);
        // A drop that is not a number is left out.
        let mut s = score(1, &[(0, 1.7), (1, 0.4)]);
        settle_by_drops(&mut s, &case, effects(&[(0, f64::NAN), (1, 0.3)]));
        assert_eq!(s.truth, TrueCause::Fault { command_index: 1 });
        assert_eq!(s.counterfactual, effects(&[(1, 0.3)]));
    }

    #[test]
    fn the_median_drop_is_run_by_run() {
        let case = three_slips();
        let base: Vec<Case> = [2.0, 3.0, 1.5].iter().map(|&m| ran(&case, m)).collect();
        let without: Vec<Case> = [1.0, 2.9, 1.0].iter().map(|&m| ran(&case, m)).collect();
        // Drops 1.0, 0.1, 0.5: the median is 0.5.
        let drop = median_drop(&base, &without, 1).unwrap();
        assert!((drop - 0.5).abs() < 1e-12, "{drop}");
        // No run judged segment 4.
        assert_eq!(median_drop(&base, &without, 4), None);
        assert_eq!(median_drop(&[], &[], 1), None);
    }

    proptest! {
        /// Whatever the drops, the truth is the push's or the fault whose absence lowered the
        /// deviation most; every tie is within the tie of it; the drops kept are finite and most
        /// first; and naming the truth is right.
        #[test]
        fn a_settled_truth_is_the_largest_drop_and_its_ties(
            drops in prop::collection::vec(
                (0usize..3, prop_oneof![Just(f64::NAN), -1.0f64..2.0]), 0..4),
            named in 0usize..3,
        ) {
            let case = three_slips();
            let mut s = score(named, &[(0, 1.7), (1, 0.4)]);
            settle_by_drops(&mut s, &case, effects(&drops));
            prop_assert!(s.counterfactual.iter().all(|d| d.metres.is_finite()));
            prop_assert!(s.counterfactual.windows(2).all(|w| w[0].metres >= w[1].metres));
            match s.counterfactual.first() {
                Some(first) if first.metres >= FAULT_MOVED_M => {
                    prop_assert_eq!(s.truth, TrueCause::Fault { command_index: first.command_index });
                    for k in &s.tied_with {
                        let tie = s.counterfactual[1..].iter().find(|d| d.command_index == *k);
                        prop_assert!(tie.is_some_and(|d| first.metres - d.metres <= COUNTERFACTUAL_TIE_M));
                    }
                }
                _ => {
                    prop_assert_eq!(s.truth, TrueCause::Fault { command_index: 0 });
                    prop_assert!(s.tied_with.is_empty());
                }
            }
            if s.truth == (TrueCause::Fault { command_index: named }) {
                prop_assert!(s.right);
            }
        }
    }
}
