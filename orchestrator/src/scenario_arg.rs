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

/// Prints a loaded scenario's warnings on standard error, one a line.
pub fn print_warnings(loaded: &Loaded) {
    for warning in &loaded.warnings {
        eprintln!("warning: {warning}");
    }
}

/// The scenario of an optional `--scenario` argument, loaded with its warnings printed.
pub fn optional_scenario(arg: Option<&str>) -> Result<Option<scenarios::Scenario>> {
    arg.map(|arg| {
        let loaded = load_scenario(arg)?;
        print_warnings(&loaded);
        Ok(loaded.scenario)
    })
    .transpose()
}
