//! Campaign records (`campaign.json`): what a run directory says about its campaign.

use serde::{Deserialize, Serialize};

use super::Case;
use super::{
    CAMPAIGN_FAULT_SECTIONS_SINCE, CAMPAIGN_FORMAT, CAMPAIGN_READABLE, CaseError, Header,
    ScenarioRef, Settings, check_header, parse,
};
use crate::oracle::Verdict;
use crate::shard::Shard;

/// What a campaign's run directory says about it (`campaign.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CampaignRecord {
    /// `drivecheck-campaign`, its schema version and the drivecheck version that ran it.
    #[serde(flatten)]
    pub header: Header,
    /// The one seed every test derives from.
    pub seed: u64,
    /// True when it ran without fault commands.
    pub no_faults: bool,
    /// The scenario.
    pub scenario: ScenarioRef,
    /// The settings.
    pub settings: Settings,
    /// The car it drove (`sim`, `tcp://…`, `udp://…`, `serial://…`).
    pub car: String,
    /// The car profile of the embedded simulated car (absent on a real car).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub car_profile: Option<super::CarProfileRef>,
    /// The car's firmware version as it reported it (absent if unknown).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub car_firmware_version: Option<String>,
    /// On the car's own firmware built for the host (`--car sitl:TREE`): the SHA-256 of the
    /// tree's files that went into the build, so that a run says which firmware it drove.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub car_firmware_tree_hash: Option<String>,
    /// When it started, RFC 3339 (for example `2026-11-22T10:55:21Z`).
    pub started_at: String,
    /// When it ended, RFC 3339; absent while running or if the process died.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ended_at: Option<String>,
    /// The outcome, once it ended.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub summary: Option<CampaignSummary>,
    /// For a replay (`drivecheck replay`): the case every test drove again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replay_of: Option<ReplayOf>,
    /// For a campaign that drove an earlier run's cases (`drivecheck run --cases-from DIR`):
    /// that run. Its tests are the earlier run's, test for test.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cases_from: Option<CasesFrom>,
    /// For one shard of a campaign (`drivecheck run --shard K/N`): which one. Its run directory
    /// holds the shard's tests only; `drivecheck runs merge` joins the shards.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<Shard>,
    /// The sessions of a campaign resumed after an interruption (`drivecheck run --resume`), in
    /// order, the first included; empty for a campaign that ran in one go.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sessions: Vec<Session>,
    /// The cars of a campaign on several cars (`drivecheck run --car A --car B …`), one entry
    /// per car and session, in the order given; empty with one car.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub cars: Vec<CarRun>,
}

/// One car of a campaign on several cars: which tests it drove, and why it left if it did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CarRun {
    /// Its name (`A` of `--car A=tcp://…`, or `car1`, `car2`, … in the order given): what the
    /// progress, the case files (`car`) and the live view call it.
    pub name: String,
    /// Its address as given (`tcp://…`, `udp://…`, `serial://…`).
    pub address: String,
    /// Its firmware version as it reported it (absent when it never answered).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub firmware: Option<String>,
    /// The tests whose case files it wrote, in order (a test it was cut off in is not listed:
    /// its partial case is kept as `case-NNN.partial-K.json` and another car drove it).
    pub tests: Vec<usize>,
    /// The session it drove in, from 1, for a resumed campaign (`sessions`); absent for a
    /// campaign that ran in one go.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub session: Option<usize>,
    /// Why it left the campaign before its end (its link was lost, preflight refused it, …);
    /// absent when it stayed to the end.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub left: Option<String>,
}

/// One session of a resumed campaign: one `drivecheck run` (or `run --resume`) process.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Session {
    /// When it started, RFC 3339.
    pub started_at: String,
    /// When it ended, RFC 3339; absent when the process died (`kill -9`, a crash, power).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ended_at: Option<String>,
    /// The car it drove.
    pub car: String,
    /// The tests whose case files it wrote, in order (an interrupted test included: it is
    /// driven again by the next session, its case kept as `case-NNN.partial-K.json`).
    pub tests: Vec<usize>,
    /// How it ended: `completed`, `interrupted` (a signal, a lost link or another stop; the run
    /// directory was completed) or `died` (found unfinished by the next session); absent while
    /// it runs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub end: Option<String>,
}

/// The case a replay drove again.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayOf {
    /// The case file as given on the command line.
    pub case: String,
    /// Its campaign's seed, if recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub campaign_seed: Option<u64>,
    /// Its test index, if recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_index: Option<usize>,
    /// Its verdict, if it was run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
    /// True when the replay left out its fault commands.
    pub no_faults: bool,
}

/// The earlier run whose cases a campaign drove again (`run --cases-from`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CasesFrom {
    /// Its run directory as given on the command line.
    pub run: String,
    /// Its campaign's seed.
    pub campaign_seed: u64,
    /// Its scenario.
    pub scenario: ScenarioRef,
    /// The cases driven: the earlier run's case files 0 to `tests` − 1.
    pub tests: usize,
}

/// A campaign's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CampaignSummary {
    /// Tests run.
    pub tests: usize,
    /// Tests passed.
    pub passed: usize,
    /// Tests failed.
    pub failed: usize,
    /// Tests aborted.
    pub aborted: usize,
    /// Largest deviation seen in any segment, metres (absent without samples).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_deviation_m: Option<f64>,
    /// Case files of the failed and aborted tests, relative to the run directory.
    pub failing_cases: Vec<String>,
    /// Why the UWB positioning was not tested, when it was not (an area without anchors: the
    /// estimate is dead reckoning only, so a pass says nothing about UWB).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uwb_not_tested: Option<String>,
    /// What the tests covered: the share of the area driven, headings and speeds, fault kinds
    /// per probe (`campaign::coverage`); absent in records of older versions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage: Option<CoverageRecord>,
}

impl CampaignRecord {
    /// Reads a campaign record from JSON: shape, format name and version.
    pub fn from_json(text: &str) -> Result<Self, CaseError> {
        let record: Self = parse(text)?;
        check_header(&record.header, CAMPAIGN_FORMAT, CAMPAIGN_READABLE)?;
        let version = record.header.schema_version;
        record
            .settings
            .faults
            .check_form(version >= CAMPAIGN_FAULT_SECTIONS_SINCE, version)?;
        Ok(record)
    }

    /// The record as pretty-printed JSON.
    pub fn to_json(&self) -> Result<String, CaseError> {
        super::to_json(self)
    }

    /// What makes `other` the record of another campaign than this one (another seed, scenario,
    /// tool version, shard count, car, settings or source of tests), if anything: what `runs merge`
    /// refuses in a shard and `run --resume` in a run directory.
    pub fn difference(&self, other: &CampaignRecord) -> Option<String> {
        let (a, b) = (self, other);
        let differs =
            |what: &str, x: String, y: String| (x != y).then(|| format!("{what} {x} and {y}"));
        let shard_count = |r: &CampaignRecord| r.shard.map_or(0, |s| s.count).to_string();
        let without_runtime = |s: &Settings| Settings {
            safety: None,
            streaming: None,
            ..s.clone()
        };
        differs("seed", a.seed.to_string(), b.seed.to_string())
            .or_else(|| {
                differs(
                    "scenario",
                    format!(
                        "{} ({})",
                        a.scenario.name,
                        a.scenario.hash.as_deref().unwrap_or("-")
                    ),
                    format!(
                        "{} ({})",
                        b.scenario.name,
                        b.scenario.hash.as_deref().unwrap_or("-")
                    ),
                )
            })
            .or_else(|| {
                differs(
                    "tool version",
                    a.header.tool().to_owned(),
                    b.header.tool().to_owned(),
                )
            })
            .or_else(|| differs("shard count", shard_count(a), shard_count(b)))
            .or_else(|| {
                differs(
                    "--no-faults",
                    a.no_faults.to_string(),
                    b.no_faults.to_string(),
                )
            })
            .or_else(|| differs("car", a.car.clone(), b.car.clone()))
            .or_else(|| {
                (without_runtime(&a.settings) != without_runtime(&b.settings)).then(|| {
                    "the campaign settings differ (tests, sizes, speeds, faults or policy)"
                        .to_owned()
                })
            })
            .or_else(|| {
                (a.replay_of != b.replay_of).then(|| "they replay different cases".to_owned())
            })
            .or_else(|| {
                (a.cases_from != b.cases_from)
                    .then(|| "they drive the cases of different runs (--cases-from)".to_owned())
            })
    }

    /// What makes `case` a case of another campaign than this one (its seed, scenario, faults or
    /// settings), if anything.
    pub fn foreign(&self, case: &Case) -> Option<String> {
        let record = self;
        let runtime_free = |s: &Settings| Settings {
            safety: None,
            streaming: None,
            ..s.clone()
        };
        if case.campaign_seed != Some(record.seed) {
            return Some(format!(
                "campaign seed {}, the campaign's is {}",
                case.campaign_seed
                    .map_or_else(|| "none".to_owned(), |s| s.to_string()),
                record.seed
            ));
        }
        if case.scenario != record.scenario {
            return Some(format!(
                "scenario {} ({}), the campaign's is {} ({})",
                case.scenario.name,
                case.scenario.hash.as_deref().unwrap_or("-"),
                record.scenario.name,
                record.scenario.hash.as_deref().unwrap_or("-")
            ));
        }
        if case.no_faults != record.no_faults {
            return Some(format!(
                "--no-faults {}, the campaign's {}",
                case.no_faults, record.no_faults
            ));
        }
        match &case.settings {
            Some(settings) if runtime_free(settings) != runtime_free(&record.settings) => Some(
                "its settings are not the campaign's (tests, sizes, speeds, faults, threshold or policy)"
                    .to_owned(),
            ),
            _ => None,
        }
    }
}

/// A campaign's coverage statistics as `campaign.json` keeps them (`summary.coverage`; computed
/// by `crate::coverage`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoverageRecord {
    /// Tests counted.
    pub tests: usize,
    /// Side of a cell, metres.
    pub cell_m: f64,
    /// Drivable cells of the area.
    pub drivable_cells: usize,
    /// Drivable cells a driven segment passed through.
    pub driven_cells: usize,
    /// `driven_cells / drivable_cells`.
    pub area_share: f64,
    /// Metres driven per heading bin: bin *k* holds headings from `k × 30°` (counter-clockwise
    /// from east) up to the next.
    pub heading_m: Vec<f64>,
    /// Metres driven per speed bin: bin *k* holds speeds from `k × 2 km/h` up to the next.
    pub speed_m: Vec<f64>,
    /// Per probe and fault type: how many fault commands the tests held, sent and confirmed by
    /// the car, and estimated to begin acting before their test ended.
    pub faults: Vec<FaultCoverageRecord>,
    /// `segments_per_test[n]`: how many tests drove `n` segments.
    pub segments_per_test: Vec<usize>,
}

/// One probe and fault type of [`CoverageRecord::faults`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultCoverageRecord {
    /// The probe (`uwb_range_50`, `uwb_travel_dist`, `uwb_yaw`).
    pub probe: String,
    /// The fault type (`OFFSET`, `AMPLIFICATION`, `SET_TO`, `BITFLIP`).
    pub kind: String,
    /// Fault commands of that probe and type in the tests' plans.
    pub planned: usize,
    /// Sent and confirmed by the car.
    pub confirmed: usize,
    /// Estimated to begin acting before their test's drive ended.
    pub acted: usize,
}
