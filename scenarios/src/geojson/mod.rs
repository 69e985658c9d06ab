//! Scenarios as GeoJSON (RFC 7946): read from what QGIS, geojson.io or a drivecheck export wrote,
//! and written for them. The schema is in `docs/geojson.md`.
//!
//! A scenario is a FeatureCollection whose features carry their role in the property
//! `drivecheck` (`fence`, `cutout`, `anchor`, `route`, `obstacle`, `wall`); the collection's
//! foreign member `drivecheck` holds the format version, the coordinate kind (`crs`: local
//! metres or WGS84 longitude/latitude), the ENU origin and the settings that are not geometry, so
//! that drivecheck's own export reads back to the same scenario and hash. A file without any of
//! that (a QGIS export) is read too: the largest polygon is the fence, its holes and the other
//! polygons cutouts, points anchors; longitude/latitude become local east-north metres around an
//! origin (exactly, on the WGS84 ellipsoid, [`crate::geodesy`]).
//!
//! ```
//! use scenarios::geojson::{ReadOptions, WriteOptions, from_geojson_str, to_geojson};
//! let scenario = scenarios::bundled::load("courtyard").unwrap().scenario;
//! let local = WriteOptions { crs: Some(scenarios::geojson::Crs::Local), origin: None };
//! let text = to_geojson(&scenario, &local).unwrap();
//! let read = from_geojson_str(&text, "courtyard.geojson", "courtyard", &ReadOptions::default())
//!     .unwrap();
//! assert_eq!(read.loaded.scenario.hash(), scenario.hash());
//! ```

mod read;
mod write;

use thiserror::Error;

use crate::error::{Problem, ScenarioError};
use crate::model::EnuOrigin;
use crate::{Loaded, finish};

pub use write::{WriteOptions, to_geojson};

/// The version of the schema this drivecheck reads and writes (the `drivecheck` member's
/// `version`).
pub const VERSION: u64 = 1;
/// The `crs` of local east-north metres.
pub const CRS_LOCAL: &str = "local-enu-m";
/// The `crs` of WGS84 longitude and latitude, degrees (RFC 7946's).
pub const CRS_WGS84: &str = "wgs84";
/// The name in the 2008 `crs` member of a file in local metres (`{"type": "name", "properties":
/// {"name": …}}`): no registry names a scenario's local east-north frame, so this URN says that
/// the coordinates are not longitude/latitude; the reader takes it for local metres.
pub const CRS_LOCAL_NAME: &str = "urn:ogc:def:crs:drivecheck::local-enu-m";

/// The kind of coordinates a GeoJSON file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Crs {
    /// Local metres, x east and y north of the scenario's origin: what drivecheck draws in.
    Local,
    /// WGS84 longitude and latitude, degrees: RFC 7946's, what QGIS and geojson.io write.
    Wgs84,
}

impl Crs {
    /// The kind a `crs` value names (`local-enu-m`, `wgs84`).
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            CRS_LOCAL => Some(Crs::Local),
            CRS_WGS84 => Some(Crs::Wgs84),
            _ => None,
        }
    }

    /// The `crs` value of this kind.
    pub fn name(self) -> &'static str {
        match self {
            Crs::Local => CRS_LOCAL,
            Crs::Wgs84 => CRS_WGS84,
        }
    }

    /// The kind in words.
    pub fn describe(self) -> &'static str {
        match self {
            Crs::Local => "local metres",
            Crs::Wgs84 => "WGS84 longitude/latitude",
        }
    }
}

/// How to read a GeoJSON file's coordinates, when the file does not say.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ReadOptions {
    /// The coordinate kind (a file that states another is refused); `None`: the file's, else
    /// inferred.
    pub crs: Option<Crs>,
    /// The local frame's origin for longitude/latitude (and the scenario's origin); `None`: the
    /// file's, else the fence's first vertex.
    pub origin: Option<EnuOrigin>,
}

/// Where the coordinate kind came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CrsSource {
    /// The file's `drivecheck.crs` (or a legacy `crs` member).
    File,
    /// [`ReadOptions::crs`].
    Asked,
    /// The numbers: longitude/latitude if they all fit and the fence would be absurdly small in
    /// metres.
    Inferred,
}

/// Where the origin came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OriginSource {
    /// [`ReadOptions::origin`].
    Asked,
    /// The file's `drivecheck.origin`.
    File,
    /// The fence's first vertex (longitude/latitude and no origin given).
    FirstVertex,
}

/// A scenario read from GeoJSON, and how its coordinates were read.
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    /// The validated scenario with its warnings.
    pub loaded: Loaded,
    /// The coordinate kind and where it came from.
    pub crs: (Crs, CrsSource),
    /// The origin and where it came from, when there is one.
    pub origin: Option<(EnuOrigin, OriginSource)>,
}

impl Imported {
    /// How the coordinates were read, in one sentence for a person (the import's note).
    pub fn note(&self) -> String {
        let (crs, crs_from) = self.crs;
        let kind = match crs_from {
            CrsSource::File => "as the file says",
            CrsSource::Asked => "as asked",
            CrsSource::Inferred => "inferred from the numbers",
        };
        let mut note = format!("coordinates read as {} ({kind})", crs.describe());
        if let Some((o, from)) = self.origin {
            let from = match from {
                OriginSource::Asked => "--origin",
                OriginSource::File => "the file's drivecheck.origin",
                OriginSource::FirstVertex => "the fence's first vertex",
            };
            note.push_str(&format!(
                "; origin {}, {}, {} m ({from})",
                o.lat, o.lon, o.height
            ));
        }
        note
    }
}

/// Parses and validates a GeoJSON scenario. `name` names it unless the file does (its
/// `drivecheck.name`); `source_name` names the source in errors, whose field is the feature and
/// member (`features[3].geometry`), with the scenario field in brackets when the problem was found
/// after reading (`features[2].geometry.coordinates[0] (cutouts[0])`).
pub fn from_geojson_str(
    text: &str,
    source_name: &str,
    name: &str,
    options: &ReadOptions,
) -> Result<Imported, ScenarioError> {
    let document: serde_json::Value = serde_json::from_str(text).map_err(|e| {
        let location = (e.line() > 0).then_some(crate::Location {
            line: e.line(),
            column: e.column(),
        });
        ScenarioError::in_source(source_name, location, Problem::JsonSyntax(e.to_string()))
    })?;
    let read = read::read(&document, name, options)
        .map_err(|(field, problem)| ScenarioError::in_field(source_name, field, problem))?;
    let fields = read.fields;
    let mut loaded = finish(read.raw, source_name, |_| None).map_err(|mut error| {
        if let Some(field) = error.place.field.take() {
            error.place.field = Some(feature_of(&fields, field));
        }
        error
    })?;
    let mut warnings: Vec<_> = read
        .warnings
        .into_iter()
        .map(|mut w| {
            w.source_name = source_name.to_owned();
            w
        })
        .collect();
    for warning in &mut loaded.warnings {
        warning.field = feature_of(&fields, std::mem::take(&mut warning.field));
    }
    warnings.append(&mut loaded.warnings);
    loaded.warnings = warnings;
    Ok(Imported {
        loaded,
        crs: read.crs,
        origin: read.origin,
    })
}

/// A scenario field (`cutouts[1]`, `anchors[0].id`) as the GeoJSON member it came from, the
/// scenario field in brackets; unchanged when it came from no feature.
fn feature_of(fields: &[(String, String)], field: String) -> String {
    let came_from = fields.iter().find(|(prefix, _)| {
        field
            .strip_prefix(prefix.as_str())
            .is_some_and(|rest| rest.is_empty() || rest.starts_with(['[', '.']))
    });
    match came_from {
        Some((_, member)) => format!("{member} ({field})"),
        None => field,
    }
}

/// Why a scenario cannot be written as GeoJSON.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum GeoJsonWriteError {
    /// Longitude/latitude (the default) for a scenario without an origin, and none given.
    #[error(
        "WGS84 longitude/latitude (RFC 7946's coordinates) need the local frame's origin on the \
         globe, and the scenario has none: give one (--origin LAT,LON[,H]), or ask for local \
         metres (--crs local), which only drivecheck and readers of the file's `crs` member take \
         for what they are"
    )]
    NoOrigin,
    /// The settings could not be carried over (a number JSON cannot hold).
    #[error("the scenario's settings cannot be written as JSON: {0}")]
    Settings(String),
}

#[cfg(test)]
mod tests;
