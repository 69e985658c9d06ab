use proptest::prelude::*;

use super::*;
use crate::files::tests::doc_examples;

const RANGE_OFFSET: FaultKey = FaultKey {
    probe: Probe::UwbRange(234),
    kind: FaultKind::Offset,
};
const YAW_OFFSET: FaultKey = FaultKey {
    probe: Probe::UwbYaw,
    kind: FaultKind::Offset,
};

fn recorded() -> Case {
    let mut case = Case::from_json(doc_examples()[1]).unwrap();
    let fault = case
        .commands
        .iter()
        .position(|c| matches!(c, CommandRecord::AddFault { .. }))
        .expect("the recorded example has a fault");
    for s in &mut case.segments {
        s.faults_active = vec![fault];
    }
    case
}

fn segment(
    test_index: usize,
    segment_index: usize,
    base: f64,
    new: f64,
    faults: &[FaultKey],
) -> PairedSegment {
    let verdict = |m: f64| {
        if m <= 1.0 {
            SegmentVerdict::Passed
        } else {
            SegmentVerdict::Failed
        }
    };
    PairedSegment {
        test_index,
        segment_index,
        base_verdict: verdict(base),
        new_verdict: verdict(new),
        base_max_m: Some(base),
        new_max_m: Some(new),
        faults: faults.to_vec(),
        speed_mps: Some(1.0 + segment_index as f64),
        route: vec![
            [test_index as f64 * 3.0, 0.0],
            [test_index as f64 * 3.0 + 2.0, 1.0],
        ],
    }
}

/// Tests whose segments have (BASE, NEW) largest deviations `pairs` each.
fn paired(tests: &[Vec<(f64, f64, &[FaultKey])>]) -> Paired {
    Paired {
        tests: tests
            .iter()
            .enumerate()
            .map(|(t, segs)| {
                let segments: Vec<PairedSegment> = segs
                    .iter()
                    .enumerate()
                    .map(|(i, &(b, n, f))| segment(t, i, b, n, f))
                    .collect();
                let verdict = |ok: bool| Some(if ok { Verdict::Passed } else { Verdict::Failed });
                PairedTest {
                    test_index: t,
                    base_verdict: verdict(segments.iter().all(|s| s.base_max_m <= Some(1.0))),
                    new_verdict: verdict(segments.iter().all(|s| s.new_max_m <= Some(1.0))),
                    segments,
                    only_base: 0,
                    only_new: 0,
                }
            })
            .collect(),
    }
}

#[test]
fn a_case_becomes_a_small_row() {
    let case = recorded();
    let row = TestRow::of(&case, 77);
    assert_eq!(row.test_index, 1);
    assert_eq!(row.commands.len(), case.commands.len());
    assert_eq!(row.segments.len(), case.segments.len());
    assert!(row.scenario.starts_with("parking-lot-2anchors (1601eca5"));
    let first = &row.segments[0];
    assert_eq!(first.faults.len(), 1);
    assert!(first.speed_mps.is_some_and(|v| v > 0.0));
    let CommandRecord::RunSegments { points, .. } = &case.commands[case.segments[0].command_index]
    else {
        panic!("a segment's command drives");
    };
    assert_eq!(first.route.len(), points.len());
    // The second segment starts where the first ended.
    if let Some(second) = row.segments.get(1) {
        assert_eq!(second.route[0], *first.route.last().unwrap());
    }
}

#[test]
fn the_digest_ignores_what_is_not_driven_and_sees_what_is() {
    let case = recorded();
    let i = case.segments[0].command_index;
    let mut other = case.commands[i].clone();
    if let CommandRecord::RunSegments { intent, margin, .. } = &mut other {
        *intent = None;
        margin.clear();
    }
    assert_eq!(
        CommandDigest::of(&other).digest,
        CommandDigest::of(&case.commands[i]).digest
    );
    if let CommandRecord::RunSegments { points, .. } = &mut other {
        points[0].speed += 0.01;
    }
    assert_ne!(
        CommandDigest::of(&other).digest,
        CommandDigest::of(&case.commands[i]).digest
    );
}

#[test]
fn the_same_tests_pair_and_other_tests_are_refused_at_the_first_difference() {
    let case = recorded();
    let row = |index: usize| {
        let mut c = case.clone();
        c.test_index = Some(index);
        TestRow::of(&c, index)
    };
    let both = pair(vec![row(0), row(1)], vec![row(1), row(0)]).unwrap();
    assert_eq!(both.tests.len(), 2);
    assert_eq!(both.tests[0].segments.len(), case.segments.len());
    assert!(
        both.segments()
            .all(|s| s.change_m() == Some(0.0) && !s.regressed() && !s.fixed())
    );

    assert_eq!(
        pair(vec![row(0), row(1), row(3)], vec![row(0), row(2), row(3)]),
        Err(PairError::Missing {
            test_index: 1,
            present: Run::Base,
            missing: Run::New
        })
    );
    assert_eq!(
        pair(vec![row(0), row(2)], vec![row(0), row(1), row(2)]),
        Err(PairError::Missing {
            test_index: 1,
            present: Run::New,
            missing: Run::Base
        })
    );
    assert_eq!(
        pair(vec![row(0)], vec![row(0), row(5)]),
        Err(PairError::Missing {
            test_index: 5,
            present: Run::New,
            missing: Run::Base
        })
    );
    assert_eq!(
        pair(vec![row(0), row(0)], vec![row(0)]),
        Err(PairError::Duplicate {
            run: Run::Base,
            test_index: 0
        })
    );
    assert_eq!(pair(vec![], vec![]), Err(PairError::NoTests));

    // A fault's parameter changed in command 3 of test 1.
    let fault = case
        .commands
        .iter()
        .position(|c| matches!(c, CommandRecord::AddFault { .. }))
        .unwrap();
    let mut changed = case.clone();
    if let CommandRecord::AddFault { param, .. } = &mut changed.commands[fault] {
        *param += 0.5;
    }
    let error = pair(vec![row(0), row(1)], vec![row(0), TestRow::of(&changed, 1)]).unwrap_err();
    assert!(
        matches!(error, PairError::Command { test_index: 1, command_index, .. } if command_index == fault),
        "{error:?}"
    );
    assert!(error.to_string().contains("(other values)"), "{error}");

    // NEW has a command more.
    let mut longer = case.clone();
    longer.commands.push(case.commands[fault].clone());
    let error = pair(vec![row(1)], vec![TestRow::of(&longer, 1)]).unwrap_err();
    assert_eq!(
        error.to_string(),
        format!(
            "test 1, command {} differs: BASE none (it has no more commands), NEW add_fault {}",
            case.commands.len(),
            CommandDigest::of(&case.commands[fault])
                .what
                .to_string()
                .trim_start_matches("add_fault ")
        )
    );

    let mut elsewhere = case.clone();
    elsewhere.scenario.hash = Some("00".to_owned());
    let error = pair(vec![row(1)], vec![TestRow::of(&elsewhere, 1)]).unwrap_err();
    assert!(
        matches!(error, PairError::Scenario { test_index: 1, .. }),
        "{error:?}"
    );
}

#[test]
fn segments_driven_in_one_run_only_are_counted_not_paired() {
    let case = recorded();
    let mut shorter = case.clone();
    shorter.segments.pop();
    let p = pair(vec![TestRow::of(&case, 1)], vec![TestRow::of(&shorter, 1)]).unwrap();
    assert_eq!(p.tests[0].only_base, 1);
    assert_eq!(p.tests[0].only_new, 0);
    assert_eq!(p.tests[0].segments.len(), case.segments.len() - 1);
    let report = compare(&p, &Options::with_noise(0.2)).unwrap();
    assert_eq!(report.segments.only_base, 1);
    assert_eq!(report.segments.paired, case.segments.len() - 1);
}

#[test]
fn identical_runs_are_no_difference() {
    let rows: Vec<Vec<(f64, f64, &[FaultKey])>> = (0..30)
        .map(|t| {
            (0..4)
                .map(|s| {
                    let m = 0.3 + 0.1 * ((t * 7 + s) % 9) as f64;
                    (m, m, &[][..])
                })
                .collect()
        })
        .collect();
    let report = compare(&paired(&rows), &Options::with_noise(0.2)).unwrap();
    assert_eq!(report.significance, Significance::NoDifference);
    assert_eq!(report.mcnemar.p, 1.0);
    let m = report.median_change.unwrap();
    assert_eq!((m.median_m, m.ci95_m, m.p), (0.0, [0.0, 0.0], 1.0));
    assert_eq!(report.segments.worse + report.segments.better, 0);
    assert_eq!(
        report.verdict,
        "no significant difference at 0.05: NEW fails 0 tests that BASE passed and fixes 0 \
         (McNemar p = 1.000); a segment's largest deviation did not change (median; 95 % CI \
         +0.000 to +0.000 m; sign-flip p = 1.000)"
    );
}

#[test]
fn a_regression_under_range_faults_is_found_and_located() {
    // 40 tests: segments under a range offset get 0.4 m worse (half of them then fail); the
    // others change by a little noise either way.
    let rows: Vec<Vec<(f64, f64, &[FaultKey])>> = (0..40)
        .map(|t| {
            let wobble = 0.02 * (((t * 13) % 5) as f64 - 2.0);
            vec![
                (0.4, 0.4 + wobble, &[][..]),
                (
                    0.5 + 0.01 * (t % 2) as f64,
                    0.9 + 0.2 * (t % 2) as f64,
                    &[RANGE_OFFSET][..],
                ),
                (0.6, 0.6 - wobble, &[YAW_OFFSET][..]),
                (0.3, 0.7, &[RANGE_OFFSET, YAW_OFFSET][..]),
            ]
        })
        .collect();
    let report = compare(&paired(&rows), &Options::with_noise(0.2)).unwrap();
    assert_eq!(report.tests.regressed, 20);
    assert_eq!(report.tests.fixed, 0);
    assert!(report.mcnemar.p < 1e-5);
    assert!(report.evidence.verdicts_worse && !report.evidence.verdicts_better);
    assert_eq!(report.significance, Significance::Worse);
    assert!(
        report
            .verdict
            .starts_with("NEW is significantly worse at 0.05: NEW fails 20 tests")
    );
    let first = &report.breakdowns.by_fault[0];
    assert_eq!(first.key, "uwb_range_234 offset");
    assert_eq!((first.segments, first.worse, first.regressed), (80, 80, 20));
    assert_eq!(report.breakdowns.by_fault.last().unwrap().key, "none");
    assert_eq!(report.segments.worse, 80);
    assert!(report.segments.worse_share == 0.5);
    // Speed bands of 2 km/h follow the segments' speeds (1 + index m/s here: 2 m/s is 7.2 km/h).
    assert!(
        report
            .breakdowns
            .by_speed
            .iter()
            .any(|r| r.key == "6–8 km/h")
    );
    assert!(
        report
            .breakdowns
            .by_region
            .iter()
            .any(|r| r.key == "x 0–10 m, y 0–10 m")
    );
}

#[test]
fn a_small_consistent_growth_is_found_by_the_sign_flips_alone() {
    // No verdict changes, but every segment is 0.05 m worse (within a 0.2 m noise).
    let rows: Vec<Vec<(f64, f64, &[FaultKey])>> = (0..50)
        .map(|t| {
            (0..3)
                .map(|s| {
                    let b = 0.2 + 0.05 * ((t + s) % 4) as f64;
                    (b, b + 0.05 + 0.01 * ((t * 3 + s) % 3) as f64, &[][..])
                })
                .collect()
        })
        .collect();
    let report = compare(&paired(&rows), &Options::with_noise(0.2)).unwrap();
    assert_eq!(report.mcnemar.p, 1.0);
    assert!(report.evidence.deviation_worse);
    assert_eq!(report.significance, Significance::Worse);
    assert_eq!(report.segments.worse, 0);
    let m = report.median_change.unwrap();
    assert!(m.ci95_m[0] > 0.0);
    // All 50 tests changed the same way: no sign assignment but the observed one and its mirror
    // reaches a median as far from 0.
    assert!(m.p < 0.002, "{}", m.p);
    assert_eq!(m.flips, DEFAULT_RESAMPLES);
}

#[test]
fn unusable_options_are_refused() {
    let p = paired(&[vec![(0.1, 0.1, &[][..])]]);
    let with = |edit: fn(&mut Options)| {
        let mut o = Options::with_noise(0.2);
        edit(&mut o);
        compare(&p, &o).map(|_| ())
    };
    assert_eq!(with(|o| o.alpha = 1.0), Err(OptionsError::Alpha(1.0)));
    assert_eq!(with(|o| o.noise_m = -0.1), Err(OptionsError::Noise(-0.1)));
    assert_eq!(with(|o| o.resamples = 0), Err(OptionsError::Resamples));
    assert!(with(|o| o.region_cell_m = 0.0).is_err());
    assert_eq!(with(|_| ()), Ok(()));
}

#[test]
fn a_reruns_noise_is_the_95th_percentile_of_the_changes() {
    let rows: Vec<Vec<(f64, f64, &[FaultKey])>> = (0..20)
        .map(|t| {
            vec![(
                0.5,
                0.5 + 0.01 * f64::from(t as u32 + 1) * if t % 2 == 0 { 1.0 } else { -1.0 },
                &[][..],
            )]
        })
        .collect();
    let noise = paired(&rows).rerun_noise_m().unwrap();
    assert!((noise - 0.19).abs() < 1e-9, "{noise}");
}

fn arbitrary_paired() -> impl Strategy<Value = Paired> {
    let one = (0.0f64..2.0, 0.0f64..2.0, any::<bool>());
    prop::collection::vec(
        (
            prop::collection::vec(one, 0..5),
            any::<bool>(),
            any::<bool>(),
            0usize..3,
            0usize..3,
        ),
        1..30,
    )
    .prop_map(|tests| Paired {
        tests: tests
            .into_iter()
            .enumerate()
            .map(|(t, (segs, bp, np, only_base, only_new))| PairedTest {
                test_index: t,
                base_verdict: Some(if bp { Verdict::Passed } else { Verdict::Failed }),
                new_verdict: Some(if np {
                    Verdict::Passed
                } else {
                    Verdict::Aborted
                }),
                segments: segs
                    .into_iter()
                    .enumerate()
                    .map(|(i, (b, n, f))| {
                        segment(t, i, b, n, if f { &[RANGE_OFFSET] } else { &[] })
                    })
                    .collect(),
                only_base,
                only_new,
            })
            .collect(),
    })
}

proptest! {
    #[test]
    fn swapping_base_and_new_negates_the_changes_and_swaps_fixed_and_regressed(
        p in arbitrary_paired(),
        noise in 0.0f64..0.5,
    ) {
        let options = Options { resamples: 300, ..Options::with_noise(noise) };
        let a = compare(&p, &options).unwrap();
        let b = compare(&p.swapped(), &options).unwrap();
        prop_assert_eq!(a.tests.paired, b.tests.paired);
        prop_assert_eq!((a.tests.fixed, a.tests.regressed), (b.tests.regressed, b.tests.fixed));
        prop_assert_eq!((a.segments.fixed, a.segments.regressed), (b.segments.regressed, b.segments.fixed));
        prop_assert_eq!((a.segments.worse, a.segments.better), (b.segments.better, b.segments.worse));
        prop_assert_eq!((a.segments.only_base, a.segments.only_new), (b.segments.only_new, b.segments.only_base));
        prop_assert_eq!(a.mcnemar.p, b.mcnemar.p);
        match (a.median_change, b.median_change) {
            (Some(x), Some(y)) => {
                prop_assert_eq!(x.median_m, -y.median_m);
                prop_assert_eq!(x.ci95_m, [-y.ci95_m[1], -y.ci95_m[0]]);
                prop_assert_eq!(x.p, y.p);
            }
            (None, None) => {}
            other => prop_assert!(false, "{:?}", other),
        }
        let expected = match a.significance {
            Significance::Worse => Significance::Better,
            Significance::Better => Significance::Worse,
            s => s,
        };
        prop_assert_eq!(b.significance, expected);
        for (x, y) in a.breakdowns.by_fault.iter().map(|r| (r, b.breakdowns.by_fault.iter().find(|s| s.key == r.key).unwrap())) {
            prop_assert_eq!((x.worse, x.regressed), (y.better, y.fixed));
            prop_assert_eq!(x.median_change_m.map(|m| -m), y.median_change_m);
        }
        for s in p.segments() {
            let t = p.swapped().tests[s.test_index].segments[s.segment_index].clone();
            prop_assert_eq!(s.change_m().map(|c| -c), t.change_m());
        }
    }
}

/// A fault present at the culprit's segments (and at many unchanged ones of its own) is not
/// blamed before the culprits: rows are ranked by what is peculiar to them, not by their size.
/// Here a yaw fault acted on every segment the two range faults made worse, and on three
/// unchanged ones of its own in every test: its row holds the most worse segments, yet the
/// range rows come first.
#[test]
fn a_fault_that_only_accompanied_the_culprits_is_not_blamed_first() {
    const RANGE_50: FaultKey = FaultKey {
        probe: Probe::UwbRange(50),
        kind: FaultKind::Amplification,
    };
    let rows: Vec<Vec<(f64, f64, &[FaultKey])>> = (0..30)
        .map(|t| {
            let wobble = 0.01 * ((t % 3) as f64 - 1.0);
            vec![
                (0.4, 0.4 + wobble, &[][..]),
                (0.5, 1.3, &[RANGE_OFFSET, YAW_OFFSET][..]),
                (0.6, 1.4, &[RANGE_50, YAW_OFFSET][..]),
                (0.3, 0.3 - wobble, &[YAW_OFFSET][..]),
                (0.5, 0.5 + wobble, &[YAW_OFFSET][..]),
                (0.2, 0.2, &[YAW_OFFSET][..]),
            ]
        })
        .collect();
    let report = compare(&paired(&rows), &Options::with_noise(0.2)).unwrap();
    let by_fault = &report.breakdowns.by_fault;
    let yaw = by_fault
        .iter()
        .position(|r| r.key == "uwb_yaw offset")
        .unwrap();
    assert_eq!(by_fault[yaw].worse, 60, "{by_fault:#?}");
    assert!(by_fault[yaw].regression_score() > by_fault[0].regression_score());
    assert_eq!(yaw, 2, "{by_fault:#?}");
    let culprits: Vec<&str> = by_fault[..2].iter().map(|r| r.key.as_str()).collect();
    assert_eq!(
        culprits,
        ["uwb_range_234 offset", "uwb_range_50 amplification"],
        "{by_fault:#?}"
    );
}
