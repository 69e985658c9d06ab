//! The five real test areas of the published experiments, embedded in the binary.
//!
//! Converted from the reference route XML by this crate's importer and [`crate::to_toml`]; the
//! files are in `scenarios/areas/`.

use crate::error::{Problem, ScenarioError};
use crate::{Loaded, from_toml_str};

/// Name and TOML text of each bundled scenario.
const AREAS: [(&str, &str); 5] = [
    ("courtyard", include_str!("../areas/courtyard.toml")),
    ("cutouts-four", include_str!("../areas/cutouts-four.toml")),
    (
        "parking-lot-2anchors",
        include_str!("../areas/parking-lot-2anchors.toml"),
    ),
    (
        "parking-lot-august",
        include_str!("../areas/parking-lot-august.toml"),
    ),
    (
        "parking-lot-rock",
        include_str!("../areas/parking-lot-rock.toml"),
    ),
];

const NAMES: [&str; 5] = [AREAS[0].0, AREAS[1].0, AREAS[2].0, AREAS[3].0, AREAS[4].0];

/// The names of the bundled scenarios.
pub fn names() -> &'static [&'static str] {
    &NAMES
}

/// The TOML text of a bundled scenario.
pub fn text(name: &str) -> Option<&'static str> {
    AREAS.iter().find(|(n, _)| *n == name).map(|(_, t)| *t)
}

/// Loads a bundled scenario; its source is `bundled:NAME`.
pub fn load(name: &str) -> Result<Loaded, ScenarioError> {
    let source_name = format!("bundled:{name}");
    let text = text(name).ok_or_else(|| {
        ScenarioError::in_source(
            &source_name,
            None,
            Problem::UnknownBundled {
                name: name.to_owned(),
                known: NAMES.join(", "),
            },
        )
    })?;
    from_toml_str(text, &source_name)
}
