//! The car profile a run drives and records (`docs/twin.md`): a [`CarProfile`] with the name the
//! user gave it (`default` or the file as given), as the `drivecheck.sim.profile` metadata record
//! holds it. Reading a `--profile` argument from a file is the command line's
//! (`orchestrator::profile_arg`).

use std::collections::BTreeMap;

use campaign::files::CarProfileRef;
use car_sim::{CarProfile, ProfileError, SimConfig};
use scenarios::Scenario;
use thiserror::Error;

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

/// A car profile that cannot be used.
#[derive(Debug, Error)]
pub enum LoadedProfileError {
    /// The recording's profile record lacks its TOML.
    #[error("the recording's car profile record has no toml")]
    NoToml,
    /// The profile's TOML does not load.
    #[error(transparent)]
    Profile(#[from] ProfileError),
    /// The profile does not fit the scenario (an anchor it moves is not there, ...).
    #[error("the car profile does not fit scenario {scenario}")]
    Misfit {
        /// The scenario's name.
        scenario: String,
        /// Why not.
        #[source]
        source: ProfileError,
    },
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
    /// The profile a recording holds (its `drivecheck.sim.profile` metadata record).
    pub fn from_metadata(entries: &BTreeMap<String, String>) -> Result<Self, LoadedProfileError> {
        let name = entries.get("name").cloned().unwrap_or_default();
        let toml = entries.get("toml").ok_or(LoadedProfileError::NoToml)?;
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
    pub fn car_without_area(&self) -> Result<car_sim::CarOptions, LoadedProfileError> {
        let mut profile = self.profile.clone();
        profile.anchors.clear();
        let mut config = SimConfig::default();
        profile.apply(&mut config, &self.name)?;
        Ok(config.car_options())
    }

    /// The simulated car of `scenario` that this profile describes.
    pub fn sim_config(&self, scenario: &Scenario) -> Result<SimConfig, LoadedProfileError> {
        let mut config = SimConfig::from_scenario(scenario);
        self.profile
            .apply(&mut config, &self.name)
            .map_err(|source| LoadedProfileError::Misfit {
                scenario: scenario.name.clone(),
                source,
            })?;
        Ok(config)
    }
}
