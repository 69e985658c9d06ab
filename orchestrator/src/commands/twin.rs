//! `drivecheck twin check`: how far a simulated car of a profile reproduces a recorded run. Every
//! recorded case is driven again on fresh embedded simulated cars of the profile, and of the
//! default car for comparison, in virtual time; the comparison is `campaign::twin`'s.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};

use super::case_input::{check_hash, read_case, scenario_of};
use super::signals::{cancel_on_ctrl_c, runtime};
use crate::cli::TwinCheckArgs;
use crate::exit::Exit;
use crate::output;
use crate::profile_arg::LoadedProfile;
use campaign::files::{
    CampaignRecord, Case, Header, ScenarioRef, TWIN_FORMAT, TWIN_SCHEMA_VERSION, TwinCheck,
    TwinProfileResult, TwinRepeat, TwinSummary,
};
use campaign::twin::{TWIN_FILE, compare_case, summarise};
use runner::CAMPAIGN_FILE;
use runner::simdrive::{SimDriver, SimSettings};

/// The recorded case files of a run directory, in test order, with their cases (those that ran).
fn recorded_cases(dir: &Path) -> Result<Vec<(PathBuf, Case)>> {
    let files = super::case_input::case_files(dir)?;
    let mut cases = Vec::new();
    for file in files {
        let case = read_case(&file)?;
        if case.verdict.is_some() {
            cases.push((file, case));
        }
    }
    Ok(cases)
}

/// What the twin check of the run `case_file` belongs to says of `profile` (its `twin.json`), for
/// a command that found the case does not fail on the profile's simulated car.
pub(super) fn agreement_note(case_file: &Path, profile: &LoadedProfile) -> String {
    let dir = case_file.parent().unwrap_or(Path::new("."));
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let hash = profile.profile.hash();
    let check = std::fs::read_to_string(dir.join(TWIN_FILE))
        .ok()
        .and_then(|text| TwinCheck::from_json(&text).ok());
    let found = check.as_ref().and_then(|c| {
        c.profiles
            .iter()
            .find(|p| p.profile.hash == hash)
            .map(|p| (c, p))
    });
    match found {
        Some((check, result)) => {
            let s = &result.summary;
            let mut note = format!(
                "the simulated car of car profile {} agrees with the car of {} on {} of segment \
                 verdicts, median Δ {} (twin.json)",
                profile.name,
                dir.display(),
                s.verdicts_agreed
                    .map_or_else(|| "-".to_owned(), |a| format!("{:.0} %", a * 100.0)),
                s.median_abs_delta_m
                    .map_or_else(|| "-".to_owned(), |m| format!("{m:.2} m")),
            );
            if let Some(repeat) = check
                .repeatability
                .as_ref()
                .and_then(|r| r.summary.verdicts_agreed)
            {
                note.push_str(&format!(
                    "; the car agrees with itself on {:.0} %",
                    repeat * 100.0
                ));
            }
            note
        }
        None => format!(
            "no twin check of car profile {} for {}: `drivecheck twin check {} --profile {}` \
             says how far its simulated car can be trusted (docs/twin.md)",
            profile.name,
            dir.display(),
            dir.display(),
            profile.name
        ),
    }
}

/// The recorded `cases` against the same cases recorded again on the car in `other`; refuses
/// other cases, naming the first.
fn repeatability(cases: &[(PathBuf, Case)], other: &Path) -> Result<TwinRepeat> {
    let again = recorded_cases(other)?;
    let mut segments = Vec::new();
    for (path, case) in cases {
        let name = path.file_name().unwrap_or_default();
        let Some((other_path, other_case)) =
            again.iter().find(|(p, _)| p.file_name() == Some(name))
        else {
            bail!(
                "--repeat {}: no {} (the same cases driven again: `drivecheck run` with the same \
                 --seed and --tests)",
                other.display(),
                name.to_string_lossy()
            );
        };
        if other_case.commands != case.commands {
            bail!(
                "--repeat: {} and {} are not the same case (their commands differ)",
                path.display(),
                other_path.display()
            );
        }
        let index = case.test_index.unwrap_or_default();
        segments.extend(compare_case(index, case, std::slice::from_ref(other_case)));
    }
    Ok(TwinRepeat {
        run: other.display().to_string(),
        summary: summarise(&segments),
    })
}

/// Drives every case again on `profile` and compares.
fn check_profile(
    (profile, firmware): (&LoadedProfile, Option<&super::firmware::HostFirmware>),
    scenario: &scenarios::Scenario,
    cases: &[(PathBuf, Case)],
    (runs, default_seed): (u32, u64),
    bar: &ProgressBar,
) -> Result<TwinProfileResult> {
    let sim = profile.sim_config(scenario)?;
    let runtime = runtime(true)?;
    let cancel = runtime.block_on(async { cancel_on_ctrl_c() });
    let scratch = std::env::temp_dir().join(format!("drivecheck-twin-{}", std::process::id()));
    // A signal's second coming ends the process: the scratch directory goes with it.
    let _registered = runner::scratch::Scratch::register(&scratch);
    let mut segments = Vec::new();
    let result = cases.iter().enumerate().try_for_each(|(i, (path, case))| {
        runner::pause_at("twin", i);
        bar.set_message(format!("{}: {}", profile.name, path.display()));
        let seed = case.campaign_seed.unwrap_or(default_seed);
        let mut driver = SimDriver::new(
            (scenario, sim.clone()),
            path,
            case,
            scratch.clone(),
            (runs, seed),
            &cancel,
        );
        driver.firmware = firmware.cloned();
        let driven = runtime.block_on(driver.drive_all(case, &SimSettings::default()));
        // A signal, not the case: the runs cut off by it are no runs.
        if cancel.is_cancelled() {
            return Err(super::signals::Interrupted(
                "the twin check did not end; nothing was compared or written",
            )
            .into());
        }
        let driven =
            driven.with_context(|| format!("{}: cannot be driven again", path.display()))?;
        let simulated: Vec<Case> = driven.into_iter().map(|(_, c)| c).collect();
        segments.extend(compare_case(case.test_index.unwrap_or(i), case, &simulated));
        bar.inc(1);
        anyhow::Ok(())
    });
    let _ = std::fs::remove_dir_all(&scratch);
    result?;
    Ok(TwinProfileResult {
        profile: profile.reference(),
        summary: summarise(&segments),
        segments,
    })
}

/// `drivecheck twin check`. Exit status: 0 checked, 2 error.
pub fn check(args: &TwinCheckArgs) -> Result<Exit> {
    let dir = &args.run;
    let record_file = dir.join(CAMPAIGN_FILE);
    let record = CampaignRecord::from_json(
        &std::fs::read_to_string(&record_file)
            .with_context(|| format!("cannot read {}", record_file.display()))?,
    )
    .with_context(|| record_file.display().to_string())?;
    let cases = recorded_cases(dir)?;
    let Some((first_path, first)) = cases.first() else {
        bail!("{}: no case file of a test that ran", dir.display());
    };
    let scenario = scenario_of(args.scenario.as_deref(), first_path, first)?;
    check_hash(first, &scenario, args.ignore_scenario_hash)?;
    let profile = crate::profile_arg::load(args.profile.as_deref())?;
    let firmware = super::firmware::fresh_car("twin check", &args.car)?;
    let mut profiles = vec![profile.clone()];
    if profile.profile.hash() != LoadedProfile::default().profile.hash() {
        profiles.push(LoadedProfile::default());
    }
    let bar = output::bar(Some((cases.len() * profiles.len()) as u64));
    if let Ok(style) = ProgressStyle::with_template("{elapsed_precise} {bar:30} {pos}/{len} {msg}")
    {
        bar.set_style(style);
    }
    let results = profiles
        .iter()
        .map(|p| {
            check_profile(
                (p, firmware.as_ref()),
                &scenario,
                &cases,
                (args.runs, record.seed),
                &bar,
            )
        })
        .collect::<Result<Vec<_>>>()?;
    bar.finish_and_clear();
    let repeatability = args
        .repeat
        .as_deref()
        .map(|other| repeatability(&cases, other))
        .transpose()?;
    let check = TwinCheck {
        header: Header::current(TWIN_FORMAT, TWIN_SCHEMA_VERSION),
        run: dir.display().to_string(),
        car: record.car.clone(),
        scenario: ScenarioRef::of(&scenario),
        cases: cases.len(),
        runs: args.runs,
        profiles: results,
        repeatability,
    };
    let json = check.to_json()?;
    let file = dir.join(TWIN_FILE);
    runner::atomic::write(&file, format!("{json}\n"))?;
    if args.json {
        output::print_json(
            output::json::TWIN_CHECK,
            &TwinJson {
                file: &file,
                twin: &check,
            },
        )?;
    } else {
        print!("{}", table(&check));
        println!("written: {}", dir.join(TWIN_FILE).display());
    }
    Ok(Exit::Success)
}

/// A twin check's result as `--json` prints it (docs/json.md).
#[derive(serde::Serialize)]
struct TwinJson<'a> {
    /// Where `twin.json` was written (in the run directory).
    file: &'a Path,
    /// `twin.json` (`drivecheck-twin`, docs/twin.md).
    twin: &'a TwinCheck,
}

/// The agreement of every profile, one row each.
fn table(check: &TwinCheck) -> String {
    let mut out = format!(
        "twin check of {} (car {}): {} case(s) driven {} time(s) on each simulated car\n\n\
         | car profile | segments | verdicts agreed | median Δ | p90 Δ |\n\
         |---|---|---|---|---|\n",
        check.run, check.car, check.cases, check.runs
    );
    let row = |name: String, s: &TwinSummary| {
        let metres = |m: Option<f64>| m.map_or_else(|| "-".to_owned(), |m| format!("{m:.2} m"));
        format!(
            "| {name} | {} | {} | {} | {} |\n",
            s.segments,
            s.verdicts_agreed
                .map_or_else(|| "-".to_owned(), |a| format!("{:.0} %", a * 100.0)),
            metres(s.median_abs_delta_m),
            metres(s.p90_abs_delta_m),
        )
    };
    for result in &check.profiles {
        let hash = &result.profile.hash[..12.min(result.profile.hash.len())];
        out.push_str(&row(
            format!("{} ({hash}…)", result.profile.name),
            &result.summary,
        ));
    }
    if let Some(repeat) = &check.repeatability {
        out.push_str(&row(
            format!("the car again ({})", repeat.run),
            &repeat.summary,
        ));
    }
    out.push_str(
        "\nΔ: a segment's recorded largest deviation minus the median of its simulated runs' \
         (absolute).\nA twin is trustworthy when these figures are near the car's own repeatability: the \
         same cases driven twice on the car (docs/twin.md).\n",
    );
    out
}
