//! The run directory: `campaign.json` (written when the campaign starts, and again with its end
//! time and summary when it ends, however it ends), one case file per test,
//! `case-000.json`, `case-001.json`, … in the formats of [`campaign::files`], and the recording
//! `campaign.mcap` (written by [`recording::Recorder`], see `docs/recording.md`).

use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use scenarios::Scenario;

use super::{RunConfig, RunError};
use campaign::coverage::CoverageBuilder;
use campaign::files::{
    CAMPAIGN_FORMAT, CAMPAIGN_SCHEMA_VERSION, CampaignRecord, CampaignSummary, CarRun, Case,
    Header, ScenarioRef, Session, Settings,
};
use campaign::oracle::Verdict;
use campaign::safety::SafetyConfig;
use campaign::streaming::StreamingConfig;

use crate::store::RunStore;
pub use crate::store::{CAMPAIGN_FILE, RECORDING_FILE};

/// One test of a campaign, as the final table shows it (and `--json` prints it).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TestSummary {
    /// The test's index.
    pub test_index: usize,
    /// Its case file, relative to the run directory.
    pub file: String,
    /// Its verdict (`None` if it never ran).
    pub verdict: Option<Verdict>,
    /// Why it failed or was aborted.
    pub reason: Option<String>,
    /// Its largest deviation of UWB from RTK, metres.
    pub worst_deviation_m: Option<f64>,
    /// Times the car reached the end of its route during the test.
    pub starvations: usize,
    /// The smallest margin left at an append, seconds.
    pub smallest_margin_s: Option<f64>,
    /// The car that drove it, in a campaign on several cars.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub car: Option<String>,
    /// It was cut off (aborted `interrupted` or `link lost`): `run --resume` drives it again.
    #[serde(skip)]
    pub cut_off: bool,
}

/// What a finished campaign wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct CampaignReport {
    /// The run directory.
    pub dir: PathBuf,
    /// `campaign.json` as written at the end.
    pub record: CampaignRecord,
    /// Every test that was started, in order.
    pub tests: Vec<TestSummary>,
}

impl CampaignReport {
    /// The case of `test` (one of [`CampaignReport::tests`]) as its case file holds it: read
    /// again when asked, so that a campaign of any size keeps only its rows in memory.
    pub fn case(&self, test: &TestSummary) -> Result<Case, RunError> {
        let path = self.dir.join(&test.file);
        let text = std::fs::read_to_string(&path).map_err(|source| RunError::Io {
            path: path.clone(),
            source,
        })?;
        Case::from_json(&text).map_err(|source| RunError::CaseFile {
            path,
            source: Box::new(source),
        })
    }

    /// Every test's case, in order, read one at a time (see [`CampaignReport::case`]).
    pub fn cases(&self) -> impl Iterator<Item = Result<Case, RunError>> + '_ {
        self.tests.iter().map(|test| self.case(test))
    }
}

/// A run directory being written.
#[derive(Debug)]
pub struct RunDirectory {
    path: PathBuf,
    record: CampaignRecord,
    tests: Vec<TestSummary>,
    /// The scenario has no anchors: UWB is not tested.
    no_anchors: bool,
    /// The coverage of the tests written so far.
    coverage: CoverageBuilder,
    /// The space kept back for the session's end.
    reserve: Reserve,
}

/// Space kept back on the run directory's disk while a session writes it ([`crate::store::RESERVE_FILE`]:
/// zeros, written when the session starts): when the disk fills, `campaign.json` is written
/// again with the session's end (`interrupted`) after giving this space back, instead of failing
/// and leaving the session to be taken for one that `died`. Removed when the session ends;
/// one a `kill -9` left is written over by the next session.
#[derive(Debug)]
struct Reserve {
    /// The file, while it holds the space.
    file: std::sync::Mutex<Option<PathBuf>>,
}

/// What [`Reserve`] keeps: enough for `campaign.json` twice over (the atomic write's copy beside
/// the old one), which grows by a few tens of bytes per test.
fn reserve_bytes(tests: usize) -> usize {
    const BASE: usize = 64 * 1024;
    const PER_TEST: usize = 256;
    const MOST: usize = 64 * 1024 * 1024;
    BASE.saturating_add(tests.saturating_mul(PER_TEST))
        .min(MOST)
}

impl Reserve {
    /// Writes `bytes` zeros to the reserve file of `dir`. When the disk cannot hold them the
    /// session goes on without (a full disk then ends it as before: with an error).
    fn keep(dir: &Path, bytes: usize) -> Self {
        use std::io::Write;
        let path = RunStore::new(dir).reserve();
        let written = (|| {
            let mut file = std::fs::File::create(&path)?;
            let zeros = vec![0u8; 64 * 1024];
            let mut left = bytes;
            while left > 0 {
                let n = left.min(zeros.len());
                file.write_all(&zeros[..n])?;
                left -= n;
            }
            file.sync_all()
        })();
        if written.is_err() {
            let _ = std::fs::remove_file(&path);
        }
        Self {
            file: std::sync::Mutex::new(written.is_ok().then_some(path)),
        }
    }

    /// Gives the space back; whether there was any to give.
    fn release(&self) -> bool {
        let taken = self.file.lock().map(|mut file| file.take()).ok().flatten();
        taken.is_some_and(|path| std::fs::remove_file(path).is_ok())
    }
}

impl Drop for Reserve {
    fn drop(&mut self) {
        self.release();
    }
}

impl RunDirectory {
    /// Creates the directory (and its parents) and writes the first `campaign.json`.
    pub fn create(
        config: &RunConfig,
        scenario: &Scenario,
        settings: Settings,
    ) -> Result<Self, RunError> {
        let path = config.out_dir.clone();
        if let Some(resume) = &config.resume {
            let kept: Vec<usize> = resume.kept.iter().copied().collect();
            return Self::resume(
                path,
                resume.record.clone(),
                scenario,
                &config.car_label,
                &kept,
                &resume.earlier,
            );
        }
        std::fs::create_dir_all(&path).map_err(|source| RunError::Io {
            path: path.clone(),
            source,
        })?;
        let record = CampaignRecord {
            header: Header::current(CAMPAIGN_FORMAT, CAMPAIGN_SCHEMA_VERSION),
            seed: config.campaign.seed,
            no_faults: config.campaign.no_faults,
            scenario: ScenarioRef::of(scenario),
            settings,
            car: config.car_label.clone(),
            car_profile: config
                .car_profile
                .as_ref()
                .map(recording::LoadedProfile::reference),
            car_firmware_version: None,
            car_firmware_tree_hash: config.car_firmware_tree_hash.clone(),
            started_at: rfc3339_now(),
            ended_at: None,
            summary: None,
            replay_of: config.tests.replay_of().cloned(),
            cases_from: config.tests.cases_from().cloned(),
            shard: config.shard,
            sessions: Vec::new(),
            cars: Vec::new(),
        };
        Self::start(path, record, scenario)
    }

    /// The run directory `path` (created) with `record`, its first `campaign.json` written.
    fn start(path: PathBuf, record: CampaignRecord, scenario: &Scenario) -> Result<Self, RunError> {
        let reserve = Reserve::keep(&path, reserve_bytes(record.settings.tests));
        let dir = Self {
            reserve,
            path,
            record,
            tests: Vec::new(),
            no_anchors: scenario.anchors.is_empty(),
            coverage: CoverageBuilder::of_scenario(scenario),
        };
        dir.write_record()?;
        Ok(dir)
    }

    /// Creates the run directory `path` that joins a campaign's shards (`drivecheck runs merge`)
    /// and writes its first `campaign.json`: `record` as the shards agree on it, without shard.
    pub fn merged(
        path: PathBuf,
        record: CampaignRecord,
        scenario: &Scenario,
    ) -> Result<Self, RunError> {
        std::fs::create_dir_all(&path).map_err(|source| RunError::Io {
            path: path.clone(),
            source,
        })?;
        let record = CampaignRecord {
            shard: None,
            ended_at: None,
            summary: None,
            sessions: Vec::new(),
            cars: Vec::new(),
            ..record
        };
        Self::start(path, record, scenario)
    }

    /// Opens the run directory `path` of an interrupted campaign again (`run --resume`): `record`
    /// is its `campaign.json`, `kept` the tests whose case files stay (read again for their rows
    /// and coverage), `earlier` every test a case file was written for before (`kept` and the
    /// interrupted ones). The sessions are completed (the first from the record itself; the last
    /// one before this, if it never ended, `died`, its tests those written after the sessions
    /// before it), a new session of `car` starts, and `campaign.json` is written without an end.
    pub fn resume(
        path: PathBuf,
        mut record: CampaignRecord,
        scenario: &Scenario,
        car: &str,
        kept: &[usize],
        earlier: &[usize],
    ) -> Result<Self, RunError> {
        if record.sessions.is_empty() {
            // The cars of a campaign on several cars drove its first session.
            for car in &mut record.cars {
                car.session.get_or_insert(1);
            }
            record.sessions.push(Session {
                started_at: record.started_at.clone(),
                ended_at: record.ended_at.clone(),
                car: record.car.clone(),
                tests: Vec::new(),
                end: None,
            });
        }
        // The last session's tests: those whose case file it wrote. A test an earlier session
        // listed was written by a later one when every file those sessions wrote for it was
        // since kept as a partial (it was cut off each time).
        let mut listed: std::collections::BTreeMap<usize, usize> = Default::default();
        for session in record.sessions.iter().rev().skip(1) {
            for &t in &session.tests {
                *listed.entry(t).or_default() += 1;
            }
        }
        let partials = partial_counts(&path);
        if let Some(last) = record.sessions.last_mut() {
            last.tests = earlier
                .iter()
                .copied()
                .filter(|t| {
                    listed.get(t).copied().unwrap_or(0) <= partials.get(t).copied().unwrap_or(0)
                })
                .collect();
            if last.end.is_none() {
                last.end = Some(
                    if last.ended_at.is_some() {
                        "interrupted"
                    } else {
                        "died"
                    }
                    .to_owned(),
                );
            }
        }
        // A car is credited with the tests whose case files stay: one it was cut off in (its
        // case now a partial) is driven again, by whichever car.
        for car in &mut record.cars {
            car.tests.retain(|t| kept.contains(t));
        }
        record.sessions.push(Session {
            started_at: rfc3339_now(),
            ended_at: None,
            car: car.to_owned(),
            tests: Vec::new(),
            end: None,
        });
        record.ended_at = None;
        record.summary = None;
        let reserve = Reserve::keep(&path, reserve_bytes(record.settings.tests));
        let mut dir = Self {
            reserve,
            path,
            record,
            tests: Vec::new(),
            no_anchors: scenario.anchors.is_empty(),
            coverage: CoverageBuilder::of_scenario(scenario),
        };
        for &test_index in kept {
            let file = format!("case-{test_index:03}.json");
            let case_path = dir.path.join(&file);
            let text = std::fs::read_to_string(&case_path).map_err(|source| RunError::Io {
                path: case_path.clone(),
                source,
            })?;
            let case = Case::from_json(&text).map_err(|source| RunError::CaseFile {
                path: case_path,
                source: Box::new(source),
            })?;
            dir.tests.push(summarise(test_index, file, &case));
            dir.coverage.add(&case);
        }
        dir.write_record()?;
        Ok(dir)
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// `campaign.json` as last written.
    pub fn record(&self) -> &CampaignRecord {
        &self.record
    }

    /// The campaign's settings (with the runtime constants once preflight set them).
    pub fn settings(&self) -> &Settings {
        &self.record.settings
    }

    /// Records the car's firmware version.
    pub fn set_firmware(&mut self, version: String) {
        self.record.car_firmware_version = Some(version);
    }

    /// Records the safety limits and streaming constants in force.
    pub fn set_runtime(&mut self, safety: SafetyConfig, streaming: StreamingConfig) {
        self.record.settings = self.record.settings.clone().with_runtime(safety, streaming);
    }

    /// Writes a test's case file (and keeps its row and its coverage for the report).
    pub fn write_case(&mut self, case: &Case) -> Result<(), RunError> {
        let test_index = case.test_index.unwrap_or(self.tests.len());
        let file = format!("case-{test_index:03}.json");
        let mut case = case.clone();
        if case.car_profile.is_none() {
            case.car_profile = self.record.car_profile.clone();
        }
        write(&self.path.join(&file), &case.to_json()?)?;
        if let Some(session) = self.record.sessions.last_mut() {
            session.tests.push(test_index);
        }
        if let Some(name) = &case.car
            && let Some(car) = self.record.cars.iter_mut().rev().find(|c| &c.name == name)
        {
            car.tests.push(test_index);
        }
        // In test order, also when a resumed campaign drives the tests it had not ended.
        let at = self.tests.partition_point(|t| t.test_index < test_index);
        self.tests.insert(at, summarise(test_index, file, &case));
        self.coverage.add(&case);
        Ok(())
    }

    /// Writes the case of a test that was cut off on a car that left a campaign on several cars
    /// as `case-NNN.partial-K.json` (K from 1, after any partial kept before): another car
    /// drives the test again, so it has no row.
    pub fn write_partial(&mut self, case: &Case) -> Result<PathBuf, RunError> {
        let test_index = case.test_index.unwrap_or(self.tests.len());
        let k = partial_counts(&self.path)
            .get(&test_index)
            .copied()
            .unwrap_or(0)
            + 1;
        let path = self
            .path
            .join(format!("case-{test_index:03}.partial-{k}.json"));
        write(&path, &case.to_json()?)?;
        Ok(path)
    }

    /// The cars of a campaign on several cars, as they start (added after those of the sessions
    /// before).
    pub fn add_cars(&mut self, cars: impl IntoIterator<Item = CarRun>) {
        let session = (!self.record.sessions.is_empty()).then_some(self.record.sessions.len());
        self.record
            .cars
            .extend(cars.into_iter().map(|car| CarRun { session, ..car }));
    }

    /// This session's car `name`: its firmware, why it left.
    pub fn car_mut(&mut self, name: &str) -> Option<&mut CarRun> {
        self.record.cars.iter_mut().rev().find(|c| c.name == name)
    }

    /// Writes `campaign.json` as it stands (a car left: the record says so before the end).
    pub fn write_now(&self) -> Result<(), RunError> {
        self.write_record()
    }

    /// Writes the final `campaign.json` (end time and summary) and returns the report.
    pub fn finish(self) -> Result<CampaignReport, RunError> {
        self.finish_at(rfc3339_now())
    }

    /// [`RunDirectory::finish`] with the end time `ended_at` (RFC 3339).
    pub fn finish_at(mut self, ended_at: String) -> Result<CampaignReport, RunError> {
        let summary = self.summary();
        let planned = match self.record.shard {
            Some(shard) => shard.tests(self.record.settings.tests).count(),
            None => self.record.settings.tests,
        };
        // Every planned test ended, none of them cut off by an interruption.
        let completed = summary.tests == planned && !self.tests.iter().any(|t| t.cut_off);
        if let Some(session) = self.record.sessions.last_mut() {
            session.ended_at = Some(ended_at.clone());
            session.end = Some(
                if completed {
                    "completed"
                } else {
                    "interrupted"
                }
                .to_owned(),
            );
        }
        self.record.ended_at = Some(ended_at);
        self.record.summary = Some(summary);
        self.write_record()?;
        Ok(CampaignReport {
            dir: self.path,
            record: self.record,
            tests: self.tests,
        })
    }

    fn summary(&self) -> CampaignSummary {
        let count = |v: Verdict| self.tests.iter().filter(|t| t.verdict == Some(v)).count();
        CampaignSummary {
            tests: self.tests.len(),
            passed: count(Verdict::Passed),
            failed: count(Verdict::Failed),
            aborted: count(Verdict::Aborted),
            worst_deviation_m: self
                .tests
                .iter()
                .filter_map(|t| t.worst_deviation_m)
                .max_by(f64::total_cmp),
            failing_cases: self
                .tests
                .iter()
                .filter(|t| t.verdict != Some(Verdict::Passed))
                .map(|t| t.file.clone())
                .collect(),
            uwb_not_tested: self.no_anchors.then(|| {
                "the scenario has no anchors: the UWB estimate was dead reckoning only, so no \
                 test says anything about UWB positioning"
                    .to_owned()
            }),
            coverage: Some(self.coverage.clone().finish().stats.into()),
        }
    }

    /// Writes `campaign.json`; on a full disk, once more after giving the reserve back.
    fn write_record(&self) -> Result<(), RunError> {
        let path = self.path.join(CAMPAIGN_FILE);
        let text = self.record.to_json()?;
        match write(&path, &text) {
            Err(RunError::Io { source, .. })
                if source.kind() == std::io::ErrorKind::StorageFull && self.reserve.release() =>
            {
                write(&path, &text)
            }
            written => written,
        }
    }
}

impl TestSummary {
    /// The summary of test `test_index` from its case file `file` (relative to the run
    /// directory) holding `case`.
    pub fn of(test_index: usize, file: String, case: &Case) -> Self {
        summarise(test_index, file, case)
    }
}

fn summarise(test_index: usize, file: String, case: &Case) -> TestSummary {
    let streaming = case.streaming.as_ref();
    TestSummary {
        test_index,
        file,
        verdict: case.verdict,
        reason: case.reason.clone(),
        worst_deviation_m: case
            .segments
            .iter()
            .filter_map(|s| s.oracle.stats.map(|stats| stats.max_m))
            .max_by(f64::total_cmp),
        starvations: streaming.map_or(0, |s| s.starvations_ms.len()),
        smallest_margin_s: streaming.and_then(|s| s.smallest_margin_s),
        car: case.car.clone(),
        cut_off: is_cut_off(case),
    }
}

/// How many partial cases (`case-NNN.partial-K.json`, kept by `run --resume`) each test has in
/// run directory `dir`.
fn partial_counts(dir: &Path) -> std::collections::BTreeMap<usize, usize> {
    let mut counts = std::collections::BTreeMap::new();
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let name = entry.file_name();
        let test = name
            .to_str()
            .and_then(|n| n.strip_prefix("case-"))
            .and_then(|n| n.split_once(".partial-"))
            .and_then(|(index, _)| index.parse::<usize>().ok());
        if let Some(test) = test {
            *counts.entry(test).or_default() += 1;
        }
    }
    counts
}

/// Was `case` cut off before it could end (aborted `interrupted` by a signal, or `link lost`)?
/// `run --resume` drives such a test again from its start.
pub fn is_cut_off(case: &Case) -> bool {
    use campaign::safety::AbortReason;
    case.abort
        .as_ref()
        .is_some_and(|a| matches!(a.reason, AbortReason::Interrupted | AbortReason::LinkLost))
}

fn write(path: &Path, text: &str) -> Result<(), RunError> {
    crate::atomic::write(path, format!("{text}\n")).map_err(|source| RunError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Now as RFC 3339 UTC with whole seconds, for example `2026-11-22T10:55:21Z`.
pub fn rfc3339_now() -> String {
    let (date, [h, m, s]) = utc_now();
    format!("{date}T{h:02}:{m:02}:{s:02}Z")
}

/// The default run directory name: `<UTC timestamp>-<scenario>-<seed>`, for example
/// `20261122T105521Z-parking-lot-2anchors-7`.
pub fn run_dir_name(scenario: &str, seed: u64) -> String {
    let (date, [h, m, s]) = utc_now();
    let compact: String = date.chars().filter(|c| *c != '-').collect();
    format!("{compact}T{h:02}{m:02}{s:02}Z-{scenario}-{seed}")
}

/// Creates the default run directory `root/name`, or `root/name-2`, `root/name-3`, … when
/// another campaign took it (two campaigns of one scenario and seed started in the same second on
/// one machine): creating the directory is the claim, so concurrent campaigns never share one.
pub fn claim_run_dir(root: &Path, name: &str) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(root)?;
    for attempt in 1u32.. {
        let path = match attempt {
            1 => root.join(name),
            n => root.join(format!("{name}-{n}")),
        };
        match std::fs::create_dir(&path) {
            Ok(()) => return Ok(path),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    unreachable!("u32 attempts")
}

/// The environment variable that names where run directories go (default [`DEFAULT_RUNS_DIR`]).
pub const RUNS_DIR_ENV: &str = "DRIVECHECK_RUNS_DIR";
/// Where run directories go when [`RUNS_DIR_ENV`] is not set: `runs/` in the working directory.
pub const DEFAULT_RUNS_DIR: &str = "runs";

/// Where run directories go: `$DRIVECHECK_RUNS_DIR` when set and not empty, else `runs/`.
pub fn runs_root() -> PathBuf {
    std::env::var_os(RUNS_DIR_ENV)
        .filter(|dir| !dir.is_empty())
        .map_or_else(|| PathBuf::from(DEFAULT_RUNS_DIR), PathBuf::from)
}

/// Claims the default run directory `<runs root>/<name>` ([`runs_root`], see [`claim_run_dir`]).
pub fn claim_default_run_dir(name: &str) -> Result<PathBuf, RunError> {
    let root = runs_root();
    let root = root.as_path();
    claim_run_dir(root, name).map_err(|source| RunError::Io {
        path: root.join(name),
        source,
    })
}

/// Today's date (`YYYY-MM-DD`) and the time of day in UTC.
fn utc_now() -> (String, [u64; 3]) {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, mo, d) = civil_from_days(i64::try_from(days).unwrap_or(0));
    (
        format!("{y:04}-{mo:02}-{d:02}"),
        [rem / 3600, rem % 3600 / 60, rem % 60],
    )
}

/// The proleptic Gregorian date of a day count since 1970-01-01 (H. Hinnant's algorithm).
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = u32::try_from(doy - (153 * mp + 2) / 5 + 1).unwrap_or(1);
    let m = u32::try_from(if mp < 10 { mp + 3 } else { mp - 9 }).unwrap_or(1);
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

// The file that marks a run directory as being written by a process: created with `O_EXCL`, so
// that of two processes given the same `--out` exactly one gets it; removed when the command ends.
// The claim of a process that died is taken by the next one.
use crate::store::CLAIM_FILE;

/// A command's claim of its output directory ([`claim_out_dir`]). When dropped it gives the claim
/// back, and removes the directory if the command made it and nothing was written (an error
/// before the first test leaves no empty run directory behind).
#[derive(Debug)]
pub struct OutClaim {
    dir: PathBuf,
    made: bool,
    /// The stale claim this one replaced: what its file said of its holder.
    took_over: Option<String>,
}

impl OutClaim {
    /// When this claim replaced a stale one (its process no longer runs on this host), the note
    /// that says so, for the command to print.
    pub fn stale_note(&self) -> Option<String> {
        self.took_over.as_ref().map(|holder| {
            format!(
                "{}: took over a stale claim ({holder}): that process no longer runs",
                self.dir.display()
            )
        })
    }
}

/// Claims the output directory `path` for this process, atomically: creates it (and its parents)
/// when missing, then its [`CLAIM_FILE`] with `O_EXCL`, then checks that nothing else is in it.
/// `made` says the caller just created it (the default run directories, claimed by name).
/// Another process holding the claim, or anything already in the directory, is an error naming it.
/// A claim whose process no longer runs on this host ([`holder_is_gone`]: a `kill -9`, a
/// SIGTERM before the signal handler) is stale: it is taken over ([`OutClaim::stale_note`]).
pub fn claim_out_dir(path: &Path, made: bool) -> Result<OutClaim, RunError> {
    let io = |source| RunError::Io {
        path: path.to_owned(),
        source,
    };
    let made = made || !path.exists();
    std::fs::create_dir_all(path).map_err(io)?;
    let marker = path.join(CLAIM_FILE);
    let took_over = match take_claim(&marker) {
        Ok(took_over) => took_over,
        Err(error) => {
            if made {
                let _ = std::fs::remove_dir(path);
            }
            return Err(match error {
                // Not ours: its claim file and the directory stay as they are.
                Claim::Held(holder) => RunError::OutDirClaimed {
                    path: path.to_owned(),
                    holder,
                },
                Claim::Io(e) => io(e),
            });
        }
    };
    // Ours from here: the guard gives the claim back (and the directory, if this process made
    // it and nothing was written).
    let claim = OutClaim {
        dir: path.to_owned(),
        made,
        took_over,
    };
    let others = std::fs::read_dir(path)
        .map_err(io)?
        .filter_map(Result::ok)
        .any(|entry| entry.file_name() != CLAIM_FILE);
    if others {
        return Err(RunError::OutDirUsed {
            path: path.to_owned(),
        });
    }
    Ok(claim)
}

/// Creates the claim file `marker` with `O_EXCL` (an existing one is `AlreadyExists`) and writes
/// who holds it, for another process's error: the claim is the file itself. `pid N on HOST since
/// TIME` (without ` on HOST` when this system does not say its name).
fn create_claim(marker: &Path) -> std::io::Result<()> {
    use std::io::Write;
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(marker)?;
    let host = host_name().map_or_else(String::new, |host| format!(" on {host}"));
    let _ = writeln!(
        file,
        "pid {}{host} since {}",
        std::process::id(),
        rfc3339_now()
    );
    Ok(())
}

/// This host's name (`/proc/sys/kernel/hostname`), if the system says it.
fn host_name() -> Option<String> {
    let name = std::fs::read_to_string("/proc/sys/kernel/hostname").ok()?;
    let name = name.trim();
    (!name.is_empty() && !name.contains(char::is_whitespace)).then(|| name.to_owned())
}

/// Whether the holder of a claim, as its file says (`pid N [on HOST] since TIME`), is gone: its
/// pid names no process of this host ([`crate::scratch::process_alive`], the liveness
/// check of scratch files too). A claim of another host, or one this
/// system cannot check, is never gone: it may be live. The one liveness check of every claim:
/// `run -o`, `replay -o`, `shrink -o` and `run --resume` alike.
fn holder_is_gone(holder: &str) -> bool {
    let mut words = holder.split_whitespace();
    if words.next() != Some("pid") {
        return false;
    }
    let Some(pid) = words.next().and_then(|pid| pid.parse::<u32>().ok()) else {
        return false;
    };
    let host = match (words.next(), words.next()) {
        (Some("on"), host) => host,
        _ => None,
    };
    if host.is_some_and(|host| Some(host) != host_name().as_deref()) {
        return false;
    }
    crate::scratch::process_alive(pid) == Some(false)
}

/// Claims an existing run directory again for this process (`run --resume`): its [`CLAIM_FILE`]
/// is created as [`claim_out_dir`] creates it; one already there is another process's claim,
/// refused, unless that process no longer lives ([`holder_is_gone`]: `kill -9`, a crash), when
/// the claim becomes this process's ([`OutClaim::stale_note`]). The directory is never removed by
/// the claim.
pub fn claim_run_dir_again(path: &Path) -> Result<OutClaim, RunError> {
    let marker = path.join(CLAIM_FILE);
    match take_claim(&marker) {
        Ok(took_over) => Ok(OutClaim {
            dir: path.to_owned(),
            made: false,
            took_over,
        }),
        Err(Claim::Held(holder)) => Err(RunError::OutDirClaimed {
            path: path.to_owned(),
            holder,
        }),
        Err(Claim::Io(source)) => Err(RunError::Io {
            path: marker,
            source,
        }),
    }
}

/// Why a claim could not be taken.
enum Claim {
    /// A live process holds it: who (its pid and since when), as its claim file says.
    Held(String),
    /// The system refused.
    Io(std::io::Error),
}

/// How long a claim file may stay empty (a process between creating it and writing its pid) before
/// it is taken for the claim of a process that died there.
const EMPTY_CLAIM_GRACE: std::time::Duration = std::time::Duration::from_secs(10);

/// Takes the claim `marker` for this process: creates it, or replaces the claim of a process that
/// no longer runs ([`holder_is_gone`], or it died before writing its pid), saying what that claim
/// said. A claim held by a live process, by a process of another host or one this system cannot
/// check (no `/proc`) is refused with its holder.
fn take_claim(marker: &Path) -> Result<Option<String>, Claim> {
    let mut took_over = None;
    for _ in 0..2 {
        match create_claim(marker) {
            Ok(()) => return Ok(took_over),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                let holder = std::fs::read_to_string(marker).unwrap_or_default();
                let holder = holder.trim();
                let gone = if holder.is_empty() {
                    empty_for_long(marker)
                } else {
                    holder_is_gone(holder)
                };
                if !gone {
                    return Err(Claim::Held(if holder.is_empty() {
                        "it is just starting".to_owned()
                    } else if on_another_host(holder) {
                        format!(
                            "{holder}; another host's process, which this one cannot check: if it \
                             no longer runs, remove {}",
                            marker.display()
                        )
                    } else {
                        holder.to_owned()
                    }));
                }
                // The process that held it died: its claim is void.
                match std::fs::remove_file(marker) {
                    Ok(()) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                    Err(e) => return Err(Claim::Io(e)),
                }
                took_over = Some(if holder.is_empty() {
                    "an empty claim file".to_owned()
                } else {
                    holder.to_owned()
                });
            }
            Err(e) => return Err(Claim::Io(e)),
        }
    }
    Err(Claim::Held(
        "another process claimed it at the same moment".to_owned(),
    ))
}

/// Whether a claim's holder (`pid N on HOST since TIME`) names another host than this one.
fn on_another_host(holder: &str) -> bool {
    let words: Vec<&str> = holder.split_whitespace().take(4).collect();
    matches!(words.as_slice(), ["pid", _, "on", host] if Some(*host) != host_name().as_deref())
}

/// Whether the empty claim `marker` was last written longer ago than [`EMPTY_CLAIM_GRACE`].
fn empty_for_long(marker: &Path) -> bool {
    std::fs::metadata(marker)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|at| at.elapsed().ok())
        .is_some_and(|age| age > EMPTY_CLAIM_GRACE)
}

impl Drop for OutClaim {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(self.dir.join(CLAIM_FILE));
        if self.made {
            // Fails, as it should, on a directory with anything in it.
            let _ = std::fs::remove_dir(&self.dir);
        }
    }
}

/// A run directory built aside and moved into place only when complete (`runs merge`): a
/// failure leaves nothing at the output path, and of two processes given the same output the
/// second's move fails (a directory is renamed onto a path only while that is missing or empty).
#[derive(Debug)]
pub struct Staged {
    staging: PathBuf,
    out: PathBuf,
    /// The staging directory is this process's scratch (`crate::scratch`): a signal removes it.
    scratch: Option<crate::scratch::Scratch>,
}

impl Staged {
    /// A fresh staging directory beside `out` (`.NAME.staging-PID`), after checking that `out`
    /// holds nothing.
    pub fn beside(out: &Path) -> Result<Self, RunError> {
        if is_used(out) {
            return Err(RunError::OutDirUsed {
                path: out.to_owned(),
            });
        }
        let parent = match out.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
            _ => PathBuf::from("."),
        };
        let name = out
            .file_name()
            .map_or_else(|| "run".to_owned(), |n| n.to_string_lossy().into_owned());
        let (scratch, staging) = crate::scratch::Scratch::create_named(|| {
            claim_run_dir(&parent, &format!(".{name}.staging-{}", std::process::id()))
        })
        .map_err(|source| RunError::Io {
            path: parent.clone(),
            source,
        })?;
        Ok(Self {
            staging,
            out: out.to_owned(),
            scratch: Some(scratch),
        })
    }

    /// Where to write.
    pub fn dir(&self) -> &Path {
        &self.staging
    }

    /// Moves the complete directory into place.
    pub fn commit(mut self) -> Result<(), RunError> {
        let renamed = match self.scratch.take() {
            Some(scratch) => scratch.settle(|| std::fs::rename(&self.staging, &self.out)),
            None => std::fs::rename(&self.staging, &self.out),
        };
        match renamed {
            Ok(()) => {
                std::mem::forget(self);
                Ok(())
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::DirectoryNotEmpty | std::io::ErrorKind::AlreadyExists
                ) || is_used(&self.out) =>
            {
                Err(RunError::OutDirUsed {
                    path: self.out.clone(),
                })
            }
            Err(source) => Err(RunError::Io {
                path: self.out.clone(),
                source,
            }),
        }
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.staging);
    }
}

/// Whether `path` holds something already: a file, or a directory that is not empty. A run
/// directory is always created fresh, so that no earlier run's files are overwritten or mixed in.
pub fn is_used(path: &Path) -> bool {
    match std::fs::read_dir(path) {
        Ok(mut entries) => entries.next().is_some(),
        Err(_) => path.exists(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A claim left by a process that died (a kill -9, a SIGTERM before the handler) is taken
    /// by the next `run -o DIR`; a live process's claim is not.
    #[test]
    fn a_dead_processs_claim_is_taken_and_a_live_ones_is_not() {
        let root = tempfile::tempdir().unwrap();
        let dir = root.path().join("out");
        std::fs::create_dir(&dir).unwrap();
        // A pid above any pid_max (4194304) is no process.
        std::fs::write(dir.join(CLAIM_FILE), "pid 4294967295 since then\n").unwrap();
        let claim = claim_out_dir(&dir, false).expect("the dead process's claim is taken");
        let holder = std::fs::read_to_string(dir.join(CLAIM_FILE)).unwrap();
        assert!(holder.contains(&std::process::id().to_string()), "{holder}");
        let note = claim
            .stale_note()
            .expect("it says it took over a stale claim");
        assert!(
            note.ends_with(
                "out: took over a stale claim (pid 4294967295 since then): that process no \
                 longer runs"
            ),
            "{note}"
        );
        drop(claim);
        // The same on this host by name, and for the resume.
        let host = host_name().expect("this system names its host");
        std::fs::write(
            dir.join(CLAIM_FILE),
            format!("pid 4294967295 on {host} since then\n"),
        )
        .unwrap();
        let claim = claim_run_dir_again(&dir).expect("the dead process's claim is taken");
        assert!(claim.stale_note().is_some());
        drop(claim);
        // A claim of its own, not stale.
        let claim = claim_out_dir(&dir, false).unwrap();
        assert_eq!(claim.stale_note(), None);
        let holder = std::fs::read_to_string(dir.join(CLAIM_FILE)).unwrap();
        assert!(
            holder.starts_with(&format!("pid {} on {host} since ", std::process::id())),
            "{holder}"
        );
        drop(claim);
        // Another host's process cannot be checked from here: refused, saying what to do.
        std::fs::write(
            dir.join(CLAIM_FILE),
            "pid 4294967295 on another-host.example since then\n",
        )
        .unwrap();
        let refused = claim_out_dir(&dir, false).unwrap_err().to_string();
        assert!(
            refused.contains(
                "(pid 4294967295 on another-host.example since then; another host's process, \
                 which this one cannot check: if it no longer runs, remove "
            ),
            "{refused}"
        );
        std::fs::write(
            dir.join(CLAIM_FILE),
            format!("pid {} since now\n", std::process::id()),
        )
        .unwrap();
        let refused = claim_out_dir(&dir, false).unwrap_err();
        assert!(
            matches!(refused, RunError::OutDirClaimed { .. }),
            "{refused}"
        );
    }

    #[test]
    fn concurrent_campaigns_claim_different_run_directories() {
        let root = tempfile::tempdir().unwrap();
        let claimed: Vec<PathBuf> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..8)
                .map(|_| scope.spawn(|| claim_run_dir(root.path(), "same-name").unwrap()))
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        let unique: std::collections::BTreeSet<_> = claimed.iter().collect();
        assert_eq!(unique.len(), 8, "{claimed:?}");
        assert!(claimed.iter().all(|p| p.is_dir()));
        assert!(claimed.contains(&root.path().join("same-name")));
        assert!(claimed.contains(&root.path().join("same-name-8")));
    }

    #[test]
    fn of_processes_given_the_same_out_exactly_one_claims_it() {
        let root = tempfile::tempdir().unwrap();
        let out = root.path().join("nested").join("R");
        let results: Vec<Result<OutClaim, RunError>> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..8)
                .map(|_| scope.spawn(|| claim_out_dir(&out, false)))
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        let (won, lost): (Vec<_>, Vec<_>) = results.into_iter().partition(Result::is_ok);
        assert_eq!(won.len(), 1, "{lost:?}");
        for error in &lost {
            let text = error.as_ref().unwrap_err().to_string();
            assert!(
                text.contains("another drivecheck process is writing it (pid ")
                    || text
                        .contains("another drivecheck process is writing it (it is just starting)"),
                "{text}"
            );
        }
        assert!(out.join(CLAIM_FILE).is_file());
        // Given back: the claim file goes, and so does the directory this process made empty.
        drop(won);
        assert!(!out.exists());
        // A directory with anything in it is refused, and kept as it was.
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(out.join("campaign.json"), "{}").unwrap();
        let error = claim_out_dir(&out, false).unwrap_err();
        assert!(matches!(error, RunError::OutDirUsed { .. }), "{error}");
        let left: Vec<_> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(left, ["campaign.json"]);
    }

    #[test]
    fn a_staged_directory_appears_whole_or_not_at_all() {
        let root = tempfile::tempdir().unwrap();
        let out = root.path().join("merged");
        // Dropped before the commit (an error half way): nothing at `out`, no staging left.
        let staged = Staged::beside(&out).unwrap();
        std::fs::write(staged.dir().join("campaign.json"), "{}").unwrap();
        drop(staged);
        assert!(!out.exists());
        assert_eq!(std::fs::read_dir(root.path()).unwrap().count(), 0);
        // Two built at once: the first commit wins, the second is refused and cleaned up.
        let first = Staged::beside(&out).unwrap();
        let second = Staged::beside(&out).unwrap();
        std::fs::write(first.dir().join("campaign.json"), "first").unwrap();
        std::fs::write(second.dir().join("campaign.json"), "second").unwrap();
        first.commit().unwrap();
        let error = second.commit().unwrap_err();
        assert!(matches!(error, RunError::OutDirUsed { .. }), "{error}");
        assert_eq!(
            std::fs::read_to_string(out.join("campaign.json")).unwrap(),
            "first"
        );
        assert_eq!(std::fs::read_dir(root.path()).unwrap().count(), 1);
    }

    #[test]
    fn days_convert_to_civil_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        // 2026-11-22 is day 20 779.
        assert_eq!(civil_from_days(20_779), (2026, 11, 22));
    }
}
