//! How right an explanation is: the truth of a failing segment of a simulated run, and whether
//! the first cause named is it (`drivecheck explain --score`).
//!
//! The truth is the injected fault that moved the estimate most during the segment's growth
//! interval and the [`TRUTH_SLACK_S`] before it (at least [`FAULT_MOVED_M`]), else the anchor
//! whose ranges came over a reflected path (at least [`REFLECTED_EXCESS_M`] longer in all), else
//! nominal. How far a fault moved the estimate is how far it pushed its probe's quantity: a
//! travelled distance as it is, a yaw by its lever ([`YAW_LEVER_M`] per radian), a range at most
//! the firmware's correction clamp. When several faults applied in one probe call, each is
//! credited with its own change, replayed in slot order as the firmware applies them.
//!
//! The inputs are plain: what the simulator recorded ([`SimTruth`]: each probe call a fault
//! changed and each range request, on the test's clock) and the simulator's fault model (how a
//! fault kind changes a probe's value), both given by the caller, which reads them from the
//! recording. Where two or more faults moved the estimate, the push does not say which caused the
//! failure: [`super::counterfactual`] settles it by driving the case again without each.

use serde::{Deserialize, Serialize};

use super::{SegmentExplanation, Source};
use crate::case::{Case, CommandRecord};
use car_link::Probe;
use car_link::firmware::UWB_CORRECTION_CLAMP_M;

/// What really made a failing segment's error grow, from a simulated run's hidden truth.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "truth")]
pub enum TrueCause {
    /// An injected fault applied during the growth (the one that moved the estimate most).
    Fault {
        /// Its command's index in the case.
        command_index: usize,
    },
    /// No fault applied, and this anchor's ranges came over a reflected path.
    Reflection {
        /// The anchor.
        anchor_id: u16,
    },
    /// Neither: dead reckoning's own drift and range noise.
    Nominal,
}

/// One failing segment: what the explanation named first, and the truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentScore {
    /// The segment.
    pub segment_index: usize,
    /// The first cause named (`None`: only `unexplained`).
    pub named: Option<Source>,
    /// The truth.
    pub truth: TrueCause,
    /// The class of the truth, for the confusion matrix (`range offset`, `wheel slip`, …).
    pub truth_class: String,
    /// Whether the first cause named is the truth (a fault: that very command; a reflection:
    /// that anchor's range; nominal: no fault and no anchor).
    pub right: bool,
    /// The faults that moved the estimate by at least [`FAULT_MOVED_M`] during the growth
    /// interval and the [`TRUTH_SLACK_S`] before it, most first (metres: how far each pushed
    /// its probe's quantity, see the module doc).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub moved: Vec<FaultEffect>,
    /// When several did and the case was driven again without each of them
    /// ([`super::counterfactual::settle`]): how much lower the segment's largest deviation came
    /// out without each (the median over the runs), most first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub counterfactual: Vec<FaultEffect>,
    /// Other faults whose absence lowered the deviation as much as the truth's, within
    /// [`super::counterfactual::COUNTERFACTUAL_TIE_M`]: each was needed as much (naming one of
    /// them is right).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tied_with: Vec<usize>,
}

/// A fault command and a length in metres (what it moved, or what its absence lowered).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FaultEffect {
    /// The fault's command index in the case.
    pub command_index: usize,
    /// Metres.
    pub metres: f64,
}

impl SegmentScore {
    /// The faults a counterfactual should tell apart: two or more moved the estimate.
    pub fn needs_counterfactual(&self) -> bool {
        matches!(self.truth, TrueCause::Fault { .. }) && self.moved.len() >= 2
    }
}

/// One probe call of the simulated car in which faults applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AppliedFault<'a> {
    /// When, seconds on the test's clock.
    pub t_s: f64,
    /// The probe's name (`uwb_range_50`, `uwb_travel_dist`, `uwb_yaw`), as `Probe` displays it.
    pub probe: &'a str,
    /// The slots that applied: bit *k* for slot *k*.
    pub slots: u8,
    /// The probe's value before the faults.
    pub before: f64,
    /// Its value after them.
    pub after: f64,
}

/// One range request of the simulated car that came back with a range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeTruth {
    /// When, seconds on the test's clock.
    pub t_s: f64,
    /// The anchor ranged.
    pub anchor_id: u16,
    /// Whether the range came over a reflected path.
    pub reflected: bool,
    /// The range measured, metres.
    pub range_m: f64,
    /// The true distance, metres.
    pub true_range_m: f64,
}

/// What the simulator recorded of a test (its hidden truth), in the order it happened.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SimTruth<'a> {
    /// The probe calls in which faults applied.
    pub faults: &'a [AppliedFault<'a>],
    /// The range requests.
    pub ranges: &'a [RangeTruth],
}

/// The truth looks this far before the growth interval (a fault's last applications before
/// the error crossed the nominal level still count), seconds.
pub const TRUTH_SLACK_S: f64 = 0.5;
/// What a yaw error of one radian moves the estimate per odometry tick at about 2 m/s, metres.
pub const YAW_LEVER_M: f64 = 0.02;
/// A fault that moved the estimate less than this is not the truth, metres.
pub const FAULT_MOVED_M: f64 = 0.05;
/// Reflected ranges longer than the direct path by less than this in all are not the truth,
/// metres.
pub const REFLECTED_EXCESS_M: f64 = 0.3;

/// The scores of a case's explained `segments` (the failing ones; the others are not scored)
/// against `truth`, what the simulator recorded of its test.
pub fn score_segments(
    segments: &[SegmentExplanation],
    case: &Case,
    truth: &SimTruth<'_>,
) -> Vec<SegmentScore> {
    segments
        .iter()
        .filter(|s| s.verdict == "failed")
        .map(|segment| score_segment(segment, case, truth))
        .collect()
}

/// The score of one explained segment (see [`score_segments`]).
pub fn score_segment(
    segment: &SegmentExplanation,
    case: &Case,
    truth: &SimTruth<'_>,
) -> SegmentScore {
    let (a, b) = (segment.from_s - TRUTH_SLACK_S, segment.to_s);
    let inside = |t_s: f64| (a..=b).contains(&t_s);
    // Faults: how far each (probe, slot) moved the estimate, metres.
    let mut moved: Vec<(usize, f64)> = Vec::new();
    for f in truth.faults.iter().filter(|f| inside(f.t_s)) {
        let delta = (f.after - f.before).abs();
        let metres = match f.probe {
            "uwb_travel_dist" => delta,
            "uwb_yaw" => delta.to_radians() * YAW_LEVER_M,
            _ => delta.min(UWB_CORRECTION_CLAMP_M),
        };
        for (command, part) in slot_shares(case, f) {
            match moved.iter_mut().find(|m| m.0 == command) {
                Some(m) => m.1 += metres * part,
                None => moved.push((command, metres * part)),
            }
        }
    }
    moved.sort_by(|x, y| y.1.total_cmp(&x.1));
    let cause = match moved.first() {
        Some(&(command_index, metres)) if metres >= FAULT_MOVED_M => {
            TrueCause::Fault { command_index }
        }
        _ => {
            let mut reflected: Vec<(u16, f64)> = Vec::new();
            for range in truth.ranges.iter().filter(|r| r.reflected && inside(r.t_s)) {
                let excess = (range.range_m - range.true_range_m).max(0.0);
                match reflected.iter_mut().find(|r| r.0 == range.anchor_id) {
                    Some(r) => r.1 += excess,
                    None => reflected.push((range.anchor_id, excess)),
                }
            }
            reflected.sort_by(|x, y| y.1.total_cmp(&x.1));
            match reflected.first() {
                Some(&(anchor_id, excess)) if excess >= REFLECTED_EXCESS_M => {
                    TrueCause::Reflection { anchor_id }
                }
                _ => TrueCause::Nominal,
            }
        }
    };
    let named = segment.top().map(|c| c.source);
    SegmentScore {
        segment_index: segment.segment_index,
        named,
        truth: cause,
        truth_class: truth_class(case, cause),
        right: is_right(cause, named),
        moved: moved
            .iter()
            .filter(|m| m.1 >= FAULT_MOVED_M)
            .map(|&(command_index, metres)| FaultEffect {
                command_index,
                metres,
            })
            .collect(),
        counterfactual: Vec::new(),
        tied_with: Vec::new(),
    }
}

/// Whether `named` is `truth` (see [`SegmentScore::right`]).
pub fn is_right(truth: TrueCause, named: Option<Source>) -> bool {
    match (truth, named) {
        (TrueCause::Fault { command_index }, Some(Source::Fault { command_index: n })) => {
            command_index == n
        }
        (TrueCause::Reflection { anchor_id }, Some(Source::Anchor { anchor_id: n })) => {
            anchor_id == n
        }
        (TrueCause::Nominal, named) => {
            !matches!(named, Some(Source::Fault { .. } | Source::Anchor { .. }))
        }
        _ => false,
    }
}

/// The class of a truth, for the confusion matrix.
pub fn truth_class(case: &Case, truth: TrueCause) -> String {
    match truth {
        TrueCause::Fault { command_index } => match case.commands.get(command_index) {
            Some(CommandRecord::AddFault { probe, kind, .. }) => match probe {
                Probe::UwbRange(_) => {
                    format!("range {}", kind.to_string().to_lowercase())
                }
                Probe::UwbTravelDist => "wheel slip".to_owned(),
                Probe::UwbYaw => "yaw".to_owned(),
                Probe::Px => "px".to_owned(),
            },
            _ => "fault".to_owned(),
        },
        TrueCause::Reflection { anchor_id } => format!("reflection on {anchor_id}"),
        TrueCause::Nominal => "nominal".to_owned(),
    }
}

/// The command index of the fault in slot `slot` of `probe`: the car fills a probe's slots in
/// the order it adds faults, which is the order of the case's `fault_places`.
fn command_of_slot(case: &Case, probe: &str, slot: usize) -> Option<usize> {
    case.fault_places
        .iter()
        .filter(|place| {
            matches!(case.commands.get(place.command_index),
                Some(CommandRecord::AddFault { probe: p, .. }) if p.to_string() == probe)
        })
        .nth(slot)
        .map(|place| place.command_index)
}

/// The faults that applied in one probe call (`applied`), each with its share of the call's
/// change of the probe's value: the simulator applies them in slot order (the fault table's
/// effect), so each slot's own change is replayed from the value before (a kind whose effect
/// grows with the calls since it started is replayed as at its first call: the record keeps no
/// slot's start). Equal shares when the changes cannot be
/// told (the value before is not finite, or no slot changed it).
pub fn slot_shares(case: &Case, applied: &AppliedFault<'_>) -> Vec<(usize, f64)> {
    let mut value = applied.before as f32;
    let mut changes: Vec<(usize, f64)> = Vec::new();
    for slot in (0..8).filter(|slot| applied.slots & (1 << slot) != 0) {
        let Some(command) = command_of_slot(case, applied.probe, slot) else {
            continue;
        };
        let change = match case.commands.get(command) {
            Some(CommandRecord::AddFault { kind, param, .. }) => {
                let next = kind.apply(value, *param as f32, 0);
                let change = f64::from((next - value).abs());
                value = next;
                change
            }
            _ => f64::NAN,
        };
        changes.push((command, change));
    }
    let total: f64 = changes.iter().map(|c| c.1).sum();
    let equal = 1.0 / changes.len().max(1) as f64;
    changes
        .into_iter()
        .map(|(command, change)| {
            let part = if total.is_finite() && total > 0.0 {
                change / total
            } else {
                equal
            };
            (command, part)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::explain::Cause;
    use proptest::prelude::*;

    /// A case with wheel-slip faults of these factors (slots 0, 1, … in order), each acting
    /// from 1 s to 2 s.
    fn slips(factors: &[f64]) -> Case {
        let places: Vec<serde_json::Value> = (0..factors.len())
            .map(|command_index| {
                serde_json::json!({
                    "command_index": command_index, "rule": "planned", "segment_index": 0,
                    "planned_along_m": 1.0, "sent_s": 1.0, "added_s": 1.0,
                    "acts_from_s": 1.0, "acts_to_s": 2.0
                })
            })
            .collect();
        let commands: Vec<serde_json::Value> = factors
            .iter()
            .map(|param| {
                serde_json::json!({
                    "command": "add_fault", "probe": "uwb_travel_dist", "kind": "amplification",
                    "param": param, "start": 0, "duration": 100
                })
            })
            .collect();
        let json = serde_json::json!({
            "format": "drivecheck-case", "schema_version": 2, "scenario": {"name": "s"},
            "commands": commands, "fault_places": places
        });
        Case::from_json(&json.to_string()).unwrap()
    }

    /// A case with two wheel-slip faults, ×1.5 (slot 0) and ×3 (slot 1).
    fn two_slips() -> Case {
        slips(&[1.5, 3.0])
    }

    fn applied(t_s: f64, slots: u8, before: f64, after: f64) -> AppliedFault<'static> {
        AppliedFault {
            t_s,
            probe: "uwb_travel_dist",
            slots,
            before,
            after,
        }
    }

    /// Failing segment 2, its growth from 3 s to 4 s, naming `first` first.
    fn explained(first: Source) -> SegmentExplanation {
        SegmentExplanation {
            segment_index: 2,
            verdict: "failed".to_owned(),
            from_s: 3.0,
            to_s: 4.0,
            error_from_m: 0.4,
            error_to_m: 1.2,
            carried_over: false,
            causes: vec![Cause {
                source: first,
                share: 1.0,
                growth_m: 0.8,
                steps: 10,
                kind: None,
                ambiguous_with: None,
            }],
        }
    }

    #[test]
    fn a_probe_call_is_shared_among_its_faults_by_each_ones_own_change() {
        let case = two_slips();
        // 10 mm: ×1.5 adds 5 mm, then ×3 adds 30 mm.
        let shares = slot_shares(&case, &applied(0.0, 0b11, 0.01, f64::NAN));
        assert_eq!(shares.len(), 2);
        assert_eq!(shares[0].0, 0);
        assert!((shares[0].1 - 1.0 / 7.0).abs() < 1e-6, "{shares:?}");
        assert!((shares[1].1 - 6.0 / 7.0).abs() < 1e-6, "{shares:?}");
        // One slot alone takes the whole call.
        assert_eq!(
            slot_shares(&case, &applied(0.0, 0b10, 0.01, f64::NAN)),
            vec![(1, 1.0)]
        );
        // Without the value before, the changes cannot be told: equal shares.
        assert_eq!(
            slot_shares(&case, &applied(0.0, 0b11, f64::NAN, f64::NAN)),
            vec![(0, 0.5), (1, 0.5)]
        );
        // A slot no fault of the case fills is no one's.
        assert_eq!(
            slot_shares(&case, &applied(0.0, 0b100, 0.01, f64::NAN)),
            vec![]
        );
    }

    #[test]
    fn the_fault_that_moved_the_estimate_most_in_the_interval_is_the_truth() {
        let case = two_slips();
        // Slot 1 alone pushes 0.3 m at 3.5 s; both push 0.07 m at 2.8 s (within the slack);
        // slot 0 pushes 2 m at 1 s, long before the interval: not counted.
        let faults = [
            applied(1.0, 0b01, 0.0, 2.0),
            applied(2.8, 0b11, 0.01, 0.08),
            applied(3.5, 0b10, 0.1, 0.4),
        ];
        let truth = SimTruth {
            faults: &faults,
            ranges: &[],
        };
        let s = score_segment(
            &explained(Source::Fault { command_index: 1 }),
            &case,
            &truth,
        );
        assert_eq!(s.truth, TrueCause::Fault { command_index: 1 });
        assert!(s.right);
        assert_eq!(s.truth_class, "wheel slip");
        // Slot 0's part of the 2.8 s call is 1/7 of 0.07 m: below the least push, not listed.
        assert_eq!(s.moved.len(), 1);
        assert_eq!(s.moved[0].command_index, 1);
        assert!(
            (s.moved[0].metres - (0.3 + 0.06)).abs() < 1e-6,
            "{:?}",
            s.moved
        );
        assert!(!s.needs_counterfactual());
        // Naming the other fault is wrong.
        let wrong = score_segment(
            &explained(Source::Fault { command_index: 0 }),
            &case,
            &truth,
        );
        assert!(!wrong.right);
    }

    #[test]
    fn without_a_fault_a_reflected_anchor_is_the_truth_else_nominal() {
        let case = two_slips();
        let range = |t_s: f64, anchor_id: u16, reflected: bool, excess: f64| RangeTruth {
            t_s,
            anchor_id,
            reflected,
            range_m: 5.0 + excess,
            true_range_m: 5.0,
        };
        // Anchor 50's reflected ranges are 0.4 m long in all; 234's longer ones are direct.
        let ranges = [
            range(3.2, 50, true, 0.2),
            range(3.4, 50, true, 0.2),
            range(3.3, 234, false, 3.0),
            range(9.0, 234, true, 3.0),
        ];
        let truth = SimTruth {
            faults: &[],
            ranges: &ranges,
        };
        let s = score_segment(&explained(Source::Anchor { anchor_id: 50 }), &case, &truth);
        assert_eq!(s.truth, TrueCause::Reflection { anchor_id: 50 });
        assert_eq!(s.truth_class, "reflection on 50");
        assert!(s.right);
        // Less than the least excess: nominal, which an odometry cause names rightly.
        let short = [range(3.2, 50, true, 0.2)];
        let s = score_segment(
            &explained(Source::Odometry),
            &case,
            &SimTruth {
                faults: &[],
                ranges: &short,
            },
        );
        assert_eq!(s.truth, TrueCause::Nominal);
        assert!(s.right);
        // Passing segments are not scored.
        let mut passing = explained(Source::Odometry);
        passing.verdict = "passed".to_owned();
        assert!(score_segments(&[passing], &case, &truth).is_empty());
    }

    #[test]
    fn a_named_anchor_or_fault_is_never_right_about_nominal() {
        let anchor = Some(Source::Anchor { anchor_id: 50 });
        assert!(!is_right(TrueCause::Nominal, anchor));
        assert!(is_right(TrueCause::Nominal, Some(Source::Heading)));
        assert!(is_right(TrueCause::Nominal, None));
        assert!(!is_right(TrueCause::Reflection { anchor_id: 234 }, anchor));
        assert!(!is_right(TrueCause::Fault { command_index: 0 }, anchor));
    }

    proptest! {
        /// However many faults apply in a call and whatever the value before, the shares of the
        /// call's change are each in 0..=1 and add up to the whole.
        #[test]
        fn the_shares_of_a_probe_call_add_up_to_one(
            factors in prop::collection::vec(0.1f64..5.0, 1..6),
            slots in 1u8..64,
            before in prop_oneof![Just(f64::NAN), -10.0f64..10.0],
        ) {
            let case = slips(&factors);
            let shares = slot_shares(&case, &applied(0.0, slots, before, f64::NAN));
            let filled = (0..8).filter(|k| slots & (1 << k) != 0 && *k < factors.len()).count();
            prop_assert_eq!(shares.len(), filled);
            for (_, part) in &shares {
                prop_assert!((0.0..=1.0 + 1e-12).contains(part), "{:?}", shares);
            }
            if !shares.is_empty() {
                let sum: f64 = shares.iter().map(|s| s.1).sum();
                prop_assert!((sum - 1.0).abs() < 1e-9, "{:?}", shares);
            }
        }
    }
}
