//! Errors and warnings, each naming the file, the field (with its index) and, for syntax, the line.

use std::fmt;

use thiserror::Error;
use trajgen::PolygonError;

/// Where in a scenario a problem is: the file (or other source), the line and column when the
/// parser knows them, and the field path (`fence[5].x`, `anchors[2].id`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Place {
    /// The file path, or another name of the source (`bundled:courtyard`).
    pub source_name: String,
    /// Line and column (1-based), when the parser gave them.
    pub location: Option<Location>,
    /// The field path, when the problem is in one field.
    pub field: Option<String>,
}

/// A 1-based line and column in a text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Location {
    /// Line, from 1.
    pub line: usize,
    /// Column in characters, from 1.
    pub column: usize,
}

impl Location {
    /// The line and column of byte `offset` in `text` (clamped to the text's end).
    pub fn of_offset(text: &str, offset: usize) -> Self {
        let mut offset = offset.min(text.len());
        while !text.is_char_boundary(offset) {
            offset -= 1;
        }
        let before = &text[..offset];
        let line = before.matches('\n').count() + 1;
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        let column = before[line_start..].chars().count() + 1;
        Self { line, column }
    }
}

impl fmt::Display for Place {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.source_name)?;
        if let Some(Location { line, column }) = self.location {
            write!(f, ":{line}:{column}")?;
        }
        if let Some(field) = &self.field {
            write!(f, ": {field}")?;
        }
        Ok(())
    }
}

/// Why a scenario could not be loaded. Displays as `file[:line:column]: field: message`.
#[derive(Debug, Error)]
#[error("{place}: {problem}")]
pub struct ScenarioError {
    /// Where the problem is.
    pub place: Place,
    /// What the problem is.
    pub problem: Problem,
}

impl ScenarioError {
    /// An error in `field` of `source_name`.
    pub fn in_field(source_name: &str, field: impl Into<String>, problem: Problem) -> Self {
        Self {
            place: Place {
                source_name: source_name.to_owned(),
                location: None,
                field: Some(field.into()),
            },
            problem,
        }
    }

    /// An error about the whole of `source_name`, at `location` when known.
    pub fn in_source(source_name: &str, location: Option<Location>, problem: Problem) -> Self {
        Self {
            place: Place {
                source_name: source_name.to_owned(),
                location,
                field: None,
            },
            problem,
        }
    }

    /// The field path, if the problem is in one field.
    pub fn field(&self) -> Option<&str> {
        self.place.field.as_deref()
    }
}

/// What is wrong with a scenario.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Problem {
    /// The file could not be read.
    #[error("cannot read the file: {0}")]
    Read(#[source] std::io::Error),
    /// The text is not valid TOML.
    #[error("invalid TOML: {0}")]
    TomlSyntax(String),
    /// The text is not well-formed XML, or not the reference route format.
    #[error("invalid XML: {0}")]
    XmlSyntax(String),
    /// A field is unknown, missing or of the wrong type.
    #[error("{0}")]
    Schema(String),
    /// A route id of the reference XML that has no role.
    #[error(
        "unknown route id {0}: expected 0 (start route), 1 (recovery route), 2 (fence), \
         3 (ignored) or 4–7 (cutouts)"
    )]
    UnknownRouteId(String),
    /// Two routes of the reference XML have the same id.
    #[error("route id {0} appears twice")]
    DuplicateRouteId(u8),
    /// A route the reference XML must have is absent.
    #[error("the XML has no route with id {id} (the {role})")]
    MissingRoute {
        /// The route id.
        id: u8,
        /// Its role.
        role: &'static str,
    },
    /// A text that should hold a number does not.
    #[error("`{0}` is not a number")]
    NotANumber(String),
    /// A number is NaN or infinite.
    #[error("not a finite number")]
    NotFinite,
    /// A polygon is not simple.
    #[error("{0}")]
    Polygon(PolygonError),
    /// A polygon has more vertices than any test area needs (a bound on the cost of checking it).
    #[error("{count} vertices: at most {max} are accepted (a real test area has tens)")]
    TooManyVertices {
        /// Vertices given.
        count: usize,
        /// The limit.
        max: usize,
    },
    /// A scenario file larger than any scenario needs (a bound on the cost of reading it).
    #[error("{bytes} bytes: at most {max} are accepted")]
    TooLarge {
        /// The file's size.
        bytes: u64,
        /// The limit.
        max: u64,
    },
    /// An oracle threshold no deviation inside the area can exceed.
    #[error(
        "{threshold} m is at least the area's diameter ({diameter:.1} m): no UWB estimate inside \
         the area can be that far from RTK, so every test would pass"
    )]
    ThresholdTestsNothing {
        /// The threshold, m.
        threshold: f64,
        /// The fence's bounding-box diagonal, m.
        diameter: f64,
    },
    /// A count above its limit.
    #[error("{count}: at most {max}")]
    TooMany {
        /// The count given.
        count: usize,
        /// The limit.
        max: usize,
    },
    /// A cutout reaches outside the fence.
    #[error("not entirely inside the fence")]
    CutoutOutsideFence,
    /// Two cutouts overlap or touch.
    #[error("overlaps cutouts[{other}]")]
    CutoutsOverlap {
        /// Index of the other cutout.
        other: usize,
    },
    /// A route has fewer than two points.
    #[error("a route needs at least 2 points, found {found}")]
    RouteTooShort {
        /// How many points there are.
        found: usize,
    },
    /// A route point lies outside the drivable area (or on its boundary).
    #[error("point ({x:.3}, {y:.3}) is outside the area")]
    PointOutsideArea {
        /// East, metres.
        x: f64,
        /// North, metres.
        y: f64,
    },
    /// A route segment meets the fence or a cutout.
    #[error("segment {segment} leaves the area (it meets the fence or a cutout)")]
    SegmentLeavesArea {
        /// Index of the segment (from point `segment` to point `segment + 1`).
        segment: usize,
    },
    /// Two consecutive route points coincide.
    #[error("segment {segment} has zero length (points {segment} and {} coincide)", segment + 1)]
    ZeroLengthSegment {
        /// Index of the segment.
        segment: usize,
    },
    /// The segment from the recovery route's end to the start route's first point leaves the area.
    #[error("the join from the recovery route's last point to start_route[0] leaves the area")]
    JoinLeavesArea,
    /// An anchor id does not fit the firmware's 0–255.
    #[error("{0} is outside 0–255 (the firmware addresses the UWB module by one byte)")]
    AnchorIdOutOfRange(i64),
    /// Two anchors share an id.
    #[error("duplicate id {id} (also anchors[{first}])")]
    DuplicateAnchorId {
        /// The id.
        id: u8,
        /// Index of the first anchor with it.
        first: usize,
    },
    /// More anchors than the firmware keeps.
    #[error("{0} anchors; the firmware keeps at most 20")]
    TooManyAnchors(usize),
    /// A value that must be above zero is not.
    #[error("must be greater than 0, found {0}")]
    NotPositive(f64),
    /// A value that must not be negative is.
    #[error("must not be negative, found {0}")]
    Negative(f64),
    /// A value outside its allowed range.
    #[error("{} is outside {low}..={high}", number(*value))]
    OutOfRange {
        /// The value.
        value: f64,
        /// Smallest allowed.
        low: f64,
        /// Largest allowed.
        high: f64,
    },
    /// A value beyond one of drivecheck's limits ([`crate::limits`]).
    #[error("{0}")]
    BeyondLimit(Box<BeyondLimit>),
    /// A value that must be a whole number is not.
    #[error("must be a whole number, found {0}")]
    NotWhole(f64),
    /// A range whose minimum exceeds its maximum.
    #[error("min {min} is greater than max {max}")]
    MinAboveMax {
        /// The minimum.
        min: f64,
        /// The maximum.
        max: f64,
    },
    /// A text or list that must not be empty is.
    #[error("must not be empty")]
    Empty,
    /// A fault kind listed twice.
    #[error("`{0}` is listed twice")]
    DuplicateKind(&'static str),
    /// The fault kind `none` among the kinds to generate.
    #[error("`none` does nothing (it only occupies a fault slot): leave it out")]
    NoneKind,
    /// A fault range that holds only its kind's neutral parameter.
    #[error(
        "holds only {neutral}, which leaves the probe's value as it is: a fault that does \
         nothing (widen the range or leave the kind out)"
    )]
    OnlyNeutral {
        /// The neutral parameter (an offset's 0, an amplification's 1).
        neutral: f64,
    },
    /// No bundled scenario has this name.
    #[error("no bundled scenario `{name}` (known: {known})")]
    UnknownBundled {
        /// The name asked for.
        name: String,
        /// The bundled names, comma-separated.
        known: String,
    },
    /// A wall whose two ends coincide.
    #[error("the wall's ends a and b coincide")]
    WallWithoutLength,
    /// The text is not valid JSON.
    #[error("invalid JSON: {0}")]
    JsonSyntax(String),
    /// The JSON is not a GeoJSON scenario drivecheck can read.
    #[error("{0}")]
    GeoJson(Box<GeoJsonProblem>),
}

/// What is wrong with a GeoJSON scenario (`docs/geojson.md`); the error's field names the
/// feature and its member (`features[3].geometry`).
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum GeoJsonProblem {
    /// A member of the wrong JSON type or GeoJSON type.
    #[error("expected {expected}, found {found}")]
    WrongType {
        /// What was expected.
        expected: &'static str,
        /// What was found.
        found: String,
    },
    /// A geometry that cannot play a feature's role (a LineString as the fence).
    #[error("a {geometry} cannot be {role}")]
    CannotBe {
        /// The geometry's type, as found.
        geometry: String,
        /// The role, with its article (`a fence`).
        role: &'static str,
    },
    /// A `drivecheck` property that names no role.
    #[error("`{0}` is not a role: expected fence, cutout, anchor, route, obstacle or wall")]
    UnknownRole(String),
    /// A route's `route` property that names no route.
    #[error("`{0}` is not a route: expected \"start\" or \"recovery\"")]
    UnknownRoute(String),
    /// A second feature in a role only one may have.
    #[error("a second {role} (the first is features[{first}])")]
    Duplicate {
        /// The role.
        role: &'static str,
        /// The first feature in it.
        first: usize,
    },
    /// No feature has a role a scenario needs.
    #[error("no {role}: {how}")]
    Missing {
        /// The role.
        role: &'static str,
        /// How to give it.
        how: &'static str,
    },
    /// A LineString route without speeds.
    #[error("a route needs `speed` (m/s, every point) or `speeds` (one per point)")]
    NoSpeed,
    /// A route whose `speeds` do not match its points.
    #[error("{speeds} speed(s) for {points} point(s)")]
    SpeedsLength {
        /// Speeds given.
        speeds: usize,
        /// Points of the LineString.
        points: usize,
    },
    /// A position that is not two or three numbers.
    #[error("a position is [x, y] or [longitude, latitude] (an optional third number is ignored)")]
    BadPosition,
    /// A wall that is not a LineString of two points.
    #[error("a wall is a LineString of 2 points, found {0}")]
    WallPoints(usize),
    /// A property that must be a whole number (an anchor id) is not one.
    #[error("`{0}` is not a whole number")]
    NotWhole(String),
    /// A longitude or latitude out of its range.
    #[error("({lon}, {lat}) is not a longitude and latitude")]
    NotLonLat {
        /// The first number.
        lon: f64,
        /// The second number.
        lat: f64,
    },
    /// Coordinates that could be longitude/latitude or local metres alike.
    #[error(
        "the coordinates could be longitude and latitude (a fence {wgs84_m:.0} m across) or \
         local metres (a fence {local_m:.1} m across): say which with --crs wgs84 or --crs local \
         (or \"crs\" in the collection's \"drivecheck\" member)"
    )]
    AmbiguousCrs {
        /// The fence's bounding-box diagonal read as longitude and latitude, metres.
        wgs84_m: f64,
        /// Its diagonal read as metres.
        local_m: f64,
    },
    /// A coordinate reference system drivecheck does not read.
    #[error(
        "coordinates in {0}: drivecheck reads longitude/latitude (WGS84, EPSG:4326, as RFC 7946 \
         requires) or its own local metres; save the layer in EPSG:4326 (QGIS: Export → Save \
         Features As…, CRS EPSG:4326)"
    )]
    UnsupportedCrs(String),
    /// The `crs` asked for conflicts with the file's marker.
    #[error("the file says its coordinates are {file}, the command line says {asked}")]
    CrsConflict {
        /// What the file says.
        file: &'static str,
        /// What was asked.
        asked: &'static str,
    },
    /// A drivecheck GeoJSON format newer than this drivecheck.
    #[error("format version {found}: this drivecheck reads version {supported}")]
    NewerVersion {
        /// The file's version.
        found: u64,
        /// The version read.
        supported: u64,
    },
}

/// A soft problem: the scenario is usable, but a person should look.
/// Displays as `file: field: message`.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{source_name}: {field}: {kind}")]
pub struct Warning {
    /// The file path or source name.
    pub source_name: String,
    /// The field path (`recovery_route[4]`).
    pub field: String,
    /// What is soft-wrong.
    pub kind: WarningKind,
}

/// The kinds of [`Warning`].
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum WarningKind {
    /// The scenario has no anchors.
    #[error("no anchors: UWB positioning cannot be tested in this area")]
    NoAnchors,
    /// A hand-drawn route turns more sharply than the generator may.
    #[error(
        "the route turns {turn_deg:.1}° here, more than the generator's {max_deg:.1}° \
         (hand-drawn; kept as drawn)"
    )]
    SharpTurn {
        /// The turn, degrees (absolute).
        turn_deg: f64,
        /// The generator's limit, degrees.
        max_deg: f64,
    },
    /// A hand-drawn route segment is outside the generator's segment lengths.
    #[error(
        "segment {segment} is {length:.2} m long, outside the generator's {min:.2}–{max:.2} m \
         (hand-drawn; kept as drawn)"
    )]
    SegmentLength {
        /// Index of the segment in its route.
        segment: usize,
        /// Its length, metres.
        length: f64,
        /// The generator's shortest segment, metres.
        min: f64,
        /// The generator's longest segment, metres.
        max: f64,
    },
    /// The step from the recovery route's end to the start route is outside the segment lengths.
    #[error(
        "the join to start_route[0] is {length:.2} m long, outside the generator's \
         {min:.2}–{max:.2} m (hand-drawn; kept as drawn)"
    )]
    JoinLength {
        /// Its length, metres.
        length: f64,
        /// The generator's shortest segment, metres.
        min: f64,
        /// The generator's longest segment, metres.
        max: f64,
    },
    /// The recovery route ends farther from the start route than a straight step may be: the
    /// runner plans the join with the return-route planner.
    #[error(
        "the recovery route ends {gap:.2} m from start_route[0], more than {limit:.2} m \
         (1.5 × generator.segment_max_m): the reset plans a route between them"
    )]
    JoinPlanned {
        /// Distance from the recovery route's last point to the start route's first, metres.
        gap: f64,
        /// The longest straight step, metres.
        limit: f64,
    },
    /// A GeoJSON feature without a `drivecheck` property whose role was inferred from its geometry.
    #[error("no `drivecheck` property: taken as {role} ({why})")]
    RoleInferred {
        /// The role, with its article.
        role: &'static str,
        /// Why.
        why: &'static str,
    },
    /// A GeoJSON anchor without an `id` property.
    #[error("no `id` property: the anchor is numbered {id}")]
    AnchorNumbered {
        /// The id given to it.
        id: u8,
    },
    /// A GeoJSON anchor without a `height` property.
    #[error("no `height` property: 0 m assumed (the firmware stores it but does not use it)")]
    AnchorHeightAssumed,
    /// Longitude/latitude without an origin: the fence's first vertex is the local frame's.
    #[error(
        "longitude/latitude and no origin given: the fence's first vertex ({lat}, {lon}) is the \
         local frame's origin (give --origin LAT,LON[,H] to choose it)"
    )]
    OriginFromFirstVertex {
        /// Its latitude, degrees.
        lat: f64,
        /// Its longitude, degrees.
        lon: f64,
    },
    /// A hand-drawn route segment comes closer to an edge than the generator's clearance.
    #[error(
        "the segment from this point comes within {distance:.2} m of an edge \
         (clearance {clearance:.2} m)"
    )]
    NearEdge {
        /// Its distance to the nearest edge, metres.
        distance: f64,
        /// The generator's clearance, metres.
        clearance: f64,
    },
}

/// A value beyond one of drivecheck's limits ([`crate::limits`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{} is beyond drivecheck's limit: {bound} {limit} ({why})", number(*value))]
pub struct BeyondLimit {
    /// The value.
    pub value: f64,
    /// `at most` or `at least`.
    pub bound: &'static str,
    /// The limit.
    pub limit: f64,
    /// What the limit guards.
    pub why: &'static str,
}

/// A number as a person reads it: plain, or in exponent form when very large or small (`1e300`,
/// not three hundred digits).
fn number(x: f64) -> String {
    if x != 0.0 && !(1e-3..1e9).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        x.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_become_lines_and_character_columns() {
        let text = "a = 1\nπ = \"é\"\nlast";
        assert_eq!(
            Location::of_offset(text, 0),
            Location { line: 1, column: 1 }
        );
        assert_eq!(
            Location::of_offset(text, 6),
            Location { line: 2, column: 1 }
        );
        // Byte 9 is the `=` after "π " (π takes 2 bytes): the 3rd character of line 2.
        assert_eq!(
            Location::of_offset(text, 9),
            Location { line: 2, column: 3 }
        );
        assert_eq!(
            Location::of_offset(text, 1000),
            Location { line: 3, column: 5 }
        );
    }

    #[test]
    fn errors_display_as_file_line_column_field_message() {
        let mut error = ScenarioError::in_field("a.toml", "fence[5].x", Problem::NotFinite);
        assert_eq!(error.to_string(), "a.toml: fence[5].x: not a finite number");
        error.place.location = Some(Location { line: 3, column: 7 });
        assert_eq!(
            error.to_string(),
            "a.toml:3:7: fence[5].x: not a finite number"
        );
    }
}
