//! Resolving a `SCENARIO` argument: a bundled scenario's name, or a path to a TOML or XML file.

use std::path::Path;

use anyhow::{Context, Result, bail};
use scenarios::Loaded;

use crate::output::{self, Says};

/// Loads the scenario a user named: an existing file wins, then a bundled name.
pub fn load_scenario(arg: &str) -> Result<Loaded> {
    let path = Path::new(arg);
    if path.exists() {
        return scenarios::load(path).map_err(anyhow::Error::new);
    }
    if scenarios::bundled::text(arg).is_some() {
        return scenarios::bundled::load(arg)
            .with_context(|| format!("bundled scenario {arg} does not load"));
    }
    bail!(
        "no scenario file {arg} and no bundled scenario of that name (bundled: {})",
        scenarios::bundled::names().join(", ")
    )
}

/// Whether `arg` names a bundled scenario (no file of that name, a bundled one), as
/// [`load_scenario`] resolves it.
pub fn is_bundled(arg: &str) -> bool {
    !Path::new(arg).exists() && scenarios::bundled::text(arg).is_some()
}

/// What the warnings of the scenario `arg` named are on standard error: a file's are
/// [`Says::Warning`]s (not with `-q`), a bundled scenario's [`Says::Detail`]s (only with `-v`):
/// they are about data the user cannot change, the same on every run.
pub fn warnings_say(arg: &str) -> Says {
    if is_bundled(arg) {
        Says::Detail
    } else {
        Says::Warning
    }
}

/// Prints the warnings of the scenario `arg` named (loaded as `loaded`), one a line, as
/// [`warnings_say`] says; every command that reads a scenario prints them here. Whether they
/// were printed.
pub fn print_warnings(arg: &str, loaded: &Loaded) -> bool {
    let kind = warnings_say(arg);
    for warning in &loaded.warnings {
        output::say(kind, format_args!("warning: {warning}"));
    }
    output::shows(kind)
}

/// The scenario of an optional `--scenario` argument, loaded with its warnings printed (see
/// [`print_warnings`]).
pub fn optional_scenario(arg: Option<&str>) -> Result<Option<scenarios::Scenario>> {
    arg.map(|arg| {
        let loaded = load_scenario(arg)?;
        print_warnings(arg, &loaded);
        Ok(loaded.scenario)
    })
    .transpose()
}
