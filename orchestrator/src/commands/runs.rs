//! `drivecheck runs` lists the run directories under `--dir` (campaigns and replays) with their
//! summary; `drivecheck runs show DIR` shows one: a campaign's record and every test, or a
//! replay's comparison.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use super::table::{metres, print_report};
use crate::cli::{RunsArgs, RunsCommand};
use crate::exit::Exit;
use crate::output;
use campaign::coverage::CoverageBuilder;
use campaign::coverage::CoverageStats;
use campaign::files::{CampaignRecord, Case, CoverageRecord};
use campaign::replay::{Comparison, REPLAY_FILE};
use campaign::shrink::{SHRINK_FILE, ShrinkReport};
use runner::{CampaignReport, TestSummary};
use serde::Serialize;

use runner::CAMPAIGN_FILE;

/// Lists or shows run directories. Exit status 0, or 2 when the directory cannot be read.
pub fn runs(args: &RunsArgs) -> Result<Exit> {
    match &args.command {
        None => list(&args.dir, args.json),
        Some(RunsCommand::Show { run, coverage }) => {
            let dir = if run.exists() {
                run.clone()
            } else {
                args.dir.join(run)
            };
            show(&dir, *coverage, args.json)
        }
        Some(RunsCommand::Merge {
            shards,
            out,
            scenario,
            junit,
        }) => super::merge::merge(
            shards,
            out,
            scenario.as_deref(),
            junit.as_deref(),
            args.json,
        ),
    }
}

/// What a directory under `--dir` holds.
enum Entry {
    Campaign(Box<CampaignRecord>),
    Replay(Box<Comparison>),
    /// A shrink: `shrink.json`.
    Shrink(Box<ShrinkReport>),
    /// A record that cannot be read (or a replay without its comparison yet), and why.
    Unreadable(String),
}

fn read_entry(dir: &Path) -> Option<Entry> {
    let replay = dir.join(REPLAY_FILE);
    let campaign = dir.join(CAMPAIGN_FILE);
    let shrink = dir.join(SHRINK_FILE);
    if shrink.exists() {
        return Some(match read_shrink(&shrink) {
            Ok(s) => Entry::Shrink(Box::new(s)),
            Err(e) => Entry::Unreadable(format!("{e:#}")),
        });
    }
    if replay.exists() {
        return Some(match read_comparison(&replay) {
            Ok(c) => Entry::Replay(Box::new(c)),
            Err(e) => Entry::Unreadable(format!("{e:#}")),
        });
    }
    if campaign.exists() {
        return Some(match read_campaign(&campaign) {
            Ok(c) => Entry::Campaign(Box::new(c)),
            Err(e) => Entry::Unreadable(format!("{e:#}")),
        });
    }
    dir.join("run-1").join(CAMPAIGN_FILE).exists().then(|| {
        Entry::Unreadable("a replay without its comparison (still running or killed)".to_owned())
    })
}

fn read_comparison(path: &Path) -> Result<Comparison> {
    let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
    Comparison::from_json(&text).with_context(|| path.display().to_string())
}

fn read_shrink(path: &Path) -> Result<ShrinkReport> {
    let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
    ShrinkReport::from_json(&text).with_context(|| path.display().to_string())
}

fn read_campaign(path: &Path) -> Result<CampaignRecord> {
    let text = std::fs::read_to_string(path).with_context(|| path.display().to_string())?;
    CampaignRecord::from_json(&text).with_context(|| path.display().to_string())
}

/// `drivecheck runs --json`: the run directories under `dir` (docs/json.md).
#[derive(Serialize)]
struct ListJson<'a> {
    /// Where the run directories are.
    dir: &'a Path,
    /// Every run directory, by name.
    runs: Vec<EntryJson<'a>>,
}

/// One run directory in `runs --json` and `runs show --json`: its kind and its record.
#[derive(Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum EntryJson<'a> {
    /// A campaign (or a replay's run, or a shard): `campaign.json`.
    Campaign {
        /// The directory.
        dir: &'a Path,
        /// `campaign.json`.
        campaign: &'a CampaignRecord,
    },
    /// A replay: `replay.json`.
    Replay {
        /// The directory.
        dir: &'a Path,
        /// `replay.json`.
        replay: &'a Comparison,
    },
    /// A shrink: `shrink.json`.
    Shrink {
        /// The directory.
        dir: &'a Path,
        /// `shrink.json`.
        shrink: &'a ShrinkReport,
    },
    /// A record that cannot be read, and why.
    Unreadable {
        /// The directory.
        dir: &'a Path,
        /// Why it cannot be read.
        error: &'a str,
    },
}

impl<'a> EntryJson<'a> {
    fn of(dir: &'a Path, entry: &'a Entry) -> Self {
        match entry {
            Entry::Campaign(campaign) => EntryJson::Campaign { dir, campaign },
            Entry::Replay(replay) => EntryJson::Replay { dir, replay },
            Entry::Shrink(shrink) => EntryJson::Shrink { dir, shrink },
            Entry::Unreadable(error) => EntryJson::Unreadable { dir, error },
        }
    }
}

fn list(root: &Path, json: bool) -> Result<Exit> {
    let entries = match std::fs::read_dir(root) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if json {
                let runs = Vec::new();
                output::print_json(output::json::RUNS, &ListJson { dir: root, runs })?;
            } else {
                println!(
                    "no run directories in {} (it does not exist)",
                    root.display()
                );
            }
            return Ok(Exit::Success);
        }
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", root.display())),
    };
    let mut dirs: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    if json {
        let read: Vec<(PathBuf, Entry)> = dirs
            .into_iter()
            .filter_map(|dir| read_entry(&dir).map(|entry| (dir, entry)))
            .collect();
        let runs = read.iter().map(|(dir, e)| EntryJson::of(dir, e)).collect();
        output::print_json(output::json::RUNS, &ListJson { dir: root, runs })?;
        return Ok(Exit::Success);
    }
    println!(
        "| run directory | kind | scenario | seed | car | tests | passed | failed | aborted | worst deviation | ended |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut shown = 0;
    for dir in &dirs {
        let Some(entry) = read_entry(dir) else {
            continue;
        };
        shown += 1;
        let name = dir
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
        println!("| {name} | {} |", row(&entry));
    }
    let noun = if shown == 1 {
        "directory"
    } else {
        "directories"
    };
    println!("\n{shown} run {noun} in {}", root.display());
    Ok(Exit::Success)
}

fn row(entry: &Entry) -> String {
    match entry {
        Entry::Campaign(r) => {
            let kind = match &r.replay_of {
                Some(of) => format!("replay run of {}", of.case),
                None if r.cases_from.is_some() => format!(
                    "campaign, cases of {}",
                    r.cases_from.as_ref().map_or("", |c| c.run.as_str())
                ),
                None if r.no_faults => "campaign, no faults".to_owned(),
                None => "campaign".to_owned(),
            };
            let kind = match r.shard {
                Some(shard) => format!("{kind}, shard {shard}"),
                None => kind,
            };
            let kind = match r.sessions.len() {
                0 | 1 => kind,
                n => format!("{kind}, {n} sessions"),
            };
            let cars: std::collections::BTreeSet<&str> =
                r.cars.iter().map(|c| c.name.as_str()).collect();
            let kind = match cars.len() {
                0 | 1 => kind,
                n => format!("{kind}, {n} cars"),
            };
            let planned = r.shard.map_or(r.settings.tests, |shard| {
                shard.tests(r.settings.tests).count()
            });
            let ran = r.summary.as_ref().map_or(0, |s| s.tests);
            let kind = if r.replay_of.is_none() && (r.ended_at.is_none() || ran < planned) {
                format!("{kind}, not finished (drivecheck run --resume)")
            } else {
                kind
            };
            let counts = r.summary.as_ref().map_or_else(
                || "- | - | - | - | -".to_owned(),
                |s| {
                    format!(
                        "{} | {} | {} | {} | {}",
                        s.tests,
                        s.passed,
                        s.failed,
                        s.aborted,
                        metres(s.worst_deviation_m)
                    )
                },
            );
            format!(
                "{kind} | {} | {} | {} | {counts} | {}",
                r.scenario.name,
                r.seed,
                r.car,
                r.ended_at.as_deref().unwrap_or("(did not end)")
            )
        }
        Entry::Replay(c) => {
            let count = |v| c.runs.iter().filter(|r| r.verdict == Some(v)).count();
            use campaign::oracle::Verdict;
            let worst = c
                .segments
                .iter()
                .flat_map(|s| s.max_m.iter().flatten())
                .copied()
                .max_by(f64::total_cmp);
            format!(
                "replay ×{} of {}{} | {} | {} | - | {} | {} | {} | {} | {} | -",
                c.runs.len(),
                c.replay_of.case,
                if c.replay_of.no_faults {
                    ", no faults"
                } else {
                    ""
                },
                c.scenario.name,
                c.runs
                    .first()
                    .map_or_else(String::new, |r| r.seed.to_string()),
                c.runs.len(),
                count(Verdict::Passed),
                count(Verdict::Failed),
                count(Verdict::Aborted),
                metres(worst)
            )
        }
        Entry::Shrink(s) => format!(
            "shrink of {} ({} → {} segments, {}) | {} | {} | sim | {} | - | - | - | {} | -",
            s.case,
            s.before.size.segments,
            s.after.size.segments,
            s.ended.words(),
            s.scenario.name,
            s.seed,
            s.simulator_runs,
            metres(s.after.median_deviation_m())
        ),
        Entry::Unreadable(why) => format!("unreadable: {why} | | | | | | | | | |"),
    }
}

fn show(dir: &Path, coverage: bool, json: bool) -> Result<Exit> {
    match read_entry(dir) {
        None => bail!(
            "{} is not a run directory (no {CAMPAIGN_FILE}, {REPLAY_FILE} or {SHRINK_FILE})",
            dir.display()
        ),
        Some(Entry::Unreadable(why)) => bail!("{}: {why}", dir.display()),
        Some(entry @ Entry::Replay(_)) if json => {
            output::print_json(output::json::RUNS_SHOW, &EntryJson::of(dir, &entry))?;
            Ok(Exit::Success)
        }
        Some(Entry::Replay(c)) => {
            println!(
                "replay of {} in {}{}",
                c.replay_of.case,
                c.scenario.name,
                if c.replay_of.no_faults {
                    ", without its faults"
                } else {
                    ""
                }
            );
            for run in &c.runs {
                println!(
                    "  {}: seed {}, {}{}",
                    run.dir,
                    run.seed,
                    run.verdict
                        .map_or("not run", campaign::oracle::Verdict::as_str),
                    run.reason
                        .as_deref()
                        .map_or_else(String::new, |r| format!(" ({r})"))
                );
            }
            println!();
            print!("{}", c.table());
            Ok(Exit::Success)
        }
        Some(entry @ Entry::Shrink(_)) if json => {
            output::print_json(output::json::RUNS_SHOW, &EntryJson::of(dir, &entry))?;
            Ok(Exit::Success)
        }
        Some(Entry::Shrink(report)) => {
            super::shrink::print_summary(&report, dir);
            Ok(Exit::Success)
        }
        Some(Entry::Campaign(record)) if json => {
            show_campaign_json(dir, *record, coverage)?;
            Ok(Exit::Success)
        }
        Some(Entry::Campaign(record)) => {
            show_campaign(dir, *record, coverage)?;
            Ok(Exit::Success)
        }
    }
}

/// `drivecheck runs show --json` of a campaign (docs/json.md).
#[derive(Serialize)]
struct ShowJson<'a> {
    /// Always `campaign` (a replay is shown as `runs --json` lists it).
    kind: &'static str,
    /// The run directory.
    dir: &'a Path,
    /// `campaign.json`.
    campaign: &'a CampaignRecord,
    /// The recording, when there is one: whether it is complete and how many messages it holds.
    recording: Option<RecordingJson>,
    /// Every test's row of the table, in order.
    tests: &'a [TestSummary],
    /// With `--coverage`: what the campaign covered (as `campaign.json`'s summary keeps it; also
    /// for a record written before the summary kept it, from the case files).
    coverage: Option<CoverageRecord>,
}

/// The state of a run's recording in `runs show --json`.
#[derive(Serialize)]
struct RecordingJson {
    /// The recording file.
    file: PathBuf,
    /// Whether it was finished (false after kill -9 or a power cut).
    complete: Option<bool>,
    /// Messages read (up to the last complete chunk when unfinished).
    messages: Option<u64>,
    /// Why it is unreadable or cut short.
    problem: Option<String>,
}

impl RecordingJson {
    /// The recording of run directory `dir`, if it has one.
    fn of(dir: &Path) -> Option<Self> {
        let file = dir.join(runner::RECORDING_FILE);
        if !file.exists() {
            return None;
        }
        Some(match recording::Summary::read(&file) {
            Ok(recording) => RecordingJson {
                complete: Some(recording.is_complete()),
                messages: Some(recording.messages),
                problem: recording.cut_short().map(ToString::to_string),
                file,
            },
            Err(error) => RecordingJson {
                complete: None,
                messages: None,
                problem: Some(error.to_string()),
                file,
            },
        })
    }
}

fn show_campaign_json(dir: &Path, record: CampaignRecord, coverage: bool) -> Result<()> {
    let tests = read_tests(dir, |_| {})?;
    let coverage = match coverage.then(|| coverage_of(&record, dir)) {
        Some(Ok(stats)) => Some(stats.into()),
        Some(Err(why)) => bail!("no coverage: {why}"),
        None => None,
    };
    let result = ShowJson {
        kind: "campaign",
        dir,
        campaign: &record,
        recording: RecordingJson::of(dir),
        tests: &tests,
        coverage,
    };
    output::print_json(output::json::RUNS_SHOW, &result)
}

/// Every test's row of the table, from the case files of run directory `dir` in test order,
/// read one at a time (each case given to `each`, then dropped).
fn read_tests(dir: &Path, mut each: impl FnMut(&Case)) -> Result<Vec<TestSummary>> {
    let mut tests = Vec::new();
    for (index, file) in report::data::case_files(dir)? {
        let case = report::data::read_case(dir, &file)?;
        each(&case);
        tests.push(TestSummary::of(
            case.test_index.unwrap_or(index),
            file,
            &case,
        ));
    }
    Ok(tests)
}

/// What a campaign covered: as its record keeps it, or (a record written before the summary
/// kept coverage) computed from its case files in its bundled scenario.
fn coverage_of(record: &CampaignRecord, dir: &Path) -> Result<CoverageStats, String> {
    record
        .summary
        .as_ref()
        .and_then(|s| s.coverage.clone())
        .map(CoverageStats::from)
        .ok_or_else(|| format!("{CAMPAIGN_FILE} has no coverage (an older version wrote it)"))
        .or_else(|why| {
            let scenario = scenarios::bundled::load(&record.scenario.name)
                .map_err(|_| {
                    format!(
                        "{why}, and scenario {} is not bundled",
                        record.scenario.name
                    )
                })?
                .scenario;
            let mut coverage = CoverageBuilder::of_scenario(&scenario);
            read_tests(dir, |case| coverage.add(case)).map_err(|e| format!("{e:#}"))?;
            Ok(coverage.finish().stats)
        })
}

fn show_campaign(dir: &Path, record: CampaignRecord, coverage: bool) -> Result<()> {
    println!(
        "campaign: scenario {} (hash {}), seed {}{}, car {} (firmware {}), drivecheck {}",
        record.scenario.name,
        record
            .scenario
            .hash
            .as_deref()
            .map_or("-", |h| h.get(..12).unwrap_or(h)),
        record.seed,
        if record.no_faults { ", no faults" } else { "" },
        record.car,
        record.car_firmware_version.as_deref().unwrap_or("unknown"),
        record.header.tool()
    );
    if let Some(of) = &record.replay_of {
        println!("replay of {}", of.case);
    }
    if let Some(of) = &record.cases_from {
        println!(
            "the {} cases of {} (campaign seed {}), driven again test for test",
            of.tests, of.run, of.campaign_seed
        );
    }
    if !record.sessions.is_empty() {
        println!("resumed: {} sessions", record.sessions.len());
        for (k, session) in record.sessions.iter().enumerate() {
            println!(
                "  session {}: {} to {}, car {}, {} test(s), {}",
                k + 1,
                session.started_at,
                session.ended_at.as_deref().unwrap_or("-"),
                session.car,
                session.tests.len(),
                session.end.as_deref().unwrap_or("running")
            );
        }
    }
    if !record.cars.is_empty() {
        let names: std::collections::BTreeSet<&str> =
            record.cars.iter().map(|c| c.name.as_str()).collect();
        println!("on {} cars:", names.len());
        for line in super::table::cars_lines(&record.cars) {
            println!("  {line}");
        }
    }
    if let Some(shard) = record.shard {
        println!(
            "shard {shard} of a {}-test campaign: its tests i with i mod {} = {} (`drivecheck runs merge` joins the shards)",
            record.settings.tests,
            shard.count,
            shard.index - 1
        );
    }
    println!(
        "started {}, ended {}",
        record.started_at,
        record.ended_at.as_deref().unwrap_or("- (did not end)")
    );
    describe_recording(dir);
    let tests = read_tests(dir, |_| {})?;
    let stats = coverage.then(|| coverage_of(&record, dir));
    println!();
    print_report(
        &CampaignReport {
            dir: dir.to_owned(),
            record,
            tests,
        },
        None,
    );
    match stats {
        Some(Ok(stats)) => print!("\n{stats}"),
        Some(Err(why)) => println!("\nno coverage: {why}"),
        None => {}
    }
    Ok(())
}

/// Says whether the run's recording is complete and, when the process was killed before it was
/// finished (kill -9, a power cut), how to read it: drivecheck's reader, Foxglove and `mcap
/// recover` read an unfinished file up to its last complete chunk.
fn describe_recording(dir: &Path) {
    let file = dir.join(runner::RECORDING_FILE);
    if !file.exists() {
        return;
    }
    match recording::Summary::read(&file) {
        Ok(recording) if recording.is_complete() => {}
        Ok(recording) => println!(
            "recording {}: unfinished (the process was killed before it ended{}); {} messages \
             read up to the last complete chunk. Streaming readers (Foxglove) read it as it is; `mcap recover {} \
             -o recovered.mcap` (the mcap CLI) writes a finished copy",
            file.display(),
            recording
                .cut_short()
                .map_or_else(String::new, |why| format!(": {why}")),
            recording.messages,
            file.display()
        ),
        Err(error) => println!("recording {}: unreadable: {error}", file.display()),
    }
}
