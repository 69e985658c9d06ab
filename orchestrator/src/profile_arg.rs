//! Resolving a `--profile` argument: the car profile the embedded simulated car is
//! (`docs/twin.md`), `default` or a TOML file.

use std::path::Path;

use anyhow::{Context, Result};
use car_sim::CarProfile;
pub use recording::{DEFAULT_PROFILE, LoadedProfile};

/// The profile of an optional `--profile` argument: the bundled default without one or with
/// `default`, else the file.
pub fn load(arg: Option<&Path>) -> Result<LoadedProfile> {
    let Some(path) = arg.filter(|p| p.as_os_str() != DEFAULT_PROFILE) else {
        return Ok(LoadedProfile::default());
    };
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the car profile {name}"))?;
    let profile = CarProfile::from_toml(&text, &name)?;
    Ok(LoadedProfile { profile, name })
}
