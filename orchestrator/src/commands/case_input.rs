//! Reading what a command is given of an earlier run: its case files (bounded in size), the
//! scenario they were recorded in and whether its hash still matches, and where a command may
//! write beside them.

use std::path::{Path, PathBuf};

use anyhow::Result;
use runner::store::RunStore;
use scenarios::{Loaded, Scenario};

use crate::scenario_arg::{load_scenario, print_warnings};
use anyhow::bail;
use campaign::files::Case;
use report::data::short;

/// The scenario `name` a run directory `dir` (given with `flag`) names, to load when no
/// `--scenario` is given: it must be bundled.
pub(super) fn bundled_scenario(flag: &str, dir: &Path, name: &str) -> Result<String> {
    if scenarios::bundled::text(name).is_none() {
        bail!(
            "{flag} {}: its scenario `{name}` is not bundled; give its file with --scenario",
            dir.display()
        );
    }
    Ok(name.to_owned())
}

/// The case files (`case-NNN.json`) of run directory `dir`, in test order.
pub(super) fn case_files(dir: &Path) -> Result<Vec<PathBuf>> {
    Ok(RunStore::new(dir)
        .case_files()?
        .into_iter()
        .map(|(_, path)| path)
        .collect())
}

/// Refuses, before anything is driven, an output file a command writes only at its end
/// (`--junit`): its directory must exist, and it must not lie in the run directory `run_dir`,
/// where it could replace a recorded file.
pub(super) fn check_output_file(flag: &str, file: &Path, run_dir: &Path) -> Result<()> {
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_owned());
    let (file_abs, dir_abs) = (absolute(file), absolute(run_dir));
    if file_abs.starts_with(&dir_abs) {
        bail!(
            "{flag} {}: inside the run directory {}, where it could replace a recorded file; \
             write it elsewhere",
            file.display(),
            run_dir.display()
        );
    }
    let parent = file_abs.parent().unwrap_or(Path::new("/"));
    if !parent.is_dir() {
        bail!(
            "{flag} {}: the directory {} does not exist",
            file.display(),
            parent.display()
        );
    }
    Ok(())
}

/// The case file at `path`, read and parsed; errors name the file (and the field). Only a regular
/// file of at most `runner::store::MAX_CASE_BYTES` is read: a FIFO or a device would block or never end.
pub(crate) fn read_case(path: &Path) -> Result<Case> {
    Ok(RunStore::read_case(path)?)
}

/// The scenario a case is driven in: `--scenario`, else the bundled one the case names, else
/// the copy the recording beside the case holds (`campaign.mcap`'s `drivecheck.scenario`, taken
/// only when it hashes to the case's scenario hash and the recording is of the case's campaign).
pub(crate) fn scenario_of(
    scenario: Option<&str>,
    case_path: &Path,
    case: &Case,
) -> Result<Scenario> {
    let name = &case.scenario.name;
    let (arg, loaded) = match scenario {
        Some(arg) => (arg.to_owned(), load_scenario(arg)?),
        None if scenarios::bundled::text(name).is_some() => (name.clone(), load_scenario(name)?),
        None => match recorded_scenario(case_path, case)? {
            Some((recording, loaded)) => (recording.display().to_string(), loaded),
            None => bail!(
                "{}: scenario.name `{name}` is not a bundled scenario and no recording beside the \
                 case holds it; give its file with --scenario",
                case_path.display()
            ),
        },
    };
    print_warnings(&arg, &loaded);
    Ok(loaded.scenario)
}

/// The scenario the recording beside the case (`campaign.mcap` in its directory) was made in,
/// when that recording is of the case's campaign and its scenario hashes to the case's.
fn recorded_scenario(case_path: &Path, case: &Case) -> Result<Option<(PathBuf, Loaded)>> {
    let Some(hash) = &case.scenario.hash else {
        return Ok(None);
    };
    let dir = case_path.parent().unwrap_or(Path::new("."));
    let store = RunStore::new(dir);
    let file = store.recording();
    if !file.is_file() {
        return Ok(None);
    }
    if let Some(seed) = case.campaign_seed {
        store.check_recording(&file, seed)?;
    }
    let Some(toml) = recording::recorded_scenario(&file)? else {
        return Ok(None);
    };
    let source = format!("{}'s drivecheck.scenario", file.display());
    let loaded = scenarios::from_toml_str(&toml, &source)?;
    Ok((loaded.scenario.hash() == *hash).then_some((file, loaded)))
}

/// Refuses a case recorded in another scenario (or without a hash) unless told to proceed.
pub(crate) fn check_hash(case: &Case, scenario: &Scenario, ignore: bool) -> Result<()> {
    let hash = scenario.hash();
    let problem = match &case.scenario.hash {
        Some(recorded) if *recorded == hash => return Ok(()),
        Some(recorded) => format!(
            "the case was recorded in scenario `{}` with hash {}, but scenario `{}` hashes to {}",
            case.scenario.name,
            short(recorded),
            scenario.name,
            short(&hash)
        ),
        None => format!(
            "the case names no scenario hash, so it cannot be checked against scenario `{}`",
            scenario.name
        ),
    };
    if ignore {
        crate::output::warning(format_args!(
            "{problem}; replaying anyway (--ignore-scenario-hash)"
        ));
        return Ok(());
    }
    bail!("{problem}; pass --ignore-scenario-hash to replay it anyway")
}
