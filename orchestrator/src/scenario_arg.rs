//! Resolving a `SCENARIO` argument: a bundled scenario's name, or a path to a TOML or XML file.

use std::path::Path;

use anyhow::{Context, Result, bail};
use scenarios::Loaded;

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

/// Prints a loaded scenario's warnings on standard error, one a line: always (what `scenario
/// check` and `area validate` are for).
pub fn print_warnings(loaded: &Loaded) {
    for warning in &loaded.warnings {
        eprintln!("warning: {warning}");
    }
}

/// Prints the warnings of the scenario `arg` named when a command uses it: a file's (unless
/// `-q`), but a bundled scenario's only with `-v` — they are the same on every run, and `scenario
/// check NAME` shows them.
pub fn print_warnings_of_use(arg: &str, loaded: &Loaded) {
    use crate::output::{Verbosity, verbosity};
    let bundled = !Path::new(arg).exists() && scenarios::bundled::text(arg).is_some();
    let shown = match verbosity() {
        Verbosity::Quiet => false,
        Verbosity::Normal => !bundled,
        Verbosity::Verbose => true,
    };
    if shown {
        print_warnings(loaded);
    }
}

/// The scenario of an optional `--scenario` argument, loaded with its warnings printed (see
/// [`print_warnings_of_use`]).
pub fn optional_scenario(arg: Option<&str>) -> Result<Option<scenarios::Scenario>> {
    arg.map(|arg| {
        let loaded = load_scenario(arg)?;
        print_warnings_of_use(arg, &loaded);
        Ok(loaded.scenario)
    })
    .transpose()
}
