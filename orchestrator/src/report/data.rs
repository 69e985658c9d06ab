//! What a report shows, read from a directory: a campaign's record, its case files and the state
//! samples of its recording split by test; a replay's comparison and its runs; a shrink's report.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use scenarios::Scenario;
use trajgen::Point;

use super::ReportError;
use crate::recording::{
    AckOutcome, CarCommand, CarStateRecord, CommandAck, CommandSent, Recording, Stamped, TestEvent,
    TestEventKind,
};
use crate::runner::RECORDING_FILE;
use campaign::case::{CampaignRecord, Case};
use campaign::replay::{Comparison, REPLAY_FILE, ReplayRun};
use campaign::shrink::{MINIMAL_FILE, SHRINK_FILE, ShrinkReport};

pub(crate) use crate::runner::CAMPAIGN_FILE;

/// One state sample of a test, on the test's clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Sample {
    /// Seconds since the test began (the case file's time base: `fault_places`, `abort.at`).
    pub t_s: f64,
    /// The RTK (fused) position.
    pub rtk: Point,
    /// The UWB position (not finite when the car had none).
    pub uwb: Point,
    /// |UWB − RTK|, metres, when both are finite.
    pub deviation_m: Option<f64>,
}

/// How a test's beginning was found in the recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Origin {
    /// The answer to the test's `set_autopilot` (the runner starts the test's clock then).
    Autopilot,
    /// The test's start event (a few round trips earlier: the start route's upload).
    StartEvent,
}

/// A test's samples from the recording.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Track {
    /// The samples from the test's start event to its end event, in time order.
    pub samples: Vec<Sample>,
    /// How `t_s = 0` was found.
    pub origin: Origin,
    /// `t_s = 0` on the recording's clock (log time, ns since the campaign started).
    pub zero_ns: u64,
}

/// A test: its case file and its samples.
#[derive(Debug, Clone)]
pub(crate) struct TestData {
    /// Its index in the campaign.
    pub index: usize,
    /// The case file's name in the run directory.
    pub file: String,
    /// The case.
    pub case: Case,
    /// Its samples, when the recording has them.
    pub track: Option<Track>,
}

/// A campaign's run directory.
#[derive(Debug, Clone)]
pub(crate) struct CampaignData {
    /// The directory.
    pub dir: PathBuf,
    /// `campaign.json`.
    pub record: CampaignRecord,
    /// Every case file, by test index.
    pub tests: Vec<TestData>,
    /// The scenario's canonical TOML from the recording (`drivecheck.scenario`), if any.
    pub recorded_scenario: Option<String>,
    /// `twin.json`, when a twin check of the run wrote one.
    pub twin: Option<campaign::files::TwinCheck>,
    /// What the page should say about missing or unreadable parts.
    pub notes: Vec<String>,
}

/// A replay directory.
#[derive(Debug, Clone)]
pub(crate) struct ReplayData {
    /// The directory.
    pub dir: PathBuf,
    /// `replay.json`.
    pub comparison: Comparison,
    /// Each run's directory, when it could be read.
    pub runs: Vec<(ReplayRun, Option<CampaignData>)>,
    /// What the page should say about missing or unreadable parts.
    pub notes: Vec<String>,
}

/// A shrink directory.
#[derive(Debug, Clone)]
pub(crate) struct ShrinkData {
    /// The directory.
    pub dir: PathBuf,
    /// `shrink.json`.
    pub report: ShrinkReport,
    /// `minimal.json`, when it could be read.
    pub minimal: Option<Case>,
    /// What the page should say about missing or unreadable parts.
    pub notes: Vec<String>,
}

/// What a directory holds.
#[derive(Debug, Clone)]
pub(crate) enum Directory {
    /// A campaign (or one run of a replay).
    Campaign(Box<CampaignData>),
    /// A replay of a case.
    Replay(Box<ReplayData>),
    /// A shrink of a case.
    Shrink(Box<ShrinkData>),
}

impl Directory {
    /// Reads `dir`: a replay directory (`replay.json`), a shrink directory (`shrink.json`) or a
    /// run directory (`campaign.json`).
    pub(crate) fn read(dir: &Path) -> Result<Self, ReportError> {
        if !dir.is_dir() {
            return Err(ReportError::NotADirectory {
                dir: dir.to_owned(),
            });
        }
        if dir.join(REPLAY_FILE).is_file() {
            return read_replay(dir).map(|d| Directory::Replay(Box::new(d)));
        }
        if dir.join(SHRINK_FILE).is_file() {
            return read_shrink(dir).map(|d| Directory::Shrink(Box::new(d)));
        }
        if dir.join(CAMPAIGN_FILE).is_file() {
            return read_campaign(dir).map(|d| Directory::Campaign(Box::new(d)));
        }
        Err(ReportError::NotARunDirectory {
            dir: dir.to_owned(),
        })
    }
}

fn read_text(path: &Path) -> Result<String, ReportError> {
    std::fs::read_to_string(path).map_err(|error| ReportError::Read {
        path: path.to_owned(),
        error,
    })
}

fn invalid(path: &Path, error: impl std::fmt::Display) -> ReportError {
    ReportError::Invalid {
        path: path.to_owned(),
        message: error.to_string(),
    }
}

/// Reads a run directory: `campaign.json`, every `case-NNN.json` and, when present,
/// `campaign.mcap` (an unreadable recording is a note, not an error: the tables still help).
pub(crate) fn read_campaign(dir: &Path) -> Result<CampaignData, ReportError> {
    let path = dir.join(CAMPAIGN_FILE);
    let record = CampaignRecord::from_json(&read_text(&path)?).map_err(|e| invalid(&path, e))?;
    let entries = std::fs::read_dir(dir).map_err(|error| ReportError::Read {
        path: dir.to_owned(),
        error,
    })?;
    let mut files: Vec<(usize, String)> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| e.file_name().to_str().map(str::to_owned))
        .filter_map(|name| {
            let index = name.strip_prefix("case-")?.strip_suffix(".json")?;
            Some((index.parse().ok()?, name))
        })
        .collect();
    files.sort();
    let mut tests = Vec::new();
    for (index, file) in files {
        let path = dir.join(&file);
        let case = Case::from_json(&read_text(&path)?).map_err(|e| invalid(&path, e))?;
        tests.push(TestData {
            index: case.test_index.unwrap_or(index),
            file,
            case,
            track: None,
        });
    }
    let mut notes = Vec::new();
    let mut recorded_scenario = None;
    let recording_path = dir.join(RECORDING_FILE);
    if recording_path.is_file() {
        recorded_scenario = read_tracks(&recording_path, &mut tests, &mut notes);
    } else {
        notes.push(format!(
            "{} does not exist: no tracks or plots",
            recording_path.display()
        ));
    }
    let twin_path = dir.join(campaign::twin::TWIN_FILE);
    let twin = match std::fs::read_to_string(&twin_path) {
        Err(_) => None,
        Ok(text) => match campaign::files::TwinCheck::from_json(&text) {
            Ok(twin) => Some(twin),
            Err(e) => {
                notes.push(format!("{}: {e}", twin_path.display()));
                None
            }
        },
    };
    Ok(CampaignData {
        dir: dir.to_owned(),
        record,
        tests,
        recorded_scenario,
        twin,
        notes,
    })
}

/// Reads the recording at `path` and gives each test its track; the recording's copy of the
/// scenario. A test at a time when the recording has test spans (a campaign on fresh simulated
/// cars, `docs/scaling.md`), so that a large campaign's recording is never in memory decoded
/// whole; what no span claims (a recording of one car for the whole campaign) is read at once.
fn read_tracks(path: &Path, tests: &mut [TestData], notes: &mut Vec<String>) -> Option<String> {
    let mut spans = match crate::recording::Spans::open(path) {
        Ok(spans) => spans,
        Err(e) => {
            notes.push(format!("{e}; no tracks or plots"));
            return None;
        }
    };
    let by_index: BTreeMap<usize, usize> = tests
        .iter()
        .enumerate()
        .map(|(i, t)| (t.index, i))
        .collect();
    for span in spans.by_ref() {
        let span = match span {
            Ok(span) => span,
            Err(why) => {
                notes.push(format!(
                    "{} is cut short ({why}): the tracks end where it does",
                    path.display()
                ));
                break;
            }
        };
        let recording = Recording::from_held(span.messages);
        let mine = match span.test_index.and_then(|t| by_index.get(&t)) {
            Some(&i) => std::slice::from_mut(&mut tests[i]),
            None => &mut tests[..],
        };
        match split_tracks(&recording, mine) {
            Ok(mut tracks) => {
                for test in mine.iter_mut() {
                    if let Some(track) = tracks.remove(&test.index) {
                        test.track = Some(track);
                    }
                }
            }
            Err(e) => notes.push(format!("{}: {e}; no tracks or plots", path.display())),
        }
    }
    spans
        .metadata("drivecheck.scenario")
        .and_then(|m| m.get("toml"))
        .cloned()
}

fn read_replay(dir: &Path) -> Result<ReplayData, ReportError> {
    let path = dir.join(REPLAY_FILE);
    let comparison = Comparison::from_json(&read_text(&path)?).map_err(|e| invalid(&path, e))?;
    let mut notes = Vec::new();
    let mut runs = Vec::new();
    for run in &comparison.runs {
        let run_dir = dir.join(&run.dir);
        let data = if run_dir.join(CAMPAIGN_FILE).is_file() {
            match read_campaign(&run_dir) {
                Ok(data) => Some(data),
                Err(e) => {
                    notes.push(e.to_string());
                    None
                }
            }
        } else {
            notes.push(format!(
                "{} does not exist: run {} is shown from {REPLAY_FILE} only",
                run_dir.join(CAMPAIGN_FILE).display(),
                run.dir
            ));
            None
        };
        runs.push((run.clone(), data));
    }
    Ok(ReplayData {
        dir: dir.to_owned(),
        comparison,
        runs,
        notes,
    })
}

fn read_shrink(dir: &Path) -> Result<ShrinkData, ReportError> {
    let path = dir.join(SHRINK_FILE);
    let report = ShrinkReport::from_json(&read_text(&path)?).map_err(|e| invalid(&path, e))?;
    let mut notes = Vec::new();
    let minimal_path = dir.join(MINIMAL_FILE);
    let minimal = match read_text(&minimal_path) {
        Ok(text) => match Case::from_json(&text) {
            Ok(case) => Some(case),
            Err(e) => {
                notes.push(invalid(&minimal_path, e).to_string());
                None
            }
        },
        Err(e) => {
            notes.push(e.to_string());
            None
        }
    };
    Ok(ShrinkData {
        dir: dir.to_owned(),
        report,
        minimal,
        notes,
    })
}

/// A test's times in the recording, ns of the run's clock.
#[derive(Debug, Clone, Copy, Default)]
struct Times {
    started: Option<u64>,
    ended: Option<u64>,
    autopilot: Option<u64>,
}

/// Splits the recording's `/car/state` samples by test: those logged between the test's start
/// and end events (`/tests`), timed from the test's beginning. The runner starts a test's clock
/// (the time base of `fault_places` and `abort.at`) once the car acknowledged the test's
/// `set_autopilot`, right after uploading the start route; that acknowledgement's log time is
/// `t = 0` (or, when it is missing, the start event, a few round trips earlier).
fn split_tracks(
    recording: &Recording,
    tests: &[TestData],
) -> Result<BTreeMap<usize, Track>, crate::recording::RecordingError> {
    let mut times: BTreeMap<usize, Times> = BTreeMap::new();
    for event in recording.messages::<TestEvent>()? {
        let entry = times.entry(event.message.test_index).or_default();
        match event.message.event {
            TestEventKind::Started { .. } => {
                entry.started.get_or_insert(event.log_time_ns);
            }
            TestEventKind::Ended { .. } => entry.ended = Some(event.log_time_ns),
        }
    }
    let acks: BTreeMap<u64, (u64, bool)> = recording
        .messages::<CommandAck>()?
        .into_iter()
        .map(|a| {
            let acked = matches!(a.message.outcome, AckOutcome::Acked);
            (a.message.id, (a.log_time_ns, acked))
        })
        .collect();
    for sent in recording.messages::<CommandSent>()? {
        let (Some(test), CarCommand::SetAutopilot { active: true, .. }) =
            (sent.message.test_index, &sent.message.command)
        else {
            continue;
        };
        if let (Some(entry), Some(&(at, true))) = (times.get_mut(&test), acks.get(&sent.message.id))
        {
            entry.autopilot.get_or_insert(at);
        }
    }
    // Log time, not the record's own `received_at_ns`: in a campaign on fresh simulated cars
    // (`run --jobs`) the record's times count from its test's start, log time from the campaign's.
    let mut states: Vec<Stamped<CarStateRecord>> = recording.messages::<CarStateRecord>()?;
    states.sort_by_key(|s| s.log_time_ns);
    let starts: Vec<u64> = times.values().filter_map(|t| t.started).collect();
    let mut tracks = BTreeMap::new();
    for test in tests {
        let Some(t) = times.get(&test.index) else {
            continue;
        };
        let Some(started) = t.started else {
            continue;
        };
        // Without an end event (a killed campaign) the test lasts until the next one starts.
        let ended = t.ended.unwrap_or_else(|| {
            starts
                .iter()
                .copied()
                .filter(|&s| s > started)
                .min()
                .unwrap_or(u64::MAX)
        });
        let (zero, origin) = match t.autopilot {
            Some(at) if at >= started && at <= ended => (at, Origin::Autopilot),
            _ => (started, Origin::StartEvent),
        };
        let from = states.partition_point(|s| s.log_time_ns < started);
        let samples = states[from..]
            .iter()
            .take_while(|s| s.log_time_ns <= ended)
            .map(
                |Stamped {
                     log_time_ns,
                     message: s,
                     ..
                 }| Sample {
                    t_s: (*log_time_ns as f64 - zero as f64) / 1e9,
                    rtk: Point::new(s.rtk.x, s.rtk.y),
                    uwb: Point::new(s.uwb.x, s.uwb.y),
                    deviation_m: s.deviation_m.filter(|d| d.is_finite()),
                },
            )
            .collect();
        tracks.insert(
            test.index,
            Track {
                samples,
                origin,
                zero_ns: zero,
            },
        );
    }
    Ok(tracks)
}

/// The scenario to draw maps with, and what the page should say about it: `given` (checked
/// against the record's hash), else the recording's own copy, else the bundled scenario of that
/// name (checked against the hash).
pub(crate) fn scenario_for(
    name: &str,
    hash: Option<&str>,
    given: Option<&Scenario>,
    recorded_toml: Option<&str>,
) -> (Option<Scenario>, Vec<String>) {
    let mut notes = Vec::new();
    let mismatch = |scenario: &Scenario| {
        let actual = scenario.hash();
        match hash {
            Some(h) if h == actual => None,
            Some(h) => Some(format!(
                "scenario `{}` hashes to {}, but the run was recorded in `{name}` with hash {}: \
                 the maps may show another area",
                scenario.name,
                short(&actual),
                short(h)
            )),
            None => None,
        }
    };
    if let Some(scenario) = given {
        notes.extend(mismatch(scenario));
        return (Some(scenario.clone()), notes);
    }
    if let Some(toml) = recorded_toml {
        match scenarios::from_toml_str(toml, "the recording's drivecheck.scenario") {
            Ok(loaded) if mismatch(&loaded.scenario).is_none() => {
                return (Some(loaded.scenario), notes);
            }
            Ok(_) => notes.push(
                "the recording's scenario does not hash to the run's scenario hash".to_owned(),
            ),
            Err(e) => notes.push(format!("the recording's scenario cannot be read: {e}")),
        }
    }
    if scenarios::bundled::text(name).is_none() {
        notes.push(format!(
            "scenario `{name}` is neither in the recording nor bundled: no maps (give its file \
             with --scenario)"
        ));
        return (None, notes);
    }
    match scenarios::bundled::load(name) {
        Ok(loaded) => {
            notes.extend(mismatch(&loaded.scenario));
            (Some(loaded.scenario), notes)
        }
        Err(e) => {
            notes.push(format!("bundled scenario `{name}`: {e}; no maps"));
            (None, notes)
        }
    }
}

/// The first 12 hex digits of a hash.
pub(crate) fn short(hash: &str) -> &str {
    hash.get(..12).unwrap_or(hash)
}
