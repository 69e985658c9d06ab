//! `drivecheck runs merge DIR… --out DIR [--junit FILE]`: the run directories of a campaign's shards
//! (`run --shard K/N`) joined into the run directory of the whole campaign: every case file,
//! `campaign.json` with the summary over all tests, and one `campaign.mcap` with every test's
//! messages in test order (as the unsharded run writes it).
//!
//! Refused, before anything is written: a directory that is not a shard, shards of different
//! campaigns (seed, scenario, tool version, settings, car, faults or not, replayed case, shard
//! count), a shard given twice, missing shards (named), a shard that did not end or lacks a case
//! file, and shards of which only some have a recording.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use crate::exit::Exit;
use crate::output;
use campaign::files::{CampaignRecord, Case};
use campaign::oracle::Verdict;
use campaign::shard::Shard;
use runner::merge::{ShardRun, merge_recordings};
use runner::{CAMPAIGN_FILE, RECORDING_FILE, RunDirectory, Staged, is_used};

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
        bail!(runner::RunError::OutDirUsed {
            path: out.to_owned()
        });
    }
    if let Some(file) = junit {
        super::case_input::check_output_file("--junit", file, out)?;
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
    super::signals::note_leftovers(runner::scratch::clear_leftovers_of(out));
    let staged = Staged::beside(out)?;
    let mut dir = RunDirectory::merged(staged.dir().to_owned(), record, &scenario)?;
    dir.add_cars(merged_cars(&shards));
    let verdicts = write_cases(&shards, tests, &mut dir)?;
    let mut report = dir.finish_at(ended_at)?;
    if recorded[0] {
        let runs: Vec<ShardRun<'_>> = shards
            .iter()
            .map(|s| ShardRun {
                dir: &s.dir,
                record: &s.record,
                shard: s.shard,
            })
            .collect();
        merge_recordings(
            &runs,
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
            output::note(&line);
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
            runner::junit::Clock::Simulated
        } else {
            runner::junit::Clock::Wall
        };
        let wall_s = report.record.ended_at.as_deref().and_then(|end| {
            let start = humantime::parse_rfc3339_weak(&report.record.started_at).ok()?;
            let end = humantime::parse_rfc3339_weak(end).ok()?;
            Some(end.duration_since(start).ok()?.as_secs_f64())
        });
        super::run::write_junit(&report, file, clock, wall_s)?;
    }
    if json {
        super::table::print_report_json(output::json::RUNS_MERGE, &report, None)?;
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
        if let Some(difference) = first.record.difference(&other.record) {
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
        if let Some(difference) = shard.record.foreign(&case) {
            bail!(
                "{}: not a case of shard {}'s campaign: {difference}",
                path.display(),
                shard.shard
            );
        }
        dir.write_case(&case)?;
        runner::pause_at("merge", test_index);
        verdicts.push(case.verdict);
    }
    Ok(verdicts)
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
