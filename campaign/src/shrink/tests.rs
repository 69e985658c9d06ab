use proptest::prelude::*;

use super::policy::{Drive, ShrinkFailure, shrink};
use super::*;
use crate::files::tests::scenario;
use crate::model::{Campaign, FaultKind, Probe, plan_test, start_tail};
use crate::oracle::FailurePolicy;

/// A generated test of the two-anchor lot (test `index` of a 10-test campaign with `seed`).
fn generated(seed: u64, index: usize) -> (Scenario, Case) {
    let s = scenario("parking-lot-2anchors");
    let campaign = Campaign {
        seed,
        tests: 10,
        no_faults: false,
    };
    let plan = plan_test(&s, &campaign, index, start_tail(&s).unwrap()).unwrap();
    let settings = crate::files::Settings::new(&s, 10, FailurePolicy::default());
    let case = Case::planned(&plan, &s, seed, false, settings);
    (s, case)
}

/// Every segment of `case` has its ahead margin and, with it, continues the route drivably from
/// the start route.
fn drivable(case: &Case, s: &Scenario) -> bool {
    let margins = case.commands.iter().all(|c| match c {
        CommandRecord::RunSegments { margin, .. } => !margin.is_empty(),
        CommandRecord::AddFault { .. } => true,
    });
    margins && case.check_route(s).is_ok()
}

/// A stand-in for the simulator: the case fails at its `target`-th segment when it still has a
/// range fault on anchor 234 with a parameter of at least `threshold` (and enough segments),
/// otherwise passes.
fn fake_run(case: &Case, target: Target, threshold: f64, seed: u64) -> RunResult {
    let target = target.first;
    let segments = segment_commands(case).len();
    let strong = case.commands.iter().any(|c| {
        matches!(c, CommandRecord::AddFault { probe: Probe::UwbRange(234), param, .. } if *param >= threshold)
    });
    let fails = strong && segments > target;
    RunResult {
        seed,
        verdict: Some(if fails {
            Verdict::Failed
        } else {
            Verdict::Passed
        }),
        first_failing_segment: fails.then_some(target),
        max_deviation_m: Some(if fails { 1.5 } else { 0.5 }),
    }
}

/// Shrinks with the stand-in; the kept target follows the failing segment as edits move it.
fn shrink_with_fake(
    case: &Case,
    s: &Scenario,
    target: usize,
    threshold: f64,
) -> (Case, usize, Vec<Step>) {
    let mut shrinker = Shrinker::new(case, s, Target::segment(target), 7).unwrap();
    let mut guard = 0;
    while let Some(candidate) = shrinker.next_candidate() {
        assert!(drivable(&candidate.case, s), "{}", candidate.edit);
        // The failure "lives" in the candidate's target segment: the fake fails there.
        let runs = (0..3)
            .map(|k| fake_run(&candidate.case, candidate.target, threshold, k))
            .collect();
        shrinker.record(candidate, runs);
        guard += 1;
        assert!(guard < 2000, "the shrink does not end");
    }
    (
        shrinker.current().clone(),
        shrinker.target().first,
        shrinker.steps().to_vec(),
    )
}

fn with_strong_fault(mut case: Case) -> Case {
    // A strong reflection on anchor 234 after the second segment, placed at its start.
    let second = segment_commands(&case)[1];
    case.commands.insert(
        second + 1,
        CommandRecord::AddFault {
            probe: Probe::UwbRange(234),
            kind: FaultKind::Amplification,
            param: 4.0,
            start: 12,
            duration: 9,
            at: Some(crate::files::PlaceRecord {
                segment_index: 1,
                along_m: 0.5,
            }),
        },
    );
    case
}

#[test]
fn a_failure_that_needs_one_fault_shrinks_to_that_fault_and_the_failing_segment() {
    let (s, case) = generated(3, 9);
    let case = with_strong_fault(case);
    let segments = segment_commands(&case).len();
    assert!(segments >= 4, "a long test: {segments} segments");
    let target = segments - 2;
    let (minimal, minimal_target, steps) = shrink_with_fake(&case, &s, target, 2.0);
    let size = Size::of(&minimal);
    // One fault left, its parameter shrunk as far as the failure allows, start and duration to
    // neutral.
    assert_eq!(size.faults, 1, "{minimal:?}");
    let fault = minimal
        .commands
        .iter()
        .find_map(|c| match c {
            CommandRecord::AddFault {
                param,
                start,
                duration,
                ..
            } => Some((*param, *start, *duration)),
            CommandRecord::RunSegments { .. } => None,
        })
        .unwrap();
    assert!((2.0..2.5).contains(&fault.0), "{fault:?}");
    assert_eq!((fault.1, fault.2), (0, 1));
    // The segments before the target were joined away and the tail cut: one segment is left.
    assert_eq!(size.segments, minimal_target + 1);
    assert!(size.segments <= 2, "{size:?}: {steps:#?}");
    assert!(drivable(&minimal, &s));
    assert!(
        steps
            .iter()
            .any(|s| s.outcome == Outcome::Kept && matches!(s.edit, Edit::CutTail { .. }))
    );
    assert!(
        steps
            .iter()
            .any(|s| s.outcome == Outcome::Kept && matches!(s.edit, Edit::DropSegments { .. }))
    );
    // Deterministic: the same shrink again gives the same steps.
    let again = shrink_with_fake(&case, &s, target, 2.0);
    assert_eq!(again.2, steps);
}

#[test]
fn a_failure_without_faults_loses_them_all() {
    let (s, case) = generated(5, 8);
    let faults = Size::of(&case).faults;
    assert!(faults >= 2, "{faults}");
    let target = segment_commands(&case).len() - 1;
    let mut shrinker = Shrinker::new(&case, &s, Target::segment(target), 1).unwrap();
    let mut tried = 0;
    while let Some(candidate) = shrinker.next_candidate() {
        let run = RunResult {
            seed: 0,
            verdict: Some(Verdict::Failed),
            first_failing_segment: Some(candidate.target.first),
            max_deviation_m: Some(1.2),
        };
        shrinker.record(candidate, vec![run]);
        tried += 1;
    }
    // Every fault went in one step, right after the tail was cut (nothing was after the target).
    assert!(
        matches!(shrinker.steps()[0].edit, Edit::DropAllFaults { .. }),
        "{:?}",
        shrinker.steps()[0]
    );
    let size = Size::of(shrinker.current());
    assert_eq!((size.faults, size.segments), (0, 1), "{tried} steps");
}

#[test]
fn a_candidate_is_kept_only_when_every_run_fails_at_its_target() {
    let run = |verdict, segment| RunResult {
        seed: 0,
        verdict: Some(verdict),
        first_failing_segment: segment,
        max_deviation_m: None,
    };
    let failed = run(Verdict::Failed, Some(2));
    let two = Target::segment(2);
    assert_eq!(
        Outcome::of(&[failed, failed, failed], two, 0.0),
        Outcome::Kept
    );
    assert_eq!(
        Outcome::of(&[failed, run(Verdict::Passed, None)], two, 0.0),
        Outcome::Passed
    );
    assert_eq!(
        Outcome::of(&[failed, run(Verdict::Failed, Some(1))], two, 0.0),
        Outcome::FailedElsewhere
    );
    assert_eq!(
        Outcome::of(&[run(Verdict::Aborted, None)], two, 0.0),
        Outcome::Aborted
    );
    assert_eq!(Outcome::of(&[], two, 0.0), Outcome::Aborted);
    // With a margin: a run that failed by too little keeps nothing.
    let by = |m: f64| RunResult {
        max_deviation_m: Some(m),
        ..failed
    };
    assert_eq!(Outcome::of(&[by(1.3), by(1.2)], two, 1.1), Outcome::Kept);
    assert_eq!(
        Outcome::of(&[by(1.3), by(1.05)], two, 1.1),
        Outcome::FailedBarely
    );
    // A target of two neighbours: either may fail first.
    let first = |segment| run(Verdict::Failed, Some(segment));
    let pair = Target { first: 2, last: 3 };
    assert_eq!(Outcome::of(&[first(2), first(3)], pair, 0.0), Outcome::Kept);
    assert_eq!(
        Outcome::of(&[first(2), first(4)], pair, 0.0),
        Outcome::FailedElsewhere
    );
    assert_eq!(Target::of_runs(&[first(3), first(2), first(3)]), Some(pair));
    assert_eq!(Target::of_runs(&[first(2), first(4)]), None);
    assert_eq!(
        Target::of_runs(&[first(2), run(Verdict::Passed, None)]),
        None
    );
    assert_eq!(Target::of_runs(&[]), None);
}

#[test]
fn a_target_beyond_the_segments_is_refused() {
    let (s, case) = generated(1, 5);
    let segments = segment_commands(&case).len();
    let error = Shrinker::new(&case, &s, Target::segment(segments), 1).unwrap_err();
    assert!(error.to_string().contains("not among"), "{error}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    /// Whatever the runs say, every candidate the shrinker proposes is drivable with its ahead
    /// margins and its faults can act, and the shrink ends with a case no larger than the start.
    #[test]
    fn every_candidate_is_drivable_and_the_shrink_ends(
        seed in 0u64..1000,
        index in 4usize..10,
        verdicts in proptest::collection::vec(any::<bool>(), 64),
    ) {
        let (s, case) = generated(seed, index);
        let segments = segment_commands(&case).len();
        let target = segments / 2;
        let before = Size::of(&case);
        let mut shrinker = Shrinker::new(&case, &s, Target::segment(target), seed).unwrap();
        let mut step = 0;
        while let Some(candidate) = shrinker.next_candidate() {
            prop_assert!(drivable(&candidate.case, &s), "{}", candidate.edit);
            prop_assert!(candidate.case.check_faults_act(&s).is_ok());
            let fails = verdicts[step % verdicts.len()];
            let run = RunResult {
                seed: 0,
                verdict: Some(if fails { Verdict::Failed } else { Verdict::Passed }),
                first_failing_segment: fails.then_some(candidate.target.first),
                max_deviation_m: None,
            };
            shrinker.record(candidate, vec![run]);
            step += 1;
            prop_assert!(step < 3000);
        }
        let after = Size::of(shrinker.current());
        prop_assert!(after.commands <= before.commands);
        prop_assert!(shrinker.target().last < after.segments);
    }
}

/// A stand-in for the simulated car behind the shrink's policy: a run fails at the case's last
/// segment (by 1.5 m against a 1 m threshold) when `fails(param, run)` says so for the
/// parameter of its fault on anchor 234 (none: 0) and the run (seed − `base`), else passes.
struct FakeCar<F> {
    base: u64,
    fails: F,
    /// The runs driven: (run, commands of the case).
    driven: Vec<(u64, usize)>,
    /// Stop before a candidate once this many runs were driven.
    stop_after: Option<(usize, Ended)>,
}

impl<F: Fn(f64, u64) -> bool> FakeCar<F> {
    fn new(base: u64, fails: F) -> Self {
        Self {
            base,
            fails,
            driven: Vec::new(),
            stop_after: None,
        }
    }
}

/// The largest parameter of the case's faults on anchor 234 (0 without one).
fn fault_param(case: &Case) -> f64 {
    case.commands
        .iter()
        .filter_map(|c| match c {
            CommandRecord::AddFault {
                probe: Probe::UwbRange(234),
                param,
                ..
            } => Some(*param),
            _ => None,
        })
        .fold(0.0, f64::max)
}

impl<F: Fn(f64, u64) -> bool> Drive for FakeCar<F> {
    type Error = String;

    fn drive(&mut self, case: &Case, seed: u64) -> Result<Case, String> {
        use crate::files::SegmentResult;
        use crate::oracle::{DeviationStats, SegmentOutcome};
        let run = seed - self.base;
        self.driven.push((run, case.commands.len()));
        let segments = segment_commands(case);
        let fails = (self.fails)(fault_param(case), run);
        let mut driven = case.clone();
        driven.segments = segments
            .iter()
            .enumerate()
            .map(|(segment_index, &command_index)| {
                let failed = fails && segment_index + 1 == segments.len();
                let max_m = if failed { 1.5 } else { 0.5 };
                SegmentResult {
                    segment_index,
                    command_index,
                    faults_preceding: Vec::new(),
                    faults_active: Vec::new(),
                    oracle: SegmentOutcome {
                        stats: Some(DeviationStats {
                            samples: 10,
                            max_m,
                            rms_m: max_m / 2.0,
                            p95_m: max_m,
                        }),
                        invalid_uwb_samples: 0,
                        unjudged_samples: 0,
                        threshold_m: 1.0,
                        verdict: if failed {
                            SegmentVerdict::Failed
                        } else {
                            SegmentVerdict::Passed
                        },
                    },
                }
            })
            .collect();
        driven.verdict = Some(if fails {
            Verdict::Failed
        } else {
            Verdict::Passed
        });
        Ok(driven)
    }

    fn stop(&mut self) -> Option<Ended> {
        self.stop_after
            .and_then(|(runs, ended)| (self.driven.len() >= runs).then_some(ended))
    }
}

/// A long generated test with a strong fault, and the shrink's settings for it.
fn strong_case() -> (Scenario, Case, Settings) {
    let (s, case) = generated(3, 9);
    let settings = Settings {
        runs: 3,
        seed: 40,
        test_index: None,
        margin_m: 0.1,
    };
    (s, with_strong_fault(case), settings)
}

#[test]
fn the_policy_keeps_a_candidate_only_when_every_run_fails_and_stops_at_the_first_that_does_not() {
    let (s, case, settings) = strong_case();
    // Strong enough (≥ 2) fails in every run; between 1 and 2 only in the first run.
    let mut car = FakeCar::new(40, |param, run| param >= 2.0 || (param >= 1.0 && run == 0));
    let shrunk = shrink(&case, &s, &settings, &mut car).unwrap();
    assert_eq!(shrunk.ended, Ended::Minimal);
    let param = fault_param(&shrunk.minimal);
    assert!((2.0..2.5).contains(&param), "{param}");
    // A kept candidate failed in all of its runs; one that passed in its second run was driven
    // no further.
    for step in shrunk.steps.iter().filter(|s| s.outcome == Outcome::Kept) {
        assert_eq!(step.runs.len(), 3, "{step:?}");
        assert!(step.runs.iter().all(|r| r.fails_at(step.target)));
    }
    let sometimes = shrunk
        .steps
        .iter()
        .filter(|s| s.outcome == Outcome::Passed && s.runs.len() == 2)
        .count();
    assert!(sometimes > 0, "{:#?}", shrunk.steps);
    assert!(shrunk.steps.iter().all(|s| s.runs.len() <= 3));
    // Runs 0–2 of every candidate have seeds 40–42; the confirmation 43–48.
    let seeds: Vec<u64> = shrunk.before.runs.iter().map(|r| r.seed).collect();
    assert_eq!(seeds, [40, 41, 42]);
    let confirmation = shrunk.confirmation.as_ref().unwrap();
    let seeds: Vec<u64> = confirmation.runs.iter().map(|r| r.seed).collect();
    assert_eq!(seeds, [43, 44, 45, 46, 47, 48]);
    assert_eq!((confirmation.failed, confirmation.stepped_back), (6, 0));
    assert!(confirmation.confirmed && confirmation.case_failed.is_none());
    // Without its fault the minimal case passes.
    let bare = shrunk.without_faults.as_ref().unwrap();
    assert!(bare.iter().all(|r| r.verdict == Some(Verdict::Passed)));
    assert_eq!(shrunk.runs_driven, car.driven.len());
    assert_eq!(shrunk.minimal.campaign_seed, case.campaign_seed);
    assert_eq!(shrunk.after.size, Size::of(&shrunk.minimal));
    assert_eq!(shrunk.min_deviation_m, 1.1);
}

#[test]
fn a_kept_case_that_fails_only_with_the_shrinks_own_seeds_is_stepped_back() {
    let (s, case, settings) = strong_case();
    // Between 2 and 3 the fault fails with the candidates' seeds (runs 0–2) only; 3 and more
    // always.
    let mut car = FakeCar::new(40, |param, run| param >= 3.0 || (param >= 2.0 && run < 3));
    let shrunk = shrink(&case, &s, &settings, &mut car).unwrap();
    let kept_weak = shrunk.steps.iter().any(|s| {
        s.outcome == Outcome::Kept && matches!(s.edit, Edit::FaultValue { to, .. } if to < 3.0)
    });
    assert!(kept_weak, "{:#?}", shrunk.steps);
    let confirmation = shrunk.confirmation.as_ref().unwrap();
    assert!(confirmation.stepped_back >= 1, "{confirmation:?}");
    // The case itself fails with every confirming seed, so the minimal case must as well.
    assert_eq!(confirmation.case_failed, Some(6));
    assert_eq!(confirmation.failed, 6);
    assert!(confirmation.confirmed);
    assert!(fault_param(&shrunk.minimal) >= 3.0, "{:?}", shrunk.minimal);
    assert_eq!(shrunk.after.runs.len(), 3);
}

#[test]
fn a_case_that_does_not_fail_in_every_run_is_not_shrunk() {
    let (s, case, settings) = strong_case();
    let mut car = FakeCar::new(40, |_, run| run != 1);
    match shrink(&case, &s, &settings, &mut car) {
        Err(failure @ ShrinkFailure::NotReproducible { .. }) => {
            let text = failure.to_string();
            assert!(text.contains("seed 41: passed;"), "{text}");
            assert!(text.contains("seed 40: failed at segment"), "{text}");
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(car.driven.len(), 3);
}

#[test]
fn the_driver_stops_the_shrink_between_candidates() {
    let (s, case, settings) = strong_case();
    let mut car = FakeCar::new(40, |param, _| param >= 2.0);
    car.stop_after = Some((7, Ended::Budget));
    let shrunk = shrink(&case, &s, &settings, &mut car).unwrap();
    assert_eq!(shrunk.ended, Ended::Budget);
    // Candidates were driven until 7 runs were, not one more; then the confirmation (6 runs,
    // all failing); no runs without faults, as the case is not minimal.
    let runs: Vec<usize> = shrunk.steps.iter().map(|s| s.runs.len()).collect();
    let candidates: usize = runs.iter().sum();
    let last = runs.iter().rev().find(|&&n| n > 0).copied().unwrap_or(0);
    assert!(3 + candidates >= 7 && 3 + candidates - last < 7, "{runs:?}");
    let confirmation = shrunk.confirmation.as_ref().unwrap();
    assert_eq!((confirmation.failed, confirmation.runs.len()), (6, 6));
    assert!(shrunk.without_faults.is_none());
    assert_eq!(car.driven.len(), 3 + candidates + 6);
    assert_eq!(shrunk.runs_driven, car.driven.len());
    // Interrupted: nothing more is driven, not even the confirmation.
    let mut car = FakeCar::new(40, |param, _| param >= 2.0);
    car.stop_after = Some((3, Ended::Interrupted));
    let shrunk = shrink(&case, &s, &settings, &mut car).unwrap();
    assert_eq!(shrunk.ended, Ended::Interrupted);
    assert!(shrunk.steps.iter().all(|s| s.runs.is_empty()));
    assert!(shrunk.confirmation.is_none() && shrunk.without_faults.is_none());
    assert_eq!(car.driven.len(), 3);
    assert_eq!(fault_param(&shrunk.minimal), fault_param(&case));
}
