//! Resolving a `--profile` argument: the car profile the embedded simulated car is
//! (`docs/twin.md`), `default` or a TOML file.

use std::path::Path;

use anyhow::{Context, Result};
use campaign::files::CarProfileRef;
use car_sim::{CarProfile, SimConfig};
use scenarios::Scenario;

/// The name of the bundled profile: the simulated car drivecheck has always had.
pub const DEFAULT_PROFILE: &str = "default";

/// A car profile as the user named it.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedProfile {
    /// The profile.
    pub profile: CarProfile,
    /// `default` or the file as given.
    pub name: String,
}

impl Default for LoadedProfile {
    fn default() -> Self {
        Self {
            profile: CarProfile::default(),
            name: DEFAULT_PROFILE.to_owned(),
        }
    }
}

impl LoadedProfile {
    /// The profile of an optional `--profile` argument: the bundled default without one or with
    /// `default`, else the file.
    pub fn load(arg: Option<&Path>) -> Result<Self> {
        let Some(path) = arg.filter(|p| p.as_os_str() != DEFAULT_PROFILE) else {
            return Ok(Self::default());
        };
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the car profile {name}"))?;
        let profile = CarProfile::from_toml(&text, &name)?;
        Ok(Self { profile, name })
    }

    /// The profile a recording holds (its `drivecheck.sim.profile` metadata record).
    pub fn from_metadata(entries: &std::collections::BTreeMap<String, String>) -> Result<Self> {
        let name = entries.get("name").cloned().unwrap_or_default();
        let toml = entries
            .get("toml")
            .context("the recording's car profile record has no toml")?;
        let profile = CarProfile::from_toml(toml, &format!("the recording's car profile {name}"))?;
        Ok(Self { profile, name })
    }

    /// What a run records of it.
    pub fn reference(&self) -> CarProfileRef {
        CarProfileRef {
            name: self.name.clone(),
            hash: self.profile.hash(),
        }
    }

    /// The car of this profile outside any area (its anchors left out): for a drive that ranges
    /// to no anchor, as the route-following benchmark's.
    pub fn car_without_area(&self) -> Result<car_sim::CarOptions> {
        let mut profile = self.profile.clone();
        profile.anchors.clear();
        let mut config = SimConfig::default();
        profile.apply(&mut config, &self.name)?;
        Ok(config.car_options())
    }

    /// The simulated car of `scenario` that this profile describes.
    pub fn sim_config(&self, scenario: &Scenario) -> Result<SimConfig> {
        let mut config = SimConfig::from_scenario(scenario);
        self.profile
            .apply(&mut config, &self.name)
            .with_context(|| format!("the car profile does not fit scenario {}", scenario.name))?;
        Ok(config)
    }
}
