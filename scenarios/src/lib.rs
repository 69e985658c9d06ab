//! Scenario files: the test area, routes, anchors, environment, vehicle and campaign settings.
//!
//! A scenario is everything drivecheck needs to know about a place before a car drives there:
//! the fence and cutouts, the hand-drawn start and recovery routes, the UWB anchors, what the
//! simulator should model around the area, and the generator's and campaign's settings. This crate
//! reads scenarios from TOML (the format of `docs/scenario-format.md`) or from the reference
//! control station's route XML, validates them with errors that name the file, the field and its
//! index, writes canonical TOML, hashes it, and bundles the five real test areas.
//!
//! ```
//! let loaded = scenarios::bundled::load("courtyard").unwrap();
//! let scenario = &loaded.scenario;
//! assert_eq!(scenario.name, "courtyard");
//! assert!(scenario.area.contains_point(scenario.start_route.positions()[0]));
//! for warning in &loaded.warnings {
//!     eprintln!("warning: {warning}");
//! }
//! // Canonical TOML loads back to the same scenario.
//! let again = scenarios::from_toml_str(&scenarios::to_toml(scenario), "copy.toml").unwrap();
//! assert_eq!(again.scenario, *scenario);
//! ```
//!
//! It is not for generating trajectories (that is `trajgen`, whose geometry it re-exports) nor for
//! running campaigns; it does no I/O beyond [`load`] reading the one file it is given.

pub mod bundled;
pub mod error;
pub mod geodesy;
pub mod geojson;
pub mod model;
pub mod settings;

#[cfg(test)]
mod fuzz;
mod locate;
mod raw;
mod validate;
mod write;
mod xml;

use std::path::Path;

pub use error::{GeoJsonProblem, Location, Place, Problem, ScenarioError, Warning, WarningKind};
pub use model::{Anchor, EnuOrigin, Environment, Obstacle, Route, Scenario, Wall};
pub use settings::{
    CampaignSettings, CommandWeights, FaultKeyError, FaultKind, FaultSettings, FaultTarget,
    GeneratorSettings, Interval, ProbeFaults, SHARED_PARAM_KEY, Vehicle,
};
/// The area geometry of [`trajgen`], re-exported for crates that see scenarios but not the generator.
pub use trajgen::geometry;
pub use trajgen::{Area, Constraints, Point, Polygon, Waypoint};
pub use validate::{MAX_ANCHORS, MAX_SPEED_KMH, check_fault_param, needs_planned_join};
pub use write::to_toml;

/// A validated scenario with its warnings and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Loaded {
    /// The scenario.
    pub scenario: Scenario,
    /// Soft problems a person should look at; the scenario is usable.
    pub warnings: Vec<Warning>,
    /// The file path or source name it was loaded from.
    pub source: String,
}

/// The file formats a scenario can be read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// The scenario format of this crate.
    Toml,
    /// The reference control station's route XML.
    Xml,
    /// A GeoJSON FeatureCollection ([`geojson`]).
    GeoJson,
}

impl Format {
    /// The format of a file: by extension (`.toml`, `.xml`, `.geojson`, `.json`), else by
    /// content (XML starts with `<`, JSON with `{`).
    pub fn detect(path: &Path, text: &str) -> Self {
        let start = text.trim_start_matches('\u{feff}').trim_start();
        match path.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("xml") => Self::Xml,
            Some(e) if e.eq_ignore_ascii_case("toml") => Self::Toml,
            Some(e) if e.eq_ignore_ascii_case("geojson") || e.eq_ignore_ascii_case("json") => {
                Self::GeoJson
            }
            _ if start.starts_with('<') => Self::Xml,
            _ if start.starts_with('{') => Self::GeoJson,
            _ => Self::Toml,
        }
    }
}

/// Reads, parses and validates the scenario at `path` (TOML, reference XML or GeoJSON, see
/// [`Format::detect`]). An XML scenario is named after the file stem, a GeoJSON one too unless
/// it names itself; GeoJSON is read with the default [`geojson::ReadOptions`].
pub fn load(path: impl AsRef<Path>) -> Result<Loaded, ScenarioError> {
    load_with(path, &geojson::ReadOptions::default()).map(|imported| imported.loaded)
}

/// [`load`], with how to read a GeoJSON file's coordinates; also says how they were read (for a
/// TOML or XML file: local metres, as the file says, and its origin).
pub fn load_with(
    path: impl AsRef<Path>,
    options: &geojson::ReadOptions,
) -> Result<geojson::Imported, ScenarioError> {
    let path = path.as_ref();
    let source_name = path.display().to_string();
    if let Ok(meta) = std::fs::metadata(path) {
        let problem = if !meta.is_file() {
            Some(Problem::Read(std::io::Error::other(
                "not a regular file (a directory, FIFO or device): a scenario is a TOML or XML file",
            )))
        } else if meta.len() > MAX_SCENARIO_BYTES {
            Some(Problem::TooLarge {
                bytes: meta.len(),
                max: MAX_SCENARIO_BYTES,
            })
        } else {
            None
        };
        if let Some(problem) = problem {
            return Err(ScenarioError::in_source(&source_name, None, problem));
        }
    }
    let text = std::fs::read_to_string(path)
        .map_err(|e| ScenarioError::in_source(&source_name, None, Problem::Read(e)))?;
    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let loaded = match Format::detect(path, &text) {
        Format::Toml => from_toml_str(&text, &source_name)?,
        Format::Xml => from_xml_str(&text, &source_name, &name)?,
        Format::GeoJson => {
            return geojson::from_geojson_str(&text, &source_name, &name, options);
        }
    };
    let origin = loaded
        .scenario
        .origin
        .map(|o| (o, geojson::OriginSource::File));
    Ok(geojson::Imported {
        loaded,
        crs: (geojson::Crs::Local, geojson::CrsSource::File),
        origin,
    })
}

/// The largest scenario file [`load`] reads, bytes (8 MiB: a scenario of the largest polygons
/// accepted is about 4 MiB).
pub const MAX_SCENARIO_BYTES: u64 = 8 * 1024 * 1024;
/// The most vertices a fence or cutout may have (a real test area has tens; checking one of this
/// size takes well under a second).
pub const MAX_POLYGON_VERTICES: usize = 100_000;
/// The most tests a campaign may have (`campaign.tests`, `drivecheck run --tests`).
pub const MAX_TESTS: usize = 1_000_000;

/// Limits on every size and speed a scenario sets, far beyond any real use and low enough that no
/// value within them exhausts memory or never ends; a value beyond one is refused with the limit
/// named (`docs/scenario-format.md#limits`).
pub mod limits {
    /// `generator.ahead_margin` and `recovery_ahead_margin`, segments (the bundled scenarios
    /// use 15–20).
    pub const MAX_AHEAD_MARGIN: usize = 200;
    /// `campaign.test_size.max`, segments per test (default 5–20).
    pub const MAX_TEST_SIZE: usize = 1_000;
    /// `campaign.points_per_segment.max` (default 4–7).
    pub const MAX_POINTS_PER_SEGMENT: usize = 100;
    /// `campaign.speed_kmh.min`, km/h: slower, one segment of a test takes minutes.
    pub const MIN_SPEED_KMH: f64 = 0.5;
    /// `generator.segment_max_m`, m.
    pub const MAX_SEGMENT_M: f64 = 100.0;
    /// `generator.clearance_m`, m.
    pub const MAX_CLEARANCE_M: f64 = 50.0;
    /// `generator.inner_tries`.
    pub const MAX_INNER_TRIES: usize = 10_000;
    /// `generator.outer_tries`.
    pub const MAX_OUTER_TRIES: usize = 100_000;
    /// A fault's offset, in its probe's unit (m, or degrees for the yaw, which is within ±180°).
    pub const MAX_FAULT_OFFSET: f64 = 1_000.0;
    /// A fault's amplification factor, either sign.
    pub const MAX_FAULT_FACTOR: f64 = 1_000.0;
    /// A fault's start and duration, probe iterations.
    pub const MAX_FAULT_ITERATIONS: u32 = 1_000_000;
    /// Every coordinate of a scenario (fence, cutouts, routes, anchors, obstacles, walls), an
    /// anchor's height and the origin's height, metres, either sign: 100 km from the local
    /// origin. A real test area spans tens of metres around its origin; the car's wire protocol
    /// carries a position as a 32-bit integer of 0.1 mm (at most ±214 748 m) and an anchor's as a
    /// binary32, so within this bound every position a campaign sends fits, and areas and
    /// distances stay far from overflow.
    pub const MAX_COORDINATE_M: f64 = 100_000.0;
    /// A route point's speed (scenario route, case file), m/s: the firmware autopilot's top
    /// speed ([`crate::MAX_SPEED_KMH`], 30 km/h).
    pub const MAX_ROUTE_SPEED: f64 = crate::MAX_SPEED_KMH / 3.6;
}

/// Parses and validates a TOML scenario; `source_name` names it in errors (and, when the file has
/// no `name`, gives the name: its file stem).
pub fn from_toml_str(text: &str, source_name: &str) -> Result<Loaded, ScenarioError> {
    let raw = raw::parse_toml(text, source_name)?;
    finish(raw, source_name, |field| locate::in_toml(text, field))
}

/// Parses and validates a scenario in the reference route XML, naming it `name`.
pub fn from_xml_str(text: &str, source_name: &str, name: &str) -> Result<Loaded, ScenarioError> {
    let (raw, index) = xml::parse_xml(text, source_name, name)?;
    finish(raw, source_name, |field| index.locate(text, field))
}

/// Parses and validates a scenario in the reference route XML (`text`) with its anchors from a
/// second reference XML file that holds only anchors (`anchors_text`), as the published
/// experiments kept them. An area file that has anchors itself is refused: anchors come from one
/// file.
pub fn from_xml_with_anchors(
    (text, source_name): (&str, &str),
    (anchors_text, anchors_source): (&str, &str),
    name: &str,
) -> Result<Loaded, ScenarioError> {
    let anchors = xml::parse_anchors(anchors_text, anchors_source)?;
    let (mut raw, index) = xml::parse_xml(text, source_name, name)?;
    if !raw.anchors.is_empty() {
        return Err(ScenarioError::in_field(
            source_name,
            "anchors".to_owned(),
            Problem::Schema(format!(
                "{} anchor(s) here and more in {anchors_source}: give the anchors in one file",
                raw.anchors.len()
            )),
        ));
    }
    raw.anchors = anchors;
    finish(raw, source_name, |field| index.locate(text, field))
}

/// Builds and validates the scenario; an error in a field gets the line and column where the
/// field is written (`locate`), when the parser did not give one.
fn finish(
    raw: raw::RawScenario,
    source_name: &str,
    locate: impl Fn(&str) -> Option<Location>,
) -> Result<Loaded, ScenarioError> {
    let located = |mut error: ScenarioError| {
        if error.place.location.is_none()
            && let Some(field) = &error.place.field
        {
            error.place.location = locate(field);
        }
        error
    };
    let scenario = raw::build(raw, source_name).map_err(located)?;
    let warnings = scenario.validate(source_name).map_err(located)?;
    Ok(Loaded {
        scenario,
        warnings,
        source: source_name.to_owned(),
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A 10 m square with a start route along y = 2 and a recovery route coming down x = 2.
    pub(crate) const SQUARE: &str = r#"
fence = [{ x = 0.0, y = 0.0 }, { x = 10.0, y = 0.0 }, { x = 10.0, y = 10.0 }, { x = 0.0, y = 10.0 }]
start_route = [
    { x = 2.0, y = 2.0, speed = 1.0 },
    { x = 3.5, y = 2.0, speed = 1.0 },
    { x = 5.0, y = 2.0, speed = 1.0 },
]
recovery_route = [
    { x = 2.0, y = 6.0, speed = 1.0 },
    { x = 2.0, y = 4.5, speed = 1.0 },
    { x = 2.0, y = 3.2, speed = 1.0 },
]
"#;

    #[test]
    fn costs_are_bounded_by_documented_limits() {
        // A fence of more vertices than the limit is refused before it is checked.
        let n = MAX_POLYGON_VERTICES + 1;
        let fence: String = (0..n)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / n as f64;
                format!(
                    "{{x={:.4},y={:.4}}},",
                    5.0 + 5.0 * t.cos(),
                    5.0 + 5.0 * t.sin()
                )
            })
            .collect();
        let text = SQUARE.replacen(
            "fence = [{ x = 0.0, y = 0.0 }, { x = 10.0, y = 0.0 }, { x = 10.0, y = 10.0 }, { x = 0.0, y = 10.0 }]",
            &format!("fence = [{fence}]"),
            1,
        );
        let error = from_toml_str(&text, "big.toml").unwrap_err().to_string();
        assert!(
            error.contains("fence: 100001 vertices: at most 100000"),
            "{error}"
        );
        // A threshold no deviation inside the area can exceed (the square's diagonal is 14.1 m).
        let text = format!("{SQUARE}\n[campaign]\noracle_threshold_m = 1e9\n");
        let error = from_toml_str(&text, "wide.toml").unwrap_err().to_string();
        assert!(
            error.contains(
                "campaign.oracle_threshold_m: 1000000000 m is at least the area's diameter (14.1 m)"
            ),
            "{error}"
        );
        // More tests than the limit.
        let text = format!("{SQUARE}\n[campaign]\ntests = 4294967297\n");
        let error = from_toml_str(&text, "many.toml").unwrap_err().to_string();
        assert!(
            error.contains("campaign.tests: 4294967297: at most 1000000"),
            "{error}"
        );
        // A file larger than the limit is not read.
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("huge.toml");
        let huge = vec![b'#'; usize::try_from(MAX_SCENARIO_BYTES).unwrap() + 1];
        std::fs::write(&file, huge).unwrap();
        let error = load(&file).unwrap_err().to_string();
        assert!(error.contains("8388609 bytes: at most 8388608"), "{error}");
    }

    #[test]
    fn format_is_detected_by_extension_then_content() {
        let p = Path::new;
        assert_eq!(Format::detect(p("a.XML"), "name = 1"), Format::Xml);
        assert_eq!(Format::detect(p("a.toml"), "<routes/>"), Format::Toml);
        assert_eq!(
            Format::detect(p("area"), "\n  <?xml?><routes/>"),
            Format::Xml
        );
        assert_eq!(Format::detect(p("area"), "name = \"x\""), Format::Toml);
    }

    #[test]
    fn a_scenario_without_a_name_is_named_after_its_file() {
        let loaded = from_toml_str(SQUARE, "some/dir/yard.toml").unwrap();
        assert_eq!(loaded.scenario.name, "yard");
        assert_eq!(loaded.source, "some/dir/yard.toml");
        assert_eq!(loaded.scenario.generator, GeneratorSettings::default());
        assert_eq!(loaded.scenario.campaign, CampaignSettings::default());
    }

    #[test]
    fn the_square_warns_about_anchors_and_the_right_angle_onto_the_start_route() {
        let loaded = from_toml_str(SQUARE, "square.toml").unwrap();
        let lines: Vec<String> = loaded.warnings.iter().map(ToString::to_string).collect();
        assert_eq!(
            lines,
            [
                "square.toml: anchors: no anchors: UWB positioning cannot be tested in this area",
                "square.toml: start_route[0]: the route turns 90.0° here, more than the \
                 generator's 30.0° (hand-drawn; kept as drawn)",
            ]
        );
    }

    #[test]
    fn a_missing_file_is_a_read_error_naming_it() {
        let error = load("/nonexistent/area.toml").unwrap_err();
        assert!(matches!(error.problem, Problem::Read(_)));
        assert!(
            error
                .to_string()
                .starts_with("/nonexistent/area.toml: cannot read the file")
        );
    }

    #[test]
    fn constraints_follow_the_generator_settings() {
        let text = format!("{SQUARE}\n[generator]\nmax_turn_deg = 45.0\nclearance_m = 0.25\n");
        let scenario = from_toml_str(&text, "s.toml").unwrap().scenario;
        let c = scenario.constraints();
        assert!((c.max_turn - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert_eq!(
            (c.min_segment, c.max_segment, c.clearance),
            (0.6, 2.0, 0.25)
        );
    }
}
