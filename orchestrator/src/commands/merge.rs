//! `drivecheck runs merge DIR… --out DIR [--junit FILE]`: the run directories of a campaign's shards
//! (`run --shard K/N`) joined into the run directory of the whole campaign: every case file,
//! `campaign.json` with the summary over all tests, and one `campaign.mcap` with every test's
//! messages in test order (as the unsharded run writes it).
//!
//! Refused, before anything is written: a directory that is not a shard, shards of different
//! campaigns (seed, scenario, tool version, settings, car, faults or not, replayed case, shard
//! count), a shard given twice, missing shards (named), a shard that did not end or lacks a case
//! file, and shards of which only some have a recording.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use crate::exit::Exit;
use crate::profile_arg::LoadedProfile;
use crate::recording::{Recorder, RecordingStart, SIM_PROFILE_METADATA, Span, Spans};
use crate::runner::{CAMPAIGN_FILE, RECORDING_FILE, RunDirectory, SPAN_GAP_NS, Staged, is_used};
use campaign::files::{CampaignRecord, Case, Settings};
use campaign::oracle::Verdict;
use campaign::shard::Shard;

/// One shard's run directory, read.
struct ShardDir {
    dir: PathBuf,
    record: CampaignRecord,
    shard: Shard,
}

/// The cars of the shards (shards run on several cars): one entry per car (name and address)
/// with every test it drove in any shard; why it left a shard, named by the shard. A shard's
/// sessions are not kept in the merged campaign, so neither is a car's session.
fn merged_cars(shards: &[ShardDir]) -> Vec<campaign::files::CarRun> {
    let mut cars: Vec<campaign::files::CarRun> = Vec::new();
    for shard in shards {
        for car in &shard.record.cars {
            let left = car
                .left
                .as_ref()
                .map(|why| format!("shard {}: {why}", shard.shard));
            match cars
                .iter_mut()
                .find(|c| c.name == car.name && c.address == car.address)
            {
                Some(known) => {
                    known.tests.extend(&car.tests);
                    known.firmware = known.firmware.take().or_else(|| car.firmware.clone());
                    known.left = match (known.left.take(), left) {
                        (Some(a), Some(b)) => Some(format!("{a}; {b}")),
                        (a, b) => a.or(b),
                    };
                }
                None => cars.push(campaign::files::CarRun {
                    session: None,
                    left,
                    ..car.clone()
                }),
            }
        }
    }
    for car in &mut cars {
        car.tests.sort_unstable();
        car.tests.dedup();
    }
    cars
}

/// Merges the shards in `dirs` into `out` (see the module doc) and prints what it wrote.
pub fn merge(
    dirs: &[PathBuf],
    out: &Path,
    scenario: Option<&str>,
    junit: Option<&Path>,
    json: bool,
) -> Result<Exit> {
    if is_used(out) {
        bail!(crate::runner::RunError::OutDirUsed {
            path: out.to_owned()
        });
    }
    if let Some(file) = junit {
        super::shared::check_output_file("--junit", file, out)?;
    }
    let shards = read_shards(dirs)?;
    let first = &shards[0];
    let tests = first.record.settings.tests;
    let recorded: Vec<bool> = shards
        .iter()
        .map(|s| s.dir.join(RECORDING_FILE).is_file())
        .collect();
    if recorded.iter().any(|&r| r) && !recorded.iter().all(|&r| r) {
        let without: Vec<String> = shards
            .iter()
            .zip(&recorded)
            .filter(|(_, r)| !**r)
            .map(|(s, _)| format!("{} ({})", s.shard, s.dir.display()))
            .collect();
        bail!(
            "only some shards have a recording ({RECORDING_FILE}); missing in shard {}: run them \
             with the same --record",
            without.join(", ")
        );
    }
    let scenario = scenario_of(&first.record, scenario)?;
    let started_at = shards
        .iter()
        .map(|s| s.record.started_at.clone())
        .min()
        .unwrap_or_default();
    let ended_at = shards
        .iter()
        .filter_map(|s| s.record.ended_at.clone())
        .max()
        .unwrap_or_default();
    let record = CampaignRecord {
        started_at,
        ..first.record.clone()
    };
    // Built aside and moved into place when complete: a shard that fails half way leaves nothing
    // at `out` that `drivecheck runs` would take for a campaign.
    let staged = Staged::beside(out)?;
    let mut dir = RunDirectory::merged(staged.dir().to_owned(), record, &scenario)?;
    dir.add_cars(merged_cars(&shards));
    let verdicts = write_cases(&shards, tests, &mut dir)?;
    let mut report = dir.finish_at(ended_at)?;
    if recorded[0] {
        merge_recordings(
            &shards,
            &verdicts,
            &report.record,
            &scenario,
            &staged.dir().join(RECORDING_FILE),
        )?;
    }
    staged.commit()?;
    // What the JUnit file and the result name is where the run directory now is.
    out.clone_into(&mut report.dir);
    let summary = report.record.summary.as_ref();
    let say = |line: String| {
        if json {
            eprintln!("{line}");
        } else {
            println!("{line}");
        }
    };
    say(format!(
        "merged {} shards of campaign seed {} on {}: {} tests, {} passed, {} failed, {} aborted{}",
        shards.len(),
        report.record.seed,
        report.record.scenario.name,
        verdicts.len(),
        summary.map_or(0, |s| s.passed),
        summary.map_or(0, |s| s.failed),
        summary.map_or(0, |s| s.aborted),
        if recorded[0] {
            format!(", recording {RECORDING_FILE}")
        } else {
            String::new()
        }
    ));
    say(format!("run directory: {}", out.display()));
    if let Some(file) = junit {
        // Shards of the embedded simulator run in virtual time (`run --shard` without
        // `--realtime`); the campaign's wall time is from its first shard's start to its last's end.
        let clock = if report.record.car == "sim" {
            crate::junit::Clock::Simulated
        } else {
            crate::junit::Clock::Wall
        };
        let wall_s = report.record.ended_at.as_deref().and_then(|end| {
            let start = humantime::parse_rfc3339_weak(&report.record.started_at).ok()?;
            let end = humantime::parse_rfc3339_weak(end).ok()?;
            Some(end.duration_since(start).ok()?.as_secs_f64())
        });
        super::run::write_junit(&report, file, clock, wall_s)?;
    }
    if json {
        super::shared::print_report_json("runs merge", &report, None)?;
    }
    Ok(Exit::Success)
}

/// Reads every shard's `campaign.json` and checks that they are the shards of one campaign, each
/// once, none missing.
fn read_shards(dirs: &[PathBuf]) -> Result<Vec<ShardDir>> {
    let mut shards = Vec::new();
    for dir in dirs {
        let path = dir.join(CAMPAIGN_FILE);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let record =
            CampaignRecord::from_json(&text).with_context(|| path.display().to_string())?;
        let Some(shard) = record.shard else {
            bail!(
                "{}: not a shard (its campaign.json names no shard): only run directories of \
                 `drivecheck run --shard K/N` merge",
                dir.display()
            );
        };
        if record.summary.is_none() {
            bail!(
                "{}: shard {shard} did not end (its campaign.json has no summary): run it again",
                dir.display()
            );
        }
        shards.push(ShardDir {
            dir: dir.clone(),
            record,
            shard,
        });
    }
    let Some(first) = shards.first() else {
        bail!("no run directory to merge");
    };
    for other in &shards[1..] {
        if let Some(difference) = difference(&first.record, &other.record) {
            bail!(
                "{} and {} are shards of different campaigns: {difference}",
                first.dir.display(),
                other.dir.display()
            );
        }
    }
    let count = first.shard.count;
    let mut by_index: BTreeMap<usize, &ShardDir> = BTreeMap::new();
    for shard in &shards {
        if let Some(before) = by_index.insert(shard.shard.index, shard) {
            bail!(
                "shard {} is given twice: {} and {}",
                shard.shard,
                before.dir.display(),
                shard.dir.display()
            );
        }
    }
    let missing: Vec<String> = Shard::all(count)
        .filter(|s| !by_index.contains_key(&s.index))
        .map(|s| s.to_string())
        .collect();
    if !missing.is_empty() {
        bail!(
            "shards missing: {} (given {} of {count}); run them with `drivecheck run --shard K/{count}` \
             and the same seed and scenario",
            missing.join(", "),
            shards.len()
        );
    }
    shards.sort_by_key(|s| s.shard.index);
    Ok(shards)
}

/// What makes `b` a shard of another campaign than `a`, if anything.
fn difference(a: &CampaignRecord, b: &CampaignRecord) -> Option<String> {
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
                "the campaign settings differ (tests, sizes, speeds, faults or policy)".to_owned()
            })
        })
        .or_else(|| (a.replay_of != b.replay_of).then(|| "they replay different cases".to_owned()))
        .or_else(|| {
            (a.cases_from != b.cases_from)
                .then(|| "they drive the cases of different runs (--cases-from)".to_owned())
        })
}

/// Every test's case, in test order, read from its shard, checked and written into `dir` one at
/// a time; every test's verdict.
fn write_cases(
    shards: &[ShardDir],
    tests: usize,
    dir: &mut RunDirectory,
) -> Result<Vec<Option<Verdict>>> {
    let mut verdicts = Vec::with_capacity(tests);
    for test_index in 0..tests {
        let shard = shards
            .iter()
            .find(|s| s.shard.contains(test_index))
            .context("every test is in a shard")?;
        let path = shard.dir.join(format!("case-{test_index:03}.json"));
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!(
                "cannot read {} (shard {} ended without test {test_index}: run it again)",
                path.display(),
                shard.shard
            )
        })?;
        let case = Case::from_json(&text).with_context(|| path.display().to_string())?;
        if case.test_index != Some(test_index) {
            bail!(
                "{}: holds test {:?}, not test {test_index}",
                path.display(),
                case.test_index
            );
        }
        // Nothing a shard says is taken on trust: the case's values and every verdict are
        // checked against its own statistics, and it must be of the shard's campaign.
        case.check().with_context(|| path.display().to_string())?;
        if let Some(difference) = not_of(&case, &shard.record) {
            bail!(
                "{}: not a case of shard {}'s campaign: {difference}",
                path.display(),
                shard.shard
            );
        }
        dir.write_case(&case)?;
        verdicts.push(case.verdict);
    }
    Ok(verdicts)
}

/// What makes `case` a case of another campaign than `record`, if anything.
fn not_of(case: &Case, record: &CampaignRecord) -> Option<String> {
    let runtime_free = |s: &Settings| Settings {
        safety: None,
        streaming: None,
        ..s.clone()
    };
    if case.campaign_seed != Some(record.seed) {
        return Some(format!(
            "campaign seed {}, the shard's is {}",
            case.campaign_seed
                .map_or_else(|| "none".to_owned(), |s| s.to_string()),
            record.seed
        ));
    }
    if case.scenario != record.scenario {
        return Some(format!(
            "scenario {} ({}), the shard's is {} ({})",
            case.scenario.name,
            case.scenario.hash.as_deref().unwrap_or("-"),
            record.scenario.name,
            record.scenario.hash.as_deref().unwrap_or("-")
        ));
    }
    if case.no_faults != record.no_faults {
        return Some(format!(
            "--no-faults {}, the shard's {}",
            case.no_faults, record.no_faults
        ));
    }
    match &case.settings {
        Some(settings) if runtime_free(settings) != runtime_free(&record.settings) => Some(
            "its settings are not the shard's (tests, sizes, speeds, faults, threshold or policy)"
                .to_owned(),
        ),
        _ => None,
    }
}

/// The campaign's scenario: `--scenario`, else the bundled one of its name; its hash must be the
/// campaign's (the coverage in the summary is computed over its area).
fn scenario_of(record: &CampaignRecord, arg: Option<&str>) -> Result<scenarios::Scenario> {
    let name = &record.scenario.name;
    let scenario = match arg {
        Some(arg) => crate::scenario_arg::load_scenario(arg)?.scenario,
        None => {
            scenarios::bundled::load(name)
                .with_context(|| {
                    format!("scenario `{name}` is not bundled: give its file with --scenario")
                })?
                .scenario
        }
    };
    if let Some(hash) = &record.scenario.hash
        && scenario.hash() != *hash
    {
        bail!(
            "scenario `{}` hashes to {}, but the shards ran `{name}` with hash {hash}: give \
             the scenario file they ran with --scenario",
            scenario.name,
            scenario.hash()
        );
    }
    Ok(scenario)
}

/// A shard's recording as the merge reads it: a span at a time from the file, each checked
/// against the shard's campaign as it is read (see [`ShardSpans::peek`]).
struct ShardSpans<'a> {
    shard: &'a ShardDir,
    spans: Spans<std::io::BufReader<std::fs::File>>,
    /// The span read ahead, checked.
    next: Option<Span>,
    /// The tests whose spans were read.
    seen: BTreeSet<usize>,
}

impl<'a> ShardSpans<'a> {
    fn open(shard: &'a ShardDir) -> Result<Self> {
        let spans = Spans::open(&shard.dir.join(RECORDING_FILE))
            .with_context(|| shard.dir.display().to_string())?;
        Ok(Self {
            shard,
            spans,
            next: None,
            seen: BTreeSet::new(),
        })
    }

    /// The next span's test (`Some(None)`: a span without a test; `None`: the end), the span
    /// read ahead and checked: damage is refused, and so is a span of a test that is not in the
    /// shard, or of a test read before.
    fn peek(&mut self, verdicts: &[Option<Verdict>]) -> Result<Option<Option<usize>>> {
        if self.next.is_none() {
            let dir = self.shard.dir.display();
            let span = match self.spans.next() {
                None => return Ok(None),
                Some(span) => span.with_context(|| format!("{dir}: {RECORDING_FILE}"))?,
            };
            if let Some(test) = span.test_index {
                if test >= verdicts.len() || !self.shard.shard.contains(test) {
                    bail!(
                        "{dir}: {RECORDING_FILE} holds test {test}, which is not in shard {}",
                        self.shard.shard
                    );
                }
                if !self.seen.insert(test) {
                    bail!("{dir}: {RECORDING_FILE} holds test {test} twice");
                }
            }
            self.next = Some(span);
        }
        Ok(self.next.as_ref().map(|span| span.test_index))
    }

    /// The span read ahead.
    fn take(&mut self) -> Option<Span> {
        self.next.take()
    }

    /// Checks that the recording is of the shard's campaign (its seed): the campaign's metadata
    /// record comes before any message, so it is read once a span is.
    fn check_campaign(&self) -> Result<()> {
        let seed = self
            .spans
            .metadata("drivecheck.campaign")
            .and_then(|m| m.get("seed"))
            .map(String::as_str);
        if seed != Some(self.shard.record.seed.to_string().as_str()) {
            bail!(
                "{}: {RECORDING_FILE} is the recording of campaign seed {}, campaign.json's is {}",
                self.shard.dir.display(),
                seed.unwrap_or("(none recorded)"),
                self.shard.record.seed
            );
        }
        Ok(())
    }

    /// Once the recording is read to its end: it has a span of every test of the shard that did
    /// not pass (a recording of the embedded simulator has one per test it keeps; `--record
    /// failing` drops the others).
    fn check_every_test(&self, verdicts: &[Option<Verdict>]) -> Result<()> {
        if self.shard.record.car == "sim"
            && let Some(missing) = (0..verdicts.len())
                .filter(|&t| self.shard.shard.contains(t))
                .find(|&t| verdicts[t] != Some(Verdict::Passed) && !self.seen.contains(&t))
        {
            bail!(
                "{}: {RECORDING_FILE} has no span of test {missing}, which did not pass: it is not \
                 this shard's recording, or it was cut",
                self.shard.dir.display()
            );
        }
        Ok(())
    }
}

/// Writes `out`: every shard's tests' messages in test order, each test's log time shifted to
/// follow the one before it as in an unsharded run; messages of a recording made without test
/// spans (one car for the whole shard) follow, a shard at a time.
///
/// The shards' recordings are read from their files a span at a time, one test per shard in
/// memory (a recording without test spans is one span), and checked as they are read: of the
/// shard's campaign (its seed), a span for every test of the shard that did not pass and none
/// for another's, no damage. A shard refused half way stops the merge; what was written is in
/// the staging directory, which is removed.
fn merge_recordings(
    shards: &[ShardDir],
    verdicts: &[Option<Verdict>],
    record: &CampaignRecord,
    scenario: &scenarios::Scenario,
    out: &Path,
) -> Result<()> {
    let mut readers: Vec<ShardSpans<'_>> =
        shards.iter().map(ShardSpans::open).collect::<Result<_>>()?;
    // Every shard read up to its first span, where its campaign's metadata has been read.
    for reader in &mut readers {
        reader.peek(verdicts)?;
        reader.check_campaign()?;
    }
    let simulated = shards.iter().all(|s| s.record.car == "sim");
    let at_start = CampaignRecord {
        ended_at: None,
        summary: None,
        ..record.clone()
    };
    // The simulated car's profile, as the first shard recorded it (the shards agree on its
    // hash: it is in their campaign records).
    let profile = match readers.first() {
        Some(reader) => reader
            .spans
            .metadata(SIM_PROFILE_METADATA)
            .map(LoadedProfile::from_metadata)
            .transpose()?,
        None => None,
    };
    let start = RecordingStart {
        campaign: &at_start,
        scenario,
        origin: tokio::time::Instant::now(),
        simulated,
        chunk_interval: crate::recording::DEFAULT_CHUNK_INTERVAL,
        live: None,
        // Shards on the embedded simulator ran a fresh car per test: every test has a span.
        test_spans: simulated,
        sim_profile: profile.as_ref(),
    };
    let mut recorder = Recorder::create(out, &start)?;
    let mut offset_ns = SPAN_GAP_NS;
    loop {
        // The shard whose next span is the lowest test.
        let mut best: Option<(usize, usize)> = None;
        for (position, reader) in readers.iter_mut().enumerate() {
            if let Some(Some(test)) = reader.peek(verdicts)?
                && best.is_none_or(|(_, b)| test < b)
            {
                best = Some((position, test));
            }
        }
        let Some((position, _)) = best else {
            break;
        };
        if let Some(span) = readers[position].take() {
            write_span(&mut recorder, span, &mut offset_ns)?;
        }
    }
    // Only spans without a test are left: each shard's in turn, each shard read to its end.
    for reader in &mut readers {
        while reader.peek(verdicts)?.is_some() {
            if let Some(span) = reader.take() {
                write_span(&mut recorder, span, &mut offset_ns)?;
            }
        }
        reader.check_every_test(verdicts)?;
    }
    recorder.campaign_ended(record)?;
    recorder.finish()?;
    Ok(())
}

/// Writes `span`'s messages starting at `offset_ns`, with its test's span record, and moves the
/// offset past it.
fn write_span(recorder: &mut Recorder, span: Span, offset_ns: &mut u64) -> Result<()> {
    let shift = offset_ns.wrapping_sub(span.start_ns);
    recorder.write_held(span.messages, shift)?;
    let length = span.end_ns.saturating_sub(span.start_ns);
    if let Some(test_index) = span.test_index {
        recorder.test_span(
            test_index,
            *offset_ns,
            *offset_ns + length,
            span.car.as_deref(),
        )?;
    } else {
        recorder.flush()?;
    }
    *offset_ns += length + SPAN_GAP_NS;
    Ok(())
}
