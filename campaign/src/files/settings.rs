//! The settings a case and a campaign record hold, and the records of the runtime constants.

use std::collections::BTreeMap;
use std::time::Duration;

use scenarios::{CampaignSettings, Interval, ProbeFaults, Scenario};
use serde::{Deserialize, Serialize};

use super::{CaseError, invalid};
use crate::model::FaultKind;
use crate::oracle::FailurePolicy;
use crate::safety::SafetyConfig;
use crate::streaming::StreamingConfig;

/// The settings a campaign ran with: the scenario's campaign settings, the ahead margin and the
/// oracle's failure policy.
///
/// The case format's own spelling of the scenario's [`CampaignSettings`]: flat fault ranges with
/// the firmware's fault kind names, every field required, and what the scenario does not hold
/// (the ahead margin, the failure policy, the runtime constants). Its `{min, max}` ranges are the
/// scenario's [`Interval`]s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Tests in the campaign.
    pub tests: usize,
    /// Commands per test, growing over the campaign.
    pub test_size: Interval<usize>,
    /// Points per `run_segments`.
    pub points_per_segment: Interval<usize>,
    /// Speed of a segment, km/h.
    pub speed_kmh: Interval<f64>,
    /// Points of every segment's ahead margin.
    pub ahead_margin: usize,
    /// Largest allowed deviation of UWB from RTK, metres.
    pub oracle_threshold_m: f64,
    /// What happens after a failing segment.
    pub failure_policy: FailurePolicy,
    /// Command weights.
    pub weights: Weights,
    /// Fault parameter ranges: every section whole (case schema 3, campaign schema 2), or the
    /// flat ranges of older files.
    pub faults: FaultRangesForm,
    /// The safety monitor's limits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyConfigRecord>,
    /// The streaming rule's constants.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub streaming: Option<StreamingConfigRecord>,
}

/// Command weights in a record: the scenario's [`scenarios::CommandWeights`], but a case file
/// must give all four (a scenario file defaults the ones it leaves out).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Weights {
    /// `run_segments`.
    pub run_segments: u32,
    /// `add_fault` on an anchor's range.
    pub anchor_range_fault: u32,
    /// `add_fault` wheel slip.
    pub wheel_slip_fault: u32,
    /// `add_fault` yaw.
    pub yaw_fault: u32,
}

/// Fault parameter ranges in a record: the scenario's three fault sections, each whole (what this
/// build writes: case schema 3, campaign record schema 2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultRanges {
    /// `add_fault` on an anchor's range.
    pub anchor_range: ProbeFaultsRecord,
    /// `add_fault` wheel slip (the odometry step).
    pub wheel_slip: ProbeFaultsRecord,
    /// `add_fault` yaw.
    pub yaw: ProbeFaultsRecord,
}

/// One fault section in a record: the scenario's [`ProbeFaults`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProbeFaultsRecord {
    /// Fault kinds drawn.
    pub kinds: Vec<FaultKind>,
    /// The parameter range of every kind with a parameter, by the kind's name (a bitflip's range
    /// holds bit numbers).
    pub ranges: BTreeMap<FaultKind, Interval<f64>>,
    /// Start, probe iterations.
    pub start: Interval<u32>,
    /// Duration, probe iterations.
    pub duration: Interval<u32>,
}

impl From<&ProbeFaults> for ProbeFaultsRecord {
    fn from(f: &ProbeFaults) -> Self {
        Self {
            kinds: f.kinds.clone(),
            ranges: f.ranges.clone(),
            start: f.start,
            duration: f.duration,
        }
    }
}

/// The fault ranges as a record holds them: whole sections, or the flat form of case schema 1–2
/// and campaign schema 1, which kept only the offset range of anchor faults, the amplification
/// of wheel slip and the offset of yaw.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(
    untagged,
    expecting = "fault ranges: the sections `anchor_range`, `wheel_slip` and `yaw`, each with \
                 `kinds`, `ranges`, `start` and `duration` (or, in older files, the flat \
                 `anchor_range_kinds`, `anchor_range_param`, … `yaw_duration`)"
)]
pub enum FaultRangesForm {
    /// Every section whole.
    Sections(FaultRanges),
    /// The flat form of older files.
    Flat(FlatFaultRanges),
}

impl FaultRangesForm {
    /// Checks that the form is the one of the file's version: the sections when `sections`,
    /// the flat form otherwise.
    pub(crate) fn check_form(&self, sections: bool, version: u32) -> Result<(), CaseError> {
        match (self, sections) {
            (Self::Sections(_), true) | (Self::Flat(_), false) => Ok(()),
            (Self::Flat(_), true) => Err(invalid(
                "settings.faults",
                format!(
                    "the flat fault ranges of older files in a schema version {version} file, \
                     which gives every section whole (`anchor_range`, `wheel_slip`, `yaw`)"
                ),
            )),
            (Self::Sections(_), false) => Err(invalid(
                "settings.faults",
                format!(
                    "fault sections in a schema version {version} file, which gives the flat \
                     ranges (`anchor_range_kinds`, …)"
                ),
            )),
        }
    }
}

/// Fault parameter ranges in the flat form of case schema 1–2 and campaign record schema 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlatFaultRanges {
    /// Fault kinds of anchor range faults.
    pub anchor_range_kinds: Vec<FaultKind>,
    /// Anchor range fault parameter.
    pub anchor_range_param: Interval<f64>,
    /// Anchor range fault start, probe iterations.
    pub anchor_range_start: Interval<u32>,
    /// Anchor range fault duration, probe iterations.
    pub anchor_range_duration: Interval<u32>,
    /// Wheel slip amplification.
    pub wheel_slip_amplification: Interval<f64>,
    /// Wheel slip start, probe iterations.
    pub wheel_slip_start: Interval<u32>,
    /// Wheel slip duration, probe iterations.
    pub wheel_slip_duration: Interval<u32>,
    /// Yaw offset, degrees.
    pub yaw_offset_deg: Interval<f64>,
    /// Yaw start, probe iterations.
    pub yaw_start: Interval<u32>,
    /// Yaw duration, probe iterations.
    pub yaw_duration: Interval<u32>,
}

impl Settings {
    /// The settings of a campaign in `scenario` with `tests` tests and `policy`.
    pub fn new(scenario: &Scenario, tests: usize, policy: FailurePolicy) -> Self {
        let c: &CampaignSettings = &scenario.campaign;
        let f = &c.faults;
        Self {
            tests,
            test_size: c.test_size,
            points_per_segment: c.points_per_segment,
            speed_kmh: c.speed_kmh,
            ahead_margin: scenario.generator.ahead_margin,
            oracle_threshold_m: c.oracle_threshold_m,
            failure_policy: policy,
            weights: Weights {
                run_segments: c.weights.run_segments,
                anchor_range_fault: c.weights.anchor_range_fault,
                wheel_slip_fault: c.weights.wheel_slip_fault,
                yaw_fault: c.weights.yaw_fault,
            },
            faults: FaultRangesForm::Sections(FaultRanges {
                anchor_range: (&f.anchor_range).into(),
                wheel_slip: (&f.wheel_slip).into(),
                yaw: (&f.yaw).into(),
            }),
            safety: None,
            streaming: None,
        }
    }

    /// These settings with the safety monitor's and the streaming rule's constants.
    pub fn with_runtime(self, safety: SafetyConfig, streaming: StreamingConfig) -> Self {
        Self {
            safety: Some(safety.into()),
            streaming: Some(streaming.into()),
            ..self
        }
    }
}

/// The safety monitor's limits as a record holds them (`settings.safety`; the monitor's
/// [`SafetyConfig`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SafetyConfigRecord {
    /// How far the car may be outside the drivable region before the test is stopped, metres.
    pub area_margin_m: f64,
    /// Largest distance from the planned route, metres.
    pub max_cross_track_m: f64,
    /// Longest time without a state sample, milliseconds.
    pub stale_after: u64,
}

impl From<SafetyConfig> for SafetyConfigRecord {
    fn from(c: SafetyConfig) -> Self {
        Self {
            area_margin_m: c.area_margin_m,
            max_cross_track_m: c.max_cross_track_m,
            stale_after: millis(c.stale_after),
        }
    }
}

impl From<SafetyConfigRecord> for SafetyConfig {
    fn from(r: SafetyConfigRecord) -> Self {
        Self {
            area_margin_m: r.area_margin_m,
            max_cross_track_m: r.max_cross_track_m,
            stale_after: Duration::from_millis(r.stale_after),
            max_plausible_speed_mps: crate::safety::MAX_PLAUSIBLE_SPEED_MPS,
        }
    }
}

/// The streaming rule's constants as a record holds them (`settings.streaming`; the rule's
/// [`StreamingConfig`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StreamingConfigRecord {
    /// Added to the measured delays, milliseconds.
    pub margin: u64,
    /// Round trip assumed before any is measured, milliseconds.
    pub initial_round_trip: u64,
    /// Generation time assumed before any is measured, milliseconds.
    pub initial_generation: u64,
    /// Most recent measurements the percentiles are taken over.
    pub window: usize,
    /// Speeds below this count as this, m/s.
    pub min_speed_mps: f64,
}

impl From<StreamingConfig> for StreamingConfigRecord {
    fn from(c: StreamingConfig) -> Self {
        Self {
            margin: millis(c.margin),
            initial_round_trip: millis(c.initial_round_trip),
            initial_generation: millis(c.initial_generation),
            window: c.window,
            min_speed_mps: c.min_speed_mps,
        }
    }
}

impl From<StreamingConfigRecord> for StreamingConfig {
    fn from(r: StreamingConfigRecord) -> Self {
        Self {
            margin: Duration::from_millis(r.margin),
            initial_round_trip: Duration::from_millis(r.initial_round_trip),
            initial_generation: Duration::from_millis(r.initial_generation),
            window: r.window,
            min_speed_mps: r.min_speed_mps,
        }
    }
}

/// A duration as whole milliseconds, as every record writes one.
pub(crate) fn millis(d: Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}
