//! What a report shows, read from a directory: a campaign's record, its case files and the state
//! samples of its recording split by test; a replay's comparison and its runs; a shrink's report.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use scenarios::Scenario;
use trajgen::Point;

use super::ReportError;
use campaign::case::{CampaignRecord, Case, TestTiming};
use campaign::oracle::Verdict;
use campaign::replay::{Comparison, REPLAY_FILE, ReplayRun};
use campaign::shrink::{MINIMAL_FILE, SHRINK_FILE, ShrinkReport};
use recording::{
    AckOutcome, CarCommand, CarStateRecord, CommandAck, CommandSent, Recording, Stamped, TestEvent,
    TestEventKind, Topic,
};
use runner::RECORDING_FILE;
use runner::store::{RunStore, StoreError};

pub use runner::CAMPAIGN_FILE;

/// One state sample of a test, on the test's clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
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
pub enum Origin {
    /// The answer to the test's `set_autopilot` (the runner starts the test's clock then).
    Autopilot,
    /// The test's start event (a few round trips earlier: the start route's upload).
    StartEvent,
}

/// A test's samples from the recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// The samples from the test's start event to its end event, in time order.
    pub samples: Vec<Sample>,
    /// How `t_s = 0` was found.
    pub origin: Origin,
    /// `t_s = 0` on the recording's clock (log time, ns since the campaign started).
    pub zero_ns: u64,
}

/// A test: its case file and its samples.
#[derive(Debug, Clone)]
pub struct TestData {
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
pub struct CampaignData {
    /// Every case file, by test index.
    pub tests: Vec<TestData>,
    /// The scenario's canonical TOML from the recording (`drivecheck.scenario`), if any.
    pub recorded_scenario: Option<String>,
    /// What the page should say about missing or unreadable parts.
    pub notes: Vec<String>,
}

/// A replay directory.
#[derive(Debug, Clone)]
pub struct ReplayData {
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
pub struct ShrinkData {
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
pub enum Directory {
    /// A campaign (or one run of a replay): read a test at a time as its page is written.
    Campaign,
    /// A replay of a case.
    Replay(Box<ReplayData>),
    /// A shrink of a case.
    Shrink(Box<ShrinkData>),
}

impl Directory {
    /// Reads `dir`: a replay directory (`replay.json`), a shrink directory (`shrink.json`) or a
    /// run directory (`campaign.json`).
    pub fn read(dir: &Path) -> Result<Self, ReportError> {
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
            return Ok(Directory::Campaign);
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

/// `campaign.json` of the run directory `dir`.
pub fn read_record(dir: &Path) -> Result<CampaignRecord, ReportError> {
    let path = RunStore::new(dir).campaign();
    CampaignRecord::from_json(&read_text(&path)?).map_err(|e| invalid(&path, e))
}

/// Refuses the recording of the run directory `dir` when it is another campaign's than
/// `campaign.json`'s ([`RunStore::check_recording`]): nothing is drawn or explained from a
/// recording beside cases it does not belong to. Without a recording or a record, nothing to
/// check.
pub fn check_recording(dir: &Path) -> Result<(), ReportError> {
    let store = RunStore::new(dir);
    let path = store.recording();
    if !path.is_file() || !store.campaign().is_file() {
        return Ok(());
    }
    let record = read_record(dir)?;
    Ok(store.check_recording(&path, record.seed)?)
}

/// The case files of the run directory `dir` (`case-NNN.json`), by the index in their names.
pub fn case_files(dir: &Path) -> Result<Vec<(usize, String)>, ReportError> {
    let files = RunStore::new(dir)
        .case_files()
        .map_err(|error| match error {
            StoreError::Read { path, source } => ReportError::Read {
                path,
                error: source,
            },
            other => ReportError::Invalid {
                path: dir.to_owned(),
                message: other.to_string(),
            },
        })?;
    Ok(files
        .into_iter()
        .filter_map(|(index, path)| Some((index, path.file_name()?.to_str()?.to_owned())))
        .collect())
}

/// The case file `file` of the run directory `dir`.
pub fn read_case(dir: &Path, file: &str) -> Result<Case, ReportError> {
    let path = dir.join(file);
    Case::from_json(&read_text(&path)?).map_err(|e| invalid(&path, e))
}

/// `twin.json` of `dir`, when a twin check of the run wrote one (an unreadable one is a note).
pub fn read_twin(dir: &Path, notes: &mut Vec<String>) -> Option<campaign::files::TwinCheck> {
    let twin_path = dir.join(campaign::twin::TWIN_FILE);
    match std::fs::read_to_string(&twin_path) {
        Err(_) => None,
        Ok(text) => match campaign::files::TwinCheck::from_json(&text) {
            Ok(twin) => Some(twin),
            Err(e) => {
                notes.push(format!("{}: {e}", twin_path.display()));
                None
            }
        },
    }
}

/// Reads a run directory: `campaign.json`, every `case-NNN.json` and, when present,
/// `campaign.mcap` (an unreadable recording is a note, not an error: the tables still help).
/// Every test's case and track in memory: for a replay's runs (one test each) and `calibrate`'s
/// fault-free run; a campaign's page and `explain` read a test at a time instead
/// (`report::campaign`, [`each_test`]).
pub fn read_campaign(dir: &Path) -> Result<CampaignData, ReportError> {
    // A run directory has its record, even where only its tests are shown.
    read_record(dir)?;
    let mut tests = Vec::new();
    for (index, file) in case_files(dir)? {
        let case = read_case(dir, &file)?;
        tests.push(TestData {
            index: case.test_index.unwrap_or(index),
            file,
            case,
            track: None,
        });
    }
    let mut notes = Vec::new();
    // A recording of another campaign is refused, not a note: its tracks would be drawn as
    // these cases'.
    check_recording(dir)?;
    let recorded_scenario = read_tracks(dir, &mut tests, &mut notes);
    Ok(CampaignData {
        tests,
        recorded_scenario,
        notes,
    })
}

/// What a test's row in the tests table, the summary and the choice of its section need: a few
/// numbers of its case file (the case itself is read again when its section is drawn).
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Its index in the campaign.
    pub index: usize,
    /// The case file's name in the run directory.
    pub file: String,
    /// Its verdict (`None`: not run).
    pub verdict: Option<Verdict>,
    /// Why it failed or was aborted.
    pub reason: Option<String>,
    /// Its largest deviation, metres.
    pub worst_deviation_m: Option<f64>,
    /// Segments judged (driven).
    pub segments: usize,
    /// Faults placed.
    pub faults: usize,
    /// Its reset and drive times.
    pub timing: Option<TestTiming>,
}

impl Row {
    /// The row of test `index`, case file `file`.
    pub fn of(index: usize, file: String, case: &Case) -> Self {
        let summary = runner::TestSummary::of(index, String::new(), case);
        Self {
            index,
            file,
            verdict: case.verdict,
            reason: case.reason.clone(),
            worst_deviation_m: summary.worst_deviation_m,
            segments: case.segments.len(),
            faults: case.fault_places.len(),
            timing: case.timing,
        }
    }
}

/// Reads the run directory's case files one at a time: each test's row, and `each` given every
/// case (the coverage) before it is dropped.
pub fn read_rows(dir: &Path, mut each: impl FnMut(&Case)) -> Result<Vec<Row>, ReportError> {
    let mut rows = Vec::new();
    for (index, file) in case_files(dir)? {
        let case = read_case(dir, &file)?;
        each(&case);
        rows.push(Row::of(case.test_index.unwrap_or(index), file, &case));
    }
    Ok(rows)
}

/// Reads the recording of the run directory `dir` a span at a time (the messages of one test,
/// or those no test's span claims: a recording of one car for the whole campaign, read at
/// once), giving `each` the span's test and messages and the recording's copy of the scenario
/// (`drivecheck.scenario`, written before the first test); `each` keeps what it needs and the
/// span is dropped. What is missing or damaged is a note. The recording's copy of the scenario.
pub fn read_spans(
    dir: &Path,
    only: Option<usize>,
    notes: &mut Vec<String>,
    mut each: impl FnMut(
        Option<usize>,
        Recording,
        Option<&str>,
        &mut Vec<String>,
    ) -> Result<(), ReportError>,
) -> Result<Option<String>, ReportError> {
    let path = dir.join(RECORDING_FILE);
    if !path.is_file() {
        notes.push(format!(
            "{} does not exist: no tracks or plots",
            path.display()
        ));
        return Ok(None);
    }
    check_recording(dir)?;
    // One test: from its place in a finished file's index, else read from the start (to it).
    let opened = match only {
        Some(test) => recording::Spans::open_test(&path, test)
            .transpose()
            .unwrap_or_else(|| recording::Spans::open(&path)),
        None => recording::Spans::open(&path),
    };
    let mut spans = match opened {
        Ok(spans) => spans,
        Err(e) => {
            notes.push(format!("{e}; no tracks or plots"));
            return Ok(None);
        }
    };
    let scenario = |spans: &recording::Spans<_>| {
        spans
            .metadata("drivecheck.scenario")
            .and_then(|m| m.get("toml"))
            .cloned()
    };
    let mut recorded = None;
    while let Some(span) = spans.next() {
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
        if recorded.is_none() {
            recorded = scenario(&spans);
        }
        let test = span.test_index;
        let recording = Recording::from_held(span.messages);
        each(test, recording, recorded.as_deref(), notes)?;
        if only.is_some() && test == only {
            break;
        }
    }
    Ok(scenario(&spans).or(recorded))
}

/// What [`each_test`] read besides the tests.
#[derive(Debug)]
pub struct EachTest {
    /// The scenario chosen (see [`scenario_for`]), if any.
    pub scenario: Option<Scenario>,
    /// What was missing or damaged, and what the choice of scenario said.
    pub notes: Vec<String>,
}

/// Reads the run directory `dir` a test at a time, in memory bounded by one test whatever the
/// campaign's size: every test `wanted` selects (by index and case file name) is given to
/// `each` with its case and, when the recording has them, its samples; with the scenario
/// [`scenario_for`] chooses (`given`, else the recording's copy, else the bundled one). Tests
/// come in the recording's order (each in its span), then those it holds no samples of.
pub fn each_test(
    dir: &Path,
    given: Option<&Scenario>,
    wanted: impl Fn(usize, &str) -> bool,
    mut each: impl FnMut(TestData, Option<&Scenario>) -> Result<(), ReportError>,
) -> Result<EachTest, ReportError> {
    let record = read_record(dir)?;
    let mut files: BTreeMap<usize, String> = case_files(dir)?
        .into_iter()
        .filter(|(index, file)| wanted(*index, file))
        .collect();
    let mut chosen: Option<(Option<Scenario>, Vec<String>)> = None;
    let choose = |recorded: Option<&str>| {
        scenario_for(
            &record.scenario.name,
            record.scenario.hash.as_deref(),
            given,
            recorded,
        )
    };
    let mut notes = Vec::new();
    let path = dir.join(RECORDING_FILE);
    // A single test is read from its place in the recording.
    let only = match (files.len(), files.keys().next()) {
        (1, Some(&test)) => Some(test),
        _ => None,
    };
    read_spans(dir, only, &mut notes, |test, recording, recorded, notes| {
        let (scenario, _) = chosen.get_or_insert_with(|| choose(recorded));
        // A test's span gives its track; one no test claims (a car recorded for the whole
        // campaign) any test's it holds.
        let targets: Vec<usize> = match test {
            Some(t) if files.contains_key(&t) => vec![t],
            Some(_) => return Ok(()),
            None => files.keys().copied().collect(),
        };
        let tracks = match Tracks::split(&recording) {
            Ok(tracks) => tracks,
            Err(e) => {
                notes.push(format!("{}: {e}; no tracks or plots", path.display()));
                return Ok(());
            }
        };
        for index in targets {
            let Some(track) = tracks.track(index) else {
                continue;
            };
            let file = files.remove(&index).unwrap_or_default();
            let case = read_case(dir, &file)?;
            each(
                TestData {
                    index: case.test_index.unwrap_or(index),
                    file,
                    case,
                    track: Some(track),
                },
                scenario.as_ref(),
            )?;
        }
        Ok(())
    })?;
    let (scenario, mut chose) = chosen.unwrap_or_else(|| choose(None));
    for (index, file) in std::mem::take(&mut files) {
        let case = read_case(dir, &file)?;
        each(
            TestData {
                index: case.test_index.unwrap_or(index),
                file,
                case,
                track: None,
            },
            scenario.as_ref(),
        )?;
    }
    chose.append(&mut notes);
    Ok(EachTest {
        scenario,
        notes: chose,
    })
}

/// Reads the recording of `dir` and gives each test its track (see [`read_spans`]); the
/// recording's copy of the scenario.
fn read_tracks(dir: &Path, tests: &mut [TestData], notes: &mut Vec<String>) -> Option<String> {
    let path = dir.join(RECORDING_FILE);
    let by_index: BTreeMap<usize, usize> = tests
        .iter()
        .enumerate()
        .map(|(i, t)| (t.index, i))
        .collect();
    let read = read_spans(dir, None, notes, |test, recording, _, notes| {
        let mine = match test.and_then(|t| by_index.get(&t)) {
            Some(&i) => std::slice::from_mut(&mut tests[i]),
            None => &mut tests[..],
        };
        match Tracks::split(&recording) {
            Ok(tracks) => {
                for test in mine.iter_mut() {
                    if let Some(track) = tracks.track(test.index) {
                        test.track = Some(track);
                    }
                }
            }
            Err(e) => notes.push(format!("{}: {e}; no tracks or plots", path.display())),
        }
        Ok(())
    });
    read.unwrap_or_default()
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

/// The recording's `/car/state` samples and when each test began and ended, to split the
/// samples by test ([`Tracks::track`]).
pub struct Tracks {
    times: BTreeMap<usize, Times>,
    states: Vec<Stamped<CarStateRecord>>,
    starts: Vec<u64>,
}

/// The topics [`Tracks::split`] reads: the test events, the commands and their
/// acknowledgements, the state samples and the poses joined with them.
pub const TRACK_TOPICS: [Topic; 6] = [
    Topic::Tests,
    Topic::Commands,
    Topic::Acks,
    Topic::CarState,
    Topic::FoxgloveRtk,
    Topic::FoxgloveUwb,
];

impl Tracks {
    /// Reads the test events, the autopilot acknowledgements and the state samples of
    /// `recording`. The runner starts a test's clock (the time base of `fault_places` and
    /// `abort.at`) once the car acknowledged the test's `set_autopilot`, right after uploading
    /// the start route; that acknowledgement's log time is `t = 0` (or, when it is missing, the
    /// start event, a few round trips earlier).
    pub fn split(recording: &Recording) -> Result<Self, recording::RecordingError> {
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
            if let (Some(entry), Some(&(at, true))) =
                (times.get_mut(&test), acks.get(&sent.message.id))
            {
                entry.autopilot.get_or_insert(at);
            }
        }
        // Log time, not the record's own `received_at_ns`: in a campaign on fresh simulated
        // cars (`run --jobs`) the record's times count from its test's start, log time from
        // the campaign's.
        let mut states: Vec<Stamped<CarStateRecord>> = recording.messages::<CarStateRecord>()?;
        states.sort_by_key(|s| s.log_time_ns);
        let starts: Vec<u64> = times.values().filter_map(|t| t.started).collect();
        Ok(Self {
            times,
            states,
            starts,
        })
    }

    /// Test `index`'s samples: those logged between its start and end events (`/tests`), timed
    /// from its beginning; `None` when the recording has no start event of it.
    pub fn track(&self, index: usize) -> Option<Track> {
        let t = self.times.get(&index)?;
        let started = t.started?;
        // Without an end event (a killed campaign) the test lasts until the next one starts.
        let ended = t.ended.unwrap_or_else(|| {
            self.starts
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
        let from = self.states.partition_point(|s| s.log_time_ns < started);
        let samples = self.states[from..]
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
        Some(Track {
            samples,
            origin,
            zero_ns: zero,
        })
    }
}

/// The scenario to draw maps with, and what the page should say about it: `given` (checked
/// against the record's hash), else the recording's own copy, else the bundled scenario of that
/// name (checked against the hash).
pub fn scenario_for(
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
pub fn short(hash: &str) -> &str {
    hash.get(..12).unwrap_or(hash)
}
